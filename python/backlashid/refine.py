"""Output-error refinement: Levenberg-Marquardt on the free-run simulation error.

The Jacobian comes from the core's sensitivity recursions (exact derivatives of the simulated
output); every damped step is a faer QR solve of [J; sqrt(lambda) D] delta = [r; 0].
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from . import _core
from .errors import BacklashIdError
from .structure import Structure


@dataclass(frozen=True)
class OutputErrorFit:
    theta: NDArray[np.float64]
    cost: float  # sum of squared simulation errors after the warm-up
    residual: NDArray[np.float64]
    jacobian: NDArray[np.float64]
    iterations: int


def spectral_radius(den: NDArray[np.float64]) -> float:
    """Largest root modulus of z^n + d_1 z^(n-1) + ... (0 for an empty denominator)."""
    return float(np.abs(np.roots(np.concatenate([[1.0], den]))).max()) if len(den) else 0.0


def is_stable(structure: Structure, theta: NDArray[np.float64]) -> bool:
    p = structure.unpack(theta)
    dens = [np.asarray(p.b), np.asarray(p.s)]
    return all(spectral_radius(d) < 1.0 for d in dens)


def simulate(structure: Structure, theta: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float64]:
    """Free-run output of an estimate from rest (no shape checks on the branches)."""
    p = structure.unpack(theta)
    return _core.simulate_estimate(*p.chain(), p.r, p.s, u)


def sensitivity(
    structure: Structure, theta: NDArray[np.float64], u: NDArray[np.float64]
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    p = structure.unpack(theta)
    if structure.is_sandwich:
        return _core.sandwich_sensitivity(*p.chain(), p.r, p.s, u)
    return _core.cascade_sensitivity(*p.chain(), u)


def refine_output_error(
    structure: Structure,
    u: NDArray[np.float64],
    y: NDArray[np.float64],
    theta0: NDArray[np.float64],
    *,
    warmup: int = 0,
    max_iter: int = 200,
    ftol: float = 1e-14,
    xtol: float = 1e-12,
) -> OutputErrorFit:
    """Minimise sum_t (y(t) - y_sim(t, theta))^2 over t >= warmup from theta0; steps that make
    a linear block unstable or overflow the simulation are rejected (the damping grows)."""
    names = structure.names

    def residual(theta: NDArray[np.float64]) -> NDArray[np.float64] | None:
        if not is_stable(structure, theta):
            return None
        try:
            r = y[warmup:] - simulate(structure, theta, u)[warmup:]
        except BacklashIdError:
            return None
        return r if np.all(np.isfinite(r)) else None

    def jacobian(theta: NDArray[np.float64]) -> NDArray[np.float64]:
        return sensitivity(structure, theta, u)[1][warmup:]

    theta = np.array(theta0, dtype=np.float64)
    r0 = residual(theta)
    if r0 is None:
        raise BacklashIdError("output-error refinement: the start is unstable or diverges")
    r, jac = r0, jacobian(theta)
    cost = float(r @ r)
    scale = np.zeros(len(theta))
    lam = 1e-3
    it = 0
    for it in range(1, max_iter + 1):
        scale = np.maximum(scale, np.sqrt(np.einsum("ij,ij->j", jac, jac)))  # Marquardt's D
        d = np.where(scale > 0, scale, 1.0)
        accepted = False
        while lam < 1e12:
            a = np.vstack([jac, np.sqrt(lam) * np.diag(d)])
            delta = _core.lstsq(a, np.concatenate([r, np.zeros(len(d))]), names)[0]
            r_trial = residual(theta + delta)
            if r_trial is not None and float(r_trial @ r_trial) < cost:
                new_cost = float(r_trial @ r_trial)
                small_step = np.linalg.norm(delta) <= xtol * (np.linalg.norm(theta) + xtol)
                small_gain = cost - new_cost <= ftol * cost
                theta, r, cost = theta + delta, r_trial, new_cost
                jac = jacobian(theta)
                lam = max(lam / 3.0, 1e-12)
                accepted = True
                break
            lam *= 4.0
        if not accepted or small_step or small_gain:
            break
    return OutputErrorFit(theta=theta, cost=cost, residual=r, jacobian=jac, iterations=it)
