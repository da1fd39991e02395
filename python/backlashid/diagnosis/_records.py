"""The diagnosis's inputs: the nominal chain it augments and the records it runs on.

The nominal model is any chain the package fits: a cascade (linear block, eq 16 -> general
backlash, eq 1), a sandwich (eq 29-36) or the input-backlash model (the sandwich with the input
block x(t) = a_1 u(t-1)). It is normalised (m_L1 = 1, r_1 = 1: :func:`~backlashid.identify.normalise`,
the outputs unchanged) and a block with a lag-0 term is the same coefficients one lag later
driven by the input one sample ahead (per block with a feedthrough): the augmentations are
written for blocks without one.

Estimation and validation are each one record (u, y) or a list of records: separate runs of the
same system, each started from its own state and never joined.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .._validation import check_scale, check_signals
from ..errors import DataError, ModelError
from ..identify import Structure, normalise
from ..models import CascadeModel, LinearBlock, SandwichModel

__all__ = ["Nominal", "nominal_chain", "records_of"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Nominal:
    """The nominal chain as the diagnosis augments it.

    Attributes
    ----------
    model : CascadeModel or SandwichModel
        The normalised model without feedthrough (it simulates the records shifted by
        ``shift``).
    structure : Structure
        Its structure (no feedthrough, no initial state).
    theta : ndarray
        Its physical vector.
    shift : int
        Samples the records' inputs are advanced by (one per block with a lag-0 term).
    """

    model: CascadeModel | SandwichModel
    structure: Structure
    theta: Array
    shift: int

    @property
    def is_sandwich(self) -> bool:
        """Whether the chain has an output block."""
        return isinstance(self.model, SandwichModel)

    def advanced(self, u: Array) -> Array:
        """The input as the chain without feedthrough takes it: u(t + shift), the last value
        repeated (it would reach an output only after the record)."""
        if self.shift == 0:
            return u
        return np.r_[u[self.shift :], np.repeat(u[-1:], self.shift)]


def nominal_chain(model: Any) -> Nominal:
    """The nominal chain of a fitted model, normalised and without feedthrough.

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The nominal model (e.g. ``fit_cascade(...).model``, ``fit_sandwich(...).model`` or
        ``fit_hammerstein_backlash(...).model``).

    Returns
    -------
    Nominal
        The chain the diagnosis augments.

    Raises
    ------
    ModelError
        If ``model`` is not a cascade or sandwich.

    Examples
    --------
    >>> import backlashid as bid
    >>> from backlashid.diagnosis._records import nominal_chain
    >>> chain = nominal_chain(bid.example2())
    >>> chain.structure.names[-3:], chain.shift
    (['r2', 's1', 's2'], 0)
    """
    if isinstance(model, CascadeModel):
        lin = model.linear
        shift = int(lin.feedthrough)
        plain: CascadeModel | SandwichModel = CascadeModel(LinearBlock(lin.a, lin.b), model.backlash)
    elif isinstance(model, SandwichModel):
        lin, out = model.input_linear, model.output_linear
        shift = int(lin.feedthrough) + int(out.feedthrough)
        plain = SandwichModel(LinearBlock(lin.a, lin.b), model.backlash, LinearBlock(out.a, out.b))
    else:
        raise ModelError(
            "diagnose needs the nominal model the package fitted: a CascadeModel (fit_cascade), a SandwichModel "
            f"(fit_sandwich) or an input-backlash model (fit_hammerstein_backlash); got {type(model).__name__}"
        )
    plain = normalise(plain)
    structure = Structure.of(plain)  # no feedthrough: shifted into the data above
    return Nominal(plain, structure, structure.pack(plain), shift)


def records_of(arg: Any, name: str) -> list[tuple[Array, Array]]:
    """One record (u, y) or a list of records, checked: 1-D, finite, u and y of one length.

    Parameters
    ----------
    arg : tuple or list
        ``(u, y)`` or ``[(u1, y1), (u2, y2), ...]``.
    name : str
        The argument's name, for messages.

    Returns
    -------
    list of (ndarray, ndarray)
        The records (copies: the caller's arrays are never changed).

    Raises
    ------
    DataError
        If it is neither, or a record is unusable.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.diagnosis._records import records_of
    >>> len(records_of([(np.zeros(5), np.ones(5)), (np.zeros(7), np.ones(7))], "validation"))
    2
    """
    hint = f"{name} must be a pair (u, y) of 1-D signals or a list of such pairs, e.g. {name}=(u, y) or {name}=[(u1, y1), (u2, y2)]"
    if not isinstance(arg, (tuple, list)) or len(arg) == 0:
        raise DataError(hint)
    pairs = [arg] if _is_pair(arg) else list(arg)
    out = []
    for k, pair in enumerate(pairs):
        if not _is_pair(pair):
            raise DataError(hint)
        label = name if len(pairs) == 1 else f"{name}[{k}]"
        u, y = check_signals((f"{label}[0] (u)", pair[0]), (f"{label}[1] (y)", pair[1]))
        check_scale(u, f"{label}[0] (u)")
        check_scale(y, f"{label}[1] (y)")
        out.append((np.array(u, dtype=np.float64), np.array(y, dtype=np.float64)))
    return out


def _is_pair(x: Any) -> bool:
    """(u, y): two signals, not two records."""
    if not isinstance(x, (tuple, list)) or len(x) != 2:
        return False
    try:
        return all(np.ndim(v) == 1 for v in x)
    except ValueError:  # ragged: records of different lengths
        return False
