"""Where the error lies: residual correlation tests, error by regime, by frequency band and
over time. Each analysis is checked for its size on residuals that hold nothing (white noise,
many seeds, stated tolerances) and for its power on planted errors."""

from __future__ import annotations

import time

import numpy as np
import pytest
from scipy.signal import lfilter

import backlashid as bx
from backlashid.diagnosis._statistics import holm
from backlashid.diagnosis.analyses import REGIMES, TEST_NAMES, frequency_analysis, regime_shares, residual_tests, time_analysis
from backlashid.errors import DataError


def record(seed, n=4000, model=None):
    rng = np.random.default_rng(seed)
    model = model or bx.example1()
    u = rng.uniform(-1.0, 1.0, n)
    return rng, model, u, model.simulate(u, internals=True)


# --------------------------------------------------------------------------- residual tests
def test_white_residual_passes_at_the_nominal_rate():
    # 200 records of white noise: each test rejects at 5 % +- 3 binomial sd (1.5 %), and the
    # Holm-corrected family at most at 5 % + 3 sd
    model, seeds, hits, family = bx.example1(), 200, dict.fromkeys(TEST_NAMES, 0), 0
    for seed in range(seeds):
        rng = np.random.default_rng(seed)
        u = rng.uniform(-1.0, 1.0, 1000)
        x = model.simulate(u, internals=True).x
        r = residual_tests(rng.standard_normal(1000), u, x, max_lag=10)
        for t in r.tests:
            hits[t.name] += t.p_value < 0.05
        family += not r.passed
    rates = {k: v / seeds for k, v in hits.items()}
    assert all(0.005 <= rate <= 0.095 for rate in rates.values()), rates
    assert 0.03 <= np.mean(list(rates.values())) <= 0.07, rates
    assert family / seeds <= 0.095


def test_a_filtered_input_fails_the_cross_correlation_tests():
    rng, _, u, sim = record(5, n=2000)
    e = rng.standard_normal(2000) + lfilter([0.0, 0.3], [1.0, -0.5], u)  # missing linear dynamics
    r = residual_tests(e, u, sim.x)
    assert not r.passed and r.p_value < 1e-4
    assert {"ccf_u", "ccf_x"} <= set(r.failed)
    assert r["ccf_u"].p_adjusted < 1e-4 and r["ccf_u"].n_outside >= 3
    for name in ("e_eu", "u2_e", "e_e2", "e2_e2"):
        assert r[name].passed, name


def test_an_input_times_noise_term_fails_only_the_higher_order_tests():
    # e(t) = v(t) + 0.8 v(t-1) u(t-1): white and uncorrelated with u, but not independent
    rng, _, u, sim = record(5, n=2000)
    v = rng.standard_normal(2000)
    e = v.copy()
    e[1:] += 0.8 * v[:-1] * u[:-1]
    r = residual_tests(e, u, sim.x)
    assert r["e_eu"].p_adjusted < 1e-10 and r["e_eu"].worst_lag == 1
    for name in ("acf", "ccf_u", "ccf_x", "u2_e"):
        assert r[name].passed, name
    assert r.failed[0] == "e_eu"


def test_coloured_noise_fails_the_whiteness_test_but_not_the_cross_tests():
    rejections = dict.fromkeys(TEST_NAMES, 0)
    for seed in range(30):
        rng, _, u, sim = record(seed, n=2000)
        e = lfilter([1.0], [1.0, -0.8], rng.standard_normal(2000))
        r = residual_tests(e, u, sim.x)
        for t in r.tests:
            rejections[t.name] += not t.passed
    assert rejections["acf"] == 30
    assert all(rejections[name] <= 3 for name in ("ccf_u", "ccf_x", "e_eu", "u2_e", "u2_e2", "e_e2")), rejections


def test_correlations_match_a_direct_computation():
    rng, _, u, sim = record(2, n=1500)
    e = rng.standard_normal(1500)
    r = residual_tests(e, u, sim.x, max_lag=5)
    ec = e - e.mean()
    direct = [ec[k:] @ ec[:-k] / (ec @ ec) for k in range(1, 6)]
    np.testing.assert_allclose(r["acf"].values, direct, rtol=1e-12)
    assert r["acf"].bound == pytest.approx(1.959964 / np.sqrt(1500), rel=1e-6)
    if r.ar_order == 0:  # white: nothing is prewhitened, phi_ue is the plain correlation
        uc = u - u.mean()
        direct_u = [ec[k:] @ uc[: 1500 - k] / np.sqrt((ec @ ec) * (uc @ uc)) for k in range(6)]
        np.testing.assert_allclose(r["ccf_u"].values, direct_u, rtol=1e-12)


