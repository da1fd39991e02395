"""The feedforward compensator of a cascade or sandwich (rust/core/src/compensation)."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import _core
from .._threads import Serialised
from .._validation import as_scalar, as_signal, shown
from ..errors import DataError, ModelError
from ..models import CascadeModel, CascadeState, GeneralBacklash, LinearBlock, SandwichModel, SandwichState

__all__ = ["Compensator", "compensate"]

Chain = CascadeModel | SandwichModel


def _native_block(block: LinearBlock) -> Any:
    a, b = block.a.tolist(), block.b.tolist()
    return _core.LinearBlock(a[1:], b, a[0]) if block.feedthrough else _core.LinearBlock(a, b)


def _native_backlash(bl: GeneralBacklash) -> Any:
    return _core.GeneralBacklash(bl.c_left, bl.c_right, bl.m_left.tolist(), bl.m_right.tolist())


def native_chain(model: Any, initial_state: Any, name: str = "model") -> tuple[Any, list[list[float]]]:
    """The compiled model and its state as the binding takes them; ModelError for a model of
    the wrong type, DataError for a state of the wrong type."""
    if isinstance(model, CascadeModel):
        s = model.rest_state() if initial_state is None else initial_state
        if not isinstance(s, CascadeState):
            raise DataError(f"initial_state must be a CascadeState for a cascade, got {type(s).__name__}")
        native = _core.CascadeModel(_native_block(model.linear), _native_backlash(model.backlash))
        return native, [list(s.u_past), list(s.x_past), [s.y_prev]]
    if isinstance(model, SandwichModel):
        w = model.rest_state() if initial_state is None else initial_state
        if not isinstance(w, SandwichState):
            raise DataError(f"initial_state must be a SandwichState for a sandwich, got {type(w).__name__}")
        sandwich = _core.SandwichModel(
            _native_block(model.input_linear), _native_backlash(model.backlash), _native_block(model.output_linear)
        )
        return sandwich, [list(w.u_past), list(w.x_past), list(w.y_past), list(w.w_past)]
    raise ModelError(f"{name} must be a CascadeModel or SandwichModel, got {type(model).__name__}")


def _threshold(value: Any) -> float:
    level = as_scalar(value, "threshold", DataError)
    if not (np.isfinite(level) and level >= 0):
        raise DataError(f"threshold = {shown(value)}: give a finite value >= 0 (0: the exact inverse)")
    return level


def _reference(reference: Any) -> NDArray[np.float64]:
    r = as_signal(reference, "reference")
    if r.ndim != 1 or r.size == 0:
        raise DataError(f"reference must be a non-empty 1-D signal, got shape {r.shape}")
    bad = np.flatnonzero(~np.isfinite(r))
    if bad.size:
        raise DataError(f"reference[{bad[0]}] is {r[bad[0]]}: give a finite reference")
    return r


def compensate(
    model: Chain, reference: ArrayLike, *, initial_state: CascadeState | SandwichState | None = None, threshold: float = 0.0
) -> NDArray[np.float64]:
    """The input that makes the model's output follow ``reference``: feedforward compensation.

    Each block is inverted in turn, output to input: for a sandwich the output block's
    inverse gives the desired backlash output, the backlash inverse
    (:meth:`GeneralBacklash.inverse`) the desired x, and the input block's inverse u; a
    cascade skips the first. A linear block's inverse is a filter of the target D samples
    ahead, D its relative degree (1 for eq 16, 0 with a feedthrough); a block with zeros on
    or outside the unit circle gets the stable approximation (zeros reflected, static gain
    kept; :attr:`Compensator.approximate` says so), which no longer tracks exactly: it
    follows slow references, but the jump across the dead band at a reversal excites its
    all-pass error, which the backlash can then hold (the inverse's memory is no longer the
    plant's) until the reference passes that level. The
    preview is D = d_G for a cascade, d_G + d_H for a sandwich: u[t] targets
    ``reference[t + D]`` (the last D samples target the last reference value), so that
    ``model.simulate(u)`` equals the reference from sample D on (to rounding; the first D
    outputs are fixed by the initial state). One loop in the Rust core.

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The model whose output should follow the reference (identified or known).
    reference : array_like
        The desired output, 1-D, finite.
    initial_state : CascadeState or SandwichState, optional
        The model's state before the first sample (default its rest state).
    threshold : float, default 0.0
        Smoothing of the backlash inverse for noisy references (see
        :meth:`GeneralBacklash.inverse`); 0 is the exact inverse.

    Returns
    -------
    numpy.ndarray
        The input u, as long as the reference (a new array).

    Raises
    ------
    ModelError
        If ``model`` is not a cascade or sandwich, a linear block has a zero on the unit
        circle, or the inverse overflows.
    DataError
        If the reference is not a finite 1-D signal, the state does not fit the model,
        ``threshold`` is negative or not finite, or the backlash cannot reach a target (the
        message names the reference sample).

    Examples
    --------
    >>> import numpy as np
    >>> import backlashid as bid
    >>> model = bid.example1()
    >>> reference = np.sin(0.02 * np.arange(400))
    >>> u = bid.compensate(model, reference)
    >>> bool(np.max(np.abs(model.simulate(u)[1:] - reference[1:])) < 1e-9)
    True
    """
    native, state = native_chain(model, initial_state)
    r = _reference(reference)
    return _core.compensate(native, r, state, _threshold(threshold))


class Compensator:
    """The feedforward compensator of a model, one sample at a time (for a control loop).

    :func:`compensate` as a stateful object: :meth:`step` takes the reference
    :attr:`delay` samples ahead and returns the input for now; :meth:`run` does it for a
    block of samples, and successive calls continue one record. It pickles with its state
    (the model and the inverses' memories), to continue elsewhere. Threads may share one:
    their calls take turns (one lock), each step seeing the state the previous one left.

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The model whose output should follow the reference (identified or known).
    initial_state : CascadeState or SandwichState, optional
        The model's state before the first sample (default its rest state).
    threshold : float, default 0.0
        Smoothing of the backlash inverse for noisy references (see
        :meth:`GeneralBacklash.inverse`); 0 is the exact inverse.

    Raises
    ------
    ModelError
        If ``model`` is not a cascade or sandwich, or a linear block has a zero on the unit
        circle.
    DataError
        If the state does not fit the model or ``threshold`` is negative or not finite.

    Examples
    --------
    >>> import numpy as np
    >>> import backlashid as bid
    >>> comp = bid.Compensator(bid.example2())
    >>> comp.delay, comp.approximate
    (2, False)
    >>> u = comp.run(np.full(5, 0.5))  # u[t] targets the reference at t + 2
    >>> round(float(bid.example2().simulate(u)[-1]), 12)
    0.5
    """

    __slots__ = ("_model", "_native", "_threshold")

    def __init__(self, model: Chain, *, initial_state: CascadeState | SandwichState | None = None, threshold: float = 0.0) -> None:
        native, state = native_chain(model, initial_state)
        self._model = model
        self._threshold = _threshold(threshold)
        self._native = Serialised(_core.Compensator(native, state, self._threshold))  # shared across threads: one call at a time

    @property
    def model(self) -> Chain:
        """The model compensated."""
        return self._model

    @property
    def threshold(self) -> float:
        """The backlash inverse's smoothing threshold."""
        return self._threshold

    @property
    def delay(self) -> int:
        """D: :meth:`step` takes the reference D samples ahead of the input it returns."""
        return int(self._native.delay)

    @property
    def approximate(self) -> bool:
        """True when a linear block is non-minimum phase and its inverse is the stable approximation."""
        return bool(self._native.approximate)

    def step(self, reference_sample: float) -> float:
        """The input u(t) for the reference r(t + D).

        Parameters
        ----------
        reference_sample : float
            The reference :attr:`delay` samples ahead, finite.

        Returns
        -------
        float
            The input for now.

        Raises
        ------
        DataError
            If the sample is not finite or the backlash cannot reach it.
        """
        r = as_scalar(reference_sample, "reference_sample", DataError)
        return float(self._native.step(r))

    def run(self, reference_block: ArrayLike) -> NDArray[np.float64]:
        """The inputs for a block of reference samples, continuing the state.

        Parameters
        ----------
        reference_block : array_like
            References r(t + D), r(t + 1 + D), ..., 1-D, finite (may be empty).

        Returns
        -------
        numpy.ndarray
            The inputs u(t), u(t + 1), ... (a new array).

        Raises
        ------
        DataError
            If the block is not a finite 1-D signal or the backlash cannot reach a sample.
        """
        block = as_signal(reference_block, "reference_block")
        if block.ndim == 1 and block.size == 0:
            return np.empty(0)  # nothing to step: the state stays
        return self._native.run(_reference(block))

    def __reduce__(self) -> tuple[Any, ...]:
        return (_restore, (self._model, self._threshold, self._native.get_state()))

    def __repr__(self) -> str:
        kind = type(self._model).__name__
        return f"Compensator({kind}, delay={self.delay}, threshold={self._threshold:g}, approximate={self.approximate})"


def _restore(model: Chain, threshold: float, state: Any) -> Compensator:
    """A pickled :class:`Compensator`: rebuilt from its model, then its memory restored."""
    comp = Compensator(model, threshold=threshold)
    comp._native.set_state(state)
    return comp
