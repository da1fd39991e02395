"""The sandwich model (Section 4, Fig. 3): linear block (16) -> general backlash (1) -> linear
block (29).

Real records rarely start at rest: ``simulate`` takes an ``initial_state`` and, with
``internals=True``, returns the ``final_state`` to continue a record from.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import _core
from .._validation import as_signal, check_instance, format_list
from ..errors import DataError
from ._backlash import GeneralBacklash
from ._chain import FORMAT_VERSION, _ModelIO, _moving_fraction, _Simulation, _values
from ._linear import LinearBlock

__all__ = ["SandwichModel", "SandwichSimulation", "SandwichState"]


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
class SandwichSimulation(_Simulation):
    """A sandwich simulation with its internal signals."""

    output: NDArray[np.float64]  # w
    x: NDArray[np.float64]
    y: NDArray[np.float64]
    f1: NDArray[np.bool_]
    f2: NDArray[np.bool_]
    final_state: SandwichState


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
        check_instance(self.input_linear, LinearBlock, "input_linear")
        check_instance(self.backlash, GeneralBacklash, "backlash")
        check_instance(self.output_linear, LinearBlock, "output_linear")
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
        check_instance(s, SandwichState, "initial_state", DataError)
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
        check_instance(s, SandwichState, "initial_state", DataError)
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
