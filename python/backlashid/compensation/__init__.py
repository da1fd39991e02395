"""Using the model: cancel its backlash with a feedforward compensator (issue 19).

:func:`compensate` returns the input that makes a cascade's or sandwich's output follow a
reference, through the inverse of each block (the backlash inverse of
:meth:`~backlashid.GeneralBacklash.inverse` and a stable inverse of the linear blocks);
:class:`Compensator` does it one sample at a time for use inside a control loop, and
:func:`closed_loop` simulates a PID loop around a plant model with and without it. Every
per-sample loop runs in the Rust core.
"""

from __future__ import annotations

from ._closed_loop import ClosedLoopResult, closed_loop
from ._compensator import Compensator, compensate

__all__ = ["ClosedLoopResult", "Compensator", "closed_loop", "compensate"]
