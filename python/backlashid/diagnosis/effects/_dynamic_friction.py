"""dynamic_friction: a friction force with a bristle state (Dahl / LuGre family) added to the
load, f + k_f w (before the sandwich's output block, which filters both; in a cascade, on the
output), dw/dt = q'/z_s - (|q'|/z_s + lambda) w stepped exactly between samples (q linear
within a sample): the force follows a motion q, saturates at +-k_f after a slide of a few z_s
and relaxes at the rate lambda per sample at standstill. The motion is the linear block's
output x (source 0: friction behind the drive's dynamics), the measured input u (source 1:
an imposed displacement, as in a friction damper whose input is a displacement and whose
measured output is a force) or the backlash's output f (source 2: the load's own motion,
which stops while the play is crossed); the refit tries each. Rust:
``rust/core/src/effects/dynamic_friction.rs``."""

from __future__ import annotations

import numpy as np

from ...identify import Structure
from ._base import Array, Augmentation, Effect, Fitted, RefitRecords, ScreenContext, linear_x, load_f

AUGMENTATION = Augmentation(
    "dynamic_friction",
    ("k_f", "z_s", "lambda", "source"),
    (0.0, 0.1, 0.0, 0.0),
    "f + k_f w on the load, dw/dt = q'/z_s - (|q'|/z_s + lambda) w, q = x (source 0), u (1) or f (2) "
    "(a Dahl/LuGre friction force relaxing at standstill)",
)
SOURCES = (0.0, 1.0, 2.0)  # q = x, q = u, q = f

PRESLIDING = (0.01, 0.03, 0.1, 0.3, 1.0)  # z_s of the start grid, in std(q)
RELAXATION = (0.0, 0.003, 0.03)  # lambda of the start grid, per sample


class DynamicFriction(Effect, rank=11, augmentation=AUGMENTATION):
    """A relaxing friction force on the load, driven by the motion of x, of u or of f."""

    def bounds(self, prob: RefitRecords) -> tuple[Array, Array]:
        """Of (k_f, z_s, lambda), the source held: |k_f| <= 2 std(y) + 0.1; s = std(u) +
        std(y) (the record's scale, x unknown without a nominal model): 1e-4 s <= z_s <= 10 s;
        0 <= lambda <= 0.5."""
        sy = float(np.std(prob.y)) + 0.1
        s = float(np.std(prob.u) + np.std(prob.y)) + 1e-9
        return np.array([-2.0 * sy, 1e-4 * s, 0.0]), np.array([2.0 * sy, 10.0 * s, 0.5])

    def refit(self, prob: RefitRecords, theta0: Array) -> Fitted:
        """At k_f = 0 the error has no gradient in z_s, lambda; at fixed (z_s, lambda, source)
        the output is linear in k_f (y = y_nom + k_f w): k_f fitted to the nominal residual on
        a grid of (source, z_s in std(q) of its motion, lambda), then everything but the source
        refitted from the best three grid points."""
        y_nom = prob.simulate(theta0)
        r0 = (prob.y - y_nom)[prob.warmup :]
        lb, ub = self.bounds(prob)
        scored = []
        for source in SOURCES:
            sq = _motion_scale(prob.structure, theta0, prob.u, source)
            for zs in np.clip(np.array(PRESLIDING) * sq, lb[1], ub[1]):
                for lam in RELAXATION:
                    unit = self.core({"k_f": 1.0, "z_s": zs, "lambda": lam, "source": source})
                    w = (prob.simulate(theta0, unit) - y_nom)[prob.warmup :]
                    k = float(np.clip((w @ r0) / max(float(w @ w), 1e-300), lb[0], ub[0]))
                    scored.append((float(np.sum((r0 - k * w) ** 2)), (k, float(zs), lam), source))
        scored.sort(key=lambda c: c[0])
        return self._multi_start(prob, theta0, [(np.array(e0), {"source": q}) for _, e0, q in scored[:3]], lb, ub)

    def directions(self, screen: ScreenContext) -> list[Array]:
        """The friction force of unit size driven by x at presliding displacements 0.03 and 0.3
        std(x) without relaxation and at 0.1 std(x) relaxing at 0.01 per sample, and driven by
        u and by f at 0.03 and 0.3 std of their motion relaxing at 0.01 per sample."""
        out = []
        slides = ((0.03, 0.01), (0.3, 0.01))
        for source, grid in ((0.0, ((0.03, 0.0), (0.3, 0.0), (0.1, 0.01))), (1.0, slides), (2.0, slides)):
            sq = _motion_scale(screen.structure, screen.theta, screen.u, source)
            out += [screen.change(self.core({"k_f": 1.0, "z_s": zs * sq, "lambda": lam, "source": source})) for zs, lam in grid]
        return out


def _motion_scale(structure: Structure, theta: Array, u: Array, source: float) -> float:
    """std of the motion q the friction follows: x of the nominal linear block (source 0), u
    (1) or the nominal backlash's output f (2)."""
    q = u if source == 1.0 else load_f(structure, theta, u) if source == 2.0 else linear_x(structure, theta, u)
    return float(np.std(q)) + 1e-12
