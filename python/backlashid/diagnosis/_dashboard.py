"""The diagnosis report's dashboard figure (``DiagnosisReport.plot`` delegates here).

The figure answers "which effect does the nominal model miss?" in the words of the decision
rule (:mod:`._verdict`): an effect is named for a significant improvement, the lowest BIC and
closing half of the gap, the residual signature being a secondary check. Its one-line title
names the effect(s) and why, the candidates panel marks on the bars which were named and which
closed half the gap but were not named (and why), and a footnote states the rule.
"""

from __future__ import annotations

import math
import textwrap
from collections import Counter
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import DataError
from ._report import _p, _pct
from ._verdict import CLOSE_ENOUGH

__all__ = ["plot_diagnosis"]

NOISE_MODEL = "colored_noise"  # judged by one-step prediction: its gap closed is 0 by construction
SHOWN = 12  # candidates drawn in rank order (the named, the held back and the noise model besides)


def plot_diagnosis(
    report: Any,
    path: Any = None,
    *,
    figsize: tuple[float, float] = (13, 15),
    window: int = 300,
    dpi: float = 110,
    scaling: Any = None,
    output: str = "y",
    sample_time: float | None = None,
    records: Any = None,
) -> Any:
    """Draw the diagnosis dashboard of a :class:`~backlashid.diagnosis.DiagnosisReport`.

    The one-line title names the effect(s) and why (the share of the gap closed and the
    p-value). The panels: measured against nominal simulation (the vertical scale set by the
    samples after the warm-up; with several validation records, a vertical line where each
    starts), the error coloured by regime, the error share by regime, the residual correlation
    tests, the gap closed by each candidate (the bars say which were named and which closed half
    the gap but were not named, and why; colored_noise, a noise model, is judged by its one-step
    prediction), and the nominal against the best augmented simulation where the error is
    largest. A footnote states the decision rule and the details of the verdict. The diagnosis
    works in model units; ``scaling``, ``output`` and ``sample_time`` put the signal panels in
    the record's units.

    The before/after panel shows the measurement, the nominal simulation and the best
    augmented one: the named effects', or, when none is named ("unexplained"), the best
    candidate that changes the simulation, simulated again here from the state that fits the
    record (labelled "not named").

    Parameters
    ----------
    report : DiagnosisReport
        What :func:`backlashid.diagnose` returned.
    path : str or path-like, optional
        Save the figure here (PNG by the file's extension) through the Agg backend, without
        touching pyplot's state; None draws into a new pyplot figure.
    figsize : tuple of float, default (13, 15)
        Figure size in inches.
    window : int, default 300
        Samples shown in the before/after panel.
    dpi : float, default 110
        Resolution of the figure.
    scaling : Scaling, optional
        The :class:`~backlashid.identify.Scaling` between the record and the model: the outputs
        and errors are drawn in the record's units (``output_from_model``; an error scales by
        ``output_scale`` alone). None: model units.
    output : str, default "y"
        Name and unit of the output for the axis labels, e.g. ``"friction force [kip]"``.
    sample_time : float, optional
        Seconds per sample: the time axes in seconds. None: in samples.
    records : sequence of int, optional
        The lengths of the validation records, in order. None: found from the report (the
        first record's from the regime analysis, the others where every candidate's free run
        restarts).

    Returns
    -------
    matplotlib.figure.Figure
        The dashboard.

    Raises
    ------
    BacklashIdError
        If matplotlib is not installed.
    DataError
        If ``records`` do not add up to the validation samples.
    """
    window = int(window)
    view = _View(scaling, str(output), sample_time)
    runs = _records_of(report, records)
    fig = _figure(path, figsize, dpi)
    width_in, height_in = float(figsize[0]), float(figsize[1])
    note = _footnote(report, view, width_chars=int(width_in * 72 * 0.96 / (8 * 0.52)))
    note_lines = note.count("\n") + 1 if note else 0
    top = 1.0 - (16 + 40) / (72 * height_in)  # the one-line title, the first panel's title and a margin
    bottom = (note_lines * 11 + 62) / (72 * height_in)  # the footnote, the last row's tick labels and x labels
    gs = fig.add_gridspec(
        4, 2, height_ratios=[1.1, 1.0, 1.0, 1.0], hspace=0.5, wspace=0.22,
        top=top, bottom=bottom, left=0.16, right=0.98,
    )  # fmt: skip
    _plot_signals(report, fig.add_subplot(gs[0, :]), view, runs)
    _plot_error(report, fig.add_subplot(gs[1, :]), view, runs)
    _plot_regimes(report, fig.add_subplot(gs[2, 0]), runs)
    _plot_tests(report, fig.add_subplot(gs[2, 1]))
    _plot_ranking(report, fig.add_subplot(gs[3, 0]))
    _plot_before_after(report, fig.add_subplot(gs[3, 1]), window, view, runs)
    headline = _fitted(_headline(report, view), 11, width_in * 72 * 0.96, weight="bold")
    fig.suptitle(headline, x=0.5, y=1.0 - 8 / (72 * height_in), ha="center", va="top", fontsize=11, fontweight="bold")
    if note:
        fig.text(0.012, 4 / (72 * height_in), note, ha="left", va="bottom", fontsize=8, color="0.2")
    if path is not None:  # a picture: its ticks fixed (a figure on screen keeps its locators, for zooming)
        from .._files import save_figure

        for ax in fig.axes:
            _ticks_in_view(ax)

        save_figure(fig, path, dpi=dpi)  # atomically
    return fig


