"""The noise floor of the diagnosis and the black-box tests of the nominal residual.

The gap a candidate closes is measured above the noise floor: the part of the nominal model's
validation error that no model of the noise-free output can remove.

With ``noise_std`` unknown the floor is the validation MSE of a one-step predictor of the
nominal residual: a linear regression on the input's lags, the nominal model's internal signal
x and its velocity, powers of the nominal output, and the residual's own last ``RESIDUAL_LAGS``
values, fitted on the estimation records and scored on the validation records (so over-fitting
cannot lower it); and of the same on the residual's past alone (an estimation record of narrow
excitation, a piezo's single sine, leaves the signals' coefficients to extrapolate on a richer
validation record: there the first read 0.062 model units where the residual's own past
predicts it to 0.009). The lower of them, for the nominal residual and for the best
candidate's, at most the nominal MSE. A model error is a deterministic function of the input's past, which those
regressors follow one step ahead, so what is left is the noise's innovation: on a noise-free
record the floor reads near zero, on white noise it reads the noise variance. It never exceeds
the nominal MSE. It is not the best of the candidates' errors, so a candidate's share of the gap
is not 1 by construction; where a candidate beats the floor, its share is clipped to 1 and the
report says the floor may be high (a model error the predictor could not follow).

For colored noise the floor is the innovation variance, below the noise's variance: its
predictable part counts as gap, which no deterministic candidate closes; the verdict rule names
colored_noise from the residual's own properties instead.

The same regressors without the residual's past (the input alone) and with it test whether the
residual depends on the input and whether anything beats the nominal model at all.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .._numerics import lstsq

__all__ = ["RESIDUAL_LAGS", "Signals", "black_box_residuals", "noise_floor", "one_step_floor"]

RESIDUAL_LAGS = 10  # the residual's own past in the one-step predictor of the floor
INPUT_LAGS = 10  # lags of u in the black-box regressors
Array = NDArray[np.float64]


@dataclass(frozen=True)
class Signals:
    """One record as the nominal model sees it.

    Attributes
    ----------
    u : ndarray
        The input (advanced by the chain's shift).
    y : ndarray
        The measured output.
    x : ndarray
        The nominal (input) linear block's output from the record's start.
    y_nom : ndarray
        The nominal free-run simulation from the record's start.
    warmup : int
        Samples left out at the start.
    """

    u: Array
    y: Array
    x: Array
    y_nom: Array
    warmup: int

    @property
    def residual(self) -> Array:
        """Measured minus the nominal simulation."""
        return self.y - self.y_nom

    def scored(self, v: Array) -> Array:
        """v after the warm-up."""
        return v[self.warmup :]


def _lag(s: Array, k: int) -> Array:
    return np.concatenate([np.zeros(k), s[:-k]]) if k else s


def _features(s: Signals, residual_lags: int, signals: bool = True) -> Array:
    """Regressors of one record (after its warm-up): input lags, x and its velocity, powers of
    the nominal output (unless ``signals`` is False), and the residual's past."""
    cols = [np.ones(s.u.size)]
    if signals:
        dx = s.x - _lag(s.x, 1)
        cols += [s.y_nom, s.y_nom**2, s.y_nom**3, dx, np.sign(dx), np.abs(dx)]
        cols += [_lag(s.u, k) for k in range(0, INPUT_LAGS + 1)] + [_lag(s.x, k) for k in range(0, 3)]
    r = s.residual
    cols += [_lag(r, k) for k in range(1, residual_lags + 1)]
    return s.scored(np.column_stack(cols))


def _fit_score(est: list[Signals], val: list[Signals], residual_lags: int, signals: bool = True) -> Array:
    """Validation residual (after the warm-ups, records one after the other) of the regression
    of the nominal residual fitted on the estimation records."""
    a_e = np.vstack([_features(s, residual_lags, signals) for s in est])
    r_e = np.concatenate([s.scored(s.residual) for s in est])
    scale = np.maximum(np.std(a_e, axis=0), 1e-12)
    scale[0] = 1.0
    coef = lstsq(a_e / scale, r_e)
    a_v = np.vstack([_features(s, residual_lags, signals) for s in val])
    r_v = np.concatenate([s.scored(s.residual) for s in val])
    return np.asarray(r_v - (a_v / scale) @ coef, dtype=np.float64)


def black_box_residuals(est: list[Signals], val: list[Signals]) -> tuple[Array, Array]:
    """The validation residuals of the black-box model of the input alone and of the one-step
    predictor with the residual's past (after the warm-ups).

    Parameters
    ----------
    est, val : list of Signals
        The estimation and validation records.

    Returns
    -------
    input_only, one_step : ndarray
        Their validation residuals.
    """
    return _fit_score(est, val, 0), _fit_score(est, val, RESIDUAL_LAGS)


def one_step_floor(est: list[Signals], val: list[Signals], mse: float, with_signals: Array | None = None) -> float:
    """The noise floor (MSE) that a model's residual shows: the lower validation MSE of its two
    one-step predictors, with the model's signals and the residual's past, and with the
    residual's past alone (an AR model: the signals' coefficients, fitted on an estimation
    record of narrow excitation, may extrapolate badly to a richer validation record), at most
    ``mse``.

    Parameters
    ----------
    est, val : list of Signals
        The records as the model sees them (``y_nom``: the model's own simulation).
    mse : float
        The model's validation MSE.
    with_signals : ndarray, optional
        The first predictor's validation residual if already computed
        (:func:`black_box_residuals`' second output).

    Returns
    -------
    float
        The floor.
    """
    if with_signals is None:
        with_signals = _fit_score(est, val, RESIDUAL_LAGS)
    own_past = _fit_score(est, val, RESIDUAL_LAGS, signals=False)
    return min(noise_floor(with_signals, mse), noise_floor(own_past, mse))


def noise_floor(one_step: Array, mse0: float) -> float:
    """The noise floor (MSE) from a one-step predictor's validation residual: its MSE, at most
    the nominal MSE.

    Parameters
    ----------
    one_step : ndarray
        A one-step predictor's validation residual (e.g. :func:`black_box_residuals`' second).
    mse0 : float
        The nominal model's validation MSE.

    Returns
    -------
    float
        The floor.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.diagnosis._noise import noise_floor
    >>> noise_floor(np.full(4, 0.1), 0.5)
    0.010000000000000002
    """
    return float(min(float(one_step @ one_step) / max(one_step.size, 1), mse0))
