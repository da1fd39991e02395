"""Shared fixtures, hypothesis strategies and independent (pure numpy / python) reference
implementations of the paper's equations, written from the paper, not from the library."""

from __future__ import annotations

import os
from pathlib import Path

os.environ.setdefault("MPLBACKEND", "Agg")

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, settings
from hypothesis import strategies as st

import backlashid as bx

settings.register_profile(
    "backlashid",
    derandomize=True,
    max_examples=60,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
    print_blob=True,
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "backlashid"))


def _shared_data() -> Path:
    """The measured benchmark records (read in place); a missing folder makes the tests that
    read them skip."""
    try:
        return bx.benchmarks.shared_data_folder(Path(__file__).parent)
    except bx.DataError:
        return Path(__file__).parent / "no-shared-data"


SHARED_DATA = _shared_data()
BENCHES = Path(__file__).resolve().parents[1] / "benches"


def load_bench(script: str, module: str | None = None):
    """The benchmark script ``benches/<script>.py`` imported once as ``module`` (default: the
    script's name) and registered in ``sys.modules`` (its dataclasses look their module up)."""
    import importlib.util
    import sys

    name = module or script
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, BENCHES / f"{script}.py")
        assert spec is not None and spec.loader is not None
        mod = importlib.util.module_from_spec(spec)
        sys.modules[name] = mod
        spec.loader.exec_module(mod)
    return sys.modules[name]


def assert_final_seeds_refused(ceiling, generator, row: str, level: float) -> None:
    """A ceiling script (``ceiling``, over the cases of ``generator``) refuses the final seeds
    (``oracle_case(row, level, 0, "final")``) and draws its null cases from a seed set of its
    own, disjoint from the tune and final sets."""
    with pytest.raises(ValueError):
        ceiling.oracle_case(row, level, 0, "final")
    assert generator.SEED_SETS[ceiling.NULL_SET] not in (generator.SEED_SETS["tune"], generator.SEED_SETS["final"])
    a = generator.case_rng(row, 0.0, 0, ceiling.NULL_SET).standard_normal(4)
    b = generator.case_rng(row, 0.0, 0, "tune").standard_normal(4)
    assert not np.allclose(a, b)

X_MAX = 2.0  # inputs x of the backlash are drawn from [-X_MAX, X_MAX]


# --------------------------------------------------------------------------- references
def branch_value(m, shift, x):
    """sum_i m_i (x + shift)^i, i = 1..n (eq 4-5), as numpy.polyval of [m_n, .., m_1, 0]
    in xi = x + shift (Horner's rule, so the rounding is that of any Horner evaluation)."""
    xi = np.asarray(x, dtype=float) + shift
    return np.polyval(np.r_[np.asarray(m, dtype=float)[::-1], 0.0], xi)


def ref_L(bl, x):
    return branch_value(bl.m_left, bl.c_left, x)


def ref_R(bl, x):
    return branch_value(bl.m_right, -bl.c_right, x)


def ref_linear(a, b, u, u_past=None, x_past=None):
    """Eq (16) by a plain loop: x(t) = sum a_i u(t-i) - sum b_j x(t-j); u_past = [u(0), u(-1), ..]."""
    a, b = list(a), list(b)
    u_past = list(u_past) if u_past is not None else [0.0] * len(a)
    x_past = list(x_past) if x_past is not None else [0.0] * len(b)
    uu = list(reversed(u_past)) + [float(v) for v in u]  # oldest first
    xx = list(reversed(x_past))
    off_u, off_x = len(u_past), len(x_past)
    out = []
    for t in range(len(u)):
        acc = 0.0
        for i, ai in enumerate(a, 1):
            acc += ai * uu[off_u + t - i]
        for j, bj in enumerate(b, 1):
            acc -= bj * xx[off_x + t - j]
        xx.append(acc)
        out.append(acc)
    return np.array(out)


def ref_backlash(bl, x, y0=0.0):
    """Eq (1) with the case order L, then R, else hold (NOTES.md item 2)."""
    y_prev, out = float(y0), []
    for xt in x:
        left = float(ref_L(bl, xt))
        right = float(ref_R(bl, xt))
        if left <= y_prev:
            y_prev = left
        elif right >= y_prev:
            y_prev = right
        out.append(y_prev)
    return np.array(out)


def ref_cascade(model, u, state=None):
    state = state or model.rest_state()
    x = ref_linear(model.linear.a, model.linear.b, u, state.u_past, state.x_past)
    return x, ref_backlash(model.backlash, x, state.y_prev)


