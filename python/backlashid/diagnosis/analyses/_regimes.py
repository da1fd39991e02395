"""Where in the model's own operating regimes the error lies.

The nominal model, simulated on the record, says at every sample what the backlash is doing
(eq 12-13: f1 = moving along the left branch L, f2 = along the right branch R, neither = holding
in the dead band) and how its input x moves. ``REGIMES`` (they overlap):

- ``dead_band``       holding: f1 = f2 = 0;
- ``left_branch``     f1 = 1 (y = L(x), x decreasing);
- ``right_branch``    f2 = 1 (y = R(x), x increasing);
- ``after_reversal``  the first k samples after the direction of x changes;
- ``re_engagement``   the first k samples of each run of motion after a hold;
- ``near_standstill`` |x(t) - x(t-1)| below ``STANDSTILL`` times its RMS over the record.

k adapts to how x moves: a quarter of the median length of a run of x in one direction, between
1 and ``MAX_WINDOW`` samples (with a white input, x reverses every 2-3 samples and k = 1; with a
slow one k is larger), so "just after" stays a minority of the samples.

For each regime: its share of the samples and its share of the residual energy sum e^2; their
ratio is the regime's mean squared error over the record's. Significance (does the regime's MSE
differ from that of the other samples?) by a circular-shift test: the regime's indicator is
shifted against e^2 by every lag at least ``MIN_SHIFT_FRACTION`` of the record away, which keeps
the autocorrelation of both and breaks only their alignment; the p-value is the share of shifts
with a difference at least as large (two-sided). Holm's method corrects over the regimes.
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
from ...models import CascadeModel, CascadeState, SandwichModel, SandwichState
from .._statistics import holm, snap_constant

__all__ = ["REGIMES", "RegimeShare", "RegimeShares", "regime_masks", "regime_shares"]

REGIMES = ("dead_band", "left_branch", "right_branch", "after_reversal", "re_engagement", "near_standstill")
MAX_WINDOW = 10  # at most this many samples count as "just after" a reversal or re-engagement
STANDSTILL = 0.1  # near standstill: |dx| < STANDSTILL * RMS(dx)
MIN_SHIFT_FRACTION = 0.05  # circular shifts closer than this share of the record are not used
MIN_SHIFT = 10
MIN_SAMPLES = 100
ALPHA = 0.05



def _description(name: str, k: int) -> str:
    return {
        "dead_band": "holding in the dead band (f1 = f2 = 0)",
        "left_branch": "moving on the left branch L (f1 = 1)",
        "right_branch": "moving on the right branch R (f2 = 1)",
        "after_reversal": f"first {k} sample(s) after x reverses",
        "re_engagement": f"first {k} sample(s) moving after a hold",
        "near_standstill": f"|x(t) - x(t-1)| < {STANDSTILL:g} RMS",
    }[name]


@dataclass(frozen=True)
class RegimeShare:
    """Error share of one regime.

    Attributes
    ----------
    name : str
        The regime, one of ``REGIMES``.
    description : str
        The regime in words.
    n_samples : int
        Evaluated samples in the regime.
    sample_share : float
        Share of the evaluated samples.
    energy_share : float
        Share of sum e^2.
    mse : float
        Mean e^2 in the regime.
    mse_rest : float
        Mean e^2 elsewhere.
    p_value : float
        Circular-shift test, two-sided, this regime alone.
    p_adjusted : float
        Holm-adjusted over the regimes.
    alpha : float
        The significance level of the test.
    z : float
        MSE difference in standard deviations of its shift distribution.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> from backlashid.diagnosis.analyses import regime_shares
    >>> rng = np.random.default_rng(0)
    >>> share = regime_shares(bid.example1(), rng.uniform(-1.5, 1.5, 800), rng.standard_normal(800))["dead_band"]
    >>> share.name, share.significant
    ('dead_band', False)
    """

    name: str
    description: str
    n_samples: int
    sample_share: float  # share of the evaluated samples
    energy_share: float  # share of sum e^2
    mse: float  # mean e^2 in the regime
    mse_rest: float  # mean e^2 elsewhere
    p_value: float  # circular-shift test, two-sided, this regime alone
    p_adjusted: float  # Holm-adjusted over the regimes
    alpha: float
    z: float = float("nan")  # MSE difference in standard deviations of its shift distribution


    @property
    def ratio(self) -> float:
        """Energy share over sample share: the regime's MSE relative to the record's."""
        return self.energy_share / self.sample_share if self.sample_share > 0 else float("nan")

    @property
    def significant(self) -> bool:
        """The regime's error differs significantly from elsewhere (Holm)."""
        return bool(self.p_adjusted < self.alpha)

    @property
    def excess(self) -> bool:
        """Significantly more error here than elsewhere."""
        return self.significant and self.mse > self.mse_rest

    @fill(to_dict=TO_DICT)
    def to_dict(self) -> dict[str, Any]:
        """
        {to_dict}
        """
        return {
            "name": self.name,
            "description": self.description,
            "n_samples": int(self.n_samples),
            "sample_share": float(self.sample_share),
            "energy_share": float(self.energy_share),
            "ratio": json_float(self.ratio),
            "mse": float(self.mse),
            "mse_rest": json_float(self.mse_rest),
            "p_value": json_float(self.p_value),
            "p_adjusted": json_float(self.p_adjusted),
            "z": json_float(self.z),
            "significant": self.significant,
            "excess": self.excess,
        }