def _ticks_in_view(ax: Any) -> None:
    """The axes' ticks fixed to those in view: a tick the locator puts outside the limits keeps
    a label that is not drawn yet sits, with its text, over the next panel's."""
    for axis in (ax.xaxis, ax.yaxis):
        if axis.get_scale() != "linear":
            continue
        lo, hi = sorted(axis.get_view_interval())
        eps = 1e-9 * (hi - lo)
        locs = np.asarray(axis.get_majorticklocs(), dtype=float)
        inside = locs[(locs >= lo - eps) & (locs <= hi + eps)]
        if 0 < inside.size < locs.size:
            axis.set_ticks(inside)


def _figure(path: Any, figsize: tuple[float, float], dpi: float) -> Any:
    """A new figure: off pyplot (Agg) when it is saved to ``path``, else pyplot's."""
    if path is not None:
        try:
            from matplotlib.backends.backend_agg import FigureCanvasAgg
            from matplotlib.figure import Figure
        except ImportError:
            from .._optional import pyplot

            pyplot()  # raises the library's message
            raise
        fig = Figure(figsize=figsize, dpi=dpi)
        FigureCanvasAgg(fig)
        return fig
    from .._optional import pyplot

    return pyplot().figure(figsize=figsize, dpi=dpi)


class _View:
    """Model units and samples to the record's units and seconds."""

    def __init__(self, scaling: Any, output: str, sample_time: float | None) -> None:
        self.scale = 1.0 if scaling is None else abs(float(scaling.output_scale))
        self.offset = 0.0 if scaling is None else float(scaling.output_offset)
        if scaling is not None and float(scaling.output_scale) < 0:
            self.scale = -self.scale
        self.output = output
        self.dt = None if sample_time is None else float(sample_time)
        self.time_label = "sample" if self.dt is None else "time [s]"

    def y(self, v: Any) -> Any:
        """An output in the record's units."""
        return np.asarray(v, dtype=float) * self.scale + self.offset

    def e(self, v: Any) -> Any:
        """An error (difference of outputs) in the record's units."""
        return np.asarray(v, dtype=float) * abs(self.scale)

    def t(self, index: Any) -> Any:
        """Sample indices on the time axis."""
        return np.asarray(index, dtype=float) * (1.0 if self.dt is None else self.dt)


# ---------------------------------------------------------------------- the validation records


@dataclass(frozen=True)
class _Records:
    """The validation records joined in the report's signals.

    Attributes
    ----------
    starts : tuple of int
        Where each record found starts (0 first).
    count : int
        The number of records the report holds.
    keep : ndarray of bool
        The samples after each record's warm-up (the scored ones).
    """

    starts: tuple[int, ...]
    count: int
    keep: NDArray[np.bool_]

    @property
    def complete(self) -> bool:
        """Whether every record's start is known."""
        return len(self.starts) >= self.count


def _records_of(report: Any, lengths: Any) -> _Records:
    """The records' starts (given as lengths, or found) and the scored samples."""
    n = report.n_validation
    if lengths is not None:
        sizes = [int(v) for v in lengths]
        if not sizes or min(sizes) < 1 or sum(sizes) != n:
            raise DataError(f"records: the validation records' lengths must add up to the report's {n} samples; got {sizes}")
        starts = tuple(int(v) for v in np.r_[0, np.cumsum(sizes)[:-1]])
        count = len(sizes)
    else:
        count = int(report.details.records[1]) if report.details is not None else 1
        starts = _found_starts(report, count)
    keep = np.ones(n, dtype=bool)
    for s in starts:
        keep[s : s + int(report.warmup)] = False
    if not keep.any():
        keep[:] = True
    return _Records(starts, max(count, len(starts)), keep)


def _found_starts(report: Any, count: int) -> tuple[int, ...]:
    """Where the validation records start: the first record's length from the regime analysis
    (it covers the first record), the others where the candidates' free runs restart."""
    n = report.n_validation
    if count <= 1 or n == 0:
        return (0,)
    found: list[int] = []
    size = report.regimes.masks["dead_band"].size if report.regimes is not None else 0
    if 0 < size < n:
        found.append(int(size))
    if len(found) < count - 1:
        found += _restarts(report, count - 1 - len(found), found)
    return tuple(sorted({0, *found}))


