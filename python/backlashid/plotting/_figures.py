"""Figures (matplotlib is an optional extra: ``pip install backlashid[plot]``)."""

from __future__ import annotations

import functools
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docstrings import PLOT, fill
from .._optional import pyplot
from .._validation import as_signal, one_record
from ..models import GeneralBacklash

__all__ = [
    "plot_branches_comparison",
    "plot_characteristic",
    "plot_residuals",
    "plot_simulation",
    "plot_trajectories",
]

# A record longer than this many samples is drawn as a window plus its whole error trace.
WINDOW = 1000


def _legend_outside(ax: Any, **kw: Any) -> Any:
    """A legend to the right of the axes, never over the data."""
    return ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize="small", **kw)


def _with_unit(name: str, unit: str | None) -> str:
    """``name [unit]``; without a unit, say the values are in the record's own units."""
    return f"{name} [{unit}]" if unit else f"{name} (units of the record)"


def _stacked(label: str, width: int = 30) -> str:
    """A y-axis label longer than ``width`` characters broken so that it does not run past its
    panel into the next one: its unit (``[...]``, or ``(units of the record)``) on the last
    line, whole, and the name before it in lines of at most about ``width`` characters (a name
    of up to ``width`` characters and its unit: two lines)."""
    import textwrap

    if len(label) <= width:
        return label
    cut = label.find(" [")
    if cut <= 0:
        cut = label.rfind(" (")
    name, unit = (label[:cut], label[cut + 1:]) if cut > 0 else (label, "")
    return "\n".join([*(textwrap.wrap(name, width) or [name]), *([unit] if unit else [])])


def _time(n: int, dt: float | None, time_unit: str) -> tuple[NDArray[np.float64], str]:
    """The time axis of n samples and its label (in samples when dt is None or 1)."""
    if dt is None or dt == 1.0:
        return np.arange(n, dtype=np.float64), "sample of the record"
    return np.arange(n) * float(dt), f"time from the record's start [{time_unit}]"


def _worst_window(error: NDArray[np.float64], warmup: int, window: int) -> slice:
    """The window of ``window`` samples after the warm-up with the largest error energy."""
    e2 = np.square(error)
    e2[:warmup] = 0.0
    if len(e2) - warmup <= window:
        return slice(warmup, len(e2))
    energy = np.convolve(e2[warmup:], np.ones(window), mode="valid")
    start = warmup + int(np.argmax(energy))
    return slice(start, start + window)


