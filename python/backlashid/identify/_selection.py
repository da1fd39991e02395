"""Structure selection: the linear orders and the branch degree chosen from the data.

Every candidate structure of a grid is fitted on the head of the record (``fit_cascade`` /
``fit_sandwich``), judged by its free-run simulation error on the held-out tail and by BIC on
the head, and the chosen structure is refitted on the whole record. A candidate whose fit
raises is a row of the table, not the end of the selection.
"""

from __future__ import annotations

import itertools
import math
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docstrings import AXES, fill
from .._json import jsonable
from .._validation import check_finite, check_flag, check_int, check_warmup, one_record, shown
from ..errors import BacklashIdError, DataError, FitWarning, NotConvergedError
from ._checks import branch_problems
from ._fit import FitResult, fit_cascade, fit_sandwich, refit_with_estimate
from ._hammerstein import fit_hammerstein_backlash
from ._nested import lag1_correlation, with_stand_ins
from ._state import model_state, simulate_from_samples
from ._structure import Structure

__all__ = ["StructureSelection", "select_structure"]

KINDS = ("cascade", "sandwich", "hammerstein")
INIT_SAMPLES = 20  # samples that set an estimated start at least (the CLI's too)
VALID_SLACK = 1.25  # a valid backlash is preferred unless an invalid one validates this much better
# A candidate's tail error is not significantly above the best one's (it joins the validation band)
# where the mean difference of their squared errors over TAIL_BLOCKS consecutive blocks of the tail
# is below TAIL_T times its standard error (batch means: Student's t, 0.975 quantile of 4 degrees
# of freedom). A tail of a few events (steps; a position that integrates, whose errors are one slow
# drift) ranks nested candidates by chance: on the position input backlashes of
# benches/structure_classes.py (development seeds) the band of 2 % alone chose sandwiches 3-5 %
# better on the tail, which validated no better than the input backlash.
TAIL_BLOCKS = 5
TAIL_T = 2.776
# and only within TAIL_LIMIT times the best validation RMSE: with five blocks, an excess that sits in
# one of them is insignificant however large (without the limit a sandwich of degree 1 at 23.8
# times the best joined the band of a position input backlash under ramps)
TAIL_LIMIT = 1.25
RULE = (
    "validation band, then BIC: among the candidates that did not raise, keep those whose "
    "validation simulation RMSE is at most (1 + tolerance) times the best one, or at most 1.25 times "
    "it with squared errors on the tail not significantly above the best one's (batch means over 5 "
    "blocks, Student's t at 0.975); choose the lowest "
    "BIC among them (ties: fewer parameters); a candidate whose refit on the whole record raises, does "
    "not converge or simulates the record worse than its fit on the head gives way to the next of the band "
    "by BIC; if none holds, the first one's estimation fit is kept. Valid backlashes first: where the band "
    "holds one whose branches increase and do not cross on the visited range, the invalid ones leave it; "
    "where it holds none, the valid candidates within 1.25 times the best validation RMSE (their own band) "
    "replace it, and an invalid model is chosen only when no valid one comes that close. Nested: a sandwich "
    "of the band gives way to the input backlash it contains (same nr, ns, degree; valid if the sandwich is; "
    "validation RMSE within 1.25 times the best) unless its head fit is significantly better: "
    "n_eff log(s_IB^2 / s_S^2) above chi^2's 0.99 quantile with its extra parameters and start values, "
    "n_eff = n (1 - rho) / (1 + rho) for the sandwich's lag-1 error correlation rho; BIC then chooses"
)
# The table's columns, in the order summary() prints them.
COLUMNS = (
    "kind", "na", "nb", "nr", "ns", "degree", "parameters", "estimation_rmse", "validation_rmse", "bic",
    "raised", "error", "warnings", "seconds", "in_band", "chosen", "refit_error", "valid",
)