def test_holm_adjustment_by_hand():
    np.testing.assert_allclose(holm([0.01, 0.04, 0.03, 0.5]), [0.04, 0.09, 0.09, 0.5])
    adj = holm([0.2, np.nan, 0.01])
    assert np.isnan(adj[1]) and adj[0] == pytest.approx(0.2) and adj[2] == pytest.approx(0.02)


def test_residual_tests_without_x_and_json():
    import json

    rng, _, u, _ = record(3, n=600)
    r = residual_tests(rng.standard_normal(600), u, None, max_lag=8)
    assert "ccf_x" not in r and len(r.tests) == len(TEST_NAMES) - 1
    d = json.loads(json.dumps(r.to_dict(), allow_nan=False))
    assert d["tests"]["acf"]["lags"] == list(range(1, 9))


@pytest.mark.parametrize(
    "change, message",
    [
        (lambda e, u, x: (np.r_[e[:10], np.nan, e[11:]], u, x), "NaN"),
        (lambda e, u, x: (e, u[:-1], x), "samples"),
        (lambda e, u, x: (e[:100], u[:100], x[:100]), "at least"),
        (lambda e, u, x: (e, np.ones_like(u), x), "constant"),
        (lambda e, u, x: (np.c_[e, e], u, x), "1-D"),
    ],
)
def test_residual_tests_reject_bad_input(change, message):
    rng, _, u, sim = record(1, n=500)
    e, uu, x = change(rng.standard_normal(500), u, sim.x)
    with pytest.raises(DataError, match=message):
        residual_tests(e, uu, x)


def test_residual_tests_reject_bad_options_and_leave_inputs_alone():
    rng, _, u, sim = record(1, n=500)
    e = rng.standard_normal(500)
    with pytest.raises(DataError, match="max_lag"):
        residual_tests(e, u, sim.x, max_lag=0)
    with pytest.raises(DataError, match="alpha"):
        residual_tests(e, u, sim.x, alpha=1.5)
    copies = e.copy(), u.copy(), sim.x.copy()
    residual_tests(e, u, sim.x)
    for before, after in zip(copies, (e, u, sim.x)):
        np.testing.assert_array_equal(before, after)


# --------------------------------------------------------------------------- regimes
@pytest.mark.parametrize("name", REGIMES)
def test_an_error_planted_in_one_regime_is_found_there(name):
    rng, model, u, _ = record(3)
    masks = regime_shares(model, u, np.ones(u.size)).masks
    e = 0.1 * rng.standard_normal(u.size) + 0.1 * masks[name] * rng.standard_normal(u.size)
    r = regime_shares(model, u, e)
    assert r.concentrated[0] == name
    hit = r[name]
    # 3600 admissible shifts: the smallest p is 1/3601, 6/3601 after Holm over the regimes
    assert hit.excess and hit.p_adjusted < 0.01 and hit.ratio > 1.15
    assert hit.energy_share > hit.sample_share and hit.z > 4.0


def test_regimes_of_a_sandwich_model():
    rng, model, u, _ = record(4, model=bx.example2())
    masks = regime_shares(model, u, np.ones(u.size), warmup=30).masks
    e = 0.05 * rng.standard_normal(u.size) * (1.0 + masks["right_branch"])
    r = regime_shares(model, u, e, warmup=30)
    assert r.concentrated[0] == "right_branch"


def test_white_residual_is_rarely_concentrated_in_a_regime():
    model, flagged = bx.example1(), 0
    for seed in range(60):
        rng = np.random.default_rng(seed)
        u = rng.uniform(-1.0, 1.0, 2000)
        flagged += regime_shares(model, u, rng.standard_normal(2000), warmup=20).significant
    assert flagged <= 5  # 5 % + 3 binomial sd


