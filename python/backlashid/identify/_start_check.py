"""Whether a record's first samples determine a model's start: other starts that simulate
them as well as the estimated one (:func:`~backlashid.identify.estimate_state`), and how
differently they simulate the rest of the record (what ``evaluate(..., init_samples)`` warns
about).

While the backlash holds through those samples, the output says nothing of where x sits inside
the dead band; an input block that integrates (a drive whose motor position integrates a
velocity command, at rest) keeps that offset, and the play engages later by as much.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from .._measures import rmse
from ..errors import BacklashIdError
from ..models import CascadeState, Model, SandwichModel, SandwichState
from ._state import started_from_samples

__all__ = ["undetermined_start"]

# another start fits the first samples as well as the estimate when its RMS error there is at
# most this many times the estimate's
SAME_FIT = 1.05
# the starts at rest: the level from this many first samples, x at this many points across the
# dead band (its ends included)
REST_LEVEL = 20
REST_POINTS = 5
# and the start estimated from this many times the samples (at most the record)
LONGER = 3


def undetermined_start(
    model: Model,
    u: NDArray[np.float64],
    y: NDArray[np.float64],
    samples: int,
    state: CascadeState | SandwichState,
    simulated: NDArray[np.float64],
) -> tuple[float, float] | None:
    """How far the first ``samples`` samples leave the start open: the largest RMS difference,
    over the rest of the record, between ``simulated`` (the simulation from ``state``) and the
    simulation from another start
    that simulates those samples as well (its RMS error there at most SAME_FIT times the
    state's own), with that error RMS; None where no other start fits as well or nothing
    follows the samples. The other starts: ``state`` with the input block's x shifted by half
    the dead band, (c_L + c_R) / 2, either way, the model at rest at the record's first
    output level with x across the dead band there (:func:`_rest_states`), and the start
    estimated from LONGER times the samples (a later motion can tell where x sat; on a
    position sandwich under steps the 100 samples' start validated at 9.8 noise stds, the 300
    samples' at 1.04, and both simulated the first 100 alike).

    While the backlash holds, the output says nothing of where x sits inside the dead band; an
    input block that integrates (a drive whose motor position integrates a velocity command,
    at rest) keeps that offset, and the play engages later by as much. A stable block forgets
    it, and the later difference is small."""
    half = 0.5 * (model.backlash.c_left + model.backlash.c_right)
    if samples >= len(u) or len(state.x_past) == 0 or not half > 0.0:
        return None
    error = rmse(y[:samples], simulated[:samples])
    same = SAME_FIT * error + 1e-9 * (1.0 + float(np.max(np.abs(y[:samples]))))
    states = [*_shifted(state, half), *_rest_states(model, y, samples, state)]
    spread = None
    for sim in [*_simulations(model, u, states), *_longer(model, u, y, samples)]:
        if rmse(y[:samples], sim[:samples]) <= same:
            later = rmse(simulated, sim, warmup=samples)
            spread = later if spread is None else max(spread, later)
    return None if spread is None else (spread, error)


def _shifted(state: CascadeState | SandwichState, half: float) -> list[CascadeState | SandwichState]:
    """``state`` with the input block's x shifted by ``half`` either way."""
    return [replace(state, x_past=tuple(v + shift for v in state.x_past)) for shift in (half, -half)]


def _simulations(model: Model, u: NDArray[np.float64], states: list[CascadeState | SandwichState]) -> list[NDArray[np.float64]]:
    """The model simulated from each of ``states`` (those it cannot start from left out)."""
    out = []
    for state in states:
        try:
            out.append(np.asarray(model.simulate(u, initial_state=state), dtype=np.float64))
        except BacklashIdError:
            continue
    return out


def _longer(model: Model, u: NDArray[np.float64], y: NDArray[np.float64], samples: int) -> list[NDArray[np.float64]]:
    """The simulation from the start estimated on LONGER times ``samples`` (at most the
    record), or none where that is no longer or the estimate raises."""
    longer = min(LONGER * samples, len(u))
    if longer <= samples:
        return []
    try:
        return [started_from_samples(model, u, y, longer)[0]]
    except BacklashIdError:
        return []


def _rest_states(model: Model, y: NDArray[np.float64], samples: int, state: CascadeState | SandwichState) -> list[CascadeState | SandwichState]:
    """The model at rest at the mean of the record's first REST_LEVEL samples (at most
    ``samples``): every past of a block at its steady value (a sandwich's backlash output y at
    the level over the output block's static gain, 0 where that block integrates), x at
    REST_POINTS across the dead band [z_L, z_R] that holds that y (eq 2-3); the input's past
    ``u_past`` as in ``state``. Empty where the level has no such band."""
    level = float(np.mean(y[: max(1, min(samples, REST_LEVEL))]))
    held = level
    if isinstance(model, SandwichModel):
        out = model.output_linear
        gain, pole_sum = float(np.sum(out.a)), 1.0 + float(np.sum(out.b))
        if gain == 0.0:
            return []
        held = 0.0 if abs(pole_sum) <= 1e-9 * (1.0 + float(np.sum(np.abs(out.b)))) else level * pole_sum / gain
    bl = model.backlash
    slope = min(float(bl.m_left[0]), float(bl.m_right[0]))
    if not slope > 0.0:  # no backlash at rest: the branches do not rise at their dead band's ends
        return []
    reach = 10.0 * (1.0 + abs(held) / slope + bl.c_left + bl.c_right)
    try:
        z_left, z_right = bl.breakpoints(held, (-reach, reach))
    except BacklashIdError:
        return []
    if not (np.isfinite(z_left) and np.isfinite(z_right) and z_left <= z_right):
        return []
    nx = len(state.x_past)
    states: list[CascadeState | SandwichState] = []
    for x in np.linspace(z_left, z_right, REST_POINTS):
        if isinstance(state, SandwichState):
            states.append(replace(state, x_past=(float(x),) * nx, y_past=(held,) * len(state.y_past), w_past=(level,) * len(state.w_past)))
        else:
            states.append(replace(state, x_past=(float(x),) * nx, y_prev=held))
    return states
