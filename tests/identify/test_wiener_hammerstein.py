"""Wiener-Hammerstein identification (issue 6): a sandwich with a tied, zero-width backlash."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

import backlashid as bid
from backlashid import DataError, SandwichModel, fit_wiener_hammerstein, wiener_hammerstein_model
from conftest import SHARED_DATA

DATA = SHARED_DATA / "wiener_hammerstein_2009" / "wh2009.npz"

# planted system: G1 and G2 of order 2, f(x) = x + 0.4 x^2 - 0.3 x^3 (monotone on the range used)
A, B = [0.3, 0.15], [-1.1, 0.4]
M = [1.0, 0.4, -0.3]
R, S = [0.5, -0.1], [-0.6, 0.25]


def planted() -> SandwichModel:
    return wiener_hammerstein_model(A, B, M, R, S)


def test_tied_zero_width_sandwich_is_the_static_map_between_two_filters():
    """eq (1) with L = R and c_L = c_R = 0 gives y(t) = f(x(t)), even where f turns down."""
    m = [1.0, 0.0, -2.0]  # f turns down for |x| > 0.41: no backlash could hold there
    model = wiener_hammerstein_model(A, B, m, R, S)
    u = np.random.default_rng(1).normal(0.0, 1.0, 3000)
    sim = model.simulate(u, internals=True)
    x = lfilter([0.0, *A], [1.0, *B], u)
    f = x * m[0] + x**2 * m[1] + x**3 * m[2]
    w = lfilter([0.0, *R], [1.0, *S], f)
    assert np.max(np.abs(x)) > 1.0  # the turning part is visited
    np.testing.assert_allclose(sim.x, x, atol=1e-12)
    np.testing.assert_allclose(sim.y, f, atol=1e-12)
    np.testing.assert_allclose(sim.output, w, atol=1e-12)
    again = SandwichModel.from_json(model.to_json())
    np.testing.assert_array_equal(again.simulate(u), sim.output)


def test_recovers_a_planted_wiener_hammerstein_system():
    rng = np.random.default_rng(0)
    u = rng.normal(0.0, 0.5, 6000)
    w = planted().simulate(u)
    fit = fit_wiener_hammerstein(u, w, nb=2, ns=2, degree=3, warmup=50)
    # G1 and G2 are identified up to gains (and x's sign): compare poles, zeros and the output
    for est, true in ((fit.model.input_linear, B), (fit.model.output_linear, S)):
        np.testing.assert_allclose(np.sort_complex(est.poles()), np.sort_complex(np.roots([1.0, *true])), atol=1e-6)
    assert fit.simulation_rmse < 1e-7 * np.std(w)
    u_val = rng.normal(0.0, 0.5, 3000)
    w_val = planted().simulate(u_val)
    assert np.sqrt(np.mean((fit.model.simulate(u_val) - w_val) ** 2)) < 1e-7 * np.std(w_val)
    # f up to the gains: x' = k x (G1 times k), y' = g y (G2 divided by g) give m'_i = g m_i / k^i
    k = fit.model.input_linear.a[0] / A[0]
    g = R[0] / fit.model.output_linear.a[0]
    recovered = fit.m * k ** np.arange(1, 4) / g
    np.testing.assert_allclose(recovered, M, rtol=1e-5)
    assert fit.baseline_rmse > 10 * fit.simulation_rmse


def test_recovers_a_planted_wiener_hammerstein_system_with_feedthrough():
    truth = wiener_hammerstein_model([0.2, 0.3, 0.15], B, M, [0.4, 0.5, -0.1], S, feedthrough=True)
    rng = np.random.default_rng(1)
    u = rng.normal(0.0, 0.5, 6000)
    w = truth.simulate(u)
    fit = fit_wiener_hammerstein(u, w, nb=2, ns=2, degree=3, warmup=50, feedthrough=True)
    assert fit.model.input_linear.feedthrough and fit.model.output_linear.feedthrough
    assert {"a0", "r0"} <= set(fit.parameters)
    u_val = rng.normal(0.0, 0.5, 3000)
    w_val = truth.simulate(u_val)
    assert np.sqrt(np.mean((fit.model.simulate(u_val) - w_val) ** 2)) < 1e-7 * np.std(w_val)
    k = fit.model.input_linear.a[0] / 0.2
    np.testing.assert_allclose(fit.model.input_linear.a / k, [0.2, 0.3, 0.15], rtol=1e-6)


@pytest.mark.skipif(not DATA.exists(), reason="the SYSID 2009 Wiener-Hammerstein data are not in shared/data")
def test_benchmark_slice_beats_the_linear_baseline_tenfold():
    """20 000 training samples, degree 8: the WH model's free-run test error is at least 10x
    below the linear baseline's (about 43 mV) on the standard test split."""
    d = np.load(DATA)
    u, y = d["u"], d["y"]
    start = int(d["train_start"])
    test = slice(int(d["test_start"]), int(d["test_stop"]))
    n_init = int(d["test_n_init"])
    fit = fit_wiener_hammerstein(u[start : start + 20_000], y[start : start + 20_000], degree=8, max_iter=60)
    wh = np.sqrt(np.mean((fit.simulate(u[test]) - y[test])[n_init:] ** 2))
    linear = np.sqrt(np.mean((fit.baseline.simulate(u[test]) - y[test])[n_init:] ** 2))
    assert 0.030 < linear < 0.060
    assert wh < linear / 10, (wh, linear)
    assert fit.model.input_linear.is_stable() and fit.model.output_linear.is_stable()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"degree": 0}, "degree"),
        ({"ns": 0}, "ns"),
        ({"nb": 2.5}, "nb"),
        ({"warmup": 5000}, "warmup"),
        ({"degree": 400}, "samples"),
    ],
)
def test_bad_settings_raise_data_error(kwargs, match):
    u = np.random.default_rng(0).normal(size=2000)
    with pytest.raises(DataError, match=match):
        fit_wiener_hammerstein(u, u.copy(), **kwargs)


