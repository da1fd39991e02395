"""width_drift: the dead-band widths c_L, c_R change linearly in time."""

from __future__ import annotations

import numpy as np

from ._base import TIME_SCALE, Array, Augmentation, Effect, RefitRecords, ScreenContext

BOUND = 50.0  # largest drift rate per time unit
STEP = 1e-4  # finite-difference step of the screening


AUGMENTATION = Augmentation("width_drift", ("dc_L", "dc_R"), (0.0, 0.0), f"c_L, c_R change by dc per {TIME_SCALE:g} samples")


class WidthDrift(Effect, rank=3, augmentation=AUGMENTATION):
    """Dead-band widths drifting linearly in time."""

    def bounds(self, prob: RefitRecords) -> tuple[Array, Array]:
        """Rates within +-BOUND."""
        b = np.full(2, BOUND)
        return -b, b

    def directions(self, screen: ScreenContext) -> list[Array]:
        """Derivatives in dc_L and dc_R, by finite differences."""
        h = STEP
        return [screen.change(self.core({"dc_L": h, "dc_R": 0.0})) / h, screen.change(self.core({"dc_L": 0.0, "dc_R": h})) / h]
