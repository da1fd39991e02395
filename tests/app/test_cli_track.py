"""``backlashid track LOG -i u -o y --out params.csv --plots figs`` (issue 20)."""

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


def _csv(path: Path, u: np.ndarray, y: np.ndarray) -> None:
    """A log of columns u, y with a header line, as the commands read it."""
    np.savetxt(path, np.column_stack([u, y]), delimiter=",", header="u,y", comments="")


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = bx.example_data(bx.example1(), 12_000, snr=25, seed=8)
    path = tmp_path_factory.mktemp("track") / "log.csv"
    _csv(path, d.u, d.noisy)
    return path


def test_track_from_a_fit_on_the_first_samples_writes_every_parameter(log: Path, tmp_path: Path) -> None:
    out = tmp_path / "sub" / "params.csv"
    res = run("track", log, "-i", "u", "-o", "y", "--fit-samples", "3000", "--every", "100", "--out", out, "--plots", tmp_path / "figs")
    assert res.exit_code == 0, res.output
    cols = np.genfromtxt(out, delimiter=",", names=True)
    names = ["a1", "a2", "b1", "b2", "c_L", "m_L2", "m_L3", "m_R1", "c_R", "m_R2", "m_R3"]
    assert list(cols.dtype.names) == ["sample"] + [v for n in names for v in (n, f"{n}_se")]
    assert cols.size == 120 and cols["sample"][-1] == 11_999
    # the same as backlashid.track in model units from the same start (scaling of the first samples)
    assert "fitted on the first 3000 samples" in res.output and "no alarm, but the detector never armed" in res.output
    assert np.all(cols["c_R_se"] > 0)
    assert (tmp_path / "figs" / "parameters.png").stat().st_size > 20_000


def test_track_from_a_model_file_uses_its_scaling(log: Path, tmp_path: Path) -> None:
    data = np.loadtxt(log, delimiter=",", skiprows=1)
    fit_file = tmp_path / "fit.json"
    scaling = {"input_offset": 0.0, "input_scale": 1.0, "output_offset": 0.5, "output_scale": 2.0}
    fit_file.write_text(json.dumps({"model": bx.example1().to_dict(), "scaling": scaling, "data": {"decimate": 1}}))
    out = tmp_path / "params.csv"
    res = run("track", log, "-i", "u", "-o", "y", "--model", fit_file, "--every", "1000", "--forgetting", "0.998", "--out", out)
    assert res.exit_code == 0, res.output
    cols = np.genfromtxt(out, delimiter=",", names=True)
    want = bx.track(data[:, 0], (data[:, 1] - 0.5) / 2.0, bx.example1(), every=1000, forgetting=0.998)
    assert np.array_equal(cols["c_L"], want.theta[:, 4]) and np.array_equal(cols["c_L_se"], want.standard_errors[:, 4])


def test_refusals_end_with_one_error_line(log: Path, tmp_path: Path) -> None:
    short = run("track", log, "-i", "u", "-o", "y", "--range", "0:500", "--out", tmp_path / "p.csv")
    assert short.exit_code == 1 and "--fit-samples" in short.output and "Traceback" not in short.output
    bad = run("track", log, "-i", "u", "-o", "y", "--fit-samples", "3000", "--forgetting", "1.5", "--out", tmp_path / "p.csv")
    assert bad.exit_code == 1 and "forgetting" in bad.output and "Traceback" not in bad.output
    missing = run("track", log, "-i", "u", "-o", "speed", "--out", tmp_path / "p.csv")
    assert missing.exit_code == 1 and "no column 'speed'" in missing.output
    assert not (tmp_path / "p.csv").exists()


def test_track_fits_and_tracks_each_structure(tmp_path: Path) -> None:
    """--structure sandwich / hammerstein: the start is that fit on the first samples and the
    columns are its parameters; the values are backlashid.track's from the same start."""
    from backlashid.identify import Scaling, Structure, fit_hammerstein_backlash, fit_sandwich

    d = bx.example_data(bx.example2(), 8000, snr=25, seed=9)
    path = tmp_path / "log.csv"
    _csv(path, d.u, d.noisy)
    scaling = Scaling.auto(d.u[:3000], d.noisy[:3000])
    u, y = scaling.input_to_model(d.u), scaling.output_to_model(d.noisy)
    for structure, names, fit in (
        ("sandwich", Structure(2, 2, 3, 2, 2).names, lambda: fit_sandwich(u[:3000], y[:3000], 2, 2, 2, 2, 3)),
        ("hammerstein", Structure(1, 0, 3, 2, 2).names, lambda: fit_hammerstein_backlash(u[:3000], y[:3000], 2, 2, 3)),
    ):
        out = tmp_path / f"{structure}_parameters.csv"
        res = run("track", path, "-i", "u", "-o", "y", "--structure", structure, "--fit-samples", "3000", "--every", "500", "--out", out)
        assert res.exit_code == 0, res.output
        cols = np.genfromtxt(out, delimiter=",", names=True)
        assert list(cols.dtype.names) == ["sample"] + [v for n in names for v in (n, f"{n}_se")]
        want = bx.track(u, y, fit(), every=500)
        assert np.array_equal(cols["c_R"], want.theta[:, names.index("c_R")])


