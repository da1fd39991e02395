"""Statistics shared by several analyses of the diagnosis."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["holm", "snap_constant"]


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
