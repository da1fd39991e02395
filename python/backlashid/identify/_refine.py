"""Output-error refinement: Levenberg-Marquardt on the free-run simulation error.

Each Jacobian is folded, row block by row block, into the triangular factor R_aug of [J | r]
by the core (streaming QR, no N x p matrix); a damped step then solves the small problem
[R; sqrt(lambda) D] delta = [Q^T r; 0] (faer QR), since ||r - J delta||^2 =
||Q^T r - R delta||^2 + rho^2. The record is the core's compiled ``Problem`` (built once per
record by :func:`problem`): each trial passes theta only.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import math
import time
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import _core
from ..errors import BacklashIdError, DataError


@dataclass
class _Budget:
    """A time budget: its deadline (``time.monotonic()``), its length, and whether a search
    was cut short by it."""

    deadline: float
    seconds: float
    hit: bool = False


_BUDGET: contextvars.ContextVar[_Budget | None] = contextvars.ContextVar("backlashid_time_budget", default=None)


@contextlib.contextmanager
def time_budget(seconds: float | None, name: str = "time_budget") -> Iterator[_Budget | None]:
    """The searches run inside end early (between their iterations) once ``seconds`` have
    passed; None adds no budget. Nested, the earlier deadline holds. Yields the budget in
    force (None without one), whose ``hit`` says whether a search was cut short."""
    outer = _BUDGET.get()
    if seconds is None:
        yield outer
        return
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not (math.isfinite(seconds) and seconds > 0):
        raise DataError(f"{name} = {seconds!r}: give a number of seconds > 0, or None for no limit")
    deadline = time.monotonic() + float(seconds)
    if outer is not None and outer.deadline <= deadline:
        yield outer
        return
    budget = _Budget(deadline, float(seconds))
    token = _BUDGET.set(budget)
    try:
        yield budget
    finally:
        _BUDGET.reset(token)


def budget_hit() -> bool:
    """Whether a search was cut short by the time budget in force (False without one)."""
    budget = _BUDGET.get()
    return budget is not None and budget.hit


def out_of_time() -> bool:
    """Whether the time budget in force (``time_budget``) has run out (and if so, marks it
    hit); False without one."""
    budget = _BUDGET.get()
    if budget is None or time.monotonic() < budget.deadline:
        return False
    budget.hit = True
    return True


@dataclass(frozen=True)
class OutputErrorFit:
    """The end of a :func:`levenberg_marquardt` search.

    Attributes
    ----------
    theta : ndarray
        The parameters, in the problem's layout.
    cost : float
        The sum of squared simulation errors after the warm-up at ``theta``.
    r_aug : ndarray
        The (p+1) x (p+1) triangular factor [R | Q^T r] of [J | r] at ``theta`` (R folded at
        ``theta`` or at most one standard error before it).
    n_residuals : int
        The residuals of the cost (samples after the warm-up).
    iterations : int
        Accepted steps.
    converged : bool
        Stopped by a tolerance or at a point no damped step improves, not by ``max_iter``.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> from backlashid.identify import Structure, levenberg_marquardt
    >>> d = bid.example_data(bid.example1(), 400, seed=1)
    >>> s = Structure(2, 2, 3)
    >>> fit = levenberg_marquardt(s.problem(d.u, d.noisy), s.pack(bid.example1()))
    >>> fit.unscaled_covariance(s.names).shape
    (11, 11)
    """

    theta: NDArray[np.float64]
    cost: float
    r_aug: NDArray[np.float64]
    n_residuals: int
    iterations: int
    converged: bool

    def unscaled_covariance(self, names: list[str]) -> NDArray[np.float64]:
        """(J^T J)^{-1} = (R^T R)^{-1} at the end.

        Parameters
        ----------
        names : list of str
            The parameter names (one per column of R).

        Returns
        -------
        ndarray
            The p x p unscaled covariance; times cost / (n - p) it is the covariance.

        Raises
        ------
        NotIdentifiableError
            If R is singular.
        """
        p = len(names)
        return _core.lstsq(self.r_aug[:p, :p], self.r_aug[:p, p], names)[2]


def spectral_radius(den: NDArray[np.float64]) -> float:
    """Largest root modulus of z^n + d_1 z^(n-1) + ... (0 for an empty denominator, inf for a
    non-finite one); the core's companion-matrix roots, as ``LinearBlock.spectral_radius()``."""
    return _core.spectral_radius([float(v) for v in den])


