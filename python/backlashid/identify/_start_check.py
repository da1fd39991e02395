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

__all__ = ["undetermined_start"]

# another start fits the first samples as well as the estimate when its RMS error there is at
# most this many times the estimate's
SAME_FIT = 1.05
# the starts at rest: the level from this many first samples, x at this many points across the
# dead band (its ends included)
REST_LEVEL = 20
REST_POINTS = 5


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
    the dead band, (c_L + c_R) / 2, either way, and the model at rest at the record's first
    output level with x across the dead band there (:func:`_rest_states`).

    While the backlash holds, the output says nothing of where x sits inside the dead band; an
    input block that integrates (a drive whose motor position integrates a velocity command,
    at rest) keeps that offset, and the play engages later by as much. A stable block forgets
    it, and the later difference is small."""
    half = 0.5 * (model.backlash.c_left + model.backlash.c_right)
    if samples >= len(u) or len(state.x_past) == 0 or not half > 0.0:
        return None
    error = rmse(y[:samples], simulated[:samples])
    same = SAME_FIT * error + 1e-9 * (1.0 + float(np.max(np.abs(y[:samples]))))
    others = [replace(state, x_past=tuple(v + shift for v in state.x_past)) for shift in (half, -half)]
    spread = None
    for other in [*others, *_rest_states(model, y, samples, state)]:
        try:
            sim = model.simulate(u, initial_state=other)
        except BacklashIdError:
            continue
        if rmse(y[:samples], sim[:samples]) <= same:
            later = rmse(simulated, sim, warmup=samples)
            spread = later if spread is None else max(spread, later)
    return None if spread is None else (spread, error)


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