def _spectrum(e: NDArray[np.float64], dt: float, segment: int = 2048) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Welch power spectral density (Hann windows, half overlap) of e: frequencies, density."""
    from numpy.lib.stride_tricks import sliding_window_view

    n = min(segment, len(e))
    frames = sliding_window_view(e - e.mean(), n)[:: max(n // 2, 1)]
    taper = np.hanning(n) if n > 2 else np.ones(n)
    power = np.mean(np.abs(np.fft.rfft(frames * taper, axis=1)) ** 2, axis=0)
    density = 2.0 * power * dt / max(float(np.sum(taper**2)), 1e-300)
    return np.fft.rfftfreq(n, dt), density


def plot_characteristic(
    backlash: GeneralBacklash,
    x: ArrayLike | None = None,
    y: ArrayLike | None = None,
    *,
    x_range: tuple[float, float] | None = None,
    ax: Any = None,
    title: str | None = None,
    unit: str | None = None,
    warmup: int = 0,
) -> Any:
    """Draw the branches L(x), R(x) of a general backlash, as in the paper's Figs 1, 4 and 7.

    When x and y are given, the path (x(t), y(t)) of a simulation is drawn under the branches
    and the axes are limited to its range; each branch is solid where the backlash moves along
    it on that record (f1, f2 of eq 12-13: L while x decreases, R while it increases) and
    dotted elsewhere. The legend sits to the right of the axes and states c_L and c_R. A dead
    band narrow beside the axis (under a tenth of the x range) gets an inset that
    zooms on x in [-c_L, c_R] with a margin of 1.5 times its width, -c_L and c_R dashed.

    Parameters
    ----------
    backlash : GeneralBacklash
        The backlash whose left branch L(x) and right branch R(x) (eq 4-5) are drawn.
    x : array_like, optional
        Input of the backlash over time (the internal signal x(t) of a cascade, eq 16).
    y : array_like, optional
        Its output y(t), as long as x.
    x_range : tuple of float, optional
        (low, high) of the x axis [default: the range of x, else around the dead band].
    ax : matplotlib.axes.Axes, optional
        Axes to draw on [default: a new figure].
    title : str, optional
        Title [default: the dead-band widths c_L and c_R].
    unit : str, optional
        Unit of x and y for the axis labels (with m_L1 = 1 both are in the units of the
        backlash output; "model units" for a scaled record) [default: not stated].
    warmup : int, default 0
        Samples at the start of x and y left out of the drawn path (an unknown initial state:
        the start-up transient of a simulated x against a measured y draws a stray streak).

    Returns
    -------
    matplotlib.axes.Axes
        The axes drawn on.

    Raises
    ------
    BacklashIdError
        If matplotlib is not installed (the ``plot`` extra).

    Examples
    --------
    >>> model = bid.example1()
    >>> sim = model.simulate(np.sin(np.arange(200) / 10), internals=True)
    >>> ax = bid.app.plot_characteristic(model.backlash, sim.x, sim.output)
    >>> [line.get_label() for line in ax.lines[:2]]
    ['L(x)', 'R(x)']
    """
    plt = pyplot()
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 5))
    points = None
    if x is not None and y is not None:
        xs, ys = as_signal(x, "x"), as_signal(y, "y")
        skip = min(max(int(warmup), 0), max(len(xs) - 1, 0), max(len(ys) - 1, 0))
        xs, ys = xs[skip:], ys[skip:]  # the start-up transient left out
        points = (xs, ys)
        ax.scatter(xs, ys, s=4, color="0.55", alpha=0.6, lw=0, label="simulated (x(t), y(t))", zorder=1)
        lo, hi = float(xs.min()), float(xs.max())
        y_lo, y_hi = float(ys.min()), float(ys.max())
    else:
        lo, hi = -2.0 * (backlash.c_left + 1.0), 2.0 * (backlash.c_right + 1.0)
        y_lo, y_hi = -np.inf, np.inf
    if x_range is not None:
        lo, hi = x_range
    grid, left, right = backlash.characteristic(lo, hi, 600)
    pad = 0.05 * (y_hi - y_lo) if np.isfinite(y_hi - y_lo) else 0.0
    # with a record: each branch solid where the backlash moves along it (f1, f2 of eq 12-13),
    # dotted over the rest of the record's range
    spans = _active_ranges(backlash, x, (lo, hi)) if x is not None and y is not None else [(lo, hi), (lo, hi)]
    rest = []
    for values, name, style, span in ((left, "L(x)", "C0", spans[0]), (right, "R(x)", "C3", spans[1])):
        shown = np.where((values >= y_lo - pad) & (values <= y_hi + pad), values, np.nan)
        active = np.zeros(grid.shape, dtype=bool) if span is None else (grid >= span[0]) & (grid <= span[1])
        ax.plot(grid, np.where(active, shown, np.nan), color=style, lw=2, label=name, zorder=2)
        rest.append((np.where(active, np.nan, shown), style))
    if x is not None and y is not None:
        for values, style in rest:
            ax.plot(grid, values, color=style, lw=1, ls=":", zorder=2)
        ax.plot([], [], color="0.3", lw=1, ls=":", label="branch where it is not active\non this record")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.axvline(0.0, color="k", lw=0.5)
    ax.set_xlabel(_with_unit("x(t), input of the backlash", unit))
    ax.set_ylabel(_with_unit("y(t), output of the backlash", unit))
    ax.set_title(title or f"General backlash, c_L = {backlash.c_left:.3g}, c_R = {backlash.c_right:.3g}")
    in_unit = f" [{unit}]" if unit else ""
    ax.plot([], [], " ", label=f"dead band -c_L <= x <= c_R:\nc_L = {backlash.c_left:.3g}, c_R = {backlash.c_right:.3g}{in_unit}")
    _legend_outside(ax)
    ax.grid(alpha=0.3)
    _dead_band_inset(ax, backlash, points)
    return ax


# where an inset may go, in axes fractions (x0, y0, width, height), the first empty one is taken
_CORNERS = ((0.1, 0.52, 0.36, 0.36), (0.6, 0.1, 0.36, 0.36), (0.6, 0.52, 0.36, 0.36), (0.1, 0.1, 0.36, 0.36))


def _emptiest_corner(ax: Any, xs: NDArray[np.float64], ys: NDArray[np.float64]) -> tuple[float, float, float, float]:
    """The corner of ax (with room for an inset's tick labels) that covers fewest of the points."""
    (x0, x1), (y0, y1) = ax.get_xlim(), ax.get_ylim()
    fx, fy = (xs - x0) / (x1 - x0), (ys - y0) / (y1 - y0)

    def covered(rect: tuple[float, float, float, float]) -> int:
        left, bottom, width, height = rect
        inside = (fx >= left - 0.1) & (fx <= left + width + 0.02) & (fy >= bottom - 0.08) & (fy <= bottom + height + 0.08)
        return int(np.count_nonzero(inside))

    return min(_CORNERS, key=covered)


def _dead_band_inset(ax: Any, backlash: GeneralBacklash, points: tuple[NDArray[np.float64], NDArray[np.float64]] | None) -> Any:
    """An inset of ax that zooms on the dead band -c_L <= x <= c_R (a margin of 1.5 times its
    width on each side, less if the zoom would span a quarter of the x axis), -c_L and c_R
    dashed; None when the dead band has no width or spans a tenth of the x axis or more (it is
    visible without)."""
    lo_main, hi_main = ax.get_xlim()
    span = hi_main - lo_main
    edges = sorted((-float(backlash.c_left), float(backlash.c_right)))
    width = edges[1] - edges[0]
    if not np.isfinite(width) or width <= 1e-9 * span or width >= 0.1 * span:
        return None
    margin = min(1.5 * width, (0.24 * span - width) / 2)
    lo, hi = edges[0] - margin, edges[1] + margin
    grid, left, right = backlash.characteristic(lo, hi, 400)
    values = np.concatenate([left, right])
    values = values[np.isfinite(values)]
    y_lo, y_hi = (float(values.min()), float(values.max())) if values.size else (-width, width)
    pad = 0.1 * (y_hi - y_lo) if y_hi > y_lo else width
    y_lo, y_hi = y_lo - pad, y_hi + pad
    # the corner with the fewest data: the path of the record and the branches over the main axes
    main_grid, main_left, main_right = backlash.characteristic(lo_main, hi_main, 200)
    xs_all, ys_all = np.concatenate([main_grid, main_grid]), np.concatenate([main_left, main_right])
    if points is not None:
        xs_all, ys_all = np.concatenate([xs_all, points[0]]), np.concatenate([ys_all, points[1]])
    inset = ax.inset_axes(_emptiest_corner(ax, xs_all, ys_all))
    if points is not None:
        near = (points[0] >= lo) & (points[0] <= hi) & (points[1] >= y_lo) & (points[1] <= y_hi)
        inset.scatter(points[0][near], points[1][near], s=4, color="0.55", alpha=0.6, lw=0, zorder=1)
    inset.plot(grid, left, color="C0", lw=1.6, zorder=2)
    inset.plot(grid, right, color="C3", lw=1.6, zorder=2)
    for edge in (-float(backlash.c_left), float(backlash.c_right)):
        inset.axvline(edge, color="0.25", ls="--", lw=0.8)
    inset.axhline(0.0, color="k", lw=0.5)
    inset.set_xlim(lo, hi)
    inset.set_ylim(y_lo, y_hi)
    for axis, (low, high) in ((inset.xaxis, (lo, hi)), (inset.yaxis, (y_lo, y_hi))):  # only ticks that are drawn
        axis.set_ticks([t for t in axis.get_ticklocs() if low <= t <= high])
    inset.set_title("zoom on the dead band\n(dashed: x = -c_L and x = c_R)", fontsize="x-small")
    inset.tick_params(labelsize="x-small")
    inset.grid(alpha=0.3)
    ax.indicate_inset_zoom(inset, edgecolor="0.3")
    return inset


def _active_ranges(backlash: GeneralBacklash, x: ArrayLike | None, x_range: tuple[float, float]) -> list[tuple[float, float] | None]:
    """Where the left and the right branch are active on the record x (f1 and f2 of eq 12-13:
    the operator moves along L while x decreases in contact, along R while it increases), or
    the whole x_range of both when no record is given; None for a branch never active."""
    if x is None:
        return [x_range, x_range]
    xs = as_signal(x, "x")
    signals = backlash.switching(xs)
    return [(float(xs[f].min()), float(xs[f].max())) if f.any() else None for f in (signals.f1, signals.f2)]


@fill(plot=PLOT)
def plot_branches_comparison(
    true_backlash: GeneralBacklash,
    estimated: GeneralBacklash,
    x_range: tuple[float, float],
    *,
    x: ArrayLike | None = None,
    x_estimated: ArrayLike | None = None,
    unit: str | None = None,
    ax: Any = None,
    title: str | None = None,
) -> Any:
    """Draw true and estimated branches on one plot, as in the paper's Figs 4 and 7.

    Given the record's internal signal x(t), each branch is drawn only where the backlash
    actually moves along it (the left branch L where x decreases in contact, f1 of eq 12; the
    right branch R where it increases, f2 of eq 13), not over the whole range of x.

    Parameters
    ----------
    true_backlash : GeneralBacklash
        The true backlash (solid lines).
    estimated : GeneralBacklash
        The estimate (dashed lines).
    x_range : tuple of float
        (low, high) of the backlash input x shown; the branches span it when no record is given.
    x : array_like, optional
        The true system's backlash input x(t) on the record: the true branches are drawn over
        the range where they are active on it.
    x_estimated : array_like, optional
        The estimated model's x(t) on the same record, for the estimated branches [default: x].
    unit : str, optional
        Unit of x and y for the axis labels [default: not stated].
    {plot}

    Examples
    --------
    >>> truth = bid.example1().backlash
    >>> ax = bid.app.plot_branches_comparison(truth, truth, (-2.0, 2.0))
    >>> len(ax.lines)  # L and R, true and estimated, and the two axis lines
    6
    """
    plt = pyplot()
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 5))
    records = (x, x if x_estimated is None else x_estimated)
    # the truth wide and light, the estimate thin, dashed and dark on top: both stay visible where they agree
    looks = (("-", 4.0, 0.45, ("C0", "C3")), ("--", 1.6, 1.0, ("navy", "darkred")))
    for bl, record, (style, lw, alpha, colors), label in zip((true_backlash, estimated), records, looks, ("true", "estimated")):
        ranges = _active_ranges(bl, record, x_range)
        for span, name, color, branch in zip(ranges, ("L(x)", "R(x)"), colors, ("left", "right")):
            if span is None:
                ax.plot([], [], style, color=color, lw=lw, alpha=alpha, label=f"{name} {label}: never active")
                continue
            grid = np.linspace(span[0], span[1], 400)
            values = bl.left(grid) if branch == "left" else bl.right(grid)
            ax.plot(grid, values, style, color=color, lw=lw, alpha=alpha, label=f"{name} {label}")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.axvline(0.0, color="k", lw=0.5)
    ax.set_xlim(*x_range)
    ax.set_xlabel(_with_unit("x(t), input of the backlash", unit))
    ax.set_ylabel(_with_unit("y(t), output of the backlash", unit))
    ax.set_title(title or "General backlash: true and estimated")
    if x is not None:
        ax.plot([], [], " ", label="each branch where it is active:\nL while x decreases (f1),\nR while x increases (f2)")
    _legend_outside(ax)
    ax.grid(alpha=0.3)
    return ax


