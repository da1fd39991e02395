"""Conversion and checks of user inputs: the ONE place where public functions validate their
arguments (issue 21) before anything reaches NumPy or the Rust core.

Every check raises :class:`~backlashid.DataError` (data and settings) or
:class:`~backlashid.ModelError` (model parameters) naming the argument, what it got and what
it expects; no Python internal (``TypeError``, ``OverflowError``, a NumPy casting or broadcast
error) escapes for a wrong type. The caller's objects are never modified: the core only reads,
and results are new arrays.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from .errors import DataError, ModelError

_CONVERSION_ERRORS = (TypeError, ValueError, OverflowError)  # wrong type, ragged, a 400-digit int


def shown(value: Any) -> str:
    """``repr`` of a value, cut to a readable length (a message must not print a whole record)."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def is_real(value: Any) -> bool:
    """Whether ``value`` is a real number (int or float, Python or NumPy; not bool)."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def as_signal(values: Any, name: str) -> NDArray[np.float64]:
    """A float64 numpy array of a real-valued array-like (dimensions are checked by the core)."""
    if values is None or isinstance(values, (str, bytes, dict)):
        raise DataError(f"{name} is a {type(values).__name__}: pass an array of numbers")
    try:
        arr = np.asarray(values)
    except _CONVERSION_ERRORS as exc:  # ragged lists and the like
        raise DataError(f"{name} is not an array of numbers ({exc}): pass a 1-D array of reals") from None
    if arr.dtype.kind == "c":
        raise DataError(f"{name} is complex: pass the real-valued signal (e.g. {name}.real)")
    if arr.dtype.kind == "O":  # e.g. a list mixing numbers and None, or Decimals
        try:
            arr = arr.astype(np.float64)
        except OverflowError:
            raise DataError(f"{name} holds an integer too large for a float (above 1.8e308): give values in range") from None
        except (TypeError, ValueError):
            raise DataError(f"{name} holds values that are not numbers: convert it to a float array first") from None
    elif arr.dtype.kind not in "biuf":  # text, dates, durations, records
        raise DataError(f"{name} has dtype {arr.dtype}, not numbers: convert it to a float array first")
    return np.asarray(arr, dtype=np.float64)


def as_coefficients(values: Any, name: str, *, allow_empty: bool = False) -> list[float]:
    """A list of floats from a scalar or 1-D sequence of model coefficients (real numbers only:
    no text, booleans or complex numbers)."""
    if isinstance(values, (str, bytes, dict)) or values is None:
        raise ModelError(f"{name} must be a list of real numbers, got {shown(values)}")
    if isinstance(values, (list, tuple)) and any(isinstance(v, (bool, np.bool_)) for v in values):
        # NumPy turns [0.5, False] into floats without a word (a model file's "false")
        raise ModelError(f"{name} must be a list of real numbers, got {shown(values)} (a boolean among them)")
    try:
        raw = np.asarray(values)
    except _CONVERSION_ERRORS:
        raise ModelError(f"{name} must be a flat list of real numbers, got {shown(values)}") from None
    if raw.dtype.kind not in "iuf" and not (raw.dtype.kind == "O" and all(is_real(v) for v in raw.ravel())):
        raise ModelError(f"{name} must be a list of real numbers, got {shown(values)} (dtype {raw.dtype})")
    try:
        arr = np.atleast_1d(raw.astype(np.float64))
    except _CONVERSION_ERRORS:
        raise ModelError(f"{name} must be a list of real numbers within the float range, got {shown(values)}") from None
    if arr.ndim != 1:
        raise ModelError(f"{name} must be a flat list of coefficients, got shape {arr.shape}")
    if arr.size == 0 and not allow_empty:
        raise ModelError(f"{name} is empty: give at least one coefficient")
    return [float(v) for v in arr]


def as_scalar(value: Any, name: str, error: type[Exception] = ModelError) -> float:
    """A real scalar parameter (an int or float, Python or NumPy; not text or a bool)."""
    if not is_real(value):
        raise error(f"{name} must be a real number, got {shown(value)} ({type(value).__name__})")
    try:
        return float(value)
    except OverflowError:
        raise error(f"{name} = {shown(value)} is too large for a float (above 1.8e308): give a value in range") from None


def check_real(
    value: Any,
    name: str,
    *,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
    error: type[Exception] = DataError,
) -> float:
    """A finite real number inside [low, high] (an end is excluded when ``*_open``), as a float."""
    x = as_scalar(value, name, error)
    below = low is not None and (x <= low if low_open else x < low)
    above = high is not None and (x >= high if high_open else x > high)
    if not np.isfinite(x) or below or above:
        lo = "-inf" if low is None else f"{low:g}"
        hi = "inf" if high is None else f"{high:g}"
        span = f"{'(' if low is None or low_open else '['}{lo}, {hi}{')' if high is None or high_open else ']'}"
        raise error(f"{name} = {shown(value)}: give a finite number in {span}")
    return x


def check_int(value: Any, name: str, least: int = 0, most: int | None = None, error: type[Exception] = DataError) -> int:
    """A whole number (int or NumPy integer, not bool) in [least, most], as an int."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least or (most is not None and value > most):
        upto = f" and <= {most}" if most is not None else ""
        raise error(f"{name} = {shown(value)}: give a whole number >= {least}{upto}")
    return int(value)


