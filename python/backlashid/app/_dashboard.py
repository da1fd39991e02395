"""The diagnosis report's dashboard figure (``DiagnosisReport.plot`` delegates here)."""

from __future__ import annotations

import math
import textwrap
from typing import Any

import numpy as np

__all__ = ["plot_diagnosis"]


def plot_diagnosis(
    report: Any,
    path: Any = None,
    *,
    figsize: tuple[float, float] = (13, 15),
    window: int = 300,
    dpi: float = 110,
) -> Any:
    """Draw the diagnosis dashboard of a :class:`~backlashid.diagnosis.DiagnosisReport`.

    The panels: measured against nominal simulation, the error coloured by regime, the error
    share by regime, the residual correlation tests, the gap closed by each candidate, and the
    nominal against the best augmented simulation where the error is largest.

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

    Returns
    -------
    matplotlib.figure.Figure
        The dashboard.

    Raises
    ------
    BacklashIdError
        If matplotlib is not installed.
    """
    window = int(window)
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
    else:
        from .._optional import pyplot

        fig = pyplot().figure(figsize=figsize, dpi=dpi)
    gs = fig.add_gridspec(4, 2, height_ratios=[1.1, 1.0, 1.0, 1.0], hspace=0.45, wspace=0.22, top=0.94, bottom=0.04, left=0.16, right=0.98)
    _plot_signals(report, fig.add_subplot(gs[0, :]))
    _plot_error(report, fig.add_subplot(gs[1, :]))
    _plot_regimes(report, fig.add_subplot(gs[2, 0]))
    _plot_tests(report, fig.add_subplot(gs[2, 1]))
    _plot_ranking(report, fig.add_subplot(gs[3, 0]))
    _plot_before_after(report, fig.add_subplot(gs[3, 1]), window)
    fig.suptitle(textwrap.fill(f"Diagnosis: {report.verdict()}", width=150), fontsize=10)
    if path is not None:
        fig.savefig(path, dpi=dpi)
    return fig


def _shade_warmup(report: Any, ax: Any) -> None:
    if report.warmup > 0:
        ax.axvspan(-0.5, report.warmup - 0.5, color="0.9", lw=0, label=f"warm-up ({report.warmup})", zorder=0)


def _plot_signals(report: Any, ax: Any) -> None:
    t = np.arange(report.n_validation)
    _shade_warmup(report, ax)
    ax.plot(t, report.y_nominal, color="C0", lw=0.9, label="nominal simulation")
    ax.plot(t, report.y_val, color="k", lw=0.5, alpha=0.6, label="measured")
    ax.set_title(f"Validation record: measured vs nominal free-run simulation (RMSE {report.nominal_validation_rmse:.4g})")
    ax.set_xlabel("sample")
    ax.set_ylabel("y")
    ax.legend(loc="upper right", fontsize="small", ncol=3)
    ax.grid(alpha=0.3)


def _plot_error(report: Any, ax: Any) -> None:
    err = np.asarray(report.y_val) - np.asarray(report.y_nominal)
    t = np.arange(err.size)
    _shade_warmup(report, ax)
    if report.regimes is not None and report.regimes.masks["dead_band"].size == err.size:
        labels = report.regimes.labels()
        styles = ((-1, "0.75", None), (0, "0.35", "dead band"), (1, "C0", "left branch"), (2, "C3", "right branch"))
        for value, color, name in styles:
            sel = labels == value
            if sel.any():
                ax.scatter(t[sel], err[sel], s=3, lw=0, color=color, label=name)
    else:
        ax.scatter(t, err, s=3, lw=0, color="0.35", label="error")
    for sign in (-2.0, 2.0):
        ax.axhline(sign * report.noise_std, color="k", ls="--", lw=0.8)
    after = err[report.warmup :]
    if after.size and np.ptp(after) > 0:  # scale to the evaluated samples, not the transient
        pad = 0.08 * float(np.ptp(after))
        ax.set_ylim(min(float(after.min()), -2 * report.noise_std) - pad, max(float(after.max()), 2 * report.noise_std) + pad)
    ax.set_title("Nominal model's error (measured - simulated) by backlash state; dashed: +-2 noise std")
    ax.set_xlabel("sample")
    ax.set_ylabel("error")
    ax.legend(loc="upper right", fontsize="small", ncol=4, markerscale=3)
    ax.grid(alpha=0.3)


