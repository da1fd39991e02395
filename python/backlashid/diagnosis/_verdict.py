"""The diagnosis's decision rule, on numbers alone (no model, no record), so it can be read and
tested by itself.

At each step of the composition the candidates are scored against the model of that step (the
nominal model, then the nominal with the effects named so far): each candidate's validation MSE,
the one-sided p-value of its improvement over the step's model (paired test on the squared
free-run errors, Newey-West standard error), its BIC n ln(MSE) + k ln(n), and the share of the
remaining gap (the step's MSE above the noise floor) it closes. The family-wise level is
``ALPHA`` with Bonferroni over the candidates and the black-box test.

:func:`decide`:

- "none" if nothing improves on the step's model significantly, or the remaining gap is under
  ``MATERIAL_GAP`` of the noise variance (a consistent but immaterial improvement);
- else the significant deterministic candidate of lowest BIC (BICs within ``SAME_CRITERION``
  are one model written two ways: the catalogue's order), if it closes at least
  ``CLOSE_ENOUGH`` of the gap (and, when the step's residual is a slowly modulated copy of the
  output, leaves no such modulation in its own residual);
- else (first step only) colored_noise if no significant deterministic candidate closes
  ``MATERIAL`` of the gap, its noise model predicts the residual significantly better one step
  ahead, and the residual is neither explained by the input (a cross-validated black box of input
  features, or its prewhitened cross-correlation with the input or x), nor modulated by the model's output, nor a function of the drive's position;
- else "unexplained"; where a significant deterministic candidate closes ``MATERIAL`` of the gap
  (not half), the one of lowest BIC is the step's ``provisional`` effect: the diagnosis names it
  with colored_noise when its own residual is colored noise (:func:`noise_named`: the noise rule
  on that residual), since the gap then holds the predictable part of colored noise, which no
  free run closes.

:func:`noise_named`, after the composition's deterministic effects (and on a provisional
effect): colored_noise is added when its noise model predicts the model's residual
significantly better one step ahead and that residual depends neither on the input, nor on the
output's modulation, nor on the drive's position.

:func:`name_effects`, once the composition has named its effects: quantization is added where the
measured outputs lie on a lattice whose rounding variance q^2 / 12 is at least ``LATTICE_MATERIAL``
of the final model's validation MSE (and the composition did not name it); it is the effect
reported, alone on the nominal model, where the first step found "none", colored_noise or
"unexplained".
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field

from .effects import EFFECTS

__all__ = [
    "ALPHA", "CLOSE_ENOUGH", "LATTICE_MATERIAL", "MATERIAL", "MATERIAL_GAP", "Evidence", "Naming", "Score", "Verdict", "decide",
    "gap_share", "name_effects", "noise_named",
]  # fmt: skip

ALPHA = 0.01  # family-wise significance level of "the validation error improved"
CLOSE_ENOUGH = 0.5  # a candidate must close at least this fraction of the gap
MATERIAL = 0.25  # a significant deterministic candidate closing this much rules out colored noise
MATERIAL_GAP = 0.01  # a gap under this fraction of the noise variance is "none", however significant
LATTICE_MATERIAL = 0.1  # a lattice's rounding variance q^2 / 12 over this share of the model's MSE is named
SHARE_RANGE = (-10.0, 1.0)  # a gap share is reported within this range
SAME_CRITERION = 0.01  # BICs this close are one model written two ways (clipping the input or the
# state of an input backlash, whose input block is a delay): the catalogue's order decides


@dataclass(frozen=True)
class Score:
    """One candidate scored against the step's model.

    Attributes
    ----------
    effect : str
        Its name.
    mse : float
        Its validation MSE (free run).
    p_value : float
        One-sided p-value of its improvement over the step's model.
    criterion : float
        Its BIC on the validation records.
    gap_closed : float
        Share of the step's gap it closes (:func:`gap_share`).
    modulation_left_p : float
        p-value of the output modulation left in its residual (NaN: not tested).
    deterministic : bool
        False for a noise model (colored_noise).
    """

    effect: str
    mse: float
    p_value: float
    criterion: float
    gap_closed: float
    modulation_left_p: float = float("nan")
    deterministic: bool = True


@dataclass(frozen=True)
class Evidence:
    """What the rule knows of the step's residual besides the candidates.

    Attributes
    ----------
    level : float
        The Bonferroni-corrected level.
    gap : float
        The step's validation MSE above the noise floor.
    floor : float
        The noise floor (MSE).
    black_box_p : float
        p-value of the black-box one-step predictor's improvement (is there anything to find?).
    input_p, modulation_p, position_p : float
        p-values of the residual depending on the input, on the output's slow modulation, on
        the drive's position.
    first_step : bool
        Whether the step's model is the nominal model (colored_noise is judged there only).
    """

    level: float
    gap: float
    floor: float
    black_box_p: float = 1.0
    input_p: float = 1.0
    modulation_p: float = 1.0
    position_p: float = 1.0
    first_step: bool = True


@dataclass(frozen=True)
class Verdict:
    """The rule's answer at one step.

    Attributes
    ----------
    best : str
        An effect's name, "none" or "unexplained".
    not_named : dict of str to str
        Candidates that close half the gap yet were not named, and why.
    ruled_out : tuple of str
        Why colored_noise was not named (first step).
    provisional : str
        Where the answer is "unexplained": the significant deterministic candidate of lowest
        BIC among those closing ``MATERIAL`` of the gap (empty: none). It is named with
        colored_noise if its own residual is colored noise (:func:`noise_named`): the gap's
        predictable part that no free run closes.
    """

    best: str
    not_named: dict[str, str] = field(default_factory=dict)
    ruled_out: tuple[str, ...] = ()
    provisional: str = ""


@dataclass(frozen=True)
class Naming:
    """The diagnosis's answer once the composition is done.

    Attributes
    ----------
    best : str
        The effect reported: an effect's name, "none" or "unexplained".
    effects : tuple of str
        The effects of the report's model, in the order named (empty for "none" and
        "unexplained").
    lattice : bool
        Whether the quantiser is added after the composition (on the composed model, or on the
        nominal model when ``best`` is "quantization").
    """

    best: str
    effects: tuple[str, ...]
    lattice: bool = False


def gap_share(mse_step: float, mse: float, gap: float) -> float:
    """The share of the gap a model of validation MSE ``mse`` closes, clipped to
    ``SHARE_RANGE`` (0 where there is no gap).

    Examples
    --------
    >>> from backlashid.diagnosis._verdict import gap_share
    >>> gap_share(2.0, 1.5, 1.0), gap_share(2.0, 0.5, 1.0), gap_share(2.0, 2.0, 0.0)
    (0.5, 1.0, 0.0)
    """
    if not gap > 0 or not math.isfinite(mse):
        return 0.0
    lo, hi = SHARE_RANGE
    return float(min(max((mse_step - mse) / gap, lo), hi))


def decide(scores: list[Score], ev: Evidence) -> Verdict:
    """The verdict of one step (see the module doc).

    Parameters
    ----------
    scores : list of Score
        Every candidate scored against the step's model.
    ev : Evidence
        The rest of what the rule reads.

    Returns
    -------
    Verdict
        The effect named (or "none" / "unexplained") and the reasons.

    Examples
    --------
    >>> from backlashid.diagnosis._verdict import Evidence, Score, decide
    >>> ev = Evidence(level=0.001, gap=1.0, floor=0.1)
    >>> decide([Score("dead_time", 0.2, 1e-20, -500.0, 0.9), Score("friction", 0.8, 1e-5, -100.0, 0.3)], ev).best
    'dead_time'
    >>> decide([Score("friction", 0.8, 1e-5, -100.0, 0.3)], ev).best
    'unexplained'
    >>> decide([Score("friction", 1.05, 0.4, -100.0, 0.0)], ev).best
    'none'
    """
    level = ev.level
    significant = {s.effect for s in scores if s.p_value < level}
    if not (significant or ev.black_box_p < level) or not ev.gap > MATERIAL_GAP * ev.floor:
        return Verdict("none")
    deterministic = _by_criterion(s for s in scores if s.deterministic and s.effect in significant)
    not_named: dict[str, str] = {}
    closing = [s for s in deterministic if s.gap_closed >= CLOSE_ENOUGH]
    if closing and ev.modulation_p < level:
        closing = _leaving_no_modulation(closing, level, not_named)
    if closing and closing[0] is deterministic[0]:
        return Verdict(closing[0].effect, not_named)
    if closing:
        not_named[closing[0].effect] = f"{deterministic[0].effect} has the lower BIC"
    for s in scores:
        if s.deterministic and s.effect not in significant and s.gap_closed >= CLOSE_ENOUGH:
            not_named[s.effect] = f"its improvement is not significant (p {s.p_value:.2g} >= {level:.2g})"
    noise = [s for s in scores if not s.deterministic]
    ruled_out: list[str] = []
    if ev.first_step and noise:
        ruled_out = _noise_ruled_out(noise[0], deterministic, significant, ev)
        if not ruled_out and not closing:
            # no "closes half" here: a noise model predicts only the predictable part of colored
            # noise, its innovations are as unpredictable as white noise
            return Verdict(noise[0].effect, not_named)
    # a candidate that closes half the gap yet a rule kept from being named is never provisional
    material = [s.effect for s in deterministic if MATERIAL <= s.gap_closed < CLOSE_ENOUGH and s.effect not in not_named]
    return Verdict("unexplained", not_named, tuple(ruled_out), material[0] if material else "")


def _by_criterion(scores: Iterable[Score]) -> list[Score]:
    """The scores by BIC; those within ``SAME_CRITERION`` of the first of their run are one
    model written two ways and keep the catalogue's order."""
    out: list[Score] = []
    for group in _runs(sorted(scores, key=lambda s: s.criterion)):
        out += sorted(group, key=lambda s: EFFECTS.index(s.effect) if s.effect in EFFECTS else len(EFFECTS))
    return out


