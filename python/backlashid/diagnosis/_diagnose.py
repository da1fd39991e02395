"""Which effects did the nominal model miss? ``diagnose``.

1. The nominal model (any chain the package fits: cascade, sandwich, input backlash;
   ``_records``) is simulated (free run) on every validation record from the state estimated
   from that record's first samples (``_start``); its error after the warm-up is the residual
   the analyses look at (residual tests, regimes, spectrum, drift).
2. Every candidate effect is screened by a score test on the estimation records (ordering,
   reported), then refitted together with the nominal parameters on the estimation records
   (``effects``) and scored on the validation records, each model from its own start.
3. The decision rule (``_verdict.decide``) names the first effect; while ``compose`` is on, the
   search continues from the augmented model: the remaining candidates are refitted on top of
   it (its effects held, the nominal parameters refitted with the new one) and the same rule
   names another while one closes a significant further part of the remaining gap, at most
   ``max_effects`` in all.
4. The noise floor (``_noise``) and the noise and quantiser checks: colored_noise (a noise model,
   judged by one-step prediction, never as a free-run error) is named only when the residual is
   noise, and quantization where the measured outputs lie on a lattice whose rounding matters
   (``_verdict.name_effects``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._validation import check_flag, check_noise_std, check_seed, shown
from ..errors import BacklashIdError, DataError
from ..models import CascadeState, SandwichState
from ._noise import Signals, black_box_residuals, one_step_floor
from ._records import Nominal, nominal_chain, records_of
from ._report import Candidate, CompositionStep, DiagnosisDetails, DiagnosisReport
from ._start import INITIAL_STATES, describe, estimated_start, held_state, nominal_start, refined_start
from ._statistics import modulation_p, paired_p, position_p, signature_removed
from ._verdict import ALPHA, CLOSE_ENOUGH, LATTICE_MATERIAL, Evidence, Naming, Score, Verdict, decide, gap_share, name_effects, noise_named
from .analyses import (
    ModelErrorModel,
    NominalSignals,
    ResidualTests,
    frequency_analysis,
    model_error,
    regime_shares,
    residual_tests,
    time_analysis,
)
from .effects import EFFECTS, REGISTRY, AugmentedModel, Screening
from .effects._base import Augmentation, CoreEffects, RefitRecords, ScreenContext, Simulator, Start, simulate
from .effects._colored_noise import fit_ar
from .effects._dead_time import MAX_DELAY
from .effects._quantization import Lattice, lattice
from .effects._registry import score_tests

__all__ = ["diagnose", "ALPHA", "default_warmup", "estimated_start", "held_state"]

MAX_EFFECTS = 3  # effects named at most by the composition
RESCREENED = 4  # candidates refitted at each later step: the most significant of a new screening
NOT_CONVERGED = "nominal fit did not converge; diagnosed from its best iterate"
NOISE_MODELS = ("colored_noise",)  # judged by one-step prediction, not by a free run
NOT_COMPOSED = ("colored_noise", "quantization")  # named by their own checks after the composition

Array = NDArray[np.float64]


def default_warmup(model: Any, n: int) -> int:
    """The default warm-up of a record: samples until the model forgets its start.

    The slowest pole's transient (of either linear block) decays to 1e-4, plus the blocks'
    memory and the longest dead time searched; at least 20, at most n // 5. A pole on or outside
    the unit circle (a position output integrates) adds nothing: the start is estimated, not
    forgotten.

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The nominal model.
    n : int
        Samples of the shortest record.

    Returns
    -------
    int
        The warm-up in samples.

    Examples
    --------
    >>> import backlashid as bid
    >>> from backlashid.diagnosis import default_warmup
    >>> default_warmup(bid.example1(), 100)
    20
    """
    blocks = [model.input_linear, model.output_linear] if hasattr(model, "output_linear") else [model.linear]
    w = MAX_DELAY
    for block in blocks:
        rho = block.spectral_radius()
        settle = math.ceil(math.log(1e-4) / math.log(rho)) if 0.0 < rho < 1.0 else 0
        w += settle + block.na + block.nb
    return int(min(max(w, 20), n // 5))


@dataclass
class _Run:
    """One model's free run on the validation records, each from its own start."""

    outputs: list[Array]
    starts: list[Start]


@dataclass
class _Scored:
    """One candidate at one step."""

    effect: str
    model: AugmentedModel
    run: _Run
    residual: Array  # scored validation residual (records one after the other)
    mse: float
    est_rmse: float
    p_value: float
    criterion: float
    prediction_rmse: float = float("nan")  # one-step prediction (noise models)