def check_flag(value: Any, name: str, error: type[Exception] = DataError) -> bool:
    """True or False (also NumPy's bool), not a truthy string or number."""
    if not isinstance(value, (bool, np.bool_)):
        raise error(f"{name} must be True or False, got {shown(value)}")
    return bool(value)


def check_choice(value: Any, name: str, choices: tuple[str, ...], error: type[Exception] = DataError) -> str:
    """One of the strings ``choices``."""
    if not isinstance(value, str) or value not in choices:
        raise error(f"{name} = {shown(value)}: use {' or '.join(repr(c) for c in choices)}")
    return value


NOISE_RANGE = (1e-100, 1e100)  # a noise std whose square neither underflows to 0 nor overflows


def check_noise_std(value: Any, name: str = "noise_std") -> float:
    """A noise standard deviation: a positive finite number (within 1e-100..1e100, so that its
    square, which divides the costs, is a normal float)."""
    return check_real(value, name, low=NOISE_RANGE[0], high=NOISE_RANGE[1])


SIGNAL_RANGE = (1e-100, 1e100)  # a signal's largest size whose squares and sums of squares stay normal floats
CHUNK = 1 << 20  # samples a whole-record check reads at once: its temporaries stay a few MB


def check_scale(values: NDArray[np.float64], name: str) -> NDArray[np.float64]:
    """A finite signal whose largest size lies within ``SIGNAL_RANGE`` (or is 0): its squares
    and their sums over a record neither overflow nor vanish in the subnormals.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid._validation import check_scale
    >>> check_scale(np.array([1e-3, 2.0]), "y").size
    2
    """
    size = float(np.max(np.abs(values))) if values.size else 0.0
    low, high = SIGNAL_RANGE
    if size > high or 0.0 < size < low:
        raise DataError(
            f"{name} reaches {size:.3g} in size, outside {low:g}..{high:g}, where its squares overflow or vanish: "
            "scale the record (e.g. to SI units or divide by its standard deviation)"
        )
    return values


def check_seed(value: Any, name: str = "seed") -> int:
    """A random seed: a whole number >= 0."""
    return check_int(value, name, 0)


def frozen(values: list[float]) -> NDArray[np.float64]:
    """A read-only float64 array, so a model's parameters cannot be changed behind its back."""
    arr = np.array(values, dtype=np.float64)
    arr.setflags(write=False)
    return arr


def format_list(values: NDArray[np.float64]) -> str:
    return "[" + ", ".join(f"{v:.6g}" for v in values) + "]"


# -- checks of the models' arguments and the identification's records (models, identify) ------


def check_instance(value: Any, cls: type, name: str, error: type[Exception] = ModelError) -> None:
    """Raise ``error`` unless ``value`` is a ``cls`` (a model's block, a simulation's state)."""
    if not isinstance(value, cls):
        raise error(f"{name} must be a {cls.__name__}, got {type(value).__name__}")


def check_warmup(warmup: Any, n: int) -> int:
    """The samples left out at the start of a record of ``n``: a whole number, 0 <= warmup < n."""
    if isinstance(warmup, bool) or not isinstance(warmup, (int, np.integer)) or not 0 <= warmup < n:
        raise DataError(f"warmup = {shown(warmup)}: give a whole number of samples, 0 <= warmup < {n} (the record length)")
    return int(warmup)


