"""Where in frequency the error lies: the residual spectrum against the noise floor, and the
residual-input coherence.

Frequencies are in cycles per sample (0 to 0.5); densities are one-sided (white noise of
standard deviation s has density 2 s^2).

- Bands: octaves down from the Nyquist frequency, [0.25, 0.5], [0.125, 0.25], .., the lowest
  from 0 (at most ``MAX_BANDS`` bands, each with at least ``MIN_BAND_BINS`` periodogram bins).
- Band power: the mean of the periodogram of the whole record over the band's bins. For white
  noise at the floor, its ratio to the floor is chi-square with 2m degrees of freedom over 2m
  (m bins), which gives the p-value that the band exceeds the floor (an F ratio when the floor
  is estimated from the same record). Holm's method corrects over the bands.
- Noise floor: 2 noise_std^2 when ``noise_std`` is given; otherwise estimated from the upper
  half of the band (f >= 0.25) as median(periodogram) / ln 2 (the median of an exponential
  variable is ln 2 times its mean), which assumes the model error lies mostly below f = 0.25.
- Welch spectrum (Hann window, 50 % overlap) for display, and the magnitude-squared coherence
  of residual and input with its threshold: under independence, P(coherence > c) =
  (1 - c)^(K - 1) with K the effective number of independent segment averages.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..._docstrings import TO_DICT, fill
from ..._json import json_float
from ..._validation import check_same_length, check_signals
from ...errors import DataError
from .._statistics import holm, snap_constant

__all__ = ["Band", "FrequencyAnalysis", "frequency_analysis"]

ALPHA = 0.05
MAX_BANDS = 8
MIN_BAND_BINS = 8
MIN_SAMPLES = 128
MAX_SEGMENT = 256  # Welch segment length at most (frequency resolution 1/256)
FLOOR_FROM = 0.25  # the estimated floor uses f >= this


@dataclass(frozen=True)
class Band:
    """One frequency band: residual power against the floor, and coherence with the input.

    Attributes
    ----------
    lo : float
        Lower band edge in cycles per sample.
    hi : float
        Upper band edge in cycles per sample.
    n_bins : int
        Periodogram bins in the band.
    power : float
        Mean residual density over the band.
    ratio : float
        Power / floor.
    energy_share : float
        Share of the residual variance in this band.
    p_value : float
        p-value of the band above the floor, this band alone.
    p_adjusted : float
        Holm over the bands.
    coherence_max : float
        Largest residual-input coherence in the band.
    coherence_p : float
        That the band holds coherence (Bonferroni over its Welch bins).
    coherence_p_adjusted : float
        Holm over the bands.
    alpha : float
        The significance level of the test.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.diagnosis.analyses import frequency_analysis
    >>> rng = np.random.default_rng(0)
    >>> band = frequency_analysis(rng.standard_normal(2000), rng.standard_normal(2000), noise_std=1.0).bands[0]
    >>> band.lo
    0.0
    """

    lo: float
    hi: float
    n_bins: int  # periodogram bins in the band
    power: float  # mean residual density over the band
    ratio: float  # power / floor
    energy_share: float  # share of the residual variance in this band
    p_value: float  # band above the floor, this band alone
    p_adjusted: float  # Holm over the bands
    coherence_max: float  # largest residual-input coherence in the band
    coherence_p: float  # that the band holds coherence (Bonferroni over its Welch bins)
    coherence_p_adjusted: float  # Holm over the bands
    alpha: float

    @property
    def label(self) -> str:
        """The band as 'lo-hi' in cycles per sample."""
        return f"{self.lo:.4g}-{self.hi:.4g}"

    @property
    def above_floor(self) -> bool:
        """The residual lies significantly above the noise floor in this band (Holm)."""
        return bool(self.p_adjusted < self.alpha)

    @property
    def coherent(self) -> bool:
        """The residual is significantly coherent with the input in this band (Holm)."""
        return bool(self.coherence_p_adjusted < self.alpha)

    @property
    def ratio_db(self) -> float:
        """``ratio`` in decibels."""
        return float(10.0 * np.log10(self.ratio)) if self.ratio > 0 else float("-inf")

    @fill(to_dict=TO_DICT)
    def to_dict(self) -> dict[str, Any]:
        """
        {to_dict}
        """
        return {
            "lo": self.lo,
            "hi": self.hi,
            "n_bins": self.n_bins,
            "power": float(self.power),
            "ratio": json_float(self.ratio),
            "ratio_db": json_float(self.ratio_db),
            "energy_share": float(self.energy_share),
            "p_value": float(self.p_value),
            "p_adjusted": float(self.p_adjusted),
            "above_floor": self.above_floor,
            "coherence_max": json_float(self.coherence_max),
            "coherence_p": json_float(self.coherence_p),
            "coherence_p_adjusted": json_float(self.coherence_p_adjusted),
            "coherent": self.coherent,
        }


@dataclass(frozen=True, eq=False)
class FrequencyAnalysis:
    """Residual spectrum by band against the noise floor, and residual-input coherence.

    Attributes
    ----------
    n : int
        Number of evaluated samples.
    noise_std : float
        The noise standard deviation of the floor.
    noise_std_estimated : bool
        Whether it was estimated from the residual.
    floor : float
        One-sided density of the noise floor.
    bands : tuple of Band
        The frequency bands.
    coherence_threshold : float
        Coherence threshold pointwise, level alpha.
    coherence_threshold_global : float
        The same, Bonferroni over all Welch bins.
    effective_segments : float
        Effective number of Welch segments (with overlap).
    alpha : float
        The significance level of the test.
    frequencies : ndarray
        The Welch frequency grid.
    psd : ndarray
        Welch density of the residual.
    coherence : ndarray
        Residual-input coherence on that grid.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.diagnosis.analyses import frequency_analysis
    >>> t = np.arange(4000)
    >>> rng = np.random.default_rng(0)
    >>> fa = frequency_analysis(rng.standard_normal(4000) + 2 * np.sin(0.6 * t), rng.standard_normal(4000), noise_std=1.0)
    >>> fa.significant
    True
    """

    n: int
    noise_std: float
    noise_std_estimated: bool
    floor: float  # one-sided density of the noise floor
    bands: tuple[Band, ...]
    coherence_threshold: float  # pointwise, level alpha
    coherence_threshold_global: float  # Bonferroni over all Welch bins
    effective_segments: float
    alpha: float
    frequencies: NDArray[np.float64] = field(repr=False)  # Welch grid
    psd: NDArray[np.float64] = field(repr=False)  # Welch density of the residual
    coherence: NDArray[np.float64] = field(repr=False)  # residual-input coherence on that grid

    @property
    def exceeding(self) -> tuple[str, ...]:
        """Bands where the residual lies significantly above the floor, strongest first."""
        hits = sorted((b for b in self.bands if b.above_floor), key=lambda b: b.p_value)
        return tuple(b.label for b in hits)

    @property
    def coherent(self) -> tuple[str, ...]:
        """Bands where the residual is significantly coherent with the input."""
        hits = sorted((b for b in self.bands if b.coherent), key=lambda b: b.coherence_p)
        return tuple(b.label for b in hits)

    @property
    def significant(self) -> bool:
        """True when some band lies above the floor or is coherent with the input."""
        return bool(self.exceeding or self.coherent)

    @property
    def excess_ratio(self) -> float:
        """Residual variance over the noise floor's (1 when the residual is the noise)."""
        total = sum(b.power * b.n_bins for b in self.bands)
        bins = sum(b.n_bins for b in self.bands)
        return float(total / bins / self.floor) if bins and self.floor > 0 else float("nan")

    @fill(to_dict=TO_DICT)
    def to_dict(self) -> dict[str, Any]:
        """
        {to_dict}
        """
        return {
            "n": self.n,
            "noise_std": float(self.noise_std),
            "noise_std_estimated": self.noise_std_estimated,
            "floor": float(self.floor),
            "excess_ratio": json_float(self.excess_ratio),
            "alpha": self.alpha,
            "coherence_threshold": float(self.coherence_threshold),
            "coherence_threshold_global": float(self.coherence_threshold_global),
            "effective_segments": float(self.effective_segments),
            "significant": self.significant,
            "exceeding": list(self.exceeding),
            "coherent": list(self.coherent),
            "bands": [b.to_dict() for b in self.bands],
        }

    def __str__(self) -> str:
        src = "estimated" if self.noise_std_estimated else "given"
        lines = [
            f"Residual spectrum by band (cycles/sample; noise std {self.noise_std:.4g} {src}, "
            f"floor {self.floor:.3g}; coherence threshold {self.coherence_threshold_global:.3f}):"
        ]
        for b in self.bands:
            marks = ("above floor" if b.above_floor else "") + (" coherent with u" if b.coherent else "")
            lines.append(
                f"  {b.label:>15s}  x{b.ratio:7.2f}  p = {b.p_value:.2g}  share {100 * b.energy_share:5.1f} %  "
                f"coh max {b.coherence_max:.2f}  {marks}"
            )
        return "\n".join(lines)


