"""Figures (matplotlib is an optional extra: ``pip install backlashid[plot]``)."""

from __future__ import annotations

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


def plot_characteristic(
    backlash: GeneralBacklash,
    x: ArrayLike | None = None,
    y: ArrayLike | None = None,
    *,
    x_range: tuple[float, float] | None = None,
    ax: Any = None,
    title: str | None = None,
) -> Any:
    """Draw the branches L(x), R(x) of a general backlash, as in the paper's Figs 1, 4 and 7.

    When x and y are given, the path (x(t), y(t)) of a simulation is drawn under the branches
    and the axes are limited to its range.

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
    if x is not None and y is not None:
        xs, ys = as_signal(x, "x"), as_signal(y, "y")
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
    for values, name, style in ((left, "L(x)", "C0"), (right, "R(x)", "C3")):
        shown = np.where((values >= y_lo - pad) & (values <= y_hi + pad), values, np.nan)
        ax.plot(grid, shown, color=style, lw=2, label=name, zorder=2)
    ax.axhline(0.0, color="k", lw=0.5)
    ax.axvline(0.0, color="k", lw=0.5)
    ax.set_xlabel("x (input of the backlash)")
    ax.set_ylabel("y (output of the backlash)")
    ax.set_title(title or f"General backlash, c_L = {backlash.c_left:.3g}, c_R = {backlash.c_right:.3g}")
    ax.legend(loc="upper left")
    ax.grid(alpha=0.3)
    return ax


@fill(plot=PLOT)
def plot_branches_comparison(
    true_backlash: GeneralBacklash,
    estimated: GeneralBacklash,
    x_range: tuple[float, float],
    *,
    ax: Any = None,
    title: str | None = None,
) -> Any:
    """Draw true and estimated branches on one plot, as in the paper's Figs 4 and 7.

    Parameters
    ----------
    true_backlash : GeneralBacklash
        The true backlash (solid lines).
    estimated : GeneralBacklash
        The estimate (dashed lines).
    x_range : tuple of float
        (low, high) of the backlash input x shown.
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
    for bl, style, label in ((true_backlash, "-", "true"), (estimated, "--", "estimated")):
        grid, left, right = bl.characteristic(*x_range, 600)
        ax.plot(grid, left, style, color="C0", lw=2, label=f"L(x) {label}")
        ax.plot(grid, right, style, color="C3", lw=2, label=f"R(x) {label}")
    ax.axhline(0.0, color="k", lw=0.5)
    ax.axvline(0.0, color="k", lw=0.5)
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.set_title(title or "General backlash: true and estimated")
    ax.legend(loc="upper left")
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
    ax: Any = None,
    title: str | None = None,
) -> Any:
    """Draw parameter estimates over the iterations, as in the paper's Figs 5, 6 and 8-10.

    Dotted lines mark the true values when given, stars the final estimates (after the
    refinement) one step after the last iteration.

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
    for k, name in enumerate(shown):
        color = f"C{k % 10}"
        ax.plot(its, h[:, names.index(name)], "-o", ms=3, color=color, label=name)
        if truth is not None:
            ax.axhline(truth[name], color=color, ls=":", lw=1)
        if final is not None:
            ax.plot([len(h) + 1], [final[name]], "*", ms=10, color=color)
    from matplotlib.ticker import MaxNLocator

    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("iteration")
    ax.set_ylabel("estimate")
    ax.set_title(title or "Parameter estimates")
    ax.legend(loc="best", fontsize="small", ncol=2)
    ax.grid(alpha=0.3)
    return ax


@fill(plot=PLOT)
def plot_simulation(
    y: ArrayLike,
    y_sim: ArrayLike,
    *,
    warmup: int = 0,
    dt: float = 1.0,
    ylabel: str = "output",
    ax: Any = None,
    title: str | None = None,
) -> Any:
    """Draw the measured output against the free-run simulation, with the fit %.

    The fit % and RMSE count the samples from ``warmup`` on; the warm-up is shaded.

    Parameters
    ----------
    y : array_like
        Measured output.
    y_sim : array_like
        Free-run simulated output, as long as y.
    warmup : int, default 0
        Samples at the start left out of the fit % and RMSE (an unknown initial state).
    dt : float, default 1.0
        Sampling period: the time axis is in its units (in samples when 1).
    ylabel : str, default "output"
        Label of the output axis.
    {plot}

    Examples
    --------
    >>> d = bid.example_data(bid.example1(), 300, seed=0)
    >>> ax = bid.app.plot_simulation(d.noisy, d.clean, warmup=20)
    >>> ax.lines[1].get_label()  # doctest: +ELLIPSIS
    'simulated (free run): fit 9... %, RMSE ...'
    """
    from ..identify import fit_percent, rmse

    plt = pyplot()
    if ax is None:
        _, ax = plt.subplots(figsize=(10, 3.8))
    ys, sims = as_signal(y, "y").ravel(), as_signal(y_sim, "y_sim").ravel()
    t = np.arange(len(ys)) * dt
    fit = fit_percent(ys, sims, warmup=warmup)
    err = rmse(ys, sims, warmup=warmup)
    ax.plot(t, ys, color="0.3", lw=1, label="measured")
    ax.plot(t, sims, color="C3", lw=1, label=f"simulated (free run): fit {fit:.1f} %, RMSE {err:.4g}")
    if warmup:
        ax.axvspan(t[0], t[warmup - 1], color="0.9", zorder=0, label=f"skipped transient ({warmup} samples)")
    ax.set_xlabel("time" if dt != 1.0 else "sample")
    ax.set_ylabel(ylabel)
    ax.set_title(title or "Measured and simulated output")
    ax.legend(loc="upper right", fontsize="small")
    ax.grid(alpha=0.3)
    return ax


def _correlation(a: NDArray[np.float64], b: NDArray[np.float64], lags: NDArray[np.int_]) -> NDArray[np.float64]:
    """Normalised cross-correlation r_ab(k) = sum a(t) b(t - k) / (N std a std b)."""
    a, b = a - a.mean(), b - b.mean()
    n, scale = len(a), len(a) * a.std() * b.std()
    if scale == 0.0:
        return np.zeros(len(lags))
    return np.array([np.dot(a[k:], b[: n - k]) if k >= 0 else np.dot(a[: n + k], b[-k:]) for k in lags]) / scale


def plot_residuals(
    residual: ArrayLike,
    u: ArrayLike,
    *,
    max_lag: int = 40,
    fig: Any = None,
    title: str | None = None,
) -> Any:
    """Draw residual diagnostics: the residual, its histogram and its correlations.

    Four panels: the residual over time, its histogram, its autocorrelation and its
    cross-correlation with the input, with the 95 % bounds ``1.96 / sqrt(N)`` of a white
    residual independent of the input.

    Parameters
    ----------
    residual : array_like
        Measured minus simulated output (the free-run simulation error).
    u : array_like
        The input over the same samples.
    max_lag : int, default 40
        Largest lag of the correlations.
    fig : matplotlib.figure.Figure, optional
        Figure to draw on [default: a new one].
    title : str, optional
        Title of the figure.

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
    bound = 1.96 / np.sqrt(n)
    axes[0, 0].plot(e, lw=0.7, color="C0")
    axes[0, 0].set_title(f"residual (RMS {np.sqrt(np.mean(e ** 2)):.4g})")
    axes[0, 0].set_xlabel("sample")
    axes[0, 1].hist(e, bins=50, color="C0", alpha=0.8)
    axes[0, 1].set_title("residual histogram")
    lags = np.arange(0, max_lag + 1)
    auto = _correlation(e, e, lags)
    axes[1, 0].stem(lags, auto, basefmt=" ")
    axes[1, 0].set_title("residual autocorrelation")
    cross_lags = np.arange(-max_lag, max_lag + 1)
    axes[1, 1].stem(cross_lags, _correlation(e, us, cross_lags), basefmt=" ")
    axes[1, 1].set_title("cross-correlation residual / input")
    for ax in (axes[1, 0], axes[1, 1]):
        ax.axhspan(-bound, bound, color="C2", alpha=0.2, label="95 % bounds (white, independent)")
        ax.set_xlabel("lag")
        ax.legend(loc="upper right", fontsize="small")
    for ax in axes.flat:
        ax.grid(alpha=0.3)
    fig.suptitle(title or "Residual diagnostics (free-run simulation error)")
    fig.tight_layout()
    return fig
