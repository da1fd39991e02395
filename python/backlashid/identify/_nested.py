"""Nested candidates: the input backlash stands in for the sandwich that contains it when the
head of the record cannot tell them apart.

An input backlash (backlash -> linear, x(t) = a_1 u(t-1)) is the sandwich (eq 29-33) whose
input block is that one gain and delay: every input backlash of orders nr, ns and degree n is a
sandwich of the same nr, ns, n with any na >= 1, nb >= 0. Whether the sandwich's extra input
dynamics are needed is then a likelihood-ratio question on the head, where both were fitted to
the same n samples (an output error, white for the right model):

    LR = n_eff log(s_IB^2 / s_S^2)  against  chi^2_{1 - NESTED_LEVEL}(dp)

with s the free-run simulation RMSE on the head, dp the sandwich's extra parameters and
estimated start values, and n_eff = n (1 - rho) / (1 + rho) the head's samples discounted for
the lag-1 correlation rho of the sandwich's error (an AR(1) error's effective sample size; an
error that is one slow drift carries less evidence than n white samples).

Why: on a tail that is a few steps, or the slow wander of a position that integrates, the
validation band ranks the two by chance. On benches/structure_classes.py's position input
backlashes (ninth seeds #5 and #16) the band kept the sandwich alone: its tail was 4-6 % below
the input backlash's, while on the head the two fitted within 0.3 % of each other.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

NESTED_LEVEL = 0.01  # the test's level: the sandwich is kept when LR exceeds chi^2's 0.99 quantile


def lag1_correlation(error: NDArray[np.float64] | None) -> float:
    """The lag-1 autocorrelation of ``error`` (0 for fewer than 3 samples or a constant)."""
    if error is None or len(error) < 3:
        return 0.0
    e = error - float(np.mean(error))
    power = float(e @ e)
    return float(e[1:] @ e[:-1]) / power if power > 0.0 else 0.0


def likelihood_ratio(small_rmse: float, big_rmse: float, n: int, rho: float) -> float:
    """``n_eff log(small_rmse**2 / big_rmse**2)``, n_eff = n (1 - rho) / (1 + rho) with a
    negative rho taken as 0 (an error that alternates is not given more samples)."""
    r = min(max(rho, 0.0), 1.0)
    n_eff = n * (1.0 - r) / (1.0 + r)
    return n_eff * 2.0 * math.log(max(small_rmse, 1e-300) / max(big_rmse, 1e-300))


def critical_value(extra: int) -> float:
    """chi^2's (1 - NESTED_LEVEL) quantile with ``extra`` degrees of freedom (at least 1)."""
    from scipy import stats  # imported when first needed: import backlashid stays fast

    return float(stats.chi2.ppf(1.0 - NESTED_LEVEL, max(int(extra), 1)))


def nested_input_backlash(rows: Sequence[dict[str, Any]], sandwich: int, pool: Sequence[int]) -> int | None:
    """The row of ``pool`` holding the input backlash nested in row ``sandwich`` (same nr, ns
    and degree), or None."""
    s = rows[sandwich]
    for j in pool:
        r = rows[j]
        if r["kind"] == "hammerstein" and (r["nr"], r["ns"], r["degree"]) == (s["nr"], s["ns"], s["degree"]):
            return j
    return None


def with_stand_ins(
    rows: Sequence[dict[str, Any]],
    preferred: Sequence[int],
    ok: Sequence[int],
    n: int,
    correlations: Sequence[float],
    start_sizes: Sequence[int],
    limit: float,
) -> tuple[list[int], str]:
    """``preferred`` with each sandwich replaced by its nested input backlash where the head
    does not need the sandwich's input dynamics, and what was replaced in words ("" for none).

    Parameters
    ----------
    rows : sequence of dict
        The table's rows (kind, nr, ns, degree, parameters, estimation_rmse, validation_rmse,
        valid).
    preferred : sequence of int
        The rows the choice is made among.
    ok : sequence of int
        The rows that did not raise.
    n : int
        The head's samples the estimation RMSE was taken over.
    correlations : sequence of float
        Each row's lag-1 correlation of its simulation error on the head.
    start_sizes : sequence of int
        Each row's number of estimated start values (0 when started from rest).
    limit : float
        The largest validation RMSE a stand-in may have (it stays near the best on the tail).

    Returns
    -------
    list of int, str
        The rows to choose among, and the note.

    Examples
    --------
    >>> rows = [dict(kind="sandwich", nr=2, ns=2, degree=3, parameters=14, estimation_rmse=1.0,
    ...              validation_rmse=1.0, valid=True),
    ...         dict(kind="hammerstein", nr=2, ns=2, degree=3, parameters=11,
    ...              estimation_rmse=1.001, validation_rmse=1.06, valid=True)]
    >>> with_stand_ins(rows, [0], [0, 1], 2780, [0.0, 0.0], [5, 4], 1.25)[0]
    [1]
    """
    chosen: list[int] = []
    notes: list[str] = []
    for i in preferred:
        j = nested_input_backlash(rows, i, ok) if rows[i]["kind"] == "sandwich" else None
        if j is not None and (rows[j]["valid"] or not rows[i]["valid"]) and rows[j]["validation_rmse"] <= limit:
            extra = rows[i]["parameters"] - rows[j]["parameters"] + start_sizes[i] - start_sizes[j]
            lr = likelihood_ratio(rows[j]["estimation_rmse"], rows[i]["estimation_rmse"], n, correlations[i])
            bound = critical_value(extra)
            if lr <= bound:
                notes.append(
                    f"the input backlash of degree {rows[j]['degree']} stands in for the sandwich that contains it: the "
                    f"sandwich's head fit is not significantly better (likelihood ratio {lr:.1f} <= {bound:.1f}, chi^2 of "
                    f"{max(extra, 1)} at {1.0 - NESTED_LEVEL:g}; its error's lag-1 correlation {correlations[i]:.2f})"
                )
                i = j
        if i not in chosen:
            chosen.append(i)
    return chosen, "; ".join(notes)
