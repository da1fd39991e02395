"""The linear dynamic block of eq (16) (also the sandwich's output block, eq 29)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import _core
from .._validation import as_coefficients, as_signal, check_flag, format_list, frozen, shown
from ..errors import DataError, ModelError

__all__ = ["LinearBlock"]


class LinearBlock:
    """The linear dynamic block x(t) = sum_{i=1}^{na} a_i u(t-i) - sum_{j=1}^{nb} b_j x(t-j)
    (eq 16).

    In a sandwich the output block (eq 29) is a LinearBlock with ``a = r`` and ``b = s``.
    ``feedthrough=True`` adds the lag-0 term (not in the paper; sampled real systems often
    respond within the sample): x(t) = a_0 u(t) + sum_{i=1}^{na} a_i u(t-i) - .., and then
    ``a = [a_0, a_1, .., a_na]`` starts at lag 0. ``na`` is always the largest input lag (the
    length of ``u_past``). Frozen: the coefficients are read-only.

    Parameters
    ----------
    a : array_like
        Input coefficients a_1..a_na (at least one), or a_0..a_na with feedthrough (at least
        a_0 and a_1; give a_1 = 0 for a block with a_0 alone).
    b : array_like, default ()
        Output coefficients b_1..b_nb; empty for an FIR block.
    feedthrough : bool, default False
        ``a`` starts at lag 0.

    Raises
    ------
    ModelError
        If a coefficient list is empty (``a``), not a flat list of real numbers, or not finite.

    Examples
    --------
    >>> from backlashid import LinearBlock
    >>> block = LinearBlock([0.7, 0.5], [-0.2, 0.35])
    >>> block.equation()
    'x(t) = 0.7 u(t-1) + 0.5 u(t-2) + 0.2 x(t-1) - 0.35 x(t-2)'
    >>> block.simulate([1.0, 0.0, 0.0]).tolist()
    [0.0, 0.7, 0.64]
    """

    __slots__ = ("_a", "_b", "_feedthrough", "_native")

    def __init__(self, a: ArrayLike, b: ArrayLike = (), *, feedthrough: bool = False) -> None:
        a_list = as_coefficients(a, "a")
        b_list = as_coefficients(b, "b", allow_empty=True)
        feedthrough = check_flag(feedthrough, "feedthrough", ModelError)
        if feedthrough:
            if len(a_list) < 2:
                raise ModelError(
                    f"feedthrough=True takes a = [a_0, a_1, ..] with at least a_0 and a_1, got {a_list}: "
                    "give a_1 = 0 for a block with a lag-0 term only"
                )
            self._native = _core.LinearBlock(a_list[1:], b_list, a_list[0])
        else:
            self._native = _core.LinearBlock(a_list, b_list)  # validates, raises ModelError
        self._feedthrough = bool(feedthrough)
        self._a = frozen(a_list)
        self._b = frozen(b_list)

    @property
    def a(self) -> NDArray[np.float64]:
        """Input coefficients a_1..a_na, or a_0..a_na with feedthrough (read-only)."""
        return self._a

    @property
    def feedthrough(self) -> bool:
        """True when ``a`` starts with the lag-0 coefficient a_0."""
        return self._feedthrough

    @property
    def lags(self) -> NDArray[np.int64]:
        """The input lag of each entry of ``a`` (0.. with feedthrough, 1.. without)."""
        return np.arange(len(self._a)) + (0 if self._feedthrough else 1)

    @property
    def b(self) -> NDArray[np.float64]:
        """Output coefficients b_1..b_nb (read-only); note the minus sign in eq (16)."""
        return self._b

    @property
    def na(self) -> int:
        """Largest input lag: the number of past inputs the block remembers."""
        return len(self._a) - int(self._feedthrough)

    @property
    def nb(self) -> int:
        """Number of output coefficients b_1..b_nb."""
        return len(self._b)

    def poles(self) -> NDArray[np.complex128]:
        """The poles: roots of z^nb + b_1 z^(nb-1) + ... + b_nb.

        Returns
        -------
        numpy.ndarray
            Complex poles sorted by decreasing modulus (empty for an FIR block).

        Examples
        --------
        >>> from backlashid import LinearBlock
        >>> LinearBlock([1.0], [-0.5]).poles()
        array([0.5+0.j])
        """
        p = np.array([complex(re, im) for re, im in self._native.poles()], dtype=np.complex128)
        return p[np.argsort(-np.abs(p), kind="stable")]

    def spectral_radius(self) -> float:
        """The largest pole modulus.

        Returns
        -------
        float
            max ``abs(poles())``, 0 for an FIR block.

        Examples
        --------
        >>> from backlashid import LinearBlock
        >>> LinearBlock([1.0], [0.0, 0.25]).spectral_radius()
        0.5
        """
        p = self.poles()
        return float(np.abs(p).max()) if p.size else 0.0

    def is_stable(self) -> bool:
        """Whether every pole lies strictly inside the unit circle.

        Returns
        -------
        bool
            ``spectral_radius() < 1``.
        """
        return self.spectral_radius() < 1.0

    def static_gain(self) -> float:
        """The steady-state gain sum(a) / (1 + sum(b)).

        Returns
        -------
        float
            The gain, inf for a pole at z = 1.

        Examples
        --------
        >>> from backlashid import LinearBlock
        >>> LinearBlock([0.5, 0.5], [-0.5]).static_gain()
        2.0
        """
        den = 1.0 + float(self._b.sum())
        return float(self._a.sum()) / den if den != 0.0 else float("inf")

    def simulate(
        self,
        u: ArrayLike,
        *,
        u_past: ArrayLike | None = None,
        x_past: ArrayLike | None = None,
    ) -> NDArray[np.float64]:
        """The block's output x for the input u.

        Parameters
        ----------
        u : array_like
            Input u(1), u(2), ...
        u_past : array_like, optional
            ``[u(0), u(-1), ..]``, na values, most recent first (default zeros).
        x_past : array_like, optional
            ``[x(0), x(-1), ..]``, nb values, most recent first (default zeros).

        Returns
        -------
        numpy.ndarray
            x(1), x(2), ...

        Raises
        ------
        DataError
            If u or a past is not finite, or a past has the wrong length.
        ModelError
            If the output overflows (an unstable block).

        Examples
        --------
        >>> from backlashid import LinearBlock
        >>> LinearBlock([1.0]).simulate([2.0, 3.0], u_past=[1.0]).tolist()
        [1.0, 2.0]
        """
        return self._native.simulate(as_signal(u, "u"), *self._past(u_past, x_past))

    def _past(self, u_past: ArrayLike | None, x_past: ArrayLike | None) -> tuple[list[float], list[float]]:
        def one(values: ArrayLike | None, n: int, name: str) -> list[float]:
            if values is None:
                return [0.0] * n
            arr = as_signal(values, name).ravel()
            if arr.size != n:
                raise DataError(f"{name} has {arr.size} values but the block needs {n}: most recent first")
            return [float(v) for v in arr]

        return one(u_past, self.na, "u_past"), one(x_past, self.nb, "x_past")

    def equation(self, input: str = "u", output: str = "x") -> str:
        """The difference equation as text.

        Parameters
        ----------
        input : str, default 'u'
            Name of the input signal.
        output : str, default 'x'
            Name of the output signal.

        Returns
        -------
        str
            E.g. ``'x(t) = 0.7 u(t-1) + 0.2 x(t-1)'``.

        Examples
        --------
        >>> from backlashid import LinearBlock
        >>> LinearBlock([1.0], [0.5]).equation("y", "w")
        'w(t) = 1 y(t-1) - 0.5 w(t-1)'
        """
        terms = [(float(c), f"{input}(t-{i})" if i else f"{input}(t)") for i, c in zip(self.lags, self._a)]
        terms += [(-float(c), f"{output}(t-{j})") for j, c in enumerate(self._b, 1)]
        text = ""
        for k, (c, sym) in enumerate(terms):
            if k == 0:
                text = f"{c:.6g} {sym}"
            else:
                text += f" {'-' if c < 0 else '+'} {abs(c):.6g} {sym}"
        return f"{output}(t) = {text}"

    def to_dict(self) -> dict[str, Any]:
        """The block as a JSON-safe dict.

        Returns
        -------
        dict
            ``{"a": [..], "b": [..]}``, plus ``"feedthrough": True`` when ``a`` starts at lag
            0 (dicts without the key, e.g. from earlier versions, load as blocks without
            feedthrough).
        """
        out: dict[str, Any] = {"a": self._a.tolist(), "b": self._b.tolist()}
        if self._feedthrough:
            out["feedthrough"] = True
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> LinearBlock:
        """The block of a :meth:`to_dict` dict.

        Parameters
        ----------
        data : dict
            With the keys "a", optionally "b" and "feedthrough".

        Returns
        -------
        LinearBlock
            The block.
        """
        if not isinstance(data, dict) or "a" not in data:
            raise ModelError(f"a linear block's dict has the keys a, b and feedthrough, got {shown(data)}")
        return cls(data["a"], data.get("b", ()), feedthrough=check_flag(data.get("feedthrough", False), "feedthrough", ModelError))

    def __reduce__(self) -> tuple[Any, ...]:
        # rebuilt from its coefficients: the Rust object behind it does not pickle
        return (_rebuild, (self._a.tolist(), self._b.tolist(), self._feedthrough))

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, LinearBlock):
            return NotImplemented
        return (
            self._feedthrough == other._feedthrough
            and np.array_equal(self._a, other._a)
            and np.array_equal(self._b, other._b)
        )

    def __hash__(self) -> int:
        return hash((tuple(self._a), tuple(self._b), self._feedthrough))

    def __repr__(self) -> str:
        extra = ", feedthrough=True" if self._feedthrough else ""
        return f"LinearBlock(a={format_list(self._a)}, b={format_list(self._b)}{extra})"


def _rebuild(a: list[float], b: list[float], feedthrough: bool) -> LinearBlock:
    return LinearBlock(a, b, feedthrough=feedthrough)