class CompiledProblem(Protocol):
    """What :func:`levenberg_marquardt` needs of a compiled problem.

    Every problem of the Rust core has it: the cascade/sandwich ``_core.Problem``, the
    diagnosis's augmented cascade, the Wiener-Hammerstein problem. theta's layout and names
    are the problem's own; the record is checked once when the problem is built.

    Attributes
    ----------
    names : list of str
        The parameter names, in theta's order.
    samples : int
        The record's length.
    warmup : int
        Samples left out of the cost at the start.

    Examples
    --------
    >>> import backlashid as bid
    >>> from backlashid.identify import Structure
    >>> d = bid.example_data(bid.example1(), 200, seed=1)
    >>> prob = Structure(2, 2, 3).problem(d.u, d.noisy)
    >>> prob.bounds()[0][:5]
    [-inf, -inf, -inf, -inf, 0.0]
    """

    @property
    def names(self) -> list[str]: ...
    @property
    def samples(self) -> int: ...
    @property
    def warmup(self) -> int: ...
    def cost(self, theta: NDArray[np.float64]) -> float: ...
    def oe_factor(self, theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]: ...
    def gradient(self, theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]: ...
    def feasible(self, theta: NDArray[np.float64]) -> bool: ...
    def bounds(self) -> tuple[list[float], list[float]]: ...


def levenberg_marquardt(
    problem: CompiledProblem,
    theta0: ArrayLike,
    *,
    lower: ArrayLike | None = None,
    upper: ArrayLike | None = None,
    max_iter: int = 200,
    se_tol: float = 1e-2,
    xtol: float = 1e-12,
    linear: ArrayLike | None = None,
    time_budget: float | None = None,
) -> OutputErrorFit:
    """The package's one Levenberg-Marquardt search: minimise the output-error cost
    sum_t (y(t) - y_sim(t, theta))^2 over t >= warmup of a compiled problem from theta0,
    within the box [lower, upper] (default: the problem's ``bounds()``, e.g. dead-band widths
    >= 0). Steps that leave the problem's stability guard (``feasible``) or overflow the
    simulation are rejected (the damping grows).

    Bounds: a parameter at a bound whose descent direction points out of the box is held for
    the step (its column left out of the damped problem); the others' step is projected onto
    the box. The start is projected onto the box too.

    Stops when a step would move the parameters by less than ``se_tol`` standard errors: the
    Gauss-Newton step delta of the linearised problem (over the parameters not held) has
    delta^T J^T J delta = ||P Q^T r||^2, its predicted gain, and divided by the noise variance
    sigma^2 = cost / (n - p) that is the squared length of delta in standard errors. The rule
    is the same for the predicted gain before a step and the actual gain of an accepted step
    (a kink of the piecewise smooth cost can make the two differ); ``xtol`` stops a step that
    is negligible in absolute terms.

    A step of at most one standard error (||R delta|| <= sigma, R folded where it started)
    ends at a point where the Jacobian is that of the start to O(1/sqrt(N)): the end is
    evaluated by one gradient pass (g = J^T r and the cost, no fold, about 0.6 of a fold)
    and the rule tested with that R, Q^T r = R^-T g. Only if a step is still worth taking is
    a factor folded there. The returned ``r_aug`` is [R | Q^T r] at theta with R folded at
    theta or at most one standard error before it (or at the point before a negligible step).

    Variable projection (``linear``): when the simulated output is affine in some parameters
    c for any fixed value of the others n (e.g. the coefficients of a static polynomial
    between two fixed linear blocks, and an output offset), the search runs over n alone,
    each n with its optimal c*(n) (Golub-Pereyra; Kaufman's step). From the factor of
    [J | r] at (c, n), its columns permuted to [c | n | r] and re-triangularised (a small QR:
    R^T R is unchanged), [[R11, R12, q1], [0, R22, q2], [0, 0, rho]]: c* = c + R11^-1 q1 is
    exact (r is affine in c), the cost at (c*, n) is ||q2||^2 + rho^2, and the damped step of
    n solves [R22; sqrt(lambda) D] delta_n = [q2; 0] with c following the linearised optimum
    (delta_c = -R11^-1 R12 delta_n from c*). Every trial is evaluated by one factor there
    (giving its own c* and cost); the stability guard, the box (over n; the linear parameters
    must be free) and the stopping rule (over n, the Gauss-Newton gain ||q2||^2 of the
    projected problem) are the same. The factor of a trial is folded at the linearised c,
    within a second-order distance of its c*, where the next step is computed. The valley
    along which c and n trade off is walked in one step rather than crept along. Far from
    c* (e.g. early, when a step moves f's coefficients a lot) that factor's R22 can point
    the wrong way at any damping: a trial rejected from a factor not folded at c* (up to a
    negligible change of the cost) therefore makes the search fold at c* before the damping
    grows.

    Parameters
    ----------
    problem : CompiledProblem
        The compiled problem: record, structure and warm-up.
    theta0 : array_like
        The start, in the problem's layout.
    lower, upper : array_like, optional
        The box, one bound per parameter (+-inf for none); default the problem's ``bounds()``.
    max_iter : int, default 200
        Most accepted-or-not outer iterations.
    se_tol : float, default 0.01
        Stop when a step would move theta by less than this many standard errors.
    xtol : float, default 1e-12
        Stop at a step shorter than this relative to ``theta``.
    linear : array_like of int, optional
        Indices of parameters the output is affine in jointly (for any fixed value of the
        others): search by variable projection over the others. Their bounds must be
        infinite. The returned ``r_aug`` is then [R | Q^T r] at ``theta`` with R folded at the
        last trial's linearised c (Q^T r exact at ``theta``).
    time_budget : float, optional
        Seconds the search may take: checked between its trials (each one pass over the
        record), it then ends like ``max_iter`` does, at the best point so far with
        ``converged`` False. None (the default): no limit, as the time grows with the
        record; a budget set by the caller (``fit_cascade(..., time_budget=)``) holds too.

    Returns
    -------
    OutputErrorFit
        The end point, its cost and factor.

    Raises
    ------
    BacklashIdError
        If the start is unstable or its simulation diverges.
    DataError
        If the bounds do not fit the problem, or ``linear`` names an index twice, out of
        range, or bounded.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> from backlashid.identify import Structure, levenberg_marquardt
    >>> d = bid.example_data(bid.example1(), 2000, seed=3)
    >>> s = Structure(2, 2, 3)
    >>> truth = s.pack(bid.example1())
    >>> fit = levenberg_marquardt(s.problem(d.u, d.noisy), truth + 0.02)
    >>> bool(fit.converged and np.max(np.abs(fit.theta - truth)) < 0.05)
    True
    """
    with _time_budget(time_budget):
        return _search(problem, theta0, lower, upper, max_iter, se_tol, xtol, linear)


