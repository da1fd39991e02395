"""What the case-study scripts share: one structure fitted as a user would, with its validity."""

from __future__ import annotations

import warnings

import numpy as np

import backlashid as bid


def fit_structure(kind: str, u: np.ndarray | list[np.ndarray], y: np.ndarray | list[np.ndarray], kw: dict[str, int], warmup: int) -> tuple[bid.FitResult, bool]:
    """The fit of a "cascade", "sandwich" or (otherwise) input-backlash structure from an
    estimated initial state, and whether it is a valid backlash (no FitWarning about its
    branches)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if kind == "cascade":
            result = bid.fit_cascade(u, y, initial_state="estimate", warmup=warmup, **kw)
        elif kind == "sandwich":
            result = bid.fit_sandwich(u, y, initial_state="estimate", warmup=warmup, **kw)
        else:
            result = bid.fit_hammerstein_backlash(u, y, initial_state="estimate", warmup=warmup, **kw)
    return result, not any("branches" in str(w.message) for w in caught)