@dataclass(frozen=True, eq=False)
class RegimeShares:
    """Error shares by regime of the nominal model's residual, with the per-sample regimes
    (``masks``: name -> bool array over the whole record, False in the warm-up).

    Attributes
    ----------
    regimes : tuple of RegimeShare
        One per regime of ``REGIMES``.
    n : int
        Evaluated samples (after the warm-up).
    warmup : int
        Samples left out at the start.
    total_mse : float
        Mean squared residual over the evaluated samples.
    window : int
        k, the samples counted as just after a reversal or a re-engagement.
    masks : dict of str to ndarray
        Per-sample regime masks (bool) over the whole record, False in the warm-up.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> from backlashid.diagnosis.analyses import regime_shares
    >>> rng = np.random.default_rng(0)
    >>> shares = regime_shares(bid.example1(), rng.uniform(-1.5, 1.5, 1000), rng.standard_normal(1000))
    >>> shares.n, shares.significant
    (1000, False)
    """

    regimes: tuple[RegimeShare, ...]
    n: int  # evaluated samples (after the warm-up)
    warmup: int
    total_mse: float
    window: int  # k: samples counted as just after a reversal or a re-engagement
    masks: dict[str, NDArray[np.bool_]] = field(repr=False)

    def __getitem__(self, name: str) -> RegimeShare:
        for r in self.regimes:
            if r.name == name:
                return r
        raise KeyError(f"no regime {name!r}; regimes: {', '.join(REGIMES)}")

    @property
    def significant(self) -> bool:
        """True when the error is concentrated in some regime."""
        return any(r.excess for r in self.regimes)

    @property
    def concentrated(self) -> tuple[str, ...]:
        """Regimes with significantly more error than elsewhere, strongest (largest z) first."""
        hits = sorted((r for r in self.regimes if r.excess), key=lambda r: -r.z)
        return tuple(r.name for r in hits)

    def labels(self) -> NDArray[np.int8]:
        """One state label per sample for colouring: 0 dead band, 1 left branch, 2 right
        branch, -1 warm-up."""
        lab = np.full(self.masks["dead_band"].size, -1, dtype=np.int8)
        lab[self.masks["dead_band"]] = 0
        lab[self.masks["left_branch"]] = 1
        lab[self.masks["right_branch"]] = 2
        return lab

    @fill(to_dict=TO_DICT)
    def to_dict(self) -> dict[str, Any]:
        """
        {to_dict}
        """
        return {
            "n": self.n,
            "warmup": self.warmup,
            "total_mse": float(self.total_mse),
            "window": self.window,
            "significant": self.significant,
            "concentrated": list(self.concentrated),
            "regimes": {r.name: r.to_dict() for r in self.regimes},
        }

    def __str__(self) -> str:
        lines = [f"Error by regime ({self.n} samples after a warm-up of {self.warmup}; Holm-corrected):"]
        for r in self.regimes:
            mark = " <- excess" if r.excess else (" (less)" if r.significant else "")
            lines.append(
                f"  {r.name:16s} samples {100 * r.sample_share:5.1f} %  error {100 * r.energy_share:5.1f} %  "
                f"x{r.ratio:5.2f}  z {r.z:5.1f}  p = {r.p_value:.2g}{mark}"
            )
        return "\n".join(lines)


# --------------------------------------------------------------------------- regimes
def _run_position(active: NDArray[np.bool_], start: NDArray[np.bool_]) -> NDArray[np.int64]:
    """Samples since the last ``start`` (0 at a start), counting only while ``active`` stays
    on; large where no start has happened in the current active run."""
    n = active.size
    idx = np.arange(n)
    big = np.iinfo(np.int64).max // 4
    last_start = np.where(start & active, idx, -1)
    last_start = np.maximum.accumulate(last_start)
    # a start only counts when the run has not been interrupted since
    last_off = np.maximum.accumulate(np.where(~active, idx, -1))
    valid = (last_start >= 0) & (last_start > last_off)
    return np.where(valid, idx - last_start, big)


