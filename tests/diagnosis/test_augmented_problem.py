"""The compiled refit problem of the diagnosis, ``_core.AugmentedProblem``: its simulation is
``_core.simulate_augmented``'s (rest and held starts), and its streamed factor carries the exact
Jacobian (R^T R = [J | r]^T [J | r] with J from central differences of the simulation) for
every effect of the catalogue."""

from __future__ import annotations

import numpy as np
import pytest

import backlashid as bid
from backlashid import _core
from backlashid.diagnosis.effects import REGISTRY
from backlashid.diagnosis.effects._base import TIME_SCALE, simulate
from backlashid.errors import DataError, ModelError
from backlashid.identify import Structure

STRUCTURE = Structure(2, 2, 3)
# Example 1 off its true values: an iterate of a refit
THETA = STRUCTURE.pack(bid.example1()) * (1.0 + 0.03 * (np.arange(11) % 3 - 1.0))

# every effect at a non-zero size, with the parameters the refit frees
CASES: list[tuple[list[tuple[str, list[float]]], list[str]]] = [
    ([], []),
    ([("saturation", [-0.9, 1.0])], ["lo", "hi"]),
    ([("friction", [0.05, 0.1])], ["F_c", "F_v"]),
    ([("width_drift", [0.3, -0.2])], ["dc_L", "dc_R"]),
    ([("compliance", [0.4, 0.6, 0.15])], ["k", "omega", "zeta"]),
    ([("hysteresis_memory", [0.2, 0.3, 0.5, -0.2])], ["r_1", "w_1", "r_2", "w_2"]),
    ([("output_offset", [0.1, 0.3])], ["o_0", "o_1"]),
    ([("dead_time", [2.0])], []),
    ([("quantization", [0.05])], []),
    # at zero size, where the refits start: derivatives of the limit
    ([("friction", [0.0, 0.0])], ["F_c", "F_v"]),
    ([("compliance", [0.0, 0.5, 0.1])], ["k", "omega", "zeta"]),
]


def record(n: int = 600) -> tuple[np.ndarray, np.ndarray]:
    """A slow triangle plus a rich random part, and a noisy output of Example 1."""
    rng = np.random.default_rng(5)
    k = np.arange(n)
    tri = 1.3 * (2.0 * np.abs(2.0 * ((k / 211.0) % 1.0) - 1.0) - 1.0)
    u = tri + 0.4 * rng.uniform(-1.0, 1.0, n)
    y = bid.example1().simulate(u) + 0.02 * rng.standard_normal(n)
    return u, y


def _names(effect: str) -> list[str]:
    """The effect's parameter names, as the catalogue has them."""
    return list(REGISTRY[effect].parameters)


def theta_of(effects: list[tuple[str, list[float]]], free: list[str]) -> np.ndarray:
    """THETA followed by the free parameters' given values."""
    given = {n: v for effect, params in effects for n, v in zip(_names(effect), params)}
    return np.concatenate([THETA, [given[f] for f in free]])


@pytest.mark.parametrize(("effects", "free"), CASES)
@pytest.mark.parametrize("held", [False, True])
def test_simulate_is_simulate_augmented(effects: list[tuple[str, list[float]]], free: list[str], held: bool) -> None:
    u, y = record()
    t0, y_prev = (700.0, 0.2) if held else (0.0, 0.0)
    prob = _core.AugmentedProblem(u, y, 2, 2, 3, effects, free, warmup=10, t0=t0, held=held, y_prev=y_prev)
    assert prob.names == STRUCTURE.names + free
    assert (prob.samples, prob.warmup) == (u.size, 10)
    theta = theta_of(effects, free)
    core = tuple((name, tuple(p)) for name, p in effects)
    want = simulate(STRUCTURE, THETA, core, u, t0, y_prev, held)
    got = prob.simulate(theta)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-13)
    assert prob.cost(theta) == pytest.approx(float(np.sum((y - got)[10:] ** 2)), rel=1e-12)
    # a different free value moves the simulation like the catalogue's parameters
    if free:
        moved = theta.copy()
        moved[-1] += 0.01
        changed = [(name, [moved[11 + free.index(n)] if n in free else v for n, v in zip(_names(name), p)]) for name, p in effects]
        want = _core.simulate_augmented(
            *STRUCTURE.unpack(THETA).chain(), u, effects=changed, t0=t0, time_scale=TIME_SCALE, **_held(u, held), y_prev=y_prev
        )
        np.testing.assert_allclose(prob.simulate(moved), want, rtol=0, atol=1e-13)


