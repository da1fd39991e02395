"""The chains benchmark's detectability oracle (benches/chain_ceiling.py): its per-family
thresholds are the order statistics it claims, its detection flags follow its frozen rules, its
seed sets are disjoint from the benchmark's, and on one sandwich case the told diagnosis is the
one given only the true candidate."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import assert_final_seeds_refused, load_bench

IC = load_bench("independent_chains")
C = load_bench("chain_ceiling")


def _case(row: str, best_z: float, best_r: float, mse0: float = 1.2, s2: float = 1.0, **extra) -> dict:
    out = {"row": row, "family": IC.ROWS[row].family, "level": 3.0, "index": 0, "seeds": "tune", "mse0": mse0,
           "noise_energy": s2, "residual_enr": float(np.sqrt(max(mse0 / s2 - 1, 0))), "reported": "none", "effects": [],
           "lattice_material": False, "candidates": {"dead_time": {"p": 0.5, "z": best_z, "R": best_r}}, "told_effects": None}  # fmt: skip
    return out | extra


def test_per_family_thresholds_are_the_order_statistics_and_the_flags_follow_the_rules():
    # 20 no-effect sandwich cases with best z 1..20 and R 0.001..0.02: k = 20 of 20 (the maximum)
    null = [_case("sandwich:none", float(z), z / 1000.0, mse0=1.0) for z in range(1, 21)]
    thr = C.thresholds(null)
    assert thr["sandwich"]["z"] == 20.0 and thr["sandwich"]["R"] == pytest.approx(0.02)
    assert thr["sandwich"]["delta"] == pytest.approx(0.0)
    # an effect case: true candidate above T by z and R; the ideal rule 1 - s2 / mse0 > T_R
    above = _case("sandwich:dead_time", 25.0, 0.05, mse0=1.5, told_effects=["dead_time"], reported="dead_time", effects=["dead_time"])
    below = _case("sandwich:dead_time", 5.0, 0.01, mse0=1.01, told_effects=[], reported="compliance", effects=["compliance"])
    summary = C.summarise(null + [above, below])
    row = summary["rows"]["sandwich:dead_time 3"]
    assert (row["det_z"], row["det_R"], row["ideal"], row["told"], row["right"]) == (0.5, 0.5, 0.5, 0.5, 0.5)


def test_the_final_seeds_are_refused_and_the_null_set_is_disjoint():
    assert_final_seeds_refused(C, IC, "sandwich:dead_time", 3.0)
    assert_final_seeds_refused(C, IC, "sandwich:none", 0.0)
    assert C.CASCADE_NONE in IC.ROWS and not IC.ROWS[C.CASCADE_NONE].effects


def test_the_told_diagnosis_has_only_the_true_candidate():
    x = C.oracle_case("sandwich:output_offset", 3.0, 0, "tune")
    assert "error" not in x, x.get("error")
    assert set(x["told_effects"]) <= {"output_offset"}
    assert len(x["candidates"]) > 10  # the first call: every candidate of the catalogue
    assert x["noise_energy"] > 0 and x["mse0"] > 0