def _band_edges(n: int) -> NDArray[np.float64]:
    """Octave edges from 0.5 down, the lowest band from 0, each with >= MIN_BAND_BINS bins."""
    j = int(np.floor(np.log2(n / (2.0 * MIN_BAND_BINS))))
    j = int(np.clip(j, 0, MAX_BANDS - 1))
    return np.r_[0.0, 0.5 / 2.0 ** np.arange(j, -1, -1)]


def _effective_segments(n: int, nseg: int) -> float:
    """Welch's K with Hann 50 % overlap, reduced for the correlation of overlapping segments."""
    step = nseg // 2
    k = 1 + (n - nseg) // step
    from scipy import signal  # imported when first needed: import backlashid stays fast

    w = signal.get_window("hann", nseg)
    denom = float(w @ w) ** 2
    corr = 0.0
    for lag in range(1, k):
        shift = lag * step
        if shift >= nseg:
            break
        rho2 = float(w[shift:] @ w[: nseg - shift]) ** 2 / denom
        corr += (1.0 - lag / k) * rho2
    return float(k / (1.0 + 2.0 * corr))


def _check_noise_std(noise_std: Any) -> None:
    """A given noise standard deviation must be a finite number >= 0."""
    try:
        s = float(noise_std)
    except (TypeError, ValueError):
        raise DataError(f"noise_std = {noise_std!r}: give a positive number or None to estimate it") from None
    if not (np.isfinite(s) and s >= 0.0):
        raise DataError(f"noise_std = {noise_std!r}: give a non-negative finite number, or None to estimate it")


