"""A model of the nominal model's error (Ljung's model error modelling).

When no effect of the catalogue explains the gap, the residual e = y - y_sim on validation
records can still be predictable from what the nominal model itself knows. A regression of e on
features of the nominal model's OWN simulated signals (the input u, the linear block's output x,
the free-run output y_sim; never a measured output, so on validation it remains a free-run
simulation) is fitted on the estimation records and scored on the validation records:

    e(t) ~ phi(u, x, y_sim)(t)^T theta,        y_sim + phi^T theta the corrected output.

The features come in groups named in words (``GROUPS``), each a question a control engineer asks
of the error:

- "the input": u(t - k), k = 0..``INPUT_LAGS`` (dynamics or a delay the linear block lacks);
- "the internal position x": x(t - 1), x(t - 2) and piecewise-linear hat functions of x(t)
  (``KNOTS`` knots across the estimation range of x: a function of where the drive is, e.g. cogging);
- "the output": y_sim, y_sim^2, y_sim^3 (a nonlinearity of the output, a stiffness);
- "the velocity": Delta x, Delta y_sim, |Delta x| and first-order low-passes of Delta x and
  Delta y_sim (time constants ``VELOCITY_TAUS``: a state driven by the velocity);
- "the direction of motion": sign(Delta x), sign(Delta y_sim), the held direction of x;
- "time since the last reversal": d exp(-t_r / tau) and exp(-t_r / tau) with t_r the samples
  since x last reversed and d its direction (``REVERSAL_TAUS``: a relaxing memory, creep);
- "time": t / T, (t / T)^2, y_sim t / T, x t / T with t the sample within the record and T the
  mean estimation record length (a drift of an offset or a gain over a record).

The sizes matter little (benches/model_error.py): the shares moved by under 0.01 with 5, 10 or 20
input lags, other time constants or a tail of 15 %; 8, 16 or 32 knots closed 0.82, 0.92, 0.93 of a
cogging gap.

Records are separate runs: lags, filters and t restart at each record's start (never joined end to
end). Features are standardised on the estimation samples after the warm-up; the fit is ridge
least squares through R factors (``_numerics.r_factor``, the tall-skinny QR): the R of [Phi, e] of
the first ``1 - TAIL`` of each estimation record, of their last ``TAIL``, of both stacked, and of the
validation samples. Since R^T R = [Phi, e]^T [Phi, e], every refit (a ridge weight, a group
dropped) is the least squares of [R_S; sqrt(lambda) I] against [z; 0], a problem of about 2 p
rows solved by the core's QR (``_core.lstsq``), and its error on any part is |R [-c; 1]|. The
ridge weight is the one of ``RIDGE_GRID`` with the lowest error on the held-out tails of a fit of
all groups on the heads; every fit (all groups, a group dropped, a group alone) uses it on all
estimation samples.

Scores on validation: the nominal MSE, the corrected MSE, and the closable share
(MSE_nom - MSE_corr) / (MSE_nom - noise floor) clipped to [-10, 1]. A group's relevance is the
share lost when it is dropped (refit on estimation without it, scored on validation); ``alone``
is the share the group closes by itself. Correlated groups can stand in for each other (a
velocity is a filter of the input, the held direction is a slow reversal memory), so drop-one
relevances can all be small while the whole closes much. The groups named are the fewest that
close the share of all groups but less than ``MATTERS`` (of the gap): the best single group if it
does, else the best pair, else those left by backward elimination (drop the group whose loss is
smallest while the share kept stays within ``MATTERS`` of the whole; what is left is ordered by
its loss). Nothing is
named unless the share is at least ``NOTHING`` and the improvement significant (paired test of
the squared validation errors, ``ALPHA``).

The hints are conservative readings (``HINTS``): the velocity or the direction of motion: a state
driven by the velocity (friction, hysteresis); time: a drift, and time with the output a drifting
gain; powers of the output: a nonlinearity of the output or a stiffness; the input's lags:
dynamics or a delay; time since the last reversal: a relaxing memory such as creep; the position
x: a position-dependent term such as cogging.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ... import _core
from ..._docstrings import TO_DICT, fill
from ..._json import json_float
from ..._numerics import r_factor
from ..._validation import as_signal, check_finite, check_real, check_warmup, shown
from ...errors import DataError
from .._statistics import paired_p

__all__ = ["GROUPS", "ModelErrorModel", "NominalSignals", "model_error"]

Array = NDArray[np.float64]

GROUPS = (
    "the input",
    "the internal position x",
    "the output",
    "the velocity",
    "the direction of motion",
    "time since the last reversal",
    "time",
)
HINTS = {  # what is missing when a group predicts the error (conservative wording)
    "the input": "dynamics or a delay between the input and the backlash that the linear block lacks",
    "the internal position x": "a term that depends on the position (cogging, a position-dependent load)",
    "the output": "a nonlinearity of the output (a stiffness or gain that changes with the output level)",
    "the velocity": "a state driven by the velocity (friction, hysteresis)",
    "the direction of motion": "a state driven by the velocity (friction, hysteresis)",
    "time since the last reversal": "a memory that relaxes after each reversal (creep)",
    "time": "a drift over the record (an offset or a gain that changes with time, e.g. warming)",
}
DRIFTING_GAIN = "a gain that drifts over the record (the output's scale changes with time, e.g. warming)"
INPUT_LAGS = 10  # u(t - k), k = 0..INPUT_LAGS
KNOTS = 16  # hat functions of x
OUTPUT_POWERS = 3
VELOCITY_TAUS = (3.0, 10.0, 30.0)  # samples: low-passes of the velocities
REVERSAL_TAUS = (4.0, 16.0, 64.0, 256.0)  # samples: decays after a reversal
RIDGE_GRID = (1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0)  # per sample, standardised features (> 0: full rank)
TAIL = 0.25  # share of each estimation record (after the warm-up) held out to choose the ridge
CLIP = (-10.0, 1.0)
NOTHING = 0.1  # a share below this: nothing predictable is missing
ALPHA = 0.01  # level of the test that the validation error improved
CLOSE_ENOUGH = 0.5  # a share at least this: the model-error model explains the gap
MATTERS = 0.05  # the groups named close the share of all groups but less than this
MIN_ROWS_PER_COLUMN = 5  # estimation samples after the warm-up per feature


@dataclass(frozen=True, eq=False)
class NominalSignals:
    """The nominal model's own simulated signals over one record.

    Attributes
    ----------
    u : ndarray
        The input.
    x : ndarray
        The linear block's output (the backlash input), simulated.
    y_sim : ndarray
        The nominal model's free-run output.
    residual : ndarray or None
        Measured y - y_sim; None when only predicting.

    Examples
    --------
    >>> import backlashid as bid
    >>> from backlashid.diagnosis.analyses import NominalSignals
    >>> model, data = bid.example1(), bid.example_data(bid.example1(), 500, snr=None, seed=0)
    >>> s = NominalSignals(data.u, model.linear.simulate(data.u), model.simulate(data.u))
    >>> s.residual is None
    True
    """

    u: Array = field(repr=False)
    x: Array = field(repr=False)
    y_sim: Array = field(repr=False)
    residual: Array | None = field(default=None, repr=False)


@dataclass(frozen=True, eq=False)
class _Basis:
    """What the features need beyond the record: the time scale, the knots of x, and the
    standardisation of the estimation samples."""

    time_scale: float
    knots: Array
    y_scale: float
    mean: Array
    scale: Array


def _lag(s: Array, k: int) -> Array:
    """s(t - k), 0 before the record's start."""
    out = np.zeros_like(s)
    out[k:] = s[: max(s.size - k, 0)]
    return out


