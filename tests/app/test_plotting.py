"""Figures: what they show is checked on the artists, not by eye."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt
import numpy as np
import pytest

import backlashid as bx
from backlashid.app import plot_branches_comparison, plot_characteristic, plot_residuals, plot_simulation, plot_trajectories
from backlashid.errors import DataError
from backlashid.identify import fit_percent
from backlashid.plotting._figures import _correlation


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


# -- what a reader needs: units on every axis, legends off the data, long records readable -------


def _legend_outside(ax) -> bool:
    """The legend's box does not overlap the axes' data area (both in display pixels)."""
    ax.figure.canvas.draw()
    legend, area = ax.get_legend().get_window_extent(), ax.get_window_extent()
    return legend.x0 >= area.x1 or legend.x1 <= area.x0 or legend.y0 >= area.y1 or legend.y1 <= area.y0


def test_long_record_is_a_window_plus_the_whole_error_and_its_spectrum(ex1):
    d = bx.example_data(ex1, 6000, snr=10, seed=3)
    y_sim = ex1.simulate(d.u)
    ax = plot_simulation(d.noisy, y_sim, warmup=30, dt=0.01, ylabel="force", unit="kN", window=500)
    fig = ax.figure
    assert len(fig.axes) == 3
    zoom, error, spectrum = fig.axes
    assert zoom is ax and len(ax.lines[0].get_xdata()) == 500  # the window, not 6000 samples in one panel
    whole = [line for line in error.lines if len(line.get_xdata()) == 6000]
    assert len(whole) == 1
    np.testing.assert_allclose(whole[0].get_ydata(), d.noisy - y_sim)
    assert spectrum.get_yscale() == "log" and spectrum.get_xlabel() == "frequency [Hz]"
    # the window is the one with the largest error energy after the warm-up
    e2 = (d.noisy - y_sim)[30:] ** 2
    start = 30 + int(np.argmax(np.convolve(e2, np.ones(500), mode="valid")))
    assert ax.lines[0].get_xdata()[0] == pytest.approx(start * 0.01)
    for a in fig.axes:
        assert _legend_outside(a)
        assert a.get_xlabel() and a.get_ylabel()
    assert "[kN]" in zoom.get_ylabel() and "[kN]" in error.get_ylabel() and "kN²" in spectrum.get_ylabel()
    assert "[s]" in zoom.get_xlabel() and "[s]" in error.get_xlabel()


def test_short_record_stays_one_panel_with_units(ex1):
    d = bx.example_data(ex1, 400, seed=1)
    ax = plot_simulation(d.noisy, d.clean)
    assert len(ax.figure.axes) == 1 and len(ax.lines[0].get_xdata()) == 400
    assert ax.get_xlabel().startswith("sample") and "units of the record" in ax.get_ylabel()
    assert _legend_outside(ax)


def test_residual_axes_carry_units(rng):
    fig = plot_residuals(rng.normal(size=300), rng.normal(size=300), dt=0.5, ylabel="position", unit="mm", time_unit="ms")
    labels = [(a.get_xlabel(), a.get_ylabel()) for a in fig.axes]
    assert all(x and y for x, y in labels)
    assert "[mm]" in labels[0][1] and "[ms]" in labels[0][0] and "[mm]" in labels[1][0]
    assert "0.5 ms" in labels[2][0]


def test_branches_comparison_draws_each_branch_where_it_is_active(ex1):
    u = np.random.default_rng(4).uniform(-1, 1, 1500)
    x = ex1.simulate(u, internals=True).x
    ax = plot_branches_comparison(ex1.backlash, ex1.backlash, (float(x.min()), float(x.max())), x=x)
    signals = ex1.backlash.switching(x)
    by_label = {line.get_label(): line for line in ax.lines}
    for name, active in (("L(x) true", signals.f1), ("R(x) true", signals.f2), ("L(x) estimated", signals.f1)):
        xs = by_label[name].get_xdata()
        assert xs.min() == pytest.approx(x[active].min()) and xs.max() == pytest.approx(x[active].max())
    # the left branch is not drawn up to the largest x, nor the right one down to the smallest
    assert by_label["L(x) true"].get_xdata().max() < x.max() - 0.1
    assert by_label["R(x) true"].get_xdata().min() > x.min() + 0.1
    assert "x(t)" in ax.get_xlabel() and "input of the backlash" in ax.get_xlabel()
    assert "y(t)" in ax.get_ylabel() and "output of the backlash" in ax.get_ylabel()
    assert _legend_outside(ax)


def test_trajectories_end_at_the_final_estimates_and_explain_the_styles():
    history = np.array([[1.0, 2.0], [1.5, 2.5], [1.6, 2.4]])
    ax = plot_trajectories(history, ["m_R1", "c_L"], ["m_R1", "c_L"], truth={"m_R1": 1.5, "c_L": 2.4},
                           final={"m_R1": 1.55, "c_L": 2.45}, refinement_steps=3)
    segments = [line for line in ax.lines if line.get_linestyle() == "--"]
    assert [list(s.get_xdata()) for s in segments] == [[3, 4], [3, 4]]
    assert [list(s.get_ydata()) for s in segments] == [[1.6, 1.55], [2.4, 2.45]]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels[:2] == ["m_R1", "c_L"]  # every curve is named ...
    assert "true value (dotted)" in labels and any("final estimate" in lab and "3 LM steps" in lab for lab in labels)
    assert _legend_outside(ax)  # ... and the legend hides none of them
    assert ax.get_xticklabels()[-1].get_text() == "final"


def test_characteristic_axes_and_legend(ex1):
    sim = ex1.simulate(np.random.default_rng(0).uniform(-1, 1, 300), internals=True)
    ax = plot_characteristic(ex1.backlash, sim.x, sim.output, unit="mm")
    assert ax.get_xlabel() == "x(t), input of the backlash [mm]" and ax.get_ylabel() == "y(t), output of the backlash [mm]"
    assert _legend_outside(ax)


def test_cli_figures_are_labelled_in_the_record_units(tmp_path, monkeypatch):
    from click.testing import CliRunner

    from backlashid.app import _cli

    d = bx.example_data(bx.example1(), 3000, snr=25, seed=0)
    path = tmp_path / "log.csv"
    np.savetxt(path, np.column_stack([d.u, d.noisy]), delimiter=",", header="u,force", comments="", fmt="%.17g")
    seen = {}

    def save(plt_, fig, target):
        fig.canvas.draw()
        seen[target.name] = [(a.get_xlabel(), a.get_ylabel(), a.get_legend()) for a in fig.axes]
        plt_.close(fig)
        return target

    monkeypatch.setattr(_cli, "_save", save)
    r = CliRunner().invoke(_cli.main, ["fit", str(path), "-i", "u", "-o", "force", "--split", "0.4", "--plots", str(tmp_path / "figs"),
                                       "--output-unit", "kN", "--sample-time", "0.01"])
    assert r.exit_code == 0, r.output
    assert sorted(seen) == ["characteristic.png", "iterations.png", "residuals.png", "simulation.png"]
    for name, axes in seen.items():
        for xlabel, ylabel, _ in axes:
            assert xlabel and ylabel, name
    simulation = seen["simulation.png"]
    assert len(simulation) == 3  # 1800 validation samples: a window, the whole error, its spectrum
    assert all("[kN]" in y for _, y, _ in simulation[:2]) and all("[s]" in x for x, _, _ in simulation[:2])
    assert "[kN]" in seen["residuals.png"][0][1] and "[s]" in seen["residuals.png"][0][0]
    assert "kN" in seen["characteristic.png"][0][0]
    # the printed errors say their units
    assert "validation (errors in kN, the measured force)" in r.output
