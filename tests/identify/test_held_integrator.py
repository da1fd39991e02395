"""A block's pole held at the integrator (identify/_integrator.py): the reparametrised problem
agrees with the compiled one it wraps (cost, gradient, factor), and the search of a position
that integrates leaves the stability guard's wall.

The records come from tests/identify/test_position_records.py's generator (scipy's lfilter for
the drive and the load, the play by a per-sample loop over the paper's eq 1)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from test_position_records import N_EST, _load_position_record

import backlashid as bid
from backlashid.identify import Structure, _fit, fit_hammerstein_backlash
from backlashid.identify._integrator import HeldIntegrator, poles_on_wall

S = Structure(1, 0, 3, 2, 2, initial_state=True)
# an input backlash before a load that integrates (poles 1 - 1e-6 and 0.88), with a state
INSIDE = 1.0 - 1e-6
THETA = np.array([0.12, 0.035, 0.0, 0.7, 1.0, 0.06, 0.0, 1.1, 0.0, -(INSIDE + 0.8825), INSIDE * 0.8825, 0.1, 0.05, 2.0, -1.0])


def _held() -> tuple[HeldIntegrator, object]:
    u, y, _ = _load_position_record("white", 0)
    prob = S.problem(u[:600], y[:600], 20)
    wall = 1.0 - 1e-13  # where LM stops (poles 1 - 1e-13 and 0.88)
    at = poles_on_wall(S.names, np.r_[THETA[:9], -(wall + 0.8825), wall * 0.8825, THETA[11:]], "s")
    assert at == [S.names.index("s1"), S.names.index("s2")]
    return HeldIntegrator(prob, at, 1.0 - 1e-6), prob


def test_the_held_problem_is_the_compiled_one_along_its_map():
    held, prob = _held()
    reduced = held.reduced(THETA)
    full = held.full(reduced)
    assert len(reduced) == len(THETA) - 1 and held.names == [n for n in S.names if n != "s2"]
    # the block's poles: rho and the other of THETA's (the map divides out 1 - rho q^-1)
    assert np.allclose(np.sort(np.roots(np.r_[1.0, full[9:11]])), np.sort(np.roots(np.r_[1.0, THETA[9:11]])), atol=1e-6)
    assert np.isclose(held.cost(reduced), prob.cost(full), rtol=1e-12)
    assert np.array_equal(held.simulate(reduced), prob.simulate(full)) and held.warmup == prob.warmup
    with pytest.raises(AttributeError):  # nothing that reads theta passes through unmapped
        held.motion(reduced)
    # the gradient (J^T r, r = y - y_sim) against central differences of the cost, and the
    # factor's normal equations against the Jacobian of the simulation by central differences
    g, _ = held.gradient(reduced)
    h = 1e-6 * np.maximum(np.abs(reduced), 1e-3)
    steps = [(h[k], e) for k, e in enumerate(np.eye(len(reduced)))]
    fd = np.array([(held.cost(reduced + hk * e) - held.cost(reduced - hk * e)) / (2 * hk) for hk, e in steps])
    assert np.max(np.abs(-2.0 * np.asarray(g) - fd)) <= 1e-5 * np.max(np.abs(fd))

    def simulated(theta: np.ndarray) -> np.ndarray:
        return np.asarray(prob.simulate(held.full(theta)))[prob.warmup :]

    jac = np.column_stack([(simulated(reduced + hk * e) - simulated(reduced - hk * e)) / (2 * hk) for hk, e in steps])
    r_red = held.oe_factor(reduced)[0]
    normal = r_red[:-1, :-1].T @ r_red[:-1, :-1]
    assert np.max(np.abs(normal - jac.T @ jac)) <= 1e-5 * np.max(np.abs(jac.T @ jac))
    assert np.isclose(np.sum(r_red[:, -1] ** 2), prob.cost(full), rtol=1e-10)


def test_a_block_without_a_pole_on_the_wall_holds_nothing():
    assert poles_on_wall(S.names, THETA, "s") is None  # 1 - 1e-6 is inside the wall's 1e-8
    assert poles_on_wall(S.names, THETA, "b") is None  # the input backlash's block has no poles


@pytest.mark.parametrize("kind, seed", [("white", 0), ("white", 2), ("lowpass", 2)])
def test_a_load_position_fit_leaves_the_stability_wall(monkeypatch, kind, seed):
    # the load's integrator wants its pole at 1: LM stopped on the guard's wall (poles 1 -
    # 1e-13), and these fits validated at 3.0-4.2 noise stds; with the pole held at the
    # integrator the other parameters reach their optimum (validation 1.0-1.2)
    u, y, noise = _load_position_record(kind, seed)

    def fitted() -> tuple[float, float]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = fit_hammerstein_backlash(u[:N_EST], y[:N_EST], 2, 2, 3, initial_state="estimate")
        return fit.simulation_rmse / noise, bid.evaluate(fit.model, u[N_EST:], y[N_EST:], init_samples=100).simulation_rmse / noise

    est, val = fitted()
    assert est <= 1.3 and val <= 1.3, (est, val)
    monkeypatch.setattr(_fit, "_off_the_wall", lambda with_state, prob, fit, names: fit)
    assert fitted()[1] > 1.5  # on the wall: validation 3.5, 4.2, 3.0 noise stds (white 0, 2, low-pass 2)