def test_regime_masks_follow_the_backlash_state():
    rng, model, u, sim = record(6, n=1000)
    r = regime_shares(model, u, rng.standard_normal(1000), warmup=25)
    m = r.masks
    evaluated = np.arange(1000) >= 25
    # dead band, left and right branch partition the evaluated samples (eq 12-13)
    total = m["dead_band"].astype(int) + m["left_branch"] + m["right_branch"]
    np.testing.assert_array_equal(total, evaluated.astype(int))
    np.testing.assert_array_equal(m["left_branch"], sim.f1 & evaluated)
    assert not any(mask[:25].any() for mask in m.values())
    assert sum(x.n_samples for x in r.regimes[:3]) == r.n == 975
    assert sum(x.energy_share for x in r.regimes[:3]) == pytest.approx(1.0)


def test_reversal_and_re_engagement_on_a_hand_made_path():
    # x(t) = u(t-1) (pure delay), straight backlash of half-width 0.5 (dead band 1 wide)
    model = bx.CascadeModel(bx.LinearBlock([1.0]), bx.GeneralBacklash(0.5, 0.5, [1.0], [1.0]))
    up = np.linspace(0.0, 2.0, 60)  # steps of 2/59
    u = np.r_[up, up[::-1], up]  # u(59) = u(60) = 2 and u(119) = u(120) = 0
    rng = np.random.default_rng(0)
    r = regime_shares(model, u, rng.standard_normal(u.size))
    # x stands still at samples 61 and 121 (the repeated values) and turns at 62 and 122
    assert r.masks["near_standstill"][[61, 121]].all()
    rev = np.flatnonzero(r.masks["after_reversal"])
    assert set(rev[np.r_[True, np.diff(rev) > 1]]) == {62, 122}
    assert r.window == 10  # runs of about 60 samples: a quarter, capped at MAX_WINDOW
    assert rev.size == 20
    # after the turn at the top, the output holds while x crosses the dead band
    # (1 / (2/59) = 29.5 steps), then re-engages on the left branch for `window` samples
    holds = r.masks["dead_band"]
    assert holds[62:91].all() and not holds[92]
    engage = np.flatnonzero(r.masks["re_engagement"])
    first = engage[(engage > 62) & (engage < 120)]
    assert first[0] in (91, 92) and first.size == 10
    assert r.masks["left_branch"][first].all()


def test_regime_shares_reject_bad_input():
    rng, model, u, _ = record(1, n=500)
    e = rng.standard_normal(500)
    with pytest.raises(DataError, match="CascadeModel or SandwichModel"):
        regime_shares("model", u, e)
    with pytest.raises(DataError, match="samples"):
        regime_shares(model, u[:-3], e)
    with pytest.raises(DataError, match="warmup"):
        regime_shares(model, u, e, warmup=-1)
    with pytest.raises(DataError, match="at least"):
        regime_shares(model, u, e, warmup=450)
    with pytest.raises(DataError, match="CascadeState"):
        regime_shares(model, u, e, initial_state=bx.example2().rest_state())
    with pytest.raises(DataError, match="NaN"):
        regime_shares(model, u, np.where(np.arange(500) == 7, np.inf, e))


# --------------------------------------------------------------------------- spectrum
def test_white_residual_stays_at_the_floor():
    flagged_known = flagged_est = 0
    for seed in range(60):
        rng = np.random.default_rng(seed)
        u, e = rng.uniform(-1.0, 1.0, 4000), 0.1 * rng.standard_normal(4000)
        known = frequency_analysis(e, u, noise_std=0.1)
        est = frequency_analysis(e, u)
        flagged_known += bool(known.exceeding) + bool(known.coherent)
        flagged_est += bool(est.exceeding)
        assert est.noise_std == pytest.approx(0.1, rel=0.06)
        assert known.floor == pytest.approx(2 * 0.1**2)
    assert flagged_known <= 8 and flagged_est <= 5  # two families at 5 % each, + 3 sd


def test_a_low_frequency_error_is_found_in_its_bands():
    rng = np.random.default_rng(1)
    u = rng.uniform(-1.0, 1.0, 4000)
    e = 0.1 * rng.standard_normal(4000) + lfilter([0.02], [1.0, -0.95], u)  # pole at f ~ 0.008
    fa = frequency_analysis(e, u, noise_std=0.1)
    lows = [b for b in fa.bands if b.hi <= 0.0313]
    assert all(b.above_floor and b.ratio > 1.5 for b in lows)
    assert not fa.bands[-1].above_floor  # 0.25-0.5 stays at the floor
    assert fa.significant and any(b.hi <= 0.0313 for b in fa.bands if b.coherent)
    assert fa.excess_ratio > 1.1
    assert sum(b.energy_share for b in fa.bands) == pytest.approx(1.0, abs=0.01)