@dataclass(frozen=True)
class StructureSelection:
    """The structures :func:`select_structure` tried, how each did, and the one it chose.

    Attributes
    ----------
    structure : Structure
        The chosen orders and degree.
    kind : str
        The chosen kind, 'cascade', 'sandwich' or 'hammerstein' (input backlash).
    fit : FitResult
        The chosen structure's fit: refitted on the whole record (``refit=True``), else the
        fit on the estimation part that was judged.
    rows : list of dict
        One row per candidate, in the order tried, with the keys kind, na, nb, nr, ns (0 for
        a cascade), degree, parameters (the number p of estimated parameters),
        estimation_rmse (free-run simulation RMSE on the estimation part, after the warm-up),
        validation_rmse (free-run simulation RMSE on the held-out tail, the model simulated
        from the record's start), bic (``n log(estimation_rmse**2) + p log(n)``, n the
        estimation samples after the warm-up), raised (bool), error ('ExceptionName:
        message' or None), warnings (the fit's FitWarning messages), seconds, in_band (in the
        validation band, :func:`validation_band`), chosen and refit_error (why its refit on
        the whole record was not kept, or None: tried and kept, or not tried) and valid (both
        branches increase and do not cross on the x range the estimation record visits).
        Values that a raising candidate has not are NaN.
    chosen : int
        Index of the chosen row.
    rule : str
        The decision rule, in words.
    tolerance : float
        Relative width of the validation band.
    estimation_samples : int
        Samples the candidates were fitted on (the head of the record).
    validation_samples : int
        Samples of the held-out tail.
    seconds : float
        Wall-clock time of the whole selection, the refit included.
    refitted : bool
        Whether ``fit`` is the refit on the whole record.
    refit_error : str or None
        Why no refit on the whole record held (``fit`` is then the first candidate's
        estimation fit), or None. A refit that raised, did not converge or simulated the
        record worse than its candidate's fit on the head was not kept: the next candidate of
        the validation band was refitted instead (its row's ``refit_error`` says why).
    note : str
        What preferring valid backlashes did (:func:`preferred_candidates`) and which input
        backlash stood in for the sandwich containing it (``_nested.with_stand_ins``), or "".

    Examples
    --------
    >>> import backlashid as bid
    >>> data = bid.example_data(bid.example1(), 1500, snr=50, seed=0)
    >>> sel = bid.select_structure(data.u, data.noisy, na=2, nb=2, degree=(2, 3))
    >>> sel.structure.degree, len(sel.rows)
    (3, 2)
    """

    structure: Structure
    kind: str
    fit: FitResult
    rows: list[dict[str, Any]]
    chosen: int
    rule: str
    tolerance: float
    estimation_samples: int
    validation_samples: int
    seconds: float
    refitted: bool = True
    refit_error: str | None = field(default=None)
    note: str = ""

    def summary(self) -> str:
        """The table of candidates as text, the chosen one marked, with the decision rule.

        Returns
        -------
        str
            Several lines of text: one per candidate, then the choice.
        """
        sandwich = any(r["kind"] != "cascade" for r in self.rows)
        lines = [
            f"Structure selection: {len(self.rows)} candidates, fitted on {self.estimation_samples} samples, "
            f"validated on the next {self.validation_samples} (free-run simulation RMSE) in {self.seconds:.1f} s",
            f"rule: {self.rule}, tolerance {self.tolerance:g}",
        ]
        head = f"  {'kind':<12}{'na':>3}{'nb':>3}" + (f"{'nr':>3}{'ns':>3}" if sandwich else "")
        head += f"{'deg':>4}{'p':>4}{'est. RMSE':>12}{'val. RMSE':>12}{'BIC':>11}  note"
        lines.append(head)
        for i, r in enumerate(self.rows):
            mark = "*" if i == self.chosen else ("+" if r["in_band"] else " ")
            row = f"{mark} {r['kind']:<12}{r['na']:>3}{r['nb']:>3}" + (f"{r['nr']:>3}{r['ns']:>3}" if sandwich else "")
            row += f"{r['degree']:>4}{r['parameters']:>4}"
            if r["raised"]:
                row += f"{'-':>12}{'-':>12}{'-':>11}  raised {r['error']}"
            else:
                note = f"{len(r['warnings'])} warning(s)" if r["warnings"] else ""
                row += f"{r['estimation_rmse']:>12.5g}{r['validation_rmse']:>12.5g}{r['bic']:>11.1f}  {note}"
            lines.append(row.rstrip())
        r = self.rows[self.chosen]
        passed_over = [i for i, row in enumerate(self.rows) if row.get("refit_error") and i != self.chosen]
        if self.refit_error is not None:
            refit = f"the estimation fit (no refit on the whole record held: {self.refit_error})"
        else:
            refit = "refitted on the whole record" if self.refitted else "the estimation fit (refit=False)"
        lines.append(f"chosen (*): {r['kind']} {self.structure}, {r['parameters']} parameters; {refit}; + = within the validation band")
        if self.note:
            lines.append(f"note: {self.note}")
        for i in passed_over if self.refit_error is None else []:
            row = self.rows[i]
            lines.append(f"passed over: {row['kind']} na={row['na']} nb={row['nb']} degree={row['degree']}: {row['refit_error']}")
        return "\n".join(lines)

    def to_dict(self) -> dict[str, Any]:
        """The selection as a JSON-safe dict.

        Returns
        -------
        dict
            The chosen kind and structure, the decision rule, the table (rows; NaN as None)
            and the chosen fit (``FitResult.to_dict()``).
        """
        s = self.structure
        return {
            "kind": self.kind,
            "structure": {"na": s.na, "nb": s.nb, "nr": s.nr, "ns": s.ns, "degree": s.degree},
            "chosen": int(self.chosen),
            "rule": self.rule,
            "tolerance": float(self.tolerance),
            "estimation_samples": int(self.estimation_samples),
            "validation_samples": int(self.validation_samples),
            "seconds": float(self.seconds),
            "refitted": bool(self.refitted),
            "refit_error": self.refit_error,
            "note": self.note,
            "rows": jsonable(self.rows),
            "fit": self.fit.to_dict(),
        }

    @fill(axes=AXES)
    def plot(self, *, ax: Any = None, title: str | None = None) -> Any:
        """Plot the validation simulation RMSE (left axis) and BIC (right axis) of every
        candidate that did not raise against its number of parameters; the chosen one circled.

        Parameters
        ----------
        {axes}
        """
        from .._optional import pyplot

        plt = pyplot()
        if ax is None:
            _, ax = plt.subplots(figsize=(7, 4))
        ok = [r for r in self.rows if not r["raised"]]
        p = np.array([r["parameters"] for r in ok], dtype=float)
        val = np.array([r["validation_rmse"] for r in ok])
        bic = np.array([r["bic"] for r in ok])
        ax.semilogy(p, val, "o", color="C0", label="validation simulation RMSE")
        ax.set_xlabel("number of parameters p")
        ax.set_ylabel("validation simulation RMSE", color="C0")
        right = ax.twinx()
        right.plot(p + 0.15, bic, "s", color="C1", mfc="none", label="BIC (estimation part)")
        right.set_ylabel("BIC", color="C1")
        best = self.rows[self.chosen]
        ax.plot([best["parameters"]], [best["validation_rmse"]], "o", ms=14, mfc="none", mec="k", label="chosen")
        handles = ax.get_legend_handles_labels()[0] + right.get_legend_handles_labels()[0]
        ax.legend(handles, [str(h.get_label()) for h in handles], loc="upper right", fontsize="small")
        ax.set_title(title or f"Structure selection: chosen {best['kind']} {self.structure}")
        return ax


