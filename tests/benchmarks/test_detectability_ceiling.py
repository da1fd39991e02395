"""The detectability oracle of the independent benchmark (benches/detectability_ceiling.py):
its null threshold is the distribution-free order statistic it claims, and on a no-effect case
the nominal fit reaches the generator's noise floor while no candidate's refit gains anything
material."""

from __future__ import annotations

import math

import numpy as np
import pytest

import backlashid as bid
from conftest import assert_final_seeds_refused, load_bench

IE = load_bench("independent_effects")
C = load_bench("detectability_ceiling")


def test_threshold_is_the_order_statistic_that_keeps_95_percent():
    # n = 20: k = ceil(0.95 * 21) = 20, the maximum; n = 220: k = ceil(0.95 * 221) = 210
    assert C.threshold(list(range(1, 21))) == (20.0, 20, 20)
    assert C.threshold(list(np.arange(220.0)[::-1])) == (209.0, 210, 220)
    # exchangeability: a fresh draw exceeds T with probability 1 - k / (n + 1) <= 5 %
    rng = np.random.default_rng(0)
    exceed = []
    for _ in range(2000):
        v = rng.standard_normal(41)
        t, _, _ = C.threshold(list(v[:40]))
        exceed.append(v[40] > t)
    assert np.mean(exceed) == pytest.approx(1 - 39 / 41, abs=0.015)
    lo, hi = C.quantile_interval(list(np.arange(1.0, 221.0)))
    assert lo < 210 < hi


def test_the_final_seeds_are_refused_and_the_null_set_is_disjoint():
    assert_final_seeds_refused(C, IE, "none", 0.0)


def test_oracle_on_a_no_effect_case_gains_nothing_material():
    x = C.oracle_case("none", 0.0, 0, "tune")
    assert "error" not in x, x.get("error")
    assert x["noise_exact"]
    # the nominal cascade holds the plant: its validation MSE is the noise energy within 2 %
    assert abs(x["excess_energy"]) < 0.02
    # every candidate refit of the catalogue, judged on the validation record: under 1 % better
    best = max(c["R"] for c in x["candidates"].values())
    assert best < 0.01
    assert len(x["candidates"]) == len(bid.EFFECTS)  # every effect of the diagnoser's catalogue


def test_oracle_sees_an_effect_the_nominal_fit_cannot_absorb():
    # a colored sensor noise at ENR 3: nothing in the nominal model absorbs it, so the residual
    # keeps about the whole ENR, and its own candidate (one-step prediction) predicts better
    x = C.oracle_case("colored_noise", 3.0, 0, "tune", candidates=["colored_noise"])
    assert "error" not in x, x.get("error")
    assert x["residual_enr"] == pytest.approx(x["enr_realised"], rel=0.25)
    own = x["candidates"]["colored_noise"]
    assert own["R"] > 0.3 and (math.isinf(own["z"]) or own["z"] > 4.0)
