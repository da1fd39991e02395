"""The linear block of eq (16) / (29): simulation against a plain loop, poles, stability,
static gain."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import backlashid as bx
from conftest import finite, inputs, ref_linear, run_isolated, stable_blocks


def test_example1_impulse_response_by_hand():
    g = bx.LinearBlock([0.7, 0.5], [-0.2, 0.35])
    u = np.zeros(6)
    u[0] = 1.0
    x = g.simulate(u)
    # x(t) = 0.7u(t-1) + 0.5u(t-2) + 0.2x(t-1) - 0.35x(t-2); the impulse is at t = 1
    expected = [0.0, 0.7, 0.5 + 0.2 * 0.7]
    expected.append(0.2 * expected[2] - 0.35 * expected[1])
    expected.append(0.2 * expected[3] - 0.35 * expected[2])
    expected.append(0.2 * expected[4] - 0.35 * expected[3])
    np.testing.assert_allclose(x, expected, rtol=0, atol=1e-15)


@given(g=stable_blocks(), n=st.integers(1, 40))
def test_impulse_response_matches_a_plain_loop(g, n):
    u = np.zeros(n)
    u[0] = 1.0
    np.testing.assert_allclose(g.simulate(u), ref_linear(g.a, g.b, u), rtol=1e-13, atol=1e-13)


@given(g=stable_blocks(), u=inputs(), data=st.data())
def test_simulation_from_a_state_matches_a_plain_loop(g, u, data):
    past = st.floats(-2.0, 2.0, **finite)
    u_past = data.draw(st.lists(past, min_size=g.na, max_size=g.na))
    x_past = data.draw(st.lists(past, min_size=g.nb, max_size=g.nb))
    x = g.simulate(u, u_past=u_past, x_past=x_past)
    np.testing.assert_allclose(x, ref_linear(g.a, g.b, u, u_past, x_past), rtol=1e-13, atol=1e-13)


def test_fir_block_is_a_convolution(rng):
    a = [0.3, -1.2, 0.5, 2.0]
    g = bx.LinearBlock(a)
    u = rng.uniform(-1, 1, 50)
    expected = np.convolve(np.r_[0.0, u], a)[: len(u)]  # one-sample delay
    np.testing.assert_allclose(g.simulate(u), expected, rtol=0, atol=1e-14)
    assert g.nb == 0 and g.poles().size == 0 and g.spectral_radius() == 0.0 and g.is_stable()


def test_example1_poles():
    g = bx.example1().linear
    expected = np.roots([1.0, -0.2, 0.35])
    p = g.poles()
    assert p.dtype == np.complex128 and p.shape == (2,)
    np.testing.assert_allclose(np.sort_complex(p), np.sort_complex(expected), rtol=0, atol=1e-12)
    assert g.spectral_radius() == pytest.approx(np.sqrt(0.35), abs=1e-12)
    assert g.is_stable()


nonzero = st.floats(-2.0, 2.0, **finite).filter(lambda v: abs(v) > 1e-3)


@given(b=st.lists(nonzero, min_size=1, max_size=5))
def test_poles_are_numpy_roots_sorted_by_modulus(b):
    # (coefficient lists with exact zeros are covered, in a subprocess, below: they can hang)
    g = bx.LinearBlock([1.0], b)
    p = g.poles()
    expected = np.roots([1.0, *b])
    assert p.shape == expected.shape
    # every numpy root is matched by a pole (up to the conditioning of the roots)
    for r in expected:
        assert np.min(np.abs(p - r)) < 1e-6 * max(1.0, abs(r))
    assert np.all(np.diff(np.abs(p)) <= 1e-12)
    assert g.spectral_radius() == pytest.approx(np.max(np.abs(expected)), abs=1e-6)
    assert g.is_stable() == (g.spectral_radius() < 1.0)


@pytest.mark.parametrize(
    "b, stable",
    [([-0.2, 0.35], True), ([0.2, -0.2], True), ([-1.5], False), ([0.0, 1.0], False), ([-1.0], False),
     ([0.0, 0.0, 0.999], True), ([], True)],
)
def test_stability_flag(b, stable):
    assert bx.LinearBlock([1.0], b).is_stable() is stable


def test_static_gain():
    g = bx.example1().linear
    assert g.static_gain() == pytest.approx((0.7 + 0.5) / (1 - 0.2 + 0.35), abs=1e-15)
    # the step response settles at the static gain
    x = g.simulate(np.ones(400))
    assert x[-1] == pytest.approx(g.static_gain(), abs=1e-12)
    assert bx.LinearBlock([2.0, 1.0]).static_gain() == 3.0
    assert bx.LinearBlock([1.0], [-1.0]).static_gain() == np.inf  # a pole at z = 1


@given(g=stable_blocks())
def test_static_gain_is_the_step_response_limit(g):
    x = g.simulate(np.ones(600))  # all poles have modulus <= 0.9: 0.9^600 ~ 1e-28
    assert x[-1] == pytest.approx(g.static_gain(), rel=1e-9, abs=1e-9)


def test_equation_and_parameters():
    g = bx.LinearBlock([0.7, 0.5], [-0.2, 0.35])
    assert g.equation() == "x(t) = 0.7 u(t-1) + 0.5 u(t-2) + 0.2 x(t-1) - 0.35 x(t-2)"
    assert (g.na, g.nb) == (2, 2)
    with pytest.raises(ValueError):
        g.a[0] = 1.0  # parameters are read-only


@pytest.mark.parametrize(
    "b",
    [
        [0.0, 0.0, 0.0, 0.5],  # x(t) = u(t-1) - 0.5 x(t-4): stable, poles on |z| = 0.5**0.25
    ],
)
def test_poles_of_sparse_denominators_return(b):
    """Found by hypothesis: for these b, poles() / is_stable() never return (nalgebra's
    Schur iteration does not converge on the companion matrix and has no iteration cap)."""
    out = run_isolated(
        "import numpy as np, backlashid as bx\n"
        f"g = bx.LinearBlock([1.0], {b!r})\n"
        "p = g.poles()\n"
        f"r = np.roots([1.0, *{b!r}])\n"
        "assert p.size == r.size\n"
        "assert all(np.min(np.abs(p - z)) < 1e-6 for z in r), (p, r)\n"
        "print(g.is_stable())\n"
    )
    assert out.strip() == str(bool(np.max(np.abs(np.roots([1.0, *b]))) < 1.0))


def test_overflow_of_a_sparse_unstable_block_raises_model_error():
    """x(t) = u(t-1) - 2 x(t-4) overflows; the error path computes the spectral radius for
    its message and must still return (with ModelError), not hang."""
    out = run_isolated(
        "import numpy as np, backlashid as bx\n"
        "g = bx.LinearBlock([1.0], [0.0, 0.0, 0.0, 2.0])\n"
        "try:\n"
        "    g.simulate(np.ones(8000))\n"
        "except bx.ModelError as e:\n"
        "    print('ModelError', e)\n"
    )
    assert out.startswith("ModelError") and "diverged" in out
