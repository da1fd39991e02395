"""The forgetting factor an input asks for: a memory that holds several of its swings.

A tracker forgets old samples with lambda, a memory of about 1 / (1 - lambda) samples. Under a
white input 1000 samples hold hundreds of swings through both contacts of the play; under a
slow ramp they hold one leg, along which one contact and the width are not excited at all, and
the estimate drifts along what the window leaves undetermined. On the development seeds 100-119
of benches/tracking_structures.py (the right input backlash under triangles of 200-2000-sample
legs, started from a fit on the first 5000 samples), four trackers that started at the noise
ended at 4.4-13.2 noise stds with a memory of 1000 samples and at 1.00-1.15 with the memory
taken from the input here (docs/tracking.md)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .._validation import as_signal, check_real
from ..errors import DataError

SWINGS = 4.0
"""Half-swings of the input (crossings of its median) the memory holds."""
FLOOR = 1000.0
"""The shortest memory, in samples: lambda = 0.999, the tracker's default for a rich input."""
HYSTERESIS = 0.25
"""A crossing counts when the input goes from below its median minus this many standard
deviations to above the median plus as many, or back: noise on a slow input does not count."""


def swing_samples(u: ArrayLike) -> float:
    """The mean samples between the input's crossings of its median (with hysteresis of
    ``HYSTERESIS`` standard deviations); the record's length when it never crosses.

    Parameters
    ----------
    u : array_like
        The input, one value per sample.

    Returns
    -------
    float
        Samples per crossing.

    Raises
    ------
    DataError
        If ``u`` is empty, not 1-D or not finite.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.tracking import swing_samples
    >>> t = np.arange(20_000)
    >>> swing_samples(np.abs((t % 2000) - 1000.0))  # a triangle of period 2000
    1000.0
    """
    x = as_signal(u, "u")
    if x.ndim != 1 or x.size == 0:
        raise DataError(f"u has shape {x.shape}: give the input the tracker will see, one value per sample")
    if not np.isfinite(x).all():
        raise DataError(f"u has {int((~np.isfinite(x)).sum())} values that are not finite: give a finite input")
    band = HYSTERESIS * float(x.std())
    middle = float(np.median(x))
    side = np.where(x > middle + band, 1, np.where(x < middle - band, -1, 0))
    side = side[side != 0]
    crossings = int(np.count_nonzero(np.diff(side)))
    return float(x.size) / crossings if crossings else float(x.size)


def forgetting_for(u: ArrayLike, *, swings: float = SWINGS, floor: float = FLOOR) -> float:
    """The forgetting factor lambda for tracking under the input ``u``: a memory 1 / (1 -
    lambda) of ``swings`` times the samples between the input's crossings of its median, at
    least ``floor`` samples (lambda = 0.999 for a white or fast input; about 0.99991 for
    triangles of 1100-sample legs).

    Parameters
    ----------
    u : array_like
        The input the tracker will see (a whole record, or a representative stretch).
    swings : float, default 4
        Crossings of the median the memory holds.
    floor : float, default 1000
        The shortest memory, in samples.

    Returns
    -------
    float
        lambda in [1 - 1 / floor, 1).

    Raises
    ------
    DataError
        If ``u`` is empty, not 1-D or not finite, or ``swings`` or ``floor`` is not a number
        > 0 (``floor`` >= 1).

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.tracking import forgetting_for
    >>> forgetting_for(np.random.default_rng(0).uniform(-1, 1, 10_000))
    0.999
    >>> t = np.arange(100_000)
    >>> round(1 / (1 - forgetting_for(np.abs((t % 2000) - 1000.0))))
    4000
    """
    per = check_real(swings, "swings", low=0.0, low_open=True)
    least = check_real(floor, "floor", low=1.0)
    memory = max(least, per * swing_samples(u))
    return 1.0 - 1.0 / memory


def chosen_forgetting(forgetting: float | str | None, drift: object, u: ArrayLike) -> float | str | None:
    """The forgetting factor :func:`~backlashid.tracking.track` (and ``backlashid track``) uses
    for these options on the input ``u``: :func:`forgetting_for` of ``u`` for ``"auto"``, or
    when neither ``forgetting`` nor ``drift`` is given; otherwise ``forgetting`` as given (the
    :class:`~backlashid.tracking.Tracker` checks it). For a Tracker fed block by block that
    should behave as ``track`` does.

    Parameters
    ----------
    forgetting : float or str or None
        The ``forgetting`` option: lambda, ``"auto"`` or None.
    drift : object
        The ``drift`` option (None: no random walk).
    u : array_like
        The input the tracker will see (a whole record, or a representative stretch).

    Returns
    -------
    float or str or None
        lambda from the input, or ``forgetting`` itself (None with drift: the Tracker then
        does not forget).

    Raises
    ------
    DataError
        If the input is needed and is empty, not 1-D or not finite.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.tracking import chosen_forgetting
    >>> u = np.random.default_rng(0).uniform(-1, 1, 5000)
    >>> chosen_forgetting(None, None, u), chosen_forgetting(0.99, None, u), chosen_forgetting(None, 1e-6, u)
    (0.999, 0.99, None)
    """
    if (isinstance(forgetting, str) and forgetting == "auto") or (forgetting is None and drift is None):
        return forgetting_for(u)
    return forgetting
