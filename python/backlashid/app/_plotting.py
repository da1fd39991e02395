"""Figures (matplotlib is an optional extra: ``pip install backlashid[plot]``)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._optional import pyplot
from .._validation import as_signal
from ..errors import DataError
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
    """Draw the branches L(x), R(x) of a general backlash (as in the paper's Figs 1, 4, 7),
    over the path (x(t), y(t)) of a simulation when x and y are given. Returns the axes."""
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


def plot_branches_comparison(
    true_backlash: GeneralBacklash,
    estimated: GeneralBacklash,
    x_range: tuple[float, float],
    *,
    ax: Any = None,
    title: str | None = None,
) -> Any:
    """True and estimated branches on one plot (the paper's Figs 4 and 7)."""
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
    """Parameter estimates over the iterations (the paper's Figs 5, 6, 8-10); dotted lines
    mark the true values when given, stars the ``final`` estimates (after the refinement) one
    step after the last iteration."""
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
    """Measured output against the free-run simulation, with the fit % (from sample ``warmup``
    on; the skipped transient is shaded). ``dt`` scales the time axis. Returns the axes."""
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
    """Residual diagnostics: the residual over time, its histogram, its autocorrelation and
    its cross-correlation with the input, with the 95 % bounds +-1.96/sqrt(N) of a white
    residual independent of the input. Returns the figure."""
    plt = pyplot()
    e, us = as_signal(residual, "residual").ravel(), as_signal(u, "u").ravel()
    if e.shape != us.shape:
        raise DataError(f"residual has {e.size} samples and u {us.size}: give one record")
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
