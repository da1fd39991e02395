"""Every entry point accepts lists, tuples, float32/int/bool arrays, non-contiguous and
read-only arrays, gives the float64 result of the same values, returns float64 arrays, and
never modifies the caller's data."""

from __future__ import annotations

import numpy as np
import pytest

import backlashid as bx

BASE = np.array([0.0, 0.5, 1.5, 1.25, -0.75, -2.0, -1.5, 0.25, 2.0, 2.0, 1.0, -3.0])


def entry_points():
    m1, m2 = bx.example1(), bx.example2()
    bl, g = m1.backlash, m1.linear
    return {
        "backlash.simulate": lambda v: bl.simulate(v),
        "backlash.simulate breakpoints": lambda v: bl.simulate(v, form="breakpoints"),
        "backlash.switching": lambda v: bl.switching(v).y,
        "backlash.left": lambda v: bl.left(v),
        "backlash.right": lambda v: bl.right(v),
        "linear.simulate": lambda v: g.simulate(v),
        "cascade.simulate": lambda v: m1.simulate(v),
        "cascade.internals": lambda v: m1.simulate(v, internals=True).x,
        "sandwich.simulate": lambda v: m2.simulate(v),
        "sandwich.internals": lambda v: m2.simulate(v, internals=True).y,
    }


def readonly(a):
    a = np.array(a)
    a.setflags(write=False)
    return a


def strided(a):
    buf = np.zeros(2 * len(a))
    buf[::2] = a
    view = buf[::2]
    assert not view.flags.c_contiguous
    return view


def reversed_view(a):
    return np.array(a[::-1])[::-1]


VARIANTS = {
    "list": lambda a: a.tolist(),
    "tuple": lambda a: tuple(a.tolist()),
    "float64": lambda a: a.copy(),
    "readonly": readonly,
    "strided x[::2]": strided,
    "negative stride": reversed_view,
    "readonly strided": lambda a: _ro_strided(a),
    "big-endian": lambda a: a.astype(">f8"),
    "fortran 1-D": lambda a: np.asfortranarray(a),
}


def _ro_strided(a):
    view = strided(a)
    view.setflags(write=False)
    return view


@pytest.mark.parametrize("name", list(entry_points()))
@pytest.mark.parametrize("variant", list(VARIANTS))
def test_array_likes_give_the_float64_result(name, variant):
    f = entry_points()[name]
    expected = f(BASE.copy())
    arg = VARIANTS[variant](BASE)
    before = np.array(arg, copy=True)
    got = f(arg)
    assert isinstance(got, np.ndarray) and got.dtype == np.float64 and got.ndim == 1
    np.testing.assert_array_equal(got, expected)
    np.testing.assert_array_equal(np.asarray(arg), before)  # caller's data unchanged


@pytest.mark.parametrize("name", list(entry_points()))
@pytest.mark.parametrize("dtype", [np.float32, np.int64, np.int32, np.uint8, np.float16, bool])
def test_other_dtypes_are_converted(name, dtype):
    f = entry_points()[name]
    values = np.array([0, 1, 3, 2, 0, 1, 1], dtype=dtype)
    before = values.copy()
    got = f(values)
    assert got.dtype == np.float64
    np.testing.assert_array_equal(got, f(values.astype(np.float64)))
    np.testing.assert_array_equal(values, before)
    assert values.dtype == dtype


def test_float32_values_are_used_as_given():
    x32 = np.array([0.1, 1.7, -1.3], dtype=np.float32)
    bl = bx.example1().backlash
    np.testing.assert_array_equal(bl.simulate(x32), bl.simulate(x32.astype(np.float64)))


def test_int_list_and_scalars_in_a_list():
    bl = bx.example1().backlash
    np.testing.assert_array_equal(bl.simulate([0, 2, -2]), bl.simulate([0.0, 2.0, -2.0]))
    np.testing.assert_array_equal(bl.simulate([np.float32(2.0), 1]), bl.simulate([2.0, 1.0]))


def test_outputs_are_fresh_float64_arrays_and_flags_are_bool():
    m1, m2 = bx.example1(), bx.example2()
    u = np.linspace(-1, 1, 40)
    sim = m1.simulate(u, internals=True)
    for arr in (sim.output, sim.x):
        assert arr.dtype == np.float64 and arr.shape == u.shape
    assert sim.f1.dtype == np.bool_ and sim.f2.dtype == np.bool_
    sim2 = m2.simulate(u, internals=True)
    for arr in (sim2.output, sim2.x, sim2.y):
        assert arr.dtype == np.float64 and arr.shape == u.shape
    sw = m1.backlash.switching(u)
    for arr in (sw.xi1, sw.xi2, sw.y):
        assert arr.dtype == np.float64
    # results do not alias the input
    y = m1.backlash.simulate(u)
    assert not np.shares_memory(y, u)
    y[:] = 99.0
    assert np.all(u <= 1.0)


def test_states_and_pasts_are_not_modified():
    m1, m2 = bx.example1(), bx.example2()
    u = np.linspace(-1, 1, 10)
    u.setflags(write=False)
    u_past, x_past = np.array([0.3, -0.1]), np.array([0.2, 0.4])[::-1]
    keep = (u_past.copy(), x_past.copy())
    m1.linear.simulate(u, u_past=u_past, x_past=x_past)
    s = bx.CascadeState(u_past, x_past, 0.1)
    m1.simulate(u, initial_state=s, internals=True)
    np.testing.assert_array_equal(u_past, keep[0])
    np.testing.assert_array_equal(x_past, keep[1])
    y_past = np.array([0.1, 0.2])
    ss = bx.SandwichState(u_past, x_past, y_past, [0.0, 0.0])
    m2.simulate(u, initial_state=ss, internals=True)
    np.testing.assert_array_equal(y_past, [0.1, 0.2])


def test_state_array_likes_are_equivalent():
    m1 = bx.example1()
    u = np.linspace(-1, 1, 10)
    ref = m1.simulate(u, initial_state=bx.CascadeState((0.3, -0.1), (0.2, 0.4), 0.1))
    for s in (
        bx.CascadeState([0.3, -0.1], [0.2, 0.4], 0.1),
        bx.CascadeState(np.array([0.3, -0.1], dtype=np.float64), np.array([0.2, 0.4]), np.float64(0.1)),
    ):
        np.testing.assert_array_equal(m1.simulate(u, initial_state=s), ref)


def test_model_parameters_cannot_be_changed_behind_its_back():
    m_left = np.array([1.0, -0.3, 0.3])
    bl = bx.GeneralBacklash(0.6, 0.5, m_left, [1.5, 0.4, 0.2])
    m_left[0] = -5.0  # the caller's array is not shared with the model
    assert bl.m_left[0] == 1.0
    with pytest.raises(ValueError):
        bl.m_left[0] = 2.0
    assert bl == bx.example1().backlash