_time_budget = time_budget  # the name levenberg_marquardt's argument hides


def _search(
    problem: CompiledProblem,
    theta0: ArrayLike,
    lower: ArrayLike | None,
    upper: ArrayLike | None,
    max_iter: int,
    se_tol: float,
    xtol: float,
    linear: ArrayLike | None,
) -> OutputErrorFit:
    """:func:`levenberg_marquardt` within its time budget."""
    names = list(problem.names)
    n_par = len(names)
    n_res = problem.samples - problem.warmup
    dof = max(n_res - n_par, 1)
    box = problem.bounds()
    lo = np.asarray(box[0] if lower is None else lower, dtype=np.float64)
    hi = np.asarray(box[1] if upper is None else upper, dtype=np.float64)
    if lo.shape != (n_par,) or hi.shape != (n_par,) or np.any(lo > hi) or np.any(np.isnan(lo) | np.isnan(hi)):
        raise DataError(f"lower and upper: give one bound per parameter ({n_par} of them) with lower <= upper and no NaN")

    theta = np.clip(np.array(theta0, dtype=np.float64), lo, hi)
    unusable = BacklashIdError("output-error refinement: the start is unstable or diverges")
    if linear is not None:
        lin = np.asarray(linear, dtype=np.int64).reshape(-1)
        if (
            lin.size != np.unique(lin).size
            or np.any((lin < 0) | (lin >= n_par))
            or not (np.isneginf(lo[lin]).all() and np.isposinf(hi[lin]).all())
        ):
            raise DataError("linear: give distinct indices of parameters without bounds")
        if lin.size:
            mask = np.zeros(n_par, dtype=bool)
            mask[lin] = True
            return _projected(problem, theta, mask, lo, hi, max_iter, se_tol, xtol, names, dof, unusable)
    try:  # the factor's pass simulates the start: an overflow is a ModelError
        if not problem.feasible(theta):
            raise unusable
        r_aug, cost = problem.oe_factor(theta)
    except BacklashIdError:
        raise unusable from None
    return _descend(problem, theta, r_aug, cost, lo, hi, max_iter, se_tol, xtol, names, dof)


