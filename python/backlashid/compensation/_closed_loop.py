"""A discrete PID loop around a plant model, with and without the feedforward compensator."""

from __future__ import annotations

import copy
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import _core
from .._optional import pyplot
from .._validation import check_real, check_scale, check_warmup, shown
from ..errors import DataError, ModelError
from ..identify import rmse
from ..models import CascadeModel, CascadeState, SandwichModel, SandwichState
from ._compensator import Chain, Compensator, _reference, compensate, native_chain

__all__ = ["ClosedLoopResult", "closed_loop"]


@dataclass(frozen=True)
class ClosedLoopResult:
    """A closed-loop simulation: what went in and came out.

    Returned by :func:`closed_loop`.

    Attributes
    ----------
    reference : numpy.ndarray
        The reference r(t).
    output : numpy.ndarray
        The plant's output y(t).
    input : numpy.ndarray
        The plant's input u(t): feedforward plus the PID's action, after the saturation.
    feedforward : numpy.ndarray
        The compensator's part of the input (zeros without a compensator).
    rmse : float
        Root mean square of output - reference from sample ``warmup`` on.
    warmup : int
        Samples at the start left out of ``rmse`` (the start's transient: a reference that
        does not start at the plant's initial output cannot be met at once).
    """

    reference: NDArray[np.float64]
    output: NDArray[np.float64]
    input: NDArray[np.float64]
    feedforward: NDArray[np.float64]
    rmse: float
    warmup: int = 0

    def plot(self) -> Any:
        """Plot reference and output, the error and the input.

        Returns
        -------
        matplotlib.figure.Figure
            Three stacked axes sharing the sample axis.

        Raises
        ------
        BacklashIdError
            If matplotlib is not installed.
        """
        plt = pyplot()
        fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 7))
        t = np.arange(self.reference.size)
        axes[0].plot(t, self.reference, label="reference", color="k", lw=1)
        axes[0].plot(t, self.output, label="output", lw=1)
        axes[0].set_ylabel("y")
        axes[0].legend(loc="best")
        axes[1].plot(t, self.output - self.reference, lw=1)
        axes[1].set_ylabel("error")
        axes[1].set_title(f"RMSE {self.rmse:.4g}", fontsize=9)
        axes[2].plot(t, self.input, label="input", lw=1)
        if np.any(self.feedforward):
            axes[2].plot(t, self.feedforward, label="feedforward", lw=1, ls="--")
            axes[2].legend(loc="best")
        axes[2].set_ylabel("u")
        axes[2].set_xlabel("sample")
        fig.tight_layout()
        return fig


def _saturation(value: Any) -> tuple[float, float] | None:
    if value is None:
        return None
    if not isinstance(value, (tuple, list, np.ndarray)) or len(value) != 2:
        raise DataError(f"saturation = {shown(value)}: give the pair (lo, hi) or None")
    lo = check_real(value[0], "saturation[0]")
    hi = check_real(value[1], "saturation[1]")
    if lo > hi:
        raise DataError(f"saturation = ({lo:g}, {hi:g}): give lo <= hi")
    return lo, hi


def _feedforward(compensator: Any, reference: NDArray[np.float64], state: CascadeState | SandwichState | None) -> NDArray[np.float64]:
    if compensator is None:
        return np.zeros_like(reference)
    if isinstance(compensator, Compensator):
        comp = copy.deepcopy(compensator)  # the caller's compensator keeps its state
        d = min(comp.delay, reference.size)
        return comp.run(np.concatenate([reference[d:], np.full(d, reference[-1])]))
    if isinstance(compensator, (CascadeModel, SandwichModel)):
        same_kind = state is not None and isinstance(state, CascadeState) == isinstance(compensator, CascadeModel)
        try:
            start = state if same_kind else None
            return compensate(compensator, reference, initial_state=start)
        except DataError as exc:
            if start is None or "state" not in str(exc):
                raise
            return compensate(compensator, reference)  # the plant's state does not fit the model's orders
    raise DataError(f"compensator must be None, a Compensator or a model, got {type(compensator).__name__}")


def closed_loop(
    plant: Chain,
    reference: ArrayLike,
    *,
    kp: float,
    ki: float = 0.0,
    kd: float = 0.0,
    compensator: Compensator | Chain | None = None,
    saturation: tuple[float, float] | None = None,
    initial_state: CascadeState | SandwichState | None = None,
    warmup: int = 0,
) -> ClosedLoopResult:
    """Simulate a discrete PID loop around a plant model, optionally with feedforward compensation.

    The controller sees the output one sample late, as a digital controller does, and
    compares it with the reference of that sample: e(t) = r(t-1) - y(t-1) (r(0) taken as
    y(0)), so a feedforward that makes y follow r leaves e = 0, and
    u(t) = u_ff(t) + kp e(t) + ki sum e + kd (e(t) - e(t-1)),
    clamped to ``saturation`` (the integral then stops growing in the clamped direction).
    u_ff is the feedforward of ``compensator`` (:func:`compensate`; a model is compensated
    from the plant's initial state if it fits, else from its rest state; a
    :class:`Compensator` continues from its state, left unchanged). One loop in the Rust core.

    Parameters
    ----------
    plant : CascadeModel or SandwichModel
        The system controlled (e.g. the true model in a study of an identified compensator).
    reference : array_like
        The reference r(t), 1-D, finite.
    kp : float
        Proportional gain.
    ki : float, default 0.0
        Integral gain (per sample).
    kd : float, default 0.0
        Derivative gain (per sample).
    compensator : Compensator, CascadeModel or SandwichModel, optional
        The feedforward's source; None for feedback alone.
    saturation : (float, float), optional
        Input limits (lo, hi).
    initial_state : CascadeState or SandwichState, optional
        The plant's state before the first sample (default its rest state).
    warmup : int, default 0
        Samples at the start left out of the result's ``rmse``.

    Returns
    -------
    ClosedLoopResult
        Reference, output, input, feedforward and the RMSE.

    Raises
    ------
    ModelError
        If ``plant`` is not a cascade or sandwich, or the loop diverges.
    DataError
        If the reference is not finite, a gain is not finite, the saturation is not a pair
        lo <= hi, the state does not fit the plant or ``compensator`` has a wrong type.

    Examples
    --------
    >>> import numpy as np
    >>> import backlashid as bid
    >>> plant = bid.example1()
    >>> r = 0.8 * np.sin(0.02 * np.arange(1000))
    >>> pi = bid.closed_loop(plant, r, kp=0.3, ki=0.1)
    >>> both = bid.closed_loop(plant, r, kp=0.3, ki=0.1, compensator=plant)
    >>> bool(both.rmse < pi.rmse / 10)
    True
    """
    native, state = native_chain(plant, initial_state, "plant")
    r = check_scale(_reference(reference), "reference")  # a loop's squared errors of a 1e160 reference overflow
    k_p, k_i, k_d = (check_real(v, name) for v, name in ((kp, "kp"), (ki, "ki"), (kd, "kd")))
    limits = _saturation(saturation)
    ff = _feedforward(compensator, r, initial_state)
    u, y = _core.closed_loop(native, state, r, ff, k_p, k_i, k_d, limits)
    start = check_warmup(warmup, r.size)
    with np.errstate(over="ignore"):
        error = rmse(r, y, warmup=start)
    if not np.isfinite(error):  # the output is finite but its squares overflow: the loop diverged
        raise ModelError(f"the closed loop diverges (its output reaches {np.max(np.abs(y)):.3g}): lower the gains or give a saturation")
    return ClosedLoopResult(reference=r.copy(), output=y, input=u, feedforward=ff, rmse=error, warmup=start)
