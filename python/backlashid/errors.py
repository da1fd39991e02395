"""The exceptions of backlashid. The Rust core's one error enum maps onto these classes.

- ``BacklashIdError``: the base of everything backlashid raises on purpose.
- ``DataError``: bad data (NaN or inf, wrong dimensionality, empty or too short, wrong dtype).
- ``ModelError``: invalid model parameters (negative widths, non-increasing branches, empty
  coefficient lists) or a model that diverges in simulation.
- ``NotIdentifiableError``: the data cannot determine the parameters (too few samples off the
  dead band, a parameter never excited, a rank-deficient regressor).
- ``NotConvergedError``: an identification did not converge; it carries the best iterate.

``DataError`` and ``ModelError`` are also ``ValueError``, so generic handlers keep working.
"""

from __future__ import annotations

__all__ = ["BacklashIdError", "DataError", "ModelError", "NotIdentifiableError", "NotConvergedError"]


class BacklashIdError(Exception):
    """Base class of the errors raised by backlashid."""


class DataError(BacklashIdError, ValueError):
    """The data cannot be used as given; the message says how to fix it."""


class ModelError(BacklashIdError, ValueError):
    """The model parameters are invalid, or the model diverged; the message says why."""


class NotIdentifiableError(BacklashIdError):
    """The data do not determine the parameters; the message says what to change."""


class NotConvergedError(BacklashIdError):
    """The identification diverged or did not converge. ``best`` holds the best result found
    (lowest simulation error), or None when no usable iterate exists."""

    def __init__(self, message: str, best: object = None) -> None:
        super().__init__(message)
        self.best = best

    def __reduce__(self) -> tuple[object, ...]:
        # exceptions pickle by their args only; keep the best iterate across processes
        return (type(self), (self.args[0], self.best))
