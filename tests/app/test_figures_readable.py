"""Figures answer their question: diverged iterates, a narrow dead band, a start-up transient
and a high sampling rate do not hide what each figure is for (checked on the artists)."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest

import backlashid as bx
from backlashid.app import plot_characteristic, plot_residuals, plot_simulation, plot_trajectories
from figure_texts import collisions


@pytest.fixture(autouse=True)
def close_figures():
    yield
    plt.close("all")


# -- trajectories: the final estimates set the y axis, diverged iterates are marked at its edge ---


def _diverging_history() -> tuple[np.ndarray, list[str], dict[str, float]]:
    final = {"a1": 0.014, "a2": -0.010, "b1": -1.84, "b2": 0.84}
    rng = np.random.default_rng(0)
    h = np.array([list(final.values())] * 8) + 0.3 * rng.standard_normal((8, 4))
    h[4, 1] = 100.0 * final["b1"]  # a diverged iterate of 100 times the largest final estimate, below
    h[7, 0] = -100.0 * final["b1"]  # and one above
    return h, list(final), final


def test_trajectories_y_limits_hold_the_final_estimates_not_a_diverged_iterate():
    h, names, final = _diverging_history()
    ax = plot_trajectories(h, names, names, final=final, refinement_steps=5)
    lo, hi = ax.get_ylim()
    assert all(lo < v < hi for v in final.values())
    assert lo > 100.0 * final["b1"] and hi < -100.0 * final["b1"]
    # the final estimates fill a good part of the axis, they do not sit flat in its middle
    spread = max(final.values()) - min(final.values())
    assert spread > 0.2 * (hi - lo)


def test_trajectories_mark_iterates_beyond_the_axis_at_its_edge():
    h, names, final = _diverging_history()
    ax = plot_trajectories(h, names, names, final=final)
    ax.figure.canvas.draw()
    up = [line for line in ax.lines if line.get_marker() == "^" and len(line.get_xdata())]
    down = [line for line in ax.lines if line.get_marker() == "v" and len(line.get_xdata())]
    assert [list(line.get_xdata()) for line in up] == [[8]] and [list(line.get_ydata()) for line in up] == [[1.0]]
    assert [list(line.get_xdata()) for line in down] == [[5]] and [list(line.get_ydata()) for line in down] == [[0.0]]
    curves = {line.get_label(): line for line in ax.lines}
    assert up[0].get_color() == curves["a1"].get_color() and down[0].get_color() == curves["a2"].get_color()
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any("iterates beyond the axis" in lab and "marked at its edge" in lab for lab in labels)
    # the marks follow the limits when a caller changes them (a shared axis, set_ylim)
    ax.set_ylim(-1000, 1000)
    ax.figure.canvas.draw()
    assert not any(len(line.get_xdata()) for line in ax.lines if line.get_marker() in "^v")


def test_trajectories_that_converge_keep_every_iterate_in_view():
    history = np.array([[0.0, 0.1], [0.5, 0.3], [0.65, 0.33], [0.7, 0.34]])
    ax = plot_trajectories(history, ["a1", "c_L"], ["a1", "c_L"], truth={"a1": 0.7, "c_L": 0.35}, final={"a1": 0.7, "c_L": 0.34})
    lo, hi = ax.get_ylim()
    assert lo <= 0.0 and hi >= 0.7
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert not any("beyond the axis" in lab for lab in labels)


# -- characteristic: a narrow dead band gets a zoom, c_L and c_R are printed ----------------------


def _narrow_dead_band() -> bx.GeneralBacklash:
    return bx.GeneralBacklash(c_left=0.8, c_right=1.0, m_left=[1.0], m_right=[1.0])


def test_characteristic_zooms_on_a_narrow_dead_band_and_states_it():
    backlash = _narrow_dead_band()
    x = 20.0 * np.sin(np.linspace(0.0, 6.0 * np.pi, 3000))
    y = backlash.simulate(x)
    ax = plot_characteristic(backlash, x, y, unit="deg")
    assert len(ax.child_axes) == 1
    inset = ax.child_axes[0]
    lo, hi = inset.get_xlim()
    assert lo < -backlash.c_left and hi > backlash.c_right
    main_lo, main_hi = ax.get_xlim()
    assert hi - lo < 0.25 * (main_hi - main_lo)
    # -c_L and c_R are marked in the zoom, and their values are printed on the figure
    dashed = sorted(line.get_xdata()[0] for line in inset.lines if line.get_linestyle() == "--")
    assert dashed == pytest.approx([-0.8, 1.0])
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any("c_L = 0.8" in lab and "c_R = 1" in lab and "[deg]" in lab for lab in labels)
    assert [line.get_label() for line in ax.lines[:2]] == ["L(x)", "R(x)"]


def test_characteristic_without_a_narrow_dead_band_has_no_zoom():
    ex1 = bx.example1()
    sim = ex1.simulate(np.random.default_rng(0).uniform(-1, 1, 300), internals=True)
    ax = plot_characteristic(ex1.backlash, sim.x, sim.output)
    assert ax.child_axes == []


def test_characteristic_leaves_the_warm_up_out_of_the_path():
    backlash = _narrow_dead_band()
    x = 20.0 * np.sin(np.linspace(0.0, 6.0 * np.pi, 3000))
    y = backlash.simulate(x)
    y_start = y.copy()
    y_start[:40] = -15.0  # a start-up transient: the simulated x against a measured y far off
    every = plot_characteristic(backlash, x, y_start).collections[0].get_offsets()
    after = plot_characteristic(backlash, x, y_start, warmup=40).collections[0].get_offsets()
    assert len(every) == 3000 and np.any(every[:, 1] == -15.0)  # the default draws every sample
    assert len(after) == 2960 and not np.any(after[:, 1] == -15.0)
    np.testing.assert_array_equal(after, np.column_stack([x[40:], y_start[40:]]))


# -- simulation: the error panel is scaled to the error after the warm-up -------------------------


def _record_with_a_transient(warmup: int = 100, n: int = 6000) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(5)
    y = np.sin(np.arange(n) / 150.0) * 10.0
    error = 0.1 * rng.standard_normal(n)
    error[:warmup] += 8.0 * np.exp(-np.arange(warmup) / 30.0)  # large in the warm-up only
    return y, y - error


def test_simulation_error_panel_is_scaled_to_the_error_after_the_warm_up():
    y, y_sim = _record_with_a_transient()
    ax = plot_simulation(y, y_sim, warmup=100, dt=0.001, unit="deg", window=1000)
    error_panel = ax.figure.axes[1]
    lo, hi = error_panel.get_ylim()
    after = (y - y_sim)[100:]
    assert lo <= after.min() and hi >= after.max()  # every evaluated sample in view
    assert hi - lo < 2.0 * np.ptp(after)  # and not the transient's range (8 beside about 0.8)
    assert (y - y_sim).max() > hi  # the transient is drawn, clipped


def test_simulation_error_panel_clips_a_transient_that_outlasts_the_warm_up():
    y, y_sim = _record_with_a_transient(warmup=160)
    ax = plot_simulation(y, y_sim, warmup=60, dt=0.001, unit="deg", window=1000)
    error_panel = ax.figure.axes[1]
    lo, hi = error_panel.get_ylim()
    bulk = np.percentile((y - y_sim)[160:], [0.0, 100.0])
    assert lo <= bulk[0] and hi >= bulk[1] and hi - lo < 3.0 * np.ptp(bulk)
    labels = [t.get_text() for t in error_panel.get_legend().get_texts()]
    assert any("beyond the axis is clipped" in lab for lab in labels)


@pytest.mark.parametrize(("dt", "unit"), [(1.0, None), (0.001, "deg"), (0.5, "N m / rad")])
def test_spectrum_label_stays_on_two_lines(dt, unit):
    y, y_sim = _record_with_a_transient()
    ax = plot_simulation(y, y_sim, warmup=100, dt=dt, unit=unit, time_unit="s", window=1000)
    spectrum = ax.figure.axes[2]
    assert spectrum.get_ylabel().count("\n") <= 1
    assert spectrum.get_ylabel().startswith("power spectral density")


# -- residuals: no overlapping text, the lags from the data, the time axis said right -------------


@pytest.mark.parametrize("warmup", [0, 50])
@pytest.mark.parametrize("ylabel", ["load", "load of the gearbox output shaft, measured at the arm"])
def test_residual_figure_texts_do_not_overlap(ylabel, warmup):
    rng = np.random.default_rng(1)
    n = 7000
    u = np.convolve(rng.standard_normal(n + 400), np.ones(400) / 20.0, mode="valid")[:n]
    e = np.convolve(rng.standard_normal(n + 50), np.ones(50) / 7.0, mode="valid")[:n]
    fig = plot_residuals(e, u, dt=0.001, ylabel=ylabel, unit="deg", warmup=warmup,
                         title="Residual diagnostics, free-run simulation error on the validation record (input motor)")
    assert collisions(fig, margin=0.0, touching=True) == []


def test_residual_lags_follow_the_decay_of_the_correlations():
    rng = np.random.default_rng(2)
    n = 8000
    e = np.convolve(rng.standard_normal(n + 60), np.ones(60) / 8.0, mode="valid")[:n]  # correlated over 60 samples
    u = rng.standard_normal(n)
    fig = plot_residuals(e, u, dt=0.001)
    auto_lags = max(line.get_xdata().max() for line in fig.axes[2].lines if len(line.get_xdata()) > 2)
    assert 60 <= auto_lags <= n // 4  # past the decay (r_ee falls below 0.2 near lag 48)
    auto = _autocorrelation(e, int(auto_lags))
    assert auto[-1] < 0.2
    # white signals: the fewest lags (20); a record too short for 20: N/4
    fig = plot_residuals(rng.standard_normal(2000), rng.standard_normal(2000))
    assert max(np.max(c.get_segments()[-1][:, 0]) for c in fig.axes[2].collections if hasattr(c, "get_segments")) == 20
    fig = plot_residuals(rng.standard_normal(40), rng.standard_normal(40))
    assert max(np.max(c.get_segments()[-1][:, 0]) for c in fig.axes[2].collections if hasattr(c, "get_segments")) == 10
    # the caller's max_lag still rules both panels
    fig = plot_residuals(e, u, max_lag=10)
    assert [len(fig.axes[k].containers[0].markerline.get_xdata()) for k in (2, 3)] == [11, 21]


def _autocorrelation(e: np.ndarray, lags: int) -> np.ndarray:
    e = e - e.mean()
    return np.array([np.dot(e[k:], e[: len(e) - k]) for k in range(lags + 1)]) / np.dot(e, e)


def test_residual_time_axis_says_where_it_starts():
    rng = np.random.default_rng(3)
    e, u = rng.standard_normal(500), rng.standard_normal(500)
    fig = plot_residuals(e, u, dt=0.01)
    assert fig.axes[0].get_xlabel() == "time from the residual's first sample [s]"
    assert fig.axes[0].lines[0].get_xdata()[0] == 0.0
    fig = plot_residuals(e, u, dt=0.01, warmup=50)
    assert fig.axes[0].get_xlabel().startswith("time from the record's start [s]") and "50 samples" in fig.axes[0].get_xlabel()
    assert fig.axes[0].lines[0].get_xdata()[0] == pytest.approx(0.5)
    fig = plot_residuals(e, u)
    assert fig.axes[0].get_xlabel() == "sample of the residual"


def test_the_wiener_hammerstein_curve_is_one_line_without_branch_talk():
    """The static curve was drawn as two tied branches, one hidden under the other, with a
    legend about branches "not active"."""
    import backlashid as bid

    rng = np.random.default_rng(0)
    u = rng.standard_normal(3000)
    x = np.zeros(3000)
    for t in range(1, 3000):
        x[t] = 0.7 * x[t - 1] + 0.3 * u[t - 1]
    y = np.tanh(x) + 0.01 * rng.standard_normal(3000)
    ax = bid.fit_wiener_hammerstein(u, y, nb=2, ns=2, degree=5).plot(u)
    labels = [line.get_label() for line in ax.get_lines()]
    assert labels == ["f(x)"]
    assert not any("active" in t.get_text() for t in ax.get_legend().get_texts())
    plt.close(ax.figure)
