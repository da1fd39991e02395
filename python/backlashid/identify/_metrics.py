"""Fit metrics, labelled by what they measure.

- Free-run **simulation** error: the model is driven by the input alone (no measured output
  fed back). This is how models are judged; use data not used for fitting.
- **One-step prediction** error: the measured output of the previous samples is fed back
  where the model has it (the backlash memory y(t-1) of the cascade; the output block's past
  w(t-j) of the sandwich). Always smaller; it says little about simulation quality.

``warmup`` samples at the start are left out (records rarely start at rest), as in the fits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._validation import as_signal, check_warmup, one_record
from ..errors import DataError
from ..models import CascadeModel, Model, SandwichModel

__all__ = ["Metrics", "evaluate", "fit_percent", "nrmse", "one_step_prediction", "rmse"]



def _pair(y: ArrayLike, y_hat: ArrayLike, warmup: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    a, b = one_record(y, y_hat, ("y", "y_hat"), flatten=True)
    warmup = check_warmup(warmup, a.size)
    return a[warmup:], b[warmup:]


def rmse(y: ArrayLike, y_hat: ArrayLike, *, warmup: int = 0) -> float:
    """Root mean square of y - y_hat over the samples from ``warmup`` on."""
    a, b = _pair(y, y_hat, warmup)
    return float(np.sqrt(np.mean((a - b) ** 2)))


def nrmse(y: ArrayLike, y_hat: ArrayLike, *, warmup: int = 0) -> float:
    """RMSE divided by the standard deviation of y (both from ``warmup`` on): 0 is perfect, 1
    is no better than the mean."""
    a, b = _pair(y, y_hat, warmup)
    std = float(np.std(a))
    if std == 0.0:
        raise DataError("y is constant over the evaluated samples: NRMSE is undefined")
    return float(np.sqrt(np.mean((a - b) ** 2))) / std


def fit_percent(y: ArrayLike, y_hat: ArrayLike, *, warmup: int = 0) -> float:
    """100 (1 - ||y - y_hat|| / ||y - mean(y)||), as MATLAB's compare reports it; equals
    100 (1 - NRMSE)."""
    return 100.0 * (1.0 - nrmse(y, y_hat, warmup=warmup))


def one_step_prediction(model: Model, u: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
    """The output predicted one step ahead with the measured output fed back.

    Cascade: y(t) = B(x(t), y_meas(t-1)), x from the linear block driven by u (x is not
    measured), B one step of eq (1). Sandwich: w(t) = sum_i r_i y(t-i) - sum_j s_j w_meas(t-j),
    with the backlash output y simulated (it is not measured). Before the record: zero.
    """
    u_arr, y_arr = one_record(u, y, flatten=True)
    past = lambda s, k: np.concatenate([np.zeros(k), s[:-k]]) if k else s  # noqa: E731
    if isinstance(model, CascadeModel):
        x = model.linear.simulate(u_arr)
        left, right = model.backlash.left(x), model.backlash.right(x)
        y_prev = past(y_arr, 1)
        return np.where(left <= y_prev, left, np.where(right >= y_prev, right, y_prev))  # eq (1)
    if isinstance(model, SandwichModel):
        y_sim = model.simulate(u_arr, internals=True).y
        w = np.zeros_like(y_arr)
        for i, r_i in zip(model.output_linear.lags, model.r):  # lag 0 first with feedthrough
            w += r_i * past(y_sim, int(i))
        for j, s_j in enumerate(model.s, 1):
            w -= s_j * past(y_arr, j)
        return w
    raise DataError(f"model must be a CascadeModel or SandwichModel, got {type(model).__name__}")


@dataclass(frozen=True)
class Metrics:
    """Free-run simulation and one-step prediction errors of a model on one record."""

    simulation_rmse: float
    simulation_nrmse: float
    simulation_fit_percent: float
    prediction_rmse: float
    samples: int
    warmup: int

    def __str__(self) -> str:
        return (
            f"free-run simulation: RMSE {self.simulation_rmse:.6g}, NRMSE {self.simulation_nrmse:.4f}, "
            f"fit {self.simulation_fit_percent:.2f} %; one-step prediction: RMSE {self.prediction_rmse:.6g} "
            f"({self.samples} samples after a warm-up of {self.warmup})"
        )


def evaluate(model: Model, u: ArrayLike, y: ArrayLike, *, warmup: int = 0) -> Metrics:
    """Both kinds of error of ``model`` on the record (u, y), from sample ``warmup`` on."""
    u_arr, y_arr = as_signal(u, "u").ravel(), as_signal(y, "y").ravel()
    simulated = model.simulate(u_arr)
    predicted = one_step_prediction(model, u_arr, y_arr)
    return Metrics(
        simulation_rmse=rmse(y_arr, simulated, warmup=warmup),
        simulation_nrmse=nrmse(y_arr, simulated, warmup=warmup),
        simulation_fit_percent=fit_percent(y_arr, simulated, warmup=warmup),
        prediction_rmse=rmse(y_arr, predicted, warmup=warmup),
        samples=y_arr.size - warmup,
        warmup=warmup,
    )
