"""The exceptions of backlashid. The Rust core's one error enum maps onto these classes.

- ``BacklashIdError``: the base of everything backlashid raises on purpose.
- ``DataError``: bad data (NaN or inf, wrong dimensionality, empty or too short, wrong dtype).
- ``ModelError``: invalid model parameters (negative widths, non-increasing branches, empty
  coefficient lists) or a model that diverges in simulation.
- ``NotIdentifiableError``: the data cannot determine the parameters (too few samples off the
  dead band, a parameter never excited, a rank-deficient regressor).
- ``NotConvergedError``: an identification did not converge; it carries the best iterate.
- ``FitWarning``: a fit that ended but whose estimate looks suspicious (a ``UserWarning``).

``DataError`` and ``ModelError`` are also ``ValueError``, so generic handlers keep working.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the identify layer sits above: only its type is named here
    from .identify import FitResult

__all__ = ["BacklashIdError", "DataError", "ModelError", "NotIdentifiableError", "NotConvergedError", "FitWarning"]


class BacklashIdError(Exception):
    """Base class of the errors raised by backlashid.

    Catch it to handle every error backlashid raises on purpose; anything else is a bug.

    Examples
    --------
    >>> import backlashid as bid
    >>> try:
    ...     bid.LinearBlock([])
    ... except bid.BacklashIdError as exc:
    ...     print(type(exc).__name__)
    ModelError
    """


class DataError(BacklashIdError, ValueError):
    """The data cannot be used as given; the message says how to fix it.

    Raised for NaN or inf samples, a wrong dimensionality, an empty or too short record, a
    dtype that is not numbers, or a bad setting such as a warm-up longer than the record.

    Examples
    --------
    >>> import backlashid as bid
    >>> bid.evaluate(bid.example1(), [0.0, 1.0], [0.0, 1.0], warmup=5)
    Traceback (most recent call last):
    ...
    backlashid.errors.DataError: warmup = 5: give a whole number of samples, 0 <= warmup < 2 (the record length)
    """


class ModelError(BacklashIdError, ValueError):
    """The model parameters are invalid, or the model diverged; the message says why.

    Examples
    --------
    >>> import backlashid as bid
    >>> bid.GeneralBacklash(-0.1, 0.1, [1.0], [1.0])
    Traceback (most recent call last):
    ...
    backlashid.errors.ModelError: ...
    """


class NotIdentifiableError(BacklashIdError):
    """The data do not determine the parameters; the message says what to change.

    Raised for a constant input or output, a backlash that hardly leaves its dead band, or a
    rank-deficient regressor.

    Examples
    --------
    >>> import numpy as np
    >>> import backlashid as bid
    >>> bid.fit_cascade(np.ones(500), np.arange(500.0))
    Traceback (most recent call last):
    ...
    backlashid.errors.NotIdentifiableError: the input u is constant: ...
    """


class NotConvergedError(BacklashIdError):
    """The identification diverged, did not converge, or ran out of its ``time_budget``.

    Parameters
    ----------
    message : str
        What went wrong and what to try instead.
    best : FitResult, optional
        The estimate the fit ended with (``converged`` False; its ``model`` is None when the
        estimate is no valid model), or None when no usable estimate exists.
    best_stable : FitResult, optional
        The best iterate that is a usable model (``fit_cascade`` and ``fit_sandwich``): the
        final estimate and the iterates of the paper's algorithm with unstable poles reflected,
        kept where the model is valid and its linear blocks stable, the one of lowest output
        error refined by the output-error Levenberg-Marquardt (``converged`` False, covariance
        NaN). Diagnose or simulate from it when the fit failed (``backlashid diagnose
        --fit-cascade`` does, and says so); None when no iterate qualifies.

    Attributes
    ----------
    best : FitResult or None
        As given; it survives pickling (e.g. from a Dask worker).
    best_stable : FitResult or None
        As given; it survives pickling too.

    Examples
    --------
    >>> import backlashid as bid
    >>> data = bid.example_data(bid.example2(), 1500, snr=None, seed=1)
    >>> try:
    ...     bid.fit_sandwich(data.u, data.noisy, paper=True)
    ... except bid.NotConvergedError as exc:
    ...     print(type(exc.best).__name__, exc.best.converged)
    FitResult False
    """

    def __init__(self, message: str, best: FitResult | None = None, best_stable: FitResult | None = None) -> None:
        super().__init__(message)
        self.best = best
        self.best_stable = best_stable

    def __reduce__(self) -> tuple[object, ...]:
        # exceptions pickle by their args only; keep the best iterates across processes
        return (type(self), (self.args[0], self.best, self.best_stable))


class FitWarning(UserWarning):
    """A fit ended, but its estimate looks suspicious; the message says where and what to try.

    Issued by :func:`~backlashid.fit_cascade` and :func:`~backlashid.fit_sandwich` when, on the
    range of x the data visit, the fitted branches cross (L(x) <= R(x)) or stop increasing
    (the paper's assumption, Section 2, fails there), or when a parameter's standard error
    exceeds the magnitude of its estimate (the data hardly determine it); by
    :func:`~backlashid.evaluate` when its ``init_samples`` leave the start a guess. Turn it into an
    error with ``warnings.simplefilter("error", FitWarning)``, or silence it with ``"ignore"``.

    Examples
    --------
    >>> import warnings
    >>> import backlashid as bid
    >>> issubclass(bid.FitWarning, UserWarning)
    True
    >>> data = bid.example_data(bid.example1(), 1500, snr=25, seed=0)
    >>> with warnings.catch_warnings():
    ...     warnings.simplefilter("error", bid.FitWarning)  # a suspicious fit would raise here
    ...     bid.fit_cascade(data.u, data.noisy).converged
    True
    """
