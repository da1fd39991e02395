"""quantization: the output quantised to steps of q."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._base import Array, Augmentation, Effect, Fitted, RefitRecords, ScreenContext

AUGMENTATION = Augmentation("quantization", ("q",), (0.0,), "y quantised to steps of q")

SCORE_ROWS = 64  # steps scored at once (a SCORE_ROWS x N block of phases)
LATTICE_RTOL = 1e-6  # a gap between measured levels is a multiple of q within this fraction of q
LATTICE_MAX_LEVELS = 0.5  # the lattice spans at most this fraction of the samples' count in levels
LATTICE_MIN_OCCUPIED = 0.3  # and its measured values occupy at least this fraction of its levels


@dataclass(frozen=True)
class Lattice:
    """The lattice {offset + k q} the measured values lie on (a quantiser after the noise).

    Attributes
    ----------
    q : float
        The step.
    offset : float
        A point of the lattice (the smallest measured value).
    levels : int
        Levels spanned between the smallest and the largest value.
    occupied : int
        Levels that hold a measured value.
    """

    q: float
    offset: float
    levels: int
    occupied: int


def lattice(y: Array) -> Lattice | None:
    """The lattice {o + k q} on which every value of y lies, or None.

    The step is the smallest gap between the sorted distinct values (refined as the median of
    the gaps within 1 % of it); every gap must be a whole multiple of it within
    ``LATTICE_RTOL`` q (plus the values' rounding). Continuous data fail that at once (each
    gap's fraction is uniform, so all of N gaps pass with probability (2e-6)^N). A lattice finer
    than the data can show is not reported: data stored in single precision or rounded to a
    few decimals lie on one too (of their last digit), but it spans far more levels than there
    are samples (over ``LATTICE_MAX_LEVELS`` N) and the values occupy few of them (under
    ``LATTICE_MIN_OCCUPIED``), while an A/D converter's quantisation that matters is coarse:
    the samples fill most of its levels.
    """
    values = np.unique(y[np.isfinite(y)])
    if values.size < 3:
        return None
    gaps = np.diff(values)
    q = float(gaps.min())
    if not q > 0.0:
        return None
    q = float(np.median(gaps[gaps <= 1.01 * q]))
    span = float(values[-1] - values[0])
    levels = int(round(span / q)) + 1
    if levels > LATTICE_MAX_LEVELS * y.size or values.size < LATTICE_MIN_OCCUPIED * levels:
        return None
    k = np.rint((values - values[0]) / q)
    if np.any(np.diff(k) < 1):
        return None
    # the step of least squares through the levels (the offset held at the smallest value)
    kk = float(k @ k)
    q = float(k @ (values - values[0]) / kk) if kk > 0 else q
    tol = LATTICE_RTOL * q + 8.0 * np.finfo(np.float64).eps * float(np.max(np.abs(values)))
    if np.any(np.abs(values - values[0] - k * q) > tol):
        return None
    return Lattice(q=q, offset=float(values[0]), levels=levels, occupied=int(values.size))


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

    def refit(self, prob: RefitRecords, theta0: Array) -> Fitted:
        """The step of the measured values' lattice, else a search of q at the nominal parameters.

        A quantiser after the noise (an A/D converter) leaves every measured value on a
        lattice {o + k q}: q is then read off the data (:func:`lattice`).

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
        found = lattice(prob.y)
        if found is not None:
            # the measured values lie on a lattice (a quantiser after the noise): its step is
            # read off the data, not searched
            return theta0, {"q": found.q}, prob.output_cost(quantise(y_sim, found.q))
        spread = float(np.std(y_sim)) + 1e-12
        grid = spread * np.geomspace(0.005, 1.0, 3000)
        score = cos_scores(prob.scored(prob.y), grid)
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
