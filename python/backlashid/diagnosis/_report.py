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
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from .._json import jsonable
from .analyses import FrequencyAnalysis, RegimeShares, ResidualTests, TimeAnalysis
from .effects import Screening

__all__ = ["Candidate", "CompositionStep", "DiagnosisDetails", "DiagnosisReport"]
CLOSES_HALF = 0.5  # a candidate "explains" the gap when it closes at least this share


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
    record and scored on the validation record.

    Attributes
    ----------
    effect : str
        A name from ``EFFECTS``.
    gap_closed : float
        Fraction of the validation gap above the noise floor removed.
    p_value : float
        Significance of the validation improvement over the nominal model.
    model : AugmentedModel or object
        The refitted augmented model: ``.simulate(u)`` gives y, ``.to_dict()`` is JSON-safe.
    params : dict of str to float
        The effect's own fitted parameters.
    n_extra : int
        Number of extra parameters over the nominal model.
    estimation_rmse : float
        Free-run simulation RMSE on the estimation record (one-step prediction RMSE for
        colored_noise).
    validation_rmse : float
        The same on the validation record.
    criterion : float
        Information criterion used in the ranking (lower is better).
    signature_removed : bool
        The residual signature the effect predicts is gone after augmentation.
    prediction_rmse : float
        One-step prediction RMSE on the validation records (noise models only; NaN else).
    validation_output : ndarray or None
        Its free-run simulation of the validation records (records one after the other).

    Examples
    --------
    >>> from backlashid.diagnosis import Candidate
    >>> c = Candidate("dead_time", 0.9, 1e-9, None, {"d": 2}, 1, 0.05, 0.05, -100.0, True)
    >>> c.explains
    True
    """

    CLOSES_HALF: ClassVar[float] = CLOSES_HALF

    effect: str
    gap_closed: float
    p_value: float
    model: Any
    params: dict[str, float]
    n_extra: int
    estimation_rmse: float
    validation_rmse: float
    criterion: float
    signature_removed: bool
    prediction_rmse: float = float("nan")
    validation_output: NDArray[np.float64] | None = field(default=None, repr=False, compare=False)

    @property
    def explains(self) -> bool:
        """Closes at least half of the gap, significantly."""
        return bool(self.gap_closed >= CLOSES_HALF and self.p_value < 0.05)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe description, the refitted model included.

        Returns
        -------
        dict
            ``json.dumps`` works on it.
        """
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
                "prediction_rmse": self.prediction_rmse,
                "model": _model_dict(self.model),
            }
        )
        return out


@dataclass(frozen=True)
class CompositionStep:
    """One effect named by the composition, in the order added.

    Attributes
    ----------
    effect : str
        The effect.
    gap_closed : float
        The share of the remaining gap (the previous step's validation MSE above the noise
        floor) it closed, within [-10, 1].
    validation_rmse : float
        The free-run validation RMSE of the model with it and every earlier effect.
    p_value : float
        p-value of its improvement over the previous step's model.

    Examples
    --------
    >>> from backlashid.diagnosis import CompositionStep
    >>> CompositionStep("dead_time", 0.97, 0.02, 1e-30).to_dict()["effect"]
    'dead_time'
    """

    effect: str
    gap_closed: float
    validation_rmse: float
    p_value: float

    def to_dict(self) -> dict[str, Any]:
        """The fields as a JSON-safe dict.

        Returns
        -------
        dict
            effect, gap_closed, validation_rmse, p_value.
        """
        out: dict[str, Any] = jsonable({k: getattr(self, k) for k in self.__dataclass_fields__})
        return out


