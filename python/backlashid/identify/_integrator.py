"""A block's pole held at the integrator: the search of a position that integrates, off the
stability guard's wall.

A drive whose measured output is a position has a pole at z = 1 in one block of its chain (the
motor's, in the input block; the load's, in the sandwich's output block). The compiled
problem's stability guard (``feasible``: every pole inside the unit circle) rejects every step
that would cross |z| = 1, so a search whose optimum wants that pole at (or a hair beyond) 1
ends on the wall, where each step along it that nudges the pole outward is rejected and the
damping grows: Levenberg-Marquardt stops with the other parameters short of their optimum (on
the position input-backlash records of tests/identify/test_position_records.py, poles 1 -
1e-13 and fits 1.3-2.5 noise stds where the plant's model reaches the noise).

:class:`HeldIntegrator` is the same problem with that pole held at AT_INTEGRATOR (just inside
1): the block's denominator 1 + b_1 q^-1 + .. + b_n q^-n = (1 - rho q^-1)(1 + b'_1 q^-1 + ..
+ b'_{n-1} q^-(n-1)), searched over b'_1..b'_{n-1} in the places of b_1..b_{n-1} (b_n left
out). The map is affine, b = T b' + c, so the factor of [J | r] is the full problem's with
its columns multiplied by T and triangularised again, and the gradient T^T g: the core's
passes, nothing simulated here.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

# how close to 1 a real pole must be to sit on the guard's wall
ON_WALL = 1e-8


def poles_on_wall(names: list[str], theta: NDArray[np.float64], prefix: str) -> list[int] | None:
    """The indices of the block's denominator coefficients (``prefix`` "b" for the input block,
    "s" for the sandwich's output block: b_1..b_n) when that block has a real pole within
    ON_WALL of z = 1 (a block of one pole needs nothing held: it has no other parameter to
    free); else None."""
    at = [names.index(f"{prefix}{k}") for k in range(1, len(names) + 1) if f"{prefix}{k}" in names]
    if len(at) < 2:
        return None
    poles = np.roots(np.r_[1.0, theta[at]])
    on = [p for p in poles if abs(p.imag) < ON_WALL and 1.0 - p.real < ON_WALL]
    return at if on else None


class HeldIntegrator:
    """A compiled problem (or a wrapper of one, e.g. :class:`~._valid.ValidOnly`) with one
    pole of the block whose denominator coefficients sit at ``coefficients`` (b_1..b_n, n >=
    2) held at ``rho``; theta in its layout with b'_1..b'_{n-1} in the places of b_1..b_{n-1}
    and b_n left out (module header): what Levenberg-Marquardt asks of a problem (names,
    bounds, cost, feasible, gradient, oe_factor, simulate, samples, warmup)."""

    def __init__(self, prob: Any, coefficients: list[int], rho: float) -> None:
        p = len(prob.names)
        n = len(coefficients)
        self._prob, self._rho = prob, rho
        self._keep = [i for i in range(p) if i != coefficients[-1]]
        index = {full: j for j, full in enumerate(self._keep)}
        # b = T b' + c: b_k = b'_k - rho b'_(k-1), b'_0 = 1, b'_n = 0
        t, c = np.zeros((p, p - 1)), np.zeros(p)
        for i in self._keep:
            if i not in coefficients:
                t[i, index[i]] = 1.0
        for k in range(1, n + 1):
            row = coefficients[k - 1]
            if k <= n - 1:
                t[row, index[coefficients[k - 1]]] += 1.0
            if k == 1:
                c[row] = -rho
            else:
                t[row, index[coefficients[k - 2]]] -= rho
        self._t, self._c = t, c
        self._coefficients = coefficients

    def __getattr__(self, name: str) -> Any:
        # what takes no theta is the problem's; anything else would read theta in the wrong layout
        if name in ("samples", "warmup", "lengths"):
            return getattr(self._prob, name)
        raise AttributeError(f"{type(self).__name__} has no {name!r}")

    def simulate(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(self._prob.simulate(self.full(theta)), dtype=np.float64)

    @property
    def names(self) -> list[str]:
        return [self._prob.names[i] for i in self._keep]

    def full(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """The problem's own theta of a theta in this layout."""
        return np.asarray(self._t @ np.asarray(theta, dtype=np.float64) + self._c, dtype=np.float64)

    def reduced(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        """A theta of the problem in this layout: the block's denominator divided by (1 - rho
        q^-1), the remainder dropped (it is what moving the pole onto rho changes)."""
        out = np.asarray(theta, dtype=np.float64)[self._keep].copy()
        quotient, _ = np.polydiv(np.r_[1.0, np.asarray(theta)[self._coefficients]], [1.0, -self._rho])
        for k, row in enumerate(self._coefficients[:-1]):
            out[self._keep.index(row)] = quotient[k + 1]
        return out

    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        lo, hi = (np.asarray(b, dtype=np.float64) for b in self._prob.bounds())
        return lo[self._keep].copy(), hi[self._keep].copy()

    def cost(self, theta: NDArray[np.float64]) -> float:
        return float(self._prob.cost(self.full(theta)))

    def feasible(self, theta: NDArray[np.float64]) -> bool:
        return bool(self._prob.feasible(self.full(theta)))

    def gradient(self, theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
        g, cost = self._prob.gradient(self.full(theta))
        return self._t.T @ np.asarray(g, dtype=np.float64), float(cost)

    def oe_factor(self, theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
        r_aug, cost = self._prob.oe_factor(self.full(theta))
        r_aug = np.asarray(r_aug, dtype=np.float64)
        m = np.column_stack([r_aug[:, :-1] @ self._t, r_aug[:, -1]])
        return np.linalg.qr(m, mode="r"), float(cost)
