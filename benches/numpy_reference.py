"""A plain NumPy (and SciPy) implementation of the cascade identification, written as a user of
the paper would write it, to benchmark backlashid against (benches/compare.py).

Same conventions as the library (NOTES.md): every signal is 0 before the record, backlash memory
y(0) = 0, h(s) = 1 for s <= 0, the exclusive switching rule (f2 := f2 and not f1), m_L1 = 1.
Parameter vector (physical order): a_1..a_na, b_1..b_nb, c_L, m_L2..m_Ln, m_R1, c_R, m_R2..m_Rn.
The least-squares vector of eq (19) has c_1 = c_L and c_2 = m_R1 c_R in the places of c_L, c_R.

Two variants of the paper's iterations:

* ``loop=True``: x(t) of eq (22) and f1, f2 of eq (25)-(26) sample by sample in one Python loop
  (the recursion of eq 22 cannot be vectorised in NumPy); the regressor eq (18) by NumPy column
  operations; ``np.linalg.lstsq``.
* ``loop=False``: x by ``scipy.signal.lfilter`` and f1, f2 as array expressions. With the
  *measured* y(t-1) in eq (25)-(26) the switching does not depend on the previous decision, so
  it vectorises; only the simulation (the model's own y(t-1)) needs a loop.

The simulation (for the output-error fit and the simulate benchmark) is ``lfilter`` for the
linear block and a Python loop for the backlash, with both branches evaluated as arrays first.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

# the per-sample reference of eq (1) and (4)-(5) has one home, shared with the withheld-effect generator
from backlashid.benchmarks._reference import backlash as backlash_loop
from backlashid.benchmarks._reference import branch

Array = NDArray[np.float64]


# -- parameter vector ----------------------------------------------------------------------------


def unpack(theta: Array, na: int, nb: int, degree: int) -> tuple[Array, Array, float, float, Array, Array]:
    """(a, b, c_L, c_R, m_L, m_R) with m_L1 = 1 put back."""
    t = np.asarray(theta, dtype=np.float64)
    k, n = na + nb, degree
    a, b = t[:na], t[na:k]
    c_l = float(t[k])
    m_l = np.concatenate([[1.0], t[k + 1 : k + n]])
    m_r1, c_r = float(t[k + n]), float(t[k + n + 1])
    m_r = np.concatenate([[m_r1], t[k + n + 2 : k + 2 * n + 1]])
    return a, b, c_l, c_r, m_l, m_r


def lagged(s: Array, k: int) -> Array:
    """s(t-k), zero before the record."""
    out = np.zeros_like(s)
    if k < len(s):
        out[k:] = s[: len(s) - k]
    return out


# -- linear block and simulation -----------------------------------------------------------------


def linear_filter(a: Array, b: Array, u: Array) -> Array:
    """x(t) = sum a_i u(t-i) - sum b_j x(t-j) (eq 16) from rest."""
    from scipy.signal import lfilter

    return lfilter(np.concatenate([[0.0], a]), np.concatenate([[1.0], b]), u)


def simulate(theta: Array, u: Array, na: int = 2, nb: int = 2, degree: int = 3) -> Array:
    """Free-run cascade output from rest: lfilter for the linear block, a Python loop for the
    backlash."""
    a, b, c_l, c_r, m_l, m_r = unpack(theta, na, nb, degree)
    x = linear_filter(a, b, u)
    with np.errstate(over="ignore", invalid="ignore"):
        return backlash_loop(branch(m_l, x + c_l), branch(m_r, x - c_r))


# -- the paper's iterations ----------------------------------------------------------------------


def arx_start(u: Array, y: Array, na: int, nb: int, degree: int, initial: tuple[float, float, float]) -> Array:
    """Iteration 1: ARX fit y(t) = sum a_i u(t-i) - sum b_j y(t-j), plus (m_R1, c_L, c_R)."""
    phi = np.column_stack([lagged(u, i) for i in range(1, na + 1)] + [-lagged(y, j) for j in range(1, nb + 1)])
    lin = np.linalg.lstsq(phi, y, rcond=None)[0]
    m_r1, c_l, c_r = initial
    return np.concatenate([lin, [c_l], np.zeros(degree - 1), [m_r1, c_r], np.zeros(degree - 1)])


def internals_loop(
    a: Array, b: Array, c_l: float, c_r: float, m_l: Array, m_r: Array, u: Array, y: Array
) -> tuple[Array, Array, Array]:
    """x (eq 22), f1, f2 (eq 25-26, exclusive rule, measured y(t-1)) in one sample loop."""
    n = len(u)
    al, bl, ml, mr = a.tolist(), b.tolist(), m_l.tolist()[::-1], m_r.tolist()[::-1]
    na, nb = len(al), len(bl)
    ul, yl = u.tolist(), y.tolist()
    x = [0.0] * n
    f1 = [False] * n
    f2 = [False] * n
    for t in range(n):
        xt = 0.0
        for i in range(1, na + 1):
            if t >= i:
                xt += al[i - 1] * ul[t - i]
        for j in range(1, nb + 1):
            if t >= j:
                xt -= bl[j - 1] * x[t - j]
        x[t] = xt
        yp = yl[t - 1] if t > 0 else 0.0
        xi1, xi2 = xt + c_l, xt - c_r
        lv = 0.0
        for m in ml:
            lv = (lv + m) * xi1
        rv = 0.0
        for m in mr:
            rv = (rv + m) * xi2
        g1 = lv - yp <= 0.0
        f1[t] = g1
        f2[t] = (yp - rv <= 0.0) and not g1
    return np.array(x), np.array(f1), np.array(f2)


def internals_vectorised(
    a: Array, b: Array, c_l: float, c_r: float, m_l: Array, m_r: Array, u: Array, y: Array
) -> tuple[Array, Array, Array]:
    """The same as :func:`internals_loop` with lfilter and array expressions."""
    x = linear_filter(a, b, u)
    yp = lagged(y, 1)
    f1 = branch(m_l, x + c_l) - yp <= 0.0
    f2 = (yp - branch(m_r, x - c_r) <= 0.0) & ~f1
    return x, f1, f2


def paper_iteration(theta: Array, u: Array, y: Array, na: int, nb: int, degree: int, loop: bool) -> Array:
    """One iteration: internal variables at theta, regressor eq (18), target eq (21), least
    squares eq (28), then c_R = c_2 / m_R1 (eq 20)."""
    a, b, c_l, c_r, m_l, m_r = unpack(theta, na, nb, degree)
    x, f1, f2 = (internals_loop if loop else internals_vectorised)(a, b, c_l, c_r, m_l, m_r, u, y)
    g1, g2 = f1.astype(np.float64), f2.astype(np.float64)
    xi1, xi2 = x + c_l, x - c_r
    cols = [lagged(u, i) * g1 for i in range(1, na + 1)]
    cols += [-lagged(x, j) * g1 for j in range(1, nb + 1)]
    cols += [g1] + [xi1**i * g1 for i in range(2, degree + 1)]
    cols += [x * g2, -g2] + [xi2**i * g2 for i in range(2, degree + 1)]
    phi = np.column_stack(cols)
    target = y - lagged(y, 1) * (1.0 - g1) * (1.0 - g2)
    theta_ls = np.linalg.lstsq(phi, target, rcond=None)[0]
    k = na + nb + degree  # position of m_R1; c_2 follows it
    theta_new = theta_ls.copy()
    theta_new[k + 1] = theta_ls[k + 1] / theta_ls[k]
    return theta_new


def fit_paper(
    u: Array,
    y: Array,
    na: int = 2,
    nb: int = 2,
    degree: int = 3,
    *,
    iterations: int = 20,
    initial: tuple[float, float, float] = (1.0, 0.001, 0.001),
    loop: bool = True,
) -> tuple[Array, list[Array]]:
    """The paper's plain algorithm: ``iterations`` iterates counting the ARX start as the first
    (as ``fit_cascade(paper=True, max_iter=iterations, tol=0)`` does). Returns the last iterate
    and the history."""
    theta = arx_start(u, y, na, nb, degree, initial)
    history = [theta]
    for _ in range(iterations - 1):
        theta = paper_iteration(theta, u, y, na, nb, degree, loop)
        history.append(theta)
    return theta, history


# -- output-error fit with scipy.optimize.least_squares -----------------------------------------


@dataclass
class OutputErrorResult:
    theta: Array
    cost: float  # sum of squared simulation errors
    nfev: int  # simulations, finite-difference ones included
    status: str
    seconds: float


class _Deadline(Exception):
    pass


def fit_output_error(
    u: Array,
    y: Array,
    theta0: Array,
    na: int = 2,
    nb: int = 2,
    degree: int = 3,
    *,
    method: str = "lm",
    max_nfev: int | None = None,
    timeout: float | None = None,
) -> OutputErrorResult:
    """Minimise sum (y - y_sim(theta))^2 with scipy.optimize.least_squares and a 2-point
    finite-difference Jacobian. ``timeout`` (seconds) stops it and returns the best point seen."""
    from scipy.optimize import least_squares

    best = {"cost": np.inf, "theta": np.array(theta0, dtype=np.float64)}
    nfev = 0
    t0 = time.perf_counter()

    def residual(theta: Array) -> Array:
        nonlocal nfev
        nfev += 1
        if timeout is not None and time.perf_counter() - t0 > timeout:
            raise _Deadline
        r = y - simulate(theta, u, na, nb, degree)
        r = np.where(np.isfinite(r), r, 1e10)  # diverged simulations: a huge residual
        cost = float(r @ r)
        if cost < best["cost"]:
            best["cost"], best["theta"] = cost, np.array(theta)
        return r

    try:
        sol = least_squares(residual, theta0, method=method, jac="2-point", max_nfev=max_nfev)
        status = sol.message if sol.success else f"stopped: {sol.message}"
        theta = sol.x
        cost = 2.0 * float(sol.cost)
    except _Deadline:
        status = f"stopped: time limit {timeout:g} s (best point seen kept)"
        theta, cost = best["theta"], best["cost"]
    return OutputErrorResult(theta=theta, cost=cost, nfev=nfev, status=status, seconds=time.perf_counter() - t0)
