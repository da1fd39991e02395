"""Several records, one model: what ``_fit`` needs beyond one record.

``fit_cascade([u1, u2, ...], [y1, y2, ...])`` fits one parameter vector to several records of
one system (issue 17). The records are never joined end to end: the core's
:class:`~backlashid._core.Problem` built by ``_core.Problem.from_records`` runs each record
from its own start (from rest, or with ``initial_state="estimate"`` from its own estimated
state: one block x0_1@i.., y_prev@i (, w0_1@i..) per record i counted from 1) and sums the
criteria: the cost, the gradient, the output-error factor (every record's rows folded into one
factor, so the standard errors come from all records) and the paper's step (the records'
regressor rows stacked in one least-squares problem). The ARX start stacks the records' rows
the same way (``_core.arx_records``).

The helpers below take either one record (a 1-D array, the plain fit, unchanged bit for bit)
or a list of them.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .. import _core
from .._validation import identification_record
from ..errors import BacklashIdError, DataError, NotIdentifiableError

Signal = NDArray[np.float64]
Records = list[NDArray[np.float64]]


def is_records(value: Any) -> bool:
    """Whether ``value`` is several records: a list or tuple of 1-D signals (a list of
    numbers is one record)."""
    return isinstance(value, (list, tuple)) and len(value) > 0 and all(np.ndim(v) >= 1 for v in value)


class _ConstantInput(Exception):
    """One record's input is constant (only all records constant is refused)."""


def validate(u: Any, y: Any, *, y_name: str, warmup: int, parameters: int) -> tuple[Records, Records]:
    """Each record checked as a fit checks one (finite, one length, a warm-up inside it, at
    least 10 samples after it), the messages naming the argument and the record index; at
    least 10 samples per parameter over all records after their warm-ups, a varying input and
    output in some record."""
    if not (is_records(u) and is_records(y)):
        single, many = ("u", y_name) if is_records(y) else (y_name, "u")
        raise DataError(
            f"{many} is a list of records but {single} is not: give both as lists of 1-D signals, one per record"
        )
    if len(u) != len(y):
        raise DataError(f"u has {len(u)} records but {y_name} has {len(y)}: give one output record per input record")
    us, ys = [], []
    for i, (ui, yi) in enumerate(zip(u, y)):
        try:
            u_arr, y_arr = identification_record(
                ui, yi, y_name=y_name, warmup=warmup, parameters=1, constant_input=_ConstantInput
            )
        except _ConstantInput:
            u_arr, y_arr = np.asarray(ui, dtype=np.float64), np.asarray(yi, dtype=np.float64)
        except DataError as exc:
            raise DataError(f"record {i} (u[{i}], {y_name}[{i}]): {exc}") from None
        us.append(u_arr)
        ys.append(y_arr)
    after = rows(us, warmup)
    if after < 10 * parameters:
        raise DataError(
            f"{after} samples after the warm-ups of {len(us)} records for {parameters} parameters: give at least "
            f"{10 * parameters} (10 per parameter)"
        )
    if all(np.ptp(ui) == 0.0 for ui in us):
        raise NotIdentifiableError("the input u is constant in every record: the system is not excited; use a varying input")
    if all(np.ptp(yi[warmup:]) == 0.0 for yi in ys):
        raise NotIdentifiableError(
            f"{y_name} never changes in any record: 0 % of samples move the output off the backlash dead band; "
            "excite the system with a larger input amplitude"
        )
    return us, ys


def rows(u: Signal | Records, warmup: int) -> int:
    """The samples after the warm-up (of every record)."""
    if isinstance(u, list):
        return sum(len(ui) - warmup for ui in u)
    return len(u) - warmup


def delayed(y: Signal | Records, shift: int) -> Signal | Records:
    """The output ``shift`` samples later (a feedthrough block, structure.py), each record
    starting with ``shift`` zeros."""
    if isinstance(y, list):
        return [np.concatenate([np.zeros(shift), yi[:-shift]]) for yi in y]
    return np.concatenate([np.zeros(shift), y[:-shift]])


def arx(u: Signal | Records, y: Signal | Records, na: int, nb: int, delay: int, warmup: int) -> Any:
    """The ARX least squares of ``_core.arx``, over the records' stacked rows for several."""
    if isinstance(u, list):
        return _core.arx_records(u, y, na, nb, delay, warmup)
    return _core.arx(u, y, na, nb, delay, warmup)


def rmse(prob: _core.Problem, theta: NDArray[np.float64]) -> float:
    """The free-run simulation RMSE over every record's samples after its warm-up (inf where
    the simulation fails)."""
    try:
        cost = prob.cost(theta)
    except BacklashIdError:
        return float("inf")
    value = float(np.sqrt(cost / max(prob.samples - prob.warmup, 1)))
    return value if np.isfinite(value) else float("inf")


def moving(model: Any, u: Signal | Records, warmup: int) -> float:
    """The fraction of samples after the warm-up (over all records) on which ``model`` moves
    the backlash."""
    if not isinstance(u, list):
        return float(model.moving_fraction(u, warmup=warmup))
    counts = [len(ui) - warmup for ui in u]
    moved = sum(model.moving_fraction(ui, warmup=warmup) * n for ui, n in zip(u, counts))
    return float(moved / max(sum(counts), 1))


def y_prev_starts(names: list[str], y: Signal | Records, warmup: int) -> list[tuple[int, float]]:
    """(position of y_prev in theta, the first measured output after the warm-up), per record."""
    if isinstance(y, list):
        return [(names.index(f"y_prev@{i + 1}"), float(yi[warmup])) for i, yi in enumerate(y)]
    return [(names.index("y_prev"), y[warmup])]


def states(names: list[str], p0: int, theta: NDArray[np.float64], several: bool) -> dict[str, float] | list[dict[str, float]]:
    """The estimated initial state under the core's names: one dict, or one per record (the
    ``@i`` suffix removed) for several records."""
    found = dict(zip(names[p0:], map(float, theta[p0:])))
    if not several:
        return found
    per: dict[int, dict[str, float]] = {}
    for name, value in found.items():
        match = re.fullmatch(r"(.+)@(\d+)", name)
        if match is None:  # pragma: no cover - the core names every state value of several records
            raise DataError(f"unexpected initial-state name {name!r}")
        per.setdefault(int(match.group(2)), {})[match.group(1)] = value
    return [per[i] for i in sorted(per)]
