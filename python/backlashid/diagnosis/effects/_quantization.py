"""quantization: the output quantised to steps of q."""

from __future__ import annotations

import numpy as np

from ._base import Array, Augmentation, Effect, Fitted, Problem, ScreenContext

AUGMENTATION = Augmentation("quantization", ("q",), (0.0,), "y quantised to steps of q")

SCORE_ROWS = 64  # steps scored at once (a SCORE_ROWS x N block of phases)


def quantise(y: Array, q: float) -> Array:
    """q round(y / q), halves away from zero: the Rust quantiser (``f64::round``) on a whole signal."""
    z = y / q
    r = np.rint(z)
    t = np.trunc(z)
    half = np.abs(z - t) == 0.5
    if np.any(half):
        r[half] = t[half] + np.sign(z[half])
    return q * r


def cos_scores(y: Array, steps: Array) -> Array:
    """mean cos(2 pi y / q) for every step q, in blocks of SCORE_ROWS steps. The cosines are
    taken in single precision (vectorised; NumPy's double cosine is ~20 times slower here): the
    phase error is below 1e-4 rad for abs(y) / q < 300, far under the scores' sampling noise."""
    two_pi_y = (2.0 * np.pi * y).astype(np.float32)
    inv = (1.0 / steps).astype(np.float32)
    out = np.empty(steps.size)
    for i in range(0, steps.size, SCORE_ROWS):
        out[i : i + SCORE_ROWS] = np.cos(np.multiply.outer(inv[i : i + SCORE_ROWS], two_pi_y)).mean(axis=1, dtype=np.float64)
    return out


class Quantization(Effect, rank=8, augmentation=AUGMENTATION):
    """Output quantised to steps of q."""

    def refit(self, prob: Problem, theta0: Array) -> Fitted:
        """A search of q at the nominal parameters.

        The error is piecewise constant in q with a minimum far narrower than any practical grid
        of q (q off by 1 % moves level k by k %). The measured output itself shows the steps: its
        values cluster at multiples of q, so mean cos(2 pi y / q) peaks at the step (the noise
        after the quantiser only damps the peak). Candidates from that fine scan and from a
        coarse scan of the error; the one of lowest error, then a fine scan of the error near it.

        The quantiser acts on the output alone, so at the nominal parameters every candidate's
        output is the nominal simulation quantised (as the Rust quantiser does): one simulation
        serves the whole search.
        """
        y_sim = prob.simulate(theta0)
        spread = float(np.std(y_sim)) + 1e-12
        grid = spread * np.geomspace(0.005, 1.0, 3000)
        score = cos_scores(prob.y[prob.warmup :], grid)
        peaks = grid[np.argsort(score)[-3:]]
        coarse = spread * np.geomspace(0.005, 1.0, 60)
        candidates = list(peaks) + [coarse[int(np.argmin([prob.output_cost(quantise(y_sim, q)) for q in coarse]))]]
        best_q, best_cost = 0.0, prob.output_cost(y_sim)
        for q0 in candidates:
            for q in q0 * np.linspace(0.99, 1.01, 21):
                c = prob.output_cost(quantise(y_sim, q))
                if c < best_cost:
                    best_q, best_cost = float(q), c
        return theta0, {"q": best_q}, best_cost

    def directions(self, screen: ScreenContext) -> list[Array]:
        """Steps of 0.1 and 0.3 std(y)."""
        sy = float(np.std(screen.y_sim)) + 1e-12
        return [screen.change(self.core({"q": q * sy})) for q in (0.1, 0.3)]