def _restarts(report: Any, wanted: int, known: list[int]) -> list[int]:
    """Up to ``wanted`` record starts, by vote of the candidates: a candidate's free run of the
    records, each from its own start, leaves its continuous run over the joined input where a
    record starts (after a stretch where the two agree)."""
    u = np.asarray(report.u_val, dtype=float)
    votes: Counter[int] = Counter()
    used = 0
    for c in report.ranking:
        out = getattr(c, "validation_output", None)
        if used >= 6 or c.model is None or not hasattr(c.model, "simulator") or out is None or np.asarray(out).size != u.size:
            continue
        onsets = _onsets(c.model, u, np.asarray(out, dtype=float))
        if onsets is not None:
            used += 1
            votes.update(onsets)
    need = max(1, (used + 1) // 2)
    gap = max(int(report.warmup), 10)
    chosen: list[int] = []
    for at, v in votes.most_common():
        if len(chosen) >= wanted or v < need:
            break
        if all(abs(at - s) > gap for s in [0, *known, *chosen]):
            chosen.append(int(at))
    return chosen


def _onsets(model: Any, u: NDArray[np.float64], out: NDArray[np.float64], quiet: int = 20) -> list[int] | None:
    """Where ``out`` leaves the model's continuous run after ``quiet`` samples of agreement (the
    input advanced by 0, 1 or 2 samples, for a nominal with lag-0 terms: the best)."""
    try:
        sim = model.simulator()
        tol = 1e-9 * (1.0 + float(np.max(np.abs(out))))
        off = None
        for shift in (0, 1, 2):
            v = np.r_[u[shift:], np.repeat(u[-1:], shift)] if shift else u
            o = np.abs(np.asarray(sim(v), dtype=float) - out) > tol
            if off is None or o.sum() < off.sum():
                off = o
    except Exception:  # a model that cannot run the joined records gives no vote
        return None
    if off is None or off.all():
        return None
    c = np.r_[0, np.cumsum(off)]
    i = np.arange(quiet, off.size)
    return [int(k) for k in i[off[quiet:] & (c[i] - c[i - quiet] == 0)]]


def _shade_warmups(report: Any, ax: Any, view: _View, runs: _Records, clipped: bool = False) -> None:
    if report.warmup <= 0:
        return
    each = " per record" if runs.count > 1 else ""
    label = f"warm-up ({report.warmup} samples{each}, not scored{'; clipped' if clipped else ''})"
    for k, s in enumerate(runs.starts):
        a, b = view.t(s - 0.5), view.t(s + report.warmup - 0.5)
        ax.axvspan(a, b, color="0.9", lw=0, label=label if k == 0 else None, zorder=0)


def _mark_starts(ax: Any, view: _View, runs: _Records) -> None:
    """A vertical line where each record after the first starts."""
    found = "" if runs.complete else f", {len(runs.starts)} of {runs.count} found"
    for k, s in enumerate(runs.starts[1:]):
        label = f"record start ({runs.count} separate runs{found})" if k == 0 else None
        ax.axvline(view.t(s - 0.5), color="C4", lw=1.4, ls="-", label=label, zorder=3)


def _scored_limits(ax: Any, values: list[Any], keep: NDArray[np.bool_], floor: float = 0.0) -> bool:
    """The y limits from the scored samples (a spike in a warm-up is clipped); whether any
    sample is clipped."""
    scored = np.concatenate([np.asarray(v, dtype=float)[keep] for v in values])
    scored = scored[np.isfinite(scored)]
    if scored.size == 0:
        return False
    lo, hi = min(float(scored.min()), -floor), max(float(scored.max()), floor)
    pad = 0.06 * (hi - lo) if hi > lo else max(abs(hi), 1.0) * 0.1
    lo, hi = lo - pad, hi + pad
    ax.set_ylim(lo, hi)
    every = np.concatenate([np.asarray(v, dtype=float) for v in values])
    every = every[np.isfinite(every)]
    return bool(every.size and (every.min() < lo or every.max() > hi))


# ---------------------------------------------------------------------- the signal panels


def _plot_signals(report: Any, ax: Any, view: _View, runs: _Records) -> None:
    t = view.t(np.arange(report.n_validation))
    nominal, measured = view.y(report.y_nominal), view.y(report.y_val)
    ax.plot(t, nominal, color="C0", lw=0.9, label="nominal simulation")
    ax.plot(t, measured, color="k", lw=0.5, alpha=0.6, label="measured")
    clipped = _scored_limits(ax, [nominal, measured], runs.keep)
    _shade_warmups(report, ax, view, runs, clipped)
    _mark_starts(ax, view, runs)
    rmse = view.e(report.nominal_validation_rmse)
    what = "Validation record" if runs.count <= 1 else f"Validation: {runs.count} records joined, each simulated from its own start"
    ax.set_title(f"{what}: measured vs nominal free-run simulation (RMSE {rmse:.4g})", fontsize=10)
    ax.set_xlabel(view.time_label)
    ax.set_ylabel(view.output)
    _headroom(ax)
    _legend_in_order(ax, ncol=4)
    ax.grid(alpha=0.3)


def _legend_in_order(ax: Any, ncol: int, **kw: Any) -> None:
    """The legend with the band and the record starts after the signals."""
    handles, labels = ax.get_legend_handles_labels()
    order = sorted(range(len(labels)), key=lambda i: (labels[i].startswith(("warm-up", "record start")), i))
    ax.legend([handles[i] for i in order], [labels[i] for i in order], loc="upper right", fontsize="small", ncol=ncol, **kw)


def _headroom(ax: Any, share: float = 0.2) -> None:
    """Room above the data for the legend row (it must not hide the signal)."""
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi + share * (hi - lo))