def _grid(value: Any, name: str, least: int) -> list[int]:
    """One dimension of the grid: an int or a non-empty sequence of ints >= ``least``."""
    values = [value] if isinstance(value, (int, np.integer)) and not isinstance(value, bool) else value
    try:
        values = list(values)
    except TypeError:
        raise DataError(f"{name} = {value!r}: give a whole number >= {least} or a list of them") from None
    if not values:
        raise DataError(f"{name} = {value!r}: the grid is empty; give at least one value")
    return sorted({check_int(v, name, least) for v in values})


def _error_text(exc: BaseException) -> str:
    return f"{type(exc).__name__}: {exc}"


def _all_raised(rows: list[dict[str, Any]], errors: list[BacklashIdError]) -> BacklashIdError:
    """The error to raise when every candidate raised: of the class most candidates raised, the
    simplest such candidate's, its message prefixed with the count."""
    counts: dict[type, int] = {}
    for exc in errors:
        counts[type(exc)] = counts.get(type(exc), 0) + 1
    cls = max(counts, key=lambda c: counts[c])
    i = min((i for i, e in enumerate(errors) if type(e) is cls), key=lambda i: rows[i]["parameters"])
    r, exc = rows[i], errors[i]
    where = f"{r['kind']} na={r['na']}, nb={r['nb']}" + (f", nr={r['nr']}, ns={r['ns']}" if r["kind"] == "sandwich" else "")
    message = (
        f"select_structure: all {len(rows)} candidates raised ({counts[cls]} {cls.__name__}); "
        f"the simplest, {where}, degree={r['degree']}: {exc}"
    )
    if isinstance(exc, NotConvergedError):
        return NotConvergedError(message, exc.best)
    try:
        return cls(message)
    except TypeError:  # pragma: no cover - every public error takes a message
        return exc


