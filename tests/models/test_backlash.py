"""The general backlash, eq (1)-(15): the three forms agree, the output obeys eq (1), degree 1
is the classic play operator, and check_branches finds where the paper's assumption fails."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

import backlashid as bx
from conftest import X_MAX, backlash_inputs, backlashes, finite, ref_backlash, ref_L, ref_R

TOL = 1e-12
y0s = st.one_of(st.just(0.0), st.floats(-4.0, 4.0, **finite))


# ------------------------------------------------------------------ 1. the forms agree
@given(bl=backlashes(require_valid=True), x=backlash_inputs(), y0=y0s)
def test_eq1_breakpoint_and_switching_forms_agree(bl, x, y0):
    y_eq1 = bl.simulate(x, y0=y0, form="eq1")
    y_bp = bl.simulate(x, y0=y0, form="breakpoints")
    sw = bl.switching(x, y0=y0)
    np.testing.assert_allclose(y_bp, y_eq1, rtol=0, atol=TOL)
    np.testing.assert_allclose(sw.y, y_eq1, rtol=0, atol=TOL)
    np.testing.assert_allclose(y_eq1, ref_backlash(bl, x, y0), rtol=0, atol=TOL)


@given(bl=backlashes(require_valid=True), x=backlash_inputs(), y0=y0s)
def test_switching_regressors_xi(bl, x, y0):
    """eq (9)-(10): xi1 = x + c_L, xi2 = x - c_R."""
    sw = bl.switching(x, y0=y0)
    np.testing.assert_array_equal(sw.xi1, x + bl.c_left)
    np.testing.assert_array_equal(sw.xi2, x - bl.c_right)


@given(bl=backlashes(require_valid=True), y0=y0s, data=st.data())
def test_forms_agree_when_x_stays_on_a_branch(bl, y0, data):
    """Ties: after a move, x repeats, so L(x(t)) or R(x(t)) equals y(t-1) exactly."""
    far = data.draw(st.floats(1.0, X_MAX, **finite))
    back = data.draw(st.floats(-X_MAX, X_MAX, **finite))
    x = np.array([far, far, far, back, back, -far, -far, -far, back, far, far])
    y = bl.simulate(x, y0=y0)
    for form_y in (bl.simulate(x, y0=y0, form="breakpoints"), bl.switching(x, y0=y0).y):
        np.testing.assert_allclose(form_y, y, rtol=0, atol=TOL)
    # a repeated x never moves the output
    for t in range(1, len(x)):
        if x[t] == x[t - 1]:
            assert y[t] == y[t - 1]


def test_forms_agree_on_a_long_example_record(ex1, ex2):
    k = np.arange(3000)
    x = 1.8 * np.sin(0.037 * k) * np.cos(0.0021 * k) + 0.2 * np.sin(1.3 * k)
    x[100:200] = x[99]  # a long tie
    for bl in (ex1.backlash, ex2.backlash):
        for y0 in (0.0, 0.7, -1.3):
            y = bl.simulate(x, y0=y0)
            np.testing.assert_allclose(bl.simulate(x, y0=y0, form="breakpoints"), y, rtol=0, atol=TOL)
            np.testing.assert_allclose(bl.switching(x, y0=y0).y, y, rtol=0, atol=TOL)
            np.testing.assert_allclose(ref_backlash(bl, x, y0), y, rtol=0, atol=TOL)


def test_example1_backlash_values():
    bl = bx.example1().backlash
    assert bl.left([-0.6])[0] == 0.0 and bl.right([0.5])[0] == 0.0  # zeros at -c_L, c_R
    assert bl.left([0.0])[0] == pytest.approx(0.6 - 0.3 * 0.36 + 0.3 * 0.216, abs=1e-15)
    assert bl.right([1.0])[0] == pytest.approx(1.5 * 0.5 + 0.4 * 0.25 + 0.2 * 0.125, abs=1e-15)
    y = bl.simulate([0.0, 0.3, -0.3, 2.0, 1.9, -2.0])
    np.testing.assert_array_equal(y[:3], 0.0)  # y(0) = 0 is inside the dead band
    assert y[3] == bl.right([2.0])[0]
    assert y[4] == y[3]
    assert y[5] == bl.left([-2.0])[0]


def test_memory_y0_changes_the_output(ex1):
    bl = ex1.backlash
    y = bl.simulate([0.0, 0.1], y0=0.4)
    np.testing.assert_array_equal(y, [0.4, 0.4])  # 0.4 is inside the band at x = 0, 0.1
    assert bl.simulate([0.0], y0=5.0)[0] == bl.left([0.0])[0]  # above L: falls onto L
    assert bl.simulate([0.0], y0=-5.0)[0] == bl.right([0.0])[0]  # below R: rises onto R


# ------------------------------------------------------------------ 2. properties
@given(bl=backlashes(require_valid=True), x=backlash_inputs(), y0=y0s)
def test_output_properties(bl, x, y0):
    y = bl.simulate(x, y0=y0)
    sw = bl.switching(x, y0=y0)
    L, R = bl.left(x), bl.right(x)
    y_prev = np.r_[y0, y[:-1]]
    inside = (R < y_prev) & (y_prev < L)
    np.testing.assert_array_equal(y[inside], y_prev[inside])  # hold, exactly
    moved = y != y_prev
    on_branch = (np.abs(y - L) <= TOL) | (np.abs(y - R) <= TOL)
    assert np.all(on_branch[moved])
    assert not np.any(sw.f1 & sw.f2)
    np.testing.assert_allclose(y[sw.f1], L[sw.f1], rtol=0, atol=TOL)
    np.testing.assert_allclose(y[sw.f2], R[sw.f2], rtol=0, atol=TOL)
    hold = ~sw.f1 & ~sw.f2
    np.testing.assert_array_equal(sw.y[hold], np.r_[y0, sw.y[:-1]][hold])
    assert sw.f1.dtype == np.bool_ and sw.f2.dtype == np.bool_


@given(bl=backlashes(require_valid=True), x=backlash_inputs(), y0=y0s)
def test_output_stays_between_the_branches_after_a_move(bl, x, y0):
    """For valid branches, once the output moved it is in [R(x), L(x)] at every later t."""
    y = bl.simulate(x, y0=y0)
    L, R = bl.left(x), bl.right(x)
    moved = np.flatnonzero(y != np.r_[y0, y[:-1]])
    assume(moved.size > 0)
    t0 = moved[0]
    assert np.all(y[t0:] <= L[t0:] + TOL)
    assert np.all(y[t0:] >= R[t0:] - TOL)


# ------------------------------------------------------------------ 3. degree 1 = play
def play(x, m_l, c_l, m_r, c_r, y0=0.0):
    y_prev, out = y0, np.empty(len(x))
    for t, xt in enumerate(x):
        y_prev = max(m_r * (xt - c_r), min(m_l * (xt + c_l), y_prev))
        out[t] = y_prev
    return out


@given(
    m=st.floats(0.05, 5.0, **finite),
    c_l=st.floats(0.0, 1.0, **finite),
    c_r=st.floats(0.0, 1.0, **finite),
    x=backlash_inputs(n_max=80, x_max=3.0),
    y0=y0s,
)
def test_degree_one_equal_slopes_is_the_play_operator(m, c_l, c_r, x, y0):
    bl = bx.GeneralBacklash(c_l, c_r, [m], [m])
    np.testing.assert_allclose(bl.simulate(x, y0=y0), play(x, m, c_l, m, c_r, y0), rtol=0, atol=TOL)
    np.testing.assert_allclose(bl.switching(x, y0=y0).y, play(x, m, c_l, m, c_r, y0), rtol=0, atol=TOL)


@given(
    m_l=st.floats(0.05, 5.0, **finite),
    m_r=st.floats(0.05, 5.0, **finite),
    c_l=st.floats(0.0, 1.0, **finite),
    c_r=st.floats(0.0, 1.0, **finite),
    x=backlash_inputs(n_max=80, x_max=3.0),
    y0=y0s,
)
def test_degree_one_different_slopes_is_the_play_operator(m_l, m_r, c_l, c_r, x, y0):
    # the play operator needs L >= R where x goes (the branches must not cross there)
    assume(np.all(m_l * (x + c_l) >= m_r * (x - c_r)))
    bl = bx.GeneralBacklash(c_l, c_r, [m_l], [m_r])
    expected = play(x, m_l, c_l, m_r, c_r, y0)
    np.testing.assert_allclose(bl.simulate(x, y0=y0), expected, rtol=0, atol=TOL)
    np.testing.assert_allclose(bl.simulate(x, y0=y0, form="breakpoints"), expected, rtol=0, atol=TOL)


def test_play_operator_hand_example():
    # width 2 (c_L = c_R = 1), slope 1: triangle wave of amplitude 3 -> output lags by 1
    bl = bx.GeneralBacklash(1.0, 1.0, [1.0], [1.0])
    x = np.array([0.0, 1.0, 2.0, 3.0, 2.0, 1.0, 0.0, -1.0, -2.0, -3.0, -2.0, 0.0])
    expected = np.array([0.0, 0.0, 1.0, 2.0, 2.0, 2.0, 1.0, 0.0, -1.0, -2.0, -2.0, -1.0])
    np.testing.assert_array_equal(bl.simulate(x), expected)


# ------------------------------------------------------------------ breakpoints z_L, z_R
def test_breakpoints_are_the_branch_inverses(ex1):
    bl = ex1.backlash
    for level in (-2.0, -0.3, 0.0, 0.5, 1.7):
        z_l, z_r = bl.breakpoints(level, (-3.0, 3.0))
        assert bl.left([z_l])[0] == pytest.approx(level, abs=1e-12)
        assert bl.right([z_r])[0] == pytest.approx(level, abs=1e-12)
        assert z_l < z_r  # the dead band at that level
    z_l, z_r = bl.breakpoints(1e6, (-3.0, 3.0))
    assert z_l == np.inf and z_r == np.inf
    z_l, z_r = bl.breakpoints(-1e6, (-3.0, 3.0))
    assert z_l == -np.inf and z_r == -np.inf


# ------------------------------------------------------------------ 8. check_branches
def test_check_branches_reports_turning_and_crossing_intervals():
    # L(x) = (x+0.1) - (x+0.1)^2 turns at x = 0.4; R(x) = 2(x-0.1) meets L where
    # L - R = -x^2 - 1.2x + 0.29 = 0
    bl = bx.GeneralBacklash(0.1, 0.1, [1.0, -1.0], [2.0])
    c = bl.check_branches(-1.0, 1.0)
    assert not c.is_valid
    assert (c.x_min, c.x_max) == (-1.0, 1.0)
    assert len(c.left_not_increasing) == 1
    lo, hi = c.left_not_increasing[0]
    assert lo == pytest.approx(0.4, abs=1e-9) and hi == 1.0
    assert c.right_not_increasing == []
    roots = np.sort(np.roots([-1.0, -1.2, 0.29]).real)
    inside = roots[(roots > -1) & (roots < 1)]
    assert len(c.crossed) == 1
    assert c.crossed[0][0] == pytest.approx(inside[0], abs=1e-9) and c.crossed[0][1] == 1.0
    assert c.crossings == pytest.approx(list(inside), abs=1e-9)
    assert "L does not increase" in str(c) and "crossed" in str(c)


def test_check_branches_interior_intervals():
    # L'(xi) = 3 (xi - 1)(xi - 2): L decreases for xi in [1, 2], i.e. x in [0.8, 1.8]
    # R = 1.5 (x - 0.2) is above L for x beyond the largest root of L - R
    p, q, c = 1.0, 2.0, 0.2
    m_l = [3 * p * q, -1.5 * (p + q), 1.0]
    bl = bx.GeneralBacklash(c, c, m_l, [1.5])
    chk = bl.check_branches(-3.0, 3.0)
    assert len(chk.left_not_increasing) == 1
    lo, hi = chk.left_not_increasing[0]
    assert lo == pytest.approx(p - c, abs=1e-9) and hi == pytest.approx(q - c, abs=1e-9)
    # analytic crossings: L(x) - R(x) as a polynomial in x
    L = np.polyval(np.r_[m_l[::-1], 0.0], np.poly1d([1.0, c]))  # poly in x
    R = np.poly1d([1.5, -1.5 * c])
    roots = np.sort([r.real for r in (L - R).roots if abs(r.imag) < 1e-12 and -3 < r.real < 3])
    assert chk.crossings == pytest.approx(list(roots), abs=1e-9)
    assert len(roots) >= 1


def test_check_branches_degree_one_crossing():
    bl = bx.GeneralBacklash(0.5, 0.5, [1.0], [2.0])  # L - R = 1.5 - x
    c = bl.check_branches(-3.0, 3.0)
    assert c.left_not_increasing == [] and c.right_not_increasing == []
    assert len(c.crossed) == 1
    assert c.crossed[0][0] == pytest.approx(1.5, abs=1e-9) and c.crossed[0][1] == 3.0
    assert bl.check_branches(-3.0, 1.4).is_valid


def test_examples_are_valid_on_the_paper_range():
    for model in (bx.example1(), bx.example2()):
        check = model.backlash.check_branches(-3.0, 3.0)
        assert check.is_valid, str(check)
        assert check.crossings == []
        assert "do not cross" in str(check)


@given(bl=backlashes(require_valid=True))
def test_valid_check_means_increasing_and_separated_on_a_grid(bl):
    x = np.linspace(-X_MAX, X_MAX, 2001)
    L, R = ref_L(bl, x), ref_R(bl, x)
    assert np.all(np.diff(L) > 0) and np.all(np.diff(R) > 0)
    assert np.all(L > R)