class _Diagnosis:
    """The records, starts and nominal simulations one ``diagnose`` call shares."""

    def __init__(
        self,
        nominal: Nominal,
        est: list[tuple[Array, Array]],
        val: list[tuple[Array, Array]],
        warmup: int,
        init_samples: int,
        initial_state: str,
    ) -> None:
        self.nominal = nominal
        self.est, self.val = est, val
        self.warmup, self.init_samples, self.how = warmup, init_samples, initial_state
        lengths = [u.size for u, _ in est]
        self.t0_est = [float(v) for v in np.r_[0, np.cumsum(lengths)[:-1]]]
        t_val = float(sum(lengths))
        self.t0_val = [t_val + float(v) for v in np.r_[0, np.cumsum([u.size for u, _ in val])[:-1]]]
        s, th = nominal.structure, nominal.theta
        self.starts_est = [nominal_start(nominal, u, y, initial_state, init_samples) for u, y in est]
        self.starts_val = [nominal_start(nominal, u, y, initial_state, init_samples) for u, y in val]
        self.ynom_est = [simulate(s, th, (), u, t0, start=st) for (u, _), t0, st in zip(est, self.t0_est, self.starts_est)]
        self.ynom_val = [simulate(s, th, (), u, t0, start=st) for (u, _), t0, st in zip(val, self.t0_val, self.starts_val)]
        prob = self.problem(())
        self.x_est = _split(prob.linear_output(th), est)
        self.x_val = _split(self.val_problem().linear_output(th), val)
        self.keep_val = np.concatenate([np.arange(u.size) >= warmup for u, _ in val])
        self.y_val = np.concatenate([y for _, y in val])
        self.n = int(self.keep_val.sum())

    # -- problems and runs
    def problem(self, base: CoreEffects, base_params: dict[str, dict[str, float]] | None = None) -> RefitRecords:
        """The refit on the estimation records, ``base`` effects held."""
        return RefitRecords(
            self.nominal.structure, [u for u, _ in self.est], [y for _, y in self.est], self.warmup, self.t0_est,
            self.starts_est, base, base_params,
        )  # fmt: skip

    def val_problem(self) -> RefitRecords:
        """The validation records as a problem (for their linear outputs)."""
        return RefitRecords(self.nominal.structure, [u for u, _ in self.val], [y for _, y in self.val], self.warmup, self.t0_val, self.starts_val)

    def run(self, model: AugmentedModel) -> _Run:
        """The model's free run on every validation record from its own refitted start."""
        outputs, starts = [], []
        for (u, y), t0, st0 in zip(self.val, self.t0_val, self.starts_val):
            sim = Simulator(model.structure, model.theta, model.core, t0)
            st = refined_start(lambda v, s, sim=sim: sim(v, start=s), u, y, self.init_samples, st0) if self.how == "estimate" else st0
            outputs.append(sim(u, start=st))
            starts.append(st)
        return _Run(outputs, starts)

    def est_run(self, model: AugmentedModel) -> list[Array]:
        """The model's free run on every estimation record (from the nominal's starts, as refitted)."""
        return [
            Simulator(model.structure, model.theta, model.core, t0)(u, start=st)
            for (u, _), t0, st in zip(self.est, self.t0_est, self.starts_est)
        ]

    def scored_val(self, outputs: list[Array]) -> Array:
        """The validation residual after the warm-ups, records one after the other."""
        return (self.y_val - np.concatenate(outputs))[self.keep_val]

    def signals(self, outputs_est: list[Array], outputs_val: list[Array]) -> tuple[list[Signals], list[Signals]]:
        """The records as a model of these outputs sees them (x: the nominal's)."""
        w = self.warmup
        est = [Signals(u, y, x, o, w) for (u, y), x, o in zip(self.est, self.x_est, outputs_est)]
        val = [Signals(u, y, x, o, w) for (u, y), x, o in zip(self.val, self.x_val, outputs_val)]
        return est, val


def _split(v: Array, records: list[tuple[Array, Array]]) -> list[Array]:
    cuts = np.cumsum([u.size for u, _ in records])[:-1]
    return list(np.split(v, cuts))


def _check_candidates(candidates: Any) -> tuple[str, ...]:
    if candidates is None:
        return EFFECTS
    if isinstance(candidates, str):
        candidates = (candidates,)
    if not isinstance(candidates, (list, tuple)):
        raise DataError(f"candidates = {shown(candidates)}: give a list of effect names from {', '.join(EFFECTS)}")
    unknown = [c for c in candidates if not isinstance(c, str) or c not in EFFECTS]
    if unknown or not candidates:
        raise DataError(f"unknown candidate effects {unknown}: choose from {', '.join(EFFECTS)}")
    return tuple(dict.fromkeys(candidates))


def _whole(value: Any, name: str, least: int, most: int, what: str) -> int:
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, np.integer)) or not least <= value <= most:
        raise DataError(f"{name} = {value!r}: give a whole number from {least} to {most} ({what})")
    return int(value)