def _diff(s: Array) -> Array:
    return np.diff(s, prepend=s[:1])  # 0 at the record's start


def _low_pass(s: Array, tau: float) -> Array:
    from scipy.signal import lfilter  # imported when first needed: import backlashid stays fast

    a = float(np.exp(-1.0 / tau))
    return np.asarray(lfilter([1.0 - a], [1.0, -a], s), dtype=np.float64)


def _held_direction(dx: Array) -> tuple[Array, Array]:
    """(d, t_r): the direction of the last motion of x (+-1, 0 before any) and the samples since x
    last reversed (or since the record's start). Both by cumulative maxima of indices."""
    idx = np.arange(dx.size)
    moving = dx != 0.0
    last_move = np.maximum.accumulate(np.where(moving, idx, -1))
    d = np.where(last_move >= 0, np.sign(dx[np.maximum(last_move, 0)]), 0.0)
    reversal = np.r_[False, (d[1:] != d[:-1]) & (d[:-1] != 0.0)]
    last_rev = np.maximum.accumulate(np.where(reversal, idx, 0))
    return d, (idx - last_rev).astype(np.float64)


def _hats(x: Array, knots: Array) -> Array:
    """Piecewise-linear hat functions of x on equally spaced knots (x clamped to their range),
    the first left out: the hats sum to one, the intercept is already a column."""
    step = knots[1] - knots[0]
    xc = np.clip(x, knots[0], knots[-1])
    return np.maximum(0.0, 1.0 - np.abs(xc[:, None] - knots[None, 1:]) / step)