def _noise_floor(
    spectrum: NDArray[np.float64], freqs: NDArray[np.float64], interior: NDArray[np.bool_], noise_std: float | None
) -> tuple[float, int | None]:
    """The floor's density and, when it is estimated, the bins' worth of information it is
    estimated from (None: given)."""
    if noise_std is not None:
        return 2.0 * float(noise_std) ** 2, None
    upper = spectrum[interior & (freqs >= FLOOR_FROM)]
    m_floor = max(1, int(0.5 * upper.size))  # the median uses about half the information
    return float(np.median(upper) / np.log(2.0)), m_floor


def _above_floor(power: float, m: int, floor: float, m_floor: int | None) -> tuple[float, float]:
    """A band's power over the floor and the p-value that it lies above it (chi-square with 2m
    degrees of freedom; F against the floor's 2 ``m_floor`` when the floor is estimated)."""
    from scipy import stats

    if floor > 0.0:
        ratio = power / floor
    else:  # noise-free: any power is above the floor
        ratio = float("inf") if power > 0.0 else 1.0
    if m == 0:
        p = float("nan")
    elif floor == 0.0:
        p = 0.0 if power > 0.0 else 1.0
    elif m_floor is not None:
        p = float(stats.f.sf(ratio, 2 * m, 2 * m_floor))
    else:
        p = float(stats.chi2.sf(2 * m * ratio, 2 * m))
    return ratio, p


def _band_coherence(coh: NDArray[np.float64], k_eff: float) -> tuple[float, float]:
    """The largest coherence over a band's Welch bins and the p-value that the band holds
    coherence (Bonferroni over its bins); NaN without bins or with an undefined coherence."""
    if not (coh.size and np.isfinite(coh).all()):
        return float("nan"), float("nan")
    c_max = float(coh.max())
    p_bin = (1.0 - min(c_max, 1.0)) ** max(k_eff - 1.0, 1.0)
    return c_max, float(min(1.0, p_bin * coh.size))


