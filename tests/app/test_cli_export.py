"""``backlashid export MODEL --format c|python-control|json --out PATH`` (issue 19)."""

from __future__ import annotations

import json
import runpy
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import backlashid as bx
from backlashid.app._cli import main


def run(*args: object):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture
def model_file(tmp_path: Path) -> Path:
    path = tmp_path / "model.json"
    path.write_text(bx.example2().to_json())
    return path


def test_json_writes_the_plain_model_of_a_fit_file_and_notes_its_scaling(tmp_path: Path) -> None:
    fit_file = tmp_path / "fit.json"
    scaling = {"input_offset": 1.0, "input_scale": 2.0, "output_offset": 0.0, "output_scale": 10.0}
    fit_file.write_text(json.dumps({"model": bx.example1().to_dict(), "scaling": scaling, "data": {"decimate": 4}}))
    res = run("export", fit_file, "--format", "json", "--out", tmp_path / "sub" / "plain.json")
    assert res.exit_code == 0, res.output
    assert bx.model_from_json((tmp_path / "sub" / "plain.json").read_text()) == bx.example1()
    assert "note: the model is in model units; the fit measured u = 1 + 2 u_model" in res.output
    assert "one step is 4 samples" in res.output
    plain = run("export", tmp_path / "sub" / "plain.json", "--format", "json", "--out", tmp_path / "again.json")
    assert plain.exit_code == 0 and "note" not in plain.output


def test_python_control_writes_a_module_that_rebuilds_the_system(tmp_path: Path, model_file: Path) -> None:
    out = tmp_path / "plant_system.py"
    res = run("export", model_file, "--format", "python-control", "--out", out)
    assert res.exit_code == 0, res.output
    module = runpy.run_path(str(out))
    assert module["model"] == bx.example2()
    control = pytest.importorskip("control", reason="python-control is not installed: pip install 'backlashid[control]'")
    system = module["system"]("plant", dt=0.5)
    assert (system.name, system.dt, system.nstates) == ("plant", 0.5, 8)
    u = np.sin(0.1 * np.arange(200))
    resp = control.input_output_response(system, 0.5 * np.arange(200), u, np.zeros(8))
    np.testing.assert_allclose(resp.outputs, bx.example2().simulate(u), rtol=0, atol=1e-12)


def test_c_writes_header_and_source_into_a_folder_and_they_compile(tmp_path: Path, model_file: Path) -> None:
    res = run("export", model_file, "--format", "c", "--out", tmp_path, "--prefix", "sw")
    assert res.exit_code == 0, res.output
    header, source = tmp_path / "sw.h", tmp_path / "sw.c"
    assert f"wrote {header}" in res.output and f"wrote {source}" in res.output
    assert "double sw_step(sw_state *state, double u);" in header.read_text()
    cc = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if cc is None:
        pytest.skip("no C compiler (cc, gcc or clang) on PATH")
    done = subprocess.run([cc, "-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-c", "-o", str(tmp_path / "sw.o"), str(source)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_bad_arguments_end_in_one_error_line(tmp_path: Path, model_file: Path) -> None:
    res = run("export", model_file, "--format", "c", "--out", tmp_path, "--prefix", "9lives")
    assert res.exit_code == 1 and "Error: prefix = '9lives'" in res.output
    res = run("export", tmp_path / "missing.json", "--format", "json", "--out", tmp_path / "x.json")
    assert res.exit_code == 1 and "no such model file" in res.output
    res = run("export", model_file, "--format", "matlab", "--out", tmp_path / "x")
    assert res.exit_code == 2 and "matlab" in res.output


def test_a_file_name_that_would_inject_c_is_refused_and_nothing_is_written(tmp_path: Path, model_file: Path) -> None:
    # the fuzz campaign's reproducer: the header's name is written into the source's #include
    out = tmp_path / 'dir' / 'bl.h"\nint injected(void) { return 42; }\n#define Z '
    res = run("export", model_file, "--format", "c", "--out", out)
    assert res.exit_code == 1 and res.output.count("\n") == 1 and "Error: path = " in res.output
    assert "letters, digits" in res.output
    assert not [p for p in tmp_path.rglob("*") if p.is_file() and p != model_file]
