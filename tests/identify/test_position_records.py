"""Records that start mid-motion, and the output block's local minimum of a sandwich.

A drive whose output is a position integrates: no input holds it at rest, so a record starts
mid-motion and a model started from rest sits at the wrong place for good. With
``initial_state="estimate"`` the fit must judge its models (valid branches, motion) and search
its starts from the record's estimated start, not from rest.

The records come from a generator of their own (the velocity drive and the position's
integrator by scipy's lfilter, the play by a per-sample loop over the paper's eq 1), not from
the package's models."""

from __future__ import annotations

import contextlib
import dataclasses
import warnings

import numpy as np
import pytest
from scipy import signal

import backlashid as bid
from backlashid.errors import BacklashIdError
from backlashid.identify import Structure, _starts, fit_hammerstein_backlash
from backlashid.identify._valid import record_motion, why_not_acceptable
from conftest import load_bench

PRE, N_EST, N_VAL = 500, 3000, 3000  # samples run before the record starts; estimation; validation
C_L, C_R = 0.3, 0.5
M_L, M_R = [1.0, 0.0, 0.01], [1.0, 0.0, 0.015]  # cubic branches, increasing everywhere


def _poly(m: list[float], s: np.ndarray) -> np.ndarray:
    return sum(c * s ** (i + 1) for i, c in enumerate(m))


def _play(x: np.ndarray) -> np.ndarray:
    left, right = _poly(M_L, x + C_L).tolist(), _poly(M_R, x - C_R).tolist()
    y, prev = np.empty_like(x), 0.0
    for t, (lo, hi) in enumerate(zip(left, right)):
        prev = lo if lo <= prev else hi if hi >= prev else prev  # eq (1): left, right, else hold
        y[t] = prev
    return y


