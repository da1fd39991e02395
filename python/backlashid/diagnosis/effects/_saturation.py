"""saturation: the drive input clipped to [lo, hi] before the linear block."""

from __future__ import annotations

import numpy as np

from ._base import Array, Augmentation, Effect, Fitted, RefitRecords, ScreenContext

# Shares of each side's samples (below / above the median input) clipped by the starts. The
# finest matter on integrating plants, where a velocity clipped on 0.3 % of the samples already
# moves the position by several noise levels.
SHARES = (0.0, 0.003, 0.01, 0.05, 0.15)
KEEP = 6.63  # chi-square(1) quantile at 0.99: the cost rise that keeps a clipping level (see refit)
BEYOND = 0.01  # how far the input must go beyond a kept level: a share of the level's distance from the median
AUGMENTATION = Augmentation("saturation", ("lo", "hi"), (-np.inf, np.inf), "drive input clipped to [lo, hi]")


def _side_levels(u: Array) -> tuple[list[float], list[float]]:
    """Clipping levels below and above the median that clip each share of that side's samples.

    Quantiles of the whole record would all sit at the median on inputs that rest there most
    of the time (velocity pulses of a position drive, step sequences).
    """
    med = float(np.median(u))
    below, above = u[u < med], u[u > med]
    lo = [float(np.quantile(below, q)) + 1e-9 for q in SHARES] if below.size else [float(u.min())]
    hi = [float(np.quantile(above, 1.0 - q)) - 1e-9 for q in SHARES] if above.size else [float(u.max())]
    return lo, hi


class Saturation(Effect, rank=1, augmentation=AUGMENTATION):
    """Drive input clipped to [lo, hi]."""

    def bounds(self, prob: RefitRecords) -> tuple[Array, Array]:
        """lo below the median input, hi above it."""
        u = prob.u
        return np.array([u.min(), np.median(u)]), np.array([np.median(u), u.max()])

    def starts(self, prob: RefitRecords, theta0: Array) -> list[tuple[Array, dict[str, float]]]:
        """The gradient vanishes at the record's range: both sides clipped by each share, and
        the three best of every pair of levels by the cost at the nominal (which has absorbed
        part of the clipping into its gain, so the cost alone favours the mildest clips)."""
        lo, hi = _side_levels(prob.u)
        pairs = [(a, b) for i, a in enumerate(lo) for j, b in enumerate(hi) if i or j]
        best = sorted(pairs, key=lambda e: prob.cost(theta0, self.core({"lo": e[0], "hi": e[1]})))[:3]
        both = list(zip(lo[1:], hi[1:]))
        return [(np.array(e0), {}) for e0 in dict.fromkeys(both + best)]

    def refit(self, prob: RefitRecords, theta0: Array) -> Fitted:
        """The refit, with a level the estimation records do not establish set to +-inf.

        A level is kept if the input goes beyond it by at least ``BEYOND`` of the level's
        distance from the median (a level at the records' range, or a ramp's plateau clipped by a hair, is
        indistinguishable from a clip anywhere beyond the range, and a validation record that
        goes further is then clipped where the system is not: on an integrating plant that
        drifts without bound) and if removing it raises the cost by more than ``KEEP`` times
        the residual variance (a likelihood-ratio test of that one parameter).
        """
        theta, params, cost = super().refit(prob, theta0)
        u = prob.u
        med = float(np.median(u))
        for name, unbounded, end in (("lo", -np.inf, float(u.min())), ("hi", np.inf, float(u.max()))):
            trial = {**params, name: unbounded}
            without = prob.cost(theta, self.core(trial))
            crossed = abs(end - params[name]) >= BEYOND * abs(params[name] - med)
            if not crossed or without - cost <= KEEP * cost / prob.n_scored:
                params, cost = trial, without
        return theta, params, cost

    def directions(self, screen: ScreenContext) -> list[Array]:
        """Clipping at the 10 % and the 90 % quantile of the input."""
        u = screen.u
        return [
            screen.change(self.core({"lo": float(np.quantile(u, 0.1)), "hi": np.inf})),
            screen.change(self.core({"lo": -np.inf, "hi": float(np.quantile(u, 0.9))})),
        ]