def _raw_features(s: NominalSignals, time_scale: float, knots: Array, y_scale: float) -> tuple[Array, list[str]]:
    """The feature columns of one record (before standardisation) and their group names."""
    u, x, y = s.u, s.x, s.y_sim / y_scale
    dx, dy = _diff(x), _diff(y)
    d, t_r = _held_direction(dx)
    tau = np.arange(u.size) / time_scale
    groups: list[tuple[str, list[Array]]] = [
        ("the input", [_lag(u, k) for k in range(INPUT_LAGS + 1)]),
        ("the internal position x", [_lag(x, 1), _lag(x, 2), *_hats(x, knots).T]),
        ("the output", [y**k for k in range(1, OUTPUT_POWERS + 1)]),
        ("the velocity", [dx, dy, np.abs(dx)] + [_low_pass(v, t) for v in (dx, dy) for t in VELOCITY_TAUS]),
        ("the direction of motion", [np.sign(dx), np.sign(dy), d]),
        ("time since the last reversal", [f for t in REVERSAL_TAUS for f in (d * np.exp(-t_r / t), np.exp(-t_r / t))]),
        ("time", [tau, tau**2, y * tau, x * tau]),
    ]
    cols = [c for _, cs in groups for c in cs]
    names = [g for g, cs in groups for _ in cs]
    return np.column_stack(cols), names


def _features(records: Sequence[NominalSignals], basis: _Basis, warmup: int) -> Array:
    """Standardised features of every record after its warm-up, records stacked (each computed
    on its own), with the intercept as the first column."""
    blocks = [_raw_features(s, basis.time_scale, basis.knots, basis.y_scale)[0][warmup:] for s in records]
    phi = (np.vstack(blocks) - basis.mean) / basis.scale
    return np.column_stack([np.ones(phi.shape[0]), phi])


def _column_groups(basis: _Basis) -> tuple[str, ...]:
    probe = NominalSignals(np.zeros(3), np.zeros(3), np.zeros(3))
    return ("intercept", *_raw_features(probe, basis.time_scale, basis.knots, basis.y_scale)[1])


def _ridge(r: Array, cols: Array, lam: float) -> Array:
    """Ridge solution on the columns ``cols`` (``cols[0]`` the intercept, unpenalised) from the R
    factor of [Phi, e]: min |e - Phi_S c|^2 + lam |c without the intercept|^2, i.e. the least
    squares of [R_S; sqrt(lam) D] c = [z; 0] (R^T R = [Phi, e]^T [Phi, e]), by the core's QR."""
    pen = np.sqrt(lam) * np.eye(cols.size)[1:]
    a = np.vstack([r[:, cols], pen])
    b = np.r_[r[:, -1], np.zeros(cols.size - 1)]
    return _core.lstsq(a, b, [f"feature {c}" for c in cols])[0]


def _sse(r: Array, cols: Array, coef: Array) -> float:
    """|e - Phi_S c|^2 from the R factor of [Phi, e]: |R [-c_full; 1]|^2."""
    v = np.zeros(r.shape[1])
    v[cols] = -coef
    v[-1] = 1.0
    return float(np.sum((r @ v) ** 2))