def test_bad_data_raise_data_error_and_inputs_are_not_modified():
    rng = np.random.default_rng(0)
    u = rng.normal(size=2000)
    y = planted().simulate(u)
    u_copy, y_copy = u.copy(), y.copy()
    with pytest.raises(DataError, match="one record"):
        fit_wiener_hammerstein(u, y[:-1])
    bad = y.copy()
    bad[7] = np.nan
    with pytest.raises(DataError, match=r"y\[7\]"):
        fit_wiener_hammerstein(u, bad)
    with pytest.raises(DataError, match="constant"):
        fit_wiener_hammerstein(np.ones(2000), y)
    fit = fit_wiener_hammerstein(u, y, nb=2, ns=2, degree=3, max_iter=20)
    np.testing.assert_array_equal(u, u_copy)
    np.testing.assert_array_equal(y, y_copy)
    assert set(fit.parameters) == {"a1", "a2", "b1", "b2", "m1", "m2", "m3", "r1", "r2", "s1", "s2"}
    assert fit.to_dict()["model"]["model"] == "sandwich"
    assert isinstance(fit, bid.WienerHammersteinFit)


def test_the_core_problem_simulates_the_converted_sandwich():
    """Two independent forms of one model: the core's Wiener-Hammerstein problem (Chebyshev f,
    output offset) and the SandwichModel the fit converts it to (monomials m_i, plus the offset)."""
    from backlashid.identify._wiener_hammerstein import _Param

    rng = np.random.default_rng(4)
    u = rng.normal(0.0, 0.5, 3000)
    w = planted().simulate(u) + 0.02
    fit = fit_wiener_hammerstein(u, w, nb=2, ns=2, degree=4, warmup=50)
    for ft, oft in ((False, False), (True, False), (False, True), (True, True)):
        param = _Param(2, 2, 4, ft, oft, k=1.7)
        prob = param.problem(u, w, 0)
        theta = rng.normal(0.0, 0.3, len(prob.names))
        theta[param.sizes[0] : param.sizes[0] + 2] = [-0.9, 0.3]  # stable G1, G2
        theta[-3:-1] = [-0.5, 0.2]
        assert prob.feasible(theta)
        a, b, c, r, s, o = param.split(theta)
        m = param.monomials(c)
        if m[0] < 0:  # x -> -x, as the fit does, so that m_1 > 0
            a, m = -a, m * (-1.0) ** np.arange(1, 5)
        model = SandwichModel(
            bid.LinearBlock(a, b, feedthrough=ft),
            bid.GeneralBacklash(0.0, 0.0, list(m), list(m)),
            bid.LinearBlock(r, s, feedthrough=oft),
        )
        np.testing.assert_allclose(prob.simulate(theta), model.simulate(u) + o[0], rtol=1e-9, atol=1e-10)
    assert fit.simulation_rmse < 1e-6 * np.std(w)
    np.testing.assert_allclose(fit.offset, 0.02, atol=1e-6)


def test_recovers_a_wiener_hammerstein_system_generated_independently():
    """lfilter blocks around a tanh (not a polynomial), a short record: the fit's free-run error
    on fresh data is far below the linear baseline's, and the poles are G1's and G2's."""
    rng = np.random.default_rng(5)
    b1, a1 = [0.0, 0.25, 0.15], [1.0, -0.9, 0.3]
    b2, a2 = [0.0, 0.6, -0.2], [1.0, -0.5, 0.1]

    def system(u: np.ndarray) -> np.ndarray:
        return lfilter(b2, a2, np.tanh(1.5 * lfilter(b1, a1, u)))

    u = rng.normal(0.0, 1.0, 4000)
    fit = fit_wiener_hammerstein(u, system(u), nb=2, ns=2, degree=9, warmup=50)
    u_val = rng.normal(0.0, 1.0, 3000)
    err = np.sqrt(np.mean((fit.simulate(u_val) - system(u_val))[50:] ** 2))
    assert err < 0.02 * fit.baseline_rmse, (err, fit.baseline_rmse)
    poles = np.sort_complex(np.r_[fit.model.input_linear.poles(), fit.model.output_linear.poles()])
    np.testing.assert_allclose(poles, np.sort_complex(np.r_[np.roots(a1), np.roots(a2)]), atol=2e-3)


