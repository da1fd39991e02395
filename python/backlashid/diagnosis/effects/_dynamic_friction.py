"""dynamic_friction: a friction force with a bristle state (Dahl / LuGre family) added to the
output, y + k_f w, dw/dt = x'/z_s - (|x'|/z_s + lambda) w stepped exactly between samples (x
linear within a sample): the force follows the motion of x, saturates at +-k_f after a slide of
a few z_s and relaxes at the rate lambda per sample at standstill (a friction damper whose
input is a displacement and whose measured output is a force). Rust:
``rust/core/src/effects/dynamic_friction.rs``."""

from __future__ import annotations

import numpy as np

from ._base import Array, Augmentation, Effect, Fitted, Problem, ScreenContext, linear_x

AUGMENTATION = Augmentation(
    "dynamic_friction",
    ("k_f", "z_s", "lambda"),
    (0.0, 0.1, 0.0),
    "y + k_f w, dw/dt = x'/z_s - (|x'|/z_s + lambda) w (a Dahl/LuGre friction force relaxing at standstill)",
)

PRESLIDING = (0.01, 0.03, 0.1, 0.3, 1.0)  # z_s of the start grid, in std(x)
RELAXATION = (0.0, 0.003, 0.03)  # lambda of the start grid, per sample


class DynamicFriction(Effect, rank=11, augmentation=AUGMENTATION):
    """A relaxing friction force on the output, driven by the motion of x."""

    def bounds(self, prob: Problem) -> tuple[Array, Array]:
        """|k_f| <= 2 std(y) + 0.1; s = std(u) + std(y) (the record's scale, x unknown without a
        nominal model): 1e-4 s <= z_s <= 10 s; 0 <= lambda <= 0.5."""
        sy = float(np.std(prob.y)) + 0.1
        s = float(np.std(prob.u) + np.std(prob.y)) + 1e-9
        return np.array([-2.0 * sy, 1e-4 * s, 0.0]), np.array([2.0 * sy, 10.0 * s, 0.5])

    def refit(self, prob: Problem, theta0: Array) -> Fitted:
        """At k_f = 0 the error has no gradient in z_s, lambda; at fixed (z_s, lambda) the output
        is linear in k_f (y = y_nom + k_f w): k_f fitted to the nominal residual on a grid of
        (z_s in std(x) of the nominal linear block, lambda), then everything refitted from the
        best three grid points."""
        sx = float(np.std(linear_x(prob.structure, theta0, prob.u))) + 1e-12
        y_nom = prob.simulate(theta0)
        r0 = (prob.y - y_nom)[prob.warmup :]
        lb, ub = self.bounds(prob)
        scored = []
        for zs in np.clip(np.array(PRESLIDING) * sx, lb[1], ub[1]):
            for lam in RELAXATION:
                w = (prob.simulate(theta0, self.core({"k_f": 1.0, "z_s": zs, "lambda": lam})) - y_nom)[prob.warmup :]
                k = float(np.clip((w @ r0) / max(float(w @ w), 1e-300), lb[0], ub[0]))
                scored.append((float(np.sum((r0 - k * w) ** 2)), (k, float(zs), lam)))
        scored.sort()
        return self._multi_start(prob, theta0, [(np.array(e0), {}) for _, e0 in scored[:3]], lb, ub)

    def directions(self, screen: ScreenContext) -> list[Array]:
        """The friction force of unit size at presliding displacements 0.03 and 0.3 std(x)
        without relaxation, and at 0.1 std(x) relaxing at 0.01 per sample."""
        sx = float(np.std(linear_x(screen.structure, screen.theta, screen.u))) + 1e-12
        return [
            screen.change(self.core({"k_f": 1.0, "z_s": zs * sx, "lambda": lam})) for zs, lam in ((0.03, 0.0), (0.3, 0.0), (0.1, 0.01))
        ]