@dataclass(frozen=True)
class _Factors:
    """R factors of [Phi, e] of the estimation samples (all, heads, tails) and of the validation
    samples, with their sample counts; the penalty is scaled by the fit's sample count."""

    est: Array
    head: Array
    tail: Array
    val: Array
    n_est: int
    n_head: int
    n_val: int

    def ridge(self) -> float:
        """The ridge weight per sample of the whole model: the lowest error on the tails of a fit
        on the heads."""
        every = np.arange(self.est.shape[1] - 1)
        sse = [_sse(self.tail, every, _ridge(self.head, every, lam * self.n_head)) for lam in RIDGE_GRID]
        return RIDGE_GRID[int(np.argmin(sse))]  # the first (least penalised) of equals

    def fit(self, cols: Array, lam: float) -> Array:
        """Coefficients on the columns ``cols`` fitted on all estimation samples."""
        return _ridge(self.est, cols, lam * self.n_est)

    def validation_mse(self, cols: Array, coef: Array) -> float:
        return _sse(self.val, cols, coef) / self.n_val


def _r(phi: Array, e: Array) -> Array:
    r = r_factor(np.column_stack([phi, e]))
    if r.shape[0] < r.shape[1]:  # fewer samples than columns: pad (the factor of the same Gram)
        r = np.vstack([r, np.zeros((r.shape[1] - r.shape[0], r.shape[1]))])
    return r


