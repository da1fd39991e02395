"""Every figure the command line draws, on a newcomer's drive and on a real record, is readable:
no two labels collide and no axes is mostly empty (the first hour's figures: labels running into
the panel below, a three-line title, a warm-up spike that flattened the record to a line).

The drive is generated here, not by the package: a 1 kHz motor angle -> gear play of 1.8 deg
with slightly curved branches -> a load with a 40 ms lag, encoder noise 0.02 deg, the log
starting mid-motion. The real record is the friction damper's harmonic test and an earthquake
(skipped where the shared records are absent)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from backlashid.app._cli import main
from conftest import SHARED_DATA

matplotlib = pytest.importorskip("matplotlib")
matplotlib.use("Agg")
from matplotlib.collections import PolyCollection  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from figure_texts import collisions  # noqa: E402


def _drive(path: Path) -> None:
    rng = np.random.default_rng(5)
    n, dt = 12_000, 1e-3
    t = np.arange(n) * dt
    wander = np.convolve(rng.standard_normal(n + 400), np.ones(200) / 200, mode="same")[200:-200] * 60
    motor = wander + 30.0 * (2.0 * np.abs(((t / 4.0) % 1.0) - 0.5) - 0.5)
    play, p = np.empty(n), 0.0
    for k, x in enumerate(motor):  # gear play: the load side follows the motor beyond +-0.9 deg
        up, down = (x - 0.9) + 2e-4 * (x - 0.9) ** 2, (x + 0.9) + 2e-4 * (x + 0.9) ** 2
        p = up if up > p else down if down < p else p
        play[k] = p
    a, load, s = np.exp(-dt / 0.04), np.empty(n), play[0]
    for k in range(n):  # the load's 40 ms lag
        s = a * s + (1 - a) * play[k]
        load[k] = s
    load += 0.02 * rng.standard_normal(n)
    keep = slice(1500, None)  # the log starts mid-motion
    np.savetxt(path, np.column_stack([t[keep] - t[1500], motor[keep], load[keep]]), delimiter=",", header="time,motor,load", comments="", fmt="%.6f")


def _reference(path: Path) -> None:
    np.savetxt(path, 8.0 * np.sin(2 * np.pi * np.arange(3000) / 1500.0), header="position", comments="")


@pytest.fixture(scope="module")
def drawn(tmp_path_factory) -> dict[str, Figure]:
    """Every figure of the commands below, by a name (command: file)."""
    folder = tmp_path_factory.mktemp("figures")
    drive, reference = folder / "drive.csv", folder / "reference.csv"
    _drive(drive)
    _reference(reference)
    units = ["--sample-time", "0.001", "--input-unit", "deg", "--output-unit", "deg"]
    commands = {
        "fit": ["fit", drive, "-i", "motor", "-o", "load", "--split", "0.6", "--warmup", "50", "--json", folder / "fit.json", "--plots", folder / "fit", *units],
        "diagnose": ["diagnose", drive, "-i", "motor", "-o", "load", "--split", "0.6", "--model", folder / "fit.json", "--png", folder / "dashboard.png", *units],
        "compensate": ["compensate", folder / "fit.json", reference, "-r", "position", "--out", folder / "u.csv", "--png", folder / "compensation.png", *units],
        "track": ["track", drive, "-i", "motor", "-o", "load", "--fit-samples", "4000", "--every", "50", "--out", folder / "track.csv", "--plots", folder / "track"],
    }
    damper = SHARED_DATA / "friction_damper_backlash"
    if damper.is_dir():
        harmonic, quake = damper / "d2_char_1Hz36lbtension0.5amplitude.npz", damper / "d2_eq_ImperialValleyDBE.npz"
        commands["damper fit"] = ["fit", "--estimation-file", harmonic, "--validation-file", quake, "-i", "x_in", "-o", "F_kip", "--decimate", "8",
                                  "--scale", "auto", "--warmup", "20", "--json", folder / "damper.json", "--plots", folder / "damper",
                                  "--input-unit", "in", "--output-unit", "kip", "--sample-time", "0.0009765625"]  # fmt: skip
        commands["damper diagnose"] = ["diagnose", "--estimation-file", harmonic, "--validation-file", quake, "-i", "x_in", "-o", "F_kip",
                                       "--model", folder / "damper.json", "--png", folder / "damper-dashboard.png", "--output-unit", "kip"]  # fmt: skip
    figures: dict[str, Figure] = {}
    original = Figure.savefig

    def keep(self: Figure, fname, *args, **kwargs):
        figures[f"{label}: {len(figures)}"] = self
        return original(self, fname, *args, **kwargs)

    Figure.savefig = keep  # type: ignore[method-assign]
    try:
        for label, args in commands.items():  # label is read by keep
            result = CliRunner().invoke(main, [str(a) for a in args])
            assert result.exit_code == 0, f"{label}: {result.output}"
    finally:
        Figure.savefig = original  # type: ignore[method-assign]
    return figures


@pytest.fixture(scope="module")
def api_drawn() -> dict[str, Figure]:
    """Every figure the API draws itself (results with ``.plot()``), on Example 1 records,
    a sandwich, a selection, a tracker, a closed loop and a Wiener-Hammerstein fit."""
    import backlashid as bid

    data, val = bid.example_data(bid.example1(), 3000, seed=1), bid.example_data(bid.example1(), 3000, seed=2)
    fit = bid.fit_cascade(data.u, data.noisy, 2, 2, 3)
    figures: dict[str, Figure] = {}

    def keep(name: str, drawn) -> None:
        figures[name] = drawn if isinstance(drawn, Figure) else drawn.figure

    keep("FitResult.plot", fit.plot())
    keep("Prediction.plot", fit.model.simulate(val.u, band=0.95).plot(measured=val.noisy))
    metrics = bid.evaluate(fit.model, val.u, val.noisy, warmup=20)
    keep("Metrics.plot", metrics.plot(val.noisy, fit.model.simulate(val.u)))
    keep("DiagnosisReport.plot", bid.diagnose(fit.model, (data.u, data.noisy), (val.u, val.noisy), candidates=["dead_time", "output_offset"]).plot())
    keep("TrackResult.plot", bid.track(val.u, val.noisy, fit, every=20).plot())
    keep("ClosedLoop.plot", bid.closed_loop(fit.model, 0.8 * np.sin(2 * np.pi * np.arange(1500) / 500), kp=0.5, ki=0.05).plot())
    selection = bid.select_structure(data.u, data.noisy, na=(1, 2), nb=(2,), degree=(1, 3))
    keep("SelectionResult.plot", selection.plot())
    keep("GeneralBacklash characteristic", bid.app.plot_characteristic(fit.model.backlash, x_range=(-2.0, 2.0)))
    wh = bid.fit_wiener_hammerstein(data.u, np.tanh(data.noisy), nb=2, ns=2, degree=5)
    keep("WienerHammersteinFit.plot", wh.plot(data.u))
    return figures


def test_every_command_draws_its_figures(drawn):
    names = {name.split(":")[0] for name in drawn}
    assert {"fit", "diagnose", "compensate", "track"} <= names
    assert sum(name.startswith("fit:") for name in drawn) == 4  # characteristic, iterations, simulation, residuals


def test_no_two_labels_of_a_figure_collide(drawn):
    bad = {name: pairs for name, fig in drawn.items() if (pairs := collisions(fig))}
    assert not bad, f"colliding texts: {bad}"


def test_the_apis_figures_are_readable_too(api_drawn):
    """The figures of the results' own ``.plot()``: the same three checks."""
    bad = {name: pairs for name, fig in api_drawn.items() if (pairs := collisions(fig))}
    assert not bad, f"colliding texts: {bad}"
    test_no_title_runs_over_two_lines(api_drawn)
    test_the_data_fill_their_axes(api_drawn)


