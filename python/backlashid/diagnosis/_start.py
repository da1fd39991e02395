"""The state every model of the diagnosis starts a record in.

Real records do not start at rest, and a drive whose output is a position integrates: no input
holds it at rest. So every record starts from a state estimated from its own first samples, as
the benchmark protocols' n_init does:

- the nominal model: :func:`~backlashid.identify.estimate_state` on the record's first
  ``samples`` samples (the state :func:`~backlashid.evaluate` with ``init_samples`` uses), so the
  diagnosis's nominal validation error is the one ``evaluate`` reports;
- an augmented model (nominal refitted with effects): its internal state (the linear blocks' past
  outputs and the backlash memory; the input's past is the record's, kept) refitted to the same
  samples from the nominal's, by a few damped Gauss-Newton steps on the core's simulation
  (the effects' own memories start at rest on it). A refitted model whose integrator continues
  from the nominal's state would carry the difference as an offset through the record.

Those first samples are inside the warm-up that every criterion leaves out. ``"rest"`` starts
from zero, as the paper assumes.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._numerics import minimize_bounded
from ..identify import estimate_state
from ..models import CascadeModel, CascadeState
from ._records import Nominal
from .effects._base import Start, held_past, refined_start, start_of

__all__ = ["INITIAL_STATES", "describe", "estimated_start", "held_state", "nominal_start", "refined_start"]

INITIAL_STATES = ("estimate", "rest")
MEMORY_GRID = 33  # backlash memories tried before the 1-D refinement (estimated_start)
MEMORY_PREFIX = 256  # first prefix of the record tried for the memory search (doubled until settled)
Array = NDArray[np.float64]


def nominal_start(nominal: Nominal, u: Array, y: Array, how: str, samples: int) -> Start:
    """The nominal model's state before a record (``u`` already advanced by the chain's shift).

    Parameters
    ----------
    nominal : Nominal
        The nominal chain.
    u, y : ndarray
        The record.
    how : {"estimate", "rest"}
        Estimated from the first ``samples`` samples, or rest.
    samples : int
        Samples the state is estimated from.

    Returns
    -------
    dict
        The start as ``_core.simulate_augmented`` takes it (empty for rest).
    """
    if how == "rest":
        return {}
    return start_of(estimate_state(nominal.model, u, y, samples=max(1, min(samples, u.size))))


def describe(how: str, samples: int) -> str:
    """How every model started each record, for the report."""
    if how == "rest":
        return "from rest (the paper's assumption)"
    return (
        f"estimated from each record's first {samples} samples (the nominal model's state as evaluate(..., "
        "init_samples) estimates it; each augmented model's internal state refitted to the same samples), "
        "which the warm-up leaves out of every criterion"
    )



def held_state(model: CascadeModel, u0: float, y_prev: float, hold: int | None = None) -> CascadeState:
    """The cascade after the input was held at u0.

    The linear block (16) after the input u0 held for ``hold`` samples from rest, or for ever
    (its equilibrium x = sum a / (1 + sum b) u0), and the backlash memory y_prev. ``diagnose``
    holds for the estimation record's length: the equilibrium of a slow pole almost cancelled
    by a zero at z = 1 is a static gain the records do not determine.

    Parameters
    ----------
    model : CascadeModel
        The cascade.
    u0 : float
        The input held before the record.
    y_prev : float
        The backlash memory y(0).
    hold : int, optional
        Samples the input is held for, from rest; default for ever (the equilibrium).

    Returns
    -------
    CascadeState
        The state to start a simulation from.

    Raises
    ------
    ModelError
        If the linear block has a pole at z = 1 and ``hold`` is None (no equilibrium).

    Examples
    --------
    >>> import backlashid as bid
    >>> from backlashid.diagnosis import held_state
    >>> held_state(bid.example1(), 0.0, 0.5).y_prev
    0.5
    """
    u_past, x_past = held_past(model.linear, float(u0), hold)
    return CascadeState(u_past=tuple(u_past), x_past=tuple(x_past), y_prev=float(y_prev))


def estimated_start(simulate: Any, u: Array, y: Array, memory_range: tuple[float, float]) -> tuple[Array, float]:
    """A simulation of the record from the backlash memory y(0) that best fits it.

    ``simulate(u, y_prev, True)`` is tried on a grid over the output's range, then a bounded
    1-D search around the best point. The memory acts only until the backlash first moves,
    which may be long after the warm-up, so it is fitted on the whole record (one parameter for
    every model alike, as initial conditions are estimated for validation in common practice);
    fitted on the warm-up alone, its error persists over a long hold and the paired test would
    read the differences between models' memories as significant.

    Once the backlash has moved, the simulation no longer depends on the memory: the search runs
    on the shortest prefix (``MEMORY_PREFIX`` samples, doubled) over whose second half the
    simulations from both ends of the range agree exactly. The backlash orders its outputs by
    their memories, so every memory in between agrees there too, and the record's cost differs
    between memories only within the prefix.

    Parameters
    ----------
    simulate : callable
        ``simulate(u, y_prev, held)`` -> output of the record.
    u : ndarray
        Input of the record.
    y : ndarray
        Measured output of the record.
    memory_range : tuple of float
        (lo, hi), the range of memories searched.

    Returns
    -------
    output : ndarray
        The simulation from the best memory.
    y_prev : float
        That memory.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> from backlashid.diagnosis import estimated_start, held_state
    >>> m = bid.example1()
    >>> u = np.r_[np.zeros(50), np.sin(0.05 * np.arange(150))]
    >>> def sim(u, y0, held):
    ...     return m.simulate(u, initial_state=held_state(m, u[0], y0))
    >>> _, y0 = estimated_start(sim, u, sim(u, 0.3, True), (-1.0, 1.0))
    >>> round(y0, 6)
    0.3
    """

    lo, hi = memory_range
    m = _settled(simulate, u, lo, hi)
    u_m, y_m = u[:m], y[:m]

    def cost(y0: float) -> float:
        r = y_m - simulate(u_m, y0, True)
        return float(r @ r)

    # the cost is flat where the memory lies outside the dead band (it is clamped onto a branch
    # at once) and quadratic inside: a coarse grid, a fine grid around its best point, then Brent
    best, best_cost = lo, math.inf
    for _ in range(2):
        grid = np.linspace(lo, hi, MEMORY_GRID)
        costs = [cost(g) for g in grid]
        k = int(np.argmin(costs))
        if costs[k] < best_cost:
            best, best_cost = float(grid[k]), costs[k]
        lo, hi = float(grid[max(k - 1, 0)]), float(grid[min(k + 1, grid.size - 1)])
    x, fx, converged = minimize_bounded(cost, lo, hi, xatol=1e-9 * max(hi - lo, 1e-12))
    if converged and fx < best_cost:
        best = float(x)
    return simulate(u, best, True), best


def _settled(simulate: Any, u: Array, lo: float, hi: float) -> int:
    """Length of the shortest prefix (MEMORY_PREFIX doubled) over whose second half the
    simulations from the memories lo and hi agree exactly; the record's length if none."""
    m = MEMORY_PREFIX
    while m < u.size:
        if np.array_equal(simulate(u[:m], lo, True)[m // 2 :], simulate(u[:m], hi, True)[m // 2 :]):
            return m
        m *= 2
    return int(u.size)
