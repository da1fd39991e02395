"""dead_time: an extra input delay of d samples, u(t - d)."""

from __future__ import annotations

import numpy as np

from ._base import MAX_ITER, Array, Augmentation, Effect, Fitted, RefitRecords, ScreenContext

MAX_DELAY = 6  # dead times searched: 1..MAX_DELAY extra samples


AUGMENTATION = Augmentation("dead_time", ("d",), (0,), "extra input delay of d samples: u(t - d)")


class DeadTime(Effect, rank=0, augmentation=AUGMENTATION):
    """Extra input delay of d samples (rest before the record)."""

    def refit(self, prob: RefitRecords, theta0: Array) -> Fitted:
        """d is discrete: a short refit of the nominal parameters at each d, then the best
        one to convergence with the iteration limit of the linear-order refit it competes with
        (the same Levenberg-Marquardt, exact sensitivities)."""
        none = np.zeros(0)
        short = [(self._refit(prob, theta0, none, none, none, {"d": d}, max_iter=5), {"d": d}) for d in range(1, MAX_DELAY + 1)]
        (theta, _, _), fixed = min(short, key=lambda s: s[0][2])
        return self._refit(prob, theta, none, none, none, fixed, max_iter=MAX_ITER)

    def directions(self, screen: ScreenContext) -> list[Array]:
        """One and two samples of delay."""
        return [screen.change(self.core({"d": 1})), screen.change(self.core({"d": 2}))]