def _screen(d: _Diagnosis, base_model: AugmentedModel | None, candidates: Sequence[str]) -> list[Screening]:
    """Score tests of the candidates on the first estimation record against the step's model."""
    s = d.nominal.structure if base_model is None else base_model.structure
    theta = d.nominal.theta if base_model is None else base_model.theta
    base = () if base_model is None else base_model.core
    (u, y), t0, st = d.est[0], d.t0_est[0], d.starts_est[0]
    y_sim = simulate(s, theta, base, u, t0, start=st)
    return score_tests(ScreenContext(s, theta, u, y, t0, y_sim, st, base), d.warmup, candidates, skip_failing=True)


def _score(d: _Diagnosis, model: AugmentedModel, r_step: Array, seed_outputs: list[Array] | None = None) -> _Scored:
    """A refitted model scored on validation against the step's residual ``r_step``."""
    run = _Run(seed_outputs, d.starts_val) if seed_outputs is not None else d.run(model)
    r = d.scored_val(run.outputs)
    mse = float(r @ r) / d.n
    est = d.est_run(model)
    re = np.concatenate([(y - o)[d.warmup :] for (_, y), o in zip(d.est, est)])
    return _Scored(
        effect=model.effect, model=model, run=run, residual=r, mse=mse, est_rmse=float(np.sqrt(np.mean(re * re))),
        p_value=paired_p(r_step, r), criterion=d.n * math.log(max(mse, 1e-300)) + model.n_extra * math.log(d.n),
    )  # fmt: skip


def _at_zero(augmentation: Augmentation, params: dict[str, float]) -> bool:
    """The refit ended with the effect at its zero size (e.g. no clipping level kept): what it
    changed is the step's own parameters, a better fit of the step's model that no effect
    may take the credit for."""
    return bool(augmentation.names) and all(params.get(n) == z for n, z in zip(augmentation.names, augmentation.zero))


def _refit_all(
    d: _Diagnosis, base_model: AugmentedModel | None, names: Sequence[str], r_step: Array, seed: int
) -> dict[str, _Scored]:
    """Every candidate refitted on top of the step's model and scored."""
    if base_model is None:
        prob, theta0 = d.problem(()), d.nominal.theta
    else:
        base_params = dict(base_model.base_params)
        base_params[base_model.effect] = dict(base_model.params)
        prob = RefitRecords(
            base_model.structure, [u for u, _ in d.est], [y for _, y in d.est], d.warmup, d.t0_est, d.starts_est,
            base_model.core, base_params,
        )  # fmt: skip
        theta0 = base_model.theta
    out: dict[str, _Scored] = {}
    for name in names:
        try:
            aug = REGISTRY[name].fit(prob, theta0)
        except BacklashIdError:
            continue
        if _at_zero(REGISTRY[name].augmentation, aug.params):  # the effect adds nothing: scored as the step's model
            aug = replace(aug, theta=np.asarray(theta0, dtype=np.float64))
        if base_model is not None and base_model.ar.size and not aug.ar.size:
            aug = replace(aug, ar=base_model.ar)
        try:
            scored = _score(d, aug, r_step)
        except BacklashIdError:  # the refitted model diverges on validation: not a candidate
            continue
        if name in NOISE_MODELS:
            pred = np.concatenate([aug.predict_from(o, y) for o, (_, y) in zip(scored.run.outputs, d.val)])
            rp = (d.y_val - pred)[d.keep_val]
            scored.prediction_rmse = float(np.sqrt(np.mean(rp * rp)))
            scored.p_value = paired_p(r_step, rp)  # one-step prediction against the step's simulation
        out[name] = scored
    return out