def frequency_analysis(residual: ArrayLike, u: ArrayLike, *, noise_std: float | None = None) -> FrequencyAnalysis:
    """The residual's spectrum by band against the noise floor, and its coherence with the input.

    Parameters
    ----------
    residual : array_like
        The model's output error after the warm-up (1-D, finite).
    u : array_like
        The input over those samples.
    noise_std : float, optional
        The noise standard deviation if known (else estimated from the residual); 0
        (noise-free data) puts every band with any power above the floor.

    Returns
    -------
    FrequencyAnalysis
        Bands above the floor and coherent with the input.

    Raises
    ------
    DataError
        If a signal is unusable or too short, the lengths differ, or ``noise_std`` < 0.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.diagnosis.analyses import frequency_analysis
    >>> rng = np.random.default_rng(0)
    >>> fa = frequency_analysis(rng.standard_normal(4000), rng.standard_normal(4000), noise_std=1.0)
    >>> fa.significant
    False
    """
    e = snap_constant(check_signals(("residual", residual), min_length=MIN_SAMPLES, what="a spectrum by band")[0], centre=True)
    u_arr = check_signals(("u", u), min_length=MIN_SAMPLES, what="a spectrum by band")[0]
    check_same_length(("residual", e), ("u", u_arr))
    n = e.size
    if noise_std is not None:
        _check_noise_std(noise_std)

    spectrum = np.abs(np.fft.rfft(e)) ** 2 * (2.0 / n)  # one-sided periodogram density
    freqs = np.arange(spectrum.size) / n
    interior = (freqs > 0.0) & (freqs < 0.5)  # DC removed, Nyquist not doubled
    floor, m_floor = _noise_floor(spectrum, freqs, interior, noise_std)
    estimated = m_floor is not None
    total = float(spectrum[interior].sum())

    nseg = int(min(MAX_SEGMENT, 2 ** int(np.floor(np.log2(n / 8)))))
    nseg = max(nseg, 16)
    from scipy import signal

    f_w, psd = signal.welch(e, nperseg=nseg)
    with np.errstate(invalid="ignore", divide="ignore"):  # a zero residual has no coherence (NaN)
        _, coh = signal.coherence(e, u_arr - u_arr.mean(), nperseg=nseg)
    k_eff = _effective_segments(n, nseg)
    coh_bins = (f_w > 0.0) & (f_w < 0.5)
    n_coh = int(coh_bins.sum())
    threshold = 1.0 - ALPHA ** (1.0 / max(k_eff - 1.0, 1.0))
    threshold_global = 1.0 - (ALPHA / n_coh) ** (1.0 / max(k_eff - 1.0, 1.0))

    edges = _band_edges(n)
    raw = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        in_band = interior & (freqs >= lo) & (freqs < hi)
        m = int(in_band.sum())
        power = float(spectrum[in_band].mean()) if m else float("nan")
        ratio, p = _above_floor(power, m, floor, m_floor)
        share = float(spectrum[in_band].sum() / total) if total > 0 else 0.0
        c_max, c_p = _band_coherence(coh[coh_bins & (f_w >= lo) & (f_w < hi)], k_eff)
        raw.append((float(lo), float(hi), m, power, ratio, share, p, c_max, c_p))
    p_adj = holm([r[6] for r in raw])
    c_adj = holm([r[8] for r in raw])
    bands = tuple(
        Band(
            lo=lo,
            hi=hi,
            n_bins=m,
            power=power,
            ratio=ratio,
            energy_share=share,
            p_value=p,
            p_adjusted=float(pa),
            coherence_max=c_max,
            coherence_p=c_p,
            coherence_p_adjusted=float(ca),
            alpha=ALPHA,
        )
        for (lo, hi, m, power, ratio, share, p, c_max, c_p), pa, ca in zip(raw, p_adj, c_adj)
    )
    return FrequencyAnalysis(
        n=n,
        noise_std=float(np.sqrt(floor / 2.0)),
        noise_std_estimated=estimated,
        floor=floor,
        bands=bands,
        coherence_threshold=float(threshold),
        coherence_threshold_global=float(threshold_global),
        effective_segments=k_eff,
        alpha=ALPHA,
        frequencies=f_w,
        psd=psd,
        coherence=coh,
    )
