"""The independent withheld-effect benchmark's generator (benches/independent_effects.py, issue 18):
its cases hit the requested ENR, its effects do what its docstring says, its nominal plant is the
package's cascade exactly, and its seed sets are reproducible and disjoint."""

from __future__ import annotations

import numpy as np
import pytest

import backlashid as bid
from conftest import load_bench

B = load_bench("independent_effects")


@pytest.mark.parametrize(
    ("effect", "level"), [("dead_time", 3.0), ("quantization", 1.0), ("colored_noise", 3.0), ("hysteresis_memory", 1.0)]
)
def test_realised_enr_matches_the_level(effect, level):
    c = B.make_case(effect, level, 0)
    d = (c.y_effect - c.y_nominal)[B.WARMUP :]
    assert B.rms(d) / c.noise_std == pytest.approx(level, rel=0.01)
    assert c.enr_realised == pytest.approx(level, rel=0.01)
    assert c.params["unabsorbed"] >= B.KAPPA_MIN or "kappa_rule" in c.params


def test_quantised_output_lies_on_its_lattice():
    c = B.make_case("quantization", 3.0, 1)
    q = c.params["q"]
    k = c.y / q
    np.testing.assert_allclose(k, np.round(k), atol=1e-9)
    # the noise is added before the rounding: the measured values are not Q(y_nominal) + noise
    assert np.unique(np.round(c.y[B.WARMUP :] / q)).size >= 20


@pytest.mark.parametrize("d", [1, 2, 3])
def test_dead_time_shifts_the_response_by_d_samples(d):
    rng = np.random.default_rng(3)
    u = rng.uniform(-1, 1, 500)
    x = B.drive(u, 0.4, 0.7)
    xd = B.drive(np.r_[np.zeros(d), u[:-d]], 0.4, 0.7)
    np.testing.assert_allclose(xd[d:], x[:-d], atol=1e-12)
    np.testing.assert_array_equal(xd[:d], 0.0)


def test_ode_integrator_without_friction_is_the_exact_zoh_drive():
    u = np.random.default_rng(4).uniform(-1, 1, 300)
    x_ode, moving = B.drive_ode(u, 0.5, 0.6)
    np.testing.assert_allclose(x_ode, B.drive(u, 0.5, 0.6), atol=1e-10)
    assert moving > 0.9


def test_nominal_plant_is_the_packages_cascade():
    """The no-effect plant is exactly a cascade with na = nb = 2 and cubic branches: the package's
    simulation of the true parameters reproduces the generator's noise-free output."""
    c = B.make_case("none", 0.0, 2)
    p = c.plant
    r, s = p["r"], p["s"]
    num, den = B.discrete_tf(*B.drive_matrices(p["w"], p["z"]), np.array([1.0, 0.0]))
    model = bid.CascadeModel(
        bid.LinearBlock(r * num[1:], den[1:]),
        bid.GeneralBacklash(r * p["c_L"], r * p["c_R"], [1.0, 0.0, p["k_L"] / (r * s) ** 2], [1.0, 0.0, p["k_R"] / (r * s) ** 2]),
    )
    np.testing.assert_allclose(model.simulate(c.u), c.y_nominal, atol=1e-9)
    noise = c.y - c.y_nominal
    assert B.rms(noise[B.WARMUP :]) == pytest.approx(c.noise_std, rel=1e-9)


def test_seed_sets_are_reproducible_and_disjoint():
    a = B.make_case("saturation", 3.0, 2, "tune")
    b = B.make_case("saturation", 3.0, 2, "tune")
    f = B.make_case("saturation", 3.0, 2, "final")
    np.testing.assert_array_equal(a.u, b.u)
    np.testing.assert_array_equal(a.y, b.y)
    assert not np.array_equal(a.u, f.u)
    assert B.SEED_SETS["tune"] != B.SEED_SETS["final"]
    # the index picks the input class, so every 10 cases see each class twice
    assert [B.INPUT_CLASSES[i % 5] for i in range(10)].count("ramps") == 2
    assert a.input_class == "multisine"


def test_case_list_counts_and_decision_rules():
    cases = B.case_list(list(B.ALL_EFFECTS), [3.0, 1.0], 10)
    assert sum(e == "none" for e, _, _ in cases) == 20
    assert sum(e == "friction" for e, _, _ in cases) == 20
    assert B.CORRECT["gain_drift"] == B.CORRECT["cogging"] == "unexplained"
    assert B.CORRECT["none"] == "none" and B.CORRECT["dead_time"] == "dead_time"