def test_frequency_analysis_rejects_bad_input():
    rng = np.random.default_rng(0)
    u, e = rng.uniform(-1, 1, 500), rng.standard_normal(500)
    for bad in (-1.0, np.inf, np.nan, "x"):
        with pytest.raises(DataError, match="noise_std"):
            frequency_analysis(e, u, noise_std=bad)
    with pytest.raises(DataError, match="at least"):
        frequency_analysis(e[:50], u[:50])
    with pytest.raises(DataError, match="samples"):
        frequency_analysis(e, u[:400])


# --------------------------------------------------------------------------- drift
@pytest.mark.parametrize("pole", [0.0, 0.9])
def test_stationary_residuals_rarely_drift(pole):
    flagged = 0
    for seed in range(100):
        rng = np.random.default_rng(seed)
        flagged += time_analysis(lfilter([1.0], [1.0, -pole], rng.standard_normal(4000))).significant
    assert flagged <= 10  # 5 % + 3 binomial sd (2.2 %), rounded up


def test_a_mean_drift_is_measured():
    rng = np.random.default_rng(1)
    e = rng.standard_normal(4000) + 0.4 * np.arange(4000) / 4000
    ta = time_analysis(e)
    assert ta.mean_drift and ta.significant
    assert abs(ta.mean_change - 0.4) < 3 * ta.mean_change_se
    assert not ta.rms_drift


def test_a_step_in_the_mean_and_one_in_the_variance_are_located():
    rng = np.random.default_rng(2)
    e = rng.standard_normal(4000)
    e[2500:] += 0.4
    ta = time_analysis(e)
    means = [c for c in ta.change_points if c.kind == "mean"]
    assert means and abs(means[0].index - 2500) < 150
    assert means[0].after - means[0].before == pytest.approx(0.4, abs=0.12)
    e = rng.standard_normal(4000)
    e[1000:] *= 1.5
    ta = time_analysis(e)
    variances = [c for c in ta.change_points if c.kind == "variance"]
    assert variances and min(abs(c.index - 1000) for c in variances) < 150
    assert ta.rms_drift or variances


def test_time_analysis_rejects_bad_input():
    with pytest.raises(DataError, match="at least"):
        time_analysis(np.ones(20))
    with pytest.raises(DataError, match="NaN"):
        time_analysis(np.r_[np.zeros(300), np.nan])


# --------------------------------------------------------------------------- speed
def test_all_analyses_of_a_4000_sample_residual_take_well_under_a_second():
    rng, model, u, sim = record(0)
    e = rng.standard_normal(u.size) * 0.1 + 0.05 * sim.output
    residual_tests(e, u, sim.x), frequency_analysis(e, u), time_analysis(e)  # imports, caches
    start = time.perf_counter()
    residual_tests(e[50:], u[50:], sim.x[50:])
    regime_shares(model, u, e, warmup=50)
    frequency_analysis(e[50:], u[50:])
    time_analysis(e[50:])
    assert time.perf_counter() - start < 1.0


def test_a_zero_residual_has_nothing_to_show():
    # a perfect model on noise-free data: every analysis answers, none finds anything
    rng, model, u, sim = record(0, n=1000)
    zero = np.zeros(1000)
    assert residual_tests(zero, u, sim.x).passed
    r = regime_shares(model, u, zero, warmup=10)
    assert not r.significant and all(x.ratio == pytest.approx(1.0) for x in r.regimes if x.n_samples)
    assert not time_analysis(zero).significant and not time_analysis(np.full(1000, 0.3)).significant
    fa = frequency_analysis(zero, u, noise_std=0.0)
    assert not fa.significant and fa.floor == 0.0
    offset = np.full(1000, 0.3)  # a constant offset (its rounding must not look like structure)
    assert residual_tests(offset, u, sim.x).passed
    assert not frequency_analysis(offset, u, noise_std=0.0).significant
    assert not regime_shares(model, u, offset).significant


def test_noise_free_floor_puts_any_error_above_it():
    import json

    rng = np.random.default_rng(0)
    u = rng.uniform(-1.0, 1.0, 1000)
    fa = frequency_analysis(lfilter([0.1], [1.0, -0.9], u), u, noise_std=0.0)
    assert all(b.above_floor for b in fa.bands if b.n_bins)
    json.dumps(fa.to_dict(), allow_nan=False)
