"""Prediction bands: the fit's covariance travels with its model (equality, hash, pickle,
JSON), the first-order variance is the quadratic form of the exact sensitivities, the band
covers the noise-free output, and the sampled band agrees with it."""

from __future__ import annotations

import dataclasses
import json
import pickle

import numpy as np
import pytest

import backlashid as bx
from backlashid.identify import Structure
from backlashid.models import ParameterCovariance, Prediction, sample_band


@pytest.fixture(scope="module")
def fit1():
    d = bx.example_data(bx.example1(), 1500, snr=25, seed=10_000)
    return d, bx.fit_cascade(d.u, d.noisy)


def _spd(p, scale, seed=0):
    a = np.random.default_rng(seed).normal(size=(p, p))
    return scale * (a @ a.T / p + np.eye(p))


def test_the_fit_attaches_its_covariance_under_the_structure_names(fit1):
    _d, fit = fit1
    cov = fit.model.covariance
    assert isinstance(cov, ParameterCovariance)
    assert list(cov.names) == fit.structure.names
    np.testing.assert_allclose(cov.matrix, fit.covariance, rtol=1e-12, atol=0)
    assert cov.standard_errors() == pytest.approx(fit.standard_errors, rel=1e-12)
    assert not cov.matrix.flags.writeable


def test_the_covariance_is_kept_by_pickle_and_json_and_left_out_of_equality(fit1):
    _d, fit = fit1
    model = fit.model
    bare = fit.structure.model(fit.theta)
    assert bare.covariance is None
    assert model == bare and hash(model) == hash(bare)  # not part of equality or hash
    for back in (pickle.loads(pickle.dumps(model)), bx.model_from_json(model.to_json()),
                 type(model).from_dict(json.loads(json.dumps(model.to_dict())))):
        assert back == model
        assert back.covariance.names == model.covariance.names
        np.testing.assert_array_equal(back.covariance.matrix, model.covariance.matrix)
    # a hand-made model writes no covariance key: files of before still read, and as before
    assert "covariance" not in bx.example1().to_dict()
    assert bx.example1().to_dict()["format_version"] == 1


def test_bad_covariances_are_refused():
    names = Structure(2, 2, 3).names
    with pytest.raises(bx.ModelError, match="shape"):
        ParameterCovariance(names, np.eye(3))
    with pytest.raises(bx.ModelError, match="non-finite"):
        ParameterCovariance(names, np.full((11, 11), np.nan))
    with pytest.raises(bx.ModelError, match="symmetric"):
        ParameterCovariance(names, np.triu(np.ones((11, 11))))
    with pytest.raises(bx.ModelError, match="names"):
        ParameterCovariance.from_dict({"names": names})
    with pytest.raises(bx.ModelError, match="covariance"):
        bx.CascadeModel(bx.example1().linear, bx.example1().backlash, covariance=np.eye(11))  # type: ignore[arg-type]


def test_the_linear_variance_sums_to_the_trace_of_the_dense_gram_matrix(fit1):
    # sum_t J_t S J_t^T = trace(S J^T J), J^T J = R^T R of the core's output-error factor
    d, fit = fit1
    s = Structure(2, 2, 3)
    cov = _spd(s.size, 1e-4)
    pred = fit.model.simulate(d.u, band=0.9, covariance=ParameterCovariance(s.names, cov))
    r_aug, _cost = s.problem(d.u, d.noisy).oe_factor(fit.theta)
    r = r_aug[: s.size, : s.size]
    np.testing.assert_allclose(np.sum(pred.std**2), np.trace(cov @ r.T @ r), rtol=1e-12)
    np.testing.assert_array_equal(pred.output, fit.model.simulate(d.u))
    z = (pred.upper - pred.output) / np.where(pred.std > 0, pred.std, 1)
    np.testing.assert_allclose(z[pred.std > 0], 1.6448536269514722, rtol=1e-12)
    assert (pred.level, pred.method) == (0.9, "linear")


def test_the_band_covers_the_noise_free_output_over_seeds():
    inside = total = 0
    for seed in range(10_000, 10_020):
        d = bx.example_data(bx.example1(), 1500, snr=25, seed=seed)
        pred = bx.fit_cascade(d.u, d.noisy).predict(d.u, band=0.95)
        hit = (pred.lower <= d.clean) & (d.clean <= pred.upper)
        inside, total = inside + int(hit.sum()), total + hit.size
    assert 0.88 <= inside / total <= 0.99, inside / total


def test_linear_and_sampling_agree_on_a_well_identified_fit(fit1):
    d, fit = fit1
    lin = fit.predict(d.u, band=0.95)
    smp = fit.predict(d.u, band=0.95, method="sampling", draws=400, seed=3)
    assert smp.method == "sampling" and smp.draws == 400
    moving = lin.std > 0
    ratio = np.mean(smp.std[moving]) / np.mean(lin.std[moving])
    assert abs(ratio - 1) < 0.15, ratio
    half_lin, half_smp = np.median((lin.upper - lin.lower)[moving]), np.median((smp.upper - smp.lower)[moving])
    assert abs(half_smp / half_lin - 1) < 0.15
    # seeded: the same draws again
    again = fit.predict(d.u, band=0.95, method="sampling", draws=400, seed=3)
    np.testing.assert_array_equal(again.lower, smp.lower)


