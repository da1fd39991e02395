"""feedback_hysteresis: a hysteretic restoring force fed back around the linear dynamics
(Bouc-Wen, nu = 1) with a static cubic stiffness, on the drive: u_eff = u - z - k_3 x^3,
z the exact solution over each sample of dz = alpha dx - beta abs(dx) z - gamma dx abs(z) with x
moving linearly between samples (the Bouc-Wen benchmark's hysteretic oscillator; with alpha =
0 a Duffing oscillator). Rust:
``rust/core/src/effects/feedback_hysteresis.rs``."""

from __future__ import annotations

import numpy as np

from ...errors import ModelError
from ._base import Array, Augmentation, Effect, Fitted, RefitRecords, ScreenContext, linear_x

AUGMENTATION = Augmentation(
    "feedback_hysteresis",
    ("alpha", "beta", "gamma", "k_3"),
    (0.0, 0.0, 0.0, 0.0),
    "u_eff = u - z - k_3 x^3, z a Bouc-Wen state (nu = 1) driven by the velocity of x",
)


def _scales(prob: RefitRecords, theta0: Array) -> tuple[float, float, float]:
    """(k, s_x, v_max): the stiffness that cancels the nominal loop's static gain (1 / |G|, or
    std(u) / std(x) without one), std(x) and max |v| of the nominal linear block's x."""
    x = linear_x(prob.structure, theta0, prob.u)
    sx = float(np.std(x)) + 1e-12
    est = prob.structure.unpack(theta0)
    gain = float(np.sum(est.a) / (1.0 + np.sum(est.b)))
    k = 1.0 / abs(gain) if np.isfinite(gain) and abs(gain) > 1e-9 else (float(np.std(prob.u)) + 1e-12) / sx
    return k, sx, float(np.max(np.abs(np.diff(x)), initial=0.0)) + 1e-12


class FeedbackHysteresis(Effect, rank=12, augmentation=AUGMENTATION):
    """A Bouc-Wen restoring force and a cubic stiffness in the drive's force balance."""

    def bounds(self, prob: RefitRecords) -> tuple[Array, Array]:
        """The record's scale s = std(u) + std(y) (x unknown without a nominal model): 0 <=
        alpha <= 1e3, 0 <= beta <= 1e3 / s, |gamma| <= 1e3 / s, |k_3| <= 1e3 / s^2; the refit
        narrows them to the nominal loop's scales (:meth:`refit`)."""
        s = float(np.std(prob.u) + np.std(prob.y)) + 1e-9
        return np.array([0.0, 0.0, -1e3 / s, -1e3 / s**2]), np.array([1e3, 1e3 / s, 1e3 / s, 1e3 / s**2])

    def box(self, prob: RefitRecords, theta0: Array) -> tuple[Array, Array]:
        """The refit's box on the nominal loop's scales (k, s_x, v_max of :func:`_scales`): 0 <=
        alpha <= 2 k (a stiffness up to twice the loop's), beta, |gamma| <= 0.9 / v_max (the
        bound an explicit Euler step of z needed to stay bounded; the exact step does not, but
        every benchmark figure was measured within it, so it is kept until one is rerun
        without), 0 <= k_3 <= 2 k / s_x^2 (a hardening spring: a softening one runs away once
        x is large)."""
        k, sx, vmax = _scales(prob, theta0)
        lb, ub = self.bounds(prob)
        lo = np.array([0.0, 0.0, -0.9 / vmax, 0.0])
        hi = np.array([2.0 * k, 0.9 / vmax, 0.9 / vmax, 2.0 * k / sx**2])
        return np.maximum(lo, lb), np.minimum(hi, ub)

    def refit(self, prob: RefitRecords, theta0: Array) -> Fitted:
        """The error has no gradient in beta, gamma at alpha = 0 and is not convex: short refits
        from a few starts (a hysteretic stiffness of 5 % and 30 % of the loop's, saturating after
        0.3 or 1 std(x) of travel; a cubic stiffness alone), the best one refitted to
        convergence, within :meth:`box`."""
        k, sx, _ = _scales(prob, theta0)
        lb, ub = self.box(prob, theta0)
        starts = [np.array([a * k, 1.0 / (c * sx), 0.0, 0.0]) for a in (0.05, 0.3) for c in (0.3, 1.0)]  # clipped to the box
        starts.append(np.array([0.0, 1.0 / sx, 0.0, 0.1 * k / sx**2]))
        return self._multi_start(prob, theta0, [(np.clip(e0, lb, ub), {}) for e0 in starts], lb, ub)

    def directions(self, screen: ScreenContext) -> list[Array]:
        """Finite-size changes (1 % of the loop's stiffness): a hysteretic force saturating after
        0.3 std(x) of travel (beta at most 0.9 / max |v|, inside :meth:`box`), and a cubic
        stiffness."""
        prob = RefitRecords(screen.structure, screen.u, screen.y, 0, screen.t0)
        k, sx, vmax = _scales(prob, screen.theta)
        h = 0.01
        beta = min(1.0 / (0.3 * sx), 0.9 / vmax)
        out = []
        for params in ({"alpha": h * k, "beta": beta, "gamma": 0.0, "k_3": 0.0}, {"alpha": 0.0, "beta": 0.0, "gamma": 0.0, "k_3": h * k / sx**2}):
            try:
                out.append(screen.change(self.core(params)) / h)
            except ModelError:  # a feedback that runs away on this record: no direction from it
                continue
        return out
