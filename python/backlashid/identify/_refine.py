"""Output-error refinement: Levenberg-Marquardt on the free-run simulation error.

Each Jacobian is folded, row block by row block, into the triangular factor R_aug of [J | r]
by the core (streaming QR, no N x p matrix); a damped step then solves the small problem
[R; sqrt(lambda) D] delta = [Q^T r; 0] (faer QR), since ||r - J delta||^2 =
||Q^T r - R delta||^2 + rho^2. The record is the core's compiled ``Problem`` (built once per
record by :func:`problem`): each trial passes theta only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import linalg

from .. import _core
from ..errors import BacklashIdError
from ._structure import Structure


@dataclass(frozen=True)
class OutputErrorFit:
    theta: NDArray[np.float64]
    cost: float  # sum of squared simulation errors after the warm-up
    r_aug: NDArray[np.float64]  # (p+1) x (p+1) factor of [J | r] at theta (or a negligible step before)
    n_residuals: int
    iterations: int  # accepted steps
    converged: bool  # stopped by a tolerance or at a point no damped step improves, not by max_iter

    def unscaled_covariance(self, names: list[str]) -> NDArray[np.float64]:
        """(J^T J)^{-1} = (R^T R)^{-1}."""
        p = len(names)
        return _core.lstsq(self.r_aug[:p, :p], self.r_aug[:p, p], names)[2]


def spectral_radius(den: NDArray[np.float64]) -> float:
    """Largest root modulus of z^n + d_1 z^(n-1) + ... (0 for an empty denominator, inf for a
    non-finite one); the core's companion-matrix roots, as ``LinearBlock.spectral_radius()``."""
    return _core.spectral_radius([float(v) for v in den])


def is_stable(structure: Structure, theta: NDArray[np.float64]) -> bool:
    p = structure.unpack(theta)
    return all(spectral_radius(np.asarray(d)) < 1.0 for d in (p.b, p.s))


def problem(structure: Structure, u: NDArray[np.float64], y: NDArray[np.float64], warmup: int = 0) -> _core.Problem:
    """The core's compiled problem of a structure and a record (u and y checked once); its
    methods take only theta: ``simulate``, ``iteration``, ``oe_factor``, ``gradient``. A
    structure with ``initial_state`` has the record's initial state at the end of theta."""
    s = structure
    return _core.Problem(
        u, y, s.na, s.nb, s.degree, s.nr, s.ns, s.feedthrough, s.output_feedthrough, warmup, s.initial_state
    )