@dataclass(frozen=True, eq=False)
class ModelErrorModel:
    """A linear-in-parameters model of the nominal model's error, fitted on estimation records
    and scored on validation records (see the module docstring).

    Attributes
    ----------
    nominal_mse : float
        Validation MSE of the nominal model (after the warm-up, all validation records).
    corrected_mse : float
        Validation MSE of the nominal model plus the model-error model.
    noise_floor : float
        The noise floor the gap is measured to (0 when none was given).
    floor_given : bool
        Whether the caller gave the noise floor.
    closable_share : float
        (nominal_mse - corrected_mse) / (nominal_mse - noise_floor), clipped to [-10, 1]; NaN
        when the nominal MSE is at or below the floor (no gap).
    raw_share : float
        The same before clipping.
    p_value : float
        One-sided p-value of "the corrected validation error is smaller" (paired squared errors,
        Newey-West standard error); nothing is named missing unless it is below ``ALPHA``.
    relevance : dict of str to float
        Per group: the share lost when the group is dropped (refit, scored on validation).
    alone : dict of str to float
        Per group: the share the group closes by itself.
    groups : tuple of str
        The groups that matter, most relevant first (empty when nothing is missing).
    ridge : float
        The ridge weight per sample chosen on the held-out tails.
    warmup : int
        Samples left out at the start of every record.
    n_estimation : int
        Estimation samples after the warm-ups.
    n_validation : int
        Validation samples after the warm-ups.
    columns : tuple of str
        The group of each coefficient ("intercept" first).
    coefficients : ndarray
        The coefficients on the standardised features.
    basis : object
        What the features of a new record need (the time scale T, the knots of x, the
        standardisation of the estimation samples); used by :meth:`predict`.

    Examples
    --------
    >>> import numpy as np
    >>> import backlashid as bid
    >>> from backlashid.diagnosis.analyses import model_error
    >>> model, rng = bid.example1(), np.random.default_rng(0)
    >>> def record(n):
    ...     u = rng.uniform(-1.0, 1.0, n)
    ...     x, y = model.linear.simulate(u), model.simulate(u)
    ...     drift = 0.3 * np.arange(n) / n * y  # a gain drifting over the record
    ...     return {"u": u, "x": x, "y_sim": y, "residual": drift + 0.01 * rng.standard_normal(n)}
    >>> mem = model_error([record(3000)], [record(3000)], warmup=20, noise_floor=1e-4)
    >>> round(mem.closable_share, 1), mem.groups[0]
    (1.0, 'time')
    """

    nominal_mse: float
    corrected_mse: float
    noise_floor: float
    floor_given: bool
    closable_share: float
    raw_share: float
    p_value: float
    relevance: dict[str, float]
    alone: dict[str, float]
    groups: tuple[str, ...]
    ridge: float
    warmup: int
    n_estimation: int
    n_validation: int
    columns: tuple[str, ...] = field(repr=False)
    coefficients: Array = field(repr=False)
    basis: _Basis = field(repr=False)

    @property
    def clipped(self) -> bool:
        """Whether the share was clipped to [-10, 1]."""
        return bool(np.isfinite(self.raw_share) and self.raw_share != self.closable_share)

    @property
    def hints(self) -> tuple[str, ...]:
        """What the groups that matter say is missing, in their order, without repeats (time with
        the output: a drifting gain, ``DRIFTING_GAIN``)."""
        hints = [HINTS[g] for g in self.groups]
        if "time" in self.groups and "the output" in self.groups:  # y_sim t / T needs y_sim: a gain
            first = min(self.groups.index("time"), self.groups.index("the output"))
            hints[first] = DRIFTING_GAIN
            hints = [h for h in hints if h not in (HINTS["time"], HINTS["the output"])]
        return tuple(dict.fromkeys(hints))

    @property
    def summary(self) -> str:
        """One sentence in words: how much of the gap the model-error model closes, in which
        signals, and what that says is missing."""
        notes = []
        if not self.floor_given:
            notes.append("no noise floor given: the gap is the nominal MSE")
        if self.clipped:
            notes.append(f"share clipped to [{CLIP[0]:g}, {CLIP[1]:g}] from {self.raw_share:.3g}")
        tail = f" ({'; '.join(notes)})" if notes else ""
        if not np.isfinite(self.closable_share):
            return f"the nominal model is at the noise floor on validation: there is no gap to close{tail}"
        pct = f"{100.0 * self.closable_share:.0f} %"
        if not self.groups:
            weak = "" if self.closable_share < NOTHING else f", not significantly (p = {self.p_value:.2g})"
            return (
                f"a model of the residual in the nominal model's signals closes {pct} of the gap{weak}: nothing it can "
                f"predict is missing (the rest is noise or a disturbance independent of the input){tail}"
            )
        where = _words(self.groups)
        what = _words(self.hints)
        if self.closable_share >= CLOSE_ENOUGH:
            verb = "is" if len(self.hints) == 1 else "are"
            return f"a model of the residual in {where} closes {pct} of the gap: {what} {verb} missing{tail}"
        return (
            f"a model of the residual in {where} closes only {pct} of the gap: part of the error suggests {what}; "
            f"the rest is not predictable from the nominal model's signals{tail}"
        )

    def predict(self, record: Mapping[str, ArrayLike] | NominalSignals) -> Array:
        """The predicted model error over a record (add it to ``y_sim`` for the corrected output).

        Parameters
        ----------
        record : mapping or NominalSignals
            ``u``, ``x`` and ``y_sim`` of the nominal model over the record (``residual`` is not
            needed), 1-D of one length.

        Returns
        -------
        ndarray
            The predicted error at every sample (the first ``warmup`` samples included: there
            the lags and filters have not settled).

        Raises
        ------
        DataError
            If a signal is missing, not 1-D, of another length or not finite.

        Examples
        --------
        >>> import numpy as np
        >>> import backlashid as bid
        >>> from backlashid.diagnosis.analyses import model_error
        >>> model, rng = bid.example1(), np.random.default_rng(1)
        >>> def record(n):
        ...     u = rng.uniform(-1.0, 1.0, n)
        ...     x, y = model.linear.simulate(u), model.simulate(u)
        ...     return {"u": u, "x": x, "y_sim": y, "residual": 0.2 * y**2 + 0.01 * rng.standard_normal(n)}
        >>> new = record(2000)
        >>> mem = model_error([record(3000)], [record(3000)], warmup=20)
        >>> corrected = new["y_sim"] + mem.predict(new)
        >>> bool(np.mean((new["residual"] - mem.predict(new))[20:] ** 2) < 2e-4)
        True
        """
        s = _record(record, "record", need_residual=False)
        return _features([s], self.basis, 0) @ self.coefficients

    @fill(to_dict=TO_DICT)
    def to_dict(self) -> dict[str, Any]:
        """
        {to_dict}
        """
        return {
            "nominal_mse": json_float(self.nominal_mse),
            "corrected_mse": json_float(self.corrected_mse),
            "noise_floor": json_float(self.noise_floor),
            "floor_given": self.floor_given,
            "closable_share": json_float(self.closable_share),
            "raw_share": json_float(self.raw_share),
            "p_value": json_float(self.p_value),
            "clipped": self.clipped,
            "relevance": {g: json_float(v) for g, v in self.relevance.items()},
            "alone": {g: json_float(v) for g, v in self.alone.items()},
            "groups": list(self.groups),
            "hints": list(self.hints),
            "ridge": float(self.ridge),
            "warmup": self.warmup,
            "n_estimation": self.n_estimation,
            "n_validation": self.n_validation,
            "summary": self.summary,
        }

    def __str__(self) -> str:
        lines = [
            f"Model-error model ({self.n_estimation} estimation, {self.n_validation} validation samples, ridge {self.ridge:g}):",
            f"  validation MSE {self.nominal_mse:.4g} nominal -> {self.corrected_mse:.4g} corrected "
            f"(noise floor {self.noise_floor:.4g}); share of the gap closed {self.closable_share:.3f}",
        ]
        lines += [f"  {g:<30} lost when dropped {self.relevance[g]:+.3f}, alone {self.alone[g]:+.3f}" for g in GROUPS]
        lines.append(f"  {self.summary}")
        return "\n".join(lines)


