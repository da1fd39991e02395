"""to_dict / from_dict, to_json / from_json and model_from_json round-trip exactly; repr
uses the paper's symbols."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import backlashid as bx
from conftest import backlashes, cascades, sandwiches


def assert_round_trips(model):
    cls = type(model)
    d = model.to_dict()
    json.dumps(d, allow_nan=False)  # plain JSON-safe data
    for back in (
        cls.from_dict(d),
        bx.model_from_dict(d),
        cls.from_json(model.to_json()),
        bx.model_from_json(model.to_json()),
        bx.model_from_json(model.to_json(indent=2, sort_keys=True)),
    ):
        assert type(back) is cls
        assert back == model and hash(back) == hash(model)
        assert back.to_dict() == d
        u = np.linspace(-1, 1, 64)
        np.testing.assert_array_equal(back.simulate(u), model.simulate(u))


def test_example1_round_trip():
    m = bx.example1()
    assert_round_trips(m)
    d = m.to_dict()
    assert d["model"] == "cascade" and d["format_version"] == 1
    assert d["linear"] == {"a": [0.7, 0.5], "b": [-0.2, 0.35]}
    assert d["backlash"] == {"c_left": 0.6, "c_right": 0.5, "m_left": [1.0, -0.3, 0.3], "m_right": [1.5, 0.4, 0.2]}


def test_example2_round_trip():
    m = bx.example2()
    assert_round_trips(m)
    d = m.to_dict()
    assert d["model"] == "sandwich"
    assert d["input_linear"] == {"a": [0.8, 0.2], "b": [0.2, -0.2]}
    assert d["output_linear"] == {"a": [1.0, 0.15], "b": [-0.2, 0.35]}
    np.testing.assert_array_equal(m.r, [1.0, 0.15])
    np.testing.assert_array_equal(m.s, [-0.2, 0.35])


@given(model=st.one_of(cascades(), sandwiches()))
def test_random_models_round_trip(model):
    assert_round_trips(model)


@given(bl=backlashes())
def test_backlash_and_linear_dicts_round_trip(bl):
    assert bx.GeneralBacklash.from_dict(bl.to_dict()) == bl
    g = bx.LinearBlock([0.1, 1 / 3, 1e-17], [np.pi / 10])
    assert bx.LinearBlock.from_dict(json.loads(json.dumps(g.to_dict()))) == g
    assert bx.LinearBlock.from_dict({"a": [1.0]}) == bx.LinearBlock([1.0], [])


def test_equality_distinguishes_parameters():
    m = bx.example1()
    other = bx.CascadeModel(m.linear, bx.GeneralBacklash(0.6, 0.5, [1.0, -0.3, 0.3], [1.5, 0.4, 0.2000001]))
    assert m != other
    assert bx.example1() == bx.example1() and bx.example2() == bx.example2()
    assert m != bx.example2()


def test_repr_uses_the_paper_symbols():
    bl = repr(bx.example1().backlash)
    for sym in ("c_L=0.6", "c_R=0.5", "m_L=[1, -0.3, 0.3]", "m_R=[1.5, 0.4, 0.2]"):
        assert sym in bl, bl
    cascade = repr(bx.example1())
    for sym in ("c_L", "c_R", "m_L", "m_R", "a=[0.7, 0.5]", "b=[-0.2, 0.35]"):
        assert sym in cascade, cascade
    sandwich = repr(bx.example2())
    for sym in ("c_L", "c_R", "m_L", "m_R", "r=[1, 0.15]", "s=[-0.2, 0.35]"):
        assert sym in sandwich, sandwich
    text = str(bx.example2())
    assert "w(t) = 1 y(t-1) + 0.15 y(t-2) + 0.2 w(t-1) - 0.35 w(t-2)" in text
    assert "x(t) = 0.7 u(t-1) + 0.5 u(t-2) + 0.2 x(t-1) - 0.35 x(t-2)" in str(bx.example1())


def test_fit_result_json_is_refused_with_a_pointer_to_its_model_entry():
    # a fit JSON nests the model under 'model': the message says to load that entry
    wrapped = {"model": bx.example1().to_dict(), "estimation": {"rmse": 0.1}}
    with pytest.raises(bx.ModelError, match=r"fit or diagnosis result.*load its 'model' entry"):
        bx.model_from_dict(wrapped)
    assert bx.model_from_dict(wrapped["model"]) == bx.example1()