def check_finite(values: NDArray[np.float64], name: str) -> None:
    """Name the first NaN or inf sample of a signal (the core's message, model/signal.rs)."""
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        raise DataError(
            f"{name}[{bad[0]}] is {values[bad[0]]}: remove or interpolate non-finite samples "
            f"({bad.size} NaN or infinite in all), or cut the record before them"
        )


def check_same_length(*signals: tuple[str, NDArray[np.float64]]) -> None:
    """DataError unless every (name, signal) has as many samples as the first."""
    first, reference = signals[0]
    for name, values in signals[1:]:
        if values.size != reference.size:
            raise DataError(f"{first} has {reference.size} samples but {name} has {values.size}: give one record (same length)")


def one_record(
    a: Any, b: Any, names: tuple[str, str] = ("u", "y"), *, flatten: bool = False
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two signals of one record: 1-D (or flattened) float64 arrays of one length."""
    a_arr, b_arr = as_signal(a, names[0]), as_signal(b, names[1])
    if flatten:
        a_arr, b_arr = a_arr.ravel(), b_arr.ravel()
    elif a_arr.ndim != 1 or b_arr.ndim != 1:
        raise DataError(f"{names[0]} and {names[1]} must be 1-D signals (got shapes {a_arr.shape} and {b_arr.shape})")
    check_same_length((names[0], a_arr), (names[1], b_arr))
    return a_arr, b_arr


def identification_record(
    u: Any, y: Any, *, y_name: str, warmup: Any, parameters: int, constant_input: type[Exception]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """What every fit checks: one finite record, a warm-up inside it, at least 10 samples per
    parameter after it, and an input that varies (else ``constant_input`` is raised)."""
    u_arr, y_arr = one_record(u, y, ("u", y_name))
    check_finite(u_arr, "u")
    check_finite(y_arr, y_name)
    check_warmup(warmup, len(u_arr))
    need = 10 * parameters
    if len(u_arr) - warmup < need:
        raise DataError(
            f"{len(u_arr) - warmup} samples after the warm-up for {parameters} parameters: give at least {need} (10 per parameter)"
        )
    if np.ptp(u_arr) == 0.0:
        raise constant_input("the input u is constant: the system is not excited; use a varying input")
    if not _reverses(u_arr):
        raise constant_input(
            "the input u never changes direction (a time or sample-number column chosen as the input?): a backlash "
            "shows only where its input reverses; choose the input signal, or a record in which it moves both ways"
        )
    if np.ptp(y_arr) == 0.0:
        raise constant_input(
            f"the output {y_name} is constant (0 % of its samples move): nothing of the system shows in it; a record at rest, "
            f"or an input too small to move the load off the dead band: check the column chosen as {y_name}, or excite more"
        )
    if all(np.array_equal(u_arr[s : s + CHUNK], y_arr[s : s + CHUNK]) for s in range(0, len(u_arr), CHUNK)):
        raise DataError(f"u and {y_name} are the same signal: choose the measured output as {y_name} (one column given twice?)")
    return u_arr, y_arr


def _reverses(u: NDArray[np.float64]) -> bool:
    """Whether u rises somewhere and falls somewhere, read CHUNK samples at a time (a record
    of 1e8 samples would otherwise make an 800 MB array of its steps)."""
    rises = falls = False
    for s in range(0, len(u) - 1, CHUNK):
        steps = np.diff(u[s : s + CHUNK + 1])
        rises = rises or bool(np.any(steps > 0.0))
        falls = falls or bool(np.any(steps < 0.0))
        if rises and falls:
            return True
    return False


def check_signals(*signals: tuple[str, Any], min_length: int = 0, what: str = "this analysis") -> list[NDArray[np.float64]]:
    """Finite 1-D float copies of one record's signals, given as (name, values) pairs.

    Each signal must be 1-D (a column or row vector is flattened), finite, of at least
    ``min_length`` samples (``what`` says what needs them), and all as long as the first.
    DataError otherwise, saying what to do.
    """
    out: list[NDArray[np.float64]] = []
    for name, values in signals:
        arr = as_signal(values, name)
        if arr.ndim != 1:
            if arr.ndim == 2 and 1 in arr.shape:
                arr = arr.ravel()
            else:
                raise DataError(f"{name} has shape {arr.shape}: pass a 1-D signal (one record)")
        check_finite(arr, name)
        if arr.size < min_length:
            raise DataError(f"{name} has {arr.size} samples; {what} needs at least {min_length}: give a longer record")
        if out:
            check_same_length((signals[0][0], out[0]), (name, arr))
        out.append(arr.copy())
    return out
