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
from .._docstrings import fill
from .._validation import as_signal, check_flag, check_instance, format_list
from ..errors import DataError
from ._backlash import GeneralBacklash
from ._chain import DOCS, FORMAT_VERSION, _ModelIO, _moving_fraction, _Simulation, _State
from ._linear import LinearBlock
from ._prediction import COVARIANCE_ATTRIBUTE, SIMULATE_BAND, SIMULATE_BAND_RAISES, ParameterCovariance, Prediction, linear_band

__all__ = ["SandwichModel", "SandwichSimulation", "SandwichState"]


@dataclass(frozen=True)
class SandwichState(_State):
    """The state of a sandwich before the first sample, most recent values first (a value
    that is not a finite number raises DataError).

    Attributes
    ----------
    u_past : tuple of float
        The input block's ``[u(0), u(-1), ..]``, na values.
    x_past : tuple of float
        The input block's ``[x(0), x(-1), ..]``, nb values.
    y_past : tuple of float
        The output block's ``[y(0), y(-1), ..]``, nr values; y(0) is also the backlash memory.
    w_past : tuple of float
        The output block's ``[w(0), w(-1), ..]``, ns values.
    """

    u_past: tuple[float, ...]
    x_past: tuple[float, ...]
    y_past: tuple[float, ...]
    w_past: tuple[float, ...]


@dataclass(frozen=True)
@fill(outputs=DOCS.outputs.format(output="w", block="input block"), signals=DOCS.signals.format(state="SandwichState"))
class SandwichSimulation(_Simulation):
    """A sandwich simulation with its internal signals.

    {outputs}
    y : numpy.ndarray
        The backlash's output, the output block's input.
    {signals}
    """

    output: NDArray[np.float64]
    x: NDArray[np.float64]
    y: NDArray[np.float64]
    f1: NDArray[np.bool_]
    f2: NDArray[np.bool_]
    final_state: SandwichState