def diagnose(
    model: Any,
    estimation: Any,
    validation: Any,
    candidates: Sequence[str] | None = None,
    noise_std: float | None = None,
    warmup: int | None = None,
    initial_state: str = "estimate",
    seed: int = 0,
    nominal_converged: bool = True,
    *,
    init_samples: int | None = None,
    compose: bool = True,
    max_effects: int = MAX_EFFECTS,
) -> DiagnosisReport:
    """Which effects beyond the nominal model explain its validation error?

    Every candidate effect is screened and refitted together with the nominal parameters on
    the estimation records, then scored on the validation records by free-run simulation (see
    the module doc for the decision rule); with ``compose`` the search continues from the
    augmented model while another effect closes a significant further part of the gap.

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The nominal model: ``fit_cascade(...).model``, ``fit_sandwich(...).model`` or the
        input-backlash model of ``fit_hammerstein_backlash(...).model``.
    estimation : tuple of array_like, or list of them
        (u_est, y_est), or a list of such records, where the effects are refitted (typically
        the records the nominal model was fitted on).
    validation : tuple of array_like, or list of them
        (u_val, y_val), or a list of records, where they are scored. Records are separate runs:
        each starts from its own estimated state, none is joined to another.
    candidates : sequence of str, optional
        The effects to try (default: every one of ``EFFECTS``).
    noise_std : float, optional
        The measurement noise standard deviation if known (else estimated, see
        :mod:`backlashid.diagnosis._noise`).
    warmup : int, optional
        Samples at the start of each record left out of every criterion (default from the
        slowest pole, :func:`default_warmup`; at least ``init_samples``).
    initial_state : {"estimate", "rest"}, default "estimate"
        How every model starts each record. "estimate": from the state estimated from the
        record's first ``init_samples`` samples (the nominal model's as
        ``evaluate(..., init_samples)`` estimates it, each augmented model's refitted to the
        same samples): records that start mid-motion and drives whose output is a position
        (an integrator) are diagnosed as they are; "rest": from zero, as the paper assumes.
    seed : int, default 0
        Accepted for reproducibility; the refits use no random starts.
    nominal_converged : bool, default True
        False when ``model`` is the best stable iterate of a nominal fit that raised
        ``NotConvergedError``: the diagnosis runs the same and the report says so.
    init_samples : int, optional
        Samples of each record that estimate its start (default: the warm-up).
    compose : bool, default True
        Continue from the augmented model to name further effects (forward selection).
    max_effects : int, default 3
        Effects named at most.

    Returns
    -------
    DiagnosisReport
        The verdict, the named effects and the model with them (``effects``, ``model``), the
        ranked candidates and where the nominal model's error lies.

    Raises
    ------
    DataError
        If a record is unusable (not a pair, lengths, NaN, too short), a candidate is unknown,
        or an option is out of range.
    ModelError
        If ``model`` is not a model the package fits.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> m = bid.example1()
    >>> rng = np.random.default_rng(0)
    >>> u = rng.uniform(-1.5, 1.5, 1200)
    >>> y = m.simulate(np.r_[0.0, 0.0, u[:-2]]) + 0.02 * rng.standard_normal(1200)
    >>> report = bid.diagnose(m, (u[:600], y[:600]), (u[600:], y[600:]), candidates=["dead_time", "output_offset"])
    >>> report.best_effect, report.best.params["d"], report.effects
    ('dead_time', 2, ('dead_time',))
    """
    started = time.perf_counter()
    nominal = nominal_chain(model)
    est = records_of(estimation, "estimation")
    val = records_of(validation, "validation")
    names, max_effects = _checked_options(candidates, initial_state, noise_std, seed, nominal_converged, compose, max_effects)
    w, n_init = _warmups(nominal, est, val, warmup, init_samples, initial_state)
    d = _Diagnosis(nominal, [(nominal.advanced(u), y) for u, y in est], [(nominal.advanced(u), y) for u, y in val], w, n_init, initial_state)

    # the nominal model's error, every candidate against it, the composition, the quantiser
    nom = _nominal_error(d)
    first = _first_step(d, names, nom, noise_std, seed)
    grid = lattice(np.concatenate([y for _, y in (*d.est, *d.val)])) if "quantization" in names else None
    steps, last, named_first = _composition(d, names, nom, first, compose, max_effects, seed, grid)
    lattice_share = _lattice_share(grid, steps, nom.mse)
    naming = name_effects(named_first, tuple(s.effect for s in steps), lattice_share)
    final, final_run = _named_model(d, last, naming, grid)
    details = _details(d, nom, first, naming, grid, lattice_share, warmup is not None, nominal_converged)
    return _report(d, nom, first, naming, steps, final, final_run, details, noise_std is None, started)


def _checked_options(
    candidates: Any, initial_state: Any, noise_std: Any, seed: Any, nominal_converged: Any, compose: Any, max_effects: Any
) -> tuple[tuple[str, ...], int]:
    """The options ``diagnose`` checks before it reads the records' lengths: the candidates and
    the most effects named."""
    names = _check_candidates(candidates)
    if not isinstance(initial_state, str) or initial_state not in INITIAL_STATES:
        raise DataError(f"initial_state = {shown(initial_state)}: choose one of {', '.join(map(repr, INITIAL_STATES))}")
    if noise_std is not None:
        check_noise_std(noise_std, "noise_std (the noise standard deviation, or None to estimate it)")
    check_seed(seed)
    check_flag(nominal_converged, "nominal_converged")
    check_flag(compose, "compose")
    return names, _whole(max_effects, "max_effects", 1, 10, "effects named at most")