def _descend(
    problem: CompiledProblem,
    theta: NDArray[np.float64],
    r_aug: NDArray[np.float64],
    cost: float,
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    max_iter: int,
    se_tol: float,
    xtol: float,
    names: list[str],
    dof: int,
    near_se: float = 1.0,
    stale: bool = False,
) -> OutputErrorFit:
    """The damped steps of :func:`levenberg_marquardt` (its docstring) from theta, where the
    factor ``r_aug`` of [J | r] was folded and the cost is ``cost``. A trial within ``near_se``
    standard errors of where the factor was folded is evaluated by a gradient pass and the
    stopping rule tested there with that factor (one standard error in the public search);
    with ``stale``, a further step from there is also taken with that factor (Q^T r from the
    gradient) instead of folding again (:func:`refine_from_factor`)."""
    n_par = len(names)
    n_res = problem.samples - problem.warmup

    scale = np.zeros(n_par)
    lam = 1e-3
    anchor = theta  # where r_aug's R was folded
    steps, converged = 0, False
    for _ in range(max_iter):
        r_mat, qtr = r_aug[:n_par, :n_par], r_aug[:n_par, n_par]
        free = _free(theta, r_mat.T @ qtr, lo, hi)
        negligible = se_tol**2 * cost / dof  # a gain of se_tol standard errors, squared
        if _gain(r_mat, qtr, free, names) <= negligible:  # also spares climbing the damping to ~1e12
            converged = True
            break
        if out_of_time():  # the time budget: the best point so far, not converged
            break
        scale = np.maximum(scale, np.linalg.norm(r_mat, axis=0))  # Marquardt's D: column norms of J
        d = np.where(scale > 0, scale, 1.0)[free]
        free_names = [k for k, f in zip(names, free) if f]
        accepted = small = rejected = expired = False
        while lam < 1e12:
            if rejected and out_of_time():
                expired = True
                break
            a = np.vstack([r_mat[:, free], np.sqrt(lam) * np.diag(d)])
            delta = np.zeros(n_par)
            delta[free] = _core.lstsq(a, np.concatenate([qtr, np.zeros(d.size)]), free_names)[0]
            delta = np.clip(theta + delta, lo, hi) - theta  # projected onto the box
            r_delta = r_mat @ (theta + delta - anchor)
            near = float(r_delta @ r_delta) <= near_se**2 * cost / dof  # within near_se standard errors
            # a near trial is evaluated with its gradient, as it is usually accepted; after a
            # rejection (at a kink they come in runs while the damping climbs) by a simulation
            # only (about 1/5 of a gradient pass), the gradient then following acceptance
            new_cost, g = _cost_at(problem, theta + delta, near and not rejected)
            if new_cost < cost:
                small = cost - new_cost <= negligible or np.linalg.norm(delta) <= xtol * (
                    np.linalg.norm(theta) + xtol
                )
                if near and not small and g is None:
                    new_cost, g = _cost_at(problem, theta + delta, True)
                theta, accepted, steps = theta + delta, True, steps + 1
                q_near = _kept_factor_qtr(r_mat, g) if near and not small else None
                if small:  # done: keep this point's factor rather than fold another Jacobian
                    cost = new_cost
                elif q_near is not None and _gain(r_mat, q_near, _free(theta, g, lo, hi), names) <= se_tol**2 * new_cost / dof:
                    # done: the rule holds with the factor folded one standard error away
                    cost, small = new_cost, True
                    r_aug = np.vstack([np.column_stack([r_mat, q_near]), np.zeros(n_par + 1)])
                    r_aug[n_par, n_par] = np.sqrt(max(cost - float(q_near @ q_near), 0.0))
                elif stale and q_near is not None:
                    # the next step from the factor folded within near_se standard errors
                    cost = new_cost
                    r_aug = np.vstack([np.column_stack([r_mat, q_near]), np.zeros(n_par + 1)])
                    r_aug[n_par, n_par] = np.sqrt(max(cost - float(q_near @ q_near), 0.0))
                else:
                    r_aug, cost = problem.oe_factor(theta)
                    anchor = theta
                lam = max(lam / 3.0, 1e-12)
                break
            rejected = True
            lam *= 4.0
        if expired:
            break
        if not accepted and anchor is not theta:
            # no damped step from a factor folded elsewhere: fold here and try again
            r_aug, cost = problem.oe_factor(theta)
            anchor, lam = theta, 1e-3
            continue
        if not accepted or small:
            converged = True
            break
    return OutputErrorFit(theta=theta, cost=cost, r_aug=r_aug, n_residuals=n_res, iterations=steps, converged=converged)


