"""Feedforward compensation (compensate, Compensator) and the closed loop (closed_loop)."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import backlashid as bid
from backlashid import CascadeState, DataError, ModelError, SandwichState
from conftest import load_bench


def _bench():
    return load_bench("compensation", "compensation_bench")


def _reference(n: int = 800) -> np.ndarray:
    t = np.arange(n)
    return 0.7 * np.sin(0.017 * t) + 0.25 * np.sin(0.053 * t + 1.0)


STATES = {
    "cascade": (bid.example1, CascadeState((0.3, -0.2), (0.5, 0.1), 0.4)),
    "sandwich": (bid.example2, SandwichState((0.3, -0.2), (0.5, 0.1), (0.2, 0.1), (0.3, 0.25))),
}


@pytest.mark.parametrize("kind", sorted(STATES))
@pytest.mark.parametrize("at_rest", [True, False])
def test_the_compensated_model_follows_the_reference_from_sample_d_on(kind: str, at_rest: bool) -> None:
    make, state = STATES[kind]
    model = make()
    start = None if at_rest else state
    r = _reference()
    u = bid.compensate(model, r, initial_state=start)
    y = model.simulate(u, initial_state=start)
    d = bid.Compensator(model).delay
    assert d == (1 if kind == "cascade" else 2)
    np.testing.assert_allclose(y[d:], r[d:], rtol=0, atol=1e-10)


def test_compensation_beats_the_uncompensated_feedforward_twenty_fold() -> None:
    # benches/compensation.py: true and identified models (N = 1500, SNR 25, seed 0) of both
    # examples, on a multisine and a trapezoidal profile, the TRUE model as the plant
    rows = _bench().measure(1500, seed=0)
    assert len(rows) == 8
    for row in rows:
        assert row.ratio >= 20, row
        assert row.rmse_unc > 0.1  # the backlash ignored costs a visible error


def test_the_compensator_steps_and_runs_in_blocks_and_pickles_with_its_state() -> None:
    model = bid.example2()
    r = _reference(300)
    whole = bid.compensate(model, r)
    comp = bid.Compensator(model)
    d = comp.delay
    targets = np.concatenate([r[d:], np.full(d, r[-1])])
    assert comp.run([]).size == 0
    first = comp.run(targets[:100])
    stepped = [comp.step(v) for v in targets[100:110]]
    copy = pickle.loads(pickle.dumps(comp))
    rest_a = comp.run(targets[110:])
    rest_b = copy.run(targets[110:])
    np.testing.assert_array_equal(rest_a, rest_b)
    np.testing.assert_allclose(np.concatenate([first, stepped, rest_a]), whole, rtol=0, atol=1e-14)
    assert "SandwichModel" in repr(comp) and comp.model is model and comp.threshold == 0.0


def test_a_non_minimum_phase_block_gets_the_stable_approximate_inverse() -> None:
    # numerator 0.3 z + 0.9: a zero at -3
    model = bid.CascadeModel(bid.LinearBlock([0.3, 0.9], [-0.5]), bid.example1().backlash)
    comp = bid.Compensator(model)
    assert comp.approximate
    # a slow monotone reference from the rest output: tracked (the static gain is kept). At a
    # reversal the jump across the dead band excites the approximation's all-pass error, which
    # the backlash can keep: no tracking claim there (compensate's docstring says so)
    # (in steady state on the dead band's right edge x = c_R = 0.5, so that x need not jump)
    u_ss = 0.5 / 2.4  # static gain (0.3 + 0.9) / (1 - 0.5)
    start = CascadeState((u_ss, u_ss), (0.5,), 0.0)
    r = 0.6 * np.sin(2 * np.pi * 0.0005 * np.arange(500))
    u = bid.compensate(model, r, initial_state=start)
    assert np.all(np.isfinite(u)) and np.max(np.abs(u)) < 10
    y = model.simulate(u, initial_state=start)
    assert np.max(np.abs(y - r)) < 0.01
    assert not bid.Compensator(bid.example1()).approximate


@pytest.mark.parametrize("make", [bid.example1, bid.example2])
def test_a_pi_loop_tracks_better_with_the_compensator(make) -> None:
    plant = make()
    half = 0.4 if make is bid.example1 else 0.2
    r = _bench().trapezoid(1500, half, half)  # from the rest output 0: no start-up jump
    pi = bid.closed_loop(plant, r, kp=0.3, ki=0.1)
    comp = bid.Compensator(plant)
    state_before = comp._native.get_state()
    with_ff = bid.closed_loop(plant, r, kp=0.3, ki=0.1, compensator=comp)
    assert comp._native.get_state() == state_before  # the caller's compensator is not advanced
    with_model = bid.closed_loop(plant, r, kp=0.3, ki=0.1, compensator=plant)
    np.testing.assert_allclose(with_ff.output, with_model.output, atol=1e-12)
    assert with_ff.rmse < 0.5 * pi.rmse
    np.testing.assert_allclose(with_ff.feedforward, bid.compensate(plant, r), atol=1e-14)
    assert np.all(pi.feedforward == 0)
    assert with_ff.rmse == pytest.approx(np.sqrt(np.mean((with_ff.output - r) ** 2)))
    # no feedback: the plant driven by the feedforward alone
    open_loop = bid.closed_loop(plant, r, kp=0.0, compensator=plant)
    np.testing.assert_allclose(open_loop.output, plant.simulate(open_loop.feedforward), atol=1e-12)
    limited = bid.closed_loop(plant, r, kp=2.0, ki=0.5, saturation=(-0.3, 0.3))
    assert np.all(np.abs(limited.input) <= 0.3)


@pytest.mark.parametrize("make", [bid.example1, bid.example2])
def test_a_perfect_feedforward_leaves_the_pid_idle(make) -> None:
    # the controller compares y(t-1) with r(t-1): with the true model's feedforward the error is
    # zero on ramps too (compared with r(t) it was r(t) - r(t-1), and the PID pushed off the ramp)
    plant = make()
    half = 0.4 if make is bid.example1 else 0.2
    r = _bench().trapezoid(1500, half, half)
    loop = bid.closed_loop(plant, r, kp=0.3, ki=0.1, kd=0.05, compensator=plant)
    np.testing.assert_allclose(loop.input, loop.feedforward, rtol=0, atol=1e-12)
    assert loop.rmse < 1e-12
    # warmup leaves the start out of the rmse: a reference away from the rest output
    start = bid.closed_loop(plant, r + 0.3, kp=0.3, ki=0.1, compensator=plant, warmup=50)
    assert start.warmup == 50
    assert start.rmse == pytest.approx(np.sqrt(np.mean((start.output - start.reference)[50:] ** 2)))


def test_the_closed_loop_result_plots() -> None:
    import matplotlib.figure

    res = bid.closed_loop(bid.example1(), _reference(200), kp=0.3, ki=0.1, compensator=bid.example1())
    fig = res.plot()
    assert isinstance(fig, matplotlib.figure.Figure) and len(fig.axes) == 3
    import matplotlib.pyplot as plt

    plt.close(fig)


def test_bad_inputs_are_refused_and_nothing_is_mutated() -> None:
    model = bid.example1()
    r = _reference(50)
    r_copy = r.copy()
    bid.compensate(model, r)
    bid.closed_loop(model, r, kp=0.2, compensator=model)
    np.testing.assert_array_equal(r, r_copy)
    for bad_model in (model.linear, "model", None, bid.example1().backlash):
        with pytest.raises(ModelError, match="model must be a CascadeModel or SandwichModel"):
            bid.compensate(bad_model, r)
        with pytest.raises(ModelError, match="model"):
            bid.Compensator(bad_model)
        with pytest.raises(ModelError, match="plant"):
            bid.closed_loop(bad_model, r, kp=0.1)
    bad = r.copy()
    bad[7] = np.nan
    with pytest.raises(DataError, match=r"reference\[7\]"):
        bid.compensate(model, bad)
    with pytest.raises(DataError, match=r"reference\[7\]"):
        bid.closed_loop(model, bad, kp=0.1)
    for reference in ([], [[0.1, 0.2]], "r", None):
        with pytest.raises(DataError, match="reference"):
            bid.compensate(model, reference)
    with pytest.raises(DataError, match="not reachable"):
        bid.compensate(model, [0.1, 0.2, 1e300])
    with pytest.raises(DataError, match="threshold"):
        bid.compensate(model, r, threshold=-1.0)
    with pytest.raises(DataError, match="initial_state"):
        bid.compensate(model, r, initial_state=bid.example2().rest_state())
    with pytest.raises(DataError):
        bid.compensate(model, r, initial_state=CascadeState((0.0,), (0.0, 0.0), 0.0))  # wrong orders
    comp = bid.Compensator(model)
    with pytest.raises(DataError, match="reference_sample"):
        comp.step("x")
    with pytest.raises(DataError, match="reference"):
        comp.step(np.inf)
    with pytest.raises(DataError, match="kp"):
        bid.closed_loop(model, r, kp=np.nan)
    with pytest.raises(DataError, match="saturation"):
        bid.closed_loop(model, r, kp=0.1, saturation=(1.0, -1.0))
    with pytest.raises(DataError, match="saturation"):
        bid.closed_loop(model, r, kp=0.1, saturation=3.0)
    with pytest.raises(DataError, match="compensator"):
        bid.closed_loop(model, r, kp=0.1, compensator="yes")
    with pytest.raises(ModelError, match="diverged"):
        bid.closed_loop(model, r, kp=-50.0)