def _warmups(
    nominal: Nominal, est: list[tuple[Array, Array]], val: list[tuple[Array, Array]], warmup: Any, init_samples: Any, initial_state: str
) -> tuple[int, int]:
    """The warm-up and the samples that estimate each record's start, checked against the
    shortest record."""
    n_min = min(u.size for u, _ in (*est, *val))
    w = default_warmup(nominal.model, n_min) if warmup is None else _whole(warmup, "warmup", 0, max(n_min - 200, 0), "samples that leave at least 200 of each record")
    n_init = w if init_samples is None else _whole(init_samples, "init_samples", 1, max(n_min - 200, 1), "samples that estimate each record's start")
    w = max(w, n_init) if initial_state == "estimate" else w
    if n_min - w < 200:
        raise DataError(
            f"the shortest record has {n_min} samples, fewer than 200 after the warm-up of {w}: "
            "give longer estimation and validation records (thousands of samples)"
        )
    return w, n_init


@dataclass
class _NominalError:
    """The nominal model's validation error and what the black-box tests find in it."""

    residual: Array  # scored validation residual
    mse: float
    sig_e: list[Signals]
    sig_v: list[Signals]
    black_box: Array  # the black-box predictor's residual
    phi: Array  # the residual's AR model on the estimation records
    y_scored: Array  # the nominal's scored validation output
    tests: ResidualTests  # of the validation residual
    p_black_box: float
    p_input: float  # the black box of input features, or the prewhitened ccf with u or x
    p_modulation: float
    p_position: float
    p_input_black_box: float  # the cross-validated black box of input features alone


def _nominal_error(d: _Diagnosis) -> _NominalError:
    """The nominal model on validation and the black-box tests of its residual."""
    phi, _ = fit_ar(d.problem(()), d.nominal.theta)
    return _residual_evidence(d, d.ynom_est, d.ynom_val, phi)


def _residual_evidence(d: _Diagnosis, outs_est: list[Array], outs_val: list[Array], phi: Array) -> _NominalError:
    """A model's validation residual (the model simulated as ``outs_est`` / ``outs_val``) and
    the black-box tests of it; ``phi`` prewhitens the modulation test."""
    w = d.warmup
    r0 = d.scored_val(outs_val)
    mse0 = float(r0 @ r0) / d.n
    sig_e, sig_v = d.signals(outs_est, outs_val)
    r_in, r_bb = black_box_residuals(sig_e, sig_v)
    p_input_bb, p_black_box = paired_p(r0, r_in), paired_p(r0, r_bb)
    y_v_scored = np.concatenate(outs_val)[d.keep_val]
    x_e_s = np.concatenate([x[w:] for x in d.x_est])
    y_e_s = np.concatenate([o[w:] for o in outs_est])
    r_e_s = np.concatenate([(y - o)[w:] for (_, y), o in zip(d.est, outs_est)])
    x_v_s = np.concatenate([x[w:] for x in d.x_val])
    p_modulation = modulation_p(r0, y_v_scored, phi)
    # the validation residual's own (prewhitened) cross-correlation with the input and with x:
    # a residual that depends on them is no noise, even where the black box fitted on an
    # estimation record of narrow excitation cannot follow it onto a richer validation record
    u_all, x_all = np.concatenate([u for u, _ in d.val]), np.concatenate(d.x_val)
    tests = residual_tests(r0, u_all[d.keep_val], x_all[d.keep_val])
    p_input = min(p_input_bb, tests["ccf_u"].p_adjusted, tests["ccf_x"].p_adjusted)
    p_position = position_p(x_e_s, y_e_s, r_e_s, x_v_s, y_v_scored, r0)
    return _NominalError(r0, mse0, sig_e, sig_v, r_bb, phi, y_v_scored, tests, p_black_box, p_input, p_modulation, p_position, p_input_bb)


@dataclass
class _FirstStep:
    """Every candidate against the nominal model: the noise floor, the gap and the verdict."""

    screening: list[Screening]
    scored: dict[str, _Scored]
    floor: float
    floor_how: str
    gap: float
    level: float
    gap_closed: dict[str, float]
    verdict: Verdict


def _first_step(d: _Diagnosis, names: Sequence[str], nom: _NominalError, noise_std: float | None, seed: int) -> _FirstStep:
    """Step 0: every candidate screened, refitted and scored against the nominal model."""
    screening = _screen(d, None, names)
    scored = _refit_all(d, None, [s.effect for s in screening], nom.residual, seed)
    if noise_std is not None:
        floor, floor_how = float(noise_std) ** 2, "given noise_std"
    else:
        floor = min(one_step_floor(nom.sig_e, nom.sig_v, nom.mse, with_signals=nom.black_box), _candidate_floor(d, scored))
        floor_how = (
            "estimated: the lowest validation MSE of one-step predictors of a residual (the residual's last 10 values, "
            "with and without input lags, the internal signal x and its velocity and powers of the output; fitted on "
            "the estimation records): the nominal model's residual and the best candidate's"
        )
    gap = max(nom.mse - floor, 0.0)
    level = ALPHA / (len(scored) + 1)
    scores = [_as_score(s, nom.mse, gap, nom.y_scored, nom.phi, level, nom.p_modulation) for s in scored.values()]
    verdict = decide(scores, Evidence(level, gap, floor, nom.p_black_box, nom.p_input, nom.p_modulation, nom.p_position, True))
    return _FirstStep(screening, scored, floor, floor_how, gap, level, {s.effect: s.gap_closed for s in scores}, verdict)


