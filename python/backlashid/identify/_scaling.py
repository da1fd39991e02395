"""Offsets and scales between measured units and the units a model is fitted in.

Real records come in engineering units with offsets (a force sensor's zero, a mean position).
The backlash of eq (1) is centred: its dead band lies around x = 0 and y = 0 is inside it, so
an output offset cannot be absorbed by the model. The model is therefore fitted to

    u_m = (u - input_offset) / input_scale,    y_m = (y - output_offset) / output_scale

and its simulated output is mapped back, y = output_offset + output_scale * y_m. "auto" takes
the mean and standard deviation of the estimation record (a warm-up is not left out: the
offsets only centre the data).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docstrings import fill
from .._validation import as_signal
from ..errors import DataError
from ..models import Model
from ._metrics import Metrics, evaluate

__all__ = ["Scaling", "evaluate_scaled", "simulate_scaled"]


@dataclass(frozen=True)
class Scaling:
    """Offsets and scales between measured units and model units:
    u_m = (u - input_offset) / input_scale, y_m = (y - output_offset) / output_scale.

    Attributes
    ----------
    input_offset : float, default 0.0
        Subtracted from the measured input.
    input_scale : float, default 1.0
        Divides the input after the offset; non-zero.
    output_offset : float, default 0.0
        Subtracted from the measured output.
    output_scale : float, default 1.0
        Divides the output after the offset; non-zero.

    Raises
    ------
    DataError
        If a value is not finite or a scale is zero.

    Examples
    --------
    >>> from backlashid.identify import Scaling
    >>> scaling = Scaling(input_offset=1.0, input_scale=2.0)
    >>> scaling.input_to_model([1.0, 3.0]).tolist()
    [0.0, 1.0]
    """

    input_offset: float = 0.0
    input_scale: float = 1.0
    output_offset: float = 0.0
    output_scale: float = 1.0

    def __post_init__(self) -> None:
        for name, value in asdict(self).items():
            if not np.isfinite(value):
                raise DataError(f"{name} = {value}: give a finite number")
        for name in ("input_scale", "output_scale"):
            if getattr(self, name) == 0.0:
                raise DataError(f"{name} = 0: a scale must be non-zero")

    @classmethod
    def auto(cls, u: ArrayLike, y: ArrayLike) -> Scaling:
        """Zero mean and unit standard deviation on the given (estimation) record.

        Parameters
        ----------
        u : array_like
            Measured input.
        y : array_like
            Measured output.

        Returns
        -------
        Scaling
            The means as offsets, the standard deviations as scales.

        Raises
        ------
        DataError
            If the input or the output is constant.

        Examples
        --------
        >>> from backlashid.identify import Scaling
        >>> Scaling.auto([1.0, 3.0], [10.0, 20.0])
        Scaling(input_offset=2.0, input_scale=1.0, output_offset=15.0, output_scale=5.0)
        """
        u_arr, y_arr = as_signal(u, "u"), as_signal(y, "y")
        su, sy = float(np.std(u_arr)), float(np.std(y_arr))
        if su == 0.0 or sy == 0.0:
            raise DataError("the input or output is constant on the estimation record: it cannot be scaled (nor identified)")
        return cls(float(np.mean(u_arr)), su, float(np.mean(y_arr)), sy)

    @property
    def is_identity(self) -> bool:
        """True when model units are the measured units (no offsets, unit scales)."""
        return self == Scaling()

    def input_to_model(self, u: ArrayLike) -> NDArray[np.float64]:
        """The measured input in model units.

        Parameters
        ----------
        u : array_like
            Measured input.

        Returns
        -------
        numpy.ndarray
            (u - input_offset) / input_scale.
        """
        return (as_signal(u, "u") - self.input_offset) / self.input_scale

    def input_from_model(self, u_m: ArrayLike) -> NDArray[np.float64]:
        """A model input in measured units (e.g. a compensator's input, to apply to the device).

        Parameters
        ----------
        u_m : array_like
            Input in model units.

        Returns
        -------
        numpy.ndarray
            input_offset + input_scale * u_m.

        Examples
        --------
        >>> from backlashid.identify import Scaling
        >>> s = Scaling(1.0, 2.0, 0.0, 1.0)
        >>> s.input_from_model(s.input_to_model([3.0, 5.0])).tolist()
        [3.0, 5.0]
        """
        return self.input_offset + self.input_scale * as_signal(u_m, "u")

    def output_to_model(self, y: ArrayLike) -> NDArray[np.float64]:
        """The measured output in model units.

        Parameters
        ----------
        y : array_like
            Measured output.

        Returns
        -------
        numpy.ndarray
            (y - output_offset) / output_scale.
        """
        return (as_signal(y, "y") - self.output_offset) / self.output_scale

    def output_from_model(self, y_m: ArrayLike) -> NDArray[np.float64]:
        """A model output in measured units.

        Parameters
        ----------
        y_m : array_like
            Output in model units.

        Returns
        -------
        numpy.ndarray
            output_offset + output_scale * y_m.
        """
        return self.output_offset + self.output_scale * as_signal(y_m, "y")

    def to_dict(self) -> dict[str, float]:
        """The scaling as a JSON-safe dict.

        Returns
        -------
        dict of str to float
            The four fields by name.
        """
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Scaling:
        """The scaling of a :meth:`to_dict` dict.

        Parameters
        ----------
        data : dict
            With the keys input_offset, input_scale, output_offset, output_scale.

        Returns
        -------
        Scaling
            The scaling.

        Raises
        ------
        DataError
            If a key is missing or a value is not a number.
        """
        try:
            return cls(**{k: float(data[k]) for k in ("input_offset", "input_scale", "output_offset", "output_scale")})
        except (KeyError, TypeError, ValueError, OverflowError) as exc:
            raise DataError(f"not a scaling description ({exc}): expected input/output offset and scale") from None


_SCALED_DOC = """Parameters
----------
model : CascadeModel or SandwichModel
    A model fitted to scaled data.
scaling : Scaling
    The scaling of that fit.
u : array_like
    Measured input."""


@fill(scaled=_SCALED_DOC)
def simulate_scaled(model: Model, scaling: Scaling, u: ArrayLike) -> NDArray[np.float64]:
    """Free-run simulation of a model fitted in model units, from and to measured units.

    {scaled}

    Returns
    -------
    numpy.ndarray
        The simulated output in measured units.

    Examples
    --------
    >>> import backlashid as bid
    >>> from backlashid.identify import Scaling, simulate_scaled
    >>> model, u = bid.example1(), [0.0, 0.9, 0.4]
    >>> simulate_scaled(model, Scaling(output_offset=5.0), u).tolist() == (5.0 + model.simulate(u)).tolist()
    True
    """
    return scaling.output_from_model(model.simulate(scaling.input_to_model(u)))


@fill(scaled=_SCALED_DOC)
def evaluate_scaled(model: Model, scaling: Scaling, u: ArrayLike, y: ArrayLike, *, warmup: int = 0, init_samples: int = 0) -> Metrics:
    """:func:`backlashid.evaluate` in measured units.

    The affine map leaves NRMSE and fit % unchanged and multiplies both RMSEs by
    ``abs(output_scale)``.

    {scaled}
    y : array_like
        Measured output, as long as ``u``.
    warmup : int, default 0
        Samples at the start left out.
    init_samples : int, default 0
        Samples at the start that initialise the simulation's state (see
        :func:`backlashid.evaluate`); 0: start at rest.

    Returns
    -------
    Metrics
        The metrics, RMSEs in measured output units.

    Raises
    ------
    DataError
        As :func:`backlashid.evaluate`.

    Examples
    --------
    >>> import backlashid as bid
    >>> from backlashid.identify import Scaling, evaluate_scaled
    >>> data = bid.example_data(bid.example1(), 500, snr=None, seed=0)
    >>> evaluate_scaled(bid.example1(), Scaling(), data.u, data.noisy).simulation_rmse
    0.0
    """
    m = evaluate(model, scaling.input_to_model(u), scaling.output_to_model(y), warmup=warmup, init_samples=init_samples)
    k = abs(scaling.output_scale)
    return replace(m, simulation_rmse=m.simulation_rmse * k, prediction_rmse=m.prediction_rmse * k)