def cost_and_gradient(problem: CompiledProblem, theta: NDArray[np.float64]) -> tuple[float, NDArray[np.float64] | None]:
    """The cost at theta (projected onto the problem's bounds) and g = J^T r there ((inf,
    None) if unusable), as the first step of :func:`refine_from_factor` evaluates them (its
    ``start``)."""
    lo, hi = (np.asarray(b, dtype=np.float64) for b in problem.bounds())
    return _cost_at(problem, np.clip(np.array(theta, dtype=np.float64), lo, hi), True)


def _cost_at(problem: CompiledProblem, theta: NDArray[np.float64], gradient: bool) -> tuple[float, NDArray[np.float64] | None]:
    """The cost at theta (inf if unusable: unstable or diverging), and g = J^T r there if
    ``gradient``."""
    try:
        if not problem.feasible(theta):
            return np.inf, None
        if gradient:
            g, c = problem.gradient(theta)
        else:
            g, c = None, problem.cost(theta)
    except BacklashIdError:
        return np.inf, None
    return (c, g) if np.isfinite(c) else (np.inf, None)


@dataclass(frozen=True)
class _Projected:
    """A point of the variable-projection search: theta with its linear part at c*, the
    cost there, the factor (original column order) with Q^T r at theta, and the blocks of the
    permuted factor [[R11, R12, q1], [0, R22, q2], [0, 0, rho]] (q1 = 0 at c*)."""

    theta: NDArray[np.float64]
    cost: float
    r_aug: NDArray[np.float64]
    r11: NDArray[np.float64]
    r12: NDArray[np.float64]
    r22: NDArray[np.float64]
    q2: NDArray[np.float64]
    refolded: bool = False


def _project(
    problem: CompiledProblem, theta: NDArray[np.float64], lin: NDArray[np.bool_], refolded: bool = False, tol: float = 0.0
) -> _Projected | None:
    """One factor at theta, the linear parameters moved to their exact optimum c* (None if
    theta is infeasible, diverges, or R11 is singular). The factor counts as folded at c*
    (``refolded``) also when moving c to c* lowers the cost by no more than ``tol`` times the
    cost (c was at its optimum up to a negligible change)."""
    try:
        if not problem.feasible(theta):
            return None
        r_aug, cost = problem.oe_factor(theta)
    except BacklashIdError:
        return None
    if not (np.isfinite(cost) and np.all(np.isfinite(r_aug))):
        return None
    p, nl = theta.size, int(lin.sum())
    r_mat, qtr = r_aug[:p, :p], r_aug[:p, p]
    order = np.r_[np.flatnonzero(lin), np.flatnonzero(~lin)]
    rp = np.linalg.qr(np.column_stack([r_aug[:, order], r_aug[:, p]]), mode="r")  # [c | n | r], R^T R kept
    r11 = rp[:nl, :nl]
    if not np.all(np.abs(np.diag(r11)) > 1e-12 * np.linalg.norm(r11, axis=0)):  # each column's own scale
        return None
    from scipy import linalg  # imported when first needed: import backlashid stays fast

    dc = linalg.solve_triangular(r11, rp[:nl, p], check_finite=False)
    out = theta.copy()
    out[lin] += dc
    qtr_star = qtr - r_mat[:, lin] @ dc
    cost_star = float(rp[nl:, p] @ rp[nl:, p])  # ||q2||^2 + rho^2
    kept = np.vstack([np.column_stack([r_mat, qtr_star]), np.zeros(p + 1)])
    kept[p, p] = abs(float(rp[p, p]))
    refolded = refolded or cost - cost_star <= tol * cost_star
    return _Projected(out, cost_star, kept, r11, rp[:nl, nl:p], rp[nl:p, nl:p], rp[nl:p, p], refolded)


