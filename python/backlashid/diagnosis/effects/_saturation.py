"""saturation: the drive input clipped to [lo, hi] before the linear block."""

from __future__ import annotations

import numpy as np

from ._base import Array, Augmentation, Effect, RefitRecords, ScreenContext

AUGMENTATION = Augmentation("saturation", ("lo", "hi"), (-np.inf, np.inf), "drive input clipped to [lo, hi]")


class Saturation(Effect, rank=1, augmentation=AUGMENTATION):
    """Drive input clipped to [lo, hi]."""

    def bounds(self, prob: RefitRecords) -> tuple[Array, Array]:
        """lo below the median input, hi above it."""
        u = prob.u
        return np.array([u.min(), np.median(u)]), np.array([np.median(u), u.max()])

    def starts(self, prob: RefitRecords, theta0: Array) -> list[tuple[Array, dict[str, float]]]:
        """The gradient vanishes at the record's range: the three best of a few clipping levels."""
        u = prob.u
        levels = [(qlo, qhi) for qlo in (0.0, 0.05, 0.15) for qhi in (0.0, 0.05, 0.15) if qlo or qhi]
        scored = []
        for qlo, qhi in levels:
            e0 = np.array([np.quantile(u, qlo), np.quantile(u, 1 - qhi)])
            e0 = e0 + np.array([1e-9, -1e-9])
            scored.append((prob.cost(theta0, self.core({"lo": e0[0], "hi": e0[1]})), tuple(e0)))
        scored.sort()
        return [(np.array(e0), {}) for _, e0 in scored[:3]]

    def directions(self, screen: ScreenContext) -> list[Array]:
        """Clipping at the 10 % and the 90 % quantile of the input."""
        u = screen.u
        return [
            screen.change(self.core({"lo": float(np.quantile(u, 0.1)), "hi": np.inf})),
            screen.change(self.core({"lo": -np.inf, "hi": float(np.quantile(u, 0.9))})),
        ]
