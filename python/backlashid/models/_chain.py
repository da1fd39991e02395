"""What the cascade and the sandwich share: the JSON round trip, state and argument checks, and
the core's count of moving samples.
"""

from __future__ import annotations

import json
from abc import ABC, abstractmethod
from dataclasses import asdict, fields, is_dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docstrings import fill
from .._validation import as_scalar, as_signal, check_int, check_warmup
from ..errors import DataError, ModelError

FORMAT_VERSION = 1

# numpydoc sections both models' methods share ({state}: the model's state class)
_SIMULATE = """u : array_like
    Input u(1), u(2), ..., 1-D, finite.
initial_state : {state}, optional
    The state before the first sample (default :meth:`rest_state`, the paper's start)."""
_SIMULATE_RAISES = """Raises
------
DataError
    If u is not a finite 1-D signal, or the state is not a {state} of the model's orders.
ModelError
    If the simulation overflows (an unstable block)."""
_MODEL = """Frozen; pickles, compares by value and round-trips through ``to_dict`` / ``to_json``. A
block of the wrong type raises ModelError.

Attributes
----------"""
_OUTPUTS = """Attributes
----------
output : numpy.ndarray
    The output {output}.
x : numpy.ndarray
    The {block}'s output, the backlash's input."""
_SIGNALS = """f1 : numpy.ndarray of bool
    The left branch is active (eq 12).
f2 : numpy.ndarray of bool
    The right branch is active (eq 13).
final_state : {state}
    The state after the last sample, to continue the record from."""
_MOVING = """warmup : int, default 0
    Samples at the start left out.

Returns
-------
float
    The fraction of samples after ``warmup`` on which the backlash moves (f1 or f2 of
    eq 12-13): ``simulate(u, internals=True)``'s flags, counted in the core."""
DOCS = SimpleNamespace(model=_MODEL, simulate=_SIMULATE, simulate_raises=_SIMULATE_RAISES, outputs=_OUTPUTS, signals=_SIGNALS, moving=_MOVING)


def _values(values: ArrayLike, name: str) -> tuple[float, ...]:
    return tuple(float(v) for v in as_signal(values, name).ravel())


def _moving_fraction(native: Any, u: ArrayLike, state: tuple[Any, ...], warmup: Any) -> float:
    """The core's count of moving samples after ``warmup`` (checked), as a fraction."""
    u = as_signal(u, "u")
    n = len(u)
    if n == 0:
        raise DataError("u is empty: give at least one sample")
    warmup = check_warmup(warmup, n)
    return native.moving_count(u, *state, warmup) / (n - warmup)


def _parse_json(text: str) -> dict[str, Any]:
    if not isinstance(text, (str, bytes, bytearray)):
        raise ModelError(f"expected JSON text, got {type(text).__name__}: pass the string from to_json()")
    try:
        data = json.loads(text)
    except RecursionError:
        raise ModelError("JSON nested too deeply to be a backlashid model description: pass the text of to_json()") from None
    except ValueError as exc:  # JSONDecodeError, UnicodeDecodeError of bytes, an int of > 4300 digits
        raise ModelError(f"not valid JSON ({type(exc).__name__}: {str(exc)[:120]})") from None
    if not isinstance(data, dict):
        raise ModelError("not a backlashid model description: expected a JSON object")
    return data


class _State:
    """What both models' states share: every field is converted on construction, the pasts
    to tuples of finite floats, the cascade's backlash memory ``y_prev`` to a float."""

    def __post_init__(self) -> None:
        for f in fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            converted = as_scalar(value, f.name, DataError) if f.name == "y_prev" else _values(value, f.name)
            object.__setattr__(self, f.name, converted)


class _Simulation:
    """What the cascade's and the sandwich's simulations share (dataclasses with ``output``,
    ``f1``, ``f2`` and ``final_state``): the fraction of moving samples, a summary and a
    JSON-safe dict."""

    output: NDArray[np.float64]
    f1: NDArray[np.bool_]
    f2: NDArray[np.bool_]

    def moving_fraction(self) -> float:
        """The fraction of samples on which the backlash moves along a branch.

        Returns
        -------
        float
            The mean of f1 or f2 (eq 12-13).
        """
        return float(np.mean(self.f1 | self.f2))

    def summary(self) -> str:
        """The simulation as one line of text.

        Returns
        -------
        str
            The number of samples, the output's range and the moving fraction.
        """
        kind = type(self).__name__.replace("Simulation", "").lower()
        span = f", output in [{self.output.min():.6g}, {self.output.max():.6g}]" if self.output.size else ""
        return f"{kind} simulation: {self.output.size} samples{span}, backlash moving on {100 * self.moving_fraction():.1f} % of samples"

    def to_dict(self) -> dict[str, Any]:
        """The simulation as a JSON-safe dict.

        Returns
        -------
        dict
            Every signal as a list, and the final state's fields.
        """
        out: dict[str, Any] = {}
        for f in fields(self):  # type: ignore[arg-type]
            value = getattr(self, f.name)
            out[f.name] = asdict(value) if is_dataclass(value) else np.asarray(value).tolist()
        return out


