"""The cascade (Section 3, Fig. 2) and sandwich (Section 4, Fig. 3) models.

Real records rarely start at rest: every ``simulate`` takes an ``initial_state`` and, with
``internals=True``, returns the ``final_state`` to continue a record from.
"""

from __future__ import annotations

import json
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from typing import Any, Literal, Union, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import _core
from ._convert import as_scalar, as_signal, format_list
from .backlash import GeneralBacklash
from .errors import DataError, ModelError
from .linear import LinearBlock

__all__ = [
    "CascadeModel",
    "CascadeState",
    "CascadeSimulation",
    "SandwichModel",
    "SandwichState",
    "SandwichSimulation",
    "model_from_dict",
    "model_from_json",
]

FORMAT_VERSION = 1


def _values(values: ArrayLike, name: str) -> tuple[float, ...]:
    return tuple(float(v) for v in as_signal(values, name).ravel())


@dataclass(frozen=True)
class CascadeState:
    """Before the first sample: ``u_past = [u(0), u(-1), ..]`` (na values),
    ``x_past = [x(0), ..]`` (nb values), most recent first, and the backlash memory y(0)."""

    u_past: tuple[float, ...]
    x_past: tuple[float, ...]
    y_prev: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "u_past", _values(self.u_past, "u_past"))
        object.__setattr__(self, "x_past", _values(self.x_past, "x_past"))
        object.__setattr__(self, "y_prev", as_scalar(self.y_prev, "y_prev", DataError))


@dataclass(frozen=True)
class SandwichState:
    """Before the first sample: the input block's ``u_past``, ``x_past`` and the output
    block's ``y_past = [y(0), y(-1), ..]`` (nr values; y(0) is also the backlash memory) and
    ``w_past = [w(0), ..]`` (ns values), most recent first."""

    u_past: tuple[float, ...]
    x_past: tuple[float, ...]
    y_past: tuple[float, ...]
    w_past: tuple[float, ...]

    def __post_init__(self) -> None:
        for name in ("u_past", "x_past", "y_past", "w_past"):
            object.__setattr__(self, name, _values(getattr(self, name), name))


@dataclass(frozen=True)
class CascadeSimulation:
    """A cascade simulation with its internal signals (eq 16, eq 12-13)."""

    output: NDArray[np.float64]  # y
    x: NDArray[np.float64]
    f1: NDArray[np.bool_]
    f2: NDArray[np.bool_]
    final_state: CascadeState

    @property
    def moving_fraction(self) -> float:
        """Fraction of samples where the backlash output moved along a branch (f1 or f2)."""
        return float(np.mean(self.f1 | self.f2))


@dataclass(frozen=True)
class SandwichSimulation:
    """A sandwich simulation with its internal signals."""

    output: NDArray[np.float64]  # w
    x: NDArray[np.float64]
    y: NDArray[np.float64]
    f1: NDArray[np.bool_]
    f2: NDArray[np.bool_]
    final_state: SandwichState

    @property
    def moving_fraction(self) -> float:
        return float(np.mean(self.f1 | self.f2))


def _check_type(value: Any, cls: type, name: str) -> None:
    if not isinstance(value, cls):
        raise ModelError(f"{name} must be a {cls.__name__}, got {type(value).__name__}")


class _ModelIO(ABC):
    """JSON and dict round trips shared by both model kinds."""

    @abstractmethod
    def to_dict(self) -> dict[str, Any]:
        """The model as a plain, JSON-safe dict."""

    def to_json(self, **kwargs: Any) -> str:
        """The model as JSON text (``json.dumps`` keyword arguments pass through)."""
        return json.dumps(self.to_dict(), **kwargs)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Any:
        model = model_from_dict(data)
        if not isinstance(model, cls):
            raise ModelError(f"this describes a {type(model).__name__}, not a {cls.__name__}")
        return model

    @classmethod
    def from_json(cls, text: str) -> Any:
        return cls.from_dict(_parse_json(text))


