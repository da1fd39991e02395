"""The python-control export: ``input_output_response`` of ``model.to_python_control()`` is
``model.simulate`` (issue 19: to 1e-12), from rest and from a busy state, with the final state
mapped back to the model's state."""

from __future__ import annotations

import sys

import numpy as np
import pytest
from export_cases import busy_state, inputs, models

import backlashid as bid
from backlashid.export import state_from_vector, state_names, state_vector, to_python_control

try:
    import control
except ImportError:  # the tests that need it skip
    control = None
needs_control = pytest.mark.skipif(control is None, reason="python-control is not installed: pip install 'backlashid[control]'")

MODELS = models()


@needs_control
@pytest.mark.parametrize("name", sorted(MODELS))
@pytest.mark.parametrize("start", ["rest", "busy"])
def test_input_output_response_is_the_simulation(name: str, start: str) -> None:
    model = MODELS[name]
    state = model.rest_state() if start == "rest" else busy_state(model)
    system = model.to_python_control(name=name)
    assert system.isdtime(strict=True) and system.dt is True
    assert system.state_labels == state_names(model)
    for kind, u in inputs(400).items():
        sim = model.simulate(u, initial_state=state, internals=True)
        resp = control.input_output_response(system, np.arange(len(u)), u, state_vector(model, state), return_states=True)
        np.testing.assert_allclose(resp.outputs, sim.output, rtol=0, atol=1e-12, err_msg=kind)
        # the state after the last sample: python-control's state at the last time is the state before it
        last = state_from_vector(model, resp.states[:, -1])
        follow = state_from_vector(model, system._rhs(len(u) - 1, resp.states[:, -1], np.array([u[-1]])))
        assert follow == sim.final_state, kind
        assert last == model.simulate(u[:-1], initial_state=state, internals=True).final_state


@needs_control
def test_example_outputs_are_named_and_a_sample_time_is_kept() -> None:
    e1, e2 = bid.example1(), bid.example2()
    s1, s2 = e1.to_python_control(dt=0.01), to_python_control(e2, "plant")
    assert (s1.input_labels, s1.output_labels, s1.dt) == (["u"], ["y"], 0.01)
    assert (s2.output_labels, s2.name, s2.nstates) == (["w"], "plant", 8)
    u = np.sin(0.2 * np.arange(120))
    resp = control.input_output_response(s1, 0.01 * np.arange(120), u, state_vector(e1))
    np.testing.assert_allclose(resp.outputs, e1.simulate(u), rtol=0, atol=1e-12)


def test_the_state_vector_maps_both_ways() -> None:
    for model in MODELS.values():
        state = busy_state(model)
        v = state_vector(model, state)
        assert len(v) == len(state_names(model))
        assert state_from_vector(model, v) == state
        assert not state_vector(model).any()
    with pytest.raises(bid.DataError, match="needs 5"):
        state_from_vector(bid.example1(), [0.0] * 4)
    with pytest.raises(bid.DataError, match="SandwichState"):
        state_vector(bid.example2(), bid.example1().rest_state())
    with pytest.raises(bid.DataError, match="CascadeModel or SandwichModel"):
        state_vector(bid.LinearBlock([1.0]))


@needs_control
@pytest.mark.parametrize("dt", [0, -1.0, float("nan"), False, "1"])
def test_bad_sample_times_are_refused(dt: object) -> None:
    with pytest.raises(bid.DataError, match="dt = "):
        bid.example1().to_python_control(dt=dt)  # type: ignore[arg-type]


def test_without_python_control_the_error_says_what_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "control", None)  # import control raises ImportError
    with pytest.raises(bid.BacklashIdError, match=r"pip install 'backlashid\[control\]'"):
        bid.example1().to_python_control()
