"""Every output file is written atomically: an interrupted write (Ctrl-C, an exception) leaves
the old file or none, never a truncated one (issue 21: ``simulate --out`` interrupted mid-write
left 823,933 of 2,000,000 rows)."""

from __future__ import annotations

import json
import os
import stat

import numpy as np
import pytest
from click.testing import CliRunner

import backlashid as bx
from backlashid._files import atomic_write, save_figure, write_text
from backlashid.app._cli import main


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def leftovers(folder):
    return sorted(p.name for p in folder.iterdir() if p.name.endswith(".tmp"))


@pytest.fixture
def record(tmp_path):
    data = bx.example_data(bx.example1(), 3000, snr=25, seed=0)
    path = tmp_path / "log.csv"
    np.savetxt(path, np.column_stack([data.u, data.noisy]), delimiter=",", header="u,y", comments="", fmt="%.17g")
    model = tmp_path / "model.json"
    model.write_text(bx.example1().to_json())
    return path, model


@pytest.mark.parametrize("interrupt", [KeyboardInterrupt, RuntimeError, OSError])
@pytest.mark.parametrize("existed", [True, False])
def test_an_interrupted_write_leaves_the_old_file_or_none(tmp_path, interrupt, existed):
    target = tmp_path / "out.csv"
    if existed:
        target.write_text("old\n")
    with pytest.raises(interrupt), atomic_write(target) as fh:
        fh.write("new,row\n" * 10_000)
        fh.flush()
        raise interrupt("stopped mid-write")
    assert (target.read_text() == "old\n") if existed else not target.exists()
    assert leftovers(tmp_path) == []


def test_a_complete_write_replaces_the_file_and_keeps_its_permissions(tmp_path):
    target = tmp_path / "out.json"
    target.write_text("old")
    os.chmod(target, 0o640)
    write_text(target, '{"new": 1}\n')
    assert json.loads(target.read_text()) == {"new": 1}
    assert stat.S_IMODE(target.stat().st_mode) == 0o640
    fresh = tmp_path / "fresh.json"
    write_text(fresh, "{}")
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(fresh.stat().st_mode) == 0o666 & ~umask  # as open(path, "w") would give
    assert leftovers(tmp_path) == []


@pytest.mark.parametrize("existed", [True, False])
def test_simulate_out_interrupted_mid_write_leaves_the_old_file_or_none(tmp_path, record, monkeypatch, existed):
    data, model = record
    out = tmp_path / "sim.csv"
    if existed:
        assert run("simulate", model, data, "-i", "u", "-o", "y", "--out", out).exit_code == 0
    before = out.read_bytes() if existed else None
    savetxt = np.savetxt

    def interrupted(fh, rows, **kwargs):  # writes the first half of the rows, then Ctrl-C
        savetxt(fh, rows[: len(rows) // 2], **kwargs)
        fh.flush()
        assert os.path.getsize(fh.name) > 10_000  # rows really reached the disk
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "savetxt", interrupted)
    r = run("simulate", model, data, "-i", "u", "-o", "y", "--out", out)
    assert r.exit_code != 0
    assert (out.read_bytes() == before) if existed else not out.exists()
    assert leftovers(tmp_path) == []
    monkeypatch.setattr(np, "savetxt", savetxt)
    r = run("simulate", model, data, "-i", "u", "-o", "y", "--out", out)
    assert r.exit_code == 0 and len(out.read_text().splitlines()) == 3001


def test_fit_json_and_figures_interrupted_before_the_rename_leave_the_old_files(tmp_path, record, monkeypatch):
    data, _ = record
    out, figs = tmp_path / "fit.json", tmp_path / "figs"
    figs.mkdir()
    out.write_text("old json")
    (figs / "simulation.png").write_bytes(b"old png")

    def interrupted(fd):  # every file is complete in its temporary copy; Ctrl-C before the rename
        raise KeyboardInterrupt

    monkeypatch.setattr(os, "fsync", interrupted)
    r = run("fit", data, "-i", "u", "-o", "y", "--split", "0.5", "--max-iter", "5", "--json", out, "--plots", figs)
    assert r.exit_code != 0
    assert out.read_text() == "old json" and (figs / "simulation.png").read_bytes() == b"old png"
    assert leftovers(tmp_path) == [] and leftovers(figs) == []
    assert sorted(p.name for p in figs.iterdir()) == ["simulation.png"]


def test_save_figure_writes_the_format_of_the_extension_atomically(tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    fig = Figure()
    fig.add_subplot().plot([0, 1], [1, 0])
    save_figure(fig, tmp_path / "a.png", dpi=50)
    save_figure(fig, str(tmp_path / "b.svg"))
    assert (tmp_path / "a.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert b"<svg" in (tmp_path / "b.svg").read_bytes()[:400]
    calls = []
    monkeypatch.setattr(Figure, "savefig", lambda self, fh, **kw: (calls.append(kw), fh.write(b"\x89PNG partial"), 1 / 0))
    with pytest.raises(ZeroDivisionError):
        save_figure(fig, tmp_path / "a.png")
    assert calls == [{"format": "png"}] and (tmp_path / "a.png").stat().st_size > 100  # the old figure
    assert leftovers(tmp_path) == []


def test_a_killed_writers_temporary_file_is_removed_by_the_next_write(tmp_path):
    """SIGKILL runs no handler: ``simulate --out`` killed mid-write left its partial temporary
    file behind; the next write of that file removes it (its writer no longer runs)."""
    import subprocess
    import sys

    target = tmp_path / "sim.csv"
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        alive = tmp_path / f".sim.csv.{child.pid}.0123456789ab.tmp"  # a writer still at work: kept
        alive.write_text("partial")
    finally:
        child.kill()
        child.wait()
    dead = tmp_path / f".sim.csv.{child.pid}.0123456789ab.tmp"
    assert dead.exists()
    other = tmp_path / f".other.csv.{child.pid}.0123456789ab.tmp"  # another file's: not ours to remove
    other.write_text("partial")
    running = tmp_path / f".sim.csv.{os.getpid()}.ba9876543210.tmp"
    running.write_text("partial")  # this process's own, still writing
    write_text(target, "done")
    assert target.read_text() == "done"
    assert not dead.exists() and other.exists() and running.exists()


def test_a_folder_as_the_target_is_named(tmp_path):
    with pytest.raises(IsADirectoryError, match="is a folder") as info:
        write_text(tmp_path, "x")
    assert info.value.filename == str(tmp_path)
    res = run("export", "--format", "json", "--out", tmp_path, _model(tmp_path))
    assert res.exit_code == 1 and res.output.startswith(f"Error: {tmp_path}: is a folder") and ".tmp" not in res.output


def _model(folder):
    path = folder / "model.json"
    path.write_text(bx.example1().to_json())
    return path
