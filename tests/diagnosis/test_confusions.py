"""Issue 18's confusions of the diagnoser, each on a record made as the physics puts the effect
(not by the diagnoser's own augmentation): quantisation at the A/D converter (after the noise),
dead time against a higher linear order, friction in the drive's force balance, and a nominal
fit that fails."""

from __future__ import annotations

import math

import numpy as np
import pytest

import backlashid as bx
from backlashid.diagnosis.effects._quantization import lattice

N = 3000


def _plant_output(u: np.ndarray) -> np.ndarray:
    return bx.example1().simulate(u)


# -- quantisation at the A/D converter -----------------------------------------------------------


@pytest.mark.parametrize("q", [0.01, 0.07, 0.3])
def test_a_quantised_record_lies_on_its_lattice(q: float) -> None:
    rng = np.random.default_rng(1)
    y = _plant_output(rng.uniform(-1.5, 1.5, 2 * N)) + 0.02 * rng.standard_normal(2 * N)
    measured = q * np.round(y / q + 0.31)  # an offset lattice, rounded after the noise
    found = lattice(measured)
    assert found is not None and abs(found.q / q - 1.0) < 1e-9


@pytest.mark.parametrize("form", ["unrounded", "float32", "1e-6", "1e-4", "float32 offset"])
def test_continuous_records_have_no_lattice(form: str) -> None:
    rng = np.random.default_rng(2)
    for seed in range(5):
        y = _plant_output(np.random.default_rng(seed).uniform(-1.5, 1.5, 2 * N)) + 0.02 * rng.standard_normal(2 * N)
        y = {
            "unrounded": y,
            "float32": y.astype(np.float32).astype(np.float64),
            "1e-6": np.round(y, 6),
            "1e-4": np.round(y, 4),
            "float32 offset": (y + 3.0).astype(np.float32).astype(np.float64),
        }[form]
        assert lattice(y) is None


def test_quantisation_after_the_noise_is_named_with_its_step() -> None:
    """Main reported none or colored_noise: the rounding after the noise is white-like noise
    that no model of the noise-free output removes; the lattice of the values shows it."""
    rng = np.random.default_rng(3)
    u = rng.uniform(-1.5, 1.5, 2 * N)
    noise = 0.01
    q = np.sqrt(12.0) * 3.0 * noise  # ENR 3: the rounding error's RMS is 3 noise std
    y = q * np.round((_plant_output(u) + noise * rng.standard_normal(2 * N)) / q)
    est, val = (u[:N], y[:N]), (u[N:], y[N:])
    model = bx.fit_cascade(*est, 2, 2, 3, warmup=50).model
    report = bx.diagnose(model, est, val)
    assert report.best_effect == "quantization"
    assert abs(report.best.params["q"] / q - 1.0) < 0.05
    assert "lattice" in report.verdict() and "lattice" in report.to_dict()["details"]


def test_a_continuous_record_names_no_quantisation() -> None:
    rng = np.random.default_rng(4)
    u = rng.uniform(-1.5, 1.5, 2 * N)
    y = (_plant_output(u) + 0.03 * rng.standard_normal(2 * N)).astype(np.float32).astype(np.float64)
    est, val = (u[:N], y[:N]), (u[N:], y[N:])
    model = bx.fit_cascade(*est, 2, 2, 3, warmup=50).model
    report = bx.diagnose(model, est, val)
    assert report.best_effect == "none" and report.details.lattice == ""



# -- friction in the drive's force balance -------------------------------------------------------


def _drive_with_friction(u: np.ndarray, wn: float, zeta: float, f_c: float, f_s: float, v_s: float, f_v: float) -> np.ndarray:
    """A spring-returned drive, x'' = wn^2 (u - x) - 2 zeta wn x' - F(x'), with Coulomb,
    Stribeck and viscous friction F = (F_c + F_s exp(-(x'/v_s)^2)) sign(x') + F_v x' and
    Karnopp's stick rule (at rest while the force is below F_c + F_s; a velocity that would
    change sign stops), 20 Euler substeps per sample, u held over each: the physics, not the
    diagnoser's discrete model."""
    sub = 20
    dt = 1.0 / sub
    x = v = 0.0
    out = np.empty(u.size)
    for t, ut in enumerate(u.tolist()):
        for _ in range(sub):
            force = wn * wn * (ut - x) - 2.0 * zeta * wn * v
            if v == 0.0 and abs(force) <= f_c + f_s:
                acc = 0.0
            else:
                sign = math.copysign(1.0, v if v != 0.0 else force)
                acc = force - sign * (f_c + f_s * math.exp(-((v / v_s) ** 2))) - f_v * v
            v_new = v + dt * acc
            v = 0.0 if v != 0.0 and v_new * v < 0.0 else v_new
            x += dt * v
        out[t] = x
    return out


@pytest.mark.parametrize("seed", [0, 2])
def test_stick_slip_friction_in_the_force_balance_is_named_friction(seed: int) -> None:
    """Main named colored_noise or unexplained: its friction acts on the last step's velocity,
    a sample late, and never holds the drive. The stick-slip form (Karnopp's rule in the linear
    block's force balance, with a Stribeck dip) explains it."""
    rng = np.random.default_rng(seed)
    k = np.arange(2 * N)
    u = np.sin(2 * np.pi * k / rng.uniform(150, 300)) * (0.6 + 0.4 * np.sin(2 * np.pi * k / 1700)) + 0.15 * rng.standard_normal(2 * N)
    wn = 0.4
    x = _drive_with_friction(u, wn, 0.6, f_c=0.06 * wn * wn, f_s=0.04 * wn * wn, v_s=0.02, f_v=0.05)
    y = bx.example1().backlash.simulate(x) + 0.01 * rng.standard_normal(2 * N)
    est, val = (u[:N], y[:N]), (u[N:], y[N:])
    model = bx.fit_cascade(*est, 2, 2, 3, warmup=50).model
    report = bx.diagnose(model, est, val)
    assert report.best_effect == "friction"
    assert report.best.params["stick"] == 1.0 and report.best.n_extra == 4 and report.best.params["F_s"] > 0.0


