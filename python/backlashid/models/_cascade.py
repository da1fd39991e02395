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
from .._docstrings import fill
from .._validation import as_signal, check_flag, check_instance
from ..errors import DataError
from ._backlash import GeneralBacklash
from ._chain import DOCS, FORMAT_VERSION, _ModelIO, _moving_fraction, _Simulation, _State
from ._linear import LinearBlock
from ._prediction import COVARIANCE_ATTRIBUTE, SIMULATE_BAND, SIMULATE_BAND_RAISES, ParameterCovariance, Prediction, linear_band

__all__ = ["CascadeModel", "CascadeSimulation", "CascadeState"]


@dataclass(frozen=True)
class CascadeState(_State):
    """The state of a cascade before the first sample, most recent values first (a value
    that is not a finite number raises DataError).

    Attributes
    ----------
    u_past : tuple of float
        ``[u(0), u(-1), ..]``, na values.
    x_past : tuple of float
        ``[x(0), x(-1), ..]``, nb values.
    y_prev : float, default 0.0
        The backlash memory y(0).

    Examples
    --------
    >>> import backlashid as bid
    >>> bid.example1().rest_state()
    CascadeState(u_past=(0.0, 0.0), x_past=(0.0, 0.0), y_prev=0.0)
    """

    u_past: tuple[float, ...]
    x_past: tuple[float, ...]
    y_prev: float = 0.0


@dataclass(frozen=True)
@fill(outputs=DOCS.outputs.format(output="y", block="linear block"), signals=DOCS.signals.format(state="CascadeState"))
class CascadeSimulation(_Simulation):
    """A cascade simulation with its internal signals (eq 16, eq 12-13).

    {outputs}
    {signals}

    Examples
    --------
    >>> import backlashid as bid
    >>> sim = bid.example1().simulate([0.0, 0.9, 0.4, -0.8], internals=True)
    >>> sim.moving_fraction(), sim.final_state.u_past
    (0.5, (-0.8, 0.4))
    """

    output: NDArray[np.float64]
    x: NDArray[np.float64]
    f1: NDArray[np.bool_]
    f2: NDArray[np.bool_]
    final_state: CascadeState


