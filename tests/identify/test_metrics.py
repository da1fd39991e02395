"""Fit metrics: simulation vs one-step prediction, and the formulas of RMSE, NRMSE, fit %."""

from __future__ import annotations

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