def _words(items: Sequence[str]) -> str:
    items = list(items)
    return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]


def _record(record: Any, name: str, *, need_residual: bool) -> NominalSignals:
    """A checked NominalSignals of a mapping or NominalSignals: 1-D finite float signals of one length."""
    keys = ("u", "x", "y_sim", "residual") if need_residual else ("u", "x", "y_sim")
    if isinstance(record, NominalSignals):
        raw = {k: getattr(record, k) for k in keys}
    elif isinstance(record, Mapping):
        raw = dict(record)
    else:
        raise DataError(f"{name} is a {type(record).__name__}: give a mapping with keys {', '.join(keys)} (or NominalSignals)")
    missing = [k for k in keys if raw.get(k) is None]
    if missing:
        raise DataError(f"{name} has no {', '.join(repr(k) for k in missing)}: give the nominal model's {', '.join(keys)}")
    arrays = {}
    for k in keys:
        arr = as_signal(raw[k], f"{name}[{k!r}]")
        if arr.ndim != 1:
            raise DataError(f"{name}[{k!r}] has shape {arr.shape}: pass a 1-D signal (one record)")
        check_finite(arr, f"{name}[{k!r}]")
        if arr.size != arrays.get("u", arr).size:
            raise DataError(f"{name}['u'] has {arrays['u'].size} samples but {name}[{k!r}] has {arr.size}: give one record (same length)")
        arrays[k] = arr
    if arrays["u"].size < 3:
        raise DataError(f"{name} has {arrays['u'].size} samples: give a record of at least 3")
    return NominalSignals(arrays["u"], arrays["x"], arrays["y_sim"], arrays.get("residual"))


def _records(records: Any, name: str, warmup: Any) -> tuple[list[NominalSignals], int]:
    if isinstance(records, (Mapping, NominalSignals)) or not isinstance(records, Sequence) or isinstance(records, (str, bytes)):
        raise DataError(f"{name} must be a list of records (mappings or NominalSignals), got {shown(records)}: wrap one record in a list")
    if len(records) == 0:
        raise DataError(f"{name} is an empty list: give at least one record")
    out = [_record(r, f"{name}[{i}]", need_residual=True) for i, r in enumerate(records)]
    w = check_warmup(warmup, min(s.u.size for s in out))
    return out, w


