"""Bad inputs raise DataError / ModelError (subclasses of BacklashIdError and ValueError)
with a message that says what is wrong; nothing else (no PanicException, no TypeError)."""

from __future__ import annotations

import json

import numpy as np
import pytest

import backlashid as bx
from backlashid.errors import BacklashIdError, DataError, ModelError
from conftest import run_isolated


def test_error_hierarchy():
    for cls in (DataError, ModelError):
        assert issubclass(cls, BacklashIdError) and issubclass(cls, ValueError)
    assert bx.DataError is DataError and bx.ModelError is ModelError
    assert not issubclass(DataError, ModelError) and not issubclass(ModelError, DataError)


def signal_entry_points():
    m1, m2 = bx.example1(), bx.example2()
    bl = m1.backlash
    return {
        "backlash.simulate": lambda v: bl.simulate(v),
        "backlash.breakpoints form": lambda v: bl.simulate(v, form="breakpoints"),
        "backlash.switching": lambda v: bl.switching(v),
        "linear.simulate": lambda v: m1.linear.simulate(v),
        "cascade.simulate": lambda v: m1.simulate(v),
        "cascade.internals": lambda v: m1.simulate(v, internals=True),
        "sandwich.simulate": lambda v: m2.simulate(v),
        "sandwich.internals": lambda v: m2.simulate(v, internals=True),
    }


BAD_SIGNALS = {
    "nan": ([0.1, np.nan, 0.3], "nan"),
    "inf": ([np.inf, 1.0], "inf"),
    "-inf": (np.array([0.0, 0.0, -np.inf]), "inf"),
    "2-D": (np.ones((4, 2)), "1-d"),
    "column": (np.ones((4, 1)), "1-d"),
    "0-D scalar": (1.0, "1-d"),
    "empty list": ([], "empty"),
    "empty array": (np.array([]), "empty"),
    "strings": (["a", "b"], "number"),
    "complex": ([1 + 1j, 2.0], "complex"),
    "complex array": (np.array([1.0, 2.0], dtype=complex), "complex"),
    "ragged": ([[1.0, 2.0], [3.0]], "array of numbers"),
    "None": (None, ""),
    "dict": ({"a": 1}, ""),
}


@pytest.mark.parametrize("entry", list(signal_entry_points()))
@pytest.mark.parametrize("bad", list(BAD_SIGNALS))
def test_bad_signals_raise_data_error(entry, bad):
    value, word = BAD_SIGNALS[bad]
    with pytest.raises(DataError) as info:
        signal_entry_points()[entry](value)
    assert word in str(info.value).lower()
    assert isinstance(info.value, ValueError)


@pytest.mark.parametrize(
    "value",
    [
        np.array(["1.0", "2.0"]),  # numbers as text: the caller should convert explicitly
        np.array(["2020-01-01", "2020-01-02"], dtype="datetime64[D]"),
        np.array([1, 2], dtype="timedelta64[s]"),
    ],
    ids=["numeric strings", "datetime64", "timedelta64"],
)
def test_non_numeric_dtypes_raise_data_error(value):
    """_convert.as_signal says non-numeric dtypes are errors ("has dtype ..., not numbers")
    but converts anything astype(float64) accepts: text and dates pass as numbers."""
    for entry in ("backlash.simulate", "cascade.simulate"):
        with pytest.raises(DataError, match="dtype"):
            signal_entry_points()[entry](value)


def test_nan_message_names_the_sample():
    with pytest.raises(DataError, match=r"u\[2\]"):
        bx.example1().simulate([0.0, 1.0, np.nan])


