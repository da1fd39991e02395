"""Figures: what they show is checked on the artists, not by eye."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest

import backlashid as bx
from backlashid.app import plot_characteristic, plot_residuals, plot_simulation, plot_trajectories
from backlashid.app._plotting import _correlation
from backlashid.errors import DataError
from backlashid.identify import fit_percent


@pytest.fixture(autouse=True)
def close_figures():
    yield
    plt.close("all")


def test_simulation_plot_states_the_fit_percent(ex1):
    d = bx.example_data(ex1, 600, snr=10, seed=2)
    y_sim = ex1.simulate(d.u)
    ax = plot_simulation(d.noisy, y_sim, warmup=50)
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    expected = fit_percent(d.noisy, y_sim, warmup=50)
    assert any(f"fit {expected:.1f} %" in label for label in labels)
    assert any("skipped transient (50 samples)" in label for label in labels)
    np.testing.assert_array_equal(ax.lines[1].get_ydata(), y_sim)


def test_correlation_is_normalised_and_finds_a_delay(rng):
    e = rng.normal(size=5000)
    lags = np.arange(-5, 6)
    auto = _correlation(e, e, lags)
    assert auto[5] == pytest.approx(1.0)
    assert np.all(np.abs(np.delete(auto, 5)) < 4 / np.sqrt(5000))
    delayed = np.concatenate([np.zeros(3), e[:-3]])  # delayed(t) = e(t - 3)
    cross = _correlation(delayed, e, lags)
    assert lags[np.argmax(cross)] == 3 and cross.max() > 0.99


def test_residual_plot_has_four_panels_and_the_white_bounds(rng):
    e, u = rng.normal(size=400), rng.normal(size=400)
    fig = plot_residuals(e, u, max_lag=10)
    assert len(fig.axes) == 4
    band = fig.axes[2].patches[0]  # the 95 % bounds of a white residual
    ys = band.get_patch_transform().transform(band.get_path().vertices)[:, 1]
    bound = 1.96 / np.sqrt(400)
    assert ys.min() == pytest.approx(-bound) and ys.max() == pytest.approx(bound)
    with pytest.raises(DataError, match="one record"):
        plot_residuals(e, u[:-1])


def test_characteristic_and_trajectories(ex1):
    sim = ex1.simulate(np.random.default_rng(0).uniform(-1, 1, 300), internals=True)
    ax = plot_characteristic(ex1.backlash, sim.x, sim.output)
    assert [line.get_label() for line in ax.lines[:2]] == ["L(x)", "R(x)"]
    history = np.array([[1.0, 2.0], [1.5, 2.5], [1.6, 2.4]])
    ax = plot_trajectories(history, ["a", "b"], ["b"], truth={"b": 2.4}, final={"a": 1.7, "b": 2.45})
    np.testing.assert_array_equal(ax.lines[0].get_ydata(), [2.0, 2.5, 2.4])
    np.testing.assert_array_equal(ax.lines[0].get_xdata(), [1, 2, 3])
    star = [line for line in ax.lines if line.get_marker() == "*"]
    assert len(star) == 1 and list(star[0].get_xdata()) == [4] and list(star[0].get_ydata()) == [2.45]
