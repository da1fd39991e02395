"""Input (Hammerstein) backlash u -> backlash -> linear block (issue 17): an independent NumPy
generator (its own play loop of eq 1 and scipy's lfilter), parameter recovery within 3 standard
errors, the fold of the input gain into the backlash, and the checks."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

import backlashid as bid
from backlashid import DataError, GeneralBacklash, LinearBlock, SandwichModel
from backlashid.identify import as_hammerstein, fit_hammerstein_backlash, hammerstein_backlash

# the play: c_L, c_R, m_L, m_R (degree 2); the load: w(t) = y(t-1) + 0.4 y(t-2) + 0.5 w(t-1) - 0.2 w(t-2)
C_L, C_R, M_L, M_R = 0.3, 0.2, [0.8, 0.1], [1.1, -0.05]
R, S = [1.0, 0.4], [-0.5, 0.2]


def _play(v: np.ndarray) -> np.ndarray:
    """Eq (1) sample by sample: L(x) if it is below the last output, R(x) if above, else hold."""
    left = lambda x: sum(m * (x + C_L) ** i for i, m in enumerate(M_L, 1))  # noqa: E731
    right = lambda x: sum(m * (x - C_R) ** i for i, m in enumerate(M_R, 1))  # noqa: E731
    y, prev = np.zeros_like(v), 0.0
    for t, x in enumerate(v):
        lx, rx = left(x), right(x)
        prev = lx if lx <= prev else (rx if rx >= prev else prev)
        y[t] = prev
    return y


def _record(seed: int, n: int = 2000, snr: float = 200.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """u uniform in [-1.5, 1.5]; y(t) = B(u(t-1)); w = the load's filter of y, plus noise."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1.5, 1.5, n)
    y = _play(np.concatenate([[0.0], u[:-1]]))
    clean = lfilter(np.concatenate([[0.0], R]), np.concatenate([[1.0], S]), y)
    return u, clean + rng.standard_normal(n) * np.std(clean) / snr, clean


TRUTH = hammerstein_backlash(GeneralBacklash(C_L, C_R, M_L, M_R), LinearBlock(R, S))


def test_the_model_simulates_as_the_independent_generator():
    u, _, clean = _record(0, 500)
    np.testing.assert_allclose(TRUTH.simulate(u), clean, atol=1e-12)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_parameters_are_recovered_within_three_standard_errors(seed):
    u, w, _ = _record(seed)
    result = fit_hammerstein_backlash(u, w, nr=2, ns=2, degree=2)
    errors, se = result.errors(TRUTH), result.standard_errors
    z = {k: abs(errors[k]) / se[k] for k in errors}
    assert max(z.values()) < 3.0, {k: round(v, 2) for k, v in z.items()}
    # the backlash on u itself, gain folded in: the generator's
    backlash, block = as_hammerstein(result.model, unit_load_gain=False)
    assert backlash.c_left == pytest.approx(C_L, abs=0.02) and backlash.c_right == pytest.approx(C_R, abs=0.02)
    np.testing.assert_allclose(backlash.m_left, M_L, atol=0.03)
    np.testing.assert_allclose(block.a, R, atol=0.03)
    # in physical units (the default): the same play, the load at unit static gain, the
    # branches carrying the load's gain G = sum(R) / (1 + sum(S)) = 2
    physical, load = as_hammerstein(result.model)
    assert physical.c_left == backlash.c_left and load.static_gain() == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(physical.m_left, np.array(M_L) * 2.0, rtol=0.03, atol=0.03)


def test_the_fit_is_the_sandwich_with_a_gain_and_a_delay_as_input_block():
    u, w, _ = _record(4, 1000)
    hammerstein = fit_hammerstein_backlash(u, w, nr=2, ns=2, degree=2)
    sandwich = bid.fit_sandwich(u, w, 1, 0, 2, 2, degree=2)
    np.testing.assert_allclose(hammerstein.theta, sandwich.theta)
    assert hammerstein.names[:2] == ["a1", "c_L"]


@pytest.mark.parametrize("gain", [2.5, -0.7])
@pytest.mark.parametrize("load", [LinearBlock([1.0, 0.3], [-0.4]), LinearBlock([-0.2, 0.05], [-0.6]), LinearBlock([0.1], [-1.0])])
def test_the_gain_folds_into_the_backlash_whatever_its_sign(gain, load):
    # a load of positive, negative and infinite static gain (an integrator: left as it is)
    bl = GeneralBacklash(0.3, 0.1, [1.0, 0.2, 0.05], [0.9, -0.1, 0.08])
    model = SandwichModel(LinearBlock([gain]), bl, load)
    u = np.random.default_rng(5).uniform(-2.0, 2.0, 400)
    for unit in (True, False):
        backlash, block = as_hammerstein(model, unit_load_gain=unit)
        np.testing.assert_allclose(hammerstein_backlash(backlash, block).simulate(u), model.simulate(u), atol=1e-12)
        if unit and np.isfinite(load.static_gain()):
            assert abs(block.static_gain()) == pytest.approx(1.0, abs=1e-12)
            assert backlash.m_left[0] > 0 and backlash.m_right[0] > 0  # still a backlash


def test_bad_arguments_are_refused_naming_them():
    u, w, _ = _record(6, 300)
    with pytest.raises(DataError, match="na"):
        fit_hammerstein_backlash(u, w, na=2)
    with pytest.raises(DataError, match="feedthrough"):
        fit_hammerstein_backlash(u, w, feedthrough=True)
    with pytest.raises(DataError, match="model"):
        as_hammerstein(bid.example2())
    with pytest.raises(DataError, match="model"):
        as_hammerstein(bid.example1())
    with pytest.raises(DataError, match="unit_load_gain"):
        as_hammerstein(TRUTH, unit_load_gain="yes")
    with pytest.raises(bid.ModelError, match="output_linear"):
        hammerstein_backlash(GeneralBacklash(0.1, 0.1, [1.0], [1.0]), [1.0])


def test_the_search_with_the_state_has_starts_of_its_own():
    # the input block is a gain and a delay, so the linear fits of the state's starts vary the
    # output block's poles (before, this structure had none: an empty list); on this record
    # LM from the best of them reaches the noise, the record started mid-motion
    from backlashid.identify import Structure, _starts
    from backlashid.identify._state import lm_holding_vanishing

    u, w, clean = _record(3, n=2500)
    u, w, clean = u[500:], w[500:], clean[500:]
    noise = float(np.std(w - clean))
    s = Structure(1, 0, 2, 2, 2, initial_state=True)
    prob = s.problem(u, w, 20)
    starts = _starts.state_starts(s, prob, u, w, 20)
    assert starts
    p0 = Structure(1, 0, 2, 2, 2).size
    best = min(lm_holding_vanishing(prob, theta, p0).cost for theta in starts)
    assert np.sqrt(best / (len(w) - 20)) <= 1.1 * noise
