"""``backlashid fit --orders auto``: the table of candidates printed, the chosen model written."""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner

import backlashid as bx
from backlashid.app._cli import main


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_fit_orders_auto_prints_the_table_and_writes_the_chosen_model(tmp_path):
    data = bx.example_data(bx.example1(), 1500, snr=50, seed=2)
    path = tmp_path / "log.csv"
    np.savetxt(path, np.column_stack([data.u, data.noisy]), delimiter=",", header="u,y", comments="", fmt="%.17g")
    out = tmp_path / "model.json"
    r = run("fit", path, "-i", "u", "-o", "y", "--orders", "auto", "--json", out)
    assert r.exit_code == 0, r.output
    assert "Structure selection: 36 candidates" in r.output and "chosen (*): cascade na=2, nb=2, degree=3" in r.output
    assert r.output.count("\n* cascade       2  2   3") == 1
    # a count of the candidates on stderr while they run, the table on stdout
    assert r.stderr.count("\ncandidate ") + r.stderr.startswith("candidate ") == 36 and "candidate 36/36: cascade na=" in r.stderr
    assert "candidate 1/36" not in r.stdout
    payload = json.loads(out.read_text())
    model = bx.model_from_dict(payload["model"])
    assert (model.linear.na, model.linear.nb, model.backlash.degree) == (2, 2, 3)
    selection = payload["structure_selection"]
    assert selection["structure"]["degree"] == 3 and len(selection["rows"]) == 36


def test_fit_orders_auto_refuses_the_wiener_hammerstein_fit(tmp_path):
    data = bx.example_data(bx.example1(), 300, snr=50, seed=2)
    path = tmp_path / "log.csv"
    np.savetxt(path, np.column_stack([data.u, data.noisy]), delimiter=",", header="u,y", comments="", fmt="%.17g")
    r = run("fit", path, "-i", "u", "-o", "y", "--orders", "auto", "--model", "wiener-hammerstein")
    assert r.exit_code == 1 and "Error: --orders auto" in r.output


def test_fit_model_auto_finds_the_input_backlash_of_a_mid_motion_drive_log(tmp_path):
    # issue 31: --model auto compares cascade, sandwich and input backlash (each from its
    # estimated start here) and keeps the chosen one; the same choice as select_structure
    from backlashid.identify import hammerstein_backlash, select_structure

    rng = np.random.default_rng(11)
    u = np.convolve(rng.uniform(-2.0, 2.0, 3300), np.ones(5) / 5, mode="same")
    drive = hammerstein_backlash(bx.GeneralBacklash(0.3, 0.2, [1.0], [1.0]), bx.LinearBlock([0.0015, 0.001], [-1.9, 0.9025]))
    w = (drive.simulate(u) + 0.01 * rng.standard_normal(u.size))[300:]
    path = tmp_path / "drive.csv"
    np.savetxt(path, np.column_stack([u[300:], w]), delimiter=",", header="motor,load", comments="", fmt="%.17g")
    out = tmp_path / "model.json"
    r = run("fit", path, "-i", "motor", "-o", "load", "--model", "auto", "--degree", "1", "--initial-state", "estimate",
            "--warmup", "20", "--json", out)
    assert r.exit_code == 0, r.output
    assert "chosen (*): hammerstein" in r.output and "Structure selection: 3 candidates" in r.output
    payload = json.loads(out.read_text())
    api = select_structure(u[300:], w, kind=("cascade", "sandwich", "hammerstein"), na=2, nb=2, nr=2, ns=2, degree=1,
                           initial_state="estimate", warmup=20)
    assert payload["parameters"] == api.fit.parameters
    assert payload["structure_selection"]["kind"] == "hammerstein"


def test_fit_valid_keeps_the_model_a_backlash_where_x_goes(tmp_path):
    # the crossing degree-5 fit of a short noisy record (as tests/identify/test_warnings_and_wording):
    # --valid gives fit_cascade(valid=True)'s model, a backlash on the visited range
    data = bx.example_data(bx.example1(), 300, snr=3, seed=37)
    path = tmp_path / "log.csv"
    np.savetxt(path, np.column_stack([data.u, data.noisy]), delimiter=",", header="u,y", comments="", fmt="%.17g")
    out = tmp_path / "model.json"
    r = run("fit", path, "-i", "u", "-o", "y", "--degree", "5", "--valid", "--json", out)
    assert r.exit_code == 0, r.output
    model = bx.model_from_dict(json.loads(out.read_text())["model"])
    x = model.simulate(data.u, internals=True).x
    assert model.backlash.degree == 5 and model.backlash.check_branches(x.min(), x.max()).is_valid
    plain = run("fit", path, "-i", "u", "-o", "y", "--degree", "5", "--json", out)
    model = bx.model_from_dict(json.loads(out.read_text())["model"])
    x = model.simulate(data.u, internals=True).x
    assert plain.exit_code == 0 and not model.backlash.check_branches(x.min(), x.max()).is_valid