def _composition(
    d: _Diagnosis,
    names: Sequence[str],
    nom: _NominalError,
    first: _FirstStep,
    compose: bool,
    max_effects: int,
    seed: int,
    grid: Lattice | None,
) -> tuple[list[CompositionStep], _Scored | None, str]:
    """The effects named one after the other, the last model (None: nothing named) and the
    first effect named (or the first step's "none" / "unexplained"); colored noise is not
    looked for where the measured outputs' lattice ``grid`` explains the residual's structure."""
    verdict = first.verdict
    best = verdict.best
    provisional = best not in first.scored and compose and bool(verdict.provisional) and max_effects >= 2
    if best not in first.scored and not provisional:
        return [], None, best
    last = first.scored[verdict.provisional if provisional else best]
    steps = [CompositionStep(last.effect, first.gap_closed[last.effect], math.sqrt(last.mse), float(last.p_value))]
    if not compose or last.effect in NOISE_MODELS:
        return steps, last, best
    # continue from the augmented model
    while len(steps) < max_effects and last.effect not in NOISE_MODELS:
        nxt = _next_step(d, names, nom, first.floor, last, seed, grid, room=max_effects - len(steps))
        if nxt is None:
            break
        last, added = nxt
        steps.extend(added)
    if len(steps) < max_effects and last.effect not in NOISE_MODELS:  # the colored noise the composed model's residual holds
        noise = _noise_step(d, nom, last, first.floor, seed, grid)
        if noise is not None:
            last = noise[0]
            steps.append(noise[1])
    if not provisional:
        return steps, last, best
    # a provisional first effect stands with colored noise after it, or where the effects
    # together close half of the nominal model's gap
    together = gap_share(nom.mse, last.mse, first.gap)
    if last.effect in NOISE_MODELS or together >= CLOSE_ENOUGH:
        return steps, last, steps[0].effect
    return [], None, best


def _next_step(
    d: _Diagnosis, names: Sequence[str], nom: _NominalError, floor: float, last: _Scored, seed: int, grid: Lattice | None, room: int
) -> tuple[_Scored, list[CompositionStep]] | None:
    """The remaining candidates refitted on top of the last model, and the step(s) the rule
    names (None: no further one; a provisional effect comes with its colored noise, where
    ``room`` leaves two more effects)."""
    final = last.model
    left = [e for e in names if e not in final.effects and e not in NOT_COMPOSED]
    if not left:
        return None
    rescreen = [s.effect for s in _screen(d, final, left)][:RESCREENED]
    more = _refit_all(d, final, rescreen, last.residual, seed)
    if not more:
        return None
    gap_step = max(last.mse - floor, 0.0)
    lvl = ALPHA / (len(more) + 1)
    sc = [_as_score(s, last.mse, gap_step, nom.y_scored, nom.phi, lvl, 1.0) for s in more.values()]
    nxt = decide(sc, Evidence(lvl, gap_step, floor, 1.0, 1.0, 1.0, 1.0, False))
    closed = {s.effect: s.gap_closed for s in sc}
    if nxt.best in more:
        chosen = more[nxt.best]
        return chosen, [CompositionStep(nxt.best, closed[nxt.best], math.sqrt(chosen.mse), float(chosen.p_value))]
    if nxt.best == "none" or not nxt.provisional or room < 2:
        return None
    cand = more[nxt.provisional]
    noise = _noise_step(d, nom, cand, floor, seed, grid)
    if noise is None:
        return None
    return noise[0], [CompositionStep(cand.effect, closed[cand.effect], math.sqrt(cand.mse), float(cand.p_value)), noise[1]]


