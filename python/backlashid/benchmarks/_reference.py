"""Per-sample NumPy reference of the paper's models, written as a reader of the paper would.

Plain Python loops over the samples (this is a reference, not a fast path): the linear block
(eq 16) as a difference equation from rest, the same block driven through Coulomb and viscous
friction, the branches (eq 4-5) by Horner's rule, the general backlash (eq 1) in its case
order, and the play operator. The withheld-effect generator builds its true systems from these,
independently of the Rust core, and ``benches/numpy_reference.py`` simulates with them.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

__all__ = ["backlash", "branch", "difference_equation", "linear_with_friction", "play"]

Array = NDArray[np.float64]


def difference_equation(num: Sequence[float], den: Sequence[float], u: Array) -> Array:
    """y(t) = sum_{k>=0} num[k] u(t-k) - sum_{j>=1} den[j-1] y(t-j), from rest (eq 16 with
    num = [0, a_1, .., a_na], den = b)."""
    num, den = [float(v) for v in num], [float(v) for v in den]
    uu = [0.0] * len(num) + u.tolist()
    yy = [0.0] * len(den)
    ku, kd = len(num), len(den)
    for t in range(len(u)):
        acc = 0.0
        for k, c in enumerate(num):
            acc += c * uu[ku + t - k]
        for j, c in enumerate(den, 1):
            acc -= c * yy[kd + t - j]
        yy.append(acc)
    return np.array(yy[kd:], dtype=np.float64)


def linear_with_friction(a: Sequence[float], b: Sequence[float], u: Array, f_c: float, f_v: float) -> Array:
    """Eq (16) driven by u_eff(t) = u(t) - F_c sign(v(t)) - F_v v(t), v(t) = x(t) - x(t-1)
    (sign(0) = 0): x(t) needs u_eff up to t - 1 only, so u_eff(t) follows x(t)."""
    a, b = [float(v) for v in a], [float(v) for v in b]
    na, nb = len(a), len(b)
    ue = [0.0] * na  # u_eff(t-na) .. u_eff(t-1), oldest first
    xx = [0.0] * max(nb, 1)
    out = np.empty(len(u))
    for t, ut in enumerate(u.tolist()):
        x = 0.0
        for i in range(1, na + 1):
            x += a[i - 1] * ue[-i]
        for j in range(1, nb + 1):
            x -= b[j - 1] * xx[-j]
        v = x - xx[-1]
        sign = 1.0 if v > 0.0 else (-1.0 if v < 0.0 else 0.0)
        ue.append(ut - f_c * sign - f_v * v)
        xx.append(x)
        out[t] = x
    return out


def branch(m: Sequence[float], xi: Array) -> Array:
    """sum_{i=1}^n m_i xi^i (eq 4-5) by Horner's rule."""
    acc = np.zeros_like(xi)
    for c in reversed([float(v) for v in m]):
        acc = (acc + c) * xi
    return acc


def backlash(left: Array, right: Array, y0: float = 0.0) -> Array:
    """Eq (1) with the exclusive case order: L if L(x) <= y(t-1), else R if R(x) >= y(t-1),
    else hold. ``left``, ``right`` are the branch values L(x(t)), R(x(t)) per sample."""
    y_prev, out = float(y0), np.empty(len(left))
    for t, (lv, rv) in enumerate(zip(left.tolist(), right.tolist())):
        if lv <= y_prev:
            y_prev = lv
        elif rv >= y_prev:
            y_prev = rv
        out[t] = y_prev
    return out


def play(x: Array, r: float) -> Array:
    """Play operator of radius r: p(t) = max(x(t) - r, min(x(t) + r, p(t-1))), p = 0 at rest."""
    p, out = 0.0, np.empty(len(x))
    for t, xt in enumerate(x.tolist()):
        p = max(xt - r, min(xt + r, p))
        out[t] = p
    return out