# ------------------------------------------------------------------ initial states
def test_wrong_initial_states_raise_data_error():
    m1, m2 = bx.example1(), bx.example2()
    u = [0.1, 0.2]
    cases = [
        lambda: m1.linear.simulate(u, u_past=[1.0]),
        lambda: m1.linear.simulate(u, x_past=[1.0, 2.0, 3.0]),
        lambda: m1.simulate(u, initial_state=bx.CascadeState([0.0], [0.0, 0.0])),
        lambda: m1.simulate(u, initial_state=bx.CascadeState([0.0, 0.0], [0.0])),
        lambda: m2.simulate(u, initial_state=bx.SandwichState([0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 0.0])),
        lambda: m2.simulate(u, initial_state=bx.SandwichState([0.0, 0.0], [0.0, 0.0], [0.0], [0.0, 0.0])),
        lambda: m2.simulate(u, initial_state=bx.SandwichState([0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0] * 3)),
    ]
    for case in cases:
        with pytest.raises(DataError, match="needs"):
            case()


def test_non_finite_or_wrong_type_states_raise_data_error():
    m1, m2 = bx.example1(), bx.example2()
    with pytest.raises(DataError, match="finite"):
        m1.simulate([0.1], initial_state=bx.CascadeState([np.nan, 0.0], [0.0, 0.0]))
    with pytest.raises(DataError, match="finite"):
        m1.simulate([0.1], initial_state=bx.CascadeState([0.0, 0.0], [0.0, 0.0], np.inf))
    with pytest.raises(DataError, match="finite"):
        m2.simulate([0.1], initial_state=bx.SandwichState([0.0, 0.0], [0.0, 0.0], [np.nan, 0.0], [0.0, 0.0]))
    with pytest.raises(DataError, match="finite"):
        m1.backlash.simulate([0.1], y0=np.nan)
    with pytest.raises(DataError, match="finite"):
        m1.backlash.switching([0.1], y0=-np.inf)
    with pytest.raises(DataError, match="SandwichState"):
        m2.simulate([0.1], initial_state=m1.rest_state())
    with pytest.raises(DataError, match="CascadeState"):
        m1.simulate([0.1], initial_state=(0.0, 0.0))
    with pytest.raises(DataError, match="y_prev"):
        bx.CascadeState([0.0, 0.0], [0.0, 0.0], "zero")


def test_non_numeric_backlash_memory_is_a_data_error():
    """y0 is state (like CascadeState.y_prev, which raises DataError), not a model parameter."""
    with pytest.raises(DataError, match="y0"):
        bx.example1().backlash.simulate([0.1], y0="zero")


# ------------------------------------------------------------------ model parameters
BAD_BACKLASH = {
    "negative c_left": ((-0.1, 0.5, [1.0], [1.0]), "c_l"),
    "negative c_right": ((0.1, -1e-12, [1.0], [1.0]), "c_r"),
    "nan c_left": ((np.nan, 0.5, [1.0], [1.0]), "c_l"),
    "inf c_right": ((0.1, np.inf, [1.0], [1.0]), "c_r"),
    "text c_left": (("wide", 0.5, [1.0], [1.0]), "c_left"),
    "list c_left": (([0.1], 0.5, [1.0], [1.0]), "c_left"),
    "None c_right": ((0.1, None, [1.0], [1.0]), "c_right"),
    "nan m_left": ((0.1, 0.5, [1.0, np.nan], [1.0]), "m_l"),
    "inf m_right": ((0.1, 0.5, [1.0], [np.inf]), "m_r"),
    "empty m_left": ((0.1, 0.5, [], [1.0]), "empty"),
    "empty m_right": ((0.1, 0.5, [1.0], np.array([])), "empty"),
    "2-D m_left": ((0.1, 0.5, [[1.0, 0.1]], [1.0]), "flat"),
    "text m_right": ((0.1, 0.5, [1.0], "steep"), "m_right"),
    "complex m_left": ((0.1, 0.5, [1.0 + 1j], [1.0]), "m_left"),
    "zero m_L1": ((0.1, 0.5, [0.0], [1.0]), "increase"),
    "negative m_L1": ((0.1, 0.5, [-1.0], [1.0]), "increase"),
    "negative m_R1": ((0.1, 0.5, [1.0], [-0.5, 0.1]), "increase"),
    # R'(x) = 1 + 6 (x - 0.5) < 0 for x < 1/3: R falls across the dead band [-0.5, 0.5]
    "R decreasing in dead band": ((0.5, 0.5, [1.0], [1.0, 3.0]), "increase"),
    # L'(x) = 1 - 2 (x + 0.5) <= 0 for x >= 0: L turns inside the dead band [-0.5, 0.5]
    "L turning in dead band": ((0.5, 0.5, [1.0, -1.0], [1.0]), "increase"),
}