@fill(plot=PLOT)
def plot_trajectories(
    history: ArrayLike,
    names: list[str],
    shown: list[str],
    *,
    truth: dict[str, float] | None = None,
    final: dict[str, float] | None = None,
    refinement_steps: int | None = None,
    ax: Any = None,
    title: str | None = None,
) -> Any:
    """Draw parameter estimates over the iterations, as in the paper's Figs 5, 6 and 8-10.

    Dotted lines mark the true values when given. The final estimates (after the output-error
    refinement, the values the fit prints) are stars one step after the last iteration, joined
    to it by a dashed segment: the curves end at the printed estimates. The legend, to the right
    of the axes, names every curve and explains the line styles.

    Iterates that diverged do not set the y axis: when some lie far from the final estimates
    (the last iterates without ``final``) and the true values, the y limits span those values
    with a margin (their spread, at least half their magnitude) and the iterates within half
    that range beyond; the iterates beyond the limits are marked at the axis edge (triangles
    pointing up or down, in the curve's colour), as the legend says.

    Parameters
    ----------
    history : array_like
        Estimates, one row per iteration, one column per parameter (``FitResult.history``).
    names : list of str
        The parameter names of the columns (``FitResult.names``: a1.., b1.., c_L, m_L2.., ...).
    shown : list of str
        The parameters to draw.
    truth : dict of str to float, optional
        True values by name.
    final : dict of str to float, optional
        Final estimates by name (``FitResult.parameters``).
    refinement_steps : int, optional
        Levenberg-Marquardt steps of the refinement (``FitResult.refinement_steps``), named in
        the legend.
    {plot}

    Examples
    --------
    >>> history = np.array([[0.5, 0.1], [0.65, 0.3], [0.7, 0.34]])
    >>> ax = bid.app.plot_trajectories(history, ["a1", "c_L"], ["a1"], truth={"a1": 0.7})
    >>> ax.lines[0].get_ydata().tolist()
    [0.5, 0.65, 0.7]
    """
    plt = pyplot()
    if ax is None:
        _, ax = plt.subplots(figsize=(6, 4))
    h = np.asarray(history, dtype=np.float64)
    its = np.arange(1, len(h) + 1)
    last = len(h) + 1
    for k, name in enumerate(shown):
        color = f"C{k % 10}"
        ax.plot(its, h[:, names.index(name)], "-o", ms=3, color=color, label=name)
        if truth is not None:
            ax.axhline(truth[name], color=color, ls=":", lw=1)
        if final is not None:
            ax.plot([len(h), last], [h[-1, names.index(name)], final[name]], "--", lw=1, color=color)
            ax.plot([last], [final[name]], "*", ms=10, color=color)
    columns = h[:, [names.index(name) for name in shown]] if shown else np.zeros((len(h), 0))
    anchors = [*(final[name] for name in shown if final is not None), *(truth[name] for name in shown if truth is not None)]
    if final is None and len(h):
        anchors += list(columns[-1])
    limits = _focus_limits(columns, np.asarray(anchors, dtype=np.float64))
    beyond = False
    if limits is not None:
        ax.set_ylim(*limits)
        for k in range(columns.shape[1]):
            beyond |= _edge_marks(ax, its, columns[:, k], f"C{k % 10}")
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    if final is not None:  # integer ticks, the last one replaced by "final" (one step after the last iteration)
        ax.set_xlim(0.5, last + 0.5)
        ticks = [int(t) for t in ax.get_xticks() if 1 <= t <= last - max(1.0, 0.08 * last)]
        ax.set_xticks([*ticks, last], [*map(str, ticks), "final"])
    ax.set_xlabel(f"iteration ({len(h)} in all)" + (", then the final estimate" if final is not None else ""))
    ax.set_ylabel("estimate (value of the parameter)")
    ax.set_title(title or "Parameter estimates")
    from matplotlib.lines import Line2D

    handles, labels = ax.get_legend_handles_labels()
    if truth is not None:
        handles.append(Line2D([], [], ls=":", color="0.3", lw=1))
        labels.append("true value (dotted)")
    if final is not None:
        steps = "" if refinement_steps is None else f", {refinement_steps} LM step{'' if refinement_steps == 1 else 's'}"
        handles.append(Line2D([], [], ls="--", marker="*", color="0.3", lw=1, ms=8))
        labels.append(f"final estimate after the\noutput-error refinement{steps}")
    if beyond:
        handles.append(Line2D([], [], ls="none", marker="^", color="0.3", ms=6))
        labels.append("iterates beyond the axis\nmarked at its edge")
    _legend_outside(ax, handles=handles, labels=labels, ncol=1 if len(shown) <= 8 else 2)
    ax.grid(alpha=0.3)
    return ax