def select_structure(
    u: ArrayLike,
    y: ArrayLike,
    *,
    kind: str | Sequence[str] = "cascade",
    na: int | Sequence[int] = (1, 2, 3),
    nb: int | Sequence[int] = (1, 2, 3),
    degree: int | Sequence[int] = (1, 2, 3, 4),
    nr: int | Sequence[int] = (1, 2),
    ns: int | Sequence[int] = (1, 2),
    validation: float = 0.3,
    tolerance: float = 0.02,
    refit: bool = True,
    warmup: int = 0,
    progress: Callable[[int, int, dict[str, Any]], None] | None = None,
    **options: Any,
) -> StructureSelection:
    """Choose the linear orders and the branch degree by held-out simulation error and BIC.

    Every candidate of the grid (all combinations of ``na``, ``nb``, ``degree`` and, for a
    sandwich, ``nr``, ``ns``; for an input backlash ``nr``, ``ns``, ``degree``) is fitted by
    :func:`fit_cascade` / :func:`fit_sandwich` / :func:`fit_hammerstein_backlash` on the head of
    the record, the first ``1 - validation`` of it. Each fitted model is then simulated free-run
    from the start of the record (from rest, or with ``initial_state="estimate"`` among the
    options from the start its fit estimated over the head; where the model's orders cannot
    hold that state, from the state the first max(warmup, 20) samples imply, as a benchmark
    protocol starts a model on a record that starts mid-motion) and its simulation RMSE on the held-out
    tail is its validation error (the head serves as the tail's warm-up); its BIC is
    ``n log(s**2) + p log(n)`` with s the free-run simulation RMSE on the n estimation samples
    after ``warmup`` and p its number of parameters.

    Decision rule: among the candidates that did not raise, keep those whose validation RMSE
    is at most ``(1 + tolerance)`` times the smallest one, or whose squared errors on the tail
    are not significantly above the best one's (a batch-means t test over 5 blocks of the tail,
    level 0.025: a tail of a few steps, or the one slow drift of a position that integrates,
    ranks candidates by chance), i.e. those within the noise of the best (an omitted term that
    matters raises the validation error by more). A sandwich among them gives way to the input
    backlash it contains (same nr, ns and degree, validation RMSE within 1.25 times the best)
    unless the head needs its input dynamics: a likelihood-ratio test of the two head fits at
    level 0.01, its samples discounted for the error's lag-1 correlation (a tail of a few steps
    or one slow drift ranks these two by chance; the head does not). Of these choose the lowest
    BIC (ties: fewer parameters). The chosen structure is then refitted on the whole
    record (``refit=True``). A candidate whose fit raises, or whose model cannot be simulated
    on the tail, is a row of the table with its error; only when every candidate raises does
    the selection raise.

    Cost: one fit per candidate (the default cascade grid is 3 x 3 x 4 = 36 fits, a few seconds
    on 5000 samples); give a smaller grid to save time. On random cascades of orders and degree
    1-3 (N = 5000, SNR 50, white input; ``benches/select_structure.py``) it picked the true
    orders and degree for 50 of 50 fresh systems.

    Parameters
    ----------
    u : array_like
        Input u(t), 1-D, finite.
    y : array_like
        Measured output (w for a sandwich), 1-D, finite, as long as ``u``.
    kind : {'cascade', 'sandwich', 'hammerstein'} or sequence of them, default 'cascade'
        The structures to try; several kinds are compared in one table: 'cascade' (linear ->
        backlash, load-side play), 'sandwich' (linear -> backlash -> linear, play between two
        masses), 'hammerstein' (backlash -> linear, the input backlash of a motor -> play ->
        load drive: ``na``, ``nb`` unused, the grid over ``nr``, ``ns`` and ``degree``).
    na : int or sequence of int, default (1, 2, 3)
        Input lags of the (input) linear block to try (eq 16).
    nb : int or sequence of int, default (1, 2, 3)
        Output lags of the (input) linear block to try (eq 16).
    degree : int or sequence of int, default (1, 2, 3, 4)
        Degrees n of the backlash branches to try (eq 4-5), each >= 1.
    nr : int or sequence of int, default (1, 2)
        Input lags of the sandwich's output block to try (eq 29); unused for a cascade.
    ns : int or sequence of int, default (1, 2)
        Output lags of the sandwich's output block to try (eq 29); unused for a cascade.
    validation : float, default 0.3
        Fraction of the record, at its end, held out for validation, in (0, 1).
    tolerance : float, default 0.02
        Relative width of the validation band: candidates whose validation RMSE is within
        ``1 + tolerance`` of the best (or not significantly above it on the tail) are judged
        equal and BIC decides among them.
    refit : bool, default True
        Refit the chosen structure on the whole record; otherwise ``fit`` is its fit on the
        estimation part.
    warmup : int, default 0
        Samples at the start left out of every fit criterion and of BIC.
    progress : callable, optional
        Called after each candidate as ``progress(done, total, row)``: the candidates judged so
        far, how many the grid holds and the new row of the table (a long grid, e.g. the 72
        candidates of ``backlashid fit --model auto --orders auto``, takes minutes).
    **options
        Further keywords of :func:`fit_cascade` / :func:`fit_sandwich` (``max_iter``,
        ``feedthrough``, ``min_moving``, ``initial_state``, ...), passed to every candidate's
        fit (an input backlash takes no ``feedthrough``). ``valid`` is on unless given
        (``valid=False``): a candidate whose branches fall or cross on the x range it visits
        is replaced by its constrained fit, a backlash there.

    Returns
    -------
    StructureSelection
        The chosen structure and fit, and the table of every candidate tried.

    Raises
    ------
    DataError
        If the record cannot be used, a grid is empty or holds a value out of range (an
        order < 1, ``nb`` or ``ns`` < 0, a degree < 1), ``kind`` is unknown, or
        ``validation`` or ``tolerance`` is out of range.
    NotIdentifiableError
        If every candidate raised it (the error of the simplest one, with the count).
    NotConvergedError
        If every candidate raised it, likewise.

    Examples
    --------
    >>> import backlashid as bid
    >>> data = bid.example_data(bid.example1(), 1500, snr=50, seed=0)
    >>> sel = bid.select_structure(data.u, data.noisy, na=2, nb=(1, 2), degree=3)
    >>> (sel.structure.na, sel.structure.nb, sel.structure.degree), sel.fit.converged
    ((2, 2, 3), True)
    """
    start = time.perf_counter()
    kinds = _kinds(kind)
    grid_a, grid_b, grid_n = _grid(na, "na", 1), _grid(nb, "nb", 0), _grid(degree, "degree", 1)
    with_output = "sandwich" in kinds or "hammerstein" in kinds
    grid_r, grid_s = (_grid(nr, "nr", 1), _grid(ns, "ns", 0)) if with_output else ([0], [0])
    _check_settings(validation, tolerance, refit)
    if progress is not None and not callable(progress):
        raise DataError(f"progress = {shown(progress)}: give a function progress(done, total, row), or None")
    record = _split_record(u, y, validation, warmup, options)
    feedthrough = bool(options.get("feedthrough", False))
    options = {"valid": True, **options}  # every candidate a backlash where it is used

    rows: list[dict[str, Any]] = []
    fits: list[FitResult | None] = []
    errors: list[BacklashIdError | None] = []
    tails: list[NDArray[np.float64] | None] = []
    correlations: list[float] = []
    candidates = _candidates(kinds, grid_a, grid_b, grid_n, grid_r, grid_s)
    for candidate in candidates:
        row, result, error, tail, correlation = _judged(candidate, record, feedthrough, options)
        rows.append(row)
        fits.append(result)
        errors.append(error)
        tails.append(tail)
        correlations.append(correlation)
        if progress is not None:
            progress(len(rows), len(candidates), dict(row))

    ok = [i for i, r in enumerate(rows) if not r["raised"]]
    if not ok:
        raise _all_raised(rows, [e for e in errors if e is not None])
    chosen, fit, refit_error, note = _choose(rows, fits, tails, correlations, ok, record, tolerance, refit, options)
    return StructureSelection(
        structure=fit.structure, kind=rows[chosen]["kind"], fit=fit, rows=rows, chosen=chosen, rule=RULE,
        tolerance=float(tolerance), estimation_samples=record.n_est, validation_samples=record.n_val,
        seconds=time.perf_counter() - start, refitted=refit and refit_error is None, refit_error=refit_error, note=note,
    )


