"""dead_time: an extra input delay of d samples, u(t - d)."""

from __future__ import annotations

import numpy as np

from ._base import Array, Augmentation, Effect, Fitted, Problem, ScreenContext

MAX_DELAY = 6  # dead times searched: 1..MAX_DELAY extra samples


AUGMENTATION = Augmentation("dead_time", ("d",), (0,), "extra input delay of d samples: u(t - d)")


class DeadTime(Effect, rank=0, augmentation=AUGMENTATION):
    """Extra input delay of d samples (rest before the record)."""

    def refit(self, prob: Problem, theta0: Array) -> Fitted:
        """d is discrete: refit the nominal parameters at each d, keep the best."""
        none = np.zeros(0)
        return self._multi_start(prob, theta0, [(none, {"d": d}) for d in range(1, MAX_DELAY + 1)], none, none)

    def directions(self, screen: ScreenContext) -> list[Array]:
        """One and two samples of delay."""
        return [screen.change(self.core({"d": 1})), screen.change(self.core({"d": 2}))]
