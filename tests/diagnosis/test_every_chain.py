"""diagnose on every chain the package fits, on lists of records, with composed effects and an
honest noise floor (the plants are simulated here, from the models' public classes)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import backlashid as bid
from backlashid.diagnosis._verdict import Evidence, Score, decide, gap_share, noise_named
from backlashid.diagnosis.effects import AugmentedModel
from backlashid.errors import DataError
from backlashid.identify import evaluate, hammerstein_backlash

N = 3000


def _input(seed: int, n: int = 2 * N) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.uniform(-1.5, 1.5, n)


def _delayed(u: np.ndarray, d: int) -> np.ndarray:
    return np.r_[np.zeros(d), u[:-d]]


# -- the decision rule alone ---------------------------------------------------------------------


def test_rule_names_the_significant_candidate_of_lowest_bic_that_closes_half():
    ev = Evidence(level=1e-3, gap=1.0, floor=0.1)
    scores = [Score("friction", 0.3, 1e-9, -300.0, 0.7), Score("dead_time", 0.2, 1e-12, -500.0, 0.8)]
    assert decide(scores, ev).best == "dead_time"


def test_rule_says_none_without_a_significant_improvement_or_a_material_gap():
    assert decide([Score("friction", 0.9, 0.3, -1.0, 0.1)], Evidence(1e-3, 1.0, 0.1)).best == "none"
    # significant, but the gap is under 1 % of the noise variance
    assert decide([Score("friction", 0.1, 1e-9, -1.0, 1.0)], Evidence(1e-3, 0.0005, 0.1)).best == "none"


def test_rule_ties_in_bic_keep_the_catalogue_order():
    # clipping the input or the state of an input backlash: one model, BICs 1e-3 apart
    scores = [Score("state_saturation", 0.2, 1e-9, -500.001, 1.0), Score("saturation", 0.2, 1e-9, -500.0, 1.0)]
    assert decide(scores, Evidence(1e-3, 1.0, 0.1)).best == "saturation"
    scores[0] = Score("state_saturation", 0.2, 1e-9, -501.0, 1.0)  # a real difference
    assert decide(scores, Evidence(1e-3, 1.0, 0.1)).best == "state_saturation"


def test_rule_names_colored_noise_only_when_the_residual_is_noise():
    noise = Score("colored_noise", 1.0, 1e-9, -10.0, 0.0, deterministic=False)
    weak = Score("friction", 0.95, 1e-4, -5.0, 0.1)
    assert decide([weak, noise], Evidence(1e-3, 0.5, 0.1)).best == "colored_noise"
    # the residual depends on the input: a deterministic model error, never noise
    verdict = decide([weak, noise], Evidence(1e-3, 0.5, 0.1, input_p=1e-6))
    assert verdict.best == "unexplained" and any("input" in r for r in verdict.ruled_out)
    # later composition steps never name a noise model
    assert decide([noise], Evidence(1e-3, 0.5, 0.1, first_step=False)).best == "unexplained"


def test_rule_holds_a_material_candidate_provisionally_for_the_colored_noise_after_it():
    noise = Score("colored_noise", 1.0, 1e-9, -10.0, 0.0, deterministic=False)
    material = Score("compliance", 0.6, 1e-12, -50.0, 0.4)
    verdict = decide([material, noise, Score("friction", 0.9, 1e-4, -5.0, 0.1)], Evidence(1e-3, 1.0, 0.1))
    assert verdict.best == "unexplained" and verdict.provisional == "compliance"
    assert decide([Score("friction", 0.9, 1e-4, -5.0, 0.1), noise], Evidence(1e-3, 1.0, 0.1, input_p=1e-6)).provisional == ""
    # one that closes half but a rule keeps from being named (its residual still modulated) is not
    modulated = Evidence(1e-3, 1.0, 0.1, modulation_p=1e-9)
    drift = Score("width_drift", 0.2, 1e-12, -80.0, 0.8, modulation_left_p=1e-6)
    verdict = decide([drift, noise], modulated)
    assert verdict.best == "unexplained" and "width_drift" in verdict.not_named and verdict.provisional == ""
    # on the provisional model's residual, the first step's noise rule
    later = Evidence(5e-3, 0.5, 0.1, first_step=False)
    assert noise_named(noise, later) == ()
    assert noise_named(Score("colored_noise", 1.0, 0.2, -10.0, 0.0, deterministic=False), later)
    assert noise_named(noise, Evidence(5e-3, 0.5, 0.1, position_p=1e-8, first_step=False))


def test_gap_share_is_clipped_and_finite():
    assert gap_share(1.0, 0.5, 1.0) == 0.5
    assert gap_share(1.0, -5.0, 1.0) == 1.0  # beats the floor: clipped
    assert gap_share(1.0, 1e6, 1.0) == -10.0  # far worse: clipped
    assert gap_share(1.0, 0.5, 0.0) == 0.0  # no gap


# -- every chain -------------------------------------------------------------------------------


def _diagnosed(model, u, y, **kw):
    return bid.diagnose(model, (u[:N], y[:N]), (u[N:], y[N:]), **kw)


def test_sandwich_names_a_dead_time():
    truth = bid.example2()
    u = _input(1)
    y = truth.simulate(_delayed(u, 2)) + 0.01 * np.random.default_rng(2).standard_normal(u.size)
    nominal = bid.fit_sandwich(u[:N], y[:N], na=2, nb=2, nr=2, ns=2, degree=3).model
    report = _diagnosed(nominal, u, y, candidates=["dead_time", "output_offset", "friction"])
    assert report.best_effect == "dead_time" and report.effects == ("dead_time",)
    assert report.best.gap_closed > 0.5 and report.best.validation_rmse < report.nominal_validation_rmse


def test_input_backlash_model_names_an_output_offset():
    truth = hammerstein_backlash(bid.GeneralBacklash(0.2, 0.3, [1.0], [1.0]), bid.LinearBlock([0.3, 0.2], [-0.6, 0.1]))
    u = _input(3)
    y = truth.simulate(u) + 0.3 + 0.01 * np.random.default_rng(4).standard_normal(u.size)
    report = _diagnosed(truth, u, y, candidates=["dead_time", "output_offset"])
    # the refit shares the offset between o_0 and the play's widths (an offset moves a branch)
    assert report.best_effect == "output_offset"
    assert report.best.validation_rmse < 1.5 * 0.01


# -- records, composition, noise floor ------------------------------------------------------


def test_lists_of_records_are_started_separately():
    m = bid.example1()
    rng = np.random.default_rng(5)
    u = [rng.uniform(-1.5, 1.5, 1500) for _ in range(4)]
    y = [m.simulate(v) + 0.02 * rng.standard_normal(v.size) for v in u]
    report = bid.diagnose(m, [(u[0], y[0]), (u[1], y[1])], [(u[2], y[2]), (u[3], y[3])], candidates=["output_offset"])
    assert report.best_effect == "none"
    assert report.details.records == (2, 2)
    assert report.u_val.size == 3000


def test_bad_records_are_named():
    m = bid.example1()
    u = np.zeros(1000)
    with pytest.raises(DataError, match=r"validation\[1\]"):
        bid.diagnose(m, (u, u), [(u, u), (u, np.r_[u[:-1], np.nan])])
    with pytest.raises(DataError, match="estimation must be a pair"):
        bid.diagnose(m, u, (u, u))


def test_two_effects_are_both_named_and_the_model_round_trips():
    m = bid.example1()
    u = _input(6)
    y = m.simulate(_delayed(u, 2)) + 1.5 + 0.01 * np.random.default_rng(7).standard_normal(u.size)
    report = _diagnosed(m, u, y, candidates=["dead_time", "output_offset", "friction"])
    assert set(report.effects) == {"dead_time", "output_offset"}
    assert report.best_effect == report.effects[0]
    assert len(report.steps) == 2 and report.steps[-1].validation_rmse < 2 * 0.01
    back = AugmentedModel.from_dict(json.loads(json.dumps(report.model.to_dict())))
    assert back.effects == report.model.effects
    assert np.array_equal(back.simulate(u[N:]), report.model.simulate(u[N:]))
    assert json.loads(json.dumps(report.to_dict()))["effects"] == list(report.effects)
    # evaluate and simulate_from_samples take the diagnosed model and start it as the diagnosis did
    metrics = evaluate(report.model, u[N:], y[N:], init_samples=report.warmup)
    assert metrics.simulation_rmse == pytest.approx(report.steps[-1].validation_rmse, rel=0.1)
    sim = bid.simulate_from_samples(report.model, u[N:], y[N:], report.warmup)
    assert np.sqrt(np.mean((sim - y[N:])[report.warmup :] ** 2)) == pytest.approx(metrics.simulation_rmse)


@pytest.mark.parametrize("ar_std", [0.02, 0.08])
def test_a_dead_time_with_colored_noise_names_both(ar_std: float):
    """Colored noise is judged on the composed model's residual: named after the dead time,
    whether the dead time closes half of the gap (small noise) or less (the gap then holds the
    noise's predictable part, which no free run closes)."""
    m = bid.example1()
    u = _input(13)
    rng = np.random.default_rng(14)
    e = rng.standard_normal(u.size)
    ar = np.zeros(u.size)
    for t in range(1, u.size):  # AR(1) at pole 0.95, std ar_std
        ar[t] = 0.95 * ar[t - 1] + ar_std * np.sqrt(1 - 0.95**2) * e[t]
    y = m.simulate(_delayed(u, 2)) + ar + 0.005 * rng.standard_normal(u.size)
    report = _diagnosed(m, u, y, candidates=["dead_time", "output_offset", "colored_noise"])
    assert report.effects == ("dead_time", "colored_noise") and report.best_effect == "dead_time"
    assert report.model.ar.size >= 1 and 0.8 < report.model.ar.sum() < 1.0  # AR(1) + white noise: about 0.95
    assert report.steps[1].effect == "colored_noise" and report.steps[1].gap_closed == 0.0 and report.steps[1].p_value < 1e-6
    assert "then colored_noise predicts the rest one step ahead" in report.verdict()
    back = AugmentedModel.from_dict(json.loads(json.dumps(report.model.to_dict())))
    assert np.array_equal(back.ar, report.model.ar)


def test_noise_free_record_reads_as_noise_free():
    m = bid.example1()
    u = _input(9)
    y = m.simulate(_delayed(u, 1))
    report = _diagnosed(m, u, y, candidates=["dead_time", "output_offset"])
    assert report.noise_std < 0.01 * np.std(y)
    assert report.best_effect == "dead_time"
    assert all(-10.0 <= c.gap_closed <= 1.0 for c in report.ranking)


def test_integrating_plant_starts_as_evaluate_does():
    """A position output (a pole at z = 1) that starts mid-motion: the nominal validation error
    is evaluate's with init_samples, not a held start's."""
    model = bid.CascadeModel(bid.LinearBlock([0.05, 0.03], [-1.6, 0.6]), bid.GeneralBacklash(0.1, 0.1, [1.0], [1.0]))
    rng = np.random.default_rng(10)
    n = 2 * N + 500
    u = np.convolve(rng.standard_normal(n), np.ones(20) / 20, mode="same")
    y = model.simulate(u) + 0.005 * rng.standard_normal(n)
    u, y = u[500:], y[500:]
    report = _diagnosed(model, u, y, candidates=["output_offset", "dead_time"], init_samples=40)
    reference = evaluate(model, u[N:], y[N:], init_samples=report.warmup).simulation_rmse
    assert report.nominal_validation_rmse == pytest.approx(reference, rel=0.1)
    assert report.best_effect == "none"


def test_a_quantiser_after_a_dead_time_is_named_second():
    from backlashid.diagnosis.effects._quantization import quantise

    m = bid.example1()
    u = _input(11)
    y = quantise(m.simulate(_delayed(u, 2)) + 0.005 * np.random.default_rng(12).standard_normal(u.size), 0.08)
    report = _diagnosed(m, u, y, candidates=["dead_time", "quantization", "output_offset"])
    assert report.effects == ("dead_time", "quantization")
    assert "then quantization" in report.verdict()
    assert dict(report.model.core)["quantization"] == pytest.approx((0.08,))