@dataclass(frozen=True)
class _Split:
    """The record as the selection uses it: every candidate fitted on its head (``n_est``
    samples) and judged on the tail."""

    u: NDArray[np.float64]
    y: NDArray[np.float64]
    n_est: int
    warmup: int
    init: int  # samples that set an estimated start; 0: every model simulated from rest

    @property
    def n_val(self) -> int:
        return len(self.u) - self.n_est

    @property
    def n_fit(self) -> int:
        """The estimation samples after the warm-up (BIC's n)."""
        return self.n_est - self.warmup

    @property
    def u_est(self) -> NDArray[np.float64]:
        return self.u[: self.n_est]

    @property
    def y_est(self) -> NDArray[np.float64]:
        return self.y[: self.n_est]


def _kinds(kind: str | Sequence[str]) -> list[str]:
    """The kinds to try, as a checked list."""
    kinds = [kind] if isinstance(kind, str) else list(kind) if isinstance(kind, Sequence) else [kind]
    if not kinds:
        raise DataError(f"kind = {kind!r}: the list is empty; give 'cascade', 'sandwich', 'hammerstein' or several of them")
    for k in kinds:
        if k not in KINDS:
            raise DataError(f"kind = {k!r}: use 'cascade', 'sandwich' or 'hammerstein' (or a list of them)")
    return kinds


def _check_settings(validation: float, tolerance: float, refit: bool) -> None:
    """DataError for a held-out fraction, band width or refit flag out of range."""
    if isinstance(validation, bool) or not isinstance(validation, (int, float)) or not 0.0 < validation < 1.0:
        raise DataError(f"validation = {validation!r}: give the held-out fraction of the record, in (0, 1)")
    if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float)) or not 0.0 <= tolerance < 1e300:
        raise DataError(f"tolerance = {shown(tolerance)}: give a relative band width >= 0 (e.g. 0.02)")
    check_flag(refit, "refit")


def _split_record(u: ArrayLike, y: ArrayLike, validation: float, warmup: int, options: dict[str, Any]) -> _Split:
    """The checked record, divided into its estimation head and the held-out tail."""
    u_arr, y_arr = one_record(u, y, ("u", "y"))
    check_finite(u_arr, "u")
    check_finite(y_arr, "y")
    n_total = len(u_arr)
    n_val = int(round(validation * n_total))
    n_est = n_total - n_val
    if n_val < 1 or n_est < 2:
        raise DataError(f"validation = {validation}: leaves {n_est} estimation and {n_val} validation samples of {n_total}")
    warmup = check_warmup(warmup, n_est)
    init = max(warmup, INIT_SAMPLES) if options.get("initial_state") == "estimate" else 0
    return _Split(u_arr, y_arr, n_est, warmup, init)


def _candidates(
    kinds: list[str], grid_a: list[int], grid_b: list[int], grid_n: list[int], grid_r: list[int], grid_s: list[int]
) -> list[tuple[str, int, int, int, int, int]]:
    """The grid as (kind, na, nb, nr, ns, degree), in the order tried (nr = ns = 0 for a cascade)."""
    candidates: list[tuple[str, int, int, int, int, int]] = []
    for k in kinds:
        outer = itertools.product(grid_r, grid_s) if k != "cascade" else [(0, 0)]
        inner = itertools.product([1], [0], grid_n) if k == "hammerstein" else itertools.product(grid_a, grid_b, grid_n)  # x(t) = a_1 u(t-1)
        for (r, s), (a, b, n) in itertools.product(list(outer), list(inner)):
            candidates.append((k, a, b, r, s, n))
    return candidates


