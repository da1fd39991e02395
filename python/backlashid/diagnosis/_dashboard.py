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
    scaling: Any = None,
    output: str = "y",
    sample_time: float | None = None,
) -> Any:
    """Draw the diagnosis dashboard of a :class:`~backlashid.diagnosis.DiagnosisReport`.

    The panels: measured against nominal simulation, the error coloured by regime, the error
    share by regime, the residual correlation tests, the gap closed by each candidate, and the
    nominal against the best augmented simulation where the error is largest. The verdict sits
    above the panels, in a band sized to its wrapped text. The diagnosis works in model units;
    ``scaling``, ``output`` and ``sample_time`` put the signal panels in the record's units.

    The before/after panel shows the measurement, the nominal simulation and the best
    augmented one: the named effect's, or, when none is named ("unexplained"), the best
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
    view = _View(scaling, str(output), sample_time)
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
    # the verdict gets its own band above the panels, as high as its wrapped lines (10 pt text,
    # about 14 pt a line), so it never covers the first panel's title
    width_chars = max(40, int(figsize[0] * 72 / 6.2))  # about 6.2 pt per character at 10 pt
    verdict = textwrap.fill(f"Diagnosis: {report.verdict()}", width=width_chars)
    lines = verdict.count("\n") + 1
    band = (lines * 14 + 34) / (72 * figsize[1])  # the text, the first title and a margin
    gs = fig.add_gridspec(
        4, 2, height_ratios=[1.1, 1.0, 1.0, 1.0], hspace=0.5, wspace=0.22,
        top=1.0 - band, bottom=0.04, left=0.16, right=0.98,
    )
    _plot_signals(report, fig.add_subplot(gs[0, :]), view)
    _plot_error(report, fig.add_subplot(gs[1, :]), view)
    _plot_regimes(report, fig.add_subplot(gs[2, 0]))
    _plot_tests(report, fig.add_subplot(gs[2, 1]))
    _plot_ranking(report, fig.add_subplot(gs[3, 0]))
    _plot_before_after(report, fig.add_subplot(gs[3, 1]), window, view)
    fig.text(0.5, 1.0 - 8 / (72 * figsize[1]), verdict, ha="center", va="top", fontsize=10)
    if path is not None:
        from .._files import save_figure

        save_figure(fig, path, dpi=dpi)  # atomically
    return fig


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


def _shade_warmup(report: Any, ax: Any, view: _View) -> None:
    if report.warmup > 0:
        a, b = view.t(-0.5), view.t(report.warmup - 0.5)
        ax.axvspan(a, b, color="0.9", lw=0, label=f"warm-up ({report.warmup} samples)", zorder=0)


def _plot_signals(report: Any, ax: Any, view: _View) -> None:
    t = view.t(np.arange(report.n_validation))
    _shade_warmup(report, ax, view)
    ax.plot(t, view.y(report.y_nominal), color="C0", lw=0.9, label="nominal simulation")
    ax.plot(t, view.y(report.y_val), color="k", lw=0.5, alpha=0.6, label="measured")
    rmse = view.e(report.nominal_validation_rmse)
    ax.set_title(f"Validation record: measured vs nominal free-run simulation (RMSE {rmse:.4g})", fontsize=10)
    ax.set_xlabel(view.time_label)
    ax.set_ylabel(view.output)
    _headroom(ax)
    ax.legend(loc="upper right", fontsize="small", ncol=3)
    ax.grid(alpha=0.3)


def _headroom(ax: Any, share: float = 0.2) -> None:
    """Room above the data for the legend row (it must not hide the signal)."""
    lo, hi = ax.get_ylim()
    ax.set_ylim(lo, hi + share * (hi - lo))


def _plot_error(report: Any, ax: Any, view: _View) -> None:
    err = view.e(np.asarray(report.y_val) - np.asarray(report.y_nominal))
    t = view.t(np.arange(err.size))
    noise = float(view.e(report.noise_std))
    _shade_warmup(report, ax, view)
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
        ax.axhline(sign * noise, color="k", ls="--", lw=0.8)
    after = err[report.warmup :]
    if after.size and np.ptp(after) > 0:  # scale to the evaluated samples, not the transient
        pad = 0.08 * float(np.ptp(after))
        ax.set_ylim(min(float(after.min()), -2 * noise) - pad, max(float(after.max()), 2 * noise) + pad)
    _headroom(ax)
    ax.set_title("Nominal model's error (measured - simulated) by backlash state; dashed: +-2 noise std", fontsize=10)
    ax.set_xlabel(view.time_label)
    ax.set_ylabel(f"error, {view.output}" if view.output != "y" else "error")
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
    ax.set_ylabel("share [%]")
    ax.set_title("Error share by regime (* significantly more error)", fontsize=10)
    total = sum(samples)
    if total > 100.5:  # a sample can be in several regimes (after a reversal and in the dead band)
        ax.text(
            0.5, 0.97, f"the regimes overlap: sample shares add up to {total:.0f} %",
            transform=ax.transAxes, ha="center", va="top", fontsize=8,
            bbox=dict(boxstyle="round,pad=0.2", fc="white", ec="0.6", alpha=0.9),
        )
        ax.texts[-1].set_position((0.99, 0.97))
        ax.texts[-1].set_horizontalalignment("right")
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


def _plot_ranking(report: Any, ax: Any) -> None:
    if not report.ranking:
        ax.text(0.5, 0.5, _no_candidates(report), ha="center", va="center", transform=ax.transAxes, fontsize=9, wrap=True)
        ax.set_title("Candidates", fontsize=10)
        ax.set_xticks([])
        ax.set_yticks([])
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
    ax.set_title("Candidates, best first", fontsize=10)
    ax.grid(alpha=0.3, axis="x")


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


def _shown_candidate(report: Any) -> tuple[Any, Any, str]:
    """The augmented simulation for the before/after panel: the named effect's, else the best
    candidate that changes the simulation, simulated again from the state that fits the record."""
    n = report.n_validation
    if report.best is not None and report.y_best is not None and np.asarray(report.y_best).size == n:
        return report.best, np.asarray(report.y_best), f"augmented: {report.best.effect}"
    top = next((c for c in report.ranking if c.effect != "colored_noise" and c.model is not None), None)
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


def _plot_before_after(report: Any, ax: Any, window: int, view: _View) -> None:
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
    t = view.t(np.arange(n)[sl])
    rmse_n = float(view.e(np.sqrt(np.mean((y[sl] - nominal[sl]) ** 2))))
    ax.plot(t, view.y(y[sl]), color="k", lw=1.2, alpha=0.6, label="measured")
    ax.plot(t, view.y(nominal[sl]), color="C0", lw=1.0, label=f"nominal (RMSE {rmse_n:.3g})")
    _, best, label = _shown_candidate(report)
    if best is not None:
        rmse_b = float(view.e(np.sqrt(np.mean((y[sl] - best[sl]) ** 2))))
        ax.plot(t, view.y(best[sl]), color="C2", lw=1.0, ls="--", label=f"{label} (RMSE {rmse_b:.3g})")
    else:
        label = "no augmented model to show: " + ("no gap" if report.best_effect == "none" else "no candidate")
        ax.plot([], [], " ", label=label)
    ax.set_title("Before/after where the nominal error is largest (RMSE on this window)", fontsize=10)
    ax.set_xlabel(view.time_label)
    ax.set_ylabel(view.output)
    _headroom(ax, 0.3)
    ax.legend(fontsize="x-small", framealpha=0.85, loc="upper center", ncol=2 if best is None else 1)
    ax.grid(alpha=0.3)
