"""The fine stage of coarse to fine: output-error LM on the whole record from the optimum of
the coarse segment, with fewer whole-record passes than :func:`levenberg_marquardt` needs.

The segment's optimum lies about sqrt(p N / N_segment) standard errors of the whole record
from the whole record's (43 at N = 1e6, p = 11). LM from there folds the whole record's
Jacobian about three times (each about 1.4 gradient passes). On long records the first step
here instead takes the gradient of the whole record and the factor R of a sub-record (the
first N / SUB_FRACTION samples, folded at the segment's optimum and scaled by
sqrt(N / N_sub), 1/20 of a whole fold): that lands within a few standard errors. The
whole record is folded there once, and the remaining steps, each within NEAR_SE standard
errors of that fold, take a gradient pass each (:func:`refine_from_factor`). Example 1 at
N = 1e6: fold, cost, fold, cost, fold, gradient before; gradient, fold, gradient, gradient now
(docs/performance.md).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numpy.typing import NDArray

from ..errors import BacklashIdError
from ._refine import OutputErrorFit, cost_and_gradient, levenberg_marquardt, refine_from_factor
from ._structure import Structure

# the first step from a sub-record's factor on records at least FROM_SEGMENTS segments long:
# on shorter ones the whole record's fold at the segment's optimum is cheap, and the cost's
# kinks make small local minima about 0.2 standard errors apart, into which a first step from
# another factor may lead (Example 1, 20 seeds at 5e4 and 1e5: 3 of 40 ended 0.02-0.17
# standard errors from the whole-record search's optimum, against at most 0.01 from the fold)
FROM_SEGMENTS = 40
# the sub-record: the first 1 / SUB_FRACTION of the record (Example 1 at N = 1e6: from 43 to
# 1.1-2.6 standard errors in the first step; the whole record's own factor at the segment's
# optimum reaches 0.2-0.4)
SUB_FRACTION = 20
# steps within this many standard errors of the last fold take that fold's factor (the
# covariance's R is folded at most this far from the end: at most 0.4 % in the standard
# errors on Example 1 at N = 2e5 and 1e6)
NEAR_SE = 3.0


def refine_whole(
    structure: Structure,
    whole: object,
    theta: NDArray[np.float64],
    u: NDArray[np.float64],
    y: NDArray[np.float64],
    warmup: int,
    segment: int,
) -> OutputErrorFit:
    """LM on the whole record (``whole``, the compiled problem of u, y) from ``theta``, the
    optimum of the first ``segment`` samples after the warm-up."""
    rows = len(u) - warmup
    if rows < FROM_SEGMENTS * segment:
        return levenberg_marquardt(whole, theta)  # type: ignore[arg-type]
    sub = rows // SUB_FRACTION
    # the whole record's gradient at theta (the first step's) on a second thread while the
    # sub-record is folded: independent passes that release the GIL
    with ThreadPoolExecutor(max_workers=1) as pool:
        at_start = pool.submit(cost_and_gradient, whole, theta)  # type: ignore[arg-type]
        try:
            factor, _ = structure.problem(u[: warmup + sub], y[: warmup + sub], warmup).oe_factor(theta)
        except BacklashIdError:
            factor = None
        start = at_start.result()
    if factor is None:
        return levenberg_marquardt(whole, theta)  # type: ignore[arg-type]
    return refine_from_factor(whole, theta, factor * np.sqrt(rows / sub), near_se=NEAR_SE, start=start)  # type: ignore[arg-type]