@dataclass(frozen=True, eq=True)
@fill(model=DOCS.model, covariance=COVARIANCE_ATTRIBUTE)
class SandwichModel(_ModelIO):
    """The sandwich of Section 4 (Fig. 3): input block (16), general backlash (1), output
    block (29), u -> x -> y -> w.

    The output block is a :class:`LinearBlock` with a = r and b = s of eq (29).

    {model}
    input_linear : LinearBlock
        The input block, u -> x.
    backlash : GeneralBacklash
        The backlash, x -> y.
    output_linear : LinearBlock
        The output block, y -> w.
    {covariance}

    Examples
    --------
    >>> import backlashid as bid
    >>> model = bid.example2()
    >>> model.r.tolist(), model.output_linear.equation("y", "w")
    ([1.0, 0.15], 'w(t) = 1 y(t-1) + 0.15 y(t-2) + 0.2 w(t-1) - 0.35 w(t-2)')
    """

    input_linear: LinearBlock
    backlash: GeneralBacklash
    output_linear: LinearBlock
    covariance: ParameterCovariance | None = field(default=None, repr=False, compare=False)
    _native: Any = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        check_instance(self.input_linear, LinearBlock, "input_linear")
        check_instance(self.backlash, GeneralBacklash, "backlash")
        check_instance(self.output_linear, LinearBlock, "output_linear")
        if self.covariance is not None:
            check_instance(self.covariance, ParameterCovariance, "covariance")
        object.__setattr__(
            self,
            "_native",
            _core.SandwichModel(self.input_linear._native, self.backlash._native, self.output_linear._native),
        )

    def __reduce__(self) -> tuple[Any, ...]:
        return (SandwichModel, (self.input_linear, self.backlash, self.output_linear, self.covariance))

    @property
    def r(self) -> NDArray[np.float64]:
        """The output block's input coefficients r of eq (29)."""
        return self.output_linear.a

    @property
    def s(self) -> NDArray[np.float64]:
        """The output block's output coefficients s of eq (29)."""
        return self.output_linear.b

    def rest_state(self) -> SandwichState:
        """The paper's start: every past signal zero.

        Returns
        -------
        SandwichState
            The state at rest.
        """
        return SandwichState(
            (0.0,) * self.input_linear.na,
            (0.0,) * self.input_linear.nb,
            (0.0,) * self.output_linear.na,
            (0.0,) * self.output_linear.nb,
        )

    @overload
    def simulate(
        self, u: ArrayLike, *, initial_state: SandwichState | None = ..., internals: Literal[False] = ...,
        band: None = ..., covariance: ParameterCovariance | None = ...,
    ) -> NDArray[np.float64]: ...

    @overload
    def simulate(
        self, u: ArrayLike, *, initial_state: SandwichState | None = ..., internals: Literal[True],
        band: None = ..., covariance: ParameterCovariance | None = ...,
    ) -> SandwichSimulation: ...

    @overload
    def simulate(
        self, u: ArrayLike, *, initial_state: SandwichState | None = ..., internals: Literal[False] = ...,
        band: float, covariance: ParameterCovariance | None = ...,
    ) -> Prediction: ...

    @fill(simulate=DOCS.simulate.format(state="SandwichState"), raises=DOCS.simulate_raises.format(state="SandwichState"), band=SIMULATE_BAND.format(kind="SandwichSimulation"),
          band_raises=SIMULATE_BAND_RAISES)
    def simulate(
        self, u: ArrayLike, *, initial_state: SandwichState | None = None, internals: bool = False,
        band: float | None = None, covariance: ParameterCovariance | None = None,
    ) -> NDArray[np.float64] | SandwichSimulation | Prediction:
        """The output w for the input u.

        Parameters
        ----------
        {simulate}
        {band}

        Returns
        -------
        numpy.ndarray or SandwichSimulation or Prediction
            w(1), w(2), ..., the simulation with its internal signals, or with ``band`` the
            output and its prediction band.

        {raises}
        {band_raises}
        """
        s = initial_state if initial_state is not None else self.rest_state()
        check_instance(s, SandwichState, "initial_state", DataError)
        u = as_signal(u, "u")
        if band is not None:
            if check_flag(internals, "internals"):
                raise DataError("band and internals=True cannot be combined: ask for one")
            return linear_band(self, u, band, s, covariance)
        args = (list(s.u_past), list(s.x_past), list(s.y_past), list(s.w_past))
        if not check_flag(internals, "internals"):
            return self._native.simulate(u, *args)
        x, y, w, f1, f2, final = self._native.simulate_internals(u, *args)
        return SandwichSimulation(w, x, y, f1, f2, SandwichState(*final))

    @fill(simulate=DOCS.simulate.format(state="SandwichState"), moving=DOCS.moving)
    def moving_fraction(self, u: ArrayLike, *, initial_state: SandwichState | None = None, warmup: int = 0) -> float:
        """How often the backlash moves on the input u.

        Parameters
        ----------
        {simulate}
        {moving}
        """
        s = initial_state if initial_state is not None else self.rest_state()
        check_instance(s, SandwichState, "initial_state", DataError)
        state = (list(s.u_past), list(s.x_past), list(s.y_past), list(s.w_past))
        return _moving_fraction(self._native, u, state, warmup)

    def to_dict(self) -> dict[str, Any]:
        """The sandwich as a plain, JSON-safe dict.

        Returns
        -------
        dict
            ``{"model": "sandwich", "format_version": 1, "input_linear": .., "backlash": ..,
            "output_linear": ..}``.
        """
        return {
            "model": "sandwich",
            "format_version": FORMAT_VERSION,
            "input_linear": self.input_linear.to_dict(),
            "backlash": self.backlash.to_dict(),
            "output_linear": self.output_linear.to_dict(),
            **({"covariance": self.covariance.to_dict()} if self.covariance is not None else {}),
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