def _noise_step(
    d: _Diagnosis, nom: _NominalError, base: _Scored, floor: float, seed: int, grid: Lattice | None
) -> tuple[_Scored, CompositionStep] | None:
    """colored_noise on top of ``base`` if the rule names it on ``base``'s residual
    (:func:`noise_named`), else None; never where the measured outputs' lattice ``grid``
    rounds off a material share of that residual (a rounding error is correlated where the
    output moves slowly: the quantiser explains it, see :func:`name_effects`)."""
    if "colored_noise" in base.model.effects or (grid is not None and grid.q**2 / 12.0 >= LATTICE_MATERIAL * base.mse):
        return None
    noise = _refit_all(d, base.model, ["colored_noise"], base.residual, seed).get("colored_noise")
    if noise is None:
        return None
    level = ALPHA / 2  # the noise model and the black box
    if not noise.p_value < level:
        return None
    ev = _residual_evidence(d, d.est_run(base.model), base.run.outputs, nom.phi)
    gap = max(base.mse - floor, 0.0)
    score = _as_score(noise, base.mse, gap, ev.y_scored, nom.phi, level, 1.0)
    # the input dependence judged by the cross-validated black box alone: the composed model's
    # parameters, refitted on records with colored noise, carry an estimation error that the
    # prewhitened ccf finds though no model of the input predicts it on validation
    if noise_named(score, Evidence(level, gap, floor, ev.p_black_box, ev.p_input_black_box, ev.p_modulation, ev.p_position, False)):
        return None
    return noise, CompositionStep(noise.effect, 0.0, math.sqrt(noise.mse), float(noise.p_value))


def _lattice_share(grid: Lattice | None, steps: list[CompositionStep], mse0: float) -> float:
    """The quantiser after the noise: the measured values' lattice's rounding variance (``grid``;
    None without one, or without quantization among the candidates) over the final model's
    validation MSE."""
    model_mse = (steps[-1].validation_rmse ** 2) if steps else mse0
    return grid.q**2 / 12.0 / model_mse if grid is not None and model_mse > 0 else 0.0


def _named_model(d: _Diagnosis, last: _Scored | None, naming: Naming, grid: Lattice | None) -> tuple[AugmentedModel | None, _Run | None]:
    """The model with the effects named and its validation run (None: the nominal model)."""
    if not (naming.lattice and grid is not None):
        return (last.model, last.run) if last is not None else (None, None)
    # the quantiser on the composed model, or alone on the nominal model
    base = last.model if last is not None and naming.best != "quantization" else _nominal_model(d.nominal)
    final = _with_quantiser(base, float(grid.q), naming.effects)
    return final, d.run(final)


def _with_quantiser(base: AugmentedModel, q: float, effects: tuple[str, ...]) -> AugmentedModel:
    """``base`` with the measured output's lattice of step ``q`` on top."""
    q_core: CoreEffects = (("quantization", (q,)),)
    return replace(
        base, effect="quantization", params={"q": q}, core=(*q_core, *base.core), effects=effects, n_extra=base.n_extra + 1,
        base_params={**base.base_params, **({base.effect: dict(base.params)} if base.effect else {})},
    )  # fmt: skip


def _lattice_text(grid: Lattice, share: float) -> str:
    """The lattice check in words."""
    return (
        f"the measured output lies on a lattice of step q = {grid.q:.6g} ({grid.occupied} of {grid.levels} levels "
        f"occupied); its rounding variance q^2/12 is {100 * share:.3g} % of the model's validation MSE"
        + ("" if share >= LATTICE_MATERIAL else " (not named: immaterial)")
    )


def _model_error(nom: _NominalError, warmup: int, floor: float) -> ModelErrorModel:
    """A gap the catalogue leaves: how much any model of the nominal's own signals closes, and which."""
    return model_error(
        [NominalSignals(s.u, s.x, s.y_nom, s.residual) for s in nom.sig_e],
        [NominalSignals(s.u, s.x, s.y_nom, s.residual) for s in nom.sig_v],
        warmup=warmup, noise_floor=floor,
    )  # fmt: skip


def _ranking(d: _Diagnosis, first: _FirstStep, naming: Naming) -> list[Candidate]:
    """The first step's candidates, the one reported first, then the others named, then by BIC."""
    ordered = sorted(first.scored.values(), key=lambda s: (s.effect != naming.best, s.effect not in naming.effects, s.criterion))
    return [
        Candidate(
            effect=s.effect, gap_closed=float(first.gap_closed[s.effect]), p_value=float(s.p_value), model=s.model,
            params=dict(s.model.params), n_extra=int(s.model.n_extra), estimation_rmse=s.est_rmse,
            validation_rmse=float(math.sqrt(s.mse)), criterion=float(s.criterion),
            signature_removed=signature_removed(s.residual, (np.concatenate(s.run.outputs) - np.concatenate(d.ynom_val))[d.keep_val]),
            prediction_rmse=s.prediction_rmse, validation_output=np.concatenate(s.run.outputs),
        )
        for s in ordered
    ]  # fmt: skip


