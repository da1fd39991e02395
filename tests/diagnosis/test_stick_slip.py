"""The stick-slip friction of the drive (``rust/core/src/effects/stick_slip.rs``): Karnopp's
rule in the force balance of the linear block, with a Stribeck dip. Its compiled refit carries
the exact Jacobian (against central differences) for every parameter, and its simulation is
the NumPy reference's."""

from __future__ import annotations

import numpy as np
import pytest
from test_augmented_problem import THETA, central_differences, record

import backlashid as bid
from backlashid import _core
from backlashid.benchmarks._reference import linear_with_stick_slip
from backlashid.identify import Structure

STRUCTURE = Structure(2, 2, 3)
NAMES = ["F_c", "F_v", "F_s", "v_s"]
CASES = [
    ([0.05, 0.1, 0.0, 0.05], ["F_c", "F_v"]),  # Coulomb plus viscous, sticking
    ([0.05, 0.1, 0.04, 0.05], NAMES),  # with a Stribeck dip
    ([0.0, 0.0, 0.0, 0.05], ["F_c", "F_v", "F_s"]),  # zero size, where the refits start
]


@pytest.mark.parametrize(("params", "free"), CASES)
def test_the_factor_carries_the_exact_jacobian(params: list[float], free: list[str]) -> None:
    u, y = record()
    warmup = 10
    prob = _core.AugmentedProblem(u, y, 2, 2, 3, [("stick_slip", params)], free, warmup=warmup)
    theta = np.concatenate([THETA, [params[NAMES.index(f)] for f in free]])
    jac = central_differences(prob, theta)[warmup:]
    y_sim, exact = prob.sensitivity(theta)
    np.testing.assert_array_equal(y_sim, prob.simulate(theta))
    np.testing.assert_allclose(exact[warmup:], jac, rtol=0, atol=1e-6 * np.max(np.abs(jac)) + 1e-9)
    r_aug, cost = prob.oe_factor(theta)
    r = (y - y_sim)[warmup:]
    gram = np.column_stack([jac, r]).T @ np.column_stack([jac, r])
    np.testing.assert_allclose(r_aug.T @ r_aug, gram, rtol=0, atol=1e-6 * np.max(np.abs(np.diag(gram))))


@pytest.mark.parametrize("params", [c[0] for c in CASES])
def test_the_simulation_is_the_reference(params: list[float]) -> None:
    u, _ = record()
    est = STRUCTURE.unpack(THETA)
    got = _core.simulate_augmented(*est.chain(), u, effects=[("stick_slip", params)])
    x = linear_with_stick_slip(est.a, est.b, u, *params)
    want = bid.GeneralBacklash(est.c_left, est.c_right, est.m_left, est.m_right).simulate(x)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)


def test_a_drive_sticks_where_its_force_is_below_the_static_friction() -> None:
    # a first-order block x(t+1) = 0.5 u_eff(t) + 0.5 x(t): a ramp that turns back
    u = np.r_[np.linspace(0.0, 1.0, 20), np.linspace(1.0, 0.8, 10)]
    x = linear_with_stick_slip([0.5], [-0.5], u, 0.3, 0.0, 0.0, 0.05)
    moving = np.abs(np.diff(x)) > 1e-12
    assert not moving[:3].any()  # u below the friction: at rest
    assert moving[8:18].all()  # then it slides
    assert not moving[-5:].any()  # the small turn back does not overcome the friction
