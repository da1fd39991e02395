"""The validation's held start (issue 18): the input held for the estimation record's length,
not for ever.

On slow ramps an output offset beyond what the play absorbs is refitted by a linear block
with a pole within 1e-8 of z = 1, nearly cancelled by a zero: its response over the record is
the nominal one, but its static gain is anything (-70 and -6400 where the benchmark found it).
The held start at equilibrium extrapolated that gain and the candidate's validation error came
out 1e3 to 1e21 times the nominal's. The generator here is this file's own: a cascade driven
by slow ramps and dwells, a constant sensor offset on the output, white noise."""

from __future__ import annotations

import numpy as np
import pytest

import backlashid as bx
from backlashid.diagnosis import held_state

N = 2000


def _ramps(n: int, rng: np.random.Generator) -> np.ndarray:
    """Ramps of 20-200 samples to targets of alternating sign, each followed half the time by a
    dwell of up to 100 samples."""
    u: list[float] = []
    level, sign = 0.0, 1.0
    while len(u) < n:
        target = sign * rng.uniform(0.3, 1.0)
        sign = -sign
        u.extend(np.linspace(level, target, int(rng.integers(20, 200)) + 1)[1:])
        level = target
        if rng.random() < 0.5:
            u.extend([level] * int(rng.integers(0, 100)))
    return np.array(u[:n])


def _offset_on_ramps(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """2 N samples: a slow drive (poles 0.51 exp(+-0.29j)), play of width 0.05 each side, slope
    0.5, and an output offset -0.07 (beyond the 0.025 a width change absorbs)."""
    rng = np.random.default_rng(seed)
    m = bx.CascadeModel(
        bx.LinearBlock([0.16, 0.123], [-0.976, 0.259]), bx.GeneralBacklash(0.05, 0.05, [0.5, 0.0, 0.25], [0.5, 0.0, 0.3])
    )
    u = _ramps(2 * N, rng)
    return u, m.simulate(u) - 0.07 + 0.02 * rng.standard_normal(2 * N)


@pytest.mark.filterwarnings("ignore::backlashid.FitWarning")  # a width the offset leaves ill-determined
@pytest.mark.parametrize("seed", [5, 7])
def test_an_offset_refit_on_ramps_validates_no_worse_than_the_nominal_model(seed: int) -> None:
    u, y = _offset_on_ramps(seed)
    fit = bx.fit_cascade(u[:N], y[:N], na=2, nb=2, degree=3)
    report = bx.diagnose(fit.model, (u[:N], y[:N]), (u[N:], y[N:]), candidates=["output_offset"])
    (offset,) = report.ranking
    # the refit starts from the nominal model with the offset at zero and only accepts cost
    # decreases on the estimation record; held at equilibrium it validated 4e3 (seed 5) and
    # 2.5e9 (seed 7) times worse than the nominal model
    assert offset.validation_rmse < 1.5 * report.nominal_validation_rmse
    assert offset.estimation_rmse < 0.025


def test_a_finite_hold_is_the_step_response_and_needs_no_equilibrium() -> None:
    m = bx.example1()
    u0, hold = 0.6, 300
    x = m.linear.simulate(np.full(hold, u0))
    state = held_state(m, u0, 0.2, hold)
    assert state.u_past == (u0, u0) and state.x_past == (x[-1], x[-2]) and state.y_prev == 0.2
    # fast poles: a hold of the record's length is the equilibrium
    np.testing.assert_allclose(held_state(m, u0, 0.2, 4000).x_past, held_state(m, u0, 0.2).x_past, rtol=1e-12)
    # a pole at z = 1 has no equilibrium, but a finite hold: x(t) = x(t-1) + 0.5 u(t-1)
    integrator = bx.CascadeModel(bx.LinearBlock([0.5], [-1.0]), m.backlash)
    np.testing.assert_allclose(held_state(integrator, u0, 0.2, hold).x_past, [0.5 * u0 * (hold - 1)], rtol=1e-12)
    # a hold shorter than the block's memory: the input before it was zero
    short = held_state(m, u0, 0.2, 1)
    assert short.u_past == (u0, 0.0) and short.x_past == (0.0, 0.0)
    with pytest.raises(bx.ModelError, match="pole at z = 1"):
        held_state(integrator, u0, 0.2)