def _structure(kind: str, a: int, b: int, r: int, s: int, n: int, feedthrough: bool, options: dict[str, Any]) -> Structure:
    """A candidate's orders and degree as a Structure."""
    if kind == "hammerstein":
        return Structure(a, b, n, r, s, output_feedthrough=bool(options.get("output_feedthrough", False)))
    if kind == "sandwich":
        return Structure(a, b, n, r, s, feedthrough=feedthrough, output_feedthrough=bool(options.get("output_feedthrough", False)))
    return Structure(a, b, n, feedthrough=feedthrough)


def _judged(
    candidate: tuple[str, int, int, int, int, int], record: _Split, feedthrough: bool, options: dict[str, Any]
) -> tuple[dict[str, Any], FitResult | None, BacklashIdError | None, NDArray[np.float64] | None, float]:
    """One candidate fitted on the head and judged on the tail: its row of the table, its fit
    (None if it raised), its error (None if it did not), its simulation error on the tail
    (None if it raised) and the lag-1 correlation of that error on the head after the warm-up
    (0 if it raised)."""
    k, a, b, r, s, n = candidate
    structure = _structure(k, a, b, r, s, n, feedthrough, options)
    p = structure.size
    row: dict[str, Any] = dict(
        kind=k, na=a, nb=b, nr=r, ns=s, degree=n, parameters=p, estimation_rmse=math.nan,
        validation_rmse=math.nan, bic=math.nan, raised=False, error=None, warnings=[], seconds=0.0,
        in_band=False, chosen=False, refit_error=None, valid=False,
    )
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result, tail, val, correlation, error = _fit_and_validate(k, structure, record, options)
    row["warnings"] = [str(w.message) for w in caught if issubclass(w.category, FitWarning)]
    for w in caught:  # anything else is shown as Python would have
        if not issubclass(w.category, FitWarning):
            warnings.showwarning(w.message, w.category, w.filename, w.lineno)
    row["seconds"] = time.perf_counter() - t0
    if error is not None:
        row["raised"], row["error"] = True, _error_text(error)
    else:
        assert result is not None
        est = float(result.simulation_rmse)
        row["estimation_rmse"], row["validation_rmse"] = est, val
        row["bic"] = record.n_fit * math.log(max(est, 1e-300) ** 2) + p * math.log(record.n_fit)
        row["valid"] = _is_backlash(result.model, record.u_est, record.warmup)
    return row, result, error, tail, correlation


def _fit_and_validate(
    kind: str, structure: Structure, record: _Split, options: dict[str, Any]
) -> tuple[FitResult | None, NDArray[np.float64] | None, float, float, BacklashIdError | None]:
    """The candidate's fit on the head, its simulation error on the tail (simulated from the
    record's start: rest, or the state the fit estimated), that error's RMSE (the validation
    RMSE) and the lag-1 correlation of the simulation error on the head after the warm-up, or
    (None, None, NaN, 0, the error) if either fails."""
    try:
        result = _fit_one(kind, record.u_est, record.y_est, structure, record.warmup, options)
        if result.model is None:
            raise NotConvergedError("the fit ended with no valid model", result)
        simulated = _simulated(result.model, record.u, record.y, record.init, result)
        tail = record.y[record.n_est :] - simulated[record.n_est :]
        val = float(np.sqrt(np.mean(tail**2)))
        if not math.isfinite(val):
            raise NotConvergedError("the model's simulation of the validation tail is not finite", result)
        head = record.y[record.warmup : record.n_est] - simulated[record.warmup : record.n_est]
    except BacklashIdError as exc:
        return None, None, math.nan, 0.0, exc
    return result, tail, val, lag1_correlation(head), None


def _choose(
    rows: list[dict[str, Any]], fits: list[FitResult | None], tails: list[NDArray[np.float64] | None],
    correlations: list[float], ok: list[int], record: _Split, tolerance: float, refit: bool, options: dict[str, Any],
) -> tuple[int, FitResult, str | None, str]:
    """The chosen row, its fit, why no refit held (or None) and the note (validity, stand-ins);
    marks the rows in the band and the chosen one."""
    for i in validation_band(rows, ok, float(tolerance), tails):
        rows[i]["in_band"] = True
    preferred, note = preferred_candidates(rows, ok, float(tolerance), tails)
    # an input backlash for the sandwich containing it, where the head does not need the sandwich
    best = min(rows[i]["validation_rmse"] for i in ok)
    preferred, stand_in = with_stand_ins(
        rows, preferred, ok, record.n_fit, correlations, [_start_size(f) for f in fits], max(TAIL_LIMIT, 1.0 + tolerance) * best
    )
    note = "; ".join(t for t in (note, stand_in) if t)
    # the preferred candidates by BIC (ties: fewer parameters): the order in which a candidate
    # whose whole-record refit fails gives way to the next equally good one (never to one
    # outside them: there the first candidate's validated estimation fit is returned)
    order = sorted(preferred, key=lambda i: (rows[i]["bic"], rows[i]["parameters"]))
    chosen, fit, refit_error = order[0], fits[order[0]], None
    if refit:
        chosen, fit, refit_error = _first_refit_that_holds(order, rows, fits, record, tolerance, options)
    rows[chosen]["chosen"] = True
    assert fit is not None
    return chosen, fit, refit_error, note


