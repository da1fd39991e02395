"""Fit metrics: simulation vs one-step prediction, and the formulas of RMSE, NRMSE, fit %."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import backlashid as bid
from backlashid.identify import evaluate, fit_percent, nrmse, one_step_prediction, rmse


@pytest.mark.parametrize("make", [bid.example1, bid.example2])
def test_the_true_model_on_clean_data_has_zero_error_both_ways(make):
    model = make()
    d = bid.example_data(model, 1000, snr=None, seed=1)
    m = evaluate(model, d.u, d.clean)
    assert m.simulation_rmse == 0.0 and m.simulation_fit_percent == 100.0
    assert m.prediction_rmse < 1e-12


def test_formulas_against_a_hand_computation():
    y = np.array([1.0, 2.0, 3.0, 4.0])
    y_hat = np.array([1.0, 2.5, 2.5, 4.0])
    assert rmse(y, y_hat) == pytest.approx(np.sqrt(0.5 / 4))
    assert nrmse(y, y_hat) == pytest.approx(np.sqrt(0.5 / 4) / np.std(y))
    # fit % = 100 (1 - ||y - y_hat|| / ||y - mean y||)
    assert fit_percent(y, y_hat) == pytest.approx(100 * (1 - np.sqrt(0.5) / np.sqrt(5.0)))
    assert rmse(y, y_hat, warmup=2) == pytest.approx(np.sqrt(0.25 / 2))


def test_cascade_prediction_feeds_back_the_measured_memory():
    # straight backlash, pure delay: x(t) = u(t-1); L = x + 0.5, R = x - 0.5
    model = bid.CascadeModel(bid.LinearBlock([1.0]), bid.GeneralBacklash(0.5, 0.5, [1.0], [1.0]))
    u = np.array([2.0, 0.0, 0.2, 0.0])
    y_meas = np.array([0.0, 1.3, 1.0, 0.7])
    pred = one_step_prediction(model, u, y_meas)
    # t0: x = 0, memory 0 inside [R, L] = [-0.5, 0.5]: hold 0
    # t1: x = 2, R = 1.5 >= memory 0: 1.5 (the measured 1.3 is only fed back at t2)
    # t2: x = 0, L = 0.5 <= measured 1.3: 0.5
    # t3: x = 0.2, L = 0.7 <= measured 1.0: 0.7
    np.testing.assert_allclose(pred, [0.0, 1.5, 0.5, 0.7])


def test_sandwich_prediction_uses_the_measured_past_of_w():
    model = bid.example2()
    d = bid.example_data(model, 300, snr=20, seed=3)
    y = model.simulate(d.u, internals=True).y
    pred = one_step_prediction(model, d.u, d.noisy)
    t = np.arange(2, 300)
    want = y[t - 1] + 0.15 * y[t - 2] + 0.2 * d.noisy[t - 1] - 0.35 * d.noisy[t - 2]  # eq (29)
    np.testing.assert_allclose(pred[t], want, rtol=0, atol=1e-12)


def test_a_wrong_model_simulates_worse_than_the_true_one_on_validation_data():
    truth = bid.example1()
    val = bid.example_data(truth, 2000, snr=25, seed=9)
    wrong = bid.CascadeModel(truth.linear, bid.GeneralBacklash(0.3, 0.3, [1.0, -0.3, 0.3], [1.5, 0.4, 0.2]))
    good, bad = evaluate(truth, val.u, val.noisy), evaluate(wrong, val.u, val.noisy)
    assert good.simulation_rmse == pytest.approx(val.noise_std, rel=0.1)
    assert bad.simulation_rmse > 2 * good.simulation_rmse
    assert "free-run simulation" in str(good) and "one-step prediction" in str(good)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: rmse([1.0, 2.0], [1.0]), "samples"),
        (lambda: rmse([1.0, 2.0], [1.0, 2.0], warmup=2), "warmup"),
        (lambda: nrmse([1.0, 1.0, 1.0], [1.0, 2.0, 3.0]), "constant"),
        (lambda: one_step_prediction(bid.example1(), [0.0, 1.0], [0.0]), "samples"),
        (lambda: one_step_prediction("model", [0.0], [0.0]), "CascadeModel"),
    ],
)
def test_bad_arguments_raise_data_errors(call, match):
    with pytest.raises(bid.DataError, match=match):
        call()


def _drive_at_rest(pole: float, load: bool = True) -> tuple[bid.CascadeModel | bid.SandwichModel, np.ndarray, np.ndarray]:
    """A drive whose motor integrates velocity pulses (pole 1) or lags them (pole < 1) -> a
    straight play of half-widths 0.4 / 0.3 -> a load lag (a sandwich; without it, the play's
    output measured: a cascade), written as its own per-sample loop; the record is cut 100
    samples after the first pulse, the play held until sample 300."""
    u = np.zeros(2000)
    for start, stop, v in ((100, 150, 1.0), (500, 560, -1.0), (900, 950, 1.0), (1300, 1380, -1.0), (1600, 1650, 0.7)):
        u[start:stop] = v
    x, p, w = np.zeros(u.size), np.zeros(u.size), np.zeros(u.size)
    for t in range(1, u.size):
        x[t] = pole * x[t - 1] + 0.05 * u[t - 1]
        p[t] = min(max(p[t - 1], x[t] - 0.3), x[t] + 0.4)  # the play: dragged by either contact
        w[t] = 0.7 * w[t - 1] + 0.3 * p[t - 1]
    motor, play = bid.LinearBlock([0.05], [-pole]), bid.GeneralBacklash(0.4, 0.3, [1.0], [1.0])
    model = bid.SandwichModel(motor, play, bid.LinearBlock([0.3], [-0.7])) if load else bid.CascadeModel(motor, play)
    measured = w if load else p
    assert np.max(np.abs(model.simulate(u) - measured)) < 1e-12  # the loop is the model
    noisy = measured + 0.005 * np.random.default_rng(0).standard_normal(u.size)
    return model, u[200:], noisy[200:]


@pytest.mark.parametrize("load", [True, False], ids=["sandwich", "cascade"])
def test_evaluate_says_when_its_first_samples_leave_the_start_a_guess(load):
    # issue 31: a position-controlled drive at rest through the first init_samples: where the
    # motor sits inside the play is not in the data, and the rest of the record depends on it
    model, u, y = _drive_at_rest(1.0, load)
    with pytest.warns(bid.FitWarning, match="first 100 samples .* do not determine the start"):
        guessed = evaluate(model, u, y, init_samples=100)
    assert guessed.simulation_rmse > 10 * 0.005
    # init_samples past the first motion (sample 300): determined, no warning, at the noise
    with warnings.catch_warnings():
        warnings.simplefilter("error", bid.FitWarning)
        known = evaluate(model, u, y, init_samples=400)
    assert known.simulation_rmse < 1.1 * 0.005


@pytest.mark.parametrize("load", [True, False], ids=["sandwich", "cascade"])
def test_a_lagging_motor_forgets_its_start_and_is_not_warned_about(load):
    # the same drive with a stable motor lag: the offset inside the play dies out
    model, u, y = _drive_at_rest(0.9, load)
    with warnings.catch_warnings():
        warnings.simplefilter("error", bid.FitWarning)
        assert evaluate(model, u, y, init_samples=100).simulation_rmse < 1.5 * 0.005


def test_each_witness_of_an_undetermined_start_works_on_its_own(monkeypatch):
    # the starts that may simulate the first samples as well as the estimate: x shifted inside
    # the dead band, the drive at rest, and the start estimated from 3 times the samples. The
    # last one alone: with 150 init samples the 450-sample estimate reaches past the first
    # motion (sample 300) and simulates the rest of the record differently
    from backlashid.identify import _start_check

    model, u, y = _drive_at_rest(1.0, True)
    monkeypatch.setattr(_start_check, "_shifted", lambda state, half: [])
    monkeypatch.setattr(_start_check, "_rest_states", lambda *args: [])
    with pytest.warns(bid.FitWarning, match="first 150 samples .* do not determine the start"):
        evaluate(model, u, y, init_samples=150)
    monkeypatch.setattr(_start_check, "_longer", lambda *args: [])
    with warnings.catch_warnings():
        warnings.simplefilter("error", bid.FitWarning)
        evaluate(model, u, y, init_samples=150)