def test_the_package_does_not_import_scipy_optimize():
    import pathlib

    source = pathlib.Path(bid.__file__).parent / "identify" / "_wiener_hammerstein.py"
    assert "scipy" not in source.read_text()


def test_f_continues_along_its_tangent_beyond_the_estimation_range_of_x():
    """Within x_range the fit's output is the core's problem / the sandwich's simulation
    exactly; beyond it f is the tangent line at the nearer end, and the output is G2 of that."""
    rng = np.random.default_rng(7)
    u = rng.normal(0.0, 0.5, 3000)
    w = planted().simulate(u) + 0.01
    fit = fit_wiener_hammerstein(u, w, nb=2, ns=2, degree=3, warmup=50)
    x = fit.model.input_linear.simulate(u)
    assert fit.x_range == (float(x.min()), float(x.max()))
    # on the estimation record: the sandwich plus the offset, bit for bit
    np.testing.assert_array_equal(fit.simulate(u), fit.model.simulate(u) + fit.offset)
    lo, hi = fit.x_range
    m = fit.m
    poly = lambda v: sum(mi * v ** (i + 1) for i, mi in enumerate(m))  # noqa: E731
    slope = lambda v: sum((i + 1) * mi * v**i for i, mi in enumerate(m))  # noqa: E731
    z = np.array([lo - 1.0, lo - 0.1, lo, 0.5 * (lo + hi), hi, hi + 0.1, hi + 2.0])
    want = np.where(z < lo, poly(lo) + slope(lo) * (z - lo), np.where(z > hi, poly(hi) + slope(hi) * (z - hi), poly(z)))
    np.testing.assert_allclose(fit.nonlinearity(z), want, rtol=1e-12, atol=1e-12)
    # a larger input drives x beyond the range: G1, the continued f, G2, then the offset
    big = 3.0 * rng.normal(0.0, 0.5, 2000)
    xb = fit.model.input_linear.simulate(big)
    assert xb.min() < lo and xb.max() > hi
    g2 = fit.model.output_linear
    np.testing.assert_allclose(fit.simulate(big), lfilter([0.0, *g2.a], [1.0, *g2.b], fit.nonlinearity(xb)) + fit.offset, atol=1e-12)
    assert not np.allclose(fit.simulate(big), fit.model.simulate(big) + fit.offset)  # the polynomial alone differs
    assert fit.to_dict()["x_range"] == [lo, hi]
    # the fit's JSON simulates as the fit, continuation included
    import json

    from backlashid.identify import WienerHammersteinFit

    again = WienerHammersteinFit.from_dict(json.loads(json.dumps(fit.to_dict())))
    np.testing.assert_array_equal(again.simulate(big), fit.simulate(big))
    assert again.x_range == fit.x_range and again.to_dict() == fit.to_dict()
    # without a range: the polynomial everywhere
    import dataclasses

    raw = dataclasses.replace(fit, x_range=None)
    np.testing.assert_array_equal(raw.simulate(big), fit.model.simulate(big) + fit.offset)


def test_a_final_run_that_fails_raises_with_the_best_iterate(monkeypatch):
    # issue 31: on a position record the final Levenberg-Marquardt run diverged and the error
    # came bare; it carries its start now, a usable model (the stable lower-degree fit)
    from backlashid.identify import _wiener_hammerstein as wh

    real = wh._Param.fit

    def failing(self, *args, **kwargs):
        if self.degree == 6:  # the full degree's run
            raise bid.NotConvergedError("output-error refinement: the start is unstable or diverges")
        return real(self, *args, **kwargs)

    monkeypatch.setattr(wh._Param, "fit", failing)
    rng = np.random.default_rng(0)
    u = rng.normal(0.0, 0.5, 3000)
    w = planted().simulate(u)
    with pytest.raises(bid.NotConvergedError, match="its start") as info:
        fit_wiener_hammerstein(u, w, nb=2, ns=2, degree=6, warmup=50)
    best = info.value.best
    assert best is not None and not best.converged and best.degree == 6
    assert np.isfinite(best.simulation_rmse) and best.simulation_rmse < 0.5 * best.baseline_rmse
    assert np.all(np.isfinite(best.model.simulate(u)))  # a model that simulates


def test_an_integrating_plant_raises_not_converged_with_what_to_do_instead():
    # a position output: the best linear approximation has a pole at 1, which no model with
    # stable blocks holds; a NotConvergedError that says so, not the package's base error
    rng = np.random.default_rng(0)
    u = rng.standard_normal(3000)
    y = 0.1 * np.cumsum(u) + 0.01 * rng.standard_normal(3000)
    with pytest.raises(bid.NotConvergedError, match="integrating plant.*initial_state='estimate'"):
        fit_wiener_hammerstein(u, y)