def _focus_limits(values: NDArray[np.float64], anchors: NDArray[np.float64]) -> tuple[float, float] | None:
    """The y limits of trajectories ``values`` (one column per curve) that end at ``anchors``
    (the final estimates and the true values): the anchors' range with a margin of their spread
    (at least half their magnitude), widened to the values within half that range beyond it;
    None when no value lies farther (nothing diverged: the axes scale to all of them)."""
    anchors = anchors[np.isfinite(anchors)]
    finite = values[np.isfinite(values)]
    if not anchors.size or not finite.size:
        return None
    pad = max(float(np.ptp(anchors)), 0.5 * float(np.max(np.abs(anchors))))
    if pad == 0.0:
        pad = 0.5 * float(np.median(np.abs(finite))) or 1.0
    lo, hi = float(anchors.min()) - pad, float(anchors.max()) + pad
    reach = 0.5 * (hi - lo)
    near = finite[(finite >= lo - reach) & (finite <= hi + reach)]
    if near.size == finite.size:
        return None
    lo, hi = min(lo, float(near.min()) if near.size else lo), max(hi, float(near.max()) if near.size else hi)
    margin = 0.04 * (hi - lo)
    return lo - margin, hi + margin


def _edge_marks(ax: Any, its: NDArray[np.int_], values: NDArray[np.float64], color: str) -> bool:
    """Triangles at the top and bottom edge of ax (pointing up and down) at the iterations whose
    value lies beyond the y limits; they follow the limits when these change later (a shared
    axis, a caller's set_ylim). Whether any lies beyond the limits now."""
    marks = _edge_marks_class()
    top = ax.add_line(marks(its, values, +1, color=color, ls="none", marker="^", ms=7, clip_on=False,
                            transform=ax.get_xaxis_transform(), label="_beyond the axis", zorder=4))
    bottom = ax.add_line(marks(its, values, -1, color=color, ls="none", marker="v", ms=7, clip_on=False,
                               transform=ax.get_xaxis_transform(), label="_beyond the axis", zorder=4))
    top.place()
    bottom.place()
    return bool(len(top.get_xdata()) or len(bottom.get_xdata()))


