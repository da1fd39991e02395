"""The general backlash of eq (1)-(15)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import _core
from .._docstrings import fill
from .._validation import as_coefficients, as_scalar, as_signal, check_int, format_list, frozen, shown
from ..errors import DataError, ModelError

__all__ = ["BacklashState", "GeneralBacklash", "BranchCheck", "SwitchingSignals"]

_SIGNAL_DOC = """Parameters
----------
x : array_like
    The backlash's input x(1), x(2), ...
y0 : float, default 0.0
    The memory y(0)."""
_X_DOC = """Parameters
----------
x : array_like
    Values of the backlash's input x (a scalar is taken as one value).

Returns
-------
numpy.ndarray
    {branch} at each value."""


_MAX_GRID = 10**7  # points of characteristic(): a plot needs far fewer
_RESCALE = "rescale x (e.g. to units where the dead band is about 1 wide) or use a lower degree"


def _finite_result(values: Any, what: str, x: NDArray[np.float64] | None = None) -> Any:
    """``values`` if every number in it is finite; else ModelError saying where the branch
    polynomials left the float range (results are never silently inf or NaN)."""
    arr = np.asarray(values, dtype=np.float64)
    bad = np.flatnonzero(~np.isfinite(arr))
    if bad.size:
        where = f" at x[{bad[0]}] = {x.ravel()[bad[0]]:.6g}" if x is not None and x.size == arr.size else ""
        raise ModelError(f"{what} is not finite{where}: the branch polynomials exceed the float range there; {_RESCALE}")
    return values


def _finite_range(lo: Any, hi: Any) -> tuple[float, float]:
    a, b = as_scalar(lo, "x_min", DataError), as_scalar(hi, "x_max", DataError)
    if not (np.isfinite(a) and np.isfinite(b)):
        raise DataError(f"the x-range [{a}, {b}] must be finite: give the range the data cover")
    return a, b


@dataclass(frozen=True)
class BranchCheck:
    """Where, on [x_min, x_max], the paper's assumption fails: a branch that does not increase,
    or L(x) <= R(x) (the branches cross at the ends of each interval).

    Returned by :meth:`GeneralBacklash.check_branches`; ``str()`` says it in words.

    Attributes
    ----------
    x_min : float
        Start of the range checked.
    x_max : float
        End of the range checked.
    left_not_increasing : list of (float, float)
        Intervals where L does not increase.
    right_not_increasing : list of (float, float)
        Intervals where R does not increase.
    crossed : list of (float, float)
        Intervals where L(x) <= R(x).

    Examples
    --------
    >>> import backlashid as bid
    >>> check = bid.example1().backlash.check_branches(-1.0, 1.0)
    >>> check.is_valid, check.crossings
    (True, [])
    """

    x_min: float
    x_max: float
    left_not_increasing: list[tuple[float, float]]
    right_not_increasing: list[tuple[float, float]]
    crossed: list[tuple[float, float]]

    @property
    def is_valid(self) -> bool:
        """True when no interval was found: both branches increase and do not cross."""
        return not (self.left_not_increasing or self.right_not_increasing or self.crossed)

    @property
    def crossings(self) -> list[float]:
        """The x where L and R cross inside the range."""
        ends = [e for interval in self.crossed for e in interval]
        return [e for e in ends if self.x_min < e < self.x_max]

    def __str__(self) -> str:
        if self.is_valid:
            return f"both branches increase and do not cross on [{self.x_min:.6g}, {self.x_max:.6g}]"
        parts = []
        fmt = lambda iv: ", ".join(f"[{a:.6g}, {b:.6g}]" for a, b in iv)  # noqa: E731
        if self.left_not_increasing:
            parts.append(f"L does not increase on {fmt(self.left_not_increasing)}")
        if self.right_not_increasing:
            parts.append(f"R does not increase on {fmt(self.right_not_increasing)}")
        if self.crossed:
            parts.append(f"L <= R (branches crossed) on {fmt(self.crossed)}")
        return "; ".join(parts)


@dataclass(frozen=True)
class SwitchingSignals:
    """The internal signals of the switching-function form, eq (9)-(15).

    Returned by :meth:`GeneralBacklash.switching`.

    Attributes
    ----------
    xi1 : numpy.ndarray
        x(t) + c_L, eq (9).
    xi2 : numpy.ndarray
        x(t) - c_R, eq (10).
    f1 : numpy.ndarray of bool
        The left branch is active, eq (12).
    f2 : numpy.ndarray of bool
        The right branch is active, eq (13); exclusive of f1 (the case order of eq 1).
    y : numpy.ndarray
        The output, eq (15).
    """

    xi1: NDArray[np.float64]
    xi2: NDArray[np.float64]
    f1: NDArray[np.bool_]
    f2: NDArray[np.bool_]
    y: NDArray[np.float64]


@dataclass(frozen=True)
class BacklashState:
    """Where a backlash inverse starts: the memory y(0) and the input x(0).

    The start of :meth:`GeneralBacklash.inverse` (a value that is not a finite number raises
    DataError). x(0) matters where the first target holds the level y(0): the inverse then
    keeps x(0) if it lies in the dead band at that level, else moves it to the band's nearer
    edge.

    Attributes
    ----------
    y_prev : float, default 0.0
        The backlash memory y(0), the level the backlash holds.
    x_prev : float, default 0.0
        The backlash input x(0).

    Examples
    --------
    >>> from backlashid import BacklashState
    >>> BacklashState(y_prev=0.2)
    BacklashState(y_prev=0.2, x_prev=0.0)
    """

    y_prev: float = 0.0
    x_prev: float = 0.0

    def __post_init__(self) -> None:
        for name in ("y_prev", "x_prev"):
            value = as_scalar(getattr(self, name), name, DataError)
            if not np.isfinite(value):
                raise DataError(f"{name} = {value}: give a finite value")
            object.__setattr__(self, name, value)


def _backlash_state(value: Any) -> BacklashState:
    """A :class:`BacklashState` from None (rest), itself or a (y_prev, x_prev) pair."""
    if value is None:
        return BacklashState()
    if isinstance(value, BacklashState):
        return value
    if isinstance(value, (tuple, list)) and len(value) == 2:
        return BacklashState(*value)
    raise DataError(f"initial_state = {shown(value)}: give a BacklashState(y_prev, x_prev) or a (y_prev, x_prev) pair")


class GeneralBacklash:
    """The general backlash of eq (1): y(t) = L(x) if x <= z_L, R(x) if x >= z_R, else y(t-1).

    The branches are L(x) = sum_{i=1}^n m_Li (x + c_L)^i (eq 4) and
    R(x) = sum_{i=1}^n m_Ri (x - c_R)^i (eq 5); degree 1 is the classic straight backlash.
    Both branches must increase across the dead band [-c_L, c_R]; use
    :meth:`check_branches` for the range your data cover. The parameters are also available
    under the paper's symbols ``c_L``, ``c_R``, ``m_L``, ``m_R``.

    Parameters
    ----------
    c_left : float
        Width c_L >= 0 (0 gives a static, possibly different, pair of curves).
    c_right : float
        Width c_R >= 0.
    m_left : array_like
        Coefficients m_L1..m_Ln of L.
    m_right : array_like
        Coefficients m_R1..m_Rn of R.

    Raises
    ------
    ModelError
        If a width is negative or a branch does not increase across the dead band, or the
        branches exceed the float range across it (extreme widths or degrees: rescale x).

    Examples
    --------
    >>> from backlashid import GeneralBacklash
    >>> play = GeneralBacklash(0.5, 0.5, [1.0], [1.0])
    >>> play.simulate([0.0, 1.0, 0.8, 0.0, -1.0]).tolist()
    [0.0, 0.5, 0.5, 0.5, -0.5]
    """

    __slots__ = ("_c_left", "_c_right", "_m_left", "_m_right", "_native")

    def __init__(self, c_left: float, c_right: float, m_left: ArrayLike, m_right: ArrayLike) -> None:
        c_l = as_scalar(c_left, "c_left")
        c_r = as_scalar(c_right, "c_right")
        m_l = as_coefficients(m_left, "m_left")
        m_r = as_coefficients(m_right, "m_right")
        self._native = _core.GeneralBacklash(c_l, c_r, m_l, m_r)  # validates, raises ModelError
        self._check_range(c_l, c_r, max(len(m_l), len(m_r)))
        self._c_left, self._c_right = c_l, c_r
        self._m_left, self._m_right = frozen(m_l), frozen(m_r)

    def _check_range(self, c_l: float, c_r: float, degree: int) -> None:
        """ModelError unless both branches, and the jump between them, are finite across the
        dead band and one unit beyond it (extreme widths or degrees overflow there)."""
        if not np.isfinite(c_l + c_r):
            raise ModelError(f"c_left + c_right = {c_l + c_r}: the dead band exceeds the float range; {_RESCALE}")
        x = np.linspace(-c_l - 1.0, c_r + 1.0, 33)
        if not np.all(np.isfinite(x)):
            raise ModelError(f"the dead band [-{c_l:.6g}, {c_r:.6g}] exceeds the float range; {_RESCALE}")
        left, right = self._native.left(x), self._native.right(x)
        if not (np.all(np.isfinite(left)) and np.all(np.isfinite(right)) and np.all(np.isfinite(left - right))):
            raise ModelError(
                f"the branches of degree {degree} with widths "
                f"c_L = {c_l:.6g}, c_R = {c_r:.6g} overflow the float range across the dead band; {_RESCALE}"
            )

    # -- parameters, under the paper's symbols too ------------------------------------------
    @property
    def c_left(self) -> float:
        """Width c_L of the left branch's offset (alias ``c_L``)."""
        return self._c_left

    @property
    def c_right(self) -> float:
        """Width c_R of the right branch's offset (alias ``c_R``)."""
        return self._c_right

    @property
    def m_left(self) -> NDArray[np.float64]:
        """Coefficients m_L1..m_Ln of L, read-only (alias ``m_L``)."""
        return self._m_left

    @property
    def m_right(self) -> NDArray[np.float64]:
        """Coefficients m_R1..m_Rn of R, read-only (alias ``m_R``)."""
        return self._m_right

    c_L = c_left
    c_R = c_right
    m_L = m_left
    m_R = m_right

    @property
    def degree(self) -> int:
        """n: the higher of the two branch degrees."""
        return max(len(self._m_left), len(self._m_right))

    # -- evaluation ----------------------------------------------------------------------------
    @fill(x=_X_DOC.format(branch="L(x)"))
    def left(self, x: ArrayLike) -> NDArray[np.float64]:
        """The left branch L(x), eq (4).

        {x}
        """
        x_arr = np.atleast_1d(as_signal(x, "x"))
        return _finite_result(self._native.left(x_arr), "L(x)", x_arr)

    @fill(x=_X_DOC.format(branch="R(x)"))
    def right(self, x: ArrayLike) -> NDArray[np.float64]:
        """The right branch R(x), eq (5).

        {x}
        """
        x_arr = np.atleast_1d(as_signal(x, "x"))
        return _finite_result(self._native.right(x_arr), "R(x)", x_arr)

    @fill(signal=_SIGNAL_DOC)
    def simulate(
        self, x: ArrayLike, *, y0: float = 0.0, form: Literal["eq1", "breakpoints"] = "eq1"
    ) -> NDArray[np.float64]:
        """The output y for the internal signal x, from the memory y(0) = y0.

        {signal}
        form : {'eq1', 'breakpoints'}, default 'eq1'
            ``"eq1"`` compares branch values with y(t-1) (fast); ``"breakpoints"`` follows
            eq (1) literally through z_L and z_R of eq (2)-(3) (a root search per sample).

        Returns
        -------
        numpy.ndarray
            y(1), y(2), ...

        Raises
        ------
        DataError
            If x or y0 is not finite, or ``form`` is unknown.
        """
        if not isinstance(form, str) or form not in ("eq1", "breakpoints"):
            raise DataError(f"form = {shown(form)}: use 'eq1' or 'breakpoints'")
        x_arr = as_signal(x, "x")
        return _finite_result(self._native.simulate(x_arr, as_scalar(y0, "y0", DataError), form), "the output y", x_arr)

    @fill(signal=_SIGNAL_DOC)
    def switching(self, x: ArrayLike, *, y0: float = 0.0) -> SwitchingSignals:
        """The switching-function form, eq (9)-(15), with the case order of eq (1).

        {signal}

        Returns
        -------
        SwitchingSignals
            xi1, xi2, f1, f2 and y.

        Examples
        --------
        >>> from backlashid import GeneralBacklash
        >>> signals = GeneralBacklash(0.5, 0.5, [1.0], [1.0]).switching([1.0, 0.8])
        >>> signals.f2.tolist(), signals.y.tolist()
        ([True, False], [0.5, 0.5])
        """
        x_arr = as_signal(x, "x")
        xi1, xi2, f1, f2, y = self._native.switching(x_arr, as_scalar(y0, "y0", DataError))
        _finite_result(np.concatenate([np.ravel(xi1), np.ravel(xi2), np.ravel(y)]), "a switching signal (xi1, xi2 or y)")
        return SwitchingSignals(xi1=xi1, xi2=xi2, f1=f1, f2=f2, y=y)

    def inverse(
        self, y_desired: ArrayLike, *, initial_state: BacklashState | tuple[float, float] | None = None, threshold: float = 0.0
    ) -> NDArray[np.float64]:
        """The backlash input x that makes the output follow ``y_desired`` (the inverse of eq 1).

        Tao and Kokotovic's backlash inverse with the polynomial branches of eq (4)-(5): a
        rising target is reached on R, x = R^-1(y_d); a falling one on L, x = L^-1(y_d),
        which crosses the dead band in one sample where the direction reverses; a target
        equal to the memory holds, x staying where it was if that is inside the dead band at
        that level. The roots are solved in the Rust core (Newton safeguarded by bisection on
        a bracket grown from the previous x, so that the root on the branch's increasing part
        the motion is on is found). The memory is what :meth:`simulate` holds, so
        ``simulate(inverse(y_d), y0=y(0))`` equals ``y_d`` to rounding.

        Parameters
        ----------
        y_desired : array_like
            The desired output y_d(1), y_d(2), ..., 1-D, finite.
        initial_state : BacklashState or (float, float), optional
            The memory y(0) and input x(0), as a :class:`BacklashState` or the pair
            ``(y_prev, x_prev)``; default both 0 (at rest).
        threshold : float, default 0.0
            Smoothing for noisy references: a reversal is followed only once the target has
            moved more than ``threshold`` back from the extremum reached in the current
            direction; until then the output holds (the tracking error stays within
            ``threshold``). 0 is the exact inverse.

        Returns
        -------
        numpy.ndarray
            x(1), x(2), ..., a new array.

        Raises
        ------
        DataError
            If ``y_desired`` is not a finite 1-D signal, the state or ``threshold`` is not
            finite (or the threshold is negative), or a branch cannot reach a target (it turns
            or overflows first: the message names the sample and the level).

        Examples
        --------
        >>> from backlashid import GeneralBacklash
        >>> play = GeneralBacklash(0.5, 0.5, [1.0], [1.0])
        >>> x = play.inverse([0.5, 1.0, 0.8, 0.8])
        >>> x.tolist()
        [1.0, 1.5, 0.30000000000000004, 0.30000000000000004]
        >>> play.simulate(x).round(12).tolist()
        [0.5, 1.0, 0.8, 0.8]
        """
        state = _backlash_state(initial_state)
        level = as_scalar(threshold, "threshold", DataError)
        y = as_signal(y_desired, "y_desired")
        return self._native.inverse(y, state.y_prev, state.x_prev, level)

    def breakpoints(self, y_prev: float, x_range: tuple[float, float]) -> tuple[float, float]:
        """The breakpoints z_L, z_R of eq (2)-(3): where L and R reach ``y_prev``.

        Parameters
        ----------
        y_prev : float
            The previous output y(t-1).
        x_range : (float, float)
            The finite range searched.

        Returns
        -------
        (float, float)
            z_L and z_R; -inf or +inf when the branch does not reach ``y_prev`` there.

        Raises
        ------
        DataError
            If ``y_prev`` or the range is not finite.

        Examples
        --------
        >>> from backlashid import GeneralBacklash
        >>> GeneralBacklash(0.5, 0.5, [1.0], [1.0]).breakpoints(0.0, (-2.0, 2.0))
        (-0.5, 0.5)
        """
        if not isinstance(x_range, (tuple, list, np.ndarray)) or len(x_range) != 2:
            raise DataError(f"x_range = {shown(x_range)}: give the pair (x_min, x_max)")
        lo, hi = _finite_range(x_range[0], x_range[1])
        y = as_scalar(y_prev, "y_prev", DataError)
        if not np.isfinite(y):
            raise DataError(f"y_prev = {y}: give a finite value")
        z_left, z_right = self._native.breakpoints(y, lo, hi)
        if np.isnan(z_left) or np.isnan(z_right):
            raise ModelError(f"the breakpoints for y_prev = {y:.6g} are not defined: the branches overflow on [{lo:.6g}, {hi:.6g}]; {_RESCALE}")
        return z_left, z_right

    def check_branches(self, x_min: float, x_max: float) -> BranchCheck:
        """Check on [x_min, x_max] that both branches increase and do not cross.

        Parameters
        ----------
        x_min : float
            Start of the range, e.g. the smallest x the data drive.
        x_max : float
            End of the range.

        Returns
        -------
        BranchCheck
            Where the paper's assumption fails, if anywhere.

        Raises
        ------
        DataError
            If the range is not finite.
        """
        lo, hi = _finite_range(x_min, x_max)
        ends = np.array([lo, hi])
        _finite_result([self._native.left(ends), self._native.right(ends)], f"a branch at the ends of [{lo:.6g}, {hi:.6g}]")
        d: Any = self._native.check_branches(lo, hi)
        return BranchCheck(**d)

    def characteristic(self, x_min: float, x_max: float, num: int = 400) -> tuple[NDArray[np.float64], ...]:
        """The characteristic (x, L(x), R(x)) on a grid, for plotting (Figs 1, 4, 7).

        Parameters
        ----------
        x_min : float
            Start of the grid.
        x_max : float
            End of the grid.
        num : int, default 400
            Grid points.

        Returns
        -------
        tuple of numpy.ndarray
            x, L(x) and R(x).

        Raises
        ------
        DataError
            If the range is not finite or ``num`` is not a whole number in [2, 10**7].
        ModelError
            If a branch exceeds the float range on the grid.
        """
        lo, hi = _finite_range(x_min, x_max)
        x = np.linspace(lo, hi, check_int(num, "num", 2, _MAX_GRID))
        return x, self.left(x), self.right(x)

    # -- serialisation -------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """The backlash as a JSON-safe dict.

        Returns
        -------
        dict
            ``c_left``, ``c_right``, ``m_left`` and ``m_right``.
        """
        return {
            "c_left": self._c_left,
            "c_right": self._c_right,
            "m_left": self._m_left.tolist(),
            "m_right": self._m_right.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> GeneralBacklash:
        """The backlash of a :meth:`to_dict` dict.

        Parameters
        ----------
        data : dict
            With the keys c_left, c_right, m_left and m_right.

        Returns
        -------
        GeneralBacklash
            The backlash (validated).
        """
        keys = ("c_left", "c_right", "m_left", "m_right")
        if not isinstance(data, dict) or any(k not in data for k in keys):
            raise ModelError(f"a backlash's dict has the keys {', '.join(keys)}, got {shown(data)}")
        return cls(*(data[k] for k in keys))

    def __reduce__(self) -> tuple[Any, ...]:
        # rebuilt (and revalidated) from its parameters: the Rust object does not pickle
        return (GeneralBacklash, (self._c_left, self._c_right, self._m_left.tolist(), self._m_right.tolist()))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, GeneralBacklash):
            return NotImplemented
        return (
            self._c_left == other._c_left
            and self._c_right == other._c_right
            and np.array_equal(self._m_left, other._m_left)
            and np.array_equal(self._m_right, other._m_right)
        )

    def __hash__(self) -> int:
        return hash((self._c_left, self._c_right, tuple(self._m_left), tuple(self._m_right)))

    def __repr__(self) -> str:
        return (
            f"GeneralBacklash(c_L={self._c_left:.6g}, c_R={self._c_right:.6g}, "
            f"m_L={format_list(self._m_left)}, m_R={format_list(self._m_right)})"
        )
