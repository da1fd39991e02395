"""``backlashid compensate MODEL REFERENCE --out U.csv`` (issue 19)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import backlashid as bx
from backlashid.app._cli import main


def run(*args: object):
    return CliRunner().invoke(main, [str(a) for a in args])


def read(path: Path) -> dict[str, np.ndarray]:
    data = np.genfromtxt(path, delimiter=",", names=True)
    return {k: np.asarray(data[k]) for k in data.dtype.names}


@pytest.fixture
def reference_file(tmp_path: Path) -> Path:
    t = np.arange(600)
    path = tmp_path / "reference.csv"
    np.savetxt(path, np.column_stack([t, 30.0 + 2.0 * np.sin(2 * np.pi * t / 150)]), delimiter=",", header="t,position", comments="")
    return path


def test_the_input_makes_the_scaled_model_follow_the_reference(tmp_path: Path, reference_file: Path) -> None:
    # a fit file with a scaling: the reference is in measured units, the input comes out in them
    fit_file = tmp_path / "fit.json"
    scaling = {"input_offset": 5.0, "input_scale": 2.0, "output_offset": 30.0, "output_scale": 4.0}
    fit_file.write_text(json.dumps({"model": bx.example1().to_dict(), "scaling": scaling, "data": {"decimate": 1}}))
    out = tmp_path / "sub" / "u.csv"
    res = run("compensate", fit_file, reference_file, "-r", "position", "--out", out, "--png", tmp_path / "figs" / "c.png")
    assert res.exit_code == 0, res.output
    cols = read(out)
    assert list(cols) == ["reference", "u", "y_model"]
    # the model in model units, driven by the input converted back, follows the reference from sample 1 on
    u_model = (cols["u"] - 5.0) / 2.0
    y = 30.0 + 4.0 * bx.example1().simulate(u_model)
    assert np.max(np.abs(y[1:] - cols["reference"][1:])) < 1e-9
    assert np.allclose(cols["y_model"], y, rtol=0, atol=1e-12)
    assert "preview 1 sample" in res.output and "(simulation on the model)" in res.output
    assert (tmp_path / "figs" / "c.png").stat().st_size > 10_000


def test_a_decimated_models_reference_is_filtered_and_decimated_as_its_records_were(tmp_path: Path) -> None:
    # a reference with a fast ripple the decimated model never saw: it comes out filtered, at
    # the model's rate, and the output says so and how to apply u
    t = np.arange(1200)
    ripple = 0.3 * np.sin(2 * np.pi * t / 3.0)
    reference = tmp_path / "reference.csv"
    np.savetxt(reference, np.column_stack([t, np.sin(2 * np.pi * t / 400) + ripple]), delimiter=",", header="t,position", comments="")
    fit_file = tmp_path / "fit.json"
    fit_file.write_text(json.dumps({"model": bx.example1().to_dict(), "data": {"decimate": 4}}))
    out = tmp_path / "u.csv"
    res = run("compensate", fit_file, reference, "-r", "position", "--out", out)
    assert res.exit_code == 0, res.output
    cols = read(out)
    assert len(cols["reference"]) == 300
    slow = np.sin(2 * np.pi * t[::4] / 400)
    assert np.max(np.abs(cols["reference"][20:-20] - slow[20:-20])) < 0.05  # the ripple (0.3) filtered out
    assert "low-pass filtered and decimated by 4" in res.output and "hold each value for 4 samples" in res.output


def test_offset_range_and_threshold(tmp_path: Path, reference_file: Path) -> None:
    model_file = tmp_path / "model.json"
    model_file.write_text(bx.example2().to_json())
    out = tmp_path / "u.csv"
    res = run("compensate", model_file, reference_file, "-r", "position", "--range", "100:400", "--reference-offset", "-30", "--threshold", "0.01", "--out", out)
    assert res.exit_code == 0, res.output
    cols = read(out)
    assert cols["reference"].size == 300
    assert np.allclose(cols["reference"] + 30.0, np.loadtxt(reference_file, delimiter=",", skiprows=1)[100:400, 1])
    # the sandwich's preview is 2 samples; after it the smoothed inverse holds the output within
    # the threshold of the reference (at the reversals), the exact one follows it
    assert "preview 2 samples" in res.output
    gap = np.max(np.abs(cols["y_model"][2:] - cols["reference"][2:]))
    assert 1e-3 < gap <= 0.01 + 1e-9
    exact = run("compensate", model_file, reference_file, "-r", "position", "--range", "100:400", "--reference-offset", "-30", "--out", out)
    assert exact.exit_code == 0, exact.output
    cols = read(out)
    assert np.max(np.abs(cols["y_model"][2:] - cols["reference"][2:])) < 1e-9


def test_refusals_end_with_one_error_line(tmp_path: Path, reference_file: Path) -> None:
    model_file = tmp_path / "model.json"
    model_file.write_text(bx.example1().to_json())
    missing = run("compensate", model_file, reference_file, "-r", "speed", "--out", tmp_path / "u.csv")
    assert missing.exit_code == 1 and "no column 'speed'" in missing.output
    bad = tmp_path / "bad.csv"
    bad.write_text("position\n1.0\nnan\n2.0\n")
    nan = run("compensate", model_file, bad, "-r", "position", "--out", tmp_path / "u.csv")
    assert nan.exit_code == 1 and "Error:" in nan.output and "Traceback" not in nan.output
    # a branch that turns: a reference above its maximum cannot be reached
    turning = bx.CascadeModel(bx.LinearBlock([1.0]), bx.GeneralBacklash(0.1, 0.1, [1.0, 0.0, -1.0], [1.0, 0.0, -1.0]))
    model_file.write_text(turning.to_json())
    high = run("compensate", model_file, reference_file, "-r", "position", "--out", tmp_path / "u.csv")
    assert high.exit_code == 1 and "cannot reach" in high.output and "Traceback" not in high.output
    assert not (tmp_path / "u.csv").exists()
    negative = run("compensate", model_file, reference_file, "--threshold", "-1", "--out", tmp_path / "u.csv")
    assert negative.exit_code == 2 and "--threshold" in negative.output


def test_a_reference_beyond_the_fits_outputs_is_warned(tmp_path: Path, reference_file: Path) -> None:
    """A reference 18x beyond the data was compensated without a word; the fit file now keeps the
    outputs its records visited."""
    data = bx.example_data(bx.example1(), 1500, snr=25, seed=0)
    log = tmp_path / "log.csv"
    np.savetxt(log, np.column_stack([data.u, data.noisy]), delimiter=",", header="u,y", comments="", fmt="%.17g")
    fit_file = tmp_path / "fit.json"
    assert run("fit", log, "-i", "u", "-o", "y", "--json", fit_file).exit_code == 0
    low, high = json.loads(fit_file.read_text())["data"]["output_range"]
    assert (low, high) == (float(data.noisy.min()), float(data.noisy.max()))
    inside = tmp_path / "inside.csv"
    np.savetxt(inside, 0.5 * (low + high) + 0.4 * (high - low) * np.sin(np.arange(600) / 30.0), header="position", comments="")
    res = run("compensate", fit_file, inside, "-r", "position", "--out", tmp_path / "u.csv")
    assert res.exit_code == 0 and "Warning" not in res.output, res.output
    res = run("compensate", fit_file, reference_file, "-r", "position", "--out", tmp_path / "u.csv")  # 28..32, far above
    assert res.exit_code == 0 and "Warning: the reference spans" in res.output and "extrapolates the model" in res.output


def test_the_figure_is_in_the_records_units_and_time(tmp_path: Path, reference_file: Path, monkeypatch) -> None:
    """Its axes said "units of the record" in samples: compensate had no unit or sample-time options."""
    from backlashid.app import _cli

    drawn = []
    monkeypatch.setattr(_cli, "_save", lambda plt, fig, path: drawn.append(fig) or path)
    model_file = tmp_path / "model.json"
    model_file.write_text(bx.example1().to_json())
    res = run("compensate", model_file, reference_file, "-r", "position", "--reference-offset", "-30", "--out", tmp_path / "u.csv",
              "--png", tmp_path / "c.png", "--sample-time", "0.001", "--input-unit", "V", "--output-unit", "mm")
    assert res.exit_code == 0, res.output
    top, bottom = drawn[0].axes[:2]
    assert (top.get_ylabel(), bottom.get_ylabel(), bottom.get_xlabel()) == ("output [mm]", "input [V]", "time [s]")
    assert bottom.get_xlim()[1] == pytest.approx(0.6, rel=0.1)  # 600 samples of 1 ms
