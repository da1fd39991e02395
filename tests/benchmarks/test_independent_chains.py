"""The second independent withheld-effect benchmark's generator (benches/independent_chains.py):
its nominal plants are the package's sandwich / input-backlash / cascade models exactly, its
integrators and ODEs reduce to the exact discretisations, its new physics behaves as the physics
says, its cases hit the requested ENR, and its seeds and decision rules are as documented."""

from __future__ import annotations

import math

import numpy as np
import pytest

import backlashid as bid
from conftest import load_bench

C = load_bench("independent_chains")
IE = C.ie


@pytest.mark.parametrize("row", ["sandwich:none", "hammerstein:none"])
def test_nominal_plants_are_the_packages_models(row):
    """Two-mass drive and input backlash without effects: the package's SandwichModel of the true
    parameters reproduces the generator's noise-free output."""
    c = C.make_case(row, 0.0, 3)
    model = C.truth_model(c.plant_object)
    assert isinstance(model, bid.SandwichModel)
    np.testing.assert_allclose(model.simulate(c.u), c.y_nominal, atol=1e-9 * np.std(c.y_nominal))
    assert IE.rms((c.y - c.y_nominal)[C.WARMUP :]) == pytest.approx(c.noise_std, rel=1e-9)


def test_integrating_plant_has_a_pole_at_one_and_starts_mid_motion():
    c = C.make_case("integrating:none", 0.0, 2)
    theta = C.nominal_theta(c.plant_object)[0]
    assert 1.0 + theta[2] + theta[3] == pytest.approx(0.0, abs=1e-12)  # den(1) = 0: an integrator
    # a constant velocity command: the position grows by that velocity every sample once settled
    x = C.velocity_drive(np.full(400, 0.3), 5.0)
    np.testing.assert_allclose(np.diff(x[-50:]), 0.3, rtol=1e-9)
    # mid-motion: PRE samples ran before the record, the motor moves at its first sample
    xm = C.velocity_drive(c.plant_object.u, c.plant["tau_m"])
    assert len(c.u) == C.N and len(c.plant_object.u) == C.N + C.PRE
    assert abs(xm[C.PRE] - xm[C.PRE - 1]) > 1e-6 * c.plant["s"]


def test_ode_integrators_without_their_forces_are_the_exact_discretisations():
    u = np.random.default_rng(4).uniform(-1, 1, 300)
    x, at_stop = C.spring_drive_ode(u, 0.5, 0.6)
    np.testing.assert_allclose(x, IE.drive(u, 0.5, 0.6), atol=1e-10)
    assert at_stop == 0.0
    xv, moving = C.velocity_drive_friction(u, 4.0, 0.0, 0.0)
    np.testing.assert_allclose(xv, C.velocity_drive(u, 4.0), atol=1e-9)
    assert moving == 1.0
    xf = C.fine_drive(u, 0.5, 0.6)
    np.testing.assert_allclose(xf[:: C.SUBSTEPS], IE.drive(u, 0.5, 0.6), atol=1e-10)


def test_travel_stop_holds_the_motor_inside_its_stops():
    u = np.random.default_rng(5).uniform(-1, 1, 2000)
    x, at_stop = C.spring_drive_ode(u, 0.8, 0.5, stops=(-0.3, 0.4))
    assert x.min() >= -0.3 and x.max() <= 0.4
    assert 0.05 < at_stop < 0.95


def test_lugre_force_slides_at_coulomb_plus_viscous_and_holds_at_standstill():
    h = 1.0 / C.SUBSTEPS
    f_c, f_s, v_s, s0, s1, s2 = 1.0, 1.5, 0.01, 200.0, 20.0, 0.3
    v = np.r_[np.full(400, 0.5), np.zeros(50)]
    f = C.lugre_force(v, f_c, f_s, v_s, s0, s1, s2, h)
    # steady sliding far above the Stribeck velocity: sigma0 z = g(v) = F_c, plus the viscous term
    assert f[399] == pytest.approx(f_c + s2 * 0.5, rel=1e-9)
    # at standstill the bristle state holds: the force is sigma0 z, constant
    np.testing.assert_allclose(f[401:], f_c, rtol=1e-9)


