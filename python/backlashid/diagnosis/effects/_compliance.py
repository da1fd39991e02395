"""compliance: y = (1 - k) f + k H f, H a unit-DC-gain lightly damped resonance."""

from __future__ import annotations

import numpy as np

from ._base import Array, Augmentation, Effect, RefitRecords, ScreenContext

AUGMENTATION = Augmentation("compliance", ("k", "omega", "zeta"), (0.0, 0.5, 0.1), "y = (1 - k) f + k H f, H a unit-DC resonance")


class Compliance(Effect, rank=7, augmentation=AUGMENTATION):
    """A resonant path of share k after the backlash."""

    def bounds(self, prob: RefitRecords) -> tuple[Array, Array]:
        """0 <= k <= 1.5, 0.02 <= omega <= 3, 0.005 <= zeta <= 0.9."""
        return np.array([0.0, 0.02, 0.005]), np.array([1.5, 3.0, 0.9])

    def starts(self, prob: RefitRecords, theta0: Array) -> list[tuple[Array, dict[str, float]]]:
        """k = 0 leaves omega and zeta without a gradient. At fixed (omega, zeta) the output is
        linear in k (y = y_nom + k (H f - f)): fit k to the nominal residual on a grid, then
        start from the best three grid points."""
        y_nom = prob.simulate(theta0)
        r0 = prob.scored(prob.y - y_nom)
        scored = []
        for omega in np.geomspace(0.04, 2.8, 16):
            for zeta in (0.02, 0.06, 0.15, 0.35):
                d = prob.scored(prob.simulate(theta0, self.core({"k": 1.0, "omega": omega, "zeta": zeta})) - y_nom)
                k = float(np.clip((d @ r0) / max(float(d @ d), 1e-300), 0.0, 1.5))
                scored.append((float(np.sum((r0 - k * d) ** 2)), (max(k, 1e-3), float(omega), zeta)))
        scored.sort()
        return [(np.array(e0), {}) for _, e0 in scored[:3]]

    def directions(self, screen: ScreenContext) -> list[Array]:
        """The pure resonance at three frequencies."""
        return [screen.change(self.core({"k": 1.0, "omega": w, "zeta": 0.1})) for w in (0.1, 0.4, 1.5)]
