"""The model as a python-control ``NonlinearIOSystem`` (discrete time), stepped by the core."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._optional import python_control
from .._validation import check_real, shown
from ..errors import DataError
from ._serialization import check_model
from ._state_vector import AnyModel, native, output_name, state_names


def _check_dt(dt: Any) -> bool | float:
    """True (an unspecified sample time) or a finite sample time > 0."""
    if dt is True:
        return True
    if isinstance(dt, bool) or not isinstance(dt, (int, float, np.integer, np.floating)):
        raise DataError(f"dt = {shown(dt)}: give True (discrete time, unspecified sample time) or a sample time > 0")
    return check_real(dt, "dt", low=0.0, low_open=True)


def to_python_control(model: AnyModel, name: str | None = None, *, dt: bool | float = True) -> Any:
    """The model as a discrete-time python-control ``NonlinearIOSystem``.

    The system's state is the model's state vector (:func:`state_vector`; its states are
    named ``u(t-1)``, ..., ``y(t-1)``), its input ``u`` and its output ``y`` (cascade) or
    ``w`` (sandwich). Its update and output functions call the core's one-step function,
    which computes what ``simulate`` computes for one sample (the same sums in the same
    order, eq 16 and eq 1), so ``control.input_output_response`` reproduces ``simulate``.

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The model to export.
    name : str, optional
        The system's name (python-control's default name if None).
    dt : True or float, default True
        The sample time: True for discrete time with an unspecified sample time, or the
        record's sample time in seconds.

    Returns
    -------
    control.NonlinearIOSystem
        The model: x[k+1] = updfcn(t, x[k], u[k]), y[k] = outfcn(t, x[k], u[k]).

    Raises
    ------
    BacklashIdError
        If python-control is not installed (``pip install 'backlashid[control]'``).
    DataError
        If ``model`` is not a model, or ``dt`` is not True or a sample time > 0.

    Examples
    --------
    >>> import control
    >>> model = bid.example1()
    >>> sys = bid.export.to_python_control(model, name="plant")
    >>> sys.nstates, sys.state_labels[-1], sys.output_labels
    (5, 'y(t-1)', ['y'])
    >>> u = np.sin(0.3 * np.arange(50))
    >>> resp = control.input_output_response(sys, np.arange(50), u, bid.export.state_vector(model))
    >>> bool(np.array_equal(resp.outputs, model.simulate(u)))
    True
    """
    model = check_model(model)
    dt = _check_dt(dt)
    if name is not None and not isinstance(name, str):
        raise DataError(f"name = {shown(name)}: give a string or None")
    control = python_control()
    core = native(model)

    def _input(u: Any) -> float:
        return float(np.asarray(u, dtype=np.float64).reshape(-1)[0])

    def updfcn(t: float, x: Any, u: Any, params: Any) -> Any:
        return core.step(np.asarray(x, dtype=np.float64), _input(u))[1]

    def outfcn(t: float, x: Any, u: Any, params: Any) -> Any:
        return np.array([core.step(np.asarray(x, dtype=np.float64), _input(u))[0]])

    return control.NonlinearIOSystem(
        updfcn, outfcn, inputs=["u"], outputs=[output_name(model)], states=state_names(model), dt=dt, name=name
    )
