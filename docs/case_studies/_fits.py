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


def print_candidates(report: bid.DiagnosisReport, nominal: str, scale: float, gap_on: str, rmse_column: str) -> bid.diagnosis.Candidate:
    """Print the diagnosis ``report``'s candidates as a Markdown table below the ``nominal``
    model's row (gap closed ``gap_on`` the validation data, p-value, extra parameters, and the
    validation RMSE in the record's units, model units times ``scale``, headed ``rmse_column``)
    and return the best augmented candidate: the named one, else the first of the ranking that
    simulates the output (not colored_noise, a one-step predictor)."""
    print(f"| candidate | gap closed on {gap_on} | p-value | extra parameters | {rmse_column} |")
    print("|---|---|---|---|---|")
    print(f"| (nominal {nominal}) | | | | {scale * report.nominal_validation_rmse:.3f} |")
    for c in report.ranking:
        if c.effect == "colored_noise":  # a noise model: its one-step prediction, its free run is the nominal's
            print(f"| {c.effect} (one-step prediction) | n/a | {c.p_value:.1e} | {c.n_extra} | {scale * c.prediction_rmse:.3f} |")
            continue
        print(f"| {c.effect} | {100 * c.gap_closed:.0f} % | {c.p_value:.1e} | {c.n_extra} | {scale * c.validation_rmse:.3f} |")
    return report.best or next(c for c in report.ranking if c.effect != "colored_noise")
