"""The package's one Levenberg-Marquardt search (identify._refine.levenberg_marquardt) on the
core's compiled cascade problem: the box, the held parameters, the stopping rule."""

import numpy as np
import pytest

import backlashid as bid
from backlashid.errors import DataError
from backlashid.identify import Structure, levenberg_marquardt

S = Structure(2, 2, 3)
TRUTH = S.pack(bid.example1())
C_L, C_R = S.names.index("c_L"), S.names.index("c_R")


@pytest.fixture(scope="module")
def prob():
    d = bid.example_data(bid.example1(), 3000, snr=25, seed=21)
    return S.problem(d.u, d.noisy)


def test_the_default_box_holds_the_dead_band_widths_non_negative(prob):
    lower, upper = prob.bounds()
    assert lower[C_L] == 0.0 and lower[C_R] == 0.0
    assert np.isneginf(np.delete(lower, [C_L, C_R])).all() and np.isposinf(upper).all()


def test_an_inactive_box_changes_nothing(prob):
    start = TRUTH + 0.03
    boxed = levenberg_marquardt(prob, start)
    free = levenberg_marquardt(prob, start, lower=np.full(S.size, -np.inf), upper=np.full(S.size, np.inf))
    np.testing.assert_array_equal(boxed.theta, free.theta)
    assert boxed.converged and boxed.cost == free.cost


def test_a_start_outside_the_box_is_projected_and_the_search_ends_inside(prob):
    start = TRUTH.copy()
    start[C_L] = -0.2
    fit = levenberg_marquardt(prob, start)
    assert fit.converged and fit.theta[C_L] >= 0.0
    assert np.max(np.abs(fit.theta - TRUTH)) < 0.05


def test_a_parameter_pinned_by_its_bounds_is_held_and_the_others_reach_a_stationary_point(prob):
    lower, upper = map(np.array, prob.bounds())
    lower[C_L] = upper[C_L] = 0.4  # truth 0.6
    fit = levenberg_marquardt(prob, TRUTH, lower=lower, upper=upper, se_tol=1e-4)
    assert fit.theta[C_L] == 0.4 and fit.converged
    free = levenberg_marquardt(prob, TRUTH)
    assert fit.cost > free.cost  # the pinned width costs fit
    g, cost = prob.gradient(fit.theta)
    g_free = np.delete(g, C_L)
    # J^T r over the free parameters vanishes (relative to its scale ||J_i|| ||r||)
    col = np.delete(np.linalg.norm(fit.r_aug[: S.size, : S.size], axis=0), C_L)
    assert np.max(np.abs(g_free) / (col * np.sqrt(cost))) < 1e-3


def test_a_width_that_the_data_pull_below_zero_stops_at_zero():
    # a backlash whose left branch meets zero at x = 0 (c_L = 0): the noise pulls the
    # unconstrained estimate to either side of it
    m = bid.example1()
    lin, bl = m.linear, m.backlash
    truth = bid.CascadeModel(lin, bid.GeneralBacklash(0.0, bl.c_right, bl.m_left, bl.m_right))
    ends = []
    for seed in range(4):
        d = bid.example_data(truth, 1500, snr=10, seed=seed)
        p = S.problem(d.u, d.noisy)
        free = levenberg_marquardt(p, S.pack(truth), lower=np.full(S.size, -np.inf), upper=np.full(S.size, np.inf))
        boxed = levenberg_marquardt(p, S.pack(truth))
        assert boxed.theta[C_L] >= 0.0 and boxed.cost >= free.cost * (1 - 1e-12)
        ends.append(free.theta[C_L])
    assert min(ends) < 0.0  # the box mattered in at least one record


@pytest.mark.parametrize(
    "lower, upper",
    [(np.zeros(3), None), (None, np.full(S.size, -1.0)), (np.full(S.size, np.nan), None)],
    ids=["wrong length", "upper below lower", "nan"],
)
def test_bad_bounds_are_a_data_error_that_says_what_to_give(prob, lower, upper):
    with pytest.raises(DataError, match="lower and upper: give one bound per parameter"):
        levenberg_marquardt(prob, TRUTH, lower=lower, upper=upper)


def test_an_unstable_start_is_refused(prob):
    start = TRUTH.copy()
    start[S.names.index("b2")] = 1.5  # a pole outside the unit circle
    assert not prob.feasible(start)
    with pytest.raises(bid.BacklashIdError, match="start is unstable"):
        levenberg_marquardt(prob, start)


# -- variable projection (linear=): the Chebyshev coefficients and offset of a Wiener-Hammerstein


@pytest.fixture(scope="module")
def wh():
    from backlashid import _core
    from backlashid.identify import wiener_hammerstein_model

    truth = wiener_hammerstein_model([0.3, 0.1], [-0.5, 0.1], [1.0, 0.0, -0.3], [0.5, 0.2], [-0.2, 0.05])
    rng = np.random.default_rng(0)
    u = rng.normal(0.0, 0.5, 2000)
    y = truth.simulate(u) + 0.01 * rng.normal(size=u.size) + 0.1
    # the two scale directions held (a1, r1); theta = [a2, b1, b2, c1, c2, c3, r2, s1, s2, offset]
    prob = _core.WienerHammersteinProblem(u, y, 2, 2, 3, warmup=20, fixed=[("a1", 0.3), ("r1", 0.5)])
    assert prob.names == ["a2", "b1", "b2", "c1", "c2", "c3", "r2", "s1", "s2", "offset"]
    return prob


