"""The initial state as parameters of the compiled problem (``_core.Problem(...,
initial_state=True)``): the core's names at the end of theta, a simulation from the state of
a cut record continues the longer record it was cut from, and an output-error refinement that
estimates the state recovers a record cut mid-motion far better than one that assumes rest."""

from __future__ import annotations

import numpy as np
import pytest

import backlashid as bid
from backlashid import CascadeModel, SandwichModel, _core
from backlashid.identify import Structure, levenberg_marquardt


def _terms(a: np.ndarray, b: np.ndarray, u_past: tuple, x_past: tuple) -> list[float]:
    """x0_k = sum_{i>=k} a_i u(k-i) - sum_{j>=k} b_j x(k-j), k = 1..max(na, nb): the core's
    parametrisation of a block's past (rust/core/src/identify/initial.rs)."""
    n = max(len(a), len(b))
    return [
        sum(a[i - 1] * u_past[i - k] for i in range(k, len(a) + 1))
        - sum(b[j - 1] * x_past[j - k] for j in range(k, len(b) + 1))
        for k in range(1, n + 1)
    ]


def _cut(model: CascadeModel | SandwichModel, n: int, cut: int, seed: int):
    """A record of n samples cut from a longer one after `cut` samples (the system mid-motion),
    its clean output, and the true parameters with the state at the cut."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1.0, 1.0, cut + n)
    structure = _structure(model, initial_state=True)
    theta = structure.pack(model)
    p0 = structure.model_size
    if isinstance(model, SandwichModel):
        st = model.simulate(u[:cut], internals=True).final_state
        lin, out = model.input_linear, model.output_linear
        state = [
            *_terms(lin.a, lin.b, st.u_past, st.x_past),
            st.y_past[0],
            *_terms(out.a, out.b, st.y_past, st.w_past),
        ]
    else:
        st = model.simulate(u[:cut], internals=True).final_state
        state = [*_terms(model.linear.a, model.linear.b, st.u_past, st.x_past), st.y_prev]
    theta[p0:] = state
    clean = model.simulate(u)[cut:]
    return u[cut:], clean, theta


def _structure(model: CascadeModel | SandwichModel, initial_state: bool) -> Structure:
    if isinstance(model, SandwichModel):
        return Structure(2, 2, 3, 2, 2, initial_state=initial_state)
    return Structure(2, 2, 3, initial_state=initial_state)


def test_the_initial_state_ends_theta_under_the_cores_names():
    s = Structure(2, 2, 3, 2, 2, initial_state=True)
    assert s.names[14:] == ["x0_1", "x0_2", "y_prev", "w0_1", "w0_2"]
    assert (s.size, s.model_size) == (19, 14)
    assert s.ls_names == Structure(2, 2, 3, 2, 2).ls_names  # the paper's iteration has no state
    assert _core.Problem.layout(1, 3, 1, 0, 0, initial_state=True)[-4:] == ["x0_1", "x0_2", "x0_3", "y_prev"]
    theta = s.pack(bid.example2())
    assert theta[14:].tolist() == [0.0] * 5  # rest
    assert s.initial(theta) == ([0.0, 0.0], 0.0, [0.0, 0.0])
    assert s.model(theta) == Structure(2, 2, 3, 2, 2).model(theta[:14])
    assert "initial state" in str(s)
    u = np.sin(0.3 * np.arange(100))
    prob = s.problem(u, u)
    assert prob.initial_state and prob.names == s.names
    lower, upper = prob.bounds()  # the state is free
    assert lower[14:] == [-np.inf] * 5 and upper[14:] == [np.inf] * 5
    assert not Structure(2, 2, 3).problem(u, u).initial_state


@pytest.mark.parametrize("model", [bid.example1(), bid.example2()], ids=["cascade", "sandwich"])
def test_a_simulation_from_the_state_at_a_cut_continues_the_longer_record(model):
    u, clean, theta = _cut(model, 400, 317, seed=1)
    s = _structure(model, initial_state=True)
    prob = s.problem(u, clean)
    np.testing.assert_allclose(prob.simulate(theta), clean, rtol=0, atol=1e-12)
    assert prob.gradient(theta)[1] < 1e-24
    # from rest the first samples are wrong
    rest = _structure(model, False).problem(u, clean)
    assert abs(rest.simulate(theta[: s.model_size])[1] - clean[1]) > 1e-3


def _standard_errors(fit, n: int) -> np.ndarray:
    """The linearised standard errors of a refinement (inf for a column that is zero at the
    estimate: y_prev once the record starts moving, a state value masked by a hold)."""
    r = fit.r_aug[:-1, :-1]
    keep = np.linalg.norm(r, axis=0) > 0
    cov = np.linalg.inv(r[:, keep].T @ r[:, keep]) * fit.cost / (n - int(keep.sum()))
    se = np.full(len(keep), np.inf)
    se[keep] = np.sqrt(np.diag(cov))
    return se


@pytest.mark.parametrize("model", [bid.example1(), bid.example2()], ids=["cascade", "sandwich"])
def test_refinement_with_the_initial_state_recovers_records_cut_mid_motion(model):
    """Six records of 300 samples cut from longer ones, noise std(y) / 200, each refined from
    the same start (the truth off by 3 %) from rest and with the initial state. From rest the
    first samples cannot be fitted (cost hundreds of times the noise's) and the estimates are
    biased; with the state the cost is the noise's, every parameter is within 4 standard
    errors and the errors are several times smaller. The state starts at zero, with the
    cascade's y_prev at the first measured output (y(1) = y_prev when the record starts
    holding): from zero a record that starts holding can end in a local minimum, holding at
    y_prev with x0 masked by the hold (the fits' starts for the state are issue 17's)."""
    s_init, s_rest = _structure(model, True), _structure(model, False)
    p0 = s_init.model_size
    errors_rest, errors_init = [], []
    for seed, cut in [(7, 150), (5, 211), (1, 317), (2, 100), (3, 400), (4, 123)]:
        u, clean, theta = _cut(model, 300, cut, seed=seed)
        noise = np.random.default_rng(6).standard_normal(len(u)) * np.std(clean) / 200
        y = clean + noise
        truth = theta[:p0]
        start = truth * (1.0 + 0.03 * np.resize([-1.0, 0.0, 1.0], p0))
        state = np.zeros(s_init.size - p0)
        if isinstance(model, CascadeModel):
            state[-1] = y[0]
        rest = levenberg_marquardt(s_rest.problem(u, y), start)
        init = levenberg_marquardt(s_init.problem(u, y), np.r_[start, state])
        assert rest.converged and init.converged
        energy = float(noise @ noise)
        assert init.cost < 1.5 * energy < 20.0 * energy < rest.cost, (cut, init.cost, rest.cost, energy)
        z = np.abs(init.theta[:p0] - truth) / _standard_errors(init, len(u))[:p0]
        assert np.all(z < 4.0), (cut, dict(zip(s_init.names, z.round(1))))
        errors_rest.append(np.max(np.abs(rest.theta - truth)))
        errors_init.append(np.max(np.abs(init.theta[:p0] - truth)))
    assert np.mean(errors_init) < np.mean(errors_rest) / 3.0, (errors_init, errors_rest)
    assert max(errors_init) < 0.025, errors_init