@pytest.mark.parametrize("case", list(BAD_BACKLASH))
def test_bad_backlash_parameters_raise_model_error(case):
    args, word = BAD_BACKLASH[case]
    with pytest.raises(ModelError) as info:
        bx.GeneralBacklash(*args)
    assert word in str(info.value).lower()


def test_branches_increasing_only_on_the_dead_band_are_accepted():
    # L(x) = (x+0.1) - (x+0.1)^2 turns at x = 0.4, outside the dead band [-0.1, 0.1]
    bl = bx.GeneralBacklash(0.1, 0.1, [1.0, -1.0], [2.0])
    assert not bl.check_branches(-1.0, 1.0).is_valid
    bx.GeneralBacklash(0.0, 0.0, [1.0], [1.0])  # zero width: allowed


@pytest.mark.parametrize(
    "a, b, word",
    [([], [], "empty"), ([np.nan], [], "a[0]"), ([1.0], [0.1, np.inf], "b[1]"),
     ("x", [], "a must"), ([[1.0, 2.0]], [], "flat"), ([1.0], [[0.1]], "flat")],
)
def test_bad_linear_parameters_raise_model_error(a, b, word):
    with pytest.raises(ModelError, match=word.replace("[", r"\[").replace("]", r"\]")):
        bx.LinearBlock(a, b)


def test_models_need_blocks_of_the_right_type():
    m = bx.example1()
    with pytest.raises(ModelError, match="LinearBlock"):
        bx.CascadeModel(m.backlash, m.linear)
    with pytest.raises(ModelError, match="GeneralBacklash"):
        bx.SandwichModel(m.linear, m.linear, m.linear)


# ------------------------------------------------------------------ divergence
def test_unstable_block_that_overflows_raises_model_error():
    g = bx.LinearBlock([1.0], [-1.5])
    with pytest.raises(ModelError, match="diverged"):
        g.simulate(np.ones(3000))
    m = bx.CascadeModel(g, bx.example1().backlash)
    with pytest.raises(ModelError, match="diverged") as info:
        m.simulate(np.ones(3000))
    assert "1.5" in str(info.value)  # names the spectral radius


@pytest.mark.parametrize(
    "model, u",
    [
        # x(t) = u(t-1) + 1.5 x(t-1) stays finite until t ~ 1750, but y = m_R3 (x - c_R)^3
        # overflows from t ~ 585
        (bx.CascadeModel(bx.LinearBlock([1.0], [-1.5]), bx.example1().backlash), np.ones(700)),
        (bx.CascadeModel(bx.LinearBlock([1.0], [-1.5]), bx.example1().backlash), np.ones(1700)),
        # a stable block and finite input: x ~ 1e120 is finite, y ~ 0.2 x^3 is not
        (bx.example1(), np.full(3, 1e120)),
    ],
    ids=["unstable-700", "unstable-1700", "stable-huge-input"],
)
def test_cascade_never_returns_non_finite_output(model, u):
    """An overflow must end in ModelError, not in inf in the returned output."""
    try:
        y = model.simulate(u)
    except ModelError as exc:
        assert "diverged" in str(exc) or "overflow" in str(exc)
    else:
        assert np.all(np.isfinite(y)), f"{np.sum(~np.isfinite(y))} non-finite outputs, no error"


def test_unstable_sandwich_message_names_the_unstable_block():
    """The input block (spectral radius 1.5) diverges; the message must not report the
    stable output block's radius as the cause."""
    m = bx.SandwichModel(bx.LinearBlock([1.0], [-1.5]), bx.example1().backlash, bx.LinearBlock([1.0]))
    with pytest.raises(ModelError, match="diverged") as info:
        m.simulate(np.ones(1000))
    assert "1.5" in str(info.value), str(info.value)