@pytest.mark.parametrize("kind", ["cascade-state", "sandwich", "sandwich-state", "feedthrough"])
def test_linear_and_sampling_agree_for_small_covariances(kind):
    # a small covariance: the sampled std is the first-order std to the sampling error
    u = np.random.default_rng(1).uniform(-1.5, 1.5, 400)
    if kind.startswith("cascade"):
        model, structure = bx.example1(), Structure(2, 2, 3)
        state = bx.CascadeState((0.5, -0.2), (0.8, 0.1), 0.3)
    elif kind.startswith("sandwich"):
        model, structure = bx.example2(), Structure(2, 2, 3, 2, 2)
        state = bx.SandwichState((0.5, -0.2), (0.8, 0.1), (0.3, 0.1), (0.4, -0.1))
    else:
        structure = Structure(2, 2, 3, feedthrough=True)
        lin = bx.LinearBlock([0.3, 0.7, 0.5], [-0.2, 0.35], feedthrough=True)
        model, state = bx.CascadeModel(lin, bx.example1().backlash), None
    state = state if kind.endswith("state") else None
    theta = structure.pack(model)
    cov = ParameterCovariance(structure.names, _spd(structure.size, 1e-7, seed=2))
    model = dataclasses.replace(structure.model(theta), covariance=cov)
    lin_band = model.simulate(u, band=0.95, initial_state=state)
    np.testing.assert_allclose(lin_band.output, model.simulate(u, initial_state=state), rtol=0, atol=1e-12)
    smp = sample_band(model, u, theta, structure.model, band=0.95, initial_state=state, draws=600, seed=5)
    moving = lin_band.std > 1e-9
    assert np.mean(moving) > 0.5
    ratio = np.median(smp.std[moving] / lin_band.std[moving])
    assert abs(ratio - 1) < 0.1, ratio


def test_feedthrough_bands_run_from_rest_only():
    structure = Structure(2, 2, 3, feedthrough=True)
    lin = bx.LinearBlock([0.3, 0.7, 0.5], [-0.2, 0.35], feedthrough=True)
    model = bx.CascadeModel(lin, bx.example1().backlash)
    cov = ParameterCovariance(structure.names, _spd(structure.size, 1e-6))
    with pytest.raises(bx.ModelError, match="from rest"):
        model.simulate([0.1, 0.2], band=0.9, covariance=cov, initial_state=bx.CascadeState((0.1, 0.0), (0.0, 0.0), 0.0))


def test_bad_arguments_name_what_to_do(fit1):
    d, fit = fit1
    for band in (0, 1, 1.5, -0.1, float("nan"), "0.95", True):
        with pytest.raises(bx.DataError, match="band"):
            fit.predict(d.u, band=band)  # type: ignore[arg-type]
        with pytest.raises(bx.DataError, match="band"):
            fit.predict(d.u, band=band, method="sampling")  # type: ignore[arg-type]
    bad_u = d.u.copy()
    bad_u[5] = np.inf
    with pytest.raises(bx.DataError, match="u"):
        fit.predict(bad_u)
    with pytest.raises(bx.DataError, match="u"):
        fit.predict(bad_u, method="sampling")
    with pytest.raises(bx.DataError, match="method"):
        fit.predict(d.u, method="bootstrap")
    with pytest.raises(bx.DataError, match="draws"):
        fit.predict(d.u, method="sampling", draws=1)
    with pytest.raises(bx.DataError, match="seed"):
        fit.predict(d.u, method="sampling", seed=-1)
    with pytest.raises(bx.ModelError, match="covariance"):
        bx.example1().simulate(d.u, band=0.95)
    with pytest.raises(bx.ModelError, match="normalised"):
        s = Structure(1, 0, 1)
        bx.CascadeModel(bx.LinearBlock([1.0]), bx.GeneralBacklash(0.5, 0.5, [2.0], [2.0])).simulate(
            [0.0, 1.0], band=0.9, covariance=ParameterCovariance(s.names, np.eye(s.size)))
    with pytest.raises(bx.ModelError, match="parameters"):
        fit.model.simulate(d.u, band=0.9, covariance=ParameterCovariance(Structure(1, 0, 1).names, np.eye(4)))
    with pytest.raises(bx.DataError, match="internals"):
        fit.model.simulate(d.u, band=0.9, internals=True)
    with pytest.raises(bx.DataError, match="initial_state"):
        fit.model.simulate(d.u, band=0.9, initial_state=bx.CascadeState((0.0,), (0.0, 0.0), 0.0))


def test_invalid_draws_are_redrawn_and_counted():
    # a wide covariance on b: many draws are unstable or have crossing branches
    structure = Structure(2, 2, 3)
    model, theta = bx.example1(), structure.pack(bx.example1())
    cov = np.diag(np.full(structure.size, 1e-6))
    cov[2, 2] = cov[3, 3] = 0.25
    model = dataclasses.replace(model, covariance=ParameterCovariance(structure.names, cov))
    u = np.random.default_rng(0).uniform(-1, 1, 200)
    pred = sample_band(model, u, theta, structure.model, draws=50, seed=0)
    assert pred.invalid_draws > 0 and pred.draws == 50
    assert np.all(np.isfinite(pred.lower)) and np.all(pred.lower <= pred.upper)
    cov[2, 2] = cov[3, 3] = 1e6  # almost every draw unstable
    hopeless = dataclasses.replace(model, covariance=ParameterCovariance(structure.names, cov))
    with pytest.raises(bx.BacklashIdError, match="valid"):
        sample_band(hopeless, u, theta, structure.model, draws=20, seed=0)


def test_the_prediction_plots_its_band_and_writes_json(fit1):
    d, fit = fit1
    pred = fit.predict(d.u[:300])
    assert isinstance(pred, Prediction)
    fig = pred.plot(measured=d.noisy[:300])
    ax = fig.axes[0]
    assert any("prediction band" in str(c.get_label()) for c in ax.collections)
    out = pred.to_dict()
    json.dumps(out, allow_nan=False)
    assert out["method"] == "linear" and len(out["lower"]) == 300
    assert 0.0 <= pred.coverage(d.clean[:300]) <= 1.0
    import matplotlib.pyplot as plt

    plt.close(fig)
