"""How close a model's output is to a measured one: RMSE, NRMSE and fit percent, a leaf the
identification's metrics, the figures and the diagnosis share (re-exported by
``backlashid.identify``)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._docstrings import fill
from ._validation import check_warmup, one_record
from .errors import DataError

__all__ = ["fit_percent", "nrmse", "rmse"]


def _pair(y: ArrayLike, y_hat: ArrayLike, warmup: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    a, b = one_record(y, y_hat, ("y", "y_hat"), flatten=True)
    warmup = check_warmup(warmup, a.size)
    return a[warmup:], b[warmup:]


_PAIR_DOC = """Parameters
----------
y : array_like
    Measured output, 1-D (flattened otherwise).
y_hat : array_like
    The model's output for the same samples.
warmup : int, default 0
    Samples at the start left out."""


@fill(pair=_PAIR_DOC)
def rmse(y: ArrayLike, y_hat: ArrayLike, *, warmup: int = 0) -> float:
    """Root mean square of y - y_hat over the samples from ``warmup`` on.

    {pair}

    Returns
    -------
    float
        The root mean square error.

    Raises
    ------
    DataError
        If the signals differ in length or ``warmup`` is not inside the record.

    Examples
    --------
    >>> from backlashid.identify import rmse
    >>> rmse([0.0, 1.0, 2.0], [0.0, 1.0, 3.0])  # doctest: +ELLIPSIS
    0.577...
    """
    a, b = _pair(y, y_hat, warmup)
    return float(np.sqrt(np.mean((a - b) ** 2)))


@fill(pair=_PAIR_DOC)
def nrmse(y: ArrayLike, y_hat: ArrayLike, *, warmup: int = 0) -> float:
    """The RMSE divided by the standard deviation of y (both from ``warmup`` on).

    0 is perfect, 1 is no better than the mean.

    {pair}

    Returns
    -------
    float
        The normalised root mean square error.

    Raises
    ------
    DataError
        If the signals differ in length, ``warmup`` is not inside the record, or y is
        constant over the evaluated samples.

    Examples
    --------
    >>> from backlashid.identify import nrmse
    >>> nrmse([1.0, -1.0, 1.0, -1.0], [0.5, -0.5, 0.5, -0.5])
    0.5
    """
    a, b = _pair(y, y_hat, warmup)
    std = float(np.std(a))
    if std == 0.0:
        raise DataError("y is constant over the evaluated samples: NRMSE is undefined")
    return float(np.sqrt(np.mean((a - b) ** 2))) / std


@fill(pair=_PAIR_DOC)
def fit_percent(y: ArrayLike, y_hat: ArrayLike, *, warmup: int = 0) -> float:
    """100 (1 - ``norm(y - y_hat)`` / ``norm(y - mean(y))``), as MATLAB's compare reports it.

    Equals 100 (1 - NRMSE): 100 is perfect, 0 is no better than the mean.

    {pair}

    Returns
    -------
    float
        The fit in percent.

    Raises
    ------
    DataError
        As :func:`nrmse`.

    Examples
    --------
    >>> from backlashid.identify import fit_percent
    >>> fit_percent([1.0, -1.0, 1.0, -1.0], [0.5, -0.5, 0.5, -0.5])
    50.0
    """
    return 100.0 * (1.0 - nrmse(y, y_hat, warmup=warmup))
