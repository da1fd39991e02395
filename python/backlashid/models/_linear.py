"""The linear dynamic block of eq (16) (also the sandwich's output block, eq 29)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import _core
from .._validation import as_coefficients, as_signal, format_list, frozen
from ..errors import DataError, ModelError

__all__ = ["LinearBlock"]


class LinearBlock:
    """x(t) = sum_{i=1}^{na} a_i u(t-i) - sum_{j=1}^{nb} b_j x(t-j)   (eq 16).

    ``a`` needs at least one coefficient; ``b`` may be empty (an FIR block). In a sandwich the
    output block (eq 29) is a LinearBlock with ``a = r`` and ``b = s``.

    ``feedthrough=True`` adds the lag-0 term (not in the paper; sampled real systems often
    respond within the sample): x(t) = a_0 u(t) + sum_{i=1}^{na} a_i u(t-i) - ..., and then
    ``a = [a_0, a_1, .., a_na]`` starts at lag 0, with na >= 1 (give a_1 = 0 for a block with
    a_0 alone). ``na`` is always the largest input lag (the length of ``u_past``).
    """

    __slots__ = ("_a", "_b", "_feedthrough", "_native")

    def __init__(self, a: ArrayLike, b: ArrayLike = (), *, feedthrough: bool = False) -> None:
        a_list = as_coefficients(a, "a")
        b_list = as_coefficients(b, "b", allow_empty=True)
        if not isinstance(feedthrough, (bool, np.bool_)):
            raise ModelError(f"feedthrough must be True or False, got {feedthrough!r}")
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
        return len(self._b)

    def poles(self) -> NDArray[np.complex128]:
        """Roots of z^nb + b_1 z^(nb-1) + ... + b_nb, sorted by decreasing modulus."""
        p = np.array([complex(re, im) for re, im in self._native.poles()], dtype=np.complex128)
        return p[np.argsort(-np.abs(p), kind="stable")]

    def spectral_radius(self) -> float:
        """Largest pole modulus (0 for an FIR block)."""
        p = self.poles()
        return float(np.abs(p).max()) if p.size else 0.0

    def is_stable(self) -> bool:
        """True when every pole lies strictly inside the unit circle."""
        return self.spectral_radius() < 1.0

    def static_gain(self) -> float:
        """Steady-state gain sum(a) / (1 + sum(b)); inf at a pole z = 1."""
        den = 1.0 + float(self._b.sum())
        return float(self._a.sum()) / den if den != 0.0 else float("inf")

    def simulate(
        self,
        u: ArrayLike,
        *,
        u_past: ArrayLike | None = None,
        x_past: ArrayLike | None = None,
    ) -> NDArray[np.float64]:
        """x for the input u; ``u_past = [u(0), u(-1), ..]`` and ``x_past = [x(0), ..]``
        (most recent first) give the state before the record, zero by default."""
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
        """The difference equation as text, e.g. 'x(t) = 0.7 u(t-1) + 0.2 x(t-1)'."""
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
        """{"a": .., "b": ..}, plus "feedthrough": true when a starts at lag 0 (dicts
        without the key, e.g. from earlier versions, load as blocks without feedthrough)."""
        out: dict[str, Any] = {"a": self._a.tolist(), "b": self._b.tolist()}
        if self._feedthrough:
            out["feedthrough"] = True
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> LinearBlock:
        return cls(data["a"], data.get("b", ()), feedthrough=bool(data.get("feedthrough", False)))

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
