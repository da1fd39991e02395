"""Statistics shared by several analyses of the diagnosis."""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._numerics import lstsq

__all__ = ["HAC_LAGS", "holm", "modulation_p", "paired_p", "position_p", "signature_removed", "snap_constant"]

HAC_LAGS = 20  # Newey-West lags of the paired test
POSITION_BINS = 32  # bins of x and of y_nom in the test of a position-dependent residual
SIGNATURE_Z = 3.0  # |z| of the residual against the effect's change after augmentation
Array = NDArray[np.float64]


def snap_constant(e: NDArray[np.float64], *, centre: bool = False) -> NDArray[np.float64]:
    """e, made exactly constant when it varies only by rounding (relative spread < 1e-12), so
    that no analysis reads structure into rounding errors; ``centre`` also removes the mean
    (a constant becomes exactly zero)."""
    scale = float(np.abs(e).max()) if e.size else 0.0
    if float(np.ptp(e)) <= 1e-12 * scale:
        return np.zeros_like(e) if centre else np.full_like(e, e[0])
    return e - e.mean() if centre else e


def holm(p_values: ArrayLike) -> NDArray[np.float64]:
    """Holm's step-down adjustment of a family of p-values (NaN entries are left out)."""
    p = np.asarray(p_values, dtype=np.float64)
    out = np.full_like(p, np.nan)
    ok = np.flatnonzero(np.isfinite(p))
    if ok.size == 0:
        return out
    order = ok[np.argsort(p[ok], kind="stable")]
    m = ok.size
    adjusted = np.minimum(1.0, np.maximum.accumulate(p[order] * (m - np.arange(m))))
    out[order] = adjusted
    return out


def paired_p(r0: Array, r1: Array) -> float:
    """One-sided p-value of E[r0^2 - r1^2] > 0 (Newey-West standard error): does the second
    model's error improve on the first's? Computed in units of the largest error of the first,
    so that the squares cannot overflow (the statistic does not depend on the unit)."""
    scale = float(np.max(np.abs(r0), initial=0.0)) or 1.0
    d = (r0 / scale) ** 2 - (r1 / scale) ** 2
    n = d.size
    dc = d - d.mean()
    var = float(dc @ dc) / n
    for k in range(1, min(HAC_LAGS, n - 1) + 1):
        var += 2.0 * (1.0 - k / (HAC_LAGS + 1)) * float(dc[k:] @ dc[:-k]) / n
    if var <= 0.0:
        return 0.0 if d.mean() > 0 else 1.0
    from scipy import stats  # imported when first needed: import backlashid stays fast

    return float(stats.norm.sf(d.mean() / math.sqrt(var / n)))


def modulation_p(residual: Array, y_nom: Array, phi: Array, order: int = 4) -> float:
    """Is the residual a slowly modulated copy of the model's output (a drifting gain), rather
    than noise independent of the input? F-test of the residual on y_nom(t) P_k(tau), k = 1..order
    (Legendre polynomials over the record), both prewhitened by the AR noise model A(q) so that
    colored noise leaves the test valid (GLS)."""
    n = residual.size
    tau = np.linspace(-1.0, 1.0, n)
    basis = np.polynomial.legendre.legvander(tau, order)[:, 1:]
    z = basis * y_nom[:, None]

    def whiten(s: Array) -> Array:
        out = s.copy()
        for k, c in enumerate(phi, 1):
            out[k:] -= c * s[:-k]
        return out[phi.size :]

    e, zw = whiten(residual), whiten(z)
    zw = np.column_stack([zw, np.ones(e.size)])
    coef = lstsq(zw, e)
    rss1 = float(np.sum((e - zw @ coef) ** 2))
    rss0 = float(np.sum((e - e.mean()) ** 2))
    m, dof = order, e.size - order - 1
    if rss1 <= 0.0 or dof <= 0:
        return 1.0
    from scipy import stats

    return float(stats.f.sf(((rss0 - rss1) / m) / (rss1 / dof), m, dof))


def _position_bins(x: Array, y_nom: Array, edges: tuple[Array, Array]) -> Array:
    """Indicators of the bins of x and of y_nom (the first bin of each is the base), and ones."""
    cols = [np.ones(x.size)]
    for s, e in zip((x, y_nom), edges):
        idx = np.searchsorted(e, s, side="right")
        cols.append((idx[:, None] == np.arange(1, e.size + 1)[None, :]).astype(float))
    return np.column_stack(cols)


def position_p(x_e: Array, ynom_e: Array, r_e: Array, x_v: Array, ynom_v: Array, r_v: Array, bins: int = POSITION_BINS) -> float:
    """Is the residual a function of where the drive is, rather than noise? The nominal
    residual's mean in each quantile bin of x(t) and of y_nom(t) (a cogging torque, a
    position-dependent load: periodic or irregular in the position, so bins and not a
    polynomial), fitted on the estimation records, must predict the validation residual
    (paired test of the squared errors): cross-validated, so slow colored noise, whose bin means
    on one record say nothing of the next, leaves the test valid."""
    q = np.linspace(0.0, 1.0, bins + 1)[1:-1]
    edges = (np.quantile(x_e, q), np.quantile(ynom_e, q))
    coef = lstsq(_position_bins(x_e, ynom_e, edges), r_e)
    return paired_p(r_v, r_v - _position_bins(x_v, ynom_v, edges) @ coef)


def signature_removed(residual: Array, change: Array) -> bool:
    """The candidate's residual no longer correlates with the change the effect makes."""
    nc = float(np.linalg.norm(change))
    nr = float(np.linalg.norm(residual))
    if nc == 0.0 or nr == 0.0:
        return True
    z = float(residual @ change) / (nr * nc) * math.sqrt(residual.size)
    return abs(z) < SIGNATURE_Z