@dataclass(frozen=True, eq=True)
@fill(model=DOCS.model, covariance=COVARIANCE_ATTRIBUTE)
class CascadeModel(_ModelIO):
    """The cascade of Section 3 (Fig. 2): a linear block (16) followed by a general
    backlash (1), u -> x -> y.

    {model}
    linear : LinearBlock
        The linear block, u -> x.
    backlash : GeneralBacklash
        The backlash, x -> y.
    {covariance}

    Examples
    --------
    >>> from backlashid import CascadeModel, GeneralBacklash, LinearBlock
    >>> model = CascadeModel(LinearBlock([1.0]), GeneralBacklash(0.5, 0.5, [1.0], [1.0]))
    >>> model.simulate([0.0, 2.0, 1.0, 0.0]).tolist()
    [0.0, 0.0, 1.5, 1.5]
    """

    linear: LinearBlock
    backlash: GeneralBacklash
    covariance: ParameterCovariance | None = field(default=None, repr=False, compare=False)
    _native: Any = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        check_instance(self.linear, LinearBlock, "linear")
        check_instance(self.backlash, GeneralBacklash, "backlash")
        if self.covariance is not None:
            check_instance(self.covariance, ParameterCovariance, "covariance")
        object.__setattr__(self, "_native", _core.CascadeModel(self.linear._native, self.backlash._native))

    def __reduce__(self) -> tuple[Any, ...]:
        return (CascadeModel, (self.linear, self.backlash, self.covariance))

    def rest_state(self) -> CascadeState:
        """The paper's start: every past signal zero, y(0) = 0.

        Returns
        -------
        CascadeState
            The state at rest.
        """
        return CascadeState((0.0,) * self.linear.na, (0.0,) * self.linear.nb, 0.0)

    @overload
    def simulate(
        self, u: ArrayLike, *, initial_state: CascadeState | None = ..., internals: Literal[False] = ...,
        band: None = ..., covariance: ParameterCovariance | None = ...,
    ) -> NDArray[np.float64]: ...

    @overload
    def simulate(
        self, u: ArrayLike, *, initial_state: CascadeState | None = ..., internals: Literal[True],
        band: None = ..., covariance: ParameterCovariance | None = ...,
    ) -> CascadeSimulation: ...

    @overload
    def simulate(
        self, u: ArrayLike, *, initial_state: CascadeState | None = ..., internals: Literal[False] = ...,
        band: float, covariance: ParameterCovariance | None = ...,
    ) -> Prediction: ...

    @fill(simulate=DOCS.simulate.format(state="CascadeState"), raises=DOCS.simulate_raises.format(state="CascadeState"), band=SIMULATE_BAND.format(kind="CascadeSimulation"),
          band_raises=SIMULATE_BAND_RAISES)
    def simulate(
        self, u: ArrayLike, *, initial_state: CascadeState | None = None, internals: bool = False,
        band: float | None = None, covariance: ParameterCovariance | None = None,
    ) -> NDArray[np.float64] | CascadeSimulation | Prediction:
        """The output y for the input u.

        Parameters
        ----------
        {simulate}
        {band}

        Returns
        -------
        numpy.ndarray or CascadeSimulation or Prediction
            y(1), y(2), ..., the simulation with its internal signals, or with ``band`` the
            output and its prediction band.

        {raises}
        {band_raises}
        """
        s = initial_state if initial_state is not None else self.rest_state()
        check_instance(s, CascadeState, "initial_state", DataError)
        u = as_signal(u, "u")
        if band is not None:
            if check_flag(internals, "internals"):
                raise DataError("band and internals=True cannot be combined: ask for one")
            return linear_band(self, u, band, s, covariance)
        if not check_flag(internals, "internals"):
            return self._native.simulate(u, list(s.u_past), list(s.x_past), s.y_prev)
        x, y, f1, f2, (u_past, x_past, y_prev) = self._native.simulate_internals(
            u, list(s.u_past), list(s.x_past), s.y_prev
        )
        return CascadeSimulation(y, x, f1, f2, CascadeState(u_past, x_past, y_prev))

    @fill(simulate=DOCS.simulate.format(state="CascadeState"), moving=DOCS.moving)
    def moving_fraction(self, u: ArrayLike, *, initial_state: CascadeState | None = None, warmup: int = 0) -> float:
        """How often the backlash moves on the input u.

        Parameters
        ----------
        {simulate}
        {moving}

        Examples
        --------
        >>> import backlashid as bid
        >>> bid.example1().moving_fraction([0.0, 0.9, 0.4, -0.8], warmup=2)
        1.0
        """
        s = initial_state if initial_state is not None else self.rest_state()
        check_instance(s, CascadeState, "initial_state", DataError)
        return _moving_fraction(self._native, u, (list(s.u_past), list(s.x_past), s.y_prev), warmup)

    def to_dict(self) -> dict[str, Any]:
        """The cascade as a plain, JSON-safe dict.

        Returns
        -------
        dict
            ``{"model": "cascade", "format_version": 1, "linear": .., "backlash": ..}``.
        """
        return {
            "model": "cascade",
            "format_version": FORMAT_VERSION,
            "linear": self.linear.to_dict(),
            "backlash": self.backlash.to_dict(),
            **({"covariance": self.covariance.to_dict()} if self.covariance is not None else {}),
        }

    def __str__(self) -> str:
        return f"Cascade model u -> x -> y\n  {self.linear.equation('u', 'x')}\n  {self.backlash!r}"

    def __repr__(self) -> str:
        return f"CascadeModel(linear={self.linear!r}, backlash={self.backlash!r})"