def _first_refit_that_holds(
    order: list[int], rows: list[dict[str, Any]], fits: list[FitResult | None], record: _Split, tolerance: float,
    options: dict[str, Any],
) -> tuple[int, FitResult | None, str | None]:
    """The first candidate of ``order`` whose refit on the whole record holds, with that refit
    and None; if none holds, the first candidate, its estimation fit and why its refit failed.
    Every row tried gets its ``refit_error``."""
    for i in order:
        head = fits[i]
        assert head is not None
        whole, why = _refit_whole(head, record.u, record.y, record.warmup, record.init, tolerance, options)
        rows[i]["refit_error"] = why
        if why is None:
            return i, whole, None
    return order[0], fits[order[0]], rows[order[0]]["refit_error"]


def validation_band(
    rows: Sequence[dict[str, Any]], pool: Sequence[int], tolerance: float, tails: Sequence[NDArray[np.float64] | None] | None = None
) -> list[int]:
    """The candidates of ``pool`` that validate as well as its best one, within the tail's
    noise: a validation RMSE within ``1 + tolerance`` of the best, or (with the tails' errors)
    within TAIL_LIMIT of it and squared errors not significantly above the best one's
    (:func:`_not_worse_on_tail`).

    Parameters
    ----------
    rows : sequence of dict
        The table's rows (``validation_rmse``).
    pool : sequence of int
        The rows to compare (none raised).
    tolerance : float
        The band's relative width.
    tails : sequence of ndarray or None, optional
        Each row's simulation error on the tail (None for a row that raised).

    Returns
    -------
    list of int
        The rows of the band, in the order of ``pool``.

    Examples
    --------
    >>> rows = [dict(validation_rmse=1.0), dict(validation_rmse=1.01), dict(validation_rmse=1.1)]
    >>> validation_band(rows, [0, 1, 2], 0.02)
    [0, 1]
    """
    best = min(pool, key=lambda i: rows[i]["validation_rmse"])
    near = (1.0 + tolerance) * rows[best]["validation_rmse"]
    limit = max(TAIL_LIMIT, 1.0 + tolerance) * rows[best]["validation_rmse"]
    return [
        i for i in pool
        if rows[i]["validation_rmse"] <= near
        or (tails is not None and rows[i]["validation_rmse"] <= limit and _not_worse_on_tail(tails[i], tails[best]))
    ]  # fmt: skip


def _not_worse_on_tail(tail: NDArray[np.float64] | None, best: NDArray[np.float64] | None) -> bool:
    """Whether the squared errors ``tail`` are not significantly above ``best``'s on the same
    samples: the mean of their difference over TAIL_BLOCKS consecutive blocks below TAIL_T times
    its standard error (batch means; False for a tail shorter than two samples per block)."""
    if tail is None or best is None or len(tail) < 2 * TAIL_BLOCKS:
        return False
    m = len(tail) // TAIL_BLOCKS
    d = (tail[: m * TAIL_BLOCKS] ** 2 - best[: m * TAIL_BLOCKS] ** 2).reshape(TAIL_BLOCKS, m).mean(axis=1)
    spread = float(np.std(d, ddof=1))
    return bool(spread > 0.0 and float(np.mean(d)) < TAIL_T * spread / math.sqrt(TAIL_BLOCKS))


def preferred_candidates(
    rows: Sequence[dict[str, Any]], ok: Sequence[int], tolerance: float, tails: Sequence[NDArray[np.float64] | None] | None = None
) -> tuple[list[int], str]:
    """The candidates the choice is made among, valid backlashes first, and what that did in
    words ("" when it changed nothing).

    The validation band (:func:`validation_band` of all rows); its valid backlashes (rows'
    ``valid``) where it holds any; else the band of the valid candidates alone, where their
    best is within VALID_SLACK of the best of all; else the band as it is (no valid backlash
    comes close).

    Parameters
    ----------
    rows : sequence of dict
        The table's rows (``validation_rmse``, ``valid``, ``kind``, ``degree``).
    ok : sequence of int
        The rows that did not raise.
    tolerance : float
        The band's relative width.
    tails : sequence of ndarray or None, optional
        Each row's simulation error on the tail (None for a row that raised); without them the
        band is the relative one alone.

    Returns
    -------
    list of int, str
        The rows to choose among, and the note.

    Examples
    --------
    >>> rows = [dict(validation_rmse=1.0, valid=False, kind="cascade", degree=3),
    ...         dict(validation_rmse=1.1, valid=True, kind="cascade", degree=1)]
    >>> preferred_candidates(rows, [0, 1], 0.02)[0]
    [1]
    """
    val = {i: rows[i]["validation_rmse"] for i in ok}
    best = min(val.values())
    band = validation_band(rows, ok, tolerance, tails)
    valid = [i for i in ok if rows[i]["valid"]]
    in_band = [i for i in band if rows[i]["valid"]]
    if in_band:
        dropped = len(band) - len(in_band)
        return in_band, (f"{dropped} candidate(s) of the band left out: their branches fall or cross on the visited range" if dropped else "")
    if valid:
        best_valid = min(val[i] for i in valid)
        if best_valid <= VALID_SLACK * best:
            near = validation_band(rows, valid, tolerance, tails)
            return near, (
                f"a valid backlash preferred: the band held none; the best valid one validates {best_valid / best:.2f} times the "
                f"best (at most {VALID_SLACK:g} allowed)"
            )
        return band, (
            f"no valid backlash within {VALID_SLACK:g} times the best validation RMSE (the best valid one: "
            f"{best_valid / best:.2f} times): the chosen model's branches fall or cross on the visited range"
        )
    return band, "no candidate is a valid backlash on the visited range: the chosen model's branches fall or cross there"


