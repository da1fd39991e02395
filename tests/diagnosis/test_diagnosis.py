"""diagnose(): which effect beyond the nominal cascade explains its validation error."""

from __future__ import annotations

import json

import numpy as np
import pytest

import backlashid as bx
from backlashid.diagnosis import effects as fx
from backlashid.diagnosis.effects import _base
from backlashid.identify import Structure

N = 3000


def _records(planted: dict, noise: float, seed: int) -> tuple[tuple, tuple]:
    """One continuous record of example 1 with a planted effect (the augmented simulator),
    split into estimation and validation halves; neither starts at rest for the second."""
    m = bx.example1()
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1.5, 1.5, 2 * N)
    s = Structure(2, 2, 3)
    core = tuple(c for effect, params in planted.items() for c in fx.REGISTRY[effect].core(params))
    y = _base.simulate(s, s.pack(m), core, u, 0.0) + noise * rng.standard_normal(2 * N)
    return (u[:N], y[:N]), (u[N:], y[N:])


@pytest.fixture(scope="module")
def clean():
    est, val = _records({}, 0.03, seed=11)
    model = bx.fit_cascade(*est, 2, 2, 3, warmup=50).model
    return model, est, val, bx.diagnose(model, est, val)


def test_clean_nominal_record_is_none(clean) -> None:
    _, _, _, report = clean
    assert report.best_effect == "none"
    assert report.noise_std_estimated
    assert abs(report.noise_std - 0.03) < 0.1 * 0.03  # the honest floor is close to the truth
    assert all(c.p_value > 1e-3 for c in report.ranking)


def test_planted_dead_time_is_named() -> None:
    est, val = _records({"dead_time": {"d": 2}}, 0.05, seed=12)
    model = bx.fit_cascade(*est, 2, 2, 3, warmup=50).model
    report = bx.diagnose(model, est, val)
    assert report.best_effect == "dead_time"
    best = report.ranking[0]
    assert best.effect == "dead_time" and best.params["d"] == 2
    assert best.gap_closed > 0.9 and best.p_value < 1e-6 and best.signature_removed
    assert report.elapsed < 10.0


def test_known_noise_and_candidate_subset() -> None:
    est, val = _records({"saturation": {"lo": -1.0, "hi": 1.1}}, 0.03, seed=13)
    model = bx.fit_cascade(*est, 2, 2, 3, warmup=50).model
    report = bx.diagnose(model, est, val, candidates=["saturation", "friction"], noise_std=0.03)
    assert not report.noise_std_estimated and report.noise_std == 0.03
    assert {c.effect for c in report.ranking} == {"saturation", "friction"}
    assert report.best_effect == "saturation"


def test_report_is_json_serialisable(clean) -> None:
    _, _, _, report = clean
    data = json.loads(json.dumps(report.to_dict()))
    assert data["best_effect"] == "none"
    assert len(data["ranking"]) == len(bx.EFFECTS)
    assert isinstance(report.summary(), str) and "none" in report.summary()


def test_bad_inputs_raise_actionable_errors(clean) -> None:
    model, est, val, _ = clean
    with pytest.raises(bx.DataError, match="pair"):
        bx.diagnose(model, est[0], val)
    with pytest.raises(bx.DataError, match="one record"):
        bx.diagnose(model, (est[0], est[1][:-1]), val)
    with pytest.raises(bx.DataError, match="choose from"):
        bx.diagnose(model, est, val, candidates=["gremlins"])
    with pytest.raises(bx.DataError, match="noise_std"):
        bx.diagnose(model, est, val, noise_std=-1.0)
    with pytest.raises(bx.DataError, match="warmup"):
        bx.diagnose(model, est, val, warmup=N)
    with pytest.raises(bx.DataError, match="longer"):
        bx.diagnose(model, (est[0][:150], est[1][:150]), val)
    with pytest.raises(bx.DataError, match="non-finite|NaN|finite"):
        bad = est[1].copy()
        bad[5] = np.nan
        bx.diagnose(model, (est[0], bad), val)
    with pytest.raises(bx.ModelError, match="CascadeModel.*SandwichModel"):
        bx.diagnose(bx.LinearBlock([1.0]), est, val)


def test_caller_arrays_are_not_mutated(clean) -> None:
    model, est, val, _ = clean
    copies = [a.copy() for a in (*est, *val)]
    bx.diagnose(model, est, val, candidates=["dead_time"])
    for a, b in zip((*est, *val), copies):
        np.testing.assert_array_equal(a, b)


def test_a_drifting_output_gain_is_unexplained_not_misattributed() -> None:
    # outside the catalogue: y * (1 + 0.15 sin(pi t / T)) over the continuous record
    m = bx.example1()
    rng = np.random.default_rng(14)
    u = rng.uniform(-1.5, 1.5, 2 * N)
    gain = 1.0 + 0.15 * np.sin(np.pi * np.arange(2 * N) / (2 * N))
    y = m.simulate(u) * gain + 0.03 * rng.standard_normal(2 * N)
    est, val = (u[:N], y[:N]), (u[N:], y[N:])
    model = bx.fit_cascade(*est, 2, 2, 3, warmup=50).model
    assert bx.diagnose(model, est, val).best_effect == "unexplained"