# -- a nominal fit that fails --------------------------------------------------------------------


def _failed_fit() -> tuple[bx.NotConvergedError, np.ndarray, np.ndarray]:
    # a slow pole (0.98) and heavy noise: the paper's plain iterations end unstable
    truth = bx.CascadeModel(bx.LinearBlock([0.1], [-0.98]), bx.example1().backlash)
    d = bx.example_data(truth, 3000, snr=5, seed=0)
    with pytest.raises(bx.NotConvergedError, match="unstable") as info:
        bx.fit_cascade(d.u[:1500], d.noisy[:1500], na=1, nb=1, paper=True)
    return info.value, d.u, d.noisy


def test_a_failed_fit_carries_its_best_stable_iterate() -> None:
    import pickle

    exc, u, y = _failed_fit()
    stable = exc.best_stable
    assert exc.best is not None and (exc.best.model is None or exc.best.model.linear.spectral_radius() > 1.0)
    assert isinstance(stable, bx.FitResult) and not stable.converged
    assert stable.model.linear.spectral_radius() < 1.0 and np.isfinite(stable.simulation_rmse)
    assert stable.simulation_rmse <= exc.best.history_rmse[np.isfinite(exc.best.history_rmse)].min()
    assert pickle.loads(pickle.dumps(exc)).best_stable.parameters == stable.parameters


def test_a_failed_fit_is_diagnosed_from_its_best_iterate_saying_so() -> None:
    exc, u, y = _failed_fit()
    report = bx.diagnose(exc.best_stable.model, (u[:1500], y[:1500]), (u[1500:], y[1500:]), nominal_converged=False)
    assert "nominal fit did not converge; diagnosed from its best iterate" in report.verdict()
    assert report.to_dict()["details"]["nominal_fit"] == "nominal fit did not converge; diagnosed from its best iterate"
    assert "did not converge" not in bx.diagnose(exc.best_stable.model, (u[:1500], y[:1500]), (u[1500:], y[1500:])).verdict()



# -- dead time against a higher linear order -----------------------------------------------------


def test_dead_time_is_named_over_a_higher_order_on_the_same_footing() -> None:
    """A dead time of 2 samples on a plant with a slow pole: an extra lag imitates the delay,
    and both refits close most of the gap; the dead-time refit reaches the optimum a refit from
    the truth reaches, and the rule prefers the lower BIC with honest counting (d one integer
    parameter, the order increase its two coefficients)."""
    from backlashid.diagnosis.effects import REGISTRY, _base
    from backlashid.identify import Structure

    truth = bx.CascadeModel(bx.LinearBlock([0.12], [-0.9]), bx.example1().backlash)
    rng = np.random.default_rng(5)
    u = np.convolve(rng.standard_normal(2 * N), [1.0, 0.6, 0.3])[: 2 * N]
    y = truth.simulate(np.r_[0.0, 0.0, u[:-2]]) + 0.02 * rng.standard_normal(2 * N)
    model = bx.fit_cascade(u[:N], y[:N], 1, 1, 3, warmup=50).model
    s = Structure(1, 1, 3)
    prob = _base.RefitRecords(s, u[:N], y[:N], 50, 0.0)
    theta, params, cost = REGISTRY["dead_time"].refit(prob, s.pack(model))
    _, _, from_truth = REGISTRY["dead_time"]._refit(prob, s.pack(truth), np.zeros(0), np.zeros(0), np.zeros(0), {"d": 2})
    assert params == {"d": 2} and cost <= from_truth * (1 + 1e-6)
    report = bx.diagnose(model, (u[:N], y[:N]), (u[N:], y[N:]), candidates=["dead_time", "linear_order", "friction"])
    assert report.best_effect == "dead_time" and report.best.params["d"] == 2
    order = next(c for c in report.ranking if c.effect == "linear_order")
    assert report.best.criterion < order.criterion and report.best.n_extra == 1 and order.n_extra == 2


# -- a position-dependent residual is not noise ---------------------------------------------------


def _records_with(extra: str, seed: int) -> tuple[bx.CascadeModel, np.ndarray, np.ndarray]:
    m = bx.example1()
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1.5, 1.5, 2 * N)
    clean = m.simulate(u)
    y = clean + 0.02 * rng.standard_normal(2 * N)
    if extra == "cogging":  # a torque ripple periodic in the position: out of the catalogue
        y = y + 0.04 * np.sin(2 * np.pi * clean / 0.15)
    else:  # AR(1) sensor noise, independent of the position
        w = 0.03 * rng.standard_normal(2 * N)
        v = np.zeros(2 * N)
        for t in range(1, 2 * N):
            v[t] = 0.9 * v[t - 1] + w[t]
        y = y + v
    return m, u, y


def test_a_residual_that_depends_on_the_position_is_not_named_colored_noise() -> None:
    m, u, y = _records_with("cogging", 7)
    report = bx.diagnose(m, (u[:N], y[:N]), (u[N:], y[N:]))
    assert report.best_effect == "unexplained"
    assert report.details.position_p_value < 1e-10
    assert any("position" in why for why in report.details.colored_noise_ruled_out)


def test_colored_noise_does_not_depend_on_the_position() -> None:
    m, u, y = _records_with("ar", 7)
    report = bx.diagnose(m, (u[:N], y[:N]), (u[N:], y[N:]))
    assert report.best_effect == "colored_noise"
    assert report.details.position_p_value > report.details.significance_level