def _projected(
    problem: CompiledProblem,
    theta: NDArray[np.float64],
    lin: NDArray[np.bool_],
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
    max_iter: int,
    se_tol: float,
    xtol: float,
    names: list[str],
    dof: int,
    unusable: BacklashIdError,
) -> OutputErrorFit:
    """:func:`levenberg_marquardt` by variable projection over the parameters not in ``lin``
    (its docstring); the same damping, stability guard, box and stopping rule."""
    from scipy import linalg

    nonlin = ~lin
    n_names = [k for k, f in zip(names, nonlin) if f]
    lo_n, hi_n = lo[nonlin], hi[nonlin]
    tol = se_tol**2 / dof  # a change of the cost by se_tol standard errors, relative to the cost
    point = _project(problem, theta, lin, tol=tol)
    if point is None:
        raise unusable
    # the Jacobian of n depends on c (e.g. through f'(x)): the start's c may be far from c*
    if not point.refolded:
        point = _project(problem, point.theta, lin, refolded=True) or point
    scale = np.zeros(int(nonlin.sum()))
    lam = 1e-3
    steps, converged = 0, False
    for _ in range(max_iter):
        r22, q2 = point.r22, point.q2
        theta_n = point.theta[nonlin]
        free = _free(theta_n, r22.T @ q2, lo_n, hi_n)
        negligible = se_tol**2 * point.cost / dof
        if _gain(r22, q2, free, n_names) <= negligible:
            converged = True
            break
        if out_of_time():  # the time budget: the best point so far, not converged
            break
        scale = np.maximum(scale, np.linalg.norm(r22, axis=0))  # Marquardt's D of the projected J
        d = np.where(scale > 0, scale, 1.0)[free]
        free_names = [k for k, f in zip(n_names, free) if f]
        accepted = small = expired = tried = False
        while lam < 1e12:
            if tried and out_of_time():
                expired = True
                break
            tried = True
            a = np.vstack([r22[:, free], np.sqrt(lam) * np.diag(d)])
            delta = np.zeros(theta_n.size)
            delta[free] = _core.lstsq(a, np.concatenate([q2, np.zeros(d.size)]), free_names)[0]
            delta = np.clip(theta_n + delta, lo_n, hi_n) - theta_n  # projected onto the box
            trial = point.theta.copy()
            trial[nonlin] += delta
            trial[lin] -= linalg.solve_triangular(point.r11, point.r12 @ delta, check_finite=False)
            new = _project(problem, trial, lin, tol=tol) if np.all(np.isfinite(trial)) else None
            if new is not None and new.cost < point.cost:
                small = point.cost - new.cost <= negligible or np.linalg.norm(delta) <= xtol * (
                    np.linalg.norm(theta_n) + xtol
                )
                point, accepted, steps = new, True, steps + 1
                lam = max(lam / 3.0, 1e-12)
                break
            if not point.refolded:
                # the factor was folded at the trial's linearised c, not at its c*: its R22 and
                # hence the step's direction can be wrong at any damping (on the SYSID 2009
                # record such a climb to lam = 1e12 took 25 folds), so fold at c* at once
                break
            lam *= 4.0
        if expired:
            break
        if not accepted and not point.refolded:  # no step from a factor folded off c*: fold at c*
            point = _project(problem, point.theta, lin, refolded=True) or dataclasses.replace(point, refolded=True)
            continue
        if not accepted or small:
            converged = True
            break
    return OutputErrorFit(
        theta=point.theta, cost=point.cost, r_aug=point.r_aug, n_residuals=problem.samples - problem.warmup,
        iterations=steps, converged=converged,
    )


def _free(theta: NDArray[np.float64], g: NDArray[np.float64] | None, lo: NDArray[np.float64], hi: NDArray[np.float64]) -> NDArray[np.bool_]:
    """The parameters a step may move: all but those at a bound whose descent direction
    g = J^T r points out of the box."""
    if g is None:
        return np.ones(theta.size, dtype=bool)
    return ~(((theta <= lo) & (g <= 0.0)) | ((theta >= hi) & (g >= 0.0)))