def test_colored_noise_is_named_on_prediction_error() -> None:
    m = bx.example1()
    rng = np.random.default_rng(15)
    u = rng.uniform(-1.5, 1.5, 2 * N)
    c = np.zeros(2 * N)
    w = 0.05 * rng.standard_normal(2 * N)
    for t in range(1, 2 * N):
        c[t] = 0.9 * c[t - 1] + w[t]
    y = m.simulate(u) + c + 0.02 * rng.standard_normal(2 * N)
    est, val = (u[:N], y[:N]), (u[N:], y[N:])
    model = bx.fit_cascade(*est, 2, 2, 3, warmup=50).model
    report = bx.diagnose(model, est, val)
    assert report.best_effect == "colored_noise"
    best = report.ranking[0]
    # AR(1) plus white noise is ARMA(1, 1): judge the prediction, not phi_1 alone
    assert best.prediction_rmse < 0.75 * report.nominal_validation_rmse  # one-step, against the free run
    assert best.validation_rmse == pytest.approx(report.nominal_validation_rmse)  # a noise model leaves the simulation
    assert 0.8 < sum(best.params.values()) < 0.95


def test_a_validation_record_that_starts_holding_a_force_is_not_a_gap() -> None:
    # the device moved, then stood still for 600 samples holding its backlash memory (output
    # 0.4 off zero) when the validation record starts: no warm-up flushes that memory, so from
    # rest the nominal model looks wrong; the estimated initial state sees no gap
    m, rng, noise = bx.example1(), np.random.default_rng(21), 0.03
    u_e = rng.uniform(-1.5, 1.5, N)
    u_v = np.r_[np.full(600, 0.6), rng.uniform(-1.5, 1.5, N - 600)]
    moving = np.r_[rng.uniform(-1.5, 1.5, 300), np.linspace(1.5, 0.6, 50)]  # ends in the dead band
    sim = m.simulate(moving, internals=True)
    assert abs(sim.output[-1]) > 0.3
    y_v = m.simulate(u_v, initial_state=sim.final_state) + noise * rng.standard_normal(N)
    y_e = m.simulate(u_e) + noise * rng.standard_normal(N)
    model = bx.fit_cascade(u_e, y_e, 2, 2, 3, warmup=50).model
    est, val = (u_e, y_e), (u_v, y_v)
    estimated = bx.diagnose(model, est, val, noise_std=noise)
    assert estimated.best_effect == "none"
    assert estimated.nominal_validation_rmse < 1.2 * noise
    assert "estimated" in estimated.details.initial_state
    from_rest = bx.diagnose(model, est, val, noise_std=noise, initial_state="rest")
    assert from_rest.best_effect != "none" and from_rest.nominal_validation_rmse > 2 * noise
    with pytest.raises(bx.DataError, match="initial_state"):
        bx.diagnose(model, est, val, initial_state="zero")


def test_withheld_effect_benchmark_subset() -> None:
    # a small subset of benches/withheld_effects.py (the generator's own effect code, not the
    # diagnoser's): the nominal structure fitted on the estimation record, then diagnosed
    from backlashid.benchmarks import cases

    effects = ("none", "friction", "quantization", "width_drift", "compliance", "colored_noise", "output_gain_drift")
    reported = {}
    for case in cases(levels=(3.0,), per_effect=1, effects=effects, seed=5):
        model = bx.fit_cascade(case.u_est, case.y_est, case.na, case.nb, case.degree, warmup=100).model
        report = bx.diagnose(model, (case.u_est, case.y_est), (case.u_val, case.y_val))
        reported[case.effect] = report.best_effect
        assert report.elapsed < 10.0
    # a catalogue effect is named, no effect is "none", a drifting output gain (outside the
    # catalogue) is "unexplained"
    assert reported == {**{e: e for e in effects}, "output_gain_drift": "unexplained"}


def test_a_model_with_feedthrough_is_diagnosed_through_its_shifted_form() -> None:
    # a_0 u(t) + a_1 u(t-1) + .. equals the same coefficients at lags 1.. on u(t+1)
    from backlashid.diagnosis._records import nominal_chain

    m, rng = bx.example1(), np.random.default_rng(31)
    model = bx.CascadeModel(bx.LinearBlock([0.3, 0.7, 0.5], [-0.2, 0.35], feedthrough=True), m.backlash)
    u = rng.uniform(-1.5, 1.5, 2 * N)
    clean = model.simulate(u)
    chain = nominal_chain(model)
    assert chain.shift == 1 and not chain.model.linear.feedthrough
    np.testing.assert_allclose(chain.model.simulate(chain.advanced(u))[50:], clean[50:], atol=1e-9)
    y = clean + 0.03 * rng.standard_normal(2 * N)
    report = bx.diagnose(model, (u[:N], y[:N]), (u[N:], y[N:]), noise_std=0.03)
    assert report.best_effect == "none" and report.nominal_validation_rmse < 1.1 * 0.03


def test_held_start_needs_an_equilibrium() -> None:
    from backlashid.diagnosis import held_state

    m = bx.example1()
    state = held_state(m, 0.6, 0.2)
    assert state.x_past == (m.linear.static_gain() * 0.6,) * 2 and state.u_past == (0.6, 0.6)
    integrator = bx.CascadeModel(bx.LinearBlock([0.5], [-1.0]), m.backlash)  # x(t) = x(t-1) + 0.5 u(t-1)
    with pytest.raises(bx.ModelError, match="pole at z = 1.*initial_state='rest'"):
        held_state(integrator, 0.6, 0.2)
