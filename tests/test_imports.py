"""``import backlashid`` and ``backlashid --help`` stay fast: the heavy dependencies (scipy's
statistics and optimisation, matplotlib, Dask, pandas) are imported when first needed, not at
import. A property of the imported-module list, not a timing (issue 21)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

import backlashid

HEAVY = ("scipy.stats", "scipy.optimize", "scipy.signal", "matplotlib", "dask", "distributed", "pandas")


def imported_modules(code: list[str]) -> set[str]:
    """The modules ``python -X importtime`` reports for a fresh interpreter running ``code``."""
    package_root = str(Path(backlashid.__file__).resolve().parents[1])  # this checkout's backlashid
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([package_root, os.environ.get("PYTHONPATH", "")])}
    run = subprocess.run([sys.executable, "-X", "importtime", *code], env=env, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    names = {line.rsplit("|", 1)[1].strip() for line in run.stderr.splitlines() if line.startswith("import time:") and line.count("|") == 2}
    assert "backlashid" in names, "the subprocess did not import backlashid"
    return names


def heavy(names: set[str]) -> list[str]:
    return sorted(n for n in names if any(n == h or n.startswith(h + ".") for h in HEAVY))


@pytest.mark.parametrize(
    "code",
    [
        ["-c", "import backlashid"],
        ["-m", "backlashid", "--help"],
        ["-m", "backlashid", "fit", "--help"],
    ],
    ids=["import", "help", "fit-help"],
)
def test_import_and_help_load_no_heavy_dependency(code: list[str]) -> None:
    names = imported_modules(code)
    assert not heavy(names), f"{' '.join(code)} imports {heavy(names)[:10]}: import them inside the functions that need them"


def test_lazy_names_are_the_subpackages_objects() -> None:
    import backlashid.app
    import backlashid.benchmarks
    import backlashid.diagnosis

    assert backlashid.diagnose is backlashid.diagnosis.diagnose
    assert backlashid.fit_many is backlashid.app.fit_many
    assert backlashid.example1 is backlashid.benchmarks.example1
    assert set(backlashid.__all__) <= set(dir(backlashid))
    with pytest.raises(AttributeError, match="no attribute 'not_a_name'"):
        backlashid.not_a_name  # noqa: B018
