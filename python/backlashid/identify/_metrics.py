"""Fit metrics, labelled by what they measure.

- Free-run **simulation** error: the model is driven by the input alone (no measured output
  fed back). This is how models are judged; use data not used for fitting.
- **One-step prediction** error: the measured output of the previous samples is fed back
  where the model has it (the backlash memory y(t-1) of the cascade; the output block's past
  w(t-j) of the sandwich). Often smaller, but not always: the fed-back output carries the
  measurement noise, which the model's feedback passes on (on the Wiener-Hammerstein benchmark
  the sandwich's one-step RMSE is 0.75 mV against a free-run 0.51 mV). Either way it says
  little about simulation quality.

``warmup`` samples at the start are left out (records rarely start at rest), as in the fits.
"""

from __future__ import annotations

import warnings
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docstrings import AXES, fill
from .._measures import fit_percent, nrmse, rmse
from .._validation import as_signal, check_finite, check_int, check_warmup, one_record
from ..errors import DataError, FitWarning
from ..models import CascadeModel, CascadeState, Model, SandwichModel, SandwichState, check_model
from ._start_check import undetermined_start
from ._state import started_from_samples

__all__ = ["Metrics", "evaluate", "fit_percent", "nrmse", "one_step_prediction", "rmse"]


def one_step_prediction(model: Model, u: ArrayLike, y: ArrayLike) -> NDArray[np.float64]:
    """The output predicted one step ahead with the measured output fed back.

    Cascade: y(t) = B(x(t), y_meas(t-1)), x from the linear block driven by u (x is not
    measured), B one step of eq (1). Sandwich: w(t) = sum_i r_i y(t-i) - sum_j s_j w_meas(t-j),
    with the backlash output y simulated (it is not measured). Before the record: zero.

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The model.
    u : array_like
        Input u(t).
    y : array_like
        Measured output (w for a sandwich), as long as ``u``.

    Returns
    -------
    numpy.ndarray
        The one-step-ahead prediction of every sample.

    Raises
    ------
    DataError
        If u and y differ in length or ``model`` is not a model.

    Examples
    --------
    >>> import backlashid as bid
    >>> model = bid.example1()
    >>> u = [0.0, 0.9, 0.4, -0.8]
    >>> bool(abs(bid.identify.one_step_prediction(model, u, model.simulate(u)) - model.simulate(u)).max() < 1e-12)
    True
    """
    u_arr, y_arr = one_record(u, y, flatten=True)
    # s delayed by k samples, zeros before the record (also for lags longer than the record)
    past = lambda s, k: np.concatenate([np.zeros(min(k, s.size)), s[: max(s.size - k, 0)]]) if k else s  # noqa: E731
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
    """Free-run simulation and one-step prediction errors of a model on one record.

    Attributes
    ----------
    simulation_rmse : float
        RMSE of the free-run simulation.
    simulation_nrmse : float
        That RMSE divided by the standard deviation of the measured output.
    simulation_fit_percent : float
        100 (1 - NRMSE).
    prediction_rmse : float
        RMSE of the one-step-ahead prediction.
    samples : int
        Samples evaluated (after the warm-up).
    warmup : int
        Samples at the start left out.

    Examples
    --------
    >>> import backlashid as bid
    >>> data = bid.example_data(bid.example1(), 1500, snr=25, seed=0)
    >>> metrics = bid.evaluate(bid.example1(), data.u, data.noisy, warmup=10)
    >>> metrics.samples, round(metrics.simulation_fit_percent)
    (1490, 96)
    """

    simulation_rmse: float
    simulation_nrmse: float
    simulation_fit_percent: float
    prediction_rmse: float
    samples: int
    warmup: int

    def summary(self) -> str:
        """The metrics as one line of text.

        Returns
        -------
        str
            Each metric labelled by what it measures.
        """
        return (
            f"free-run simulation: RMSE {self.simulation_rmse:.6g}, NRMSE {self.simulation_nrmse:.4f}, "
            f"fit {self.simulation_fit_percent:.2f} %; one-step prediction: RMSE {self.prediction_rmse:.6g} "
            f"({self.samples} samples after a warm-up of {self.warmup})"
        )

    __str__ = summary

    def to_dict(self) -> dict[str, float | int]:
        """The metrics as a JSON-safe dict.

        Returns
        -------
        dict
            The fields by name.
        """
        return {k: (int(v) if k in ("samples", "warmup") else float(v)) for k, v in asdict(self).items()}

    @fill(axes=AXES)
    def plot(self, y: ArrayLike, y_sim: ArrayLike, *, ax: Any = None, title: str | None = None) -> Any:
        """Plot the measured output against the free-run simulation these metrics describe,
        the warm-up shaded; :func:`backlashid.app.plot_simulation`.

        Parameters
        ----------
        y : array_like
            The measured output the metrics were computed on.
        y_sim : array_like
            The model's free-run simulation of it.
        {axes}

        Raises
        ------
        DataError
            If y does not have ``samples + warmup`` samples.
        """
        from ..plotting import plot_simulation

        ys = as_signal(y, "y").ravel()
        if ys.size != self.samples + self.warmup:
            raise DataError(f"y has {ys.size} samples, the metrics were computed on {self.samples + self.warmup}: give that record")
        return plot_simulation(ys, y_sim, warmup=self.warmup, ax=ax, title=title)