def model_error(
    estimation: Sequence[Mapping[str, ArrayLike] | NominalSignals],
    validation: Sequence[Mapping[str, ArrayLike] | NominalSignals],
    *,
    warmup: int,
    noise_floor: float | None = None,
) -> ModelErrorModel:
    """Fit a model of the nominal model's error on estimation records and score it on validation.

    Parameters
    ----------
    estimation : list of mapping or NominalSignals
        Records to fit on: each ``u``, ``x``, ``y_sim`` (the nominal model's simulated signals)
        and ``residual`` (measured y - y_sim), 1-D of one length. Records are separate runs.
    validation : list of mapping or NominalSignals
        Records to score on, alike (the nominal model simulated free-run over each).
    warmup : int
        Samples at the start of every record left out of the fit and the scores.
    noise_floor : float, optional
        The noise variance the gap is measured to (e.g. the diagnosis' floor); 0 when None.

    Returns
    -------
    ModelErrorModel
        The fitted model, its validation scores, the relevance of each feature group, and
        a ``summary`` sentence.

    Raises
    ------
    DataError
        If a list is empty or not a list, a record misses a signal, signals differ in length,
        are not 1-D or not finite, the warm-up does not fit every record, the noise floor is
        negative or not finite, or there are fewer than ``MIN_ROWS_PER_COLUMN`` estimation
        samples per feature.

    Examples
    --------
    >>> import numpy as np
    >>> import backlashid as bid
    >>> from backlashid.diagnosis.analyses import model_error
    >>> model, rng = bid.example1(), np.random.default_rng(0)
    >>> def record(n):
    ...     u = rng.uniform(-1.0, 1.0, n)
    ...     x, y = model.linear.simulate(u), model.simulate(u)
    ...     return {"u": u, "x": x, "y_sim": y, "residual": 0.05 * rng.standard_normal(n)}
    >>> mem = model_error([record(3000)], [record(3000)], warmup=20)
    >>> abs(mem.closable_share) < 0.02, mem.groups
    (True, ())
    >>> print(mem.summary)  # doctest: +ELLIPSIS
    a model of the residual in the nominal model's signals closes ... nothing it can predict is missing ...
    """
    est, warmup = _records(estimation, "estimation", warmup)
    val, _ = _records(validation, "validation", warmup)
    floor_given = noise_floor is not None
    floor = 0.0 if noise_floor is None else check_real(noise_floor, "noise_floor", low=0.0)

    x_all = np.concatenate([s.x[warmup:] for s in est])
    lo, hi = np.quantile(x_all, [0.005, 0.995])
    if hi <= lo:
        lo, hi = lo - 0.5, lo + 0.5
    y_scale = float(np.std(np.concatenate([s.y_sim[warmup:] for s in est]))) or 1.0
    time_scale = float(np.mean([s.u.size for s in est]))
    raw = [_raw_features(s, time_scale, np.linspace(lo, hi, KNOTS), y_scale)[0][warmup:] for s in est]
    stacked = np.vstack(raw)
    if stacked.shape[0] < MIN_ROWS_PER_COLUMN * (stacked.shape[1] + 1):
        raise DataError(
            f"estimation has {stacked.shape[0]} samples after the warm-up for {stacked.shape[1] + 1} features: "
            f"give at least {MIN_ROWS_PER_COLUMN * (stacked.shape[1] + 1)}"
        )
    scale = stacked.std(axis=0)
    basis = _Basis(time_scale, np.linspace(lo, hi, KNOTS), y_scale, stacked.mean(axis=0), np.where(scale > 0, scale, 1.0))

    e_est = [s.residual[warmup:] for s in est]  # type: ignore[index]
    phi_est = [(b - basis.mean) / basis.scale for b in raw]
    phi_est = [np.column_stack([np.ones(b.shape[0]), b]) for b in phi_est]
    cut = [int(round((1.0 - TAIL) * b.shape[0])) for b in phi_est]
    head = _r(np.vstack([b[:c] for b, c in zip(phi_est, cut)]), np.concatenate([e[:c] for e, c in zip(e_est, cut)]))
    tail = _r(np.vstack([b[c:] for b, c in zip(phi_est, cut)]), np.concatenate([e[c:] for e, c in zip(e_est, cut)]))
    e_val = np.concatenate([s.residual[warmup:] for s in val])  # type: ignore[index]
    phi_val = _features(val, basis, warmup)
    factors = _Factors(
        est=r_factor(np.vstack([head, tail])),  # [Phi, e] of all = of heads and tails stacked
        head=head,
        tail=tail,
        val=_r(phi_val, e_val),
        n_est=sum(b.shape[0] for b in phi_est),
        n_head=sum(cut),
        n_val=e_val.size,
    )

    columns = _column_groups(basis)
    col_group = np.array(columns)
    every = np.arange(len(columns))
    nominal_mse = float(np.mean(e_val**2))
    gap = nominal_mse - floor

    lam = factors.ridge()

    def share(cols: Array) -> tuple[float, Array, float]:
        coef = factors.fit(cols, lam)
        mse = factors.validation_mse(cols, coef)
        return ((nominal_mse - mse) / gap if gap > 0 else float("nan")), coef, mse

    raw_share, coef, corrected_mse = share(every)

    def columns_of(kept: Sequence[str]) -> Array:
        return every[np.isin(col_group, ["intercept", *kept])]

    relevance = {g: raw_share - share(columns_of([h for h in GROUPS if h != g]))[0] for g in GROUPS}
    alone = {g: share(columns_of([g]))[0] for g in GROUPS}
    p_value = paired_p(e_val, e_val - phi_val @ coef)
    groups: tuple[str, ...] = ()
    if np.isfinite(raw_share) and raw_share >= NOTHING and p_value < ALPHA:
        groups = _groups_that_matter(lambda kept: share(columns_of(kept))[0], raw_share, relevance, alone)
    return ModelErrorModel(
        nominal_mse=nominal_mse,
        corrected_mse=corrected_mse,
        noise_floor=floor,
        floor_given=floor_given,
        closable_share=float(np.clip(raw_share, *CLIP)) if np.isfinite(raw_share) else float("nan"),
        raw_share=float(raw_share),
        p_value=p_value,
        relevance=relevance,
        alone=alone,
        groups=groups,
        ridge=lam,
        warmup=warmup,
        n_estimation=factors.n_est,
        n_validation=factors.n_val,
        columns=columns,
        coefficients=_full(coef, every, len(columns)),
        basis=basis,
    )