def _details(
    d: _Diagnosis,
    nom: _NominalError,
    first: _FirstStep,
    naming: Naming,
    grid: Lattice | None,
    lattice_share: float,
    warmup_given: bool,
    nominal_converged: bool,
) -> DiagnosisDetails:
    """How the verdict was reached: the tests, the floor, the lattice, the model-error model."""
    mem = _model_error(nom, d.warmup, first.floor) if naming.best == "unexplained" else None
    return DiagnosisDetails(
        screening=tuple(first.screening),
        black_box_p_value=nom.p_black_box,
        input_p_value=nom.p_input,
        modulation_p_value=nom.p_modulation,
        position_p_value=nom.p_position,
        significance_level=first.level,
        noise_floor=first.floor_how,
        warmup_rule="given" if warmup_given else "slowest pole's transient to 1e-4 plus the blocks' memory and dead-time search",
        screened_order=tuple(s.effect for s in first.screening),
        initial_state=describe(d.how, d.init_samples),
        colored_noise_ruled_out=first.verdict.ruled_out,
        closing_not_named=first.verdict.not_named,
        lattice="" if grid is None else _lattice_text(grid, lattice_share),
        nominal_fit="converged" if nominal_converged else NOT_CONVERGED,
        records=(len(d.est), len(d.val)),
        floor_exceeded=tuple(s.effect for s in first.scored.values() if first.gap > 0 and s.mse < first.floor),
        model_error=mem,
    )


def _report(
    d: _Diagnosis,
    nom: _NominalError,
    first: _FirstStep,
    naming: Naming,
    steps: list[CompositionStep],
    final: AugmentedModel | None,
    final_run: _Run | None,
    details: DiagnosisDetails,
    noise_estimated: bool,
    started: float,
) -> DiagnosisReport:
    """The report: the verdict, the ranking and where the nominal model's error lies."""
    ranking = _ranking(d, first, naming)
    noise = math.sqrt(first.floor)
    y_nominal = np.concatenate(d.ynom_val)
    y_best = np.concatenate(final_run.outputs) if final_run is not None else y_nominal
    residual_full = d.y_val - y_nominal
    u_val_all = np.concatenate([u for u, _ in d.val])
    first_val = d.val[0]
    state0 = _state(d.nominal, d.starts_val[0])
    regimes = regime_shares(d.nominal.model, first_val[0], first_val[1] - d.ynom_val[0], warmup=d.warmup, initial_state=state0)
    spectrum = frequency_analysis(residual_full[d.keep_val], u_val_all[d.keep_val], noise_std=noise)
    drift = time_analysis(residual_full[d.keep_val])
    return DiagnosisReport(
        best_effect=naming.best,
        ranking=ranking,
        regimes=regimes,
        tests=nom.tests,
        spectrum=spectrum,
        drift=drift,
        noise_std=noise,
        noise_std_estimated=noise_estimated,
        nominal_validation_rmse=math.sqrt(nom.mse),
        gap=first.gap,
        warmup=d.warmup,
        u_val=u_val_all,
        y_val=d.y_val,
        y_nominal=y_nominal,
        y_best=y_best,
        elapsed=time.perf_counter() - started,
        details=details,
        effects=naming.effects,
        model=final if final is not None else _nominal_model(d.nominal),
        steps=tuple(steps),
    )


def _candidate_floor(d: _Diagnosis, scored: dict[str, _Scored]) -> float:
    """The one-step predictor's validation MSE on the residual of the candidate of lowest
    validation MSE (inf without one): what is left once the best candidate's error is predicted
    from the input and its own past."""
    det = [s for s in scored.values() if s.effect not in NOISE_MODELS]
    if not det:
        return math.inf
    best = min(det, key=lambda s: s.mse)
    try:
        sig_e, sig_v = d.signals(d.est_run(best.model), best.run.outputs)
        return one_step_floor(sig_e, sig_v, best.mse)
    except BacklashIdError:
        return math.inf


def _as_score(s: _Scored, mse_step: float, gap: float, y_out: Array, phi: Array, level: float, p_mod: float) -> Score:
    """A scored candidate as the verdict reads it (the modulation left in its residual tested
    only where the step's residual is modulated)."""
    noise_model = s.effect in NOISE_MODELS
    left = modulation_p(s.residual, y_out, phi) if (p_mod < level and not noise_model) else float("nan")
    return Score(s.effect, s.mse, s.p_value, s.criterion, 0.0 if noise_model else gap_share(mse_step, s.mse, gap), left, not noise_model)


def _nominal_model(nominal: Nominal) -> AugmentedModel:
    """The nominal chain as an augmented model without effects."""
    return AugmentedModel("", nominal.structure, nominal.theta, {}, (), effects=())


def _state(nominal: Nominal, start: Start) -> CascadeState | SandwichState | None:
    """A start as the nominal model's state object (None for rest)."""
    if not start:
        return None
    if nominal.is_sandwich:
        return SandwichState(tuple(start["u_past"]), tuple(start["x_past"]), tuple(start["y_past"]), tuple(start["w_past"]))
    return CascadeState(tuple(start["u_past"]), tuple(start["x_past"]), float(start["y_prev"]))