WH_LINEAR = [3, 4, 5, 9]  # f's coefficients and the offset: y is affine in them for fixed G1, G2
WH_STARTS = [
    np.array([0.1, -0.4, 0.05, 1.0, 0.0, 0.0, 0.25, -0.1, 0.0, 0.0]),
    np.array([0.0, -0.2, 0.0, 3.0, 1.0, -1.0, 0.0, 0.0, 0.0, 2.0]),
]


@pytest.mark.parametrize("start", WH_STARTS, ids=["near", "far"])
def test_variable_projection_reaches_the_minimum_of_the_plain_search_in_fewer_steps(wh, start):
    plain = levenberg_marquardt(wh, start)
    vp = levenberg_marquardt(wh, start, linear=WH_LINEAR)
    assert plain.converged and vp.converged
    assert vp.cost == pytest.approx(plain.cost, rel=1e-7)
    cov = plain.unscaled_covariance(wh.names) * plain.cost / (plain.n_residuals - len(wh.names))
    assert np.all(np.abs(vp.theta - plain.theta) < 0.1 * np.sqrt(np.diag(cov)))  # within 0.1 standard errors
    assert vp.iterations < plain.iterations


def test_variable_projection_returns_the_exact_linear_optimum_and_its_factor(wh):
    fit = levenberg_marquardt(wh, WH_STARTS[1], linear=WH_LINEAR, max_iter=3)
    p = len(wh.names)
    assert fit.cost == pytest.approx(wh.cost(fit.theta), rel=1e-9)  # c* and the offset exact at G1, G2
    qtr, rho = fit.r_aug[:p, p], fit.r_aug[p, p]
    assert float(qtr @ qtr) + rho**2 == pytest.approx(fit.cost, rel=1e-9)
    r_mat = fit.r_aug[:p, :p]
    g = wh.gradient(fit.theta)[0]
    # J^T r over the linear parameters vanishes at c* (relative to ||J_i|| ||r||)
    col = np.linalg.norm(r_mat, axis=0)
    assert np.max(np.abs(g[WH_LINEAR]) / (col[WH_LINEAR] * np.sqrt(fit.cost))) < 1e-6


@pytest.mark.parametrize("linear", [[C_L], [0, 0], [S.size]], ids=["bounded", "twice", "out of range"])
def test_linear_indices_must_be_distinct_unbounded_parameters(prob, linear):
    with pytest.raises(DataError, match="linear: give distinct indices"):
        levenberg_marquardt(prob, TRUTH, linear=linear)


# -- the fine stage of coarse to fine: LM from a sub-record's factor (identify._coarse) ----------


@pytest.fixture(scope="module")
def long_record():
    d = bid.example_data(bid.example1(), 60_000, snr=25, seed=5)
    seg = S.problem(d.u[:3000], d.noisy[:3000])
    start = levenberg_marquardt(seg, TRUTH).theta  # a segment's optimum, far from the record's
    return d, start


def _distance_in_se(fit, theta):
    r = fit.r_aug[: S.size, : S.size]
    return float(np.linalg.norm(r @ (theta - fit.theta)) / np.sqrt(fit.cost / (fit.n_residuals - S.size)))


def test_lm_from_a_sub_records_factor_ends_at_the_plain_searchs_optimum_with_its_covariance(long_record):
    from backlashid.identify._refine import refine_from_factor

    d, start = long_record
    whole = S.problem(d.u, d.noisy)
    plain = levenberg_marquardt(whole, start)
    sub = 6000
    factor = S.problem(d.u[:sub], d.noisy[:sub]).oe_factor(start)[0] * np.sqrt(len(d.u) / sub)
    fit = refine_from_factor(whole, start, factor, near_se=3.0)
    assert fit.converged and _distance_in_se(plain, start) > 5.0
    assert _distance_in_se(plain, fit.theta) < 0.02
    assert abs(fit.cost / plain.cost - 1) < 1e-8
    se_plain = np.sqrt(np.diag(plain.unscaled_covariance(S.names)))
    se_fit = np.sqrt(np.diag(fit.unscaled_covariance(S.names)))
    np.testing.assert_allclose(se_fit, se_plain, rtol=0.01)


def test_lm_from_a_useless_factor_falls_back_to_the_plain_search(long_record):
    from backlashid.identify._refine import refine_from_factor

    d, start = long_record
    whole = S.problem(d.u, d.noisy)
    plain = levenberg_marquardt(whole, start)
    singular = refine_from_factor(whole, start, np.zeros((S.size + 1, S.size + 1)))
    np.testing.assert_array_equal(singular.theta, plain.theta)
    # a factor far too large gives a step that changes nothing: still the plain optimum
    tiny_step = refine_from_factor(whole, start, 1e8 * np.eye(S.size + 1))
    assert _distance_in_se(plain, tiny_step.theta) < 0.02


def test_the_fine_stage_uses_the_sub_record_only_on_long_records(long_record, monkeypatch):
    from backlashid.identify import _coarse

    d, start = long_record
    whole = S.problem(d.u, d.noisy)
    calls = []
    monkeypatch.setattr(_coarse, "refine_from_factor", lambda *a, **k: calls.append(a) or levenberg_marquardt(whole, start))
    _coarse.refine_whole(S, whole, start, d.u, d.noisy, 0, 3000)  # 20 segments: the plain search
    assert not calls
    _coarse.refine_whole(S, whole, start, d.u, d.noisy, 0, 1000)  # 60 segments
    assert len(calls) == 1 and calls[0][2].shape == (S.size + 1, S.size + 1)
