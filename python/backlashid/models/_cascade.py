"""The cascade model (Section 3, Fig. 2): linear block (16) -> general backlash (1).

Real records rarely start at rest: ``simulate`` takes an ``initial_state`` and, with
``internals=True``, returns the ``final_state`` to continue a record from.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Literal, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import _core
from .._validation import as_scalar, as_signal, check_instance
from ..errors import DataError
from ._backlash import GeneralBacklash
from ._chain import FORMAT_VERSION, _ModelIO, _moving_fraction, _Simulation, _values
from ._linear import LinearBlock

__all__ = ["CascadeModel", "CascadeSimulation", "CascadeState"]


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
class CascadeSimulation(_Simulation):
    """A cascade simulation with its internal signals (eq 16, eq 12-13)."""

    output: NDArray[np.float64]  # y
    x: NDArray[np.float64]
    f1: NDArray[np.bool_]
    f2: NDArray[np.bool_]
    final_state: CascadeState


@dataclass(frozen=True, eq=True)
class CascadeModel(_ModelIO):
    """Linear block (16) followed by a general backlash (1): u -> x -> y."""

    linear: LinearBlock
    backlash: GeneralBacklash
    _native: Any = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        check_instance(self.linear, LinearBlock, "linear")
        check_instance(self.backlash, GeneralBacklash, "backlash")
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
        check_instance(s, CascadeState, "initial_state", DataError)
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
        check_instance(s, CascadeState, "initial_state", DataError)
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