def test_track_says_when_the_structure_does_not_fit(tmp_path: Path) -> None:
    """A cascade started on a motor -> play -> load log: the command names the mismatch, says
    the standard errors are not trustworthy and points at --structure."""
    rng = np.random.default_rng(3)
    u = rng.uniform(-1, 1, 30_000)
    play = bx.GeneralBacklash(0.3, 0.25, [1.0, 0.15], [1.05, -0.1])
    w = bx.identify.hammerstein_backlash(play, bx.LinearBlock([0.08, 0.04], [-1.3, 0.42])).simulate(u)
    path = tmp_path / "drive.csv"
    _csv(path, u, w + w.std() / 25 * rng.standard_normal(u.size))
    res = run("track", path, "-i", "u", "-o", "y", "--fit-samples", "5000", "--every", "1000", "--out", tmp_path / "p.csv")
    assert res.exit_code == 0, res.output
    assert "mismatch: the tracked CascadeModel does not explain the record" in res.output
    assert "not trustworthy" in res.output and "--structure" in res.output
    fine = run("track", path, "-i", "u", "-o", "y", "--structure", "hammerstein", "--degree", "2", "--fit-samples", "5000",
               "--every", "1000", "--out", tmp_path / "q.csv")
    assert fine.exit_code == 0 and "mismatch" not in fine.output, fine.output


def test_track_says_how_many_updates_the_innovation_bound_refused(log: Path, tmp_path: Path) -> None:
    """Three spikes of about 100 noise stds in the log: the command says the bound refused
    those three updates and calls them outliers (the model fits, no mismatch)."""
    data = np.genfromtxt(log, delimiter=",", names=True)
    y = data["y"].copy()
    y[[5000, 7000, 9000]] += 100 * y[:3000].std() / 25
    path = tmp_path / "spiked.csv"
    _csv(path, data["u"], y)
    res = run("track", path, "-i", "u", "-o", "y", "--fit-samples", "3000", "--every", "1000", "--out", tmp_path / "p.csv")
    assert res.exit_code == 0, res.output
    assert "refused the update on 3 of 12000 samples" in res.output and "outliers in the record" in res.output
    clean = run("track", log, "-i", "u", "-o", "y", "--fit-samples", "3000", "--every", "1000", "--out", tmp_path / "q.csv")
    assert "refused" not in clean.output


def test_track_judges_its_own_start_and_says_where_the_verdicts_may_come_from(log: Path, tmp_path: Path) -> None:
    """The start fitted on the head is checked on the samples after it: on a white record it
    simulates them at the noise and nothing more is said; a head of two slow sine periods does
    not determine Example 1's cascade (its start misses the white rest by orders of magnitude),
    and the CLI says so before the monitor's verdicts, whose advice then points at the start
    rather than at another structure."""
    res = run("track", log, "-i", "u", "-o", "y", "--fit-samples", "3000", "--every", "100", "--out", tmp_path / "a.csv")
    assert res.exit_code == 0, res.output
    line = next(t for t in res.output.splitlines() if t.startswith("the start simulates the 9000 samples"))
    assert float(line.split(" at ")[1].split(" times")[0]) < 1.3 and "did not determine" not in line
    assert "forgetting 0.999: a memory of 1000 samples" in res.output
    rng = np.random.default_rng(8)
    u = np.concatenate([0.8 * np.sin(2 * np.pi * np.arange(3000) / 1500), rng.uniform(-1, 1, 9000)])
    y = np.asarray(bx.example1().simulate(u))
    path = tmp_path / "sine_head.csv"
    _csv(path, u, y + y.std() / 25 * rng.standard_normal(u.size))
    res = run("track", path, "-i", "u", "-o", "y", "--fit-samples", "3000", "--every", "100", "--out", tmp_path / "b.csv")
    assert res.exit_code == 0, res.output
    assert "the head did not determine the model for the rest of the record" in res.output
    assert "mismatch:" in res.output and "the start missed the record after its head" in res.output
    assert "try another --structure" not in res.output


def test_track_reports_a_run_off_estimate_on_a_position_record_instead_of_failing(tmp_path: Path) -> None:
    """A motor -> play -> integrating load (the output a position): the prediction-error tracker
    runs off (docs/tracking.md, Limits) to an estimate whose left branch decreases, which is no
    valid model. The command still reports (the tracked structure named from its start) and
    exits 0; before, it ended on 'Error: branch L does not increase'."""
    rng = np.random.default_rng(5)
    u = rng.uniform(-1, 1, 60_000)
    play = bx.GeneralBacklash(0.3, 0.25, [1.0, 0.15], [1.05, -0.1])
    w = np.asarray(bx.identify.hammerstein_backlash(play, bx.LinearBlock([0.08, 0.04], [-1.7, 0.7])).simulate(u))
    path = tmp_path / "position.csv"
    _csv(path, u, w + w[:5000].std() / 25 * rng.standard_normal(u.size))
    res = run("track", path, "-i", "u", "-o", "y", "--structure", "hammerstein", "--degree", "2", "--every", "1000",
              "--out", tmp_path / "p.csv")
    assert res.exit_code == 0, res.output
    assert "mismatch: the tracked SandwichModel does not explain the record" in res.output and "Error" not in res.output