def _plot_error(report: Any, ax: Any, view: _View, runs: _Records) -> None:
    err = view.e(np.asarray(report.y_val) - np.asarray(report.y_nominal))
    t = view.t(np.arange(err.size))
    noise = float(view.e(report.noise_std))
    size = report.regimes.masks["dead_band"].size if report.regimes is not None else 0
    if size and size <= err.size:  # the regimes cover the first record
        labels = report.regimes.labels()
        styles = ((-1, "0.75", None), (0, "0.35", "dead band"), (1, "C0", "left branch"), (2, "C3", "right branch"))
        for value, color, name in styles:
            sel = np.flatnonzero(labels == value)
            if sel.size:
                ax.scatter(t[sel], err[sel], s=3, lw=0, color=color, label=name)
        if size < err.size:
            ax.scatter(t[size:], err[size:], s=3, lw=0, color="0.6", label="later records (regimes of the first only)")
    else:
        ax.scatter(t, err, s=3, lw=0, color="0.35", label="error")
    for sign in (-2.0, 2.0):
        ax.axhline(sign * noise, color="k", ls="--", lw=0.8)
    _scored_limits(ax, [err], runs.keep, floor=2 * noise)  # the evaluated samples, not the transient
    _shade_warmups(report, ax, view, runs)
    _mark_starts(ax, view, runs)
    _headroom(ax)
    ax.set_title("Nominal model's error (measured - simulated) by backlash state; dashed: +-2 noise std", fontsize=10)
    ax.set_xlabel(view.time_label)
    ax.set_ylabel(f"error, {view.output}" if view.output != "y" else "error")
    _legend_in_order(ax, ncol=3 if runs.count > 1 else 4, markerscale=3)
    ax.grid(alpha=0.3)


def _plot_regimes(report: Any, ax: Any, runs: _Records) -> None:
    if report.regimes is None:
        ax.set_axis_off()
        return
    names = [r.name for r in report.regimes.regimes]
    pos = np.arange(len(names))
    samples = [100 * r.sample_share for r in report.regimes.regimes]
    energy = [100 * r.energy_share for r in report.regimes.regimes]
    ax.bar(pos - 0.2, samples, 0.4, color="0.7", label="share of samples")
    ax.bar(pos + 0.2, energy, 0.4, color="C1", label="share of error energy")
    for i, r in enumerate(report.regimes.regimes):
        if r.significant:
            mark = "*" if r.excess else "(-)"
            ax.text(i + 0.2, energy[i] + 1.5, mark, ha="center", fontsize=11 if r.excess else 8)
    ax.set_xticks(pos)
    ax.set_xticklabels([n.replace("_", "\n") for n in names], fontsize=8)
    ax.set_ylabel("share [%]")
    first = ", first record" if runs.count > 1 else ""
    ax.set_title(f"Error share by regime{first} (* significantly more error)", fontsize=10)
    total = sum(samples)
    if total > 100.5:  # a sample can be in several regimes (after a reversal and in the dead band)
        ax.text(
            0.99, 0.97, f"the regimes overlap: sample shares add up to {total:.0f} %",
            transform=ax.transAxes, ha="right", va="top", fontsize=8,
            bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="0.6", alpha=0.9),
        )  # fmt: skip
    # the legend in a band above the tallest bar (and the overlap note), never over a bar
    ax.set_ylim(0, max(max(samples), max(energy)) * (1.55 if total > 100.5 else 1.35) + 5)
    ax.legend(fontsize="small", loc="upper left")
    ax.grid(alpha=0.3, axis="y")