@pytest.mark.parametrize(("row", "level"), [("physics:creep", 3.0), ("physics:sensor_clip", 1.0), ("physics:duffing", 1.0)])
def test_realised_enr_matches_the_level(row, level):
    c = C.make_case(row, level, 0)
    d = (c.y_effect - c.y_nominal)[C.WARMUP :]
    assert IE.rms(d) / c.noise_std == pytest.approx(level, rel=0.01)
    assert c.params["unabsorbed"] >= C.KAPPA_MIN or "kappa_rule" in c.params


def test_sensor_clip_bounds_the_measured_output():
    c = C.make_case("physics:sensor_clip", 3.0, 1)
    p = c.params["sensor_clip"]
    assert c.y.min() >= p["clip_low"] and c.y.max() <= p["clip_high"]
    assert 0.03 <= p["clipped"] <= 0.30


def test_pair_scales_each_member_alone_to_the_level():
    c = C.make_case("pair:dead_time+output_offset", 3.0, 2)
    # neither member scales: the noise sits at their geometric mean, each within a factor 1.73 of the level
    a, b = c.params["dead_time"]["enr_alone"], c.params["output_offset"]["enr_alone"]
    assert math.sqrt(a * b) == pytest.approx(3.0, rel=1e-9)
    assert 3.0 / 1.74 < a < 3.0 * 1.74 and 3.0 / 1.74 < b < 3.0 * 1.74
    assert "o" in c.params["output_offset"] and c.params["dead_time"]["d"] in (1, 2, 3)
    c = C.make_case("pair:saturation+width_drift", 1.0, 0)  # both scale: each alone at the level
    assert c.params["saturation"]["enr_alone"] == pytest.approx(1.0, rel=0.02)
    assert c.params["width_drift"]["enr_alone"] == pytest.approx(1.0, rel=0.02)


def test_seed_sets_are_new_reproducible_and_disjoint():
    a = C.make_case("hammerstein:none", 0.0, 1, "tune")
    b = C.make_case("hammerstein:none", 0.0, 1, "tune")
    f = C.make_case("hammerstein:none", 0.0, 1, "final")
    np.testing.assert_array_equal(a.y, b.y)
    assert not np.array_equal(a.u, f.u)
    assert set(C.SEED_SETS.values()).isdisjoint(IE.SEED_SETS.values())
    with pytest.raises(ValueError, match="seed set"):
        C.make_case("hammerstein:none", 0.0, 1, "other")


def test_case_list_and_decision_rules():
    cases = C.case_list(list(C.ROWS), None, 10)
    assert sum(r == "sandwich:none" for r, _, _ in cases) == 20
    assert sum(r == "integrating:friction" for r, _, _ in cases) == 10  # ENR 3 only
    assert sum(r == "physics:lugre" for r, _, _ in cases) == 20
    assert C.ROWS["physics:travel_stop"].verdicts == ("state_saturation",)
    assert C.ROWS["ooc:eccentric_gear"].verdicts == ("unexplained",)
    pair = {"row": "pair:friction+quantization", "reported": "friction", "effects": ["friction"]}
    assert not C.correct(pair) and C._rank1(pair)
    assert C.correct({**pair, "effects": ["quantization", "friction"]})
    assert C.correct({"row": "ooc:supply_ripple", "reported": "unexplained"})
    assert not C.correct({"row": "sandwich:none", "reported": "fit_error"})


def test_velocity_drive_friction_tends_to_the_frictionless_drive():
    """A vanishing Coulomb friction must not invent a drift of the integrated position (a stop at
    every reversal would lose a substep's motion each time, and the integrator keeps it)."""
    u = np.diff(np.random.default_rng(6).uniform(-1, 1, 2001))
    x0 = C.velocity_drive(u, 3.0)
    x1, _ = C.velocity_drive_friction(u, 3.0, 1e-7, 0.0)
    assert IE.rms(x1 - x0) < 1e-4 * IE.rms(x0)
    x2, moving = C.velocity_drive_friction(u, 3.0, 0.2, 0.0)  # a real friction sticks
    assert moving < 1.0 and IE.rms(x2 - x0) > 1e-2 * IE.rms(x0)
