"""state_saturation: the linear block's output x clipped to [lo, hi] inside its recursion (eq 16).

A tank that overflows, a motor against its travel stop: the clipped level is what the block
remembers, so it leaves the stop as soon as its drive turns (``saturation`` clips the drive
input u instead; ``sensor_saturation`` the measured output).
"""

from __future__ import annotations

import numpy as np

from ...identify import Structure
from ...models import LinearBlock
from ._base import Array, Augmentation, Effect, RefitRecords, ScreenContext

AUGMENTATION = Augmentation("state_saturation", ("lo", "hi"), (-np.inf, np.inf), "x clipped to [lo, hi] inside the recursion")


def nominal_x(structure: Structure, theta: Array, u: Array) -> Array:
    """x of the nominal chain's input block (eq 16) for u, from rest."""
    est = structure.unpack(theta)
    return LinearBlock(est.a, est.b).simulate(u)


class StateSaturation(Effect, rank=20, augmentation=AUGMENTATION):
    """The linear block's output x held within [lo, hi] (a stop of the state itself)."""

    def bounds(self, prob: RefitRecords) -> tuple[Array, Array]:
        """lo below the output's median, hi above it, within its range widened by the range
        (x is the backlash's input: its range is the output's plus the dead band)."""
        y = prob.y
        lo, mid, hi = float(y.min()), float(np.median(y)), float(y.max())
        spread = hi - lo
        return np.array([lo - spread, mid]), np.array([mid, hi + spread])

    def starts(self, prob: RefitRecords, theta0: Array) -> list[tuple[Array, dict[str, float]]]:
        """The gradient vanishes beyond x's range: the three best of a few clipping levels at
        quantiles of the nominal x."""
        x = nominal_x(prob.structure, theta0, prob.u)
        levels = [(qlo, qhi) for qlo in (0.0, 0.05, 0.15) for qhi in (0.0, 0.05, 0.15) if qlo or qhi]
        scored = []
        for qlo, qhi in levels:
            e0 = np.array([np.quantile(x, qlo), np.quantile(x, 1 - qhi)]) + np.array([1e-9, -1e-9])
            scored.append((prob.cost(theta0, self.core({"lo": e0[0], "hi": e0[1]})), tuple(e0)))
        scored.sort()
        return [(np.array(e0), {}) for _, e0 in scored[:3]]

    def directions(self, screen: ScreenContext) -> list[Array]:
        """x held at its 10 % and at its 90 % quantile."""
        x = nominal_x(screen.structure, screen.theta, screen.u)
        return [
            screen.change(self.core({"lo": float(np.quantile(x, 0.1)), "hi": np.inf})),
            screen.change(self.core({"lo": -np.inf, "hi": float(np.quantile(x, 0.9))})),
        ]
