"""friction: friction in the drive's force balance, opposing the drive's velocity on the linear
block's input: Coulomb and viscous (u - F_c sign(v) - F_v v, v = x(t) - x(t-1)), or stick-slip
(Karnopp's rule: the drive stays at rest while the force is below the static friction) with a
Stribeck dip F_s exp(-(v / v_s)^2) of the sliding friction."""

from __future__ import annotations

import math

import numpy as np

from ...errors import BacklashIdError
from ._base import MAX_ITER, Array, Augmentation, AugmentedModel, CoreEffects, Effect, Fitted, RefitRecords, ScreenContext

STEP = 1e-4  # relative finite-difference step of the screening
SHORT_ITER = 5  # iterations of the short refits from each start


AUGMENTATION = Augmentation(
    "friction",
    ("F_c", "F_v"),
    (0.0, 0.0),
    "u - F_c sign(v) - F_v v, v = x(t) - x(t-1); or stick-slip (stuck while the force is under F_c + F_s, "
    "sliding against F_c + F_s exp(-(v/v_s)^2) + F_v v)",
)


class _StickSlip(Effect):
    """The stick-slip form's refit (``rust/core/src/effects/stick_slip.rs``); no catalogue
    entry of its own (no name: the registry skips it), reported as friction."""

    parameters = ("F_c", "F_v", "F_s", "v_s")

    def core(self, params: dict[str, float]) -> CoreEffects:
        """The Rust stick_slip effect."""
        return (("stick_slip", tuple(float(params[n]) for n in self.parameters)),)


_STICK_SLIP = _StickSlip()


class Friction(Effect, rank=2, augmentation=AUGMENTATION):
    """Friction in the drive's force balance: Coulomb and viscous, or stick-slip with a
    Stribeck dip, whichever has the lower BIC on the estimation record."""

    def bounds(self, prob: RefitRecords) -> tuple[Array, Array]:
        """0 <= F_c <= 2 std(u), 0 <= F_v <= 2."""
        s = float(np.std(prob.u))
        return np.zeros(2), np.array([2.0 * s + 1e-12, 2.0])

    def starts(self, prob: RefitRecords, theta0: Array) -> list[tuple[Array, dict[str, float]]]:
        """The error is not convex in (F_c, F_v): short refits from a few corners first."""
        s = float(np.std(prob.u))
        return [(np.array([fc * s, fv]), {}) for fc, fv in ((0.02, 0.0), (0.15, 0.0), (0.05, 0.3), (0.3, 0.6))]

    def fit(self, prob: RefitRecords, theta0: Array) -> AugmentedModel:
        """Three forms refitted, the one of lowest BIC (n ln(SSE / n) + k ln n) kept:
        Coulomb and viscous friction on the last step's velocity (k = 2); stick-slip with
        Coulomb and viscous sliding friction (k = 2); stick-slip with a Stribeck dip from that
        fit (k = 4).

        Parameters
        ----------
        prob : RefitRecords
            What the refits run on.
        theta0 : ndarray
            Nominal parameters.

        Returns
        -------
        AugmentedModel
            Parameters F_c, F_v (and F_s, v_s, stick = 1 for the stick-slip forms).
        """
        n = max(prob.n_scored, 1)

        def bic(cost: float, k: int) -> float:
            return n * math.log(max(cost, 1e-300) / n) + k * math.log(n)

        forms: list[tuple[float, Fitted, CoreEffects, int]] = []
        theta, params, cost = self.refit(prob, theta0)
        forms.append((bic(cost, 2), (theta, params, cost), self.core(params), 2))
        for fitted, k in self._stick_slip(prob, theta0):
            forms.append((bic(fitted[2], k), fitted, _STICK_SLIP.core(fitted[1]), k))
        _, (theta, params, _), core, k = min(forms, key=lambda f: f[0])
        if core[0][0] == "stick_slip":
            params = {**params, "stick": 1.0}
            if k == 2:
                params = {n_: v for n_, v in params.items() if n_ not in ("F_s", "v_s")}
        return prob.model(self.name, prob.structure, theta, params, core, k)

    def _stick_slip(self, prob: RefitRecords, theta0: Array) -> list[tuple[Fitted, int]]:
        """The stick-slip refits: Coulomb and viscous (F_s = 0 held), then a Stribeck dip."""
        s = float(np.std(prob.u)) + 1e-12
        v_scale = float(np.std(np.diff(prob.linear_output(theta0)))) + 1e-12
        lb = np.array([0.0, 0.0, 0.0, 1e-3 * v_scale])
        ub = np.array([2.0 * s, 2.0, 2.0 * s, 10.0 * v_scale])
        out: list[tuple[Fitted, int]] = []
        try:
            held = {"F_s": 0.0, "v_s": v_scale}
            short = [
                _STICK_SLIP._refit(prob, theta0, np.array([fc * s, 0.0]), lb[:2], ub[:2], held, max_iter=SHORT_ITER)
                for fc in (0.02, 0.1)
            ]
            theta, params, _ = min(short, key=lambda f: f[2])
            e = np.array([params["F_c"], params["F_v"]])
            coulomb = _STICK_SLIP._refit(prob, theta, e, lb[:2], ub[:2], held, max_iter=MAX_ITER)
            out.append((coulomb, 2))
            theta, params, _ = coulomb
            short = [
                _STICK_SLIP._refit(
                    prob, theta, np.array([params["F_c"], params["F_v"], 0.5 * params["F_c"] + 0.02 * s, vs * v_scale]),
                    lb, ub, {}, max_iter=SHORT_ITER,
                )
                for vs in (0.3, 1.0)
            ]
            theta, params, _ = min(short, key=lambda f: f[2])
            e = np.array([params[k] for k in _STICK_SLIP.parameters])
            out.append((_STICK_SLIP._refit(prob, theta, e, lb, ub, {}, max_iter=MAX_ITER), 4))
        except BacklashIdError:  # a stick-slip form that cannot be refitted is left out
            pass
        return out

    def directions(self, screen: ScreenContext) -> list[Array]:
        """Derivatives in F_c (scaled by std(u)) and F_v, by finite differences."""
        h, su = STEP, float(np.std(screen.u)) + 1e-12
        return [screen.change(self.core({"F_c": h * su, "F_v": 0.0})) / h, screen.change(self.core({"F_c": 0.0, "F_v": h})) / h]
