"""Every result object keeps one protocol: frozen, ``summary() -> str``, a JSON-safe
``to_dict()``, and (where it has something to draw) ``plot()`` returning a matplotlib object
drawn by :mod:`backlashid.app`."""

from __future__ import annotations

import dataclasses
import json
import pickle

import numpy as np
import pytest

import backlashid as bid
from backlashid.identify import LinearBaseline, Metrics, WienerHammersteinFit, fit_wiener_hammerstein, wiener_hammerstein_model

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


@pytest.fixture(scope="module")
def cascade_fit():
    data = bid.example_data(bid.example1(), 1500, snr=25, seed=0)
    return data, bid.fit_cascade(data.u, data.noisy)


@pytest.fixture(scope="module")
def wh_fit():
    truth = wiener_hammerstein_model([0.3], [-0.5], [1.0, 0.0, -0.3], [0.5], [-0.2])
    u = np.random.default_rng(0).normal(0.0, 0.5, 2000)
    return u, truth.simulate(u), fit_wiener_hammerstein(u, truth.simulate(u), nb=1, ns=1, degree=3, warmup=20)


@pytest.fixture(scope="module")
def diagnosis():
    from backlashid.benchmarks import make_case

    case = make_case("friction", 3.0, 0, n_est=1500, n_val=1500)
    return bid.diagnose(case.nominal, estimation=(case.u_est, case.y_est), validation=(case.u_val, case.y_val))


@pytest.fixture(scope="module")
def results(cascade_fit, wh_fit, diagnosis):
    """One of each result class, with the arguments its plot() takes."""
    data, fit = cascade_fit
    u, y, wh = wh_fit
    metrics = bid.evaluate(fit.model, data.u, data.noisy, warmup=10)
    sandwich = bid.example2().simulate(data.u, internals=True)
    return {
        bid.FitResult: (fit, (), {"truth": bid.example1()}),
        Metrics: (metrics, (data.noisy, fit.model.simulate(data.u)), {}),
        WienerHammersteinFit: (wh, (u,), {}),
        LinearBaseline: (wh.baseline, (u, y), {"warmup": 20}),
        bid.CascadeSimulation: (fit.model.simulate(data.u, internals=True), None, None),
        bid.SandwichSimulation: (sandwich, None, None),
        bid.DiagnosisReport: (diagnosis, None, None),  # its plot() is a whole dashboard: tested below
    }


CLASSES = [bid.FitResult, Metrics, WienerHammersteinFit, LinearBaseline, bid.CascadeSimulation, bid.SandwichSimulation, bid.DiagnosisReport]


def results_drawn_on_axes(cls: type) -> bool:
    """The results whose plot() draws on one axes (the simulations draw nothing, the diagnosis a
    whole figure)."""
    return "Simulation" not in cls.__name__ and cls is not bid.DiagnosisReport


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_results_are_frozen(results, cls):
    result = results[cls][0]
    assert type(result) is cls and dataclasses.is_dataclass(result)
    name = dataclasses.fields(result)[0].name
    with pytest.raises(dataclasses.FrozenInstanceError):
        setattr(result, name, getattr(result, name))


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_summary_is_text_and_to_dict_is_json(results, cls):
    result = results[cls][0]
    text = result.summary()
    assert isinstance(text, str) and text.strip()
    data = result.to_dict()
    assert isinstance(data, dict) and data
    assert set(json.loads(json.dumps(data))) == set(data)


@pytest.mark.parametrize("cls", [c for c in CLASSES if results_drawn_on_axes(c)], ids=lambda c: c.__name__)
def test_plot_draws_with_the_app_layer(results, cls):
    result, args, kwargs = results[cls]
    drawn = result.plot(*args, **kwargs)
    assert isinstance(drawn, (matplotlib.axes.Axes, matplotlib.figure.Figure))
    figure = drawn if isinstance(drawn, matplotlib.figure.Figure) else drawn.figure
    assert figure.axes and any(ax.lines or ax.collections for ax in figure.axes)
    # drawing on given axes uses them
    _, ax = plt.subplots()
    assert result.plot(*args, ax=ax, **kwargs) is ax
    plt.close("all")


def test_fit_result_plot_draws_every_parameter_and_the_truth(cascade_fit):
    _, fit = cascade_fit
    ax = fit.plot(truth=bid.example1())
    labels = [line.get_label() for line in ax.lines]
    assert set(fit.names) <= set(labels)
    assert len(ax.lines) >= 3 * len(fit.names)  # trajectory, truth and final star each
    plt.close("all")


def test_metrics_plot_needs_the_record_it_describes(results):
    metrics, (y, y_sim), _ = results[Metrics]
    with pytest.raises(bid.DataError, match="samples"):
        metrics.plot(y[:-1], y_sim[:-1])


def test_summary_and_to_dict_say_what_the_fields_hold(results, cascade_fit):
    data, fit = cascade_fit
    d = fit.to_dict()
    assert d["parameters"] == fit.parameters and d["warmup"] == fit.warmup and len(d["history"]) == fit.iterations
    metrics = results[Metrics][0]
    assert metrics.to_dict() == dataclasses.asdict(metrics) and str(metrics) == metrics.summary()
    assert "warm-up of 10" in metrics.summary()
    wh = results[WienerHammersteinFit][0]
    assert (wh.to_dict()["nb"], wh.to_dict()["ns"]) == (1, 1) and "nb = 1" in wh.summary()
    assert wh.baseline.to_dict()["offset"] == wh.baseline.offset and "linear baseline" in wh.baseline.summary()
    sim = results[bid.CascadeSimulation][0]
    assert sim.to_dict()["output"] == sim.output.tolist() and f"{100 * sim.moving_fraction():.1f} %" in sim.summary()


def test_not_converged_error_carries_a_picklable_fit_result():
    d = bid.example_data(bid.example2(), 1500, snr=None, seed=1)
    with pytest.raises(bid.NotConvergedError) as info:
        bid.fit_sandwich(d.u, d.noisy, paper=True)
    best = info.value.best
    assert isinstance(best, bid.FitResult) and not best.converged
    assert best.summary() and json.dumps(best.to_dict())
    again = pickle.loads(pickle.dumps(info.value))
    assert type(again) is bid.NotConvergedError and str(again) == str(info.value)
    assert isinstance(again.best, bid.FitResult) and again.best.parameters == best.parameters
    np.testing.assert_array_equal(again.best.history, best.history)


def test_diagnosis_report_plot_is_the_app_dashboard(diagnosis, tmp_path):
    from backlashid.app import plot_diagnosis

    figure = diagnosis.plot()
    assert isinstance(figure, matplotlib.figure.Figure) and len(figure.axes) >= 5
    assert all(ax.lines or ax.collections or ax.patches or ax.texts for ax in figure.axes)
    path = tmp_path / "dashboard.png"
    diagnosis.plot(path)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert len(plot_diagnosis(diagnosis).axes) == len(figure.axes)
    plt.close("all")
