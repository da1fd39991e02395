"""friction: Coulomb and viscous friction on the drive, u - F_c sign(v) - F_v v, v = x(t) - x(t-1)."""

from __future__ import annotations

import numpy as np

from ._base import Array, Augmentation, Effect, Problem, ScreenContext

STEP = 1e-4  # relative finite-difference step of the screening


AUGMENTATION = Augmentation("friction", ("F_c", "F_v"), (0.0, 0.0), "u - F_c sign(v) - F_v v, v = x(t) - x(t-1)")


class Friction(Effect, rank=2, augmentation=AUGMENTATION):
    """Coulomb and viscous friction on the drive input."""

    def bounds(self, prob: Problem) -> tuple[Array, Array]:
        """0 <= F_c <= 2 std(u), 0 <= F_v <= 2."""
        s = float(np.std(prob.u))
        return np.zeros(2), np.array([2.0 * s + 1e-12, 2.0])

    def starts(self, prob: Problem, theta0: Array) -> list[tuple[Array, dict[str, float]]]:
        """The error is not convex in (F_c, F_v): short refits from a few corners first."""
        s = float(np.std(prob.u))
        return [(np.array([fc * s, fv]), {}) for fc, fv in ((0.02, 0.0), (0.15, 0.0), (0.05, 0.3), (0.3, 0.6))]

    def directions(self, screen: ScreenContext) -> list[Array]:
        """Derivatives in F_c (scaled by std(u)) and F_v, by finite differences."""
        h, su = STEP, float(np.std(screen.u)) + 1e-12
        return [screen.change(self.core({"F_c": h * su, "F_v": 0.0})) / h, screen.change(self.core({"F_c": 0.0, "F_v": h})) / h]