def _runs(ordered: list[Score]) -> list[list[Score]]:
    runs: list[list[Score]] = []
    for s in ordered:
        if runs and s.criterion - runs[-1][0].criterion <= SAME_CRITERION:
            runs[-1].append(s)
        else:
            runs.append([s])
    return runs


def noise_named(noise: Score, ev: Evidence) -> tuple[str, ...]:
    """Why colored_noise is not named on a model's residual after the first step (empty: it is
    named): the first step's rule for colored noise, on that model's residual.

    Examples
    --------
    >>> from backlashid.diagnosis._verdict import Evidence, Score, noise_named
    >>> noise = Score("colored_noise", 1.0, 1e-9, -10.0, 0.0, deterministic=False)
    >>> noise_named(noise, Evidence(level=0.005, gap=1.0, floor=0.2, first_step=False))
    ()
    >>> noise_named(noise, Evidence(level=0.005, gap=1.0, floor=0.2, input_p=1e-6, first_step=False))
    ('the residual depends on the input (p 1e-06)',)
    """
    significant = {noise.effect} if noise.p_value < ev.level else set()
    return tuple(_noise_ruled_out(noise, [], significant, ev))


def _leaving_no_modulation(closing: list[Score], level: float, not_named: dict[str, str]) -> list[Score]:
    """The closing candidates that leave no output modulation in their residual (the step's
    residual is a slowly modulated copy of the output: a drifting gain is no width drift); the
    others go into ``not_named``."""
    kept = []
    for s in closing:
        if math.isnan(s.modulation_left_p) or s.modulation_left_p >= level:
            kept.append(s)
        else:
            not_named[s.effect] = f"its residual is still modulated by the output (p {s.modulation_left_p:.2g})"
    return kept


