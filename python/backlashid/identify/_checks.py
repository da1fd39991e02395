"""Checks of a finished fit that warn (``FitWarning``) instead of failing: branches that cross
or stop increasing on the range of x the data visit, and parameters whose standard error
exceeds their estimate. One place, called once at the end of ``_fit``."""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import BacklashIdError, FitWarning

__all__ = ["warn_if_suspicious"]

# the frames from warnings.warn up to the user's call: here, _fit, fit_cascade / fit_sandwich,
# the option-checking wrapper (_shared_options), then the caller
STACKLEVEL = 5


def _intervals(found: list[tuple[float, float]]) -> str:
    return ", ".join(f"[{a:.4g}, {b:.4g}]" for a, b in found)


def branch_problems(
    model: Any, u: NDArray[np.float64], warmup: int, x_range: tuple[float, float] | None = None, advice: bool = True
) -> str | None:
    """What is wrong with the fitted branches on the x range the record visits (after the
    warm-up), in words, or None when both increase and do not cross there. ``x_range``: that
    range (finite) where the fit has it already, else x is simulated. Without ``advice``: what
    is wrong and the range only."""
    if x_range is not None:
        lo, hi = x_range
    else:
        # x is the first linear block's output alone (a cascade's ``linear``, a sandwich's
        # ``input_linear``): no need to simulate the backlash and the blocks after it; several
        # records: the x range of them all
        first = model.linear if hasattr(model, "linear") else model.input_linear
        records = u if isinstance(u, list) else [u]
        x = np.concatenate([np.asarray(first.simulate(r))[warmup:] for r in records])
        if x.size == 0:
            return None
        lo, hi = float(x.min()), float(x.max())  # both finite: every x is (min and max pass NaN on)
        if not (np.isfinite(lo) and np.isfinite(hi)):
            x = x[np.isfinite(x)]
            if x.size == 0:
                return None
            lo, hi = float(x.min()), float(x.max())
    check = model.backlash.check_branches(lo, hi)
    if check.is_valid:
        return None
    parts = []
    for name, found in (("L", check.left_not_increasing), ("R", check.right_not_increasing)):
        if found:
            parts.append(f"branch {name} does not increase on x in {_intervals(found)}")
    if check.crossed:
        parts.append(f"the branches cross (L(x) <= R(x)) on x in {_intervals(check.crossed)}")
    if not advice:
        return "; ".join(parts) + f" inside the range of x visited [{check.x_min:.4g}, {check.x_max:.4g}]"
    return (
        "; ".join(parts)
        + f", inside the range of x the data visit [{check.x_min:.4g}, {check.x_max:.4g}]: the estimate is no "
        "backlash there (Section 2's assumption fails); try a lower degree, a longer record or a larger input "
        "amplitude, and check the model with GeneralBacklash.check_branches"
    )


SHOWN_PARAMETERS = 6  # parameters named in a warning, the others counted


def uncertain_parameters(names: list[str], theta: NDArray[np.float64], standard_errors: NDArray[np.float64]) -> str | None:
    """The parameters whose standard error exceeds the magnitude of their estimate, in words,
    or None."""
    bad = [f"{n} = {t:.4g} +- {s:.2g}" for n, t, s in zip(names, theta, standard_errors) if s > abs(t)]
    if not bad:
        return None
    shown = ", ".join(bad[:SHOWN_PARAMETERS]) + (f" and {len(bad) - SHOWN_PARAMETERS} more of {len(names)}" if len(bad) > SHOWN_PARAMETERS else "")
    return (
        f"standard error larger than the estimate for {shown}: the data hardly determine "
        f"{'this parameter' if len(bad) == 1 else 'these parameters'}; try a lower degree or lower orders, "
        "a longer record or a richer input"
    )


def warn_if_suspicious(result: Any, u: NDArray[np.float64], x_range: tuple[float, float] | None = None) -> None:
    """Issue a :class:`FitWarning` for each problem of a finished fit (``result``, a
    FitResult, of input ``u``; ``x_range`` the range of x after the warm-up if known),
    naming the function that returned it."""
    if result.model is None:
        return
    fit = "fit_sandwich" if result.structure.is_sandwich else "fit_cascade"
    try:
        branches = branch_problems(result.model, u, result.warmup, x_range)
    except BacklashIdError:  # a model that does not simulate is reported elsewhere
        branches = None
    se = np.sqrt(np.clip(np.diag(result.covariance), 0, None))
    for problem in (branches, uncertain_parameters(result.names, result.theta, se)):
        if problem is not None:
            warnings.warn(f"{fit}: {problem}", FitWarning, stacklevel=STACKLEVEL)
