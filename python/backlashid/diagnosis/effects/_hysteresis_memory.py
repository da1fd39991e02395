"""hysteresis_memory: extra plays on x, y + sum_k w_k play_{r_k}(x)."""

from __future__ import annotations

import numpy as np

from ..._numerics import lstsq, r_factor
from ._base import Array, Augmentation, Effect, Fitted, RefitRecords, ScreenContext

N_PLAYS = 2  # extra plays


AUGMENTATION = Augmentation(
    "hysteresis_memory",
    tuple(n for k in range(1, N_PLAYS + 1) for n in (f"r_{k}", f"w_{k}")),
    tuple(v for _ in range(N_PLAYS) for v in (0.1, 0.0)),
    "y + sum_k w_k play_{r_k}(x)",
)


class HysteresisMemory(Effect, rank=9, augmentation=AUGMENTATION):
    """Weighted play operators on the internal signal x added to the output."""

    @staticmethod
    def _x(prob: RefitRecords, theta0: Array) -> Array:
        """x of the nominal linear block on every record from its start."""
        return prob.linear_output(theta0)

    def refit(self, prob: RefitRecords, theta0: Array) -> Fitted:
        """The weights enter linearly at fixed half-widths: pick the pairs of half-widths whose
        plays explain most of the nominal residual, then refit everything from the best three."""
        x = self._x(prob, theta0)
        sx = float(np.std(x)) + 1e-12
        y_nom = prob.simulate(theta0)
        r0 = prob.y - y_nom
        radii = sx * np.geomspace(0.01, 2.0, 10)
        # play_r(x) of weight 1 on top of the nominal output, by the augmented simulator
        plays = [prob.scored(prob.simulate(theta0, self.core({"r_1": r, "w_1": 1.0, "r_2": 0.0, "w_2": 0.0})) - y_nom) for r in radii]
        # every pair's least squares on the R factor of [plays | residual] (same solution and
        # residual norm as on the record's columns, 11 rows instead of N)
        r = r_factor(np.column_stack([*plays, prob.scored(r0)]))
        target = r[:, -1]
        pairs = []
        for i in range(len(radii)):
            for j in range(i + 1, len(radii)):
                a = r[:, [i, j]]
                w = lstsq(a, target)
                rss = float(np.sum((target - a @ w) ** 2))
                pairs.append((rss, (float(radii[i]), float(w[0]), float(radii[j]), float(w[1]))))
        pairs.sort()
        lb = np.array([0.0, -np.inf] * N_PLAYS)
        ub = np.array([5 * sx, np.inf] * N_PLAYS)
        return self._multi_start(prob, theta0, [(np.array(e0), {}) for _, e0 in pairs[:3]], lb, ub)

    def directions(self, screen: ScreenContext) -> list[Array]:
        """One play of weight 1 at half-widths 0.05 and 0.3 std(u)."""
        su = float(np.std(screen.u)) + 1e-12
        return [screen.change((("hysteresis_memory", (r * su, 1.0)),)) for r in (0.05, 0.3)]
