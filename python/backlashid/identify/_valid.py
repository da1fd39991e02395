"""Keeping a fit among valid backlash models: the search's optimum can be a vector that is no
backlash (a branch that falls across the dead band) or one that hardly moves, where the data
(e.g. a measured ``abs(speed)`` that no backlash represents) pull the branches outside the
model class. The fit then continues from a valid model of a lower branch degree with the one
Levenberg-Marquardt search restricted to valid models: :class:`ValidOnly` adds the model's
validity and motion to the compiled problem's stability guard ``feasible``, whose failing
trial steps the search rejects.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import BacklashIdError, ModelError
from . import _records
from ._checks import branch_problems
from ._structure import Structure

__all__ = ["ValidOnly", "acceptable_motion", "record_motion", "why_not_acceptable"]


def record_motion(
    structure: Structure,
    prob: Any,
    theta: NDArray[np.float64],
    u: NDArray[np.float64] | list[NDArray[np.float64]],
    warmup: int,
) -> tuple[float, tuple[float, float]] | None:
    """The moving fraction of the model of ``theta`` on ``u`` after ``warmup`` and the range of
    x there, from the compiled problem ``prob`` of that record (from rest, or from theta's
    initial state for a problem with one): one simulation, or none where its last gradient pass
    ran at this theta (``Problem.motion``). None where the problem's simulation is not the
    model's on ``u`` (several records, a shifted feedthrough block, another warm-up) or fails:
    then simulate the model (from rest)."""
    if (
        isinstance(u, list)
        or structure.shift
        or not hasattr(prob, "motion")
        or prob.records != 1
        or prob.warmup != warmup
        or prob.samples != len(u)
    ):
        return None
    try:
        count, lo, hi = prob.motion(theta)
    except BacklashIdError:
        return None
    return count / (len(u) - warmup), (lo, hi)


def why_not_acceptable(
    structure: Structure,
    prob: Any,
    theta: NDArray[np.float64],
    u: NDArray[np.float64] | list[NDArray[np.float64]],
    warmup: int,
    min_moving: float,
    branches: bool = False,
) -> str | None:
    """None for a stable, valid model that moves the backlash on at least ``min_moving`` of
    the samples after ``warmup`` (from rest; over every record of a list) and, with
    ``branches``, whose branches increase and do not cross on the x range it visits there;
    else what is wrong."""
    return acceptable_motion(structure, prob, theta, u, warmup, min_moving, branches)[0]


def acceptable_motion(
    structure: Structure,
    prob: Any,
    theta: NDArray[np.float64],
    u: NDArray[np.float64] | list[NDArray[np.float64]],
    warmup: int,
    min_moving: float,
    branches: bool = False,
) -> tuple[str | None, float | None]:
    """:func:`why_not_acceptable` and the moving fraction it found (None if it stopped
    before simulating), which the fit reports without simulating the record again."""
    if not prob.feasible(theta):
        return "is unstable", None
    try:
        model = structure.model(theta)
    except ModelError as exc:
        return f"is no valid backlash ({exc})", None
    found = record_motion(structure, prob, theta, u, warmup)
    try:
        moving = found[0] if found is not None else _records.moving(model, u, warmup)
    except ModelError as exc:
        return f"does not simulate ({exc})", None
    if moving < min_moving:
        return f"moves the backlash on only {100 * moving:.1f} % of samples (min_moving = {min_moving:g})", moving
    if branches:
        try:
            problems = branch_problems(model, u, warmup, found[1] if found is not None else None, advice=False)
        except ModelError as exc:
            return f"does not simulate ({exc})", moving
        if problems is not None:
            return f"is no backlash: {problems}", moving
    return None, moving


class ValidOnly:
    """A compiled problem whose ``feasible`` also requires a valid model that moves enough
    and, with ``branches``, is a backlash on the x range it visits (:func:`why_not_acceptable`);
    everything else is the problem's."""

    def __init__(
        self,
        prob: Any,
        structure: Structure,
        u: NDArray[np.float64] | list[NDArray[np.float64]],
        warmup: int,
        min_moving: float,
        branches: bool = False,
    ) -> None:
        self._prob, self._structure, self._u, self._warmup, self._min_moving = prob, structure, u, warmup, min_moving
        self._branches = branches

    def __getattr__(self, name: str) -> Any:
        return getattr(self._prob, name)

    def on(self, prob: Any, u: NDArray[np.float64] | list[NDArray[np.float64]]) -> ValidOnly:
        """The same guard on another problem, of the record ``u`` (e.g. the record's head)."""
        return ValidOnly(prob, self._structure, u, self._warmup, self._min_moving, self._branches)

    def feasible(self, theta: NDArray[np.float64]) -> bool:
        why = why_not_acceptable(self._structure, self._prob, theta, self._u, self._warmup, self._min_moving, self._branches)
        return why is None
