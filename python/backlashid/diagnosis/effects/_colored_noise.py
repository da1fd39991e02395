"""colored_noise: an AR noise model of the output error (judged by one-step prediction)."""

from __future__ import annotations

import numpy as np

from ..._numerics import lstsq
from ._base import Array, Augmentation, AugmentedModel, Effect, RefitRecords, ScreenContext, ar_predict

MAX_AR = 4  # highest order of the AR model


def fit_ar(prob: RefitRecords, theta0: Array) -> tuple[Array, float]:
    """AR(p) model of the nominal output error, p <= MAX_AR chosen by BIC (least squares)."""
    r = prob.scored(prob.y - prob.simulate(theta0))
    n = r.size
    best: tuple[float, Array] = (n * np.log(np.mean(r * r) + 1e-300), np.zeros(0))
    for p in range(1, MAX_AR + 1):
        a = np.column_stack([r[p - k : n - k] for k in range(1, p + 1)])
        phi = lstsq(a, r[p:])
        e = r[p:] - a @ phi
        bic = (n - p) * np.log(np.mean(e * e) + 1e-300) + p * np.log(n)
        if bic < best[0]:
            best = (bic, np.asarray(phi, dtype=np.float64))
    phi = best[1]
    e = r - ar_predict(r, phi)
    return phi, float(e @ e)


AUGMENTATION = Augmentation(
    "colored_noise", tuple(f"phi_{k}" for k in range(1, MAX_AR + 1)), (0.0,) * MAX_AR, "AR noise model on the output error"
)


class ColoredNoise(Effect, rank=10, augmentation=AUGMENTATION, simulated=False):
    """An AR noise model on the output error."""

    def fit(self, prob: RefitRecords, theta0: Array) -> AugmentedModel:
        """The AR model of the nominal output error; the nominal parameters are kept."""
        phi, _ = fit_ar(prob, theta0)
        params = {f"phi_{k}": float(phi[k - 1]) if k <= phi.size else 0.0 for k in range(1, MAX_AR + 1)}
        return prob.model(self.name, prob.structure, theta0, params, (), int(phi.size), ar=phi)

    def directions(self, screen: ScreenContext) -> list[Array]:
        """The residual's own past (a Ljung-Box-like LM test)."""
        full = screen.y - screen.y_sim
        return [np.concatenate([np.zeros(k), full[:-k]]) for k in range(1, MAX_AR + 1)]
