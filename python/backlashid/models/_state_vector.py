"""A model's state as one flat vector, the layout of the core's step function
(rust/core/src/model/state_space.rs), of the python-control system and of the exported C.

The state vector, most recent values first within each block:

- cascade: ``[u(t-1)..u(t-na), x(t-1)..x(t-nb), y(t-1)]``, that is ``CascadeState``'s
  ``u_past``, ``x_past`` and ``y_prev`` one after the other (na + nb + 1 values);
- sandwich: ``[u(t-1)..u(t-na), x(t-1)..x(t-nb), y(t-1)..y(t-nr), w(t-1)..w(t-ns)]``, that is
  ``SandwichState``'s ``u_past``, ``x_past``, ``y_past`` and ``w_past`` (na + nb + nr + ns
  values; y(t-1) is the backlash memory).

Before the first sample (t = 1) the vector is the model state's fields in that order.
"""

from __future__ import annotations

from typing import Any, Union

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import _core
from .._validation import as_signal, check_instance
from ..errors import DataError
from ._cascade import CascadeModel, CascadeState
from ._linear import LinearBlock
from ._sandwich import SandwichModel, SandwichState
from ._serialization import check_model

AnyModel = Union[CascadeModel, SandwichModel]


def _native_block(block: LinearBlock) -> Any:
    a = [float(v) for v in block.a]
    b = [float(v) for v in block.b]
    return _core.LinearBlock(a[1:], b, a[0]) if block.feedthrough else _core.LinearBlock(a, b)


def native(model: AnyModel) -> Any:
    """The core's model (its ``step``), built from the model's public parameters."""
    bl = model.backlash
    backlash = _core.GeneralBacklash(bl.c_left, bl.c_right, [float(v) for v in bl.m_left], [float(v) for v in bl.m_right])
    if isinstance(model, CascadeModel):
        return _core.CascadeModel(_native_block(model.linear), backlash)
    return _core.SandwichModel(_native_block(model.input_linear), backlash, _native_block(model.output_linear))


def _blocks(model: AnyModel) -> list[tuple[str, int]]:
    """(signal, number of past values) of each part of the state vector, in order."""
    if isinstance(model, CascadeModel):
        return [("u", model.linear.na), ("x", model.linear.nb), ("y", 1)]
    i, o = model.input_linear, model.output_linear
    return [("u", i.na), ("x", i.nb), ("y", o.na), ("w", o.nb)]


def state_names(model: AnyModel) -> list[str]:
    """The names of the entries of the model's state vector, in order.

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The model.

    Returns
    -------
    list of str
        ``u(t-1)``, .., ``u(t-na)``, ``x(t-1)``, .., ``x(t-nb)``, then ``y(t-1)`` (cascade)
        or ``y(t-1)``, .., ``y(t-nr)``, ``w(t-1)``, .., ``w(t-ns)`` (sandwich).

    Raises
    ------
    DataError
        If ``model`` is not a CascadeModel or SandwichModel.

    Examples
    --------
    >>> bid.export.state_names(bid.example2())[-3:]
    ['y(t-2)', 'w(t-1)', 'w(t-2)']
    """
    return [f"{signal}(t-{k})" for signal, n in _blocks(check_model(model)) for k in range(1, n + 1)]


def output_name(model: AnyModel) -> str:
    """The model's output signal: y for the cascade, w for the sandwich (eq 29)."""
    return "y" if isinstance(model, CascadeModel) else "w"


def state_vector(model: AnyModel, state: CascadeState | SandwichState | None = None) -> NDArray[np.float64]:
    """The model state as the flat vector of the step function, python-control and the C export.

    Most recent values first within each block: for the cascade
    ``[u(t-1)..u(t-na), x(t-1)..x(t-nb), y(t-1)]``, the fields ``u_past``, ``x_past``,
    ``y_prev`` of :class:`CascadeState` one after the other; for the sandwich
    ``[u(t-1)..u(t-na), x(t-1)..x(t-nb), y(t-1)..y(t-nr), w(t-1)..w(t-ns)]``, the fields
    ``u_past``, ``x_past``, ``y_past``, ``w_past`` of :class:`SandwichState` (y(t-1) is the
    backlash memory). Before the first sample, t = 1.

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The model.
    state : CascadeState or SandwichState, optional
        The model's state (default: :meth:`rest_state`).

    Returns
    -------
    numpy.ndarray
        The state vector, :func:`state_names` long.

    Raises
    ------
    DataError
        If ``model`` is not a model, or ``state`` is not a state of its kind and orders.

    Examples
    --------
    >>> model = bid.example1()
    >>> state = bid.CascadeState(u_past=[0.1, 0.2], x_past=[0.3, 0.4], y_prev=0.5)
    >>> bid.export.state_vector(model, state).tolist()
    [0.1, 0.2, 0.3, 0.4, 0.5]
    """
    model = check_model(model)
    if state is None:
        state = model.rest_state()
    kind = CascadeState if isinstance(model, CascadeModel) else SandwichState
    check_instance(state, kind, "initial_state", DataError)
    parts = [state.u_past, state.x_past, (state.y_prev,)] if isinstance(state, CascadeState) else [state.u_past, state.x_past, state.y_past, state.w_past]
    for (signal, n), part in zip(_blocks(model), parts):
        if len(part) != n:
            raise DataError(f"initial_state holds {len(part)} past values of {signal} but the model needs {n} (its order)")
    return np.array([v for part in parts for v in part], dtype=np.float64)


def state_from_vector(model: AnyModel, vector: ArrayLike) -> CascadeState | SandwichState:
    """The model state of a flat state vector: the inverse of :func:`state_vector`.

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The model.
    vector : array_like
        The state vector (e.g. python-control's final state), finite.

    Returns
    -------
    CascadeState or SandwichState
        The state, to continue ``model.simulate`` from.

    Raises
    ------
    DataError
        If ``model`` is not a model, or the vector's length is not the model's state size.

    Examples
    --------
    >>> bid.export.state_from_vector(bid.example1(), [0.1, 0.2, 0.3, 0.4, 0.5])
    CascadeState(u_past=(0.1, 0.2), x_past=(0.3, 0.4), y_prev=0.5)
    """
    model = check_model(model)
    v = as_signal(vector, "state vector")
    if v.ndim != 1 or not np.all(np.isfinite(v)):
        raise DataError("the state vector must be 1-D and finite")
    sizes = [n for _, n in _blocks(model)]
    if len(v) != sum(sizes):
        raise DataError(f"the state vector has {len(v)} values but the model needs {sum(sizes)}: {', '.join(state_names(model))}")
    cuts = np.cumsum(sizes)[:-1]
    parts = [tuple(float(x) for x in part) for part in np.split(v, cuts)]
    if isinstance(model, CascadeModel):
        return CascadeState(parts[0], parts[1], parts[2][0])
    return SandwichState(*parts)