def _plot_tests(report: Any, ax: Any) -> None:
    if report.tests is None:
        ax.set_axis_off()
        return
    shown = [name for name in ("acf", "ccf_u", "ccf_x") if name in report.tests]
    width = 0.8 / max(len(shown), 1)
    for i, name in enumerate(shown):
        t = report.tests[name]
        offset = (i - (len(shown) - 1) / 2) * width
        label = f"{name} (p {t.p_adjusted:.1e}{'' if t.passed else ', FAIL'})"
        ax.bar(t.lags + offset, t.values, width, color=f"C{i}", label=label)
    bound = report.tests.tests[0].bound
    ax.axhspan(-bound, bound, color="0.85", zorder=0, label=f"95 % bounds +-{bound:.3f}")
    ax.axhline(0.0, color="k", lw=0.5)
    failed = ", ".join(report.tests.failed) or "none"
    ax.set_title(textwrap.fill(f"Residual correlations (failed tests: {failed})", width=60), fontsize=10)
    ax.set_xlabel("lag k [samples]")
    ax.set_ylabel("normalised correlation")
    _headroom(ax, 0.45)  # the legend above the bars
    ax.legend(fontsize="x-small", loc="upper right", ncol=2)
    ax.grid(alpha=0.3)


# ---------------------------------------------------------------------- the candidates


def _named(report: Any) -> tuple[str, ...]:
    """The effects named (the best alone for a report built without them)."""
    if report.effects:
        return tuple(report.effects)
    return (report.best.effect,) if report.best is not None else ()


def _level(report: Any) -> float:
    """The level the rule judged the candidates at (0.05 for a report built by hand)."""
    level = report.details.significance_level if report.details is not None else float("nan")
    return float(level) if math.isfinite(level) and level > 0 else 0.05


def _lowest_bic(report: Any, c: Any) -> bool:
    """Whether ``c`` has the lowest BIC of the significant deterministic candidates."""
    level = _level(report)
    rivals = [x.criterion for x in report.ranking if x.effect != NOISE_MODEL and x.p_value < level and math.isfinite(x.criterion)]
    return bool(rivals) and math.isfinite(c.criterion) and c.criterion <= min(rivals)


def _step_of(report: Any, effect: str) -> tuple[int, Any]:
    """The composition step that named ``effect`` (its index, or -1 and None)."""
    for i, st in enumerate(report.steps):
        if st.effect == effect:
            return i, st
    return -1, None


def _named_note(report: Any, c: Any) -> str:
    """Why a named candidate was named, for its bar."""
    i, st = _step_of(report, c.effect)
    several = len(report.steps) > 1
    prefix = f"named, step {i + 1}: " if several and st is not None else "named: "
    if st is None:
        if c.effect == "quantization":
            return prefix + "the measured output lies on a lattice (see below)"
        return prefix + f"closes {_pct(c.gap_closed).strip()} of the gap, p {_p(c.p_value)}"
    of = "gap" if i == 0 else "rest"
    if c.effect == NOISE_MODEL:
        return prefix + f"noise model, predicts the {'residual' if i == 0 else 'rest'} one step ahead, p {_p(st.p_value)}"
    return prefix + f"closes {_pct(st.gap_closed).strip()} of the {of}, p {_p(st.p_value)}"


def _held_reason(report: Any, c: Any) -> str:
    """Why a candidate closing half the gap was not named ("" if it does not, or was named)."""
    if c.effect in _named(report) or c.effect == NOISE_MODEL:
        return ""
    held = report.details.closing_not_named if report.details is not None else {}
    if c.effect in held:
        return str(held[c.effect])
    if not (math.isfinite(c.gap_closed) and c.gap_closed >= CLOSE_ENOUGH):
        return ""
    level = _level(report)
    if not c.p_value < level:
        return f"its improvement is not significant (p {_p(c.p_value)} >= {level:.2g})"
    best = report.best
    if best is not None and best.effect != NOISE_MODEL and math.isfinite(c.criterion) and c.criterion > best.criterion:
        return f"{best.effect} has the lower BIC"
    return "the rule did not name it"


def _bar_note(report: Any, c: Any) -> tuple[str, str]:
    """The bar's kind (named, held, noise, significant, other) and its text."""
    level = _level(report)
    p_text = f"p {_p(c.p_value)}"
    if c.effect in _named(report):
        return "named", _named_note(report, c)
    if c.effect == NOISE_MODEL:
        one_step = f"RMSE {c.prediction_rmse:.3g}, " if math.isfinite(c.prediction_rmse) else ""
        return "noise", f"noise model: judged one step ahead ({one_step}{p_text}); not named"
    reason = _held_reason(report, c)
    if reason:
        return "held", f"{_pct(c.gap_closed).strip()}, {p_text}; not named: {reason}"
    significant = math.isfinite(c.p_value) and c.p_value < level
    share = _pct(c.gap_closed).strip()
    return ("significant", f"{share}, {p_text}") if significant else ("other", f"{share}, {p_text} (not significant)")


