"""Online identification: track a model's parameters sample by sample (issues 20, 33).

The paper motivates the general backlash by wear ("backlash in gears ... can change with
time and wear"); :class:`Tracker` follows a cascade, a sandwich or an input backlash whose
parameters drift, one block of samples at a time, with a state of fixed size whatever the
record length (picklable: resume later or ship it to a worker), and raises an :class:`Alarm`
when the dead-band width changes (a sandwich's referred to the input). A monitor tests the
tracker's own innovations and says when the tracked structure does not explain the data
(:class:`MismatchTest`): a wrong model's wandering estimate is then not taken for wear; and
when the estimate is off the data while the structure may be right ("unsettled").
:func:`track` runs it over a whole record, with a memory taken from the input
(:func:`forgetting_for`: slow ramps need more than the 1000 samples a white input does). The per-sample work (the recursive prediction-error or least-squares update, the
detector, the monitor) runs in the Rust core (rust/core/src/tracking).
"""

from __future__ import annotations

from ._memory import chosen_forgetting, forgetting_for, swing_samples
from ._result import Alarm, MismatchTest, TrackResult
from ._tracker import Tracker, track

__all__ = ["Alarm", "MismatchTest", "TrackResult", "Tracker", "chosen_forgetting", "forgetting_for", "swing_samples", "track"]