@functools.cache
def _edge_marks_class() -> type:
    """A Line2D that places its markers at the edge where values pass the y limits, at each draw."""
    from matplotlib.lines import Line2D

    class EdgeMarks(Line2D):  # type: ignore[misc]
        def __init__(self, x: NDArray[np.int_], values: NDArray[np.float64], side: int, **kw: Any) -> None:
            super().__init__([], [], **kw)
            self.set_in_layout(False)  # an empty line's box would sit at the figure's origin
            self.positions, self.values, self.side = np.asarray(x), np.asarray(values, dtype=np.float64), side

        def place(self) -> None:
            if self.axes is None:
                return
            lo, hi = sorted(self.axes.get_ylim())
            xs = self.positions[self.values > hi] if self.side > 0 else self.positions[self.values < lo]
            if not np.array_equal(xs, np.asarray(self.get_xdata())):
                self.set_data(xs, np.full(len(xs), 1.0 if self.side > 0 else 0.0))

        def draw(self, renderer: Any) -> None:
            self.place()
            super().draw(renderer)

    return EdgeMarks


@fill(plot=PLOT)
def plot_simulation(
    y: ArrayLike,
    y_sim: ArrayLike,
    *,
    warmup: int = 0,
    dt: float = 1.0,
    ylabel: str = "output",
    unit: str | None = None,
    time_unit: str = "s",
    window: int = WINDOW,
    band: tuple[ArrayLike, ArrayLike, str] | None = None,
    ax: Any = None,
    title: str | None = None,
) -> Any:
    """Draw the measured output against the free-run simulation, with the fit %.

    The fit % and RMSE count the samples from ``warmup`` on; the warm-up is shaded. A record
    longer than ``window`` samples is not drawn whole (its traces would hide each other): the
    figure shows the window of ``window`` samples with the largest error, the error
    (measured - simulated) over the whole record with that window marked, and the power
    spectra of the error and of the measured output. The legends sit to the right of the axes.

    Parameters
    ----------
    y : array_like
        Measured output.
    y_sim : array_like
        Free-run simulated output, as long as y.
    warmup : int, default 0
        Samples at the start left out of the fit % and RMSE (an unknown initial state).
    dt : float, default 1.0
        Sampling period in ``time_unit``: the time axis is in time (in samples when 1).
    ylabel : str, default "output"
        Name of the output signal for the axis labels.
    unit : str, optional
        Unit of the output for the axis labels [default: not stated].
    time_unit : str, default "s"
        Unit of ``dt``.
    window : int, default 1000
        Longest record drawn whole; longer ones show a window of this many samples.
    band : tuple of (array_like, array_like, str), optional
        A prediction band of the simulated output (lower, upper, label), shaded, e.g. from
        ``model.simulate(u, band=0.95)`` (:class:`backlashid.models.Prediction`).
    {plot}

    Examples
    --------
    >>> d = bid.example_data(bid.example1(), 300, seed=0)
    >>> ax = bid.app.plot_simulation(d.noisy, d.clean, warmup=20)
    >>> ax.lines[1].get_label()  # doctest: +ELLIPSIS
    'simulated (free run): fit 9... %, RMSE ...'
    """
    from .._measures import fit_percent, rmse

    plt = pyplot()
    ys, sims = as_signal(y, "y").ravel(), as_signal(y_sim, "y_sim").ravel()
    t, time_label = _time(len(ys), dt, time_unit)
    fit = fit_percent(ys, sims, warmup=warmup)
    err = rmse(ys, sims, warmup=warmup)
    rmse_text = f"RMSE {err:.4g}" + (f" {unit}" if unit else "")
    long = len(ys) > window and ax is None
    if ax is None and not long:
        _, ax = plt.subplots(figsize=(10, 3.8))
    elif long:
        fig = plt.figure(figsize=(11, 9.5), layout="constrained")
        ax, ax_err, ax_psd = fig.subplots(3, 1, height_ratios=[1.2, 1.0, 1.0])
    shown = _worst_window(ys - sims, warmup, window) if long else slice(0, len(ys))
    ax.plot(t[shown], ys[shown], color="k", lw=1.6, alpha=0.55, label="measured")
    if band is not None:
        lower, upper = as_signal(band[0], "band lower").ravel(), as_signal(band[1], "band upper").ravel()
        ax.fill_between(t[shown], lower[shown], upper[shown], color="C3", alpha=0.25, lw=0, label=band[2], zorder=1)
    ax.plot(t[shown], sims[shown], color="C3", lw=0.9, ls="--", label=f"simulated (free run): fit {fit:.1f} %, {rmse_text}")
    if warmup and shown.start < warmup:
        ax.axvspan(t[shown.start], t[warmup - 1], color="0.9", zorder=0, label=f"skipped transient ({warmup} samples)")
    ax.set_xlabel(time_label)
    ax.set_ylabel(_stacked(_with_unit(ylabel, unit)))
    heading = title or "Measured and simulated output"
    if long:
        heading += f"\nthe {window} of {len(ys)} samples where the error is largest (fit % and RMSE: whole record; the error below)"
    ax.set_title(heading)
    _legend_outside(ax)
    ax.grid(alpha=0.3)
    if long:
        _plot_error_panels(ys - sims, t, time_label, dt, warmup, shown, err, ylabel, unit, time_unit, ys, ax_err, ax_psd)
        if band is not None:  # where the band is visible: around the zero error
            ax_err.fill_between(t, lower - sims, upper - sims, color="C3", alpha=0.35, lw=0, zorder=3,
                                label="prediction band - simulated")
            _legend_outside(ax_err)
    return ax