def _window(direction: NDArray[np.int64]) -> int:
    """k: a quarter of the median run length of x in one direction, in [1, MAX_WINDOW]."""
    d = direction[direction != 0]
    if d.size < 2:
        return 1
    starts = np.flatnonzero(np.r_[True, d[1:] != d[:-1], True])
    runs = np.diff(starts)
    return int(np.clip(np.median(runs) // 4, 1, MAX_WINDOW))


def regime_masks(
    x: NDArray[np.float64], f1: NDArray[np.bool_], f2: NDArray[np.bool_], x_before: float, evaluated: NDArray[np.bool_]
) -> tuple[dict[str, NDArray[np.bool_]], int]:
    """The regime indicators of ``REGIMES`` from the internal signals of a simulation.

    Parameters
    ----------
    x : ndarray
        The linear block's output x(t).
    f1 : ndarray of bool
        The left-branch switching signal (eq 25, exclusive rule).
    f2 : ndarray of bool
        The right-branch switching signal (eq 26).
    x_before : float
        x(0), the sample before the record.
    evaluated : ndarray of bool
        The samples evaluated (False in the warm-up).

    Returns
    -------
    masks : dict of str to ndarray
        A bool mask per regime name.
    window : int
        k, the samples counted as just after a reversal or a re-engagement.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> from backlashid.diagnosis.analyses import REGIMES, regime_masks
    >>> sim = bid.example1().simulate(np.sin(0.05 * np.arange(400)), internals=True)
    >>> masks, k = regime_masks(sim.x, sim.f1, sim.f2, 0.0, np.ones(400, dtype=bool))
    >>> set(masks) == set(REGIMES)
    True
    """
    f1 = np.asarray(f1, dtype=bool)
    f2 = np.asarray(f2, dtype=bool) & ~f1  # exclusive case order of eq (1)
    moving = f1 | f2
    dx = np.diff(x, prepend=x_before)
    rms_dx = float(np.sqrt(np.mean(dx[evaluated] ** 2))) if evaluated.any() else 0.0
    tol = STANDSTILL * rms_dx
    direction = np.where(dx > tol, 1, np.where(dx < -tol, -1, 0))
    k = _window(direction[evaluated])
    n = x.size
    idx = np.arange(n)
    # last nonzero direction strictly before t
    last_idx = np.maximum.accumulate(np.where(direction != 0, idx, -1))
    prev_idx = np.r_[-1, last_idx[:-1]]
    prev_dir = np.where(prev_idx >= 0, direction[np.maximum(prev_idx, 0)], 0)
    reversal = (direction != 0) & (prev_dir != 0) & (direction != prev_dir)
    since_rev = _run_position(np.ones(n, dtype=bool), reversal)
    moving_before = np.r_[moving[0], moving[:-1]]  # before the record: no hold known
    engage = moving & ~moving_before
    since_engage = _run_position(moving, engage)
    masks = {
        "dead_band": ~moving,
        "left_branch": f1,
        "right_branch": f2,
        "after_reversal": since_rev < k,
        "re_engagement": since_engage < k,
        "near_standstill": np.abs(dx) < tol,
    }
    return {name: m & evaluated for name, m in masks.items()}, k


def _shift_test(mask: NDArray[np.bool_], e2: NDArray[np.float64]) -> tuple[float, float, float, float]:
    """(mse in, mse out, two-sided circular-shift p-value, z) of e2 over the mask; z is the
    observed MSE difference in standard deviations of its shift distribution (it still
    orders regimes whose p-values all sit at the resolution 1 / (shifts + 1))."""
    n = e2.size
    n_in = int(mask.sum())
    total = float(e2.sum())
    if n_in == 0 or n_in == n:
        inside = float(e2[mask].mean()) if n_in else float("nan")
        return inside, float("nan") if n_in == n else float(e2.mean()), float("nan"), float("nan")
    m = mask.astype(np.float64)
    # c[s] = sum_t m(t) e2(t + s) for every circular shift s, by FFT
    c = np.fft.irfft(np.conj(np.fft.rfft(m)) * np.fft.rfft(e2), n)
    diff = c / n_in - (total - c) / (n - n_in)
    observed = diff[0]
    min_shift = max(MIN_SHIFT, int(MIN_SHIFT_FRACTION * n))
    shifts = np.arange(min_shift, n - min_shift + 1)
    if shifts.size < 20:
        return float(c[0] / n_in), float((total - c[0]) / (n - n_in)), float("nan"), float("nan")
    null = diff[shifts]
    tol = 1e-12 * max(abs(observed), total / n)
    p = (1.0 + np.count_nonzero(np.abs(null) >= abs(observed) - tol)) / (1.0 + shifts.size)
    spread = float(null.std())
    z = (observed - float(null.mean())) / spread if spread > 0 else float("nan")
    return float(c[0] / n_in), float((total - c[0]) / (n - n_in)), float(p), float(z)


def _simulate(model: Any, u: NDArray[np.float64], initial_state: Any) -> tuple[Any, float]:
    state: CascadeState | SandwichState
    if isinstance(model, CascadeModel):
        if initial_state is not None and not isinstance(initial_state, CascadeState):
            raise DataError(f"initial_state must be a CascadeState for a CascadeModel, got {type(initial_state).__name__}")
        state = initial_state or model.rest_state()
    elif isinstance(model, SandwichModel):
        if initial_state is not None and not isinstance(initial_state, SandwichState):
            raise DataError(f"initial_state must be a SandwichState for a SandwichModel, got {type(initial_state).__name__}")
        state = initial_state or model.rest_state()
    else:
        raise DataError(
            f"model must be the nominal CascadeModel or SandwichModel, got {type(model).__name__}: "
            "regimes are those of the nominal model's backlash"
        )
    sim = model.simulate(u, initial_state=state, internals=True)
    x_before = state.x_past[0] if state.x_past else 0.0
    return sim, float(x_before)


def regime_shares(
    model: Any, u: ArrayLike, residual: ArrayLike, *, warmup: int = 0, initial_state: Any = None
) -> RegimeShares:
    """Error shares of a residual by the backlash regimes the nominal model passes through.

    The model is driven by u from ``initial_state``; a zero residual counts as spread over the
    regimes as the samples are (no regime stands out).

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The nominal model.
    u : array_like
        Input of the record, 1-D, finite.
    residual : array_like
        Measured minus the nominal model's simulation, the whole record.
    warmup : int, default 0
        Samples at the start left out.
    initial_state : CascadeState or SandwichState, optional
        The model's state before the record (default: rest).

    Returns
    -------
    RegimeShares
        The share of the error and of the samples per regime, with a circular-shift test.

    Raises
    ------
    DataError
        If the model is not a cascade or sandwich, the signals are unusable or of different
        lengths, the warm-up is out of range, or the state is of the wrong kind.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> from backlashid.diagnosis.analyses import regime_shares
    >>> m = bid.example1()
    >>> rng = np.random.default_rng(0)
    >>> u = rng.uniform(-1.5, 1.5, 2000)
    >>> shares = regime_shares(m, u, 0.05 * rng.standard_normal(2000), warmup=20)
    >>> [r.name for r in shares.regimes][:3]
    ['dead_band', 'left_branch', 'right_branch']
    """
    if not isinstance(warmup, (int, np.integer)) or isinstance(warmup, bool) or warmup < 0:
        raise DataError(f"warmup = {warmup!r}: give a non-negative integer number of samples")
    warmup = int(warmup)
    e = check_signals(("residual", residual), min_length=warmup + MIN_SAMPLES, what=f"a warm-up of {warmup} plus the regime test")[0]
    u_arr = check_signals(("u", u), min_length=warmup + MIN_SAMPLES, what=f"a warm-up of {warmup} plus the regime test")[0]
    check_same_length(("residual", e), ("u", u_arr))
    sim, x_before = _simulate(model, u_arr, initial_state)
    evaluated = np.arange(e.size) >= warmup
    masks, k = regime_masks(np.asarray(sim.x), np.asarray(sim.f1), np.asarray(sim.f2), x_before, evaluated)
    e2 = snap_constant(e[warmup:] ** 2)
    total = float(e2.sum())
    n = e2.size
    raw = []
    for name in REGIMES:
        m = masks[name][warmup:]
        mse_in, mse_out, p, z = _shift_test(m, e2)
        raw.append((name, int(m.sum()), float(e2[m].sum()), mse_in, mse_out, p, z))
    adjusted = holm([r[5] for r in raw])
    shares = tuple(
        RegimeShare(
            name=name,
            description=_description(name, k),
            n_samples=count,
            sample_share=count / n,
            energy_share=energy / total if total > 0 else count / n,  # no error: spread as the samples
            mse=mse_in if count else 0.0,
            mse_rest=mse_out,
            p_value=p,
            p_adjusted=float(p_adj),
            alpha=ALPHA,
            z=z,
        )
        for (name, count, energy, mse_in, mse_out, p, z), p_adj in zip(raw, adjusted)
    )
    return RegimeShares(regimes=shares, n=n, warmup=warmup, total_mse=total / n, window=k, masks=masks)
