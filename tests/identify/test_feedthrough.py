"""Direct feedthrough (lag 0) in the linear blocks (issue 6): x(t) = a_0 u(t) + sum a_i u(t-i) - sum b_j x(t-j)."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest

import backlashid as bid
from backlashid import (
    CascadeModel,
    CascadeState,
    DataError,
    LinearBlock,
    ModelError,
    SandwichModel,
    SandwichState,
    fit_cascade,
    fit_sandwich,
)
from backlashid.identify import Structure, normalise
from conftest import ref_backlash


def hand_linear(a, b, u, feedthrough, u_past=(), x_past=()):
    """The difference equation by a plain loop; a starts at lag 0 with feedthrough."""
    first = 0 if feedthrough else 1
    u_hist = {-k: v for k, v in enumerate(u_past)}  # u(0), u(-1), .. at times 0, -1, ..
    x_hist = {-k: v for k, v in enumerate(x_past)}
    out = []
    for t in range(1, len(u) + 1):
        u_hist[t] = float(u[t - 1])
        acc = sum(ai * u_hist.get(t - lag, 0.0) for lag, ai in enumerate(a, first))
        acc -= sum(bj * x_hist.get(t - j, 0.0) for j, bj in enumerate(b, 1))
        x_hist[t] = acc
        out.append(acc)
    return np.array(out)


def ex1_feedthrough(a0: float = 0.3) -> CascadeModel:
    return CascadeModel(LinearBlock([a0, 0.7, 0.5], [-0.2, 0.35], feedthrough=True), bid.example1().backlash)


def ex2_feedthrough() -> SandwichModel:
    ex2 = bid.example2()
    return SandwichModel(
        LinearBlock([0.3, 0.8, 0.2], [0.2, -0.2], feedthrough=True),
        ex2.backlash,
        LinearBlock([1.0, 0.6, 0.15], [-0.2, 0.35], feedthrough=True),
    )


# -- simulation ---------------------------------------------------------------------------------


@pytest.mark.parametrize(("a", "b"), [([0.4, 0.7, 0.5], [-0.2, 0.35]), ([0.2, 0.3, 0.2, 0.1], [-0.5, 0.2, 0.05]), ([0.5, 0.0], [])])
def test_linear_block_with_feedthrough_follows_the_hand_loop(a, b):
    rng = np.random.default_rng(3)
    u = rng.uniform(-1, 1, 300)
    block = LinearBlock(a, b, feedthrough=True)
    assert block.na == len(a) - 1 and block.feedthrough
    np.testing.assert_allclose(block.simulate(u), hand_linear(a, b, u, True), atol=1e-13)
    u_past, x_past = rng.normal(size=block.na), rng.normal(size=block.nb)
    np.testing.assert_allclose(
        block.simulate(u, u_past=u_past, x_past=x_past), hand_linear(a, b, u, True, u_past, x_past), atol=1e-13
    )
    # the lag-0 term acts within the sample: an impulse at t = 1 shows at t = 1
    impulse = np.zeros(5)
    impulse[0] = 1.0
    assert block.simulate(impulse)[0] == a[0]
    assert LinearBlock(a[1:], b).simulate(impulse)[0] == 0.0


def test_a_block_with_zero_feedthrough_equals_the_paper_block():
    u = np.random.default_rng(4).uniform(-1, 1, 200)
    np.testing.assert_array_equal(
        LinearBlock([0.0, 0.7, 0.5], [-0.2, 0.35], feedthrough=True).simulate(u),
        LinearBlock([0.7, 0.5], [-0.2, 0.35]).simulate(u),
    )


def test_cascade_and_sandwich_with_feedthrough_follow_the_hand_loops():
    rng = np.random.default_rng(5)
    u = rng.uniform(-1, 1, 400)
    cas = ex1_feedthrough()
    sim = cas.simulate(u, internals=True)
    x = hand_linear(cas.linear.a, cas.linear.b, u, True)
    np.testing.assert_allclose(sim.x, x, atol=1e-13)
    np.testing.assert_allclose(sim.output, ref_backlash(cas.backlash, x), atol=1e-13)

    sw = ex2_feedthrough()
    sim = sw.simulate(u, internals=True)
    x = hand_linear(sw.input_linear.a, sw.input_linear.b, u, True)
    y = ref_backlash(sw.backlash, x)
    w = hand_linear(sw.r, sw.s, y, True)
    np.testing.assert_allclose(sim.x, x, atol=1e-13)
    np.testing.assert_allclose(sim.y, y, atol=1e-13)
    np.testing.assert_allclose(sim.output, w, atol=1e-12)


def test_continuing_from_the_final_state_equals_one_run():
    u = np.random.default_rng(6).uniform(-1, 1, 300)
    for model in (ex1_feedthrough(), ex2_feedthrough()):
        whole = model.simulate(u)
        first = model.simulate(u[:137], internals=True)
        rest = model.simulate(u[137:], initial_state=first.final_state)
        np.testing.assert_allclose(np.r_[first.output, rest], whole, atol=1e-14)
    assert isinstance(first.final_state, SandwichState)
    assert len(ex1_feedthrough().rest_state().u_past) == 2
    assert isinstance(ex1_feedthrough().rest_state(), CascadeState)


def test_feedthrough_shows_in_the_equation_and_repr():
    block = LinearBlock([0.4, 0.7], [-0.2], feedthrough=True)
    assert block.equation() == "x(t) = 0.4 u(t) + 0.7 u(t-1) + 0.2 x(t-1)"
    assert "feedthrough=True" in repr(block)
    assert "feedthrough=True" in repr(ex2_feedthrough())
    assert list(block.lags) == [0, 1]


def test_bad_feedthrough_blocks_are_refused():
    with pytest.raises(ModelError, match="a_1 = 0"):
        LinearBlock([0.4], [0.1], feedthrough=True)
    with pytest.raises(ModelError, match="True or False"):
        LinearBlock([0.4, 0.1], [], feedthrough="yes")  # type: ignore[arg-type]
    with pytest.raises(ModelError):
        LinearBlock([np.nan, 0.1], [], feedthrough=True)


# -- serialisation --------------------------------------------------------------------------------


def test_feedthrough_round_trips_and_old_dicts_still_load():
    block = LinearBlock([0.4, 0.7], [-0.2], feedthrough=True)
    assert block.to_dict() == {"a": [0.4, 0.7], "b": [-0.2], "feedthrough": True}
    assert LinearBlock([0.7], [-0.2]).to_dict() == {"a": [0.7], "b": [-0.2]}  # unchanged format
    assert LinearBlock.from_dict(block.to_dict()) == block
    assert LinearBlock.from_dict({"a": [0.4, 0.7], "b": [-0.2]}) != block  # same numbers, other lags
    for model in (ex1_feedthrough(), ex2_feedthrough()):
        again = bid.model_from_json(model.to_json())
        assert again == model
        assert pickle.loads(pickle.dumps(model)) == model
    old = json.loads(bid.example2().to_json())  # a dict written before feedthrough existed
    assert bid.model_from_dict(old) == bid.example2()


# -- identification -------------------------------------------------------------------------------


def test_fit_cascade_recovers_a_planted_feedthrough():
    truth = ex1_feedthrough()
    u = np.random.default_rng(0).uniform(-1, 1, 1500)
    result = fit_cascade(u, truth.simulate(u), 2, 2, 3, feedthrough=True)
    assert result.names[:3] == ["a0", "a1", "a2"]
    assert max(abs(e) for e in result.errors(truth).values()) < 1e-9
    assert result.model.linear.feedthrough
    np.testing.assert_allclose(result.model.simulate(u), truth.simulate(u), atol=1e-9)


def test_fit_cascade_with_feedthrough_under_noise_and_warmup():
    truth = ex1_feedthrough(0.25)
    rng = np.random.default_rng(1)
    u = rng.uniform(-1, 1, 3000)
    y = truth.simulate(u)
    y_noisy = y + rng.normal(0.0, np.std(y) / 25, y.size)
    result = fit_cascade(u[500:], y_noisy[500:], 2, 2, 3, feedthrough=True, warmup=50)
    err = result.errors(truth)
    assert max(abs(e) for e in err.values()) < 0.05, err
    # within 4 standard errors: the shift leaves the statistics of the paper's fit intact
    assert all(abs(err[k]) < 4 * result.standard_errors[k] for k in ("a0", "a1", "a2", "b1", "b2"))


def test_fit_sandwich_recovers_planted_feedthrough_in_both_blocks():
    truth = ex2_feedthrough()
    u = np.random.default_rng(0).uniform(-1, 1, 1500)
    result = fit_sandwich(u, truth.simulate(u), 2, 2, 2, 2, 3, feedthrough=True, output_feedthrough=True)
    assert "r0" not in result.names and result.names[-4:] == ["r1", "r2", "s1", "s2"]
    assert max(abs(e) for e in result.errors(truth).values()) < 1e-9


def test_identifiability_normalisation_with_feedthrough():
    """A planted sandwich with r_0 = 2 and m_L1 = 1.6 is recovered as its normalised form
    (m_L1 = 1, r_0 = 1), which has the same input/output behaviour."""
    ex2 = bid.example2()
    bl = bid.GeneralBacklash(0.4, 0.5, [1.6, 0.1, 0.3], [1.2, 0.2, 0.6])
    truth = SandwichModel(
        LinearBlock([0.3, 0.8, 0.2], [0.2, -0.2], feedthrough=True),
        bl,
        LinearBlock([2.0, 1.2, 0.3], [-0.2, 0.35], feedthrough=True),
    )
    norm = normalise(truth)
    assert norm.backlash.m_left[0] == pytest.approx(1.0) and norm.r[0] == pytest.approx(1.0)
    assert norm.input_linear.feedthrough and norm.output_linear.feedthrough
    u = np.random.default_rng(2).uniform(-1, 1, 1500)
    np.testing.assert_allclose(norm.simulate(u), truth.simulate(u), atol=1e-12)
    result = fit_sandwich(u, truth.simulate(u), 2, 2, 2, 2, 3, feedthrough=True, output_feedthrough=True)
    assert max(abs(e) for e in result.errors(truth).values()) < 1e-8
    packed = Structure(2, 2, 3, 2, 2, feedthrough=True, output_feedthrough=True).pack(truth)
    np.testing.assert_allclose(result.theta, packed, atol=1e-8)
    assert ex2.backlash.m_left[0] == 1.0  # the paper's example is already normalised


def test_feedthrough_of_a_system_without_one_is_estimated_as_zero():
    truth = bid.example1()
    u = np.random.default_rng(0).uniform(-1, 1, 1500)
    result = fit_cascade(u, truth.simulate(u), 2, 2, 3, feedthrough=True)
    assert abs(result.parameters["a0"]) < 1e-9
    assert result.parameters["a1"] == pytest.approx(0.7, abs=1e-9)


def test_structure_checks():
    with pytest.raises(DataError, match="output_feedthrough"):
        Structure(2, 2, 3, output_feedthrough=True)
    with pytest.raises(DataError, match="feedthrough"):
        Structure(2, 2, 3).pack(ex1_feedthrough())
    assert Structure(2, 2, 3, 2, 2, feedthrough=True, output_feedthrough=True).shift == 2


def test_one_step_prediction_uses_the_output_feedthrough():
    """With the exact model and noise-free data the one-step prediction is exact, r_0 y(t) included."""
    model = ex2_feedthrough()
    u = np.random.default_rng(7).uniform(-1, 1, 500)
    w = model.simulate(u)
    np.testing.assert_allclose(bid.identify.one_step_prediction(model, u, w), w, atol=1e-12)
    assert bid.evaluate(model, u, w, warmup=10).prediction_rmse < 1e-12


def test_a_feedthrough_model_is_the_lagged_model_one_sample_later():
    """The identity the fit relies on (structure.py): with the coefficients a_0..a_na moved to
    lags 1..na+1 (and r_0..r_nr likewise), the model's output at t + shift is the feedthrough
    model's output at t, shift = number of feedthrough blocks."""
    u = np.random.default_rng(8).uniform(-1, 1, 400)
    cas = ex1_feedthrough()
    lagged = CascadeModel(LinearBlock(cas.linear.a, cas.linear.b), cas.backlash)
    np.testing.assert_allclose(lagged.simulate(u)[1:], cas.simulate(u)[:-1], atol=1e-13)
    sw = ex2_feedthrough()
    lagged_sw = SandwichModel(LinearBlock(sw.input_linear.a, sw.input_linear.b), sw.backlash, LinearBlock(sw.r, sw.s))
    np.testing.assert_allclose(lagged_sw.simulate(u)[2:], sw.simulate(u)[:-2], atol=1e-13)
    assert np.all(lagged_sw.simulate(u)[:2] == 0.0)  # from rest: the zeros the fit prepends