def _start_size(fit: FitResult | None) -> int:
    """The number of start values ``fit`` estimated (0 from rest or for no fit)."""
    return len(fit.initial_state) if fit is not None and isinstance(fit.initial_state, dict) else 0


def _is_backlash(model: Any, u: NDArray[np.float64], warmup: int) -> bool:
    """Whether both branches increase and do not cross on the x range the record visits."""
    try:
        return branch_problems(model, u, warmup) is None
    except BacklashIdError:
        return False


def _simulated(model: Any, u: NDArray[np.float64], y: NDArray[np.float64], init: int, fit: FitResult | None = None) -> NDArray[np.float64]:
    """The free run over the whole record from rest, or (``init`` > 0, an estimated start) from
    the initial state ``fit`` estimated with the model on the record's head, else from the
    state the record's first ``init`` samples imply, as a benchmark protocol starts a model.
    The fit's state is the better start: estimated over the whole head, not its first samples
    (a position that integrates holds a wrong start's offset for good; under steps the first
    samples may not determine the play's memory)."""
    if init and fit is not None and isinstance(fit.initial_state, dict):
        try:
            return np.asarray(model.simulate(u, initial_state=model_state(model, fit.initial_state)), dtype=np.float64)
        except BacklashIdError:  # orders that cannot hold the state's free response: from the first samples
            pass
    return np.asarray(simulate_from_samples(model, u, y, init) if init else model.simulate(u), dtype=np.float64)


def _refit_whole(
    head: FitResult, u: NDArray[np.float64], y: NDArray[np.float64], warmup: int, init: int, tolerance: float,
    options: dict[str, Any],
) -> tuple[FitResult | None, str | None]:
    """The refit of a candidate on the whole record (with an estimated state, its search also
    from the candidate's estimate: :func:`refit_with_estimate`) and None, or None and why it is
    not kept: it raised, did not converge, or simulates the whole record (free run from each
    fit's start, after the warm-up) worse than the candidate's estimation fit, which it was
    meant to improve (a refit that diverged into a pole at 1 is far worse)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FitWarning)  # the candidate's own fit has shown its warnings
            structural = ("feedthrough", "output_feedthrough")  # the head's structure has them
            whole = refit_with_estimate(head, u, y, warmup=warmup, **{k: v for k, v in options.items() if k not in structural})
    except BacklashIdError as exc:
        return None, f"the refit on the whole record raised {_error_text(exc)}"
    if not whole.converged or whole.model is None:
        return None, f"the refit on the whole record did not converge (reason {whole.reason!r})"
    assert head.model is not None
    skip = max(warmup, init)
    errors = [float(np.sqrt(np.mean((y - _simulated(f.model, u, y, init, f))[skip:] ** 2))) for f in (whole, head)]
    if not (math.isfinite(errors[0]) and errors[0] <= (1.0 + tolerance) * errors[1]):
        return None, (
            f"the refit on the whole record simulates it worse (RMSE {errors[0]:.4g}) than the fit on its head does "
            f"({errors[1]:.4g}): it left the estimate's basin"
        )
    return whole, None


def _fit_one(kind: str, u: Any, y: Any, structure: Structure, warmup: int, options: dict[str, Any]) -> FitResult:
    s = structure
    if kind == "hammerstein":
        rest = {k: v for k, v in options.items() if k not in ("feedthrough", "output_feedthrough")}
        return fit_hammerstein_backlash(u, y, s.nr, s.ns, s.degree, output_feedthrough=s.output_feedthrough, warmup=warmup, **rest)
    if kind == "sandwich":
        return fit_sandwich(u, y, s.na, s.nb, s.nr, s.ns, s.degree, warmup=warmup, **options)
    rest = {k: v for k, v in options.items() if k != "output_feedthrough"}  # a sandwich's option, in a mixed table
    return fit_cascade(u, y, s.na, s.nb, s.degree, warmup=warmup, **rest)
