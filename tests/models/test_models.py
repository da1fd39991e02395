"""Cascade (Fig. 2) and sandwich (Fig. 3) models: block composition, internal signals,
continuation from final_state, and non-zero initial states against plain loops."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import backlashid as bx
from conftest import cascades, finite, inputs, ref_cascade, ref_linear, ref_sandwich, sandwiches

TOL = dict(rtol=1e-12, atol=1e-12)


def high_order_cascade():
    """Order 4 in u, 3 in x: cut points 1..3 are shorter than the model order."""
    return bx.CascadeModel(
        bx.LinearBlock([0.5, -0.3, 0.25, 0.4], [-0.5, 0.3, -0.1]), bx.example1().backlash
    )


def high_order_sandwich():
    return bx.SandwichModel(
        bx.LinearBlock([0.8, 0.2, -0.3], [0.2, -0.2, 0.05]),
        bx.example2().backlash,
        bx.LinearBlock([1.0, 0.15, -0.2, 0.1], [-0.2, 0.35, 0.1]),
    )


# ------------------------------------------------------------------ composition
@given(model=cascades(), u=inputs())
def test_cascade_is_linear_then_backlash(model, u):
    x = model.linear.simulate(u)
    expected = model.backlash.simulate(x)
    np.testing.assert_allclose(model.simulate(u), expected, **TOL)


@given(model=sandwiches(), u=inputs())
def test_sandwich_is_linear_then_backlash_then_linear(model, u):
    x = model.input_linear.simulate(u)
    y = model.backlash.simulate(x)
    w = model.output_linear.simulate(y)
    np.testing.assert_allclose(model.simulate(u), w, **TOL)


def test_examples_against_plain_loops(rng):
    u = rng.uniform(-1, 1, 1500)
    m1, m2 = bx.example1(), bx.example2()
    np.testing.assert_allclose(m1.simulate(u), ref_cascade(m1, u)[1], **TOL)
    np.testing.assert_allclose(m2.simulate(u), ref_sandwich(m2, u)[2], **TOL)
    # the record exercises both branches and the dead band
    s = m1.simulate(u, internals=True)
    assert s.f1.any() and s.f2.any() and (~s.f1 & ~s.f2).any()


# ------------------------------------------------------------------ internals
@given(model=cascades(), u=inputs())
def test_cascade_internals_are_consistent(model, u):
    sim = model.simulate(u, internals=True)
    assert isinstance(sim, bx.CascadeSimulation)
    np.testing.assert_array_equal(sim.output, model.simulate(u))
    np.testing.assert_allclose(sim.x, model.linear.simulate(u), **TOL)
    bl = model.backlash
    np.testing.assert_allclose(sim.output, bl.simulate(sim.x), **TOL)
    L, R = bl.left(sim.x), bl.right(sim.x)
    y_prev = np.r_[0.0, sim.output[:-1]]
    assert not np.any(sim.f1 & sim.f2)
    np.testing.assert_allclose(sim.output[sim.f1], L[sim.f1], **TOL)
    np.testing.assert_allclose(sim.output[sim.f2], R[sim.f2], **TOL)
    hold = ~sim.f1 & ~sim.f2
    np.testing.assert_allclose(sim.output[hold], y_prev[hold], **TOL)
    assert sim.moving_fraction() == pytest.approx(np.mean(sim.f1 | sim.f2))
    assert sim.final_state.y_prev == sim.output[-1]
    # the core's count of the same flags, without storing them
    k = len(u) // 3
    assert model.moving_fraction(u, warmup=k) == np.mean((sim.f1 | sim.f2)[k:])


@given(model=sandwiches(), u=inputs())
def test_sandwich_internals_are_consistent(model, u):
    sim = model.simulate(u, internals=True)
    assert isinstance(sim, bx.SandwichSimulation)
    np.testing.assert_array_equal(sim.output, model.simulate(u))
    np.testing.assert_allclose(sim.x, model.input_linear.simulate(u), **TOL)
    np.testing.assert_allclose(sim.y, model.backlash.simulate(sim.x), **TOL)
    np.testing.assert_allclose(sim.output, model.output_linear.simulate(sim.y), **TOL)
    L, R = model.backlash.left(sim.x), model.backlash.right(sim.x)
    assert not np.any(sim.f1 & sim.f2)
    np.testing.assert_allclose(sim.y[sim.f1], L[sim.f1], **TOL)
    np.testing.assert_allclose(sim.y[sim.f2], R[sim.f2], **TOL)
    hold = ~sim.f1 & ~sim.f2
    np.testing.assert_allclose(sim.y[hold], np.r_[0.0, sim.y[:-1]][hold], **TOL)
    assert sim.final_state.y_past[0] == sim.y[-1]
    k = len(u) // 3
    assert model.moving_fraction(u, warmup=k) == np.mean((sim.f1 | sim.f2)[k:])


def test_moving_fraction_continues_a_record_and_rejects_a_bad_warmup():
    for model in (bx.example1(), bx.example2()):
        u = np.sin(0.05 * np.arange(900)) * 2.0
        first = model.simulate(u[:400], internals=True)
        rest = model.simulate(u[400:], initial_state=first.final_state, internals=True)
        got = model.moving_fraction(u[400:], initial_state=first.final_state, warmup=100)
        assert got == np.mean((rest.f1 | rest.f2)[100:])
        assert 0.0 < got < 1.0
        for bad in (-1, 900 - 400, 2.5, True):
            with pytest.raises(bx.DataError, match="warmup"):
                model.moving_fraction(u[400:], warmup=bad)
        with pytest.raises(bx.DataError):
            model.moving_fraction(np.r_[0.1, np.nan])
        with pytest.raises(bx.DataError, match="empty"):
            model.moving_fraction(np.array([]))


# ------------------------------------------------------------------ continuation
def continue_in_parts(model, u, cuts):
    parts, state = [], None
    for lo, hi in zip([0, *cuts], [*cuts, len(u)]):
        sim = model.simulate(u[lo:hi], initial_state=state, internals=True)
        parts.append(sim.output)
        state = sim.final_state
    return np.concatenate(parts)


@pytest.mark.parametrize("make", [high_order_cascade, high_order_sandwich, bx.example1, bx.example2])
@pytest.mark.parametrize("cuts", [[1], [2], [3], [1, 2, 3], [1, 4, 5, 7], [150], [299], [10, 11, 200]])
def test_continuing_from_final_state_equals_the_whole_record(make, cuts, rng):
    model = make()
    u = rng.uniform(-1, 1, 300)
    whole = model.simulate(u)
    np.testing.assert_allclose(continue_in_parts(model, u, cuts), whole, **TOL)


@given(model=st.one_of(cascades(), sandwiches()), u=inputs(n_min=2), data=st.data())
def test_continuation_random_models_and_cuts(model, u, data):
    cuts = sorted(set(data.draw(st.lists(st.integers(1, len(u) - 1), min_size=1, max_size=4))))
    np.testing.assert_allclose(continue_in_parts(model, u, cuts), model.simulate(u), **TOL)


def test_final_state_holds_the_most_recent_values_first():
    model = high_order_cascade()
    u = np.array([1.0, 2.0])  # shorter than na = 4: the rest comes from the initial state
    s0 = bx.CascadeState([9.0, 8.0, 7.0, 6.0], [5.0, 4.0, 3.0], 0.25)
    sim = model.simulate(u, initial_state=s0, internals=True)
    assert sim.final_state.u_past == (2.0, 1.0, 9.0, 8.0)
    assert sim.final_state.x_past == (sim.x[1], sim.x[0], 5.0)
    assert sim.final_state.y_prev == sim.output[-1]


# ------------------------------------------------------------------ initial states
past = st.floats(-1.5, 1.5, **finite)


@given(model=cascades(), u=inputs(), data=st.data())
def test_cascade_initial_state_matches_plain_loop(model, u, data):
    g = model.linear
    state = bx.CascadeState(
        data.draw(st.lists(past, min_size=g.na, max_size=g.na)),
        data.draw(st.lists(past, min_size=g.nb, max_size=g.nb)),
        data.draw(past),
    )
    x_ref, y_ref = ref_cascade(model, u, state)
    sim = model.simulate(u, initial_state=state, internals=True)
    np.testing.assert_allclose(sim.x, x_ref, **TOL)
    np.testing.assert_allclose(sim.output, y_ref, **TOL)


@given(model=sandwiches(), u=inputs(), data=st.data())
def test_sandwich_initial_state_matches_plain_loop(model, u, data):
    gi, go = model.input_linear, model.output_linear
    state = bx.SandwichState(
        data.draw(st.lists(past, min_size=gi.na, max_size=gi.na)),
        data.draw(st.lists(past, min_size=gi.nb, max_size=gi.nb)),
        data.draw(st.lists(past, min_size=go.na, max_size=go.na)),
        data.draw(st.lists(past, min_size=go.nb, max_size=go.nb)),
    )
    x_ref, y_ref, w_ref = ref_sandwich(model, u, state)
    sim = model.simulate(u, initial_state=state, internals=True)
    np.testing.assert_allclose(sim.x, x_ref, **TOL)
    np.testing.assert_allclose(sim.y, y_ref, **TOL)
    np.testing.assert_allclose(sim.output, w_ref, **TOL)


def test_nonzero_initial_state_changes_the_output(rng):
    u = rng.uniform(-1, 1, 50)
    m1, m2 = bx.example1(), bx.example2()
    s1 = bx.CascadeState([0.5, -0.2], [0.3, 0.1], 0.4)
    y_rest, y_s1 = m1.simulate(u), m1.simulate(u, initial_state=s1)
    assert not np.allclose(y_rest[:5], y_s1[:5])
    np.testing.assert_allclose(y_s1, ref_cascade(m1, u, s1)[1], **TOL)
    # the backlash memory alone: y(1) holds y(0) = 0.4 when x(1) stays in the dead band
    only_y = bx.CascadeState([0.0, 0.0], [0.0, 0.0], 0.4)
    assert m1.simulate(np.zeros(3), initial_state=only_y).tolist() == [0.4, 0.4, 0.4]
    s2 = bx.SandwichState([0.5, -0.2], [0.3, 0.1], [0.4, -0.1], [0.2, 0.0])
    w_rest, w_s2 = m2.simulate(u), m2.simulate(u, initial_state=s2)
    assert not np.allclose(w_rest[:5], w_s2[:5])
    np.testing.assert_allclose(w_s2, ref_sandwich(m2, u, s2)[2], **TOL)
    # w(1) = r1 y(0) + r2 y(-1) - s1 w(0) - s2 w(-1)
    assert w_s2[0] == pytest.approx(1.0 * 0.4 + 0.15 * -0.1 + 0.2 * 0.2 - 0.35 * 0.0, abs=1e-15)


def test_rest_state_is_the_default():
    for model in (bx.example1(), bx.example2(), high_order_cascade(), high_order_sandwich()):
        u = np.linspace(-1, 1, 37)
        np.testing.assert_array_equal(model.simulate(u), model.simulate(u, initial_state=model.rest_state()))


def test_sandwich_output_is_delayed_one_sample_from_y():
    m = bx.example2()
    sim = m.simulate(np.ones(20), internals=True)
    assert sim.output[0] == 0.0  # w(1) depends on y(0), y(-1), w(0), w(-1) only
    np.testing.assert_allclose(sim.output, ref_linear(m.r, m.s, sim.y), **TOL)