@dataclass(frozen=True, eq=True)
class CascadeModel(_ModelIO):
    """Linear block (16) followed by a general backlash (1): u -> x -> y."""

    linear: LinearBlock
    backlash: GeneralBacklash
    _native: Any = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        _check_type(self.linear, LinearBlock, "linear")
        _check_type(self.backlash, GeneralBacklash, "backlash")
        object.__setattr__(self, "_native", _core.CascadeModel(self.linear._native, self.backlash._native))

    def __reduce__(self) -> tuple[Any, ...]:
        return (CascadeModel, (self.linear, self.backlash))

    def rest_state(self) -> CascadeState:
        """The paper's start: every past signal zero, y(0) = 0."""
        return CascadeState((0.0,) * self.linear.na, (0.0,) * self.linear.nb, 0.0)

    @overload
    def simulate(
        self, u: ArrayLike, *, initial_state: CascadeState | None = ..., internals: Literal[False] = ...
    ) -> NDArray[np.float64]: ...

    @overload
    def simulate(
        self, u: ArrayLike, *, initial_state: CascadeState | None = ..., internals: Literal[True]
    ) -> CascadeSimulation: ...

    def simulate(
        self, u: ArrayLike, *, initial_state: CascadeState | None = None, internals: bool = False
    ) -> NDArray[np.float64] | CascadeSimulation:
        """The output y for input u; with ``internals=True`` a :class:`CascadeSimulation`
        that also holds x, f1, f2 and the final state."""
        s = initial_state if initial_state is not None else self.rest_state()
        _check_state(s, CascadeState)
        u = as_signal(u, "u")
        if not internals:
            return self._native.simulate(u, list(s.u_past), list(s.x_past), s.y_prev)
        x, y, f1, f2, (u_past, x_past, y_prev) = self._native.simulate_internals(
            u, list(s.u_past), list(s.x_past), s.y_prev
        )
        return CascadeSimulation(y, x, f1, f2, CascadeState(u_past, x_past, y_prev))

    def moving_fraction(self, u: ArrayLike, *, initial_state: CascadeState | None = None, warmup: int = 0) -> float:
        """The fraction of samples after ``warmup`` on which the backlash moves (f1 or f2 of
        eq 12-13): ``simulate(u, internals=True)``'s flags, counted in the core."""
        s = initial_state if initial_state is not None else self.rest_state()
        _check_state(s, CascadeState)
        return _moving_fraction(self._native, u, (list(s.u_past), list(s.x_past), s.y_prev), warmup)

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": "cascade",
            "format_version": FORMAT_VERSION,
            "linear": self.linear.to_dict(),
            "backlash": self.backlash.to_dict(),
        }

    def __str__(self) -> str:
        return f"Cascade model u -> x -> y\n  {self.linear.equation('u', 'x')}\n  {self.backlash!r}"

    def __repr__(self) -> str:
        return f"CascadeModel(linear={self.linear!r}, backlash={self.backlash!r})"