def _plot_error_panels(e: NDArray[np.float64], t: NDArray[np.float64], time_label: str, dt: float, warmup: int, shown: slice,
                       err: float, ylabel: str, unit: str | None, time_unit: str, ys: NDArray[np.float64], ax_err: Any, ax_psd: Any) -> None:
    """The error over the whole record (the window marked) and the spectra of error and output."""
    if warmup:
        ax_err.axvspan(t[0], t[warmup - 1], color="0.9", zorder=0, label=f"skipped transient ({warmup} samples)")
    ax_err.axvspan(t[shown.start], t[shown.stop - 1], color="C1", alpha=0.25, lw=0, zorder=0, label="window shown above")
    ax_err.plot(t, e, color="C0", lw=0.4, label="measured - simulated")
    for sign in (-1.0, 1.0):
        ax_err.axhline(sign * err, color="k", ls="--", lw=0.8, label="+-RMSE" if sign > 0 else None)
    after = e[warmup:]
    limits = _error_limits(after, err)
    if limits is not None:  # scale to the evaluated samples, not the transient (drawn, but clipped)
        ax_err.set_ylim(*limits[:2])
        if limits[2]:
            ax_err.plot([], [], " ", label="error beyond the axis is clipped: the axis\nspans the bulk of the error after the warm-up")
    ax_err.set_xlabel(time_label)
    ax_err.set_ylabel(_stacked(_with_unit(f"measured - simulated {ylabel}", unit)))
    ax_err.set_title(f"Free-run simulation error over the whole record ({len(e)} samples)")
    _legend_outside(ax_err)
    ax_err.grid(alpha=0.3)
    in_samples = time_label.startswith("sample")
    step = 1.0 if in_samples else float(dt)
    f_unit = "cycles/sample" if in_samples else ("Hz" if time_unit == "s" else f"1/{time_unit}")
    for signal, color, label in ((ys[warmup:], "0.3", "measured output"), (after, "C0", "error (measured - simulated)")):
        if signal.size >= 8:
            f, density = _spectrum(signal, step)
            ax_psd.semilogy(f[1:], density[1:], color=color, lw=0.9, label=label)
    squared = f"{unit}²" if unit else "(units of the record)²"
    ax_psd.set_xlabel(f"frequency [{f_unit}]")
    per = f_unit if f_unit == "Hz" else f"({f_unit})"
    ax_psd.set_ylabel(_stacked(f"power spectral density [{squared}/{per}]"))
    ax_psd.set_title("Where the error lies in frequency (Welch spectra after the transient)")
    _legend_outside(ax_psd)
    ax_psd.grid(alpha=0.3, which="both")