def _augmented(model: Any) -> bool:
    """A diagnosed model (``DiagnosisReport.model``, an augmented chain): it simulates from the
    samples and predicts by its own methods."""
    return not isinstance(model, (CascadeModel, SandwichModel)) and all(
        callable(getattr(model, name, None)) for name in ("simulate", "simulate_from_samples", "predict_from")
    )


def evaluate(model: Model, u: ArrayLike, y: ArrayLike, *, warmup: int = 0, init_samples: int = 0) -> Metrics:
    """Both kinds of error of ``model`` on the record (u, y), from sample ``warmup`` on.

    With ``init_samples=n`` (the benchmark protocols' "n samples to initialise the state") the
    simulation starts from the state estimated on the first n measured samples
    (:func:`~backlashid.identify.simulate_from_samples`: the model's parameters held, its state fitted; what n
    samples do not determine stays at rest), and every metric is computed after them (a
    warm-up of at least n). Without it the simulation starts at rest.

    Parameters
    ----------
    model : CascadeModel, SandwichModel or AugmentedModel
        The model to judge, best on data not used to fit it (a diagnosed model,
        ``DiagnosisReport.model``, too).
    u : array_like
        Input u(t).
    y : array_like
        Measured output (w for a sandwich), as long as ``u``.
    warmup : int, default 0
        Samples at the start left out (the record's initial state is unknown).
    init_samples : int, default 0
        Samples at the start that initialise the simulation's state; 0: start at rest.

    Returns
    -------
    Metrics
        The free-run simulation RMSE, NRMSE and fit % and the one-step prediction RMSE;
        ``warmup`` is max(warmup, init_samples).

    Raises
    ------
    DataError
        If ``model`` is not a model, the record cannot be used (not finite, of two lengths),
        ``warmup`` or ``init_samples`` is not inside it, or the errors exceed the float range.

    Warns
    -----
    FitWarning
        If the first ``init_samples`` samples leave the start a guess: another start (x
        elsewhere inside the dead band, or the model at rest at the record's first level)
        simulates them as well, and the rest of the record differently by more than their own
        error (the backlash holds through them, and an input block that integrates keeps where
        x sits inside the dead band). Give more ``init_samples``, reaching past the backlash's
        first motion.

    Examples
    --------
    >>> import backlashid as bid
    >>> truth = bid.example1()
    >>> data = bid.example_data(truth, 1500, snr=None, seed=0)
    >>> bid.evaluate(truth, data.u, data.noisy).simulation_rmse
    0.0
    >>> bid.evaluate(truth, data.u[700:], data.noisy[700:], init_samples=50).simulation_rmse < 1e-8
    True
    """
    augmented = _augmented(model)
    if not augmented:
        check_model(model)
    u_arr, y_arr = one_record(u, y, flatten=True)
    check_finite(u_arr, "u")
    check_finite(y_arr, "y")
    init = check_int(init_samples, "init_samples", 0)
    if init == 0:
        check_warmup(warmup, y_arr.size)
    if init == 0:
        simulated = model.simulate(u_arr)
    else:
        if init >= y_arr.size:
            raise DataError(f"init_samples = {init}: leave samples to evaluate, give fewer than the record's {y_arr.size}")
        if augmented:
            simulated = model.simulate_from_samples(u_arr, y_arr, init)
        else:
            simulated, state = started_from_samples(model, u_arr, y_arr, init)
            _warn_if_undetermined(model, u_arr, y_arr, init, state, simulated)
        warmup = max(check_warmup(warmup, y_arr.size), init)
    # a diagnosed model's predictor: its simulation plus its noise model (the simulation without one)
    predicted = model.predict_from(simulated, y_arr) if augmented else one_step_prediction(model, u_arr, y_arr)
    metrics = Metrics(
        simulation_rmse=rmse(y_arr, simulated, warmup=warmup),
        simulation_nrmse=nrmse(y_arr, simulated, warmup=warmup),
        simulation_fit_percent=fit_percent(y_arr, simulated, warmup=warmup),
        prediction_rmse=rmse(y_arr, predicted, warmup=warmup),
        samples=y_arr.size - warmup,
        warmup=warmup,
    )
    overflow = [name for name, value in asdict(metrics).items() if not np.isfinite(value)]
    if overflow:  # finite data whose errors square beyond the float range (|y| near 1e154)
        raise DataError(f"{overflow[0]} exceeds the float range: the record's values are too large; rescale u and y (e.g. to SI units)")
    return metrics


def _warn_if_undetermined(
    model: Model, u: NDArray[np.float64], y: NDArray[np.float64], init: int, state: CascadeState | SandwichState | None, simulated: NDArray[np.float64]
) -> None:
    """A FitWarning where the first ``init`` samples leave the start ``state`` (the one
    ``simulated`` ran from) open by more than their own error
    (:func:`~backlashid.identify._start_check.undetermined_start`)."""
    open_by = None if state is None else undetermined_start(model, u, y, init, state, simulated)
    if open_by is None or open_by[0] <= open_by[1]:
        return
    spread, error = open_by
    warnings.warn(
        f"evaluate: the first {init} samples (init_samples) do not determine the start: another start "
        f"(x elsewhere inside the dead band, the drive at rest, or the start more samples imply) simulates them as well and the rest of "
        f"the record {spread:.3g} RMS differently ({spread / error if error > 0 else float('inf'):.3g} times "
        f"their own error {error:.3g}): while the backlash holds, where x sits inside the dead band is a "
        "guess. Give more init_samples, reaching past the backlash's first motion",
        FitWarning,
        stacklevel=3,
    )
