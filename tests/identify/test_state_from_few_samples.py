"""The state estimated from a handful of noisy samples (the benchmark protocols' "n samples to
initialise"): the maximum a posteriori estimate of ``simulate_from_samples`` does not carry a
slow mode's error through the record (issue 17), and with many samples it is the data's."""

from __future__ import annotations

import numpy as np
import pytest

from backlashid import CascadeModel, GeneralBacklash, LinearBlock
from backlashid.identify import estimate_state, simulate_from_samples
from backlashid.identify._state import _data_only, _estimate, _record, _structure


def _model(seed: int, order: int) -> CascadeModel:
    """A stable cascade of ``order`` with one slow pole (0.95-0.985) and unit static gain, and
    an asymmetric backlash."""
    rng = np.random.default_rng(seed)
    poles = np.concatenate([[rng.uniform(0.95, 0.985)], rng.uniform(0.2, 0.8, order - 1)])
    den = np.poly(poles)[1:]
    num = rng.uniform(-1.0, 1.0, order)
    num[0] = 1.0
    gain = num.sum() / (1.0 + den.sum())
    return CascadeModel(LinearBlock(num / gain, den), GeneralBacklash(0.2, 0.1, [1.0], [1.2]))


def _record_cut(model: CascadeModel, seed: int, noise: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Input held in steps of 10 samples, the record cut mid-run at 300 (u, clean y, noisy y)."""
    rng = np.random.default_rng(100 + seed)
    u = np.repeat(rng.uniform(-1.0, 1.0, 60), 10)
    y = model.simulate(u)
    u, y = u[300:], y[300:]
    return u, y, y + noise * np.std(y) * rng.standard_normal(y.size)


def _rmse(sim: np.ndarray, clean: np.ndarray, n: int) -> float:
    return float(np.sqrt(np.mean((sim - clean)[n:] ** 2)))


@pytest.mark.parametrize("order", [3, 4])
@pytest.mark.parametrize("n", [2, 3, 4])
def test_a_few_noisy_samples_initialise_no_worse_than_rest(order, n):
    # n <= state dimension (order + 1): the samples alone fit a valley of states exactly, and
    # the exact fit of noisy samples once carried the slow mode's error through the record
    for seed in range(6):
        model = _model(seed, order)
        u, clean, noisy = _record_cut(model, seed, 0.05)
        from_rest = _rmse(model.simulate(u), clean, n)
        estimated = _rmse(simulate_from_samples(model, u, noisy, n), clean, n)
        assert estimated <= 1.2 * from_rest, (seed, estimated, from_rest)


def test_many_samples_give_the_datas_estimate():
    # 200 noise-free samples: the estimate is the output error's alone, and exact
    model = _model(1, 4)
    u, clean, _ = _record_cut(model, 1, 0.0)
    structure, theta = _estimate(model, u, clean, 200)
    p0 = structure.model_size
    prob = _record(model, structure, u[:200], clean[:200])
    lo, hi = (np.asarray(b, dtype=np.float64) for b in prob.bounds())
    lo[:p0] = hi[:p0] = theta[:p0]
    data = _data_only(model, structure, prob, u, clean, 200, lo, hi)[0]
    np.testing.assert_allclose(theta, data, rtol=0.0, atol=1e-12)
    state = estimate_state(model, u, clean, samples=200)
    assert np.max(np.abs(model.simulate(u, initial_state=state) - clean)[200:]) < 1e-6


@pytest.mark.parametrize("n", [8, 10])
def test_a_noise_free_record_is_continued_exactly_where_the_prior_acts(n):
    # state dimension 5, n in (5, 10] (from 8 on the samples determine it here): the posterior's sigma is the data's residual, zero on a
    # record the model fits exactly, so the prior leaves the exact continuation
    # (an input that moves the backlash at almost every sample: a hold masks the state)
    model = _model(2, 4)
    assert _structure(model).size - _structure(model).model_size == 5
    u = np.random.default_rng(7).uniform(-1.0, 1.0, 600)
    u, clean = u[300:], model.simulate(u)[300:]
    sim = simulate_from_samples(model, u, clean, n)
    assert np.max(np.abs(sim - clean)[n:]) < 1e-6


def test_noise_std_must_be_positive():
    from backlashid import DataError

    model = _model(0, 3)
    u, clean, _ = _record_cut(model, 0, 0.0)
    for bad in (0.0, -1.0, np.nan, "x"):
        with pytest.raises(DataError, match="noise_std"):
            simulate_from_samples(model, u, clean, 3, noise_std=bad)