_LOADED_DOC = """Returns
-------
CascadeModel or SandwichModel
    The model, of this class.

Raises
------
ModelError
    If {what} no model of this class."""


class _ModelIO(ABC):
    """JSON and dict round trips shared by both model kinds."""

    @abstractmethod
    def to_dict(self) -> dict[str, Any]:
        """The model as a plain, JSON-safe dict.

        Returns
        -------
        dict
            The kind ("model"), "format_version" and every block's ``to_dict()``.
        """

    def to_json(self, **kwargs: Any) -> str:
        """The model as JSON text.

        Parameters
        ----------
        **kwargs : dict, optional
            Keyword arguments of ``json.dumps`` (e.g. ``indent=2``).

        Returns
        -------
        str
            ``json.dumps(to_dict())``.

        Raises
        ------
        DataError
            If ``json.dumps`` refuses a keyword argument, or ``indent`` is above 64.

        Examples
        --------
        >>> import backlashid as bid
        >>> text = bid.example1().to_json()
        >>> bid.CascadeModel.from_json(text) == bid.example1()
        True
        """
        indent = kwargs.get("indent")
        if isinstance(indent, (int, np.integer)) and not isinstance(indent, bool):
            check_int(indent, "indent", 0, 64)  # json.dumps would build a string of indent spaces per level
        try:
            return json.dumps(self.to_dict(), **kwargs)
        except (TypeError, ValueError, OverflowError) as exc:  # a keyword json.dumps refuses
            raise DataError(f"to_json's keywords are json.dumps's; it refused {kwargs} ({type(exc).__name__}: {exc})") from None

    def to_python_control(self, name: str | None = None, *, dt: bool | float = True) -> Any:
        """The model as a discrete-time python-control ``NonlinearIOSystem``.

        Its state is the flat state vector of :func:`backlashid.export.state_vector` (states
        named ``u(t-1)``, .., ``y(t-1)``); its update and output functions call the core's
        one-step function, so ``control.input_output_response`` reproduces :meth:`simulate`.
        See :func:`backlashid.export.to_python_control`.

        Parameters
        ----------
        name : str, optional
            The system's name.
        dt : True or float, default True
            True (discrete time, unspecified sample time) or the sample time in seconds.

        Returns
        -------
        control.NonlinearIOSystem
            The model, input ``u``, output ``y`` (cascade) or ``w`` (sandwich).

        Raises
        ------
        BacklashIdError
            If python-control is not installed (``pip install 'backlashid[control]'``).
        DataError
            If ``dt`` is not True or a sample time > 0.
        """
        from ._export_python_control import to_python_control

        return to_python_control(self, name, dt=dt)  # type: ignore[arg-type]

    def to_c(self, path: Any, *, prefix: str = "bl") -> tuple[Any, Any]:
        """Write the model's step function and its inverses as a dependency-free C99 header and source.

        See :func:`backlashid.export.to_c`: ``<prefix>_state``, ``<prefix>_init`` and
        ``<prefix>_step``, computed in the core's order, so that the C reproduces
        :meth:`simulate` to the last bit; the backlash inverse
        (``<prefix>_backlash_inverse_step``) and the feedforward compensator
        (``<prefix>_inverse_step``), ports of the core's.

        Parameters
        ----------
        path : str or pathlib.Path
            An existing directory (``<prefix>.h`` and ``<prefix>.c`` in it) or a file path
            without extension (``path.h`` and ``path.c``).
        prefix : str, default "bl"
            The C identifier every generated name starts with.

        Returns
        -------
        tuple of pathlib.Path
            The header and the source written.

        Raises
        ------
        DataError
            If ``prefix`` is not a C identifier, or the folder of ``path`` does not exist.
        """
        from ._export_c import to_c

        return to_c(self, path, prefix=prefix)  # type: ignore[arg-type]

    @classmethod
    @fill(loaded=_LOADED_DOC.format(what="``data`` describes"))
    def from_dict(cls, data: dict[str, Any]) -> Any:
        """The model of a :meth:`to_dict` dict.

        Parameters
        ----------
        data : dict
            A dict from ``to_dict()``.

        {loaded}
        """
        from ._serialization import model_from_dict

        model = model_from_dict(data)
        if not isinstance(model, cls):
            raise ModelError(f"this describes a {type(model).__name__}, not a {cls.__name__}")
        return model

    @classmethod
    @fill(loaded=_LOADED_DOC.format(what="``text`` is not JSON of"))
    def from_json(cls, text: str) -> Any:
        """The model of :meth:`to_json` text.

        Parameters
        ----------
        text : str
            JSON text from ``to_json()``.

        {loaded}
        """
        return cls.from_dict(_parse_json(text))
