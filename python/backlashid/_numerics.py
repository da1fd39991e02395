"""Small numerical routines the package shares: Brent's bounded 1-D minimiser and bracketed
root finder (the package's only scalar searches, in place of SciPy's optimisers), and least
squares for tall, narrow matrices.

``minimize_bounded`` is Brent's method (golden section with parabolic steps; Brent 1973, ch. 5,
as in Forsythe, Malcolm and Moler's ``fmin``) with the tolerances of ``fminbound``;
``find_root`` is Brent's bracketed root search (ch. 4, ``zeroin``) with an absolute and a
relative tolerance. Both take a Python function of a float: the loop is over iterations, never
over samples.

``lstsq`` equals ``numpy.linalg.lstsq(a, b, rcond=None)[0]`` (the minimum-norm solution, singular
values below eps max(n, p) times the largest dropped) for a matrix of thousands of rows and a
few dozen columns. LAPACK's QR of such a matrix hands each Householder reflection to the BLAS
threads; on a shared two-core machine those hand-offs cost 50-250 ms a call against 2 ms on
one thread. The R factor of blocks of about ``BLOCK_SIZE`` elements (below OpenBLAS's threading
threshold), stacked and factored again, is the same R (a tall-skinny QR), and the solution
follows from R's small SVD.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["BLOCK_SIZE", "find_root", "lstsq", "minimize_bounded", "r_factor"]

Array = NDArray[np.float64]

BLOCK_SIZE = 3000  # rows x columns of one block of the tall-skinny QR

_SQRT_EPS = math.sqrt(2.2e-16)
_GOLDEN = 0.5 * (3.0 - math.sqrt(5.0))


def minimize_bounded(fun: Callable[[float], float], lo: float, hi: float, xatol: float, max_eval: int = 500) -> tuple[float, float, bool]:
    """Brent's minimiser of ``fun`` on [lo, hi] (golden section and parabolic interpolation).

    The tolerance is ``fminbound``'s: stop when x lies within 2 (sqrt(eps) abs(x) + xatol / 3)
    of the middle of the bracket, less half its width.

    Parameters
    ----------
    fun : callable
        ``fun(x) -> float``.
    lo, hi : float
        The bracket, finite, lo <= hi.
    xatol : float
        Absolute tolerance in x.
    max_eval : int, default 500
        Most evaluations of ``fun``.

    Returns
    -------
    x : float
        The best point.
    fx : float
        ``fun(x)``.
    converged : bool
        False if ``max_eval`` was reached or the function returned NaN.

    Examples
    --------
    >>> from backlashid._numerics import minimize_bounded
    >>> x, fx, ok = minimize_bounded(lambda x: (x - 0.3) ** 2, -1.0, 1.0, 1e-10)
    >>> round(x, 8), ok
    (0.3, True)
    """
    if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
        raise ValueError(f"minimize_bounded needs a finite bracket lo <= hi, got ({lo}, {hi})")
    a, b = lo, hi
    v = w = xf = a + _GOLDEN * (b - a)
    fx = fv = fw = fun(xf)
    n_eval, fu = 1, math.inf
    rat = e = 0.0
    xm = 0.5 * (a + b)
    tol1 = _SQRT_EPS * abs(xf) + xatol / 3.0
    tol2 = 2.0 * tol1
    converged = True
    while abs(xf - xm) > tol2 - 0.5 * (b - a):
        golden = True
        if abs(e) > tol1:  # try a parabola through (v, w, x)
            golden = False
            r = (xf - w) * (fx - fv)
            q = (xf - v) * (fx - fw)
            p = (xf - v) * q - (xf - w) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = abs(q)
            r, e = e, rat
            if abs(p) < abs(0.5 * q * r) and q * (a - xf) < p < q * (b - xf):
                rat = p / q
                x = xf + rat
                if x - a < tol2 or b - x < tol2:
                    rat = tol1 * (1.0 if xm >= xf else -1.0)
            else:
                golden = True
        if golden:
            e = (a - xf) if xf >= xm else (b - xf)
            rat = _GOLDEN * e
        x = xf + (1.0 if rat >= 0 else -1.0) * max(abs(rat), tol1)
        fu = fun(x)
        n_eval += 1
        if fu <= fx:
            if x >= xf:
                a = xf
            else:
                b = xf
            v, fv, w, fw = w, fw, xf, fx
            xf, fx = x, fu
        else:
            if x < xf:
                a = x
            else:
                b = x
            if fu <= fw or w == xf:
                v, fv, w, fw = w, fw, x, fu
            elif fu <= fv or v == xf or v == w:
                v, fv = x, fu
        xm = 0.5 * (a + b)
        tol1 = _SQRT_EPS * abs(xf) + xatol / 3.0
        tol2 = 2.0 * tol1
        if n_eval >= max_eval:
            converged = False
            break
    if math.isnan(xf) or math.isnan(fx) or math.isnan(fu):
        converged = False
    return xf, fx, converged


def find_root(fun: Callable[[float], float], lo: float, hi: float, xtol: float, rtol: float, max_iter: int = 200) -> float:
    """Brent's root of ``fun`` in [lo, hi], where ``fun`` changes sign (``zeroin``).

    Inverse quadratic interpolation, secant steps and bisection; stops when the bracket is
    within (xtol + rtol abs(x)) / 2 of x.

    Parameters
    ----------
    fun : callable
        ``fun(x) -> float``.
    lo, hi : float
        The bracket; ``fun(lo)`` and ``fun(hi)`` of opposite signs (or one of them 0).
    xtol : float
        Absolute tolerance.
    rtol : float
        Relative tolerance.
    max_iter : int, default 200
        Most iterations.

    Returns
    -------
    float
        The root.

    Raises
    ------
    ValueError
        If ``fun`` has the same sign at both ends, or no root is found in ``max_iter`` steps.

    Examples
    --------
    >>> from backlashid._numerics import find_root
    >>> round(find_root(lambda x: x * x - 2.0, 0.0, 2.0, 1e-15, 1e-14), 12)
    1.414213562373
    """
    x_pre, x_cur = float(lo), float(hi)
    f_pre, f_cur = fun(x_pre), fun(x_cur)
    if f_pre == 0.0:
        return x_pre
    if f_cur == 0.0:
        return x_cur
    if math.copysign(1.0, f_pre) == math.copysign(1.0, f_cur):
        raise ValueError(f"find_root needs a sign change on [{lo}, {hi}]: f = {f_pre}, {f_cur}")
    x_blk = f_blk = s_pre = s_cur = 0.0
    for _ in range(max_iter):
        if f_pre != 0.0 and f_cur != 0.0 and math.copysign(1.0, f_pre) != math.copysign(1.0, f_cur):
            x_blk, f_blk = x_pre, f_pre
            s_pre = s_cur = x_cur - x_pre
        if abs(f_blk) < abs(f_cur):  # x_cur is the best point so far
            x_pre, x_cur, x_blk = x_cur, x_blk, x_cur
            f_pre, f_cur, f_blk = f_cur, f_blk, f_cur
        delta = 0.5 * (xtol + rtol * abs(x_cur))
        s_bis = 0.5 * (x_blk - x_cur)
        if f_cur == 0.0 or abs(s_bis) < delta:
            return x_cur
        if abs(s_pre) > delta and abs(f_cur) < abs(f_pre):
            if x_pre == x_blk:  # secant
                s_try = -f_cur * (x_cur - x_pre) / (f_cur - f_pre)
            else:  # inverse quadratic interpolation
                d_pre = (f_pre - f_cur) / (x_pre - x_cur)
                d_blk = (f_blk - f_cur) / (x_blk - x_cur)
                s_try = -f_cur * (f_blk * d_blk - f_pre * d_pre) / (d_blk * d_pre * (f_blk - f_pre))
            if 2.0 * abs(s_try) < min(abs(s_pre), 3.0 * abs(s_bis) - delta):
                s_pre, s_cur = s_cur, s_try
            else:
                s_pre = s_cur = s_bis
        else:
            s_pre = s_cur = s_bis
        x_pre, f_pre = x_cur, f_cur
        x_cur += s_cur if abs(s_cur) > delta else (delta if s_bis > 0 else -delta)
        f_cur = fun(x_cur)
    raise ValueError(f"find_root: no convergence in {max_iter} iterations on [{lo}, {hi}]")


def _block_rows(cols: int) -> int:
    return max(2 * cols, BLOCK_SIZE // cols)


def r_factor(m: Array) -> Array:
    """R of the QR of m (n x p, n >= p): R^T R = m^T m, and a least-squares problem over any of
    m's columns has the same solution and residual norm on R's columns. By blocks of rows
    while m is taller than one block.

    Parameters
    ----------
    m : ndarray
        (n, p) matrix.

    Returns
    -------
    ndarray
        (min(n, p), p) upper triangular factor.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid._numerics import r_factor
    >>> m = np.random.default_rng(0).standard_normal((5000, 3))
    >>> r = r_factor(m)
    >>> bool(np.allclose(r.T @ r, m.T @ m))
    True
    """
    rows = _block_rows(m.shape[1])
    while m.shape[0] > rows:
        m = np.vstack([np.linalg.qr(m[i : i + rows], mode="r") for i in range(0, m.shape[0], rows)])
    return np.linalg.qr(m, mode="r")


def lstsq(a: ArrayLike, b: ArrayLike) -> Array:
    """Minimum-norm least-squares solution of a x = b, as ``numpy.linalg.lstsq(a, b, rcond=None)[0]``.

    Parameters
    ----------
    a : array_like
        (n, p) matrix.
    b : array_like
        (n,) or (n, k) right-hand side.

    Returns
    -------
    ndarray
        (p,) or (p, k) solution.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid._numerics import lstsq
    >>> a = np.column_stack([np.ones(1000), np.arange(1000.0)])
    >>> np.round(lstsq(a, 2.0 + 0.5 * np.arange(1000.0)), 10).tolist()
    [2.0, 0.5]
    """
    a_arr = np.asarray(a, dtype=np.float64)
    b_arr = np.asarray(b, dtype=np.float64)
    n, p = a_arr.shape
    if p == 0 or n <= 2 * _block_rows(p + 1):
        return np.linalg.lstsq(a_arr, b_arr, rcond=None)[0]
    r = r_factor(np.column_stack([a_arr, b_arr]))
    rcond = np.finfo(np.float64).eps * max(n, p)
    return np.linalg.lstsq(r[:p, :p], r[:p, p:] if b_arr.ndim == 2 else r[:p, p], rcond=rcond)[0]
