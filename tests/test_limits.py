"""Resource limits (issue 21): memory that cannot be allocated raises MemoryError instead of
aborting the interpreter, absurd orders are refused before anything proportional to them is
built, Ctrl-C interrupts long Rust calls, and a fit's time budget ends it with
NotConvergedError carrying its best estimate."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import backlashid as bid
from backlashid._validation import CHUNK, _reverses
from backlashid.identify import Structure, levenberg_marquardt

PYTHON_DIR = str(Path(bid.__file__).resolve().parents[1])
LINUX = sys.platform.startswith("linux")


def _child(code: str) -> subprocess.Popen[str]:
    """A Python subprocess running ``code`` with this checkout's package first on the path."""
    env = {**os.environ, "PYTHONPATH": PYTHON_DIR + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.Popen(
        [sys.executable, "-c", textwrap.dedent(code)], env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )


# The child caps its own address space (what `prlimit --as` does) at what it uses after the
# imports plus `room` bytes, so that the record fits but the Rust output does not.
_LIMITED = """
import resource, numpy as np, backlashid as bid
from backlashid.identify import Structure
def vm_bytes():
    for line in open("/proc/self/status"):
        if line.startswith("VmSize:"):
            return int(line.split()[1]) * 1024
n = 120_000_000  # 0.96 GB per signal
u = np.zeros(n)
u[::1000] = 1.0  # touched: the record is really there
room = 600_000_000  # less than one more signal
limit = vm_bytes() + room
resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
"""


@pytest.mark.skipif(not LINUX, reason="address-space limits (RLIMIT_AS) are Linux only")
@pytest.mark.parametrize(
    "call",
    [
        "bid.example1().simulate(u)",
        "bid.example2().simulate(u)",
        "bid.example1().linear.simulate(u)",
        "bid.example1().backlash.simulate(u)",
        "bid.example1().simulate(u, internals=True)",
        "Structure(2, 2, 3).problem(u, u).simulate(Structure(2, 2, 3).pack(bid.example1()))",
    ],
)
def test_an_allocation_that_cannot_be_satisfied_raises_memory_error(call: str) -> None:
    child = _child(
        _LIMITED
        + f"""
try:
    {call}
    print("no error")
except MemoryError as exc:
    print("MemoryError:", exc)
"""
    )
    out, err = child.communicate(timeout=120)
    assert child.returncode == 0, err[-2000:]  # no abort (SIGABRT: -6)
    assert out.startswith("MemoryError: cannot allocate"), (out, err[-2000:])


@pytest.mark.skipif(not LINUX, reason="address-space limits (RLIMIT_AS) are Linux only")
def test_a_problem_reads_its_record_in_place_and_sums_its_cost_without_a_record_sized_buffer() -> None:
    # the room above holds less than one more signal: compiling the problem (no copy of u, y)
    # and its cost (summed as the simulation runs) fit in it
    child = _child(
        _LIMITED
        + """
s = Structure(2, 2, 3)
print("cost", s.problem(u, u).cost(s.pack(bid.example1())))
"""
    )
    out, err = child.communicate(timeout=120)
    assert child.returncode == 0, err[-2000:]
    assert out.startswith("cost "), (out, err[-2000:])
    assert float(out.split()[1]) > 0


@pytest.mark.skipif(not LINUX, reason="address-space limits (RLIMIT_AS) are Linux only")
def test_a_fits_record_checks_need_no_record_sized_buffer() -> None:
    # issue 31's 1e8-sample fit: the checks that the input reverses and is not the output
    # itself once made an array of the record's steps (+760 MB at 1e8 samples)
    child = _child(
        """
import resource, numpy as np
from backlashid._validation import identification_record
def vm_bytes():
    for line in open("/proc/self/status"):
        if line.startswith("VmSize:"):
            return int(line.split()[1]) * 1024
n = 120_000_000  # 0.96 GB per signal
u, y = np.zeros(n), np.zeros(n)
u[::1000] = 1.0  # rises and falls
y[1::1000] = 1.0  # and the output is another signal
limit = vm_bytes() + 600_000_000  # less than one more signal
resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
identification_record(u, y, y_name="y", warmup=0, parameters=10, constant_input=ValueError)
print("checked")
"""
    )
    out, err = child.communicate(timeout=120)
    assert child.returncode == 0 and out.startswith("checked"), err[-2000:]


@pytest.mark.parametrize("at", [1, CHUNK - 1, CHUNK, CHUNK + 1, 2 * CHUNK + 2])
def test_the_chunked_reversal_check_sees_a_fall_at_any_step(at: int) -> None:
    # the step from sample at - 1 to at falls, every other one rises: the chunks overlap by one
    u = np.arange(2 * CHUNK + 3, dtype=np.float64)
    assert not _reverses(u) and not _reverses(u[::-1].copy())
    u[at:] -= 2.0
    assert _reverses(u)


def test_absurd_orders_are_refused_before_anything_is_built() -> None:
    start = time.perf_counter()
    with pytest.raises(bid.ModelError, match=r"b has 2000 coefficients.*at most 200"):
        bid.LinearBlock([1.0], [1e-3] * 2000)
    d = bid.example_data(bid.example1(), 400, seed=1)
    for kwargs, name in ((dict(na=10**9), "na"), (dict(nb=10**9), "nb"), (dict(degree=10**9), "degree")):
        with pytest.raises(bid.ModelError, match=rf"^{name} = 1000000000: orders and the degree are at most 200"):
            bid.fit_cascade(d.u, d.noisy, **kwargs)
    with pytest.raises(bid.ModelError, match=r"^ns = 1000000000"):
        bid.fit_sandwich(d.u, d.noisy, ns=10**9)
    with pytest.raises(bid.ModelError, match=r"^na = 1000000000"):
        _ = Structure(10**9, 2, 3).names
    assert time.perf_counter() - start < 30  # no minute of growing memory (not a timing test: a hang guard)
    # the cap itself is usable: 200 poles in well under a second
    assert bid.LinearBlock([1.0], [1e-3] * 200).poles().size == 200


# the child prints "ready" just before the long Rust call, then what ended it
_INTERRUPTED = """
import signal, sys, time, numpy as np, backlashid as bid
signal.signal(signal.SIGINT, signal.default_int_handler)
{setup}
print("ready", flush=True)
try:
    {call}
    print("finished")
except KeyboardInterrupt:
    print("KeyboardInterrupt")
"""


@pytest.mark.skipif(not LINUX, reason="POSIX signals")
@pytest.mark.parametrize(
    ("setup", "call"),
    [
        # one Rust call of about a minute: a root search per sample
        (
            "x = np.sin(np.arange(10_000_000) * 0.01)",
            "bid.example1().backlash.simulate(x, form='breakpoints')",
        ),
        # a fit on a long record: Rust passes with Python between them
        (
            "d = bid.example_data(bid.example1(), 3_000_000, snr=25, seed=0)",
            "bid.fit_cascade(d.u, d.noisy, coarse=0)",
        ),
    ],
    ids=["breakpoints", "fit"],
)
def test_ctrl_c_interrupts_a_long_call(setup: str, call: str) -> None:
    child = _child(_INTERRUPTED.format(setup=setup, call=call))
    assert child.stdout is not None
    assert child.stdout.readline().strip() == "ready"
    time.sleep(1.0)
    child.send_signal(signal.SIGINT)
    sent = time.monotonic()
    out, err = child.communicate(timeout=60)
    waited = time.monotonic() - sent
    assert out.strip() == "KeyboardInterrupt", (out, err[-2000:])
    assert child.returncode == 0
    assert waited < 10, waited  # within a few seconds, not after the call (a hang guard)


def test_a_fit_out_of_time_raises_not_converged_with_its_best_estimate() -> None:
    d = bid.example_data(bid.example1(), 20_000, snr=25, seed=0)
    with pytest.raises(bid.NotConvergedError, match=r"ran out of its time budget \(time_budget = 0.001 s\)") as info:
        bid.fit_cascade(d.u, d.noisy, time_budget=0.001)
    assert info.value.best is not None and not info.value.best.converged
    assert info.value.best_stable is not None and info.value.best_stable.model is not None
    with pytest.raises(bid.NotConvergedError, match="time budget"):
        bid.fit_sandwich(d.u, bid.example2().simulate(d.u), time_budget=0.001)


def test_a_generous_time_budget_changes_nothing() -> None:
    d = bid.example_data(bid.example1(), 3000, snr=25, seed=0)
    free = bid.fit_cascade(d.u, d.noisy)
    budgeted = bid.fit_cascade(d.u, d.noisy, time_budget=3600.0)
    assert np.array_equal(free.theta, budgeted.theta) and budgeted.converged


@pytest.mark.parametrize("bad", [0, -1.0, float("nan"), float("inf"), "10", True])
def test_a_time_budget_must_be_positive_seconds(bad: object) -> None:
    d = bid.example_data(bid.example1(), 1000, seed=0)
    with pytest.raises(bid.DataError, match="time_budget = .*: give a number of seconds > 0"):
        bid.fit_cascade(d.u, d.noisy, time_budget=bad)


def test_levenberg_marquardt_out_of_time_ends_like_max_iter() -> None:
    d = bid.example_data(bid.example1(), 5000, snr=25, seed=3)
    s = Structure(2, 2, 3)
    start = s.pack(bid.example1()) + 0.05
    prob = s.problem(d.u, d.noisy)
    cut = levenberg_marquardt(prob, start, time_budget=1e-9)
    assert not cut.converged and cut.iterations == 0 and np.array_equal(cut.theta, start)
    free = levenberg_marquardt(prob, start)
    assert free.converged and free.iterations > 0
    assert np.array_equal(levenberg_marquardt(prob, start, time_budget=3600.0).theta, free.theta)