def _shown_rows(report: Any) -> list[Any]:
    """The candidates drawn: the first ``SHOWN`` in rank order, and any named, held back or
    noise model after them."""
    held = report.details.closing_not_named if report.details is not None else {}
    return [
        c for i, c in enumerate(report.ranking)
        if i < SHOWN or c.effect in _named(report) or c.effect in held or c.effect == NOISE_MODEL or _held_reason(report, c)
    ]  # fmt: skip


COLORS = {"named": "#4daf4a", "held": "#ff9f3f", "significant": "0.6", "other": "0.82", "noise": "none"}


def _plot_ranking(report: Any, ax: Any) -> None:
    if not report.ranking:
        ax.text(0.5, 0.5, _no_candidates(report), ha="center", va="center", transform=ax.transAxes, fontsize=9, wrap=True)
        ax.set_title("Candidates", fontsize=10)
        ax.set_xticks([])
        ax.set_yticks([])
        return
    rows = _shown_rows(report)
    notes = [_bar_note(report, c) for c in rows]
    pos = np.arange(len(rows))
    raw = np.array([0.0 if c.effect == NOISE_MODEL or not math.isfinite(c.gap_closed) else c.gap_closed for c in rows])
    closed = np.clip(raw, -0.25, 1.1)  # a tiny gap gives huge shares either way: show them clipped
    ax.barh(pos, closed, color=[COLORS[kind] for kind, _ in notes], height=0.75)
    ax.set_yticks(pos)
    ax.set_yticklabels([c.effect for c in rows], fontsize=7)
    for label, (kind, _) in zip(ax.get_yticklabels(), notes):
        if kind == "named":
            label.set_fontweight("bold")
    ax.set_ylim(len(rows) - 0.5, -0.5)  # best first
    ax.axvline(CLOSE_ENOUGH, color="k", ls="--", lw=0.8)
    ax.axvline(1.0, color="0.45", lw=0.8)
    lo, hi = min(0.0, float(closed.min()) - 0.05), max(1.05, float(closed.max()) + 0.05)
    ax.set_xlim(lo, hi)
    _bar_texts(ax, pos, closed, [text for _, text in notes], (lo, hi))
    clipped = ", clipped" if np.any(closed != raw) else ""
    first = "; at the first step" if len(report.steps) > 1 else ""
    ax.set_xlabel(f"share of the gap closed on validation{first}{clipped} (dashed: half, the rule's threshold)", fontsize=9)
    ax.set_title("Candidates, best first: which were named, and why not the others", fontsize=10)
    ax.grid(alpha=0.3, axis="x")


def _bar_texts(ax: Any, pos: Any, closed: Any, texts: list[str], xlim: tuple[float, float]) -> None:
    """Each bar's note after the bar's end, or from the bar's root where it does not fit there,
    shortened to the room it has."""
    from matplotlib import patheffects

    lo, hi = xlim
    fig = ax.figure
    per_unit = ax.get_position().width * fig.get_figwidth() * 72 / (hi - lo)  # points per unit of the x axis
    halo = [patheffects.withStroke(linewidth=2.2, foreground="white", alpha=0.7)]  # legible across the lines at half and 1
    for y, v, text in zip(pos, closed, texts):
        x = max(float(v), 0.0) + 0.015
        if _width_pt(text, 7) > (hi - x) * per_unit - 4:
            x = 0.015  # over the bar: black on its light colour
        shown = _fitted(text, 7, (hi - x) * per_unit - 4)
        ax.text(x, y, shown, va="center", ha="left", fontsize=7, color="k", clip_on=True, path_effects=halo, zorder=4)


def _width_pt(text: str, size: float, weight: str = "normal") -> float:
    """The drawn width of a one-line text in points (its glyphs' outline: no renderer needed)."""
    from matplotlib.font_manager import FontProperties
    from matplotlib.textpath import TextPath

    if not text.strip():
        return 0.0
    return float(TextPath((0, 0), text, size=size, prop=FontProperties(weight=weight)).get_extents().width)


def _fitted(text: str, size: float, room: float, weight: str = "normal") -> str:
    """The text, shortened at a word with " ..." until it is at most ``room`` points wide."""
    width = len(text)
    shown = text
    while width > 12 and _width_pt(shown, size, weight) > room:
        width -= 3
        shown = textwrap.shorten(text, width, placeholder=" ...")
    return shown


def _no_candidates(report: Any) -> str:
    """Why the candidates panel is empty."""
    if report.best_effect == "none" or not report.gap > 0:
        return (
            "No candidate refitted: the nominal model's validation error\n"
            "is at the noise floor, there is no gap to close"
        )
    return (
        f"No candidate refitted: this report holds none\n(verdict: {report.best_effect}; "
        "diagnose refits every effect\nof `candidates` unless the nominal fit failed)"
    )


# ---------------------------------------------------------------------- title and footnote


def _headline(report: Any, view: _View) -> str:
    """The verdict in one line, in the rule's terms: the effect(s) named and why."""
    text = _headline_text(report, view)
    fit = report.details.nominal_fit if report.details is not None else ""
    if fit not in ("", "converged"):
        text += " (nominal fit did not converge)"
    return "Diagnosis: " + text