@dataclass(frozen=True)
class DiagnosisDetails:
    """The diagnoser's intermediate numbers and reasons behind the verdict.

    Attributes
    ----------
    screening : tuple of Screening
        The score tests of the candidates, most significant first.
    black_box_p_value : float
        p-value of the black-box residual model's (with the residual's past) improvement.
    input_p_value : float
        Does the residual depend on the input? The lower of the p-values of the black-box model
        of input features alone (fitted on estimation, scored on validation) and of the
        validation residual's prewhitened cross-correlation tests with the input and with x
        (Holm-adjusted).
    modulation_p_value : float
        p-value of the residual being a slowly modulated copy of the output.
    position_p_value : float
        p-value of the residual being a function of where the drive is (its bin means of the
        nominal model's x and output, fitted on the estimation record, predict the validation
        residual): noise does not depend on the position, a cogging torque does.
    significance_level : float
        The Bonferroni-corrected level the candidates were judged at.
    noise_floor : str
        Where the noise floor came from.
    warmup_rule : str
        Where the warm-up came from.
    screened_order : tuple of str
        The candidates in screening order.
    initial_state : str
        How every model started the validation record.
    colored_noise_ruled_out : tuple of str
        Why colored_noise was not named.
    closing_not_named : dict of str to str
        Candidates that close half the gap yet were not named, and why.
    lattice : str
        The lattice the measured output lies on (a quantiser after the noise) and whether it
        was named; empty when there is none.
    nominal_fit : str
        "converged", or that the nominal model is the best iterate of a fit that did not
        converge; empty when not stated.
    records : tuple of int
        The numbers of estimation and validation records.
    floor_exceeded : tuple of str
        Candidates whose validation MSE is below the estimated noise floor (their share of the
        gap is clipped to 1: the floor may be high).
    model_error : object or None
        For a gap no catalogue effect explains: the model-error model of the nominal's residual
        (``closable_share``, the signals it needs, ``summary``); None otherwise.

    Examples
    --------
    >>> from backlashid.diagnosis import DiagnosisDetails
    >>> DiagnosisDetails(closing_not_named={"friction": "dead_time has the lower BIC"}).to_dict()["closing_not_named"]
    {'friction': 'dead_time has the lower BIC'}
    """

    screening: tuple[Screening, ...] = ()
    black_box_p_value: float = float("nan")
    input_p_value: float = float("nan")
    modulation_p_value: float = float("nan")
    position_p_value: float = float("nan")
    significance_level: float = float("nan")
    noise_floor: str = ""
    warmup_rule: str = ""
    screened_order: tuple[str, ...] = ()
    initial_state: str = ""
    colored_noise_ruled_out: tuple[str, ...] = ()
    closing_not_named: dict[str, str] = field(default_factory=dict)
    lattice: str = ""
    nominal_fit: str = ""
    records: tuple[int, int] = (1, 1)
    floor_exceeded: tuple[str, ...] = ()
    model_error: Any = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe dict of the fields (the screenings as dicts).

        Returns
        -------
        dict
            ``json.dumps`` works on it.
        """
        out: dict[str, Any] = jsonable({k: getattr(self, k) for k in self.__dataclass_fields__ if k != "model_error"})
        out["model_error"] = _model_dict(self.model_error)
        return out


@dataclass(frozen=True)
class DiagnosisReport:
    """What :func:`diagnose` found: the best effect, the ranked candidates, and where the
    nominal model's validation error lies.

    Attributes
    ----------
    best_effect : str
        A name from ``EFFECTS``, "none" or "unexplained".
    ranking : list of Candidate
        The refitted candidates, best first.
    regimes : RegimeShares
        The validation error's share per backlash regime.
    tests : ResidualTests
        Correlation tests of the nominal model's validation residual.
    spectrum : FrequencyAnalysis
        The residual's spectrum against the noise floor.
    drift : TimeAnalysis
        The residual's trends and change points.
    noise_std : float
        The noise standard deviation (given or estimated).
    noise_std_estimated : bool
        Whether ``noise_std`` was estimated.
    nominal_validation_rmse : float
        Free-run simulation RMSE of the nominal model on the validation record.
    gap : float
        Nominal validation MSE above the noise floor (>= 0).
    warmup : int
        Samples at the start of each record left out.
    u_val : ndarray
        Validation input.
    y_val : ndarray
        Validation output.
    y_nominal : ndarray
        Nominal simulation of the validation record.
    y_best : ndarray
        The best candidate's output (the nominal one without a best candidate).
    elapsed : float
        Seconds the diagnosis took.
    details : DiagnosisDetails or None
        The diagnoser's intermediate numbers (None for a report built by hand).
    effects : tuple of str
        The effects named, in the order the composition added them (empty for "none" and
        "unexplained"); ``best_effect`` is the first.
    model : AugmentedModel or None
        The nominal model (normalised: m_L1 = 1, r_1 = 1) with every named effect, refitted:
        ``model.simulate(u, initial_state=...)``, ``model.to_dict()`` and
        ``AugmentedModel.from_dict`` (JSON round trip). Without a named effect, the nominal
        model itself. For a nominal block with a lag-0 term, it is driven by the input one
        sample ahead per such block.
    steps : tuple of CompositionStep
        Per named effect: the share of the remaining gap it closed and the validation RMSE.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> from backlashid.diagnosis import DiagnosisReport
    >>> z = np.zeros(3)
    >>> r = DiagnosisReport("none", [], None, None, None, None, 0.1, True, 0.1, 0.0, 0, z, z, z, z, 0.5)
    >>> r.verdict()
    'none: no gap beyond the noise (nominal RMSE 0.1, noise std 0.1)'
    """

    best_effect: str
    ranking: list[Candidate]
    regimes: RegimeShares
    tests: ResidualTests
    spectrum: FrequencyAnalysis
    drift: TimeAnalysis
    noise_std: float
    noise_std_estimated: bool
    nominal_validation_rmse: float
    gap: float
    warmup: int
    u_val: NDArray[np.float64]
    y_val: NDArray[np.float64]
    y_nominal: NDArray[np.float64]
    y_best: NDArray[np.float64]
    elapsed: float
    details: DiagnosisDetails | None = None
    effects: tuple[str, ...] = ()
    model: Any = None
    steps: tuple[CompositionStep, ...] = ()

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
        """Number of validation samples."""
        return int(np.asarray(self.y_val).size)

    @property
    def gap_ratio(self) -> float:
        """The gap relative to the noise variance."""
        var = float(self.noise_std) ** 2
        return float(self.gap) / var if var > 0 else float("nan")

    # ------------------------------------------------------------------ text
    def verdict(self) -> str:
        """The verdict in one line: the effect named and how much of the gap it closes, or why
        none is named.

        Returns
        -------
        str
            The verdict.
        """
        text = self._verdict()
        fit = self.details.nominal_fit if self.details is not None else ""
        return text if fit in ("", "converged") else f"{text} ({fit})"

    def _verdict(self) -> str:
        best = self.best
        lattice = self.details.lattice if self.details is not None else ""
        if self.best_effect == "quantization" and lattice and "(not named" not in lattice:
            return f"quantization: {lattice}"
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
            held = self.details.closing_not_named if self.details is not None else {}
            if top and top.effect in held:
                tail += f", but {held[top.effect]}"
            for c in self.ranking:
                if c.effect in held and c is not top:
                    tail += f"; {c.effect} closes {_pct(c.gap_closed).strip()}, but {held[c.effect]}"
                    break
            if self.ranking and self.ranking[0].effect == "colored_noise":
                tail += "; colored_noise predicts the residual one step ahead but is not named" + self._not_noise()
            first = "no deterministic candidate explains" if held else "no deterministic candidate closes by half"
            mem = self.details.model_error if self.details is not None else None
            if mem is not None and getattr(mem, "summary", ""):
                tail += f"; {mem.summary}"
            return f"unexplained: a significant gap that {first}{tail}"
        if best is None:
            return f"{self.best_effect}"
        # a quantiser named from the lattice after the deterministic effects has no step of its own
        quantiser = f"; then quantization: {lattice}" if "quantization" in self.effects[1:] and lattice else ""
        if len(self.steps) > 1:
            parts = [
                f"{st.effect} predicts the rest one step ahead (a noise model: the free run is unchanged; p = {_p(st.p_value)})"
                if st.effect == "colored_noise"
                else f"{st.effect} closes {_pct(st.gap_closed).strip()} of the {'gap' if i == 0 else 'rest'} (p = {_p(st.p_value)})"
                for i, st in enumerate(self.steps)
            ]
            return (
                f"{' + '.join(self.effects)}: " + ", then ".join(parts)
                + f"; validation RMSE {self.nominal_validation_rmse:.4g} -> {self.steps[-1].validation_rmse:.4g}"
                + quantiser
            )
        # the rule names it (significant, closes half); the signature is the dashboard's secondary check
        sig = "is gone" if best.signature_removed else "still shows in its residual"
        return (
            f"{best.effect}: closes {_pct(best.gap_closed).strip()} of the gap (p = {_p(best.p_value)}); "
            f"secondary check: the residual signature it predicts {sig}{quantiser}"
        )

    def _not_noise(self) -> str:
        """Why the residual is not noise, as the diagnoser recorded it in ``details``."""
        reasons = self.details.colored_noise_ruled_out if self.details is not None else ()
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
            f"Verdict: {self.verdict()}",
            f"Nominal free-run simulation RMSE {self.nominal_validation_rmse:.4g}; noise std {self.noise_std:.4g} ({src}); "
            f"gap above the noise floor (MSE) {self.gap:.3g}"
            + (f" = {self.gap_ratio:.2f} x noise variance" if math.isfinite(self.gap_ratio) else ""),
        ]
        if self.ranking:
            lines += [
                "",
                "Candidates, best first (validation RMSE of the free-run simulation; colored_noise, a noise model, "
                "is judged by its one-step prediction RMSE, shown in brackets)",
                f"  {'#':>2}  {'effect':18s} {'gap closed':>10s} {'p-value':>8s} {'+par':>4s} {'est RMSE':>9s} "
                f"{'val RMSE':>9s} {'criterion':>10s}  signature",
            ]
            for i, c in enumerate(self.ranking[:12], 1):
                extra = f"  (one-step {c.prediction_rmse:.4g})" if math.isfinite(c.prediction_rmse) else ""
                lines.append(
                    f"  {i:2d}  {c.effect:18s} {_pct(c.gap_closed):>10s} {_p(c.p_value):>8s} {c.n_extra:4d} "
                    f"{c.estimation_rmse:9.4g} {c.validation_rmse:9.4g} {c.criterion:10.4g}  "
                    f"{'removed' if c.signature_removed else 'remains'}{extra}"
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
                "details": self.details.to_dict() if self.details is not None else {},
                "effects": list(self.effects),
                "steps": [st.to_dict() for st in self.steps],
                "model": _model_dict(self.model),
            }
        )
        return out

    # ------------------------------------------------------------------ figure
    def plot(self, path: Any = None, **kw: Any) -> Any:
        """The dashboard figure (drawn by :func:`backlashid.app.plot_diagnosis`).

        Measured vs nominal simulation, the error coloured by regime, error share by regime,
        residual correlation tests, gap closed by candidate, and the nominal against the best
        augmented simulation where the error is largest.

        Parameters
        ----------
        path : str or path-like, optional
            Where to save it (PNG by the file's extension), through the Agg backend.
        **kw
            ``figsize`` (default (13, 15)), ``window`` (samples in the before/after panel,
            default 300), ``dpi`` (default 110), and the record's units: ``scaling`` (the
            :class:`~backlashid.identify.Scaling` of the records, so outputs and errors are
            drawn in measured units), ``output`` (axis label, e.g. ``"force [kip]"``),
            ``sample_time`` (seconds per sample, so time is in seconds), ``records`` (the
            validation records' lengths, where each starts marked; found from the runs when
            not given).

        Returns
        -------
        matplotlib.figure.Figure
            The figure.

        Raises
        ------
        TypeError
            If an unknown keyword is given.
        """
        from ._dashboard import plot_diagnosis

        return plot_diagnosis(self, path, **kw)