def _plot_regimes(report: Any, ax: Any) -> None:
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
    ax.set_ylabel("%")
    ax.set_title("Error share by regime (* significantly more error)")
    ax.legend(fontsize="small")
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
    ax.set_title(f"Residual correlations (failed tests: {failed})", fontsize=10)
    ax.set_xlabel("lag k")
    ax.set_ylabel("normalised correlation")
    ax.legend(fontsize="x-small")
    ax.grid(alpha=0.3)


def _plot_ranking(report: Any, ax: Any) -> None:
    if not report.ranking:
        ax.text(0.5, 0.5, "no candidates", ha="center", va="center", transform=ax.transAxes)
        ax.set_axis_off()
        return
    ranked = report.ranking[:12]
    pos = np.arange(len(ranked))
    raw = np.array([c.gap_closed if math.isfinite(c.gap_closed) else 0.0 for c in ranked])
    lo, hi = -0.25, 1.1  # a tiny gap gives huge shares either way: show them clipped
    closed = np.clip(raw, lo, hi)
    colors = ["C2" if c.explains else ("C1" if c.p_value < 0.05 else "0.65") for c in ranked]
    ax.barh(pos, closed, color=colors)
    ax.set_yticks(pos)
    ax.set_yticklabels([f"{c.effect}{'' if c.signature_removed else ' (sig. remains)'}" for c in ranked], fontsize=7)
    ax.invert_yaxis()
    ax.axvline(ranked[0].CLOSES_HALF, color="k", ls="--", lw=0.8)
    ax.axvline(1.0, color="k", lw=0.8)
    ax.set_xlim(min(0.0, float(closed.min()) - 0.05), max(1.05, float(closed.max()) + 0.05))
    clipped = " (clipped)" if np.any(closed != raw) else ""
    ax.set_xlabel(f"share of the gap closed on validation{clipped} (green: >= half and p < 0.05)")
    ax.set_title("Candidates, best first")
    ax.grid(alpha=0.3, axis="x")


def _plot_before_after(report: Any, ax: Any, window: int) -> None:
    y = np.asarray(report.y_val)
    nominal = np.asarray(report.y_nominal)
    n = y.size
    w = int(np.clip(window, 10, max(n - report.warmup, 10)))
    err2 = (y - nominal) ** 2
    err2[: report.warmup] = 0.0
    if n - report.warmup > w:
        energy = np.convolve(err2, np.ones(w), mode="valid")
        start = int(np.argmax(energy[report.warmup :]) + report.warmup)
    else:
        start = report.warmup
    sl = slice(start, min(start + w, n))
    t = np.arange(n)[sl]
    ax.plot(t, y[sl], color="0.45", lw=1.0, label="measured")
    ax.plot(t, nominal[sl], color="C0", lw=1.0, label="nominal")
    if report.best is not None and report.y_best is not None and np.asarray(report.y_best).size == n:
        name = report.best.effect
        best = np.asarray(report.y_best)
        rmse_b = float(np.sqrt(np.mean((y[sl] - best[sl]) ** 2)))
        ax.plot(t, best[sl], color="C2", lw=1.0, ls="--", label=f"augmented: {name} (RMSE {rmse_b:.3g})")
    rmse_n = float(np.sqrt(np.mean((y[sl] - nominal[sl]) ** 2)))
    ax.set_title(f"Before/after where the nominal error is largest (nominal RMSE {rmse_n:.3g})", fontsize=10)
    ax.set_xlabel("sample")
    ax.set_ylabel("y")
    ax.legend(fontsize="x-small")
    ax.grid(alpha=0.3)