def test_no_panic_on_extreme_but_finite_values():
    """Huge finite data and parameters end in a result or a backlashid error, never a panic."""
    code = (
        "import numpy as np, backlashid as bx\n"
        "from backlashid.errors import BacklashIdError\n"
        # (1e300, 1e300, [1e300], [1e-300]) overflows across its dead band: refused since issue 21
        "bl = bx.GeneralBacklash(1e300, 1e300, [1.0], [1e-300])\n"
        "m = bx.CascadeModel(bx.LinearBlock([1e300], [1e300]), bl)\n"
        "for f in (lambda: bx.GeneralBacklash(1e300, 1e300, [1e300], [1e-300]),\n"
        "          lambda: bx.GeneralBacklash(1e300, 1e300, [1e300, 1e-300], [1e-300, 1e300]),\n"
        "          lambda: bx.GeneralBacklash(1e-300, 1e-300, [5e-324], [1e308, 1e308, 1e308]),\n"
        "          lambda: bl.simulate([1e308, -1e308, 0.0]), lambda: bl.switching([1e308, -1e308]),\n"
        "          lambda: bl.simulate([1e308, -1e308], form='breakpoints'), lambda: m.simulate([1e308, 1.0]),\n"
        "          lambda: bl.check_branches(-1e308, 1e308), lambda: bl.breakpoints(1e308, (-1e308, 1e308))):\n"
        "    try:\n"
        "        f()\n"
        "    except BacklashIdError:\n"
        "        pass\n"
        "print('ok')\n"
    )
    assert run_isolated(code, timeout=20).strip() == "ok"


# ------------------------------------------------------------------ dict / JSON
GOOD = bx.example1().to_dict()

BAD_DICTS = {
    "empty": {},
    "unknown kind": {"model": "hammerstein"},
    "missing backlash": {"model": "cascade", "linear": GOOD["linear"]},
    "missing a": {**GOOD, "linear": {"b": [0.1]}},
    "linear not a dict": {**GOOD, "linear": [0.7, 0.5]},
    "missing c_left": {**GOOD, "backlash": {k: v for k, v in GOOD["backlash"].items() if k != "c_left"}},
    "negative c_right": {**GOOD, "backlash": {**GOOD["backlash"], "c_right": -1.0}},
    "text coefficient": {**GOOD, "backlash": {**GOOD["backlash"], "m_left": ["one"]}},
    "null b": {**GOOD, "linear": {"a": [0.7], "b": None}},
    "sandwich missing output": {"model": "sandwich", "input_linear": GOOD["linear"], "backlash": GOOD["backlash"]},
    "a list": [1, 2],
    "a string": "cascade",
    "None": None,
}


@pytest.mark.parametrize("case", list(BAD_DICTS))
def test_invalid_dicts_raise_model_error(case):
    with pytest.raises(ModelError) as info:
        bx.model_from_dict(BAD_DICTS[case])
    assert str(info.value)


@pytest.mark.parametrize(
    "text, word",
    [("", "json"), ("{", "json"), ("[1, 2]", "object"), ('"cascade"', "object"), ("null", "object"),
     ('{"model": "sandwich"}', "missing"), ('{"model": 3}', "unknown"),
     (json.dumps({**GOOD, "backlash": {**GOOD["backlash"], "c_left": float("nan")}}), "c_l")],
)
def test_invalid_json_raises_model_error(text, word):
    with pytest.raises(ModelError) as info:
        bx.model_from_json(text)
    assert word in str(info.value).lower()
    with pytest.raises(ModelError):
        bx.CascadeModel.from_json(text)


def test_from_dict_of_the_other_kind_raises_model_error():
    with pytest.raises(ModelError, match="SandwichModel"):
        bx.CascadeModel.from_dict(bx.example2().to_dict())
    with pytest.raises(ModelError, match="CascadeModel"):
        bx.SandwichModel.from_json(bx.example1().to_json())


def test_invalid_example_data_arguments():
    with pytest.raises(DataError, match="n = 0"):
        bx.example_data(bx.example1(), 0)
    with pytest.raises(DataError, match="snr"):
        bx.example_data(bx.example1(), 10, snr=-1.0)
