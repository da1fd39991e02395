"""The augmented chain beyond the cascade (``_core.simulate_augmented`` with r, s and
``_core.AugmentedProblem`` with nr, ns): the sandwich (Example 2) and the input backlash
(Hammerstein) without effects are ``SandwichModel.simulate`` from the same state, the new
effects at zero size are the nominal model, an explicit start is the one given, and bad pasts
are DataErrors naming the argument."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

import backlashid as bid
from backlashid import _core
from backlashid.diagnosis.effects import EFFECTS, REGISTRY
from backlashid.diagnosis.effects._base import RefitRecords, simulate
from backlashid.errors import DataError
from backlashid.identify import Structure
from backlashid.models import GeneralBacklash, LinearBlock, SandwichModel

SANDWICH = Structure(2, 2, 3, 2, 2)
HAMMERSTEIN = Structure(1, 0, 3, 2, 2)


def example2() -> SandwichModel:
    return bid.example2()


def hammerstein() -> SandwichModel:
    m = example2()
    return SandwichModel(LinearBlock([1.0], []), m.backlash, m.output_linear)


def record(n: int = 800) -> np.ndarray:
    rng = np.random.default_rng(8)
    k = np.arange(n)
    return 1.4 * np.sin(2 * np.pi * k / 173) + 0.4 * rng.uniform(-1.0, 1.0, n)


def core_args(m: SandwichModel) -> tuple[list[Any], dict[str, Any]]:
    """simulate_augmented's positional estimate and the output block's r, s."""
    bl: GeneralBacklash = m.backlash
    chain = [m.input_linear.a.tolist(), m.input_linear.b.tolist(), bl.c_left, bl.c_right, list(bl.m_left), list(bl.m_right)]
    return chain, {"r": m.output_linear.a.tolist(), "s": m.output_linear.b.tolist()}


def state_kwargs(state: Any) -> dict[str, Any]:
    """A SandwichState as simulate_augmented's keywords (y_prev = y_past[0])."""
    return {
        "u_past": list(state.u_past),
        "x_past": list(state.x_past),
        "y_past": list(state.y_past),
        "w_past": list(state.w_past),
        "y_prev": float(state.y_past[0]),
    }


@pytest.mark.parametrize("make", [example2, hammerstein], ids=["sandwich", "hammerstein"])
def test_a_sandwich_without_effects_is_the_sandwich_model_from_the_same_state(make: Any) -> None:
    m = make()
    u = record()
    chain, rs = core_args(m)
    np.testing.assert_array_equal(_core.simulate_augmented(*chain, u, **rs), m.simulate(u))
    busy = m.simulate(u[:300], internals=True).final_state
    assert any(v != 0.0 for v in busy.w_past)
    want = m.simulate(u[300:], initial_state=busy)
    got = _core.simulate_augmented(*chain, u[300:], **rs, **state_kwargs(busy))
    np.testing.assert_array_equal(got, want)
    # the compiled refit from that explicit start simulates the same
    s = SANDWICH if m.input_linear.na == 2 else HAMMERSTEIN
    theta = s.pack(m)
    prob = _core.AugmentedProblem(u[300:], want, s.na, s.nb, s.degree, nr=s.nr, ns=s.ns, **state_kwargs(busy))
    assert prob.names == s.names
    np.testing.assert_array_equal(prob.simulate(theta), want)
    assert prob.cost(theta) == 0.0


@pytest.mark.parametrize("structure", [Structure(2, 2, 3), SANDWICH, HAMMERSTEIN], ids=["cascade", "sandwich", "hammerstein"])
@pytest.mark.parametrize("effect", ["state_saturation", "sensor_saturation"])
def test_the_new_effects_at_zero_size_are_the_nominal_model(structure: Structure, effect: str) -> None:
    model = bid.example1() if not structure.is_sandwich else (example2() if structure.na == 2 else hammerstein())
    theta = structure.pack(model)
    u = record()
    nominal = model.simulate(u)
    zero = ((effect, REGISTRY[effect].zero),)
    np.testing.assert_array_equal(simulate(structure, theta, zero, u, 0.0), nominal)
    prob = RefitRecords(structure, u, nominal, 10, 0.0)
    compiled = prob.compiled(zero, [])
    np.testing.assert_array_equal(compiled.simulate(theta), nominal)
    # and a clip inside the range changes it
    lo, hi = np.quantile(nominal, [0.2, 0.8])
    clipped = simulate(structure, theta, ((effect, (float(lo), float(hi))),), u, 0.0)
    assert np.max(np.abs(clipped - nominal)) > 0.05
    if effect == "sensor_saturation":
        np.testing.assert_allclose(clipped, np.clip(nominal, lo, hi), rtol=0, atol=1e-12)


