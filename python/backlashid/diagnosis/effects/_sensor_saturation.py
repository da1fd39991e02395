"""sensor_saturation: the measured output clipped to [lo, hi] (the sensor's range)."""

from __future__ import annotations

import numpy as np

from ._base import Array, Augmentation, Effect, RefitRecords, ScreenContext

AUGMENTATION = Augmentation("sensor_saturation", ("lo", "hi"), (-np.inf, np.inf), "measured output clipped to [lo, hi]")


class SensorSaturation(Effect, rank=21, augmentation=AUGMENTATION):
    """The measured output clipped to [lo, hi]."""

    def bounds(self, prob: RefitRecords) -> tuple[Array, Array]:
        """lo below the output's median, hi above it, within its range."""
        y = prob.y
        return np.array([y.min(), np.median(y)]), np.array([np.median(y), y.max()])

    def starts(self, prob: RefitRecords, theta0: Array) -> list[tuple[Array, dict[str, float]]]:
        """The gradient vanishes beyond the simulated range: the three best of a few clipping
        levels at quantiles of the nominal simulation."""
        y_nom = prob.simulate(theta0)
        levels = [(qlo, qhi) for qlo in (0.0, 0.05, 0.15) for qhi in (0.0, 0.05, 0.15) if qlo or qhi]
        scored = []
        for qlo, qhi in levels:
            e0 = np.array([np.quantile(y_nom, qlo), np.quantile(y_nom, 1 - qhi)]) + np.array([1e-9, -1e-9])
            scored.append((prob.cost(theta0, self.core({"lo": e0[0], "hi": e0[1]})), tuple(e0)))
        scored.sort()
        return [(np.array(e0), {}) for _, e0 in scored[:3]]

    def directions(self, screen: ScreenContext) -> list[Array]:
        """The nominal output clipped at its 10 % and at its 90 % quantile."""
        y = screen.y_sim
        return [
            screen.change(self.core({"lo": float(np.quantile(y, 0.1)), "hi": np.inf})),
            screen.change(self.core({"lo": -np.inf, "hi": float(np.quantile(y, 0.9))})),
        ]