@dataclass(frozen=True, eq=True)
class SandwichModel(_ModelIO):
    """Input block (16), general backlash (1), output block (29): u -> x -> y -> w.

    The output block is a :class:`LinearBlock` with a = r and b = s of eq (29).
    """

    input_linear: LinearBlock
    backlash: GeneralBacklash
    output_linear: LinearBlock
    _native: Any = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        _check_type(self.input_linear, LinearBlock, "input_linear")
        _check_type(self.backlash, GeneralBacklash, "backlash")
        _check_type(self.output_linear, LinearBlock, "output_linear")
        object.__setattr__(
            self,
            "_native",
            _core.SandwichModel(self.input_linear._native, self.backlash._native, self.output_linear._native),
        )

    def __reduce__(self) -> tuple[Any, ...]:
        return (SandwichModel, (self.input_linear, self.backlash, self.output_linear))

    @property
    def r(self) -> NDArray[np.float64]:
        return self.output_linear.a

    @property
    def s(self) -> NDArray[np.float64]:
        return self.output_linear.b

    def rest_state(self) -> SandwichState:
        return SandwichState(
            (0.0,) * self.input_linear.na,
            (0.0,) * self.input_linear.nb,
            (0.0,) * self.output_linear.na,
            (0.0,) * self.output_linear.nb,
        )

    @overload
    def simulate(
        self, u: ArrayLike, *, initial_state: SandwichState | None = ..., internals: Literal[False] = ...
    ) -> NDArray[np.float64]: ...

    @overload
    def simulate(
        self, u: ArrayLike, *, initial_state: SandwichState | None = ..., internals: Literal[True]
    ) -> SandwichSimulation: ...

    def simulate(
        self, u: ArrayLike, *, initial_state: SandwichState | None = None, internals: bool = False
    ) -> NDArray[np.float64] | SandwichSimulation:
        """The output w for input u; with ``internals=True`` a :class:`SandwichSimulation`
        that also holds x, y, f1, f2 and the final state."""
        s = initial_state if initial_state is not None else self.rest_state()
        _check_state(s, SandwichState)
        u = as_signal(u, "u")
        args = (list(s.u_past), list(s.x_past), list(s.y_past), list(s.w_past))
        if not internals:
            return self._native.simulate(u, *args)
        x, y, w, f1, f2, final = self._native.simulate_internals(u, *args)
        return SandwichSimulation(w, x, y, f1, f2, SandwichState(*final))

    def moving_fraction(self, u: ArrayLike, *, initial_state: SandwichState | None = None, warmup: int = 0) -> float:
        """The fraction of samples after ``warmup`` on which the backlash moves (f1 or f2 of
        eq 12-13): ``simulate(u, internals=True)``'s flags, counted in the core."""
        s = initial_state if initial_state is not None else self.rest_state()
        _check_state(s, SandwichState)
        state = (list(s.u_past), list(s.x_past), list(s.y_past), list(s.w_past))
        return _moving_fraction(self._native, u, state, warmup)

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": "sandwich",
            "format_version": FORMAT_VERSION,
            "input_linear": self.input_linear.to_dict(),
            "backlash": self.backlash.to_dict(),
            "output_linear": self.output_linear.to_dict(),
        }

    def __str__(self) -> str:
        return (
            "Sandwich model u -> x -> y -> w\n"
            f"  {self.input_linear.equation('u', 'x')}\n"
            f"  {self.backlash!r}\n"
            f"  {self.output_linear.equation('y', 'w')}"
        )

    def __repr__(self) -> str:
        return (
            f"SandwichModel(input_linear={self.input_linear!r}, backlash={self.backlash!r}, "
            f"output_linear=LinearBlock(r={format_list(self.r)}, s={format_list(self.s)}"
            f"{', feedthrough=True' if self.output_linear.feedthrough else ''}))"
        )


Model = Union[CascadeModel, SandwichModel]


def _check_state(state: Any, cls: type) -> None:
    if not isinstance(state, cls):
        raise DataError(f"initial_state must be a {cls.__name__}, got {type(state).__name__}")


def _moving_fraction(native: Any, u: ArrayLike, state: tuple[Any, ...], warmup: Any) -> float:
    """The core's count of moving samples after ``warmup`` (checked), as a fraction."""
    u = as_signal(u, "u")
    n = len(u)
    if n == 0:
        raise DataError("u is empty: give at least one sample")
    if isinstance(warmup, bool) or not isinstance(warmup, (int, np.integer)) or not 0 <= warmup < n:
        raise DataError(f"warmup = {warmup!r}: give a whole number of samples, 0 <= warmup < {n} (the record length)")
    return native.moving_count(u, *state, int(warmup)) / (n - int(warmup))


def model_from_dict(data: dict[str, Any]) -> Model:
    """Rebuild a model from :meth:`CascadeModel.to_dict` / :meth:`SandwichModel.to_dict`."""
    try:
        kind = data["model"]
        if kind == "cascade":
            return CascadeModel(LinearBlock.from_dict(data["linear"]), GeneralBacklash.from_dict(data["backlash"]))
        if kind == "sandwich":
            return SandwichModel(
                LinearBlock.from_dict(data["input_linear"]),
                GeneralBacklash.from_dict(data["backlash"]),
                LinearBlock.from_dict(data["output_linear"]),
            )
    except (KeyError, TypeError) as exc:
        raise ModelError(f"not a backlashid model description (missing {exc}): use a dict from to_dict()") from None
    raise ModelError(f"unknown model kind {kind!r}: expected 'cascade' or 'sandwich'")


def _parse_json(text: str) -> dict[str, Any]:
    if not isinstance(text, (str, bytes, bytearray)):
        raise ModelError(f"expected JSON text, got {type(text).__name__}: pass the string from to_json()")
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ModelError(f"not valid JSON ({exc})") from None
    if not isinstance(data, dict):
        raise ModelError("not a backlashid model description: expected a JSON object")
    return data


def model_from_json(text: str) -> Model:
    """Rebuild a model from :meth:`to_json` text."""
    return model_from_dict(_parse_json(text))