def _gain(r_mat: NDArray[np.float64], qtr: NDArray[np.float64], free: NDArray[np.bool_], names: list[str]) -> float:
    """The predicted gain of the Gauss-Newton step over the free parameters: ||Q^T r||^2 with
    all free, else ||R_F delta_F||^2 of the least-squares step in the free columns. Infinite
    where it overflows (the residuals of a diverging simulation, or a huge step in nearly
    dependent free columns): no reason to stop."""
    with np.errstate(over="ignore", invalid="ignore"):
        if free.all():
            gain = float(qtr @ qtr)
        else:
            free = free & np.any(r_mat != 0.0, axis=0)  # a zero column (a state the data never excite) gains nothing
            if not free.any():
                return 0.0
            delta = _core.lstsq(r_mat[:, free], qtr, [k for k, f in zip(names, free) if f])[0]
            step = r_mat[:, free] @ delta
            gain = float(step @ step)
    return gain if np.isfinite(gain) else math.inf


def _kept_factor_qtr(r_mat: NDArray[np.float64], g: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
    """Q^T r at a point from its gradient g = J^T r and a factor R folded nearby: R^T q = g
    (None without a gradient or for a singular R)."""
    if g is None or not np.all(np.abs(np.diag(r_mat)) > 0):
        return None
    from scipy import linalg

    q = linalg.solve_triangular(r_mat, g, trans="T", check_finite=False)
    return q if np.all(np.isfinite(q)) else None



def refine_from_factor(
    problem: CompiledProblem,
    theta0: ArrayLike,
    factor: NDArray[np.float64],
    *,
    max_iter: int = 200,
    se_tol: float = 1e-2,
    xtol: float = 1e-12,
    near_se: float = 1.0,
    start: tuple[float, NDArray[np.float64] | None] | None = None,
) -> OutputErrorFit:
    """:func:`levenberg_marquardt` from theta0 with ``factor``, an approximation of the R of
    [J | r] there (e.g. a sub-record's, scaled), in place of the first fold.

    The first step is the Gauss-Newton step of R from the gradient pass at theta0
    (Q^T r = R^-T g), over the parameters not held at a bound and projected onto the box; its
    end is folded. If that step does not lower the cost (or the factor is singular), the
    plain :func:`levenberg_marquardt` runs from theta0 instead. The search then goes on as
    :func:`levenberg_marquardt` does, except that a step ending within ``near_se`` standard
    errors of where the factor was folded is evaluated by a gradient pass only and, if
    another step is worth taking, taken from that factor again (its Q^T r from the gradient)
    rather than from a new fold: over a few standard errors the Jacobian changes by
    O(1/sqrt(N)), and a step costs one gradient pass instead of a fold and a gradient pass.
    The problem's own bounds apply; the returned ``r_aug`` is the factor folded within
    ``near_se`` standard errors of ``theta``, with Q^T r at ``theta``. ``start``: the cost
    and gradient at theta0 if already evaluated (:func:`cost_and_gradient`), else one
    gradient pass here.
    """
    names = list(problem.names)
    n_par = len(names)
    dof = max(problem.samples - problem.warmup - n_par, 1)
    lo, hi = (np.asarray(b, dtype=np.float64) for b in problem.bounds())
    theta = np.clip(np.array(theta0, dtype=np.float64), lo, hi)
    plain = lambda: levenberg_marquardt(problem, theta, max_iter=max_iter, se_tol=se_tol, xtol=xtol)  # noqa: E731
    cost, g = _cost_at(problem, theta, True) if start is None else start
    r_mat = np.asarray(factor, dtype=np.float64)[:n_par, :n_par]
    q = _kept_factor_qtr(r_mat, g)
    if q is None:
        return plain()
    free = _free(theta, g, lo, hi)
    delta = np.zeros(n_par)
    if free.any():  # damped as the first step of levenberg_marquardt
        d = np.linalg.norm(r_mat, axis=0)[free]
        a = np.vstack([r_mat[:, free], np.sqrt(1e-3) * np.diag(np.where(d > 0, d, 1.0))])
        delta[free] = _core.lstsq(a, np.concatenate([q, np.zeros(d.size)]), [k for k, f in zip(names, free) if f])[0]
    trial = np.clip(theta + delta, lo, hi)
    try:
        if not problem.feasible(trial):
            return plain()
        r_aug, new_cost = problem.oe_factor(trial)
    except BacklashIdError:
        return plain()
    if not new_cost < cost:
        return plain()
    fit = _descend(problem, trial, r_aug, new_cost, lo, hi, max_iter - 1, se_tol, xtol, names, dof, near_se, stale=True)
    return dataclasses.replace(fit, iterations=fit.iterations + 1)
