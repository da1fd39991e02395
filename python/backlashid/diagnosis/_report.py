"""The diagnosis report: which effect the nominal model misses, and where its error lies.

:class:`Candidate` is one augmentation of the nominal model (an effect from ``EFFECTS``),
refitted and scored on validation data; :class:`DiagnosisReport` holds the ranking with the
analyses of the nominal model's validation residual (:mod:`residual_tests`, :mod:`regimes`,
:mod:`spectral`, :mod:`drift`), and shows them as one screen of text (``summary``), a JSON-safe
dict (``to_dict``) and a dashboard figure (``plot``).

Errors are free-run simulation errors (one-step prediction for ``colored_noise``, which is a
noise model), over the samples after the warm-up.
"""

from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .analyses._drift import TimeAnalysis
from .analyses._regimes import RegimeShares
from .analyses._residual_tests import ResidualTests
from .analyses._spectral import FrequencyAnalysis

__all__ = ["Candidate", "DiagnosisReport", "jsonable"]

MAX_LIST = 64  # arrays longer than this are left out of to_dict()
CLOSES_HALF = 0.5  # a candidate "explains" the gap when it closes at least this share


def jsonable(value: Any) -> Any:
    """``value`` with numpy types turned into Python ones, NaN and inf into None, and arrays
    longer than ``MAX_LIST`` left out (None), so that ``json.dumps`` works."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist()) if value.size <= MAX_LIST else None
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        f = float(value)
        return f if math.isfinite(f) else None
    if value is None or isinstance(value, str):
        return value
    if hasattr(value, "to_dict"):
        return jsonable(value.to_dict())
    return str(value)


def _model_dict(model: Any) -> Any:
    if model is None:
        return None
    to_dict = getattr(model, "to_dict", None)
    if callable(to_dict):
        return jsonable(to_dict())
    return repr(model)


def _pct(v: float) -> str:
    if not math.isfinite(v):
        return "  n/a"
    if abs(v) >= 9.995:  # a tiny gap makes the share meaningless: do not print its digits
        return ">999 %" if v > 0 else "<-999 %"
    return f"{100 * v:4.0f} %"


def _p(v: float) -> str:
    return f"{v:.1e}" if math.isfinite(v) else "n/a"


@dataclass(frozen=True)
class Candidate:
    """One candidate effect: the nominal model augmented by it, refitted on the estimation
    record and scored on the validation record."""

    effect: str  # a name from EFFECTS
    gap_closed: float  # fraction of the validation gap above the noise floor removed
    p_value: float  # significance of the validation improvement over the nominal model
    model: Any  # refitted augmented model: .simulate(u) -> ndarray y, .to_dict() JSON-safe
    params: dict[str, float]  # the effect's own fitted parameters
    n_extra: int  # number of extra parameters over the nominal
    estimation_rmse: float  # free-run simulation RMSE (one-step prediction RMSE for colored_noise)
    validation_rmse: float  # the same on validation data
    criterion: float  # information criterion used in the ranking (lower is better)
    signature_removed: bool  # the residual signature the effect predicts is gone after augmentation

    @property
    def explains(self) -> bool:
        """Closes at least half of the gap, significantly."""
        return bool(self.gap_closed >= CLOSES_HALF and self.p_value < 0.05)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = jsonable(
            {
                "effect": self.effect,
                "gap_closed": self.gap_closed,
                "p_value": self.p_value,
                "params": {str(k): v for k, v in dict(self.params).items()},
                "n_extra": self.n_extra,
                "estimation_rmse": self.estimation_rmse,
                "validation_rmse": self.validation_rmse,
                "criterion": self.criterion,
                "signature_removed": self.signature_removed,
                "model": _model_dict(self.model),
            }
        )
        return out


@dataclass
class DiagnosisReport:
    """What ``diagnose`` found: the best effect, the ranked candidates, and where the nominal
    model's validation error lies."""

    best_effect: str  # a name from EFFECTS, "none" or "unexplained"
    ranking: list[Candidate]
    regimes: RegimeShares  # regimes.py
    tests: ResidualTests  # residual_tests.py, on the nominal model's validation residual
    spectrum: FrequencyAnalysis  # spectral.py
    drift: TimeAnalysis  # drift.py
    noise_std: float
    noise_std_estimated: bool
    nominal_validation_rmse: float
    gap: float  # nominal validation MSE above the noise floor (>= 0)
    warmup: int
    u_val: NDArray[np.float64]
    y_val: NDArray[np.float64]
    y_nominal: NDArray[np.float64]
    y_best: NDArray[np.float64]
    elapsed: float  # seconds
    details: dict[str, Any] = field(default_factory=dict)  # the diagnoser's extra numbers (in to_dict)

    # ------------------------------------------------------------------ derived
    @property
    def best(self) -> Candidate | None:
        """The candidate of ``best_effect`` (None for "none" and "unexplained")."""
        for c in self.ranking:
            if c.effect == self.best_effect:
                return c
        return None

    @property
    def n_validation(self) -> int:
        return int(np.asarray(self.y_val).size)

    @property
    def gap_ratio(self) -> float:
        """The gap relative to the noise variance."""
        var = float(self.noise_std) ** 2
        return float(self.gap) / var if var > 0 else float("nan")

    # ------------------------------------------------------------------ text
    def _verdict(self) -> str:
        best = self.best
        if self.best_effect == "none":
            return (
                f"none: no gap beyond the noise (nominal RMSE {self.nominal_validation_rmse:.4g}, "
                f"noise std {self.noise_std:.4g})"
            )
        if self.best_effect == "unexplained":
            # colored_noise is judged on one-step prediction, so it can rank first on a residual
            # that it cannot be: name the best effect that changes the simulation instead
            top = next((c for c in self.ranking if c.effect != "colored_noise"), None)
            tail = f"; the best, {top.effect}, closes {_pct(top.gap_closed).strip()}" if top else ""
            # candidates that close half the gap, yet a rule keeps from being named, and why
            held = self.details.get("closing_not_named") or {}
            if top and top.effect in held:
                tail += f", but {held[top.effect]}"
            for c in self.ranking:
                if c.effect in held and c is not top:
                    tail += f"; {c.effect} closes {_pct(c.gap_closed).strip()}, but {held[c.effect]}"
                    break
            if self.ranking and self.ranking[0].effect == "colored_noise":
                tail += "; colored_noise predicts the residual one step ahead but is not named" + self._not_noise()
            first = "no deterministic candidate explains" if held else "no deterministic candidate closes by half"
            return f"unexplained: a significant gap that {first}{tail}"
        if best is None:
            return f"{self.best_effect}"
        sig = "its signature is gone" if best.signature_removed else "its signature remains"
        return f"{best.effect}: closes {_pct(best.gap_closed).strip()} of the gap (p = {_p(best.p_value)}); {sig}"

    def _not_noise(self) -> str:
        """Why the residual is not noise, as the diagnoser recorded it in ``details``."""
        reasons = self.details.get("colored_noise_ruled_out") or []
        return ": " + " and ".join(reasons) if reasons else ""

    def _where(self) -> list[str]:
        lines = []
        t = self.tests
        if t is not None:
            if t.passed:
                lines.append(f"  residual tests: all {len(t.tests)} pass (smallest adjusted p {t.p_value:.2g})")
            else:
                failed = ", ".join(f"{name} (p {t[name].p_adjusted:.1e})" for name in t.failed)
                passed = ", ".join(x.name for x in t.tests if x.passed)
                lines.append(f"  residual tests fail: {failed}")
                if passed:
                    lines.append(f"    pass: {passed}")
        r = self.regimes
        if r is not None:
            hits = [r[name] for name in r.concentrated]
            if hits:
                parts = [
                    f"{h.name} ({_pct(h.energy_share).strip()} of the error on {_pct(h.sample_share).strip()} "
                    f"of the samples, x{h.ratio:.2f}, z {h.z:.1f}, p {h.p_adjusted:.1e})"
                    for h in hits[:3]
                ]
                lines.append("  regimes with more error: " + "; ".join(parts))
            else:
                lines.append("  regimes: the error is spread over the regimes as the samples are")
        s = self.spectrum
        if s is not None:
            above = [b for b in s.bands if b.above_floor]
            if above:
                above.sort(key=lambda b: b.p_value)
                parts = [f"{b.label} (x{b.ratio:.2f})" for b in above[:4]]
                lines.append("  bands above the noise floor (cycles/sample): " + ", ".join(parts))
            else:
                lines.append("  spectrum: at the noise floor in every band")
            if s.coherent:
                lines.append("    coherent with the input in: " + ", ".join(s.coherent[:4]))
        d = self.drift
        if d is not None:
            parts = []
            if d.mean_drift:
                parts.append(f"mean trend {d.mean_change:+.3g} over the record (p {d.mean_p:.1e})")
            if d.rms_drift:
                parts.append(f"RMS x{d.rms_ratio:.2f} over the record (p {d.rms_p:.1e})")
            for c in d.change_points[:3]:
                parts.append(f"{c.kind} change at sample {c.index} (p {c.p_value:.1e})")
            lines.append("  over time: " + ("; ".join(parts) if parts else "no drift and no change point"))
        return lines

    def summary(self) -> str:
        """One screen of text: verdict, ranking, where the error lies."""
        src = "estimated" if self.noise_std_estimated else "given"
        lines = [
            f"Diagnosis of the nominal model: {self.n_validation} validation samples, warm-up {self.warmup} "
            f"excluded, {self.elapsed:.2f} s",
            f"Verdict: {self._verdict()}",
            f"Nominal free-run simulation RMSE {self.nominal_validation_rmse:.4g}; noise std {self.noise_std:.4g} ({src}); "
            f"gap above the noise floor (MSE) {self.gap:.3g}"
            + (f" = {self.gap_ratio:.2f} x noise variance" if math.isfinite(self.gap_ratio) else ""),
        ]
        if self.ranking:
            lines += [
                "",
                "Candidates, best first (validation; RMSE of the free-run simulation, one-step for colored_noise)",
                f"  {'#':>2}  {'effect':18s} {'gap closed':>10s} {'p-value':>8s} {'+par':>4s} {'est RMSE':>9s} "
                f"{'val RMSE':>9s} {'criterion':>10s}  signature",
            ]
            for i, c in enumerate(self.ranking[:12], 1):
                lines.append(
                    f"  {i:2d}  {c.effect:18s} {_pct(c.gap_closed):>10s} {_p(c.p_value):>8s} {c.n_extra:4d} "
                    f"{c.estimation_rmse:9.4g} {c.validation_rmse:9.4g} {c.criterion:10.4g}  "
                    f"{'removed' if c.signature_removed else 'remains'}"
                )
        lines += ["", "Where the nominal model's validation error lies"]
        lines += self._where()
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()

    # ------------------------------------------------------------------ dict
    def to_dict(self) -> dict[str, Any]:
        """JSON-safe (``json.dumps`` works): scalars, the candidates and the analyses; the
        signals are left out."""
        best = self.best
        out: dict[str, Any] = jsonable(
            {
                "best_effect": self.best_effect,
                "best_gap_closed": best.gap_closed if best else None,
                "ranking": [c.to_dict() for c in self.ranking],
                "noise_std": self.noise_std,
                "noise_std_estimated": self.noise_std_estimated,
                "nominal_validation_rmse": self.nominal_validation_rmse,
                "gap": self.gap,
                "gap_ratio": self.gap_ratio,
                "warmup": self.warmup,
                "n_validation": self.n_validation,
                "elapsed": self.elapsed,
                "tests": self.tests.to_dict() if self.tests is not None else None,
                "regimes": self.regimes.to_dict() if self.regimes is not None else None,
                "spectrum": self.spectrum.to_dict() if self.spectrum is not None else None,
                "drift": self.drift.to_dict() if self.drift is not None else None,
                "details": self.details,
            }
        )
        return out

    # ------------------------------------------------------------------ figure
    def plot(self, path: Any = None, **kw: Any) -> Any:
        """The dashboard figure: measured vs nominal simulation, the error coloured by regime,
        error share by regime, residual correlation tests, gap closed by candidate, and the
        nominal against the best augmented simulation where the error is largest. Returns the
        Figure; with ``path``, saves it (PNG by the file's extension) through the Agg backend.
        Keywords: ``figsize`` (13, 15), ``window`` (samples in the before/after panel, 300),
        ``dpi`` (110)."""
        figsize = kw.pop("figsize", (13, 15))
        window = int(kw.pop("window", 300))
        dpi = kw.pop("dpi", 110)
        if kw:
            raise TypeError(f"unexpected keyword(s) {', '.join(sorted(kw))}: use figsize, window, dpi")
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
        gs = fig.add_gridspec(
            4, 2, height_ratios=[1.1, 1.0, 1.0, 1.0], hspace=0.45, wspace=0.22, top=0.94, bottom=0.04, left=0.16, right=0.98
        )
        self._plot_signals(fig.add_subplot(gs[0, :]))
        self._plot_error(fig.add_subplot(gs[1, :]))
        self._plot_regimes(fig.add_subplot(gs[2, 0]))
        self._plot_tests(fig.add_subplot(gs[2, 1]))
        self._plot_ranking(fig.add_subplot(gs[3, 0]))
        self._plot_before_after(fig.add_subplot(gs[3, 1]), window)
        fig.suptitle(textwrap.fill(f"Diagnosis: {self._verdict()}", width=150), fontsize=10)
        if path is not None:
            fig.savefig(path, dpi=dpi)
        return fig

    def _shade_warmup(self, ax: Any) -> None:
        if self.warmup > 0:
            ax.axvspan(-0.5, self.warmup - 0.5, color="0.9", lw=0, label=f"warm-up ({self.warmup})", zorder=0)

    def _plot_signals(self, ax: Any) -> None:
        t = np.arange(self.n_validation)
        self._shade_warmup(ax)
        ax.plot(t, self.y_nominal, color="C0", lw=0.9, label="nominal simulation")
        ax.plot(t, self.y_val, color="k", lw=0.5, alpha=0.6, label="measured")
        ax.set_title(f"Validation record: measured vs nominal free-run simulation (RMSE {self.nominal_validation_rmse:.4g})")
        ax.set_xlabel("sample")
        ax.set_ylabel("y")
        ax.legend(loc="upper right", fontsize="small", ncol=3)
        ax.grid(alpha=0.3)

    def _plot_error(self, ax: Any) -> None:
        err = np.asarray(self.y_val) - np.asarray(self.y_nominal)
        t = np.arange(err.size)
        self._shade_warmup(ax)
        if self.regimes is not None and self.regimes.masks["dead_band"].size == err.size:
            labels = self.regimes.labels()
            styles = ((-1, "0.75", None), (0, "0.35", "dead band"), (1, "C0", "left branch"), (2, "C3", "right branch"))
            for value, color, name in styles:
                sel = labels == value
                if sel.any():
                    ax.scatter(t[sel], err[sel], s=3, lw=0, color=color, label=name)
        else:
            ax.scatter(t, err, s=3, lw=0, color="0.35", label="error")
        for sign in (-2.0, 2.0):
            ax.axhline(sign * self.noise_std, color="k", ls="--", lw=0.8)
        after = err[self.warmup :]
        if after.size and np.ptp(after) > 0:  # scale to the evaluated samples, not the transient
            pad = 0.08 * float(np.ptp(after))
            ax.set_ylim(min(float(after.min()), -2 * self.noise_std) - pad, max(float(after.max()), 2 * self.noise_std) + pad)
        ax.set_title("Nominal model's error (measured - simulated) by backlash state; dashed: +-2 noise std")
        ax.set_xlabel("sample")
        ax.set_ylabel("error")
        ax.legend(loc="upper right", fontsize="small", ncol=4, markerscale=3)
        ax.grid(alpha=0.3)

    def _plot_regimes(self, ax: Any) -> None:
        if self.regimes is None:
            ax.set_axis_off()
            return
        names = [r.name for r in self.regimes.regimes]
        pos = np.arange(len(names))
        samples = [100 * r.sample_share for r in self.regimes.regimes]
        energy = [100 * r.energy_share for r in self.regimes.regimes]
        ax.bar(pos - 0.2, samples, 0.4, color="0.7", label="share of samples")
        ax.bar(pos + 0.2, energy, 0.4, color="C1", label="share of error energy")
        for i, r in enumerate(self.regimes.regimes):
            if r.significant:
                mark = "*" if r.excess else "(-)"
                ax.text(i + 0.2, energy[i] + 1.5, mark, ha="center", fontsize=11 if r.excess else 8)
        ax.set_xticks(pos)
        ax.set_xticklabels([n.replace("_", "\n") for n in names], fontsize=8)
        ax.set_ylabel("%")
        ax.set_title("Error share by regime (* significantly more error)")
        ax.legend(fontsize="small")
        ax.grid(alpha=0.3, axis="y")

    def _plot_tests(self, ax: Any) -> None:
        if self.tests is None:
            ax.set_axis_off()
            return
        shown = [name for name in ("acf", "ccf_u", "ccf_x") if name in self.tests]
        width = 0.8 / max(len(shown), 1)
        for i, name in enumerate(shown):
            t = self.tests[name]
            offset = (i - (len(shown) - 1) / 2) * width
            label = f"{name} (p {t.p_adjusted:.1e}{'' if t.passed else ', FAIL'})"
            ax.bar(t.lags + offset, t.values, width, color=f"C{i}", label=label)
        bound = self.tests.tests[0].bound
        ax.axhspan(-bound, bound, color="0.85", zorder=0, label=f"95 % bounds +-{bound:.3f}")
        ax.axhline(0.0, color="k", lw=0.5)
        failed = ", ".join(self.tests.failed) or "none"
        ax.set_title(f"Residual correlations (failed tests: {failed})", fontsize=10)
        ax.set_xlabel("lag k")
        ax.set_ylabel("normalised correlation")
        ax.legend(fontsize="x-small")
        ax.grid(alpha=0.3)

    def _plot_ranking(self, ax: Any) -> None:
        if not self.ranking:
            ax.text(0.5, 0.5, "no candidates", ha="center", va="center", transform=ax.transAxes)
            ax.set_axis_off()
            return
        ranked = self.ranking[:12]
        pos = np.arange(len(ranked))
        raw = np.array([c.gap_closed if math.isfinite(c.gap_closed) else 0.0 for c in ranked])
        lo, hi = -0.25, 1.1  # a tiny gap gives huge shares either way: show them clipped
        closed = np.clip(raw, lo, hi)
        colors = ["C2" if c.explains else ("C1" if c.p_value < 0.05 else "0.65") for c in ranked]
        ax.barh(pos, closed, color=colors)
        ax.set_yticks(pos)
        ax.set_yticklabels([f"{c.effect}{'' if c.signature_removed else ' (sig. remains)'}" for c in ranked], fontsize=7)
        ax.invert_yaxis()
        ax.axvline(CLOSES_HALF, color="k", ls="--", lw=0.8)
        ax.axvline(1.0, color="k", lw=0.8)
        ax.set_xlim(min(0.0, float(closed.min()) - 0.05), max(1.05, float(closed.max()) + 0.05))
        clipped = " (clipped)" if np.any(closed != raw) else ""
        ax.set_xlabel(f"share of the gap closed on validation{clipped} (green: >= half and p < 0.05)")
        ax.set_title("Candidates, best first")
        ax.grid(alpha=0.3, axis="x")

    def _plot_before_after(self, ax: Any, window: int) -> None:
        y = np.asarray(self.y_val)
        nominal = np.asarray(self.y_nominal)
        n = y.size
        w = int(np.clip(window, 10, max(n - self.warmup, 10)))
        err2 = (y - nominal) ** 2
        err2[: self.warmup] = 0.0
        if n - self.warmup > w:
            energy = np.convolve(err2, np.ones(w), mode="valid")
            start = int(np.argmax(energy[self.warmup :]) + self.warmup)
        else:
            start = self.warmup
        sl = slice(start, min(start + w, n))
        t = np.arange(n)[sl]
        ax.plot(t, y[sl], color="0.45", lw=1.0, label="measured")
        ax.plot(t, nominal[sl], color="C0", lw=1.0, label="nominal")
        if self.best is not None and self.y_best is not None and np.asarray(self.y_best).size == n:
            name = self.best.effect
            best = np.asarray(self.y_best)
            rmse_b = float(np.sqrt(np.mean((y[sl] - best[sl]) ** 2)))
            ax.plot(t, best[sl], color="C2", lw=1.0, ls="--", label=f"augmented: {name} (RMSE {rmse_b:.3g})")
        rmse_n = float(np.sqrt(np.mean((y[sl] - nominal[sl]) ** 2)))
        ax.set_title(f"Before/after where the nominal error is largest (nominal RMSE {rmse_n:.3g})", fontsize=10)
        ax.set_xlabel("sample")
        ax.set_ylabel("y")
        ax.legend(fontsize="x-small")
        ax.grid(alpha=0.3)