def refine_output_error(
    structure: Structure,
    problem: _core.Problem,
    y: NDArray[np.float64],
    theta0: NDArray[np.float64],
    *,
    max_iter: int = 200,
    se_tol: float = 1e-2,
    xtol: float = 1e-12,
) -> OutputErrorFit:
    """Minimise sum_t (y(t) - y_sim(t, theta))^2 over t >= warmup from theta0 (``problem``
    holds the record and the warm-up; ``y`` is its output, for the residuals of a plain
    simulation); steps that make
    a linear block unstable or overflow the simulation are rejected (the damping grows).

    Stops when a step would move the parameters by less than ``se_tol`` standard errors: the
    Gauss-Newton step delta of the linearised problem has delta^T J^T J delta = ||Q^T r||^2,
    its predicted gain, and divided by the noise variance sigma^2 = cost / (n - p) that is
    the squared length of delta in standard errors. The rule is the same for the predicted
    gain before a step and the actual gain of an accepted step (a kink of the piecewise
    smooth cost can make the two differ); ``xtol`` stops a step that is negligible in
    absolute terms.

    A step of at most one standard error (||R delta|| <= sigma, R folded where it started)
    ends at a point where the Jacobian is that of the start to O(1/sqrt(N)): the end is
    evaluated by one gradient pass (g = J^T r and the cost, no fold, about 0.6 of a fold)
    and the rule tested with that R, Q^T r = R^-T g. Only if a step is still worth taking is
    a factor folded there. The returned ``r_aug`` is [R | Q^T r] at theta with R folded at
    theta or at most one standard error before it (or at the point before a negligible step).
    """
    names = structure.names
    n_par = structure.size
    warmup = problem.warmup
    dof = max(len(y) - warmup - n_par, 1)

    def cost_at(theta: NDArray[np.float64], gradient: bool) -> tuple[float, NDArray[np.float64] | None]:
        """The cost at theta (inf if unusable), and g = J^T r there if ``gradient``."""
        if not is_stable(structure, theta):
            return np.inf, None
        try:
            if gradient:
                g, c = problem.gradient(theta)
            else:
                g, r = None, y[warmup:] - problem.simulate(theta)[warmup:]
                with np.errstate(over="ignore", invalid="ignore"):
                    c = float(r @ r)
        except BacklashIdError:
            return np.inf, None
        return (c, g) if np.isfinite(c) else (np.inf, None)

    theta = np.array(theta0, dtype=np.float64)
    unusable = BacklashIdError("output-error refinement: the start is unstable or diverges")
    if not is_stable(structure, theta):
        raise unusable
    try:  # the factor's pass simulates the start: an overflow is a ModelError
        r_aug, cost = problem.oe_factor(theta)
    except BacklashIdError:
        raise unusable from None
    scale = np.zeros(n_par)
    lam = 1e-3
    steps, converged = 0, False
    for _ in range(max_iter):
        r_mat, qtr = r_aug[:n_par, :n_par], r_aug[:n_par, n_par]
        negligible = se_tol**2 * cost / dof  # a gain of se_tol standard errors, squared
        if float(qtr @ qtr) <= negligible:  # also spares climbing the damping to ~1e12
            converged = True
            break
        scale = np.maximum(scale, np.linalg.norm(r_mat, axis=0))  # Marquardt's D: column norms of J
        d = np.where(scale > 0, scale, 1.0)
        accepted = small = rejected = False
        while lam < 1e12:
            a = np.vstack([r_mat, np.sqrt(lam) * np.diag(d)])
            delta = _core.lstsq(a, np.concatenate([qtr, np.zeros(n_par)]), names)[0]
            r_delta = r_mat @ delta
            near = float(r_delta @ r_delta) <= cost / dof  # within one standard error
            # a near trial is evaluated with its gradient, as it is usually accepted; after a
            # rejection (at a kink they come in runs while the damping climbs) by a simulation
            # only (about 1/5 of a gradient pass), the gradient then following acceptance
            new_cost, g = cost_at(theta + delta, near and not rejected)
            if new_cost < cost:
                small = cost - new_cost <= negligible or np.linalg.norm(delta) <= xtol * (
                    np.linalg.norm(theta) + xtol
                )
                if near and not small and g is None:
                    new_cost, g = cost_at(theta + delta, True)
                theta, accepted, steps = theta + delta, True, steps + 1
                q_near = _kept_factor_qtr(r_mat, g) if near and not small else None
                if small:  # done: keep this point's factor rather than fold another Jacobian
                    cost = new_cost
                elif q_near is not None and float(q_near @ q_near) <= se_tol**2 * new_cost / dof:
                    # done: the rule holds with the factor folded one standard error away
                    cost, small = new_cost, True
                    r_aug = np.vstack([np.column_stack([r_mat, q_near]), np.zeros(n_par + 1)])
                    r_aug[n_par, n_par] = np.sqrt(max(cost - float(q_near @ q_near), 0.0))
                else:
                    r_aug, cost = problem.oe_factor(theta)
                lam = max(lam / 3.0, 1e-12)
                break
            rejected = True
            lam *= 4.0
        if not accepted or small:
            converged = True
            break
    return OutputErrorFit(
        theta=theta, cost=cost, r_aug=r_aug, n_residuals=len(y) - warmup, iterations=steps, converged=converged
    )


def _kept_factor_qtr(r_mat: NDArray[np.float64], g: NDArray[np.float64] | None) -> NDArray[np.float64] | None:
    """Q^T r at a point from its gradient g = J^T r and a factor R folded nearby: R^T q = g
    (None without a gradient or for a singular R)."""
    if g is None or not np.all(np.abs(np.diag(r_mat)) > 0):
        return None
    q = linalg.solve_triangular(r_mat, g, trans="T", check_finite=False)
    return q if np.all(np.isfinite(q)) else None
