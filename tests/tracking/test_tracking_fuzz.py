"""Fuzz the tracking entry points (Tracker, its update, track) in the manner of
tests/test_fuzz.py: generated valid and junk arguments; every call returns finite numbers or
raises one of the library's exceptions (never a Rust panic or a Python internal), leaves the
caller's arrays unchanged, and a restored pickle continues with the same bits."""

from __future__ import annotations

import copy
import pickle
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import backlashid as bid
from backlashid import BacklashIdError
from backlashid.identify import Structure

finite = dict(allow_nan=False, allow_infinity=False)
JUNK = st.one_of(
    st.none(),
    st.booleans(),
    st.floats(),
    st.integers(-(10**30), 10**30),
    st.just(10**400),
    st.text(max_size=4),
    st.just(1 + 2j),
    st.lists(st.floats(), max_size=4),
    st.just(np.zeros((3, 4))),
    st.just(np.zeros(0)),
    st.just(np.array(["1.0"] * 3)),
    st.dictionaries(st.text(max_size=3), st.integers(), max_size=2),
)


def maybe(valid: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    """A valid value 7 times in 8, else junk."""
    return st.sampled_from([True] * 7 + [False]).flatmap(lambda ok: valid if ok else JUNK)


@st.composite
def cascades(draw: Any) -> bid.CascadeModel:
    a = draw(st.lists(st.floats(-2.0, 2.0, **finite).filter(lambda v: abs(v) > 1e-3), min_size=1, max_size=3))
    poles = draw(st.lists(st.floats(-0.8, 0.8, **finite), max_size=2))
    b = list(np.poly(poles)[1:]) if poles else []
    c_l, c_r = draw(st.floats(0.0, 0.5, **finite)), draw(st.floats(0.0, 0.5, **finite))
    m_l = [draw(st.floats(0.5, 2.0, **finite))] + draw(st.lists(st.floats(-0.05, 0.05, **finite), max_size=2))
    m_r = [draw(st.floats(0.5, 2.0, **finite))] + draw(st.lists(st.floats(-0.05, 0.05, **finite), max_size=2))
    return bid.CascadeModel(bid.LinearBlock(a, b), bid.GeneralBacklash(c_l, c_r, m_l, m_r))


STARTS = st.sampled_from(["example1", "cascade", "structure", "example2", "junk"]).flatmap(
    lambda kind: {
        "example1": st.just(bid.example1()),
        "cascade": cascades(),
        "structure": st.builds(Structure, st.integers(1, 3), st.integers(0, 2), st.integers(1, 3)),
        "example2": st.just(bid.example2()),
        "junk": JUNK,
    }[kind]
)


@st.composite
def signal_pairs(draw: Any) -> tuple[Any, Any]:
    n = draw(st.integers(0, 60))
    u = np.array(draw(st.lists(st.floats(-2, 2, **finite), min_size=n, max_size=n)))
    y = np.array(draw(st.lists(st.floats(-5, 5, **finite), min_size=n, max_size=n)))
    how = draw(st.sampled_from(["clean"] * 5 + ["nan", "huge", "short", "list", "2d", "junk"]))
    if how == "nan" and n:
        y[draw(st.integers(0, n - 1))] = np.nan
    elif how == "huge" and n:
        u[draw(st.integers(0, n - 1))] = 1e300
    elif how == "short" and n:
        y = y[:-1]
    elif how == "list":
        return u.tolist(), y.tolist()
    elif how == "2d":
        return u.reshape(1, -1), y
    elif how == "junk":
        return u, draw(JUNK)
    return u, y


def outcome(f: Any, *args: Any, **kwargs: Any) -> tuple[str, Any]:
    before = copy.deepcopy((args, kwargs))
    try:
        result = ("ok", f(*args, **kwargs))
    except (BacklashIdError, MemoryError) as exc:
        assert str(exc)
        result = ("error", exc)
    except BaseException as exc:
        if type(exc).__name__ == "PanicException":
            pytest.fail(f"Rust panic: {exc}")
        raise
    after = (args, kwargs)
    assert repr(after) == repr(before) or all(
        np.array_equal(np.asarray(x, dtype=object), np.asarray(y, dtype=object)) for x, y in zip(after[0], before[0])
    ), "the caller's arguments changed"
    return result


def finite_result(r: bid.TrackResult) -> None:
    assert np.all(np.isfinite(r.theta)) and np.all(np.isfinite(r.standard_errors)), r
    assert all(np.isfinite([a.width, a.reference, a.statistic]).all() for a in r.alarms)


@settings(
    max_examples=250,
    deadline=5000,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
@given(
    start=STARTS,
    method=maybe(st.sampled_from(["prediction_error", "regression"])),
    forgetting=maybe(st.one_of(st.none(), st.floats(0.5, 1.0, **finite))),
    drift=maybe(st.one_of(st.none(), st.floats(0.0, 1e-2, **finite), st.just({"c_R": 1e-3}))),
    noise_std=maybe(st.one_of(st.none(), st.floats(1e-3, 1.0, **finite))),
    spacing=maybe(st.one_of(st.none(), st.integers(1, 50))),
    first=signal_pairs(),
    second=signal_pairs(),
    every=maybe(st.integers(1, 7)),
)
def test_tracking_never_panics_and_resumes_alike(start, method, forgetting, drift, noise_std, spacing, first, second, every):
    options = dict(method=method, forgetting=forgetting, drift=drift, noise_std=noise_std, spacing=spacing)
    kind, tracker = outcome(bid.Tracker, start, **options)
    if kind == "error":
        return
    kind, r = outcome(tracker.update, *first, every=every)
    if kind == "ok":
        finite_result(r)
    twin = pickle.loads(pickle.dumps(tracker))
    kind, r = outcome(tracker.update, *second, every=every)
    kind2, r2 = outcome(twin.update, *second, every=every)
    assert kind == kind2
    if kind == "ok":
        finite_result(r)
        assert np.array_equal(r.theta, r2.theta) and np.array_equal(r.standard_errors, r2.standard_errors)
        assert r.alarms == r2.alarms
    else:
        assert type(r) is type(r2) and str(r) == str(r2)
    kind, whole = outcome(bid.track, *first, start, every=every, **options)
    if kind == "ok":
        finite_result(whole)
