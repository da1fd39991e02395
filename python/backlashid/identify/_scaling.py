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

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import as_signal
from ..errors import DataError
from ..models import Model
from ._metrics import Metrics, evaluate

__all__ = ["Scaling", "evaluate_scaled", "simulate_scaled"]


@dataclass(frozen=True)
class Scaling:
    """u_m = (u - input_offset) / input_scale, y_m = (y - output_offset) / output_scale."""

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
        """Zero mean and unit standard deviation on the given (estimation) record."""
        u_arr, y_arr = as_signal(u, "u"), as_signal(y, "y")
        su, sy = float(np.std(u_arr)), float(np.std(y_arr))
        if su == 0.0 or sy == 0.0:
            raise DataError("the input or output is constant on the estimation record: it cannot be scaled (nor identified)")
        return cls(float(np.mean(u_arr)), su, float(np.mean(y_arr)), sy)

    @property
    def is_identity(self) -> bool:
        return self == Scaling()

    def input_to_model(self, u: ArrayLike) -> NDArray[np.float64]:
        return (as_signal(u, "u") - self.input_offset) / self.input_scale

    def output_to_model(self, y: ArrayLike) -> NDArray[np.float64]:
        return (as_signal(y, "y") - self.output_offset) / self.output_scale

    def output_from_model(self, y_m: ArrayLike) -> NDArray[np.float64]:
        return self.output_offset + self.output_scale * as_signal(y_m, "y")

    def to_dict(self) -> dict[str, float]:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Scaling:
        try:
            return cls(**{k: float(data[k]) for k in ("input_offset", "input_scale", "output_offset", "output_scale")})
        except (KeyError, TypeError, ValueError) as exc:
            raise DataError(f"not a scaling description ({exc}): expected input/output offset and scale") from None


def simulate_scaled(model: Model, scaling: Scaling, u: ArrayLike) -> NDArray[np.float64]:
    """Free-run simulation of ``model`` (fitted in model units) from a measured input, in
    measured output units."""
    return scaling.output_from_model(model.simulate(scaling.input_to_model(u)))


def evaluate_scaled(model: Model, scaling: Scaling, u: ArrayLike, y: ArrayLike, *, warmup: int = 0) -> Metrics:
    """:func:`backlashid.evaluate` in measured units: the affine map leaves NRMSE and fit %
    unchanged and multiplies both RMSEs by |output_scale|."""
    m = evaluate(model, scaling.input_to_model(u), scaling.output_to_model(y), warmup=warmup)
    k = abs(scaling.output_scale)
    return Metrics(
        simulation_rmse=m.simulation_rmse * k,
        simulation_nrmse=m.simulation_nrmse,
        simulation_fit_percent=m.simulation_fit_percent,
        prediction_rmse=m.prediction_rmse * k,
        samples=m.samples,
        warmup=m.warmup,
    )
