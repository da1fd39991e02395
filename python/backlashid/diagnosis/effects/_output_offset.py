"""output_offset: a constant and a linearly drifting offset on the output."""

from __future__ import annotations

import numpy as np

from ._base import TIME_SCALE, Array, Augmentation, Effect, RefitRecords, ScreenContext

AUGMENTATION = Augmentation("output_offset", ("o_0", "o_1"), (0.0, 0.0), f"y + o_0 + o_1 t / {TIME_SCALE:g}")


class OutputOffset(Effect, rank=4, augmentation=AUGMENTATION, intercept=False):
    """Output offset o_0 and its drift o_1 per time unit."""

    def bounds(self, prob: RefitRecords) -> tuple[Array, Array]:
        """Within +-1000 (std(y) + 1)."""
        b = np.full(2, 1e3 * (float(np.std(prob.y)) + 1.0))
        return -b, b

    def directions(self, screen: ScreenContext) -> list[Array]:
        """The constant and time."""
        u = screen.u
        t = np.asarray((screen.t0 + np.arange(u.size)) / TIME_SCALE, dtype=np.float64)
        return [np.ones(u.size), t]