def test_no_title_runs_over_two_lines(drawn):
    for name, fig in drawn.items():
        titles = [fig._suptitle] if fig._suptitle is not None else []  # matplotlib keeps it there
        titles += [ax.title for ax in fig.axes]
        for title in titles:
            assert title.get_text().count("\n") <= 1, f"{name}: a title of {title.get_text().count(chr(10)) + 1} lines: {title.get_text()!r}"


def test_the_data_fill_their_axes(drawn):
    """No panel is mostly empty: the lines drawn on an axes (after any clipped start) cover at
    least a fifth of its y range (a warm-up spike once set a panel to -850..400 with the record
    a flat line)."""
    for name, fig in drawn.items():
        for ax in fig.axes:
            spans = []
            for line in ax.get_lines():
                y = np.asarray(line.get_ydata(), dtype=float)
                x = np.asarray(line.get_xdata(), dtype=float) if np.ndim(line.get_xdata()) else np.zeros(0)
                if y.size < 50 or x.size != y.size:
                    continue
                lo, hi = ax.get_xlim()
                inside = y[(x >= min(lo, hi)) & (x <= max(lo, hi)) & np.isfinite(y)]
                if inside.size:
                    spans.append((np.quantile(inside, 0.002), np.quantile(inside, 0.998)))
            for band in ax.collections:  # bands (fill_between) are data too
                if isinstance(band, PolyCollection):
                    for path in band.get_paths():
                        v = path.vertices
                        if len(v) >= 50 and np.all(np.isfinite(v)):
                            spans.append((float(np.quantile(v[:, 1], 0.002)), float(np.quantile(v[:, 1], 0.998))))
            if not spans or ax.get_yscale() != "linear":
                continue
            low, high = min(s[0] for s in spans), max(s[1] for s in spans)
            y0, y1 = ax.get_ylim()
            assert (high - low) >= 0.2 * abs(y1 - y0), f"{name}, panel {ax.get_title()!r}: the data span {high - low:.3g} of a y range {abs(y1 - y0):.3g}"


def test_the_collision_check_finds_two_labels_drawn_over_each_other():
    fig = Figure(figsize=(4, 3))
    ax = fig.add_subplot()
    ax.text(0.5, 0.5, "first label")
    ax.text(0.5, 0.5, "second label")
    assert collisions(fig) == [("first label", "second label")]
