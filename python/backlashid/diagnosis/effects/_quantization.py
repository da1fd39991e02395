"""quantization: the output quantised to steps of q."""

from __future__ import annotations

import numpy as np

from ._base import Array, Augmentation, Effect, Fitted, Problem, ScreenContext

AUGMENTATION = Augmentation("quantization", ("q",), (0.0,), "y quantised to steps of q")


class Quantization(Effect, rank=8, augmentation=AUGMENTATION):
    """Output quantised to steps of q."""

    def refit(self, prob: Problem, theta0: Array) -> Fitted:
        """A search of q at the nominal parameters.

        The error is piecewise constant in q with a minimum far narrower than any practical grid
        of q (q off by 1 % moves level k by k %). The measured output itself shows the steps: its
        values cluster at multiples of q, so mean cos(2 pi y / q) peaks at the step (the noise
        after the quantiser only damps the peak). Candidates from that fine scan and from a
        coarse scan of the error; the one of lowest error, then a fine scan of the error near it.
        """
        y_sim = prob.simulate(theta0)
        spread = float(np.std(y_sim)) + 1e-12
        y = prob.y[prob.warmup :]
        grid = spread * np.geomspace(0.005, 1.0, 3000)
        score = np.array([np.mean(np.cos(2.0 * np.pi * y / q)) for q in grid])
        peaks = grid[np.argsort(score)[-3:]]
        coarse = spread * np.geomspace(0.005, 1.0, 60)
        candidates = list(peaks) + [coarse[int(np.argmin([prob.cost(theta0, self.core({"q": q})) for q in coarse]))]]
        best_q, best_cost = 0.0, prob.cost(theta0, ())
        for q0 in candidates:
            for q in q0 * np.linspace(0.99, 1.01, 21):
                c = prob.cost(theta0, self.core({"q": q}))
                if c < best_cost:
                    best_q, best_cost = float(q), c
        return theta0, {"q": best_q}, best_cost

    def directions(self, screen: ScreenContext) -> list[Array]:
        """Steps of 0.1 and 0.3 std(y)."""
        sy = float(np.std(screen.y_sim)) + 1e-12
        return [screen.change(self.core({"q": q * sy})) for q in (0.1, 0.3)]