def _error_limits(after: NDArray[np.float64], err: float) -> tuple[float, float, bool] | None:
    """The y limits of the error panel from the samples after the warm-up: their range with a
    5 % margin, except past the 1st and 99th percentiles (and +-RMSE) widened by 30 % of their
    spread, where the rare excursions (the rest of a start-up transient, a spike) are clipped;
    whether some are. None when the error is constant or missing."""
    after = after[np.isfinite(after)]
    if not after.size or np.ptp(after) == 0:
        return None
    low, high = float(after.min()), float(after.max())
    q_lo, q_hi = (float(q) for q in np.percentile(after, [1.0, 99.0]))
    q_lo, q_hi = min(q_lo, -err), max(q_hi, err)
    spread = 0.3 * (q_hi - q_lo)
    pad = 0.05 * (high - low)
    lo = low - pad if low >= q_lo - spread else q_lo - spread
    hi = high + pad if high <= q_hi + spread else q_hi + spread
    return lo, hi, bool(low < lo or high > hi)


def _correlation(a: NDArray[np.float64], b: NDArray[np.float64], lags: NDArray[np.int_]) -> NDArray[np.float64]:
    """Normalised cross-correlation r_ab(k) = sum a(t) b(t - k) / (N std a std b)."""
    a, b = a - a.mean(), b - b.mean()
    n, scale = len(a), len(a) * a.std() * b.std()
    if scale == 0.0:
        return np.zeros(len(lags))
    return np.array([np.dot(a[k:], b[: n - k]) if k >= 0 else np.dot(a[: n + k], b[-k:]) for k in lags]) / scale


def _decay_lag(signal: NDArray[np.float64], limit: int, level: float = 0.2) -> int | None:
    """The first lag (at most ``limit``) where the normalised autocorrelation of signal falls
    below ``level``; None when it stays above."""
    s = signal - signal.mean()
    power = float(np.dot(s, s))
    if power == 0.0:
        return 0
    size = 1 << (2 * len(s) - 1).bit_length()
    spectrum = np.fft.rfft(s, size)
    auto = np.fft.irfft(spectrum * np.conj(spectrum), size)[: limit + 1] / power
    below = np.flatnonzero(auto < level)
    return int(below[0]) if below.size else None