def ref_sandwich(model, u, state=None):
    state = state or model.rest_state()
    x = ref_linear(model.input_linear.a, model.input_linear.b, u, state.u_past, state.x_past)
    y = ref_backlash(model.backlash, x, state.y_past[0])
    w = ref_linear(model.r, model.s, y, state.y_past, state.w_past)
    return x, y, w


# --------------------------------------------------------------------------- strategies
finite = dict(allow_nan=False, allow_infinity=False)


@st.composite
def backlashes(draw, x_max=X_MAX, max_degree=4, require_valid=False):
    """A general backlash whose branches increase on [-x_max, x_max] (and, with
    require_valid, do not cross there either)."""
    degree_l = draw(st.integers(1, max_degree))
    degree_r = draw(st.integers(1, max_degree))
    c_l = draw(st.floats(0.0, 1.0, **finite))
    c_r = draw(st.floats(0.0, 1.0, **finite))
    reach = x_max + 1.0  # |x +- c| <= reach on the range

    def coefficients(degree):
        m1 = draw(st.floats(0.1, 3.0, **finite))
        higher = [
            m1 * draw(st.floats(-1.0, 1.0, **finite)) / (i * reach ** (i - 1))
            for i in range(2, degree + 1)
        ]
        return [m1, *higher]

    m_l, m_r = coefficients(degree_l), coefficients(degree_r)
    try:
        bl = bx.GeneralBacklash(c_l, c_r, m_l, m_r)
    except bx.ModelError:
        assume(False)
    check = bl.check_branches(-x_max, x_max)
    assume(not check.left_not_increasing and not check.right_not_increasing)
    if require_valid:
        assume(check.is_valid)
    return bl


@st.composite
def backlash_inputs(draw, n_max=60, x_max=X_MAX):
    """x sequences with ties: values from a small pool, explicit repeats, and free values."""
    n = draw(st.integers(1, n_max))
    pool = draw(st.lists(st.floats(-x_max, x_max, **finite), min_size=1, max_size=5))
    xs = []
    for _ in range(n):
        kind = draw(st.sampled_from(["pool", "repeat", "free"]))
        if kind == "repeat" and xs:
            xs.append(xs[-1])
        elif kind == "pool":
            xs.append(draw(st.sampled_from(pool)))
        else:
            xs.append(draw(st.floats(-x_max, x_max, **finite)))
    return np.array(xs)


@st.composite
def stable_blocks(draw, max_na=4, max_nb=3):
    """A stable linear block: b from poles drawn inside the disc of radius 0.9."""
    na = draw(st.integers(1, max_na))
    a = draw(st.lists(st.floats(-2.0, 2.0, **finite), min_size=na, max_size=na))
    assume(any(abs(v) > 1e-3 for v in a))
    nb = draw(st.integers(0, max_nb))
    poles = []
    while len(poles) < nb:
        if nb - len(poles) >= 2 and draw(st.booleans()):
            r = draw(st.floats(0.0, 0.9, **finite))
            phi = draw(st.floats(0.0, np.pi, **finite))
            p = r * np.exp(1j * phi)
            poles += [p, np.conj(p)]
        else:
            poles.append(draw(st.floats(-0.9, 0.9, **finite)))
    b = np.real(np.poly(poles))[1:] if poles else []
    return bx.LinearBlock(a, list(b))


@st.composite
def cascades(draw):
    return bx.CascadeModel(draw(stable_blocks()), draw(backlashes(x_max=6.0, max_degree=3)))


@st.composite
def sandwiches(draw):
    return bx.SandwichModel(
        draw(stable_blocks()), draw(backlashes(x_max=6.0, max_degree=3)), draw(stable_blocks())
    )


def inputs(n_min=1, n_max=80, amp=1.0):
    return st.lists(st.floats(-amp, amp, **finite), min_size=n_min, max_size=n_max).map(np.array)


# --------------------------------------------------------------------------- fixtures
@pytest.fixture
def ex1():
    return bx.example1()


@pytest.fixture
def ex2():
    return bx.example2()


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


# --------------------------------------------------------------------------- isolation
HANG_TIMEOUT = 5.0  # seconds; the call itself takes milliseconds


def run_isolated(code: str, timeout: float = HANG_TIMEOUT) -> str:
    """Run ``code`` in a fresh interpreter (a call that never returns cannot stop the suite:
    the Rust core holds the GIL, so it cannot be interrupted in-process). Returns stdout;
    fails the test on a hang or a non-zero exit."""
    import subprocess
    import sys

    try:
        done = subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, timeout=timeout
        )
    except subprocess.TimeoutExpired:
        pytest.fail(f"did not return within {timeout:g} s (hangs):\n{code}", pytrace=False)
    assert done.returncode == 0, done.stderr
    return done.stdout