def _held(u: np.ndarray, held: bool) -> dict[str, list[float]]:
    """The pasts of the held start (``simulate(held=True)``)."""
    if not held:
        return {}
    est = STRUCTURE.unpack(THETA)
    x_eq = bid.LinearBlock(est.a, est.b).static_gain() * float(u[0])
    return {"u_past": [float(u[0])] * 2, "x_past": [x_eq] * 2}


def central_differences(prob: _core.AugmentedProblem, theta: np.ndarray) -> np.ndarray:
    """d y_sim / d theta by central differences of ``simulate``."""
    cols = []
    for j in range(theta.size):
        h = 1e-6 * max(abs(theta[j]), 0.1)
        plus, minus = theta.copy(), theta.copy()
        plus[j] += h
        minus[j] -= h
        cols.append((prob.simulate(plus) - prob.simulate(minus)) / (2 * h))
    return np.column_stack(cols)


@pytest.mark.parametrize(("effects", "free"), CASES)
def test_the_factor_carries_the_exact_jacobian(effects: list[tuple[str, list[float]]], free: list[str]) -> None:
    u, y = record()
    warmup = 10
    prob = _core.AugmentedProblem(u, y, 2, 2, 3, effects, free, warmup=warmup)
    theta = theta_of(effects, free)
    jac = central_differences(prob, theta)[warmup:]
    r = (y - prob.simulate(theta))[warmup:]
    aug = np.column_stack([jac, r])
    r_aug, cost = prob.oe_factor(theta)
    p = theta.size
    assert r_aug.shape == (p + 1, p + 1)
    assert np.allclose(np.tril(r_aug, -1), 0.0)
    gram = aug.T @ aug
    scale = np.max(np.abs(np.diag(gram)))
    np.testing.assert_allclose(r_aug.T @ r_aug, gram, rtol=0, atol=1e-6 * scale)
    assert cost == pytest.approx(float(r @ r), rel=1e-12)
    g, g_cost = prob.gradient(theta)
    np.testing.assert_allclose(g, jac.T @ r, rtol=0, atol=1e-6 * np.sqrt(scale * (r @ r)))
    assert g_cost == pytest.approx(cost, rel=1e-12)
    y_sim, exact = prob.sensitivity(theta)
    np.testing.assert_array_equal(y_sim, prob.simulate(theta))
    np.testing.assert_allclose(exact[warmup:], jac, rtol=0, atol=1e-6 * np.max(np.abs(jac)) + 1e-9)
    if effects and effects[0][0] == "quantization":
        assert not np.any(exact)  # round() is flat: the quantised output has no slope


def test_bounds_feasibility_and_refusals() -> None:
    u, y = record(200)
    prob = _core.AugmentedProblem(
        u, y, 2, 2, 3, [("compliance", [0.2, 0.5, 0.1]), ("hysteresis_memory", [0.1, 0.0])], ["omega", "r_1", "w_1"]
    )
    lower, upper = prob.bounds()
    assert lower == [-np.inf] * 4 + [0.0] + [-np.inf] * 3 + [0.0] + [-np.inf] * 2 + [0.0, 0.0, -np.inf]
    assert lower[:11] == _core.Problem(u, y, 2, 2, 3, 0, 0).bounds()[0]
    assert upper == [np.inf] * 11 + [np.pi, np.inf, np.inf]
    theta = np.concatenate([THETA, [0.5, 0.1, 0.0]])
    assert prob.feasible(theta)
    assert not prob.feasible(np.concatenate([THETA, [np.pi, 0.1, 0.0]]))  # omega on the open interval's edge
    unstable = theta.copy()
    unstable[2] = -2.5
    assert not prob.feasible(unstable)
    with pytest.raises(ModelError, match="outside the refit"):
        _core.AugmentedProblem(u, y, 2, 2, 3, [("dead_time", [1.0])], ["d"])
    with pytest.raises(ModelError, match="not a parameter"):
        _core.AugmentedProblem(u, y, 2, 2, 3, [("friction", [0.0, 0.0])], ["k"])
    with pytest.raises(DataError, match="warmup"):
        _core.AugmentedProblem(u, y, 2, 2, 3, warmup=200)
    for method in (prob.simulate, prob.feasible, prob.cost):
        with pytest.raises(DataError, match="theta has 11 parameters"):
            method(THETA)
    wild = _core.AugmentedProblem(np.resize(u, 2000), np.resize(y, 2000), 2, 2, 3, [("friction", [0.0, 0.0])], ["F_v"])
    with pytest.raises(ModelError, match="diverged"):
        wild.cost(np.concatenate([THETA, [-50.0]]))