def _lags_from_data(e: NDArray[np.float64], u: NDArray[np.float64]) -> tuple[int, int]:
    """The largest lags of the correlation panels, each at least 20 and at most N/4: of the
    autocorrelation 2.5 times the lag where the residual's autocorrelation falls below 0.2 (its
    decay and what follows), of the cross-correlation 1.5 times the lag where the slower of
    the residual's and the input's autocorrelations does."""
    limit = max(len(e) // 4, 1)
    own, inputs = _decay_lag(e, limit), _decay_lag(u, limit)
    slower = None if own is None or inputs is None else max(own, inputs)

    def span(decay: int | None, factor: float) -> int:
        return limit if decay is None else int(min(max(int(np.ceil(factor * decay)), 20), limit))

    return span(own, 2.5), span(slower, 1.5)


def _draw_correlation(ax: Any, lags: NDArray[np.int_], values: NDArray[np.float64]) -> None:
    """Stems for a few lags, a line (with the zero line) for many."""
    if len(lags) <= 81:
        ax.stem(lags, values, basefmt=" ")
    else:
        ax.plot(lags, values, color="C0", lw=1.2)
        ax.axhline(0.0, color="k", lw=0.5)


def plot_residuals(
    residual: ArrayLike,
    u: ArrayLike,
    *,
    max_lag: int | None = None,
    dt: float = 1.0,
    ylabel: str = "output",
    unit: str | None = None,
    time_unit: str = "s",
    fig: Any = None,
    title: str | None = None,
    warmup: int = 0,
) -> Any:
    """Draw residual diagnostics: the residual, its histogram and its correlations.

    Four panels: the residual over time, its histogram, its autocorrelation and its
    cross-correlation with the input, with the 95 % bounds ``1.96 / sqrt(N)`` of a white
    residual independent of the input. The correlations reach, unless ``max_lag`` is given, the
    lags over which the residual and the input decorrelate (at a high sampling rate a fixed
    few dozen lags show only their flat start).

    Parameters
    ----------
    residual : array_like
        Measured minus simulated output (the free-run simulation error).
    u : array_like
        The input over the same samples.
    max_lag : int, optional
        Largest lag of the correlations [default: from the data, each at least 20 and at most
        N/4: of the autocorrelation 2.5 times the lag where it falls below 0.2, of the
        cross-correlation 1.5 times the lag where the autocorrelation of the residual or of the
        input, the slower, does].
    dt : float, default 1.0
        Sampling period in ``time_unit`` (the time axis is in samples when 1).
    ylabel : str, default "output"
        Name of the output signal for the axis labels.
    unit : str, optional
        Unit of the output (and so of the residual) [default: not stated].
    time_unit : str, default "s"
        Unit of ``dt``.
    fig : matplotlib.figure.Figure, optional
        Figure to draw on [default: a new one].
    title : str, optional
        Title of the figure.
    warmup : int, default 0
        Samples of the record before the residual's first (a warm-up left out): the time axis
        counts from the record's start. With 0 it counts from the residual's first sample.

    Returns
    -------
    matplotlib.figure.Figure
        The figure drawn on.

    Raises
    ------
    DataError
        If residual and u differ in length.
    BacklashIdError
        If matplotlib is not installed.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> fig = bid.app.plot_residuals(rng.standard_normal(500), rng.uniform(-1, 1, 500), max_lag=10)
    >>> len(fig.axes)
    4
    """
    plt = pyplot()
    e, us = one_record(residual, u, ("residual", "u"), flatten=True)
    if fig is None:
        fig = plt.figure(figsize=(11, 6.5))
    axes = fig.subplots(2, 2)
    n = len(e)
    t, time_label = _residual_time(n, dt, time_unit, warmup)
    axes[0, 0].plot(t, e, lw=0.5 if n > WINDOW else 0.7, color="C0")
    axes[0, 0].set_title(f"residual (RMS {np.sqrt(np.mean(e ** 2)):.4g}{' ' + unit if unit else ''})")
    axes[0, 0].set_xlabel(time_label)
    axes[0, 0].set_ylabel(_stacked(_with_unit(f"measured - simulated {ylabel}", unit), 28))
    axes[0, 1].hist(e, bins=50, color="C0", alpha=0.8)
    axes[0, 1].set_title("residual histogram")
    axes[0, 1].set_xlabel(_with_unit("residual", unit))
    axes[0, 1].set_ylabel("samples")
    lag_unit = "samples" if dt is None or dt == 1.0 else f"samples of {dt:g} {time_unit}"
    _correlation_panels(axes[1, 0], axes[1, 1], e, us, _lags_from_data(e, us) if max_lag is None else (int(max_lag),) * 2, lag_unit)
    for ax in axes.flat:
        ax.grid(alpha=0.3)
    heading = title or "Residual diagnostics (free-run simulation error)"
    fig.suptitle(f"{heading}\ngreen band: 95 % bounds +-1.96/sqrt(N) of a white residual independent of the input")
    fig.tight_layout()
    return fig


def _residual_time(n: int, dt: float | None, time_unit: str, warmup: int) -> tuple[NDArray[np.float64], str]:
    """The residual's time axis and label: from the record's start past a warm-up of
    ``warmup`` samples, else from the residual's first sample."""
    t, label = _time(n, dt, time_unit)
    in_samples = label.startswith("sample")
    if warmup > 0:
        shift = float(warmup) if in_samples else warmup * float(dt)  # type: ignore[arg-type]
        return t + shift, f"{label}\n(its first {warmup} samples, the warm-up, left out)"
    if in_samples:
        return t, "sample of the residual"
    return t, f"time from the residual's first sample [{time_unit}]"


def _correlation_panels(ax_auto: Any, ax_cross: Any, e: NDArray[np.float64], us: NDArray[np.float64], max_lags: tuple[int, int],
                        lag_unit: str) -> None:
    """The residual's autocorrelation and its cross-correlation with the input up to the lags
    max_lags (of each), with the 95 % bounds of a white residual independent of the input."""
    bound = 1.96 / np.sqrt(len(e))
    lags = np.arange(0, max_lags[0] + 1)
    _draw_correlation(ax_auto, lags, _correlation(e, e, lags))
    ax_auto.set_title("residual autocorrelation")
    ax_auto.set_ylabel("normalised correlation r_ee(k)")
    cross_lags = np.arange(-max_lags[1], max_lags[1] + 1)
    _draw_correlation(ax_cross, cross_lags, _correlation(e, us, cross_lags))
    ax_cross.set_title("cross-correlation residual / input")
    ax_cross.set_ylabel("normalised correlation r_eu(k)")
    for ax in (ax_auto, ax_cross):
        ax.axhspan(-bound, bound, color="C2", alpha=0.2)
        ax.set_xlabel(f"lag k [{lag_unit}]")