def _noise_ruled_out(noise: Score, deterministic: list[Score], significant: set[str], ev: Evidence) -> list[str]:
    """Why colored_noise is not named at the first step (empty: nothing rules it out)."""
    level = ev.level
    material = [s.effect for s in deterministic if s.gap_closed >= MATERIAL]
    ruled_out: list[str] = []
    if noise.effect not in significant:
        ruled_out.append("its noise model does not predict significantly better")
    if ev.input_p < level:
        ruled_out.append(f"the residual depends on the input (p {ev.input_p:.2g})")
    if ev.modulation_p < level:
        ruled_out.append(f"the residual is modulated by the output (p {ev.modulation_p:.2g})")
    if ev.position_p < level:
        ruled_out.append(f"the residual depends on the drive's position (p {ev.position_p:.2g})")
    if material:
        ruled_out.append(f"{material[0]} closes over a quarter of the gap")
    return ruled_out


def name_effects(first: str, composed: tuple[str, ...], lattice_share: float) -> Naming:
    """The diagnosis's answer once the composition is done (see the module doc).

    Parameters
    ----------
    first : str
        The first step's verdict (:func:`decide`): an effect, "none" or "unexplained".
    composed : tuple of str
        The effects the composition named, in order (empty for "none" and "unexplained").
    lattice_share : float
        The measured outputs' lattice rounding variance q^2 / 12 over the final model's
        validation MSE (0 without a lattice or without quantization among the candidates).

    Returns
    -------
    Naming
        The effect reported, the effects of the report's model, and whether the quantiser is
        added after the composition.

    Examples
    --------
    >>> from backlashid.diagnosis._verdict import name_effects
    >>> name_effects("dead_time", ("dead_time", "friction"), 0.01).effects
    ('dead_time', 'friction')
    >>> name_effects("dead_time", ("dead_time",), 0.3).effects
    ('dead_time', 'quantization')
    >>> name_effects("none", (), 0.3).best
    'quantization'
    """
    if lattice_share >= LATTICE_MATERIAL and "quantization" not in composed:
        if first in ("none", "colored_noise", "unexplained"):  # the quantiser alone, on the nominal model
            return Naming("quantization", ("quantization",), lattice=True)
        return Naming(first, (*composed, "quantization"), lattice=True)
    return Naming(first, composed if first not in ("none", "unexplained") else ())