def _input(kind: str, rng: np.random.Generator, n: int) -> np.ndarray:
    if kind == "white":
        return rng.standard_normal(n)
    levels = rng.uniform(-1.5, 1.5, n // 150 + 1)  # a velocity command held for 150 samples
    return np.repeat(levels, 150)[:n]


def _position_record(kind: str, seed: int, tau: float = 6.0, noise: float = 0.02) -> tuple[np.ndarray, np.ndarray, float]:
    """A velocity-controlled motor (v' = (u - v) / tau, x' = v, zero-order hold) -> play -> y,
    the record cut PRE samples into the run, its mean position near 0; the noise std."""
    rng = np.random.default_rng(seed)
    u = _input(kind, rng, PRE + N_EST + N_VAL)
    p = np.exp(-1.0 / tau)
    # x(k) = x(k-1) + v(k-1), v(k) = p v(k-1) + (1 - p) u(k-1): x / u = (1 - p) z^-2 / ((1 - z^-1)(1 - p z^-1))
    x = signal.lfilter([0.0, 0.0, 1.0 - p], np.polymul([1.0, -1.0], [1.0, -p]), u)
    x = 2.0 * (x - np.mean(x[PRE:])) / np.std(x[PRE:])  # the drive's gain: x spans a few dead bands
    y = _play(x)[PRE:] + noise * rng.standard_normal(N_EST + N_VAL)
    return u[PRE:], y, noise


@pytest.mark.parametrize("kind, seed", [("white", 3), ("steps", 1), ("steps", 5)])
def test_a_position_record_started_mid_motion_is_fitted_to_the_noise(kind, seed):
    # records the fit missed by 4.8 to 570 noise stds when it judged and started from rest; not
    # every record of this generator is fitted to the noise (of 18 white, steps and low-pass
    # records, 5 reach 1.4 noise stds, 0 before): position records remain issue 31's weak spot
    u, y, noise = _position_record(kind, seed)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fit = bid.fit_cascade(u[:N_EST], y[:N_EST], 2, 2, degree=3, initial_state="estimate", valid=True, warmup=20)
    fell_back = [str(w.message) for w in caught if "the best fit of degree" in str(w.message)]
    assert not fell_back, fell_back
    assert fit.converged, fit.reason
    val = bid.evaluate(fit.model, u[N_EST:], y[N_EST:], init_samples=100).simulation_rmse
    assert val <= 1.3 * noise, (val / noise, fit.summary())


def test_the_fit_judges_a_position_record_from_its_estimated_start():
    # from rest, the right model's x runs outside the range the record visits (the record
    # starts mid-motion), where its cubic branches cross: a check from rest refuses it
    u, y = _position_record("white", 3)[:2]
    u, y = u[:N_EST], y[:N_EST]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = bid.fit_cascade(u, y, 2, 2, degree=3, initial_state="estimate", valid=True, warmup=20)
    s = fit.structure
    from_rest = why_not_acceptable(s, s.problem(u, y, 20), fit.theta, u, 20, 0.02, True)
    assert from_rest is not None and "cross" in from_rest
    # the moving fraction reported is the one from the record's estimated start
    with_state = dataclasses.replace(s, initial_state=True)
    theta = np.r_[fit.theta, list(fit.initial_state.values())]
    moving, _ = record_motion(with_state, with_state.problem(u, y, 20), theta, u, 20)
    assert fit.moving_fraction == pytest.approx(moving, rel=1e-12)
    assert abs(moving - record_motion(s, s.problem(u, y, 20), fit.theta, u, 20)[0]) > 0.02


def test_a_sandwich_fit_leaves_the_swapped_dynamics_of_its_blocks():
    # the independent chains benchmark's two-mass drive (tune seed, 'none', index 17): the fit
    # gave the input block the load's slow resonant poles and stopped there (3.1 noise stds on
    # validation); the output block's pole restarts leave that minimum
    ic = load_bench("independent_chains")
    case = ic.make_case("sandwich:none", 0.0, 17, "tune")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = ic.fit_nominal(case)
    y_sim = np.asarray(fit.model.simulate(case.u))
    val = np.sqrt(np.mean((case.y - y_sim)[ic.N_EST :] ** 2))
    assert val <= 1.1 * case.noise_std, val / case.noise_std


def test_output_pole_restarts_need_a_sandwich():
    u, y, _ = _position_record("steps", 1)
    s = Structure(2, 2, 3)
    assert _starts.output_pole_restarts(s, s.problem(u, y), np.r_[0.1, 0.1, -1.5, 0.55, 0.3, 0.0, 0.01, 1.0, 0.5, 0.0, 0.015]) == []


def test_a_dead_band_at_its_bound_is_held_in_the_covariance():
    # an estimate with c_L = 0 on its bound: the factor's c_L column says nothing two-sided;
    # the others' covariance is computed with it held there, its own variance is NaN
    from backlashid.errors import NotIdentifiableError
    from backlashid.identify._fit import _model_covariance

    rng = np.random.default_rng(0)
    block = np.triu(rng.standard_normal((4, 4))) + 3 * np.eye(4)
    block[:, 1] = 0.0  # c_L's column
    names = ["a1", "c_L", "c_R", "m_R1"]
    cov = _model_covariance(block, np.array([0.5, 0.0, 0.2, 1.0]), names)
    free = [0, 2, 3]
    assert np.all(np.isnan(cov[1])) and np.all(np.isnan(cov[:, 1]))
    expected = np.linalg.inv(block[:, free].T @ block[:, free])
    assert np.allclose(cov[np.ix_(free, free)], expected, rtol=1e-10)
    with pytest.raises(NotIdentifiableError):  # the same column with c_L off its bound: no covariance
        _model_covariance(block, np.array([0.5, 0.1, 0.2, 1.0]), names)


@pytest.mark.parametrize("kind, seed", [("white", 3), ("steps", 1)])
def test_the_search_with_the_state_on_the_head_of_a_long_record(monkeypatch, kind, seed):
    # on a record longer than STATE_SEARCH_SAMPLES the search with the state runs on its head;
    # its best trial, refined on the whole record, replaces the estimate only where it is
    # cheaper there: never worse than no search, and better where the head finds the basin
    from backlashid.identify import _fit

    u, y, noise = _position_record(kind, seed)
    u, y = u[:N_EST], y[:N_EST]

    def fitted() -> bid.FitResult:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return bid.fit_cascade(u, y, 2, 2, degree=3, initial_state="estimate", valid=True, warmup=20)

    monkeypatch.setattr(_fit, "STATE_SEARCH_SAMPLES", 1500)
    # the stage after it held off: from the wall it takes both fits to the noise on white 3
    monkeypatch.setattr(_fit, "_off_the_wall", lambda with_state, prob, fit, names: fit)
    with_head = fitted()
    monkeypatch.setattr(_fit, "_searched_with_state", lambda *args: args[6])  # no search with the state
    without = fitted()
    assert with_head.simulation_rmse <= without.simulation_rmse * (1 + 1e-9)
    if kind == "white":  # this record's head holds the right basin
        assert with_head.simulation_rmse <= 1.3 * noise < without.simulation_rmse


def _load_position_record(kind: str, seed: int, tau: float = 8.0, noise: float = 0.02) -> tuple[np.ndarray, np.ndarray, float]:
    """A position-controlled motor x(t) = u(t-1) -> play -> a load whose velocity lags the
    play's output (v' = (p - v) / tau, zero-order hold) and whose POSITION y is measured: the
    integrator after the play (an input backlash before a load that integrates). The command
    is centred, not the play's output, so the position also drifts with the play's asymmetry."""
    rng = np.random.default_rng(seed)
    n = PRE + N_EST + N_VAL
    u = signal.lfilter([1.0], [1.0, -0.97], rng.standard_normal(n)) if kind == "lowpass" else _input(kind, rng, n)
    u = 2.0 * (u - np.mean(u)) / np.std(u)
    p = np.exp(-1.0 / tau)
    # y(k) = y(k-1) + v(k-1), v(k) = p v(k-1) + (1 - p) P(k-1)
    y = signal.lfilter([0.0, 1.0 - p], np.polymul([1.0, -1.0], [1.0, -p]), _play(np.r_[0.0, u[:-1]]))[PRE:]
    return u[PRE:], y - np.mean(y) + noise * rng.standard_normal(y.size), noise


@pytest.mark.parametrize("kind, seed", [("lowpass", 1), ("lowpass", 2), ("white", 3)])
def test_a_load_position_after_an_input_backlash_is_fitted_to_the_noise(kind, seed):
    # the integrator sits after the play: every start whose load block is a little off drifts
    # over the record, and these fits ended 600-1900 noise stds off (or raised); the fit of the
    # position's one-sample changes starts the search. Not every record is reached: of 12
    # low-pass, white and step records, 9 fit the estimation record within 1.8 noise stds, and
    # low-pass seed 0 and steps seed 3 still miss by 200-300. White seed 3 with the multiple
    # shooting (2026-11-29): estimation 1.18 noise stds (1.22 before), validation 2.75 (2.15):
    # a lower optimum of the criterion that validates worse on this record
    u, y, noise = _load_position_record(kind, seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = fit_hammerstein_backlash(u[:N_EST], y[:N_EST], 2, 2, 3, initial_state="estimate")
    est = bid.evaluate(fit.model, u[:N_EST], y[:N_EST], init_samples=100).simulation_rmse
    val = bid.evaluate(fit.model, u[N_EST:], y[N_EST:], init_samples=100).simulation_rmse
    assert est <= 1.5 * noise and val <= 3 * noise, (est / noise, val / noise)


def test_each_derived_fit_runs_once_per_record_searched(monkeypatch):
    # the state's refinement may run twice or more in one fit (kept among the valid models,
    # from the optimum): each fit of a derived record runs once, and only where its block has
    # a pole to give back: the output's changes for a sandwich's output block (none in a
    # cascade), the input's sums for an input block with poles (none in the input backlash's
    # one-sample delay)
    from backlashid.identify import _fit

    calls = []
    original = _fit._derived_fit
    monkeypatch.setattr(_fit, "_derived_fit", lambda setup, s, u, y, warmup: calls.append((s.nb, s.ns, len(y))) or original(setup, s, u, y, warmup))
    u, y, _ = _load_position_record("lowpass", 1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit_hammerstein_backlash(u[:N_EST], y[:N_EST], 2, 2, 3, initial_state="estimate", valid=True)
        assert calls == [(0, 1, N_EST - 1)] * 2  # the output's changes, raw and smoothed: one output pole fewer
        calls.clear()
        bid.fit_cascade(u[:N_EST], y[:N_EST], 2, 2, degree=3, initial_state="estimate")
    assert calls == [(1, 0, N_EST)]  # the input's sums: one input pole fewer


def test_a_noisy_load_position_is_started_from_its_smoothed_changes(monkeypatch):
    # five times the noise of the records above: the position's one-sample changes are
    # mostly noise, and the search from their fit ended 3.5 noise stds off (validation 11.2);
    # from the fit of the low-passed position's changes, at the noise (1.01; validation 1.39)
    from backlashid.identify import _fit

    u, y, noise = _load_position_record("lowpass", 0, noise=0.1)

    def fitted() -> tuple[float, float]:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = fit_hammerstein_backlash(u[:N_EST], y[:N_EST], 2, 2, 3, initial_state="estimate", warmup=20)
        val = bid.evaluate(fit.model, u[N_EST:], y[N_EST:], init_samples=100).simulation_rmse
        return fit.simulation_rmse / noise, val / noise

    est, val = fitted()
    assert est <= 1.1 and val <= 1.5, (est, val)
    monkeypatch.setattr(_fit, "_smoothed_velocity_model", lambda *args: None)
    assert fitted()[0] > 2.0


@pytest.mark.parametrize("kind, seed", [("lowpass", 1), ("white", 3)])
def test_a_load_position_after_a_warm_up_is_fitted_to_the_noise(kind, seed):
    # select_structure's setting warmup=20: the start from the output's changes had its state
    # fitted where it reaches the cost through the play only (the white record ended 50 noise
    # stds off), and on the low-pass record every LM from rest diverged and no search with the
    # state ran (18936 noise stds, reason 'diverged')
    u, y, noise = _load_position_record(kind, seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = fit_hammerstein_backlash(u[:N_EST], y[:N_EST], 2, 2, 3, initial_state="estimate", warmup=20)
    assert fit.converged and fit.reason != "diverged", fit.reason
    assert fit.simulation_rmse <= 1.3 * noise, fit.simulation_rmse / noise
    val = bid.evaluate(fit.model, u[N_EST:], y[N_EST:], init_samples=100).simulation_rmse
    # white 3 with the integrator held off the guard's wall (2026-11-29): estimation 0.993
    # noise stds (1.001 on the wall), validation 1.51 (1.20); from 1000 samples 1.22 (1.05)
    assert val <= 1.6 * noise, val / noise


def test_the_selection_judges_its_tail_from_the_state_each_fit_estimated():
    # the held-out tail simulated from the fit's own start (estimated over the whole head)
    # continues the fit's simulation of the head exactly; from the first samples it would not
    from backlashid.identify import _selection

    u, y, noise = _load_position_record("white", 3)
    u, y = u[:N_EST], y[:N_EST]
    head = 2100
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        fit = fit_hammerstein_backlash(u[:head], y[:head], 2, 2, 3, initial_state="estimate", warmup=20)
    simulated = _selection._simulated(fit.model, u, y, 20, fit)
    on_head = np.sqrt(np.mean((y - simulated)[20:head] ** 2))
    assert on_head == pytest.approx(fit.simulation_rmse, rel=1e-6)
    tail = np.sqrt(np.mean((y - simulated)[head:] ** 2))
    assert tail <= 1.5 * noise, tail / noise


def test_a_refit_on_the_whole_record_also_searches_from_the_heads_estimate(monkeypatch):
    # select_structure refits its choice on the whole record; from scratch that fit can land
    # in another basin than the head's (a structure_classes record: 1.25 -> 2.84 noise stds
    # on validation). The head's estimate (model and state) is one of the refit's starts, so
    # the refit is never worse than LM from it on the whole record
    from backlashid.identify import _fit
    from backlashid.identify._fit import refit_with_estimate

    u, y, noise = _load_position_record("white", 3)
    u, y = u[:N_EST], y[:N_EST]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        head = fit_hammerstein_backlash(u[:2100], y[:2100], 2, 2, 3, initial_state="estimate", warmup=20, valid=True)
        starts, ends = [], []
        original = _fit._state_first_then_all
        monkeypatch.setattr(_fit, "_state_first_then_all", lambda prob, theta, p0: starts.append(theta) or ends.append(original(prob, theta, p0)) or ends[-1])
        whole = refit_with_estimate(head, u, y, warmup=20, initial_state="estimate", valid=True)
        # the helper also starts the velocity trials: the head's estimate is one of its starts
        k = next(i for i, theta in enumerate(starts) if np.array_equal(theta[: head.structure.size], head.theta))
        assert ends[k] is not None and whole.converged
        assert whole.simulation_rmse**2 * ends[k].n_residuals <= ends[k].cost * (1 + 1e-9)
        assert whole.simulation_rmse <= 1.3 * noise
        starts.clear()
        with contextlib.suppress(BacklashIdError):  # from rest a position record may fail; no state to start from
            refit_with_estimate(head, u, y, warmup=20, valid=True)
    assert starts == []


@pytest.mark.parametrize("family, index", [("integrating", 3), ("sandwich_position", 0)])
def test_a_motor_position_before_the_play_is_fitted_from_the_input_sums(monkeypatch, family, index):
    # structure_classes' velocity-commanded motors (the integrator in the input block, before
    # the play; slow ramps, white noise), first seeds: the fits ended 15.7 and 6.7 noise stds
    # off on estimation. The fit of the input's sums (one input pole fewer), the integrator
    # put back, starts the search with the state
    from backlashid.identify import _fit

    sc = load_bench("structure_classes")
    rec = sc.make_record(family, index, "first")
    n, noise = sc.ic.N_EST, rec["sigma"]
    u, y = rec["u"], rec["y"]

    def fitted() -> bid.FitResult:
        options = dict(initial_state="estimate", warmup=20, valid=True)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            if family == "integrating":
                return bid.fit_cascade(u[:n], y[:n], 2, 2, degree=3, **options)
            return bid.fit_sandwich(u[:n], y[:n], 2, 2, 2, 2, 3, **options)

    fit = fitted()
    val = bid.evaluate(fit.model, u[n:], y[n:], init_samples=100).simulation_rmse
    assert fit.simulation_rmse <= 1.2 * noise and val <= 1.2 * noise, (fit.simulation_rmse / noise, val / noise)
    # the start reaches it without the multiple shooting (which alone also does on the sandwich)
    monkeypatch.setattr(_fit, "_multiple_shooting", lambda with_state, prob, u, y, warmup, fit, names: fit)
    assert fitted().simulation_rmse <= 1.2 * noise
    monkeypatch.setattr(_fit, "_summed_input_model", lambda *args: None)
    assert fitted().simulation_rmse > 3 * noise  # and without either the search does not