def _headline_text(report: Any, view: _View) -> str:
    effects, best = _named(report), report.best
    lattice = report.details.lattice if report.details is not None else ""
    if report.best_effect == "none":
        return (
            f"none: no gap beyond the noise (nominal RMSE {view.e(report.nominal_validation_rmse):.4g}, "
            f"noise std {view.e(report.noise_std):.4g})"
        )
    if report.best_effect == "unexplained":
        return "unexplained: a significant gap that no candidate explains by the rule (the bars say why)"
    names = " + ".join(effects) if effects else report.best_effect
    if report.best_effect == "quantization" and lattice and "(not named" not in lattice:
        return f"{names} named: the measured output lies on a lattice (see below)"
    if len(report.steps) > 1:
        last = view.e(report.steps[-1].validation_rmse)
        return f"{names} named step by step: validation RMSE {view.e(report.nominal_validation_rmse):.4g} -> {last:.4g} (steps on the bars)"
    if best is None:
        return f"{names} named"
    if best.effect == NOISE_MODEL:
        return f"{names} named: a noise model that predicts the residual one step ahead (p = {_p(best.p_value)})"
    _, st = _step_of(report, best.effect)
    share, p = (st.gap_closed, st.p_value) if st is not None else (best.gap_closed, best.p_value)
    if len(effects) > 1:  # the effect after it named by its own check (the lattice): say it shortly
        why = ", lowest BIC" if _lowest_bic(report, best) else ""
        return f"{names} named: {best.effect} closes {_pct(share).strip()} of the gap (p = {_p(p)}{why})"
    why = ", the lowest BIC of the significant candidates" if _lowest_bic(report, best) else ""
    return f"{names} named: closes {_pct(share).strip()} of the gap (p = {_p(p)}){why}"


def _footnote(report: Any, view: _View, width_chars: int) -> str:
    """The rule, and the verdict's details (the steps, the secondary check, the reasons)."""
    level = _level(report)
    rule = (
        f"How an effect is named: its validation improvement is significant (p < {level:.2g}), it has the lowest BIC of the "
        f"significant deterministic candidates, and it closes at least half of the gap ({100 * CLOSE_ENOUGH:.0f} %); colored_noise, "
        "a noise model, is judged by its one-step prediction instead (its gap closed is 0 by construction). "
        "The residual signature an effect predicts is a secondary check, not part of the rule."
    )
    parts = (rule, _verdict_details(report, view), _held_text(report))
    return "\n".join(textwrap.fill(p, width=max(width_chars, 60)) for p in parts if p)


def _held_text(report: Any) -> str:
    """The candidates that close half the gap but were not named, and why (for the footnote)."""
    if report.best_effect == "unexplained":  # the verdict says it already
        return ""
    held = [(c.effect, _held_reason(report, c)) for c in report.ranking]
    said = [f"{effect} ({reason})" for effect, reason in held if reason]
    return "Closing half the gap but not named: " + "; ".join(said) + "." if said else ""


def _steps(report: Any) -> list[tuple[str, float, float, float]]:
    """(effect, share of the gap or of the rest closed, p-value, validation RMSE) per named
    effect: the composition's steps, or the best candidate's numbers."""
    if report.steps:
        return [(st.effect, st.gap_closed, st.p_value, st.validation_rmse) for st in report.steps]
    best = report.best
    return [(best.effect, best.gap_closed, best.p_value, best.validation_rmse)] if best is not None else []


def _verdict_details(report: Any, view: _View) -> str:
    """The verdict's details for the footnote."""
    best, steps = report.best, _steps(report)
    if report.best_effect == "none":  # the title says it all
        fit = report.details.nominal_fit if report.details is not None else ""
        return f"Note: {fit}." if fit not in ("", "converged") else ""
    if report.best_effect == "unexplained" or best is None or not steps:
        return f"Verdict: {report.verdict()}"
    said = [
        f"{e} predicts the {'residual' if i == 0 else 'rest'} one step ahead (p = {_p(p)})"
        if e == NOISE_MODEL
        else f"{e} closes {_pct(share).strip()} of the {'gap' if i == 0 else 'rest'} (p = {_p(p)}, validation RMSE {view.e(rmse):.4g})"
        for i, (e, share, p, rmse) in enumerate(steps)
    ]
    text = "Named: " + ", then ".join(said) + f"; the nominal model's validation RMSE is {view.e(report.nominal_validation_rmse):.4g}."
    held = report.details.closing_not_named if report.details is not None else {}
    if best.effect in held:
        text += (
            f" At the first step {best.effect} was held back ({held[best.effect]}); it is named as the rule's provisional "
            "effect (significant, lowest BIC, closing over a quarter of the gap) since the model named closes half of the gap."
        )
    lattice = report.details.lattice if report.details is not None else ""
    if lattice and "quantization" in _named(report):
        text += f" quantization: {lattice}."
    if best.effect != NOISE_MODEL:
        sig = "is gone" if best.signature_removed else "still shows in its residual"
        text += f" Secondary check: the residual signature {best.effect} predicts {sig}."
    fit = report.details.nominal_fit if report.details is not None else ""
    return text + (f" Note: {fit}." if fit not in ("", "converged") else "")


