"""saturation on a drive whose output is a position: the velocity command clipped.

On an integrating plant each clipped sample moves the position for good, so the refit needs
starts that clip a few tenths of a percent of the samples, and a clipping level the estimation
record does not establish (at its range's end) must not clip a validation record that goes
further. The records come from a generator of their own: the velocity drive and the position's
integrator by scipy's lfilter, a symmetric linear play by a per-sample loop."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy import signal

import backlashid as bid

N_EST, N_VAL, PRE = 3000, 3000, 300
WIDTH, NOISE, TAU = 0.2, 0.02, 5.0


def _play(x: np.ndarray) -> np.ndarray:
    y, prev = np.empty_like(x), 0.0
    for t, xt in enumerate(x.tolist()):
        prev = min(max(prev, xt - WIDTH), xt + WIDTH)  # the play: the load moves when the motor pushes it
        y[t] = prev
    return y


def _record(u: np.ndarray, clip: float, seed: int) -> np.ndarray:
    """Velocity command clipped to +-clip -> motor velocity (first order, TAU samples) ->
    position (an integrator) -> play -> y + noise; the record starts PRE samples into the run."""
    p = np.exp(-1.0 / TAU)
    x = signal.lfilter([0.0, 0.0, 1.0 - p], np.polymul([1.0, -1.0], [1.0, -p]), np.clip(u, -clip, clip))
    y = _play(0.5 * x)
    return y[PRE:] + NOISE * np.random.default_rng(seed).standard_normal(y.size - PRE)


def _diagnose(u: np.ndarray, y: np.ndarray) -> bid.DiagnosisReport:
    est, val = (u[:N_EST], y[:N_EST]), (u[N_EST:], y[N_EST:])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = bid.fit_cascade(*est, 2, 2, degree=1, initial_state="estimate", warmup=20).model
        return bid.diagnose(model, est, val, candidates=["saturation"])


@pytest.mark.parametrize(
    "seed",
    [
        pytest.param(
            2,
            marks=pytest.mark.xfail(
                strict=True,
                reason="since the fits' multiple shooting (2026-11-29) the nominal cascade reaches a lower "
                "optimum (estimation RMSE 0.311 against 0.524) and the saturation refit from it stops at "
                "0.2045, closing 36 % of the gap: 'unexplained' (the refit has no multiple shooting)",
            ),
        ),
        3,
    ],
)
def test_a_clipped_velocity_command_is_named_and_closes_most_of_the_gap(seed):
    # 1 % of the commands clipped; the starts clipped 5 % at least before (on these records
    # the refit then ended worse than the nominal and the verdict was 'unexplained')
    u = np.random.default_rng(seed).standard_normal(PRE + N_EST + N_VAL)
    y = _record(u, float(np.quantile(np.abs(u), 0.99)), seed)
    rep = _diagnose(u[PRE:], y)
    assert rep.best_effect == "saturation", rep.summary()
    assert rep.ranking[0].validation_rmse <= 0.5 * rep.nominal_validation_rmse, rep.summary()


@pytest.mark.parametrize("seed", [0, 2, 3])
def test_no_clip_is_put_where_the_estimation_record_did_not_reach(seed):
    # no clipping, the validation commands 1.5 times wider: a level at the estimation range's
    # end clipped the validation record and drifted it to 225-675 noise stds before
    u = np.random.default_rng(seed).standard_normal(PRE + N_EST + N_VAL)
    u[PRE + N_EST :] *= 1.5
    y = _record(u, np.inf, seed)
    rep = _diagnose(u[PRE:], y)
    assert rep.best_effect != "saturation", rep.summary()
    for cand in rep.ranking:
        assert cand.validation_rmse <= 1.5 * rep.nominal_validation_rmse, cand.params