def _groups_that_matter(share: Any, full: float, relevance: dict[str, float], alone: dict[str, float]) -> tuple[str, ...]:
    """The fewest groups whose share is within ``MATTERS`` of the share of all: the best single
    group, else the best pair (ordered by the share each closes alone), else by backward
    elimination."""
    best = max(GROUPS, key=lambda g: alone[g])
    if alone[best] > full - MATTERS:
        return (best,)
    pairs = {(g, h): share([g, h]) for i, g in enumerate(GROUPS) for h in GROUPS[i + 1 :]}
    pair = max(pairs, key=lambda k: pairs[k])
    if pairs[pair] > full - MATTERS:
        return tuple(sorted(pair, key=lambda g: -alone[g]))
    return _backward(share, full, relevance)


def _backward(share: Any, full: float, relevance: dict[str, float]) -> tuple[str, ...]:
    """The groups that matter, most relevant first: backward elimination from all groups, each
    step dropping the group whose loss is smallest while the share kept stays within ``MATTERS``
    of the share of all (correlated groups that stand in for each other: one is dropped, the
    other then carries the loss). Ordered by the loss when each is dropped from the groups kept."""
    kept, current, losses = list(GROUPS), full, dict(relevance)
    while len(kept) > 1:
        trial = {g: share([h for h in kept if h != g]) for g in kept}
        cheapest = max(kept, key=lambda g: trial[g])
        if full - trial[cheapest] >= MATTERS:
            losses = {g: current - trial[g] for g in kept}
            break
        kept.remove(cheapest)
        current = trial[cheapest]
    else:
        losses = {kept[0]: current}
    return tuple(sorted(kept, key=lambda g: -losses[g]))


def _full(coef: Array, cols: Array, p: int) -> Array:
    out = np.zeros(p)
    out[cols] = coef
    out.setflags(write=False)
    return out
