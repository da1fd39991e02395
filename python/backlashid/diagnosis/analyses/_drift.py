"""Where in time the error lies: trends of the residual's local mean and local RMS, and change
points in its mean and variance.

- Trends: the record is cut into blocks (``block_count``: about 200 samples each, 8 to 40
  blocks). Block means, and the logs of the block RMS about the block mean, are regressed on
  the block's time; the slope's t-test (blocks - 2 degrees of freedom) gives the p-value. Block
  statistics are nearly independent when the residual's correlation time is short against the
  block, so the test allows for autocorrelation within a block.
- Change points: binary segmentation. In a segment, the CUSUM S_k = sum_{t<k} (z_t - mean z)
  peaks at the candidate; T = max |S_k| / (sigma sqrt(n)) follows the supremum of a Brownian
  bridge (Kolmogorov distribution) without a change, with sigma^2 the long-run variance of z
  (Bartlett kernel, Andrews' AR(1) bandwidth, computed around the two-segment fit so that a
  change does not inflate it). Changes in the mean use z = e; changes in variance use
  z = (e - its segment's mean)^2 (Inclan-Tiao with a long-run variance). A change is kept
  when p < ``ALPHA`` / 4; segments shorter than ``min_segment`` are not split.
- The verdict: the four tests (mean trend, RMS trend, first mean change, first variance change)
  share ``ALPHA`` by Bonferroni, so a stationary residual is flagged at most ``ALPHA`` of the time.
Indices are sample numbers of the residual as passed (after any warm-up the caller removed).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..._docstrings import TO_DICT, fill
from ..._json import json_float
from ..._validation import check_signals
from .._statistics import snap_constant

__all__ = ["ChangePoint", "TimeAnalysis", "time_analysis"]

ALPHA = 0.05  # for the four tests together (mean trend, RMS trend, mean and variance changes)
LEVEL = ALPHA / 4  # each of the four (Bonferroni)
MIN_SAMPLES = 100
MAX_CHANGES = 5  # per kind (mean, variance)


@dataclass(frozen=True)
class ChangePoint:
    """A change at sample ``index`` (the first sample of the new segment).

    Attributes
    ----------
    index : int
        The first sample of the new segment.
    kind : str
        "mean" or "variance".
    p_value : float
        The p-value.
    before : float
        Mean (kind "mean") or standard deviation (kind "variance") before.
    after : float
        The same after.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.diagnosis.analyses import time_analysis
    >>> e = np.random.default_rng(0).standard_normal(3000) + np.r_[np.zeros(1000), 2 * np.ones(2000)]
    >>> abs(time_analysis(e).change_points[0].index - 1000) < 20
    True
    """

    index: int
    kind: str  # "mean" or "variance"
    p_value: float
    before: float  # mean (kind "mean") or standard deviation (kind "variance") before
    after: float  # the same after

    @fill(to_dict=TO_DICT)
    def to_dict(self) -> dict[str, Any]:
        """
        {to_dict}
        """
        return {
            "index": int(self.index),
            "kind": self.kind,
            "p_value": float(self.p_value),
            "before": float(self.before),
            "after": float(self.after),
        }

    def __str__(self) -> str:
        what = "mean" if self.kind == "mean" else "std"
        return f"{self.kind} change at sample {self.index}: {what} {self.before:.4g} -> {self.after:.4g} (p = {self.p_value:.2g})"


@dataclass(frozen=True, eq=False)
class TimeAnalysis:
    """Drift of the residual over the record.

    Attributes
    ----------
    n : int
        Number of evaluated samples.
    n_blocks : int
        Number of blocks of the local mean and RMS.
    mean_change : float
        Change of the local mean over the record (linear trend).
    mean_change_se : float
        Its standard error.
    mean_p : float
        p-value of the mean trend.
    rms_ratio : float
        Local RMS at the end of the record over that at the start (trend).
    rms_p : float
        p-value of the RMS trend.
    change_points : tuple of ChangePoint
        Significant changes of the mean or the variance.
    alpha : float
        The significance level of the test.
    block_centers : ndarray
        Sample index of each block's centre.
    block_mean : ndarray
        Mean of each block.
    block_rms : ndarray
        RMS about the block mean.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.diagnosis.analyses import time_analysis
    >>> time_analysis(np.random.default_rng(0).standard_normal(3000)).significant
    False
    """

    n: int
    n_blocks: int
    mean_change: float  # change of the local mean over the record (linear trend)
    mean_change_se: float
    mean_p: float
    rms_ratio: float  # local RMS at the end of the record over that at the start (trend)
    rms_p: float
    change_points: tuple[ChangePoint, ...]
    alpha: float
    block_centers: NDArray[np.float64] = field(repr=False)  # sample index of each block's centre
    block_mean: NDArray[np.float64] = field(repr=False)
    block_rms: NDArray[np.float64] = field(repr=False)  # RMS about the block mean

    @property
    def mean_drift(self) -> bool:
        """The local mean trends significantly (Bonferroni over the four tests)."""
        return bool(self.mean_p < self.alpha / 4)  # Bonferroni over the four tests

    @property
    def rms_drift(self) -> bool:
        """The local RMS trends significantly (Bonferroni over the four tests)."""
        return bool(self.rms_p < self.alpha / 4)

    @property
    def significant(self) -> bool:
        """True when the mean or the RMS drifts or the residual has a change point."""
        return self.mean_drift or self.rms_drift or bool(self.change_points)

    @property
    def p_value(self) -> float:
        """Smallest p-value of the four tests, Bonferroni-corrected (a change point's p-value is
        that of its CUSUM)."""
        ps = [4 * self.mean_p, 4 * self.rms_p] + [4 * c.p_value for c in self.change_points]
        return float(min(1.0, min(ps)))

    @fill(to_dict=TO_DICT)
    def to_dict(self) -> dict[str, Any]:
        """
        {to_dict}
        """
        return {
            "n": self.n,
            "n_blocks": self.n_blocks,
            "mean_change": float(self.mean_change),
            "mean_change_se": float(self.mean_change_se),
            "mean_p": float(self.mean_p),
            "mean_drift": self.mean_drift,
            "rms_ratio": json_float(self.rms_ratio),
            "rms_p": float(self.rms_p),
            "rms_drift": self.rms_drift,
            "change_points": [c.to_dict() for c in self.change_points],
            "significant": self.significant,
            "p_value": self.p_value,
            "alpha": self.alpha,
        }

    def __str__(self) -> str:
        lines = [
            f"Residual over time ({self.n} samples, {self.n_blocks} blocks):",
            f"  mean trend {self.mean_change:+.4g} over the record (se {self.mean_change_se:.2g}), p = {self.mean_p:.2g}",
            f"  RMS trend x{self.rms_ratio:.3f} over the record, p = {self.rms_p:.2g}",
        ]
        lines += [f"  {c}" for c in self.change_points] or ["  no change points"]
        return "\n".join(lines)


def block_count(n: int) -> int:
    return int(np.clip(n // 200, 8, 40))


def _trend(t: NDArray[np.float64], v: NDArray[np.float64]) -> tuple[float, float, float]:
    """Slope of v on t (t spans the record as 0..1), its standard error and two-sided p."""
    b = t.size
    tc = t - t.mean()
    sxx = float(tc @ tc)
    slope = float(tc @ (v - v.mean())) / sxx
    resid = v - v.mean() - slope * tc
    s2 = float(resid @ resid) / (b - 2)
    se = float(np.sqrt(s2 / sxx))
    if se == 0.0:
        return slope, 0.0, 0.0 if slope != 0.0 else 1.0
    from scipy import stats  # imported when first needed: import backlashid stays fast

    p = float(2.0 * stats.t.sf(abs(slope) / se, b - 2))
    return slope, se, p


def long_run_variance(d: NDArray[np.float64]) -> float:
    """Long-run variance of a zero-mean series (Andrews & Monahan): prewhiten by an AR(1),
    Bartlett kernel with Andrews' bandwidth on what is left, recolour by 1 / (1 - rho)^2."""
    n = d.size
    g0 = float(d @ d) / n
    if g0 == 0.0:
        return 0.0
    rho = float(np.clip((d[1:] @ d[:-1]) / float(d[:-1] @ d[:-1]), -0.97, 0.97))
    w = d[1:] - rho * d[:-1]
    m = w.size
    w0 = float(w @ w) / m
    r1 = float(np.clip((w[1:] @ w[:-1]) / m / w0, -0.97, 0.97)) if w0 > 0 else 0.0
    a1 = 4.0 * r1**2 / ((1.0 - r1) ** 2 * (1.0 + r1) ** 2)
    bw = 1.1447 * (a1 * m) ** (1.0 / 3.0)
    lrv = w0
    for j in range(1, int(min(np.floor(bw), m // 4)) + 1):
        lrv += 2.0 * (1.0 - j / (bw + 1.0)) * float(w[j:] @ w[:-j]) / m
    lrv = max(lrv, 1e-3 * w0)  # a strongly negative correlation cannot make it vanish
    return lrv / (1.0 - rho) ** 2


def _cusum_split(z: NDArray[np.float64], min_segment: int, scale: float) -> tuple[int, float]:
    """(candidate split k, p-value) of one segment; variation below 1e-12 ``scale`` (the
    size of the series' values) is rounding, not a change."""
    n = z.size
    zc = z - z.mean()
    s = np.cumsum(zc)[:-1]  # S_k for k = 1..n-1 (split before sample k)
    ks = np.arange(1, n)
    allowed = (ks >= min_segment) & (ks <= n - min_segment)
    if not allowed.any():
        return -1, 1.0
    k = int(ks[allowed][np.argmax(np.abs(s[allowed]))])
    fit = np.r_[np.full(k, z[:k].mean()), np.full(n - k, z[k:].mean())]
    lrv = long_run_variance(z - fit)
    if lrv <= (1e-12 * scale) ** 2:
        return k, 0.0 if np.ptp(fit) > 1e-12 * scale else 1.0
    stat = abs(s[k - 1]) / np.sqrt(lrv * n)
    from scipy import stats

    return k, float(stats.kstwobign.sf(stat))


def _binary_segmentation(z: NDArray[np.float64], min_segment: int, scale: float) -> list[tuple[int, float]]:
    found: list[tuple[int, float]] = []
    stack = [(0, z.size)]
    while stack and len(found) < MAX_CHANGES:
        a, b = stack.pop()
        if b - a < 2 * min_segment:
            continue
        k, p = _cusum_split(z[a:b], min_segment, scale)
        if k > 0 and p < LEVEL:
            found.append((a + k, p))
            stack += [(a, a + k), (a + k, b)]
    return sorted(found)


def _segment_values(e: NDArray[np.float64], cuts: list[int]) -> list[NDArray[np.float64]]:
    edges = [0, *cuts, e.size]
    return [e[a:b] for a, b in zip(edges[:-1], edges[1:])]


def time_analysis(residual: ArrayLike) -> TimeAnalysis:
    """Trends and change points of a residual over its record.

    A constant residual has no drift and no change point.

    Parameters
    ----------
    residual : array_like
        Measured minus simulated output, 1-D, finite: the samples after the warm-up.

    Returns
    -------
    TimeAnalysis
        Trends of the local mean and RMS, and the change points.

    Raises
    ------
    DataError
        If the residual is not 1-D, holds NaN or is too short.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.diagnosis.analyses import time_analysis
    >>> e = np.random.default_rng(0).standard_normal(3000)
    >>> time_analysis(e + np.r_[np.zeros(1500), np.ones(1500)]).change_points[0].kind
    'mean'
    """
    e = snap_constant(check_signals(("residual", residual), min_length=MIN_SAMPLES, what="a drift analysis")[0])
    n = e.size
    min_segment = max(30, n // 50)

    blocks = np.array_split(np.arange(n), block_count(n))
    centers = np.array([b.mean() for b in blocks])
    b_mean = np.array([e[b].mean() for b in blocks])
    b_rms = np.array([e[b].std() for b in blocks])
    t = centers / max(n - 1, 1)
    mean_change, mean_se, mean_p = _trend(t, b_mean)
    if np.all(b_rms > 0):
        log_slope, _, rms_p = _trend(t, np.log(b_rms))
        rms_ratio = float(np.exp(log_slope))
    else:
        rms_ratio, rms_p = float("nan"), 1.0

    changes: list[ChangePoint] = []
    scale = float(np.abs(e).max())
    mean_cuts = _binary_segmentation(e, min_segment, scale)
    for k, p in mean_cuts:
        prev = max([c for c, _ in mean_cuts if c < k], default=0)
        nxt = min([c for c, _ in mean_cuts if c > k], default=n)
        changes.append(ChangePoint(k, "mean", p, float(e[prev:k].mean()), float(e[k:nxt].mean())))
    segments = _segment_values(e, [k for k, _ in mean_cuts])
    dev = np.concatenate([s - s.mean() for s in segments])
    var_cuts = _binary_segmentation(dev**2, min_segment, scale**2)
    for k, p in var_cuts:
        prev = max([c for c, _ in var_cuts if c < k], default=0)
        nxt = min([c for c, _ in var_cuts if c > k], default=n)
        changes.append(
            ChangePoint(k, "variance", p, float(np.sqrt(np.mean(dev[prev:k] ** 2))), float(np.sqrt(np.mean(dev[k:nxt] ** 2))))
        )
    changes.sort(key=lambda c: (c.index, c.kind))
    return TimeAnalysis(
        n=n,
        n_blocks=len(blocks),
        mean_change=mean_change,
        mean_change_se=mean_se,
        mean_p=mean_p,
        rms_ratio=rms_ratio,
        rms_p=rms_p,
        change_points=tuple(changes),
        alpha=ALPHA,
        block_centers=centers,
        block_mean=b_mean,
        block_rms=b_rms,
    )