# ---------------------------------------------------------------------- before and after


def _shown_candidate(report: Any) -> tuple[Any, Any, str]:
    """The augmented simulation for the before/after panel: the named effects', else the best
    candidate that changes the simulation, simulated again from the state that fits the record."""
    n = report.n_validation
    if report.best is not None and report.y_best is not None and np.asarray(report.y_best).size == n:
        names = " + ".join(_named(report))
        return report.best, np.asarray(report.y_best), f"augmented: {names}"
    top = next((c for c in report.ranking if c.effect != NOISE_MODEL and c.model is not None), None)
    if top is None:
        return None, None, ""
    u, y = np.asarray(report.u_val, dtype=float), np.asarray(report.y_val, dtype=float)
    kept = getattr(top, "validation_output", None)
    if kept is not None and np.asarray(kept).size == n:  # the ranking's own run, each record from its start
        return top, np.asarray(kept, dtype=float), f"best candidate, not named: {top.effect}"
    try:
        if hasattr(top.model, "simulator"):
            from ._start import estimated_start

            span = (float(y.min()), float(y.max()))
            sim = top.model.simulator()
            out, _ = estimated_start(lambda v, y0, held: sim(v, y0, held), u, y, span)
        else:
            out = top.model.simulate(u)
    except Exception:  # a candidate that cannot be simulated again is left out, not drawn wrong
        return None, None, ""
    out = np.asarray(out, dtype=float)
    if out.size != n or not np.all(np.isfinite(out)):
        return None, None, ""
    label = f"best candidate, not named: {top.effect}"
    # the report does not keep where the estimation record ended (t0 of a time-dependent effect):
    # say so if this run is not the one the ranking scored
    again = float(np.sqrt(np.mean((y - out)[report.warmup :] ** 2)))
    if math.isfinite(top.validation_rmse) and abs(again - top.validation_rmse) > 0.02 * top.validation_rmse:
        label += " (simulated again from t = 0, not the ranking's run)"
    return top, out, label


def _window_start(err2: NDArray[np.float64], w: int, runs: _Records, warmup: int) -> int:
    """The start of the ``w`` samples of most nominal error energy, within one record."""
    n = err2.size
    if n - warmup <= w:
        return min(warmup, max(n - w, 0))
    energy = np.convolve(err2, np.ones(w), mode="valid")
    for b in runs.starts[1:]:  # a window across a record start would join two runs
        energy[max(b - w + 1, 0) : b] = -1.0
    energy[:warmup] = -1.0
    return int(np.argmax(energy))


def _plot_before_after(report: Any, ax: Any, window: int, view: _View, runs: _Records) -> None:
    y = np.asarray(report.y_val)
    nominal = np.asarray(report.y_nominal)
    n = y.size
    w = int(np.clip(window, 10, max(n - report.warmup, 10)))
    err2 = (y - nominal) ** 2
    err2[~runs.keep] = 0.0
    start = _window_start(err2, w, runs, int(report.warmup))
    sl = slice(start, min(start + w, n))
    t = view.t(np.arange(n)[sl])
    rmse_n = float(view.e(np.sqrt(np.mean((y[sl] - nominal[sl]) ** 2))))
    ax.plot(t, view.y(y[sl]), color="k", lw=1.2, alpha=0.6, label="measured")
    ax.plot(t, view.y(nominal[sl]), color="C0", lw=1.0, label=f"nominal (RMSE {rmse_n:.3g})")
    _, best, label = _shown_candidate(report)
    if best is not None:
        rmse_b = float(view.e(np.sqrt(np.mean((y[sl] - best[sl]) ** 2))))
        label = textwrap.fill(f"{label} (RMSE {rmse_b:.3g})", width=70)  # within the panel
        ax.plot(t, view.y(best[sl]), color="C2", lw=1.0, ls="--", label=label)
    else:
        label = "no augmented model to show: " + ("no gap" if report.best_effect == "none" else "no candidate")
        ax.plot([], [], " ", label=label)
    ax.set_title("Before/after where the nominal error is largest (RMSE on this window)", fontsize=10)
    ax.set_xlabel(view.time_label)
    ax.set_ylabel(view.output)
    _headroom(ax, 0.3)
    ax.legend(fontsize="x-small", framealpha=0.85, loc="upper center", ncol=2 if best is None else 1)
    ax.grid(alpha=0.3)