def test_the_catalogue_lists_the_new_effects_last() -> None:
    assert EFFECTS[-2:] == ("state_saturation", "sensor_saturation")
    for name in EFFECTS[-2:]:
        e = REGISTRY[name]
        assert e.parameters == ("lo", "hi")
        assert e.zero == (-np.inf, np.inf)
        assert e.core({"lo": -1.0, "hi": 2.0}) == ((name, (-1.0, 2.0)),)


def test_a_held_sandwich_starts_at_both_blocks_equilibria() -> None:
    m = example2()
    u = np.full(400, 0.7)
    theta = SANDWICH.pack(m)
    # the input held for ever at 0.7 (x = 0.7, the input block's gain is 1) and the backlash
    # memory on its right branch there: every block in equilibrium, the output constant at
    # the output block's gain (1) times R(0.7)
    y0 = float(m.backlash.right(np.array([0.7]))[0])
    held = simulate(SANDWICH, theta, (), u, 0.0, held=True, y_prev=y0)
    np.testing.assert_allclose(held, y0, rtol=0, atol=1e-12)
    prob = _core.AugmentedProblem(u, u, 2, 2, 3, nr=2, ns=2, held=True, y_prev=y0)
    np.testing.assert_allclose(prob.simulate(theta), held, rtol=0, atol=1e-12)
    # from rest the same input starts from 0
    assert abs(simulate(SANDWICH, theta, (), u, 0.0)[0]) < 1e-12


def bad_simulations() -> list[tuple[dict[str, Any], str]]:
    return [
        ({"u_past": [0.0]}, "u_past"),
        ({"x_past": [0.0, 0.0, 0.0]}, "x_past"),
        ({"u_past": [0.0, np.nan]}, "u_past"),
        ({"y_past": [0.0]}, "y_past"),
        ({"w_past": [0.0, np.inf]}, "w_past"),
        ({"y_past": [0.5, 0.0], "y_prev": 0.4}, "y_past"),
        ({"r": [], "s": []}, "r"),
    ]


@pytest.mark.parametrize(("kwargs", "word"), bad_simulations())
def test_bad_pasts_are_data_errors_naming_the_argument(kwargs: dict[str, Any], word: str) -> None:
    chain, rs = core_args(example2())
    u = record(50)
    with pytest.raises(DataError, match=word):
        _core.simulate_augmented(*chain, u, **{**rs, **kwargs})
    if "r" not in kwargs:
        with pytest.raises(DataError, match=word):
            _core.AugmentedProblem(u, u, 2, 2, 3, nr=2, ns=2, **kwargs)


def test_a_cascade_has_no_output_block_past_and_held_excludes_a_given_start() -> None:
    chain, _ = core_args(example2())
    u = record(50)
    for kw in ({"y_past": [0.0, 0.0]}, {"w_past": [0.0]}, {"s": [0.1]}):
        with pytest.raises(DataError, match="give r"):
            _core.simulate_augmented(*chain, u, **kw)
    with pytest.raises(DataError, match="nr"):
        _core.AugmentedProblem(u, u, 2, 2, 3, w_past=[0.0])
    with pytest.raises(DataError, match="nr"):
        _core.AugmentedProblem(u, u, 2, 2, 3, nr=-1)
    with pytest.raises(DataError, match="held"):
        _core.AugmentedProblem(u, u, 2, 2, 3, nr=2, ns=2, held=True, u_past=[0.0, 0.0])
    with pytest.raises(DataError, match="held"):
        simulate(SANDWICH, SANDWICH.pack(example2()), (), u, 0.0, held=True, start={"u_past": [0.0, 0.0]})
