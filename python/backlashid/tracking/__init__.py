"""Online identification: track a cascade's parameters sample by sample (issue 20).

The paper motivates the general backlash by wear ("backlash in gears ... can change with
time and wear"); :class:`Tracker` follows a cascade whose parameters drift, one block of
samples at a time, with a state of fixed size whatever the record length (picklable: resume
later or ship it to a worker), and raises an :class:`Alarm` when the dead-band width
c_L + c_R changes. :func:`track` runs it over a whole record. The per-sample work (the
recursive prediction-error or least-squares update, the detector) runs in the Rust core
(rust/core/src/tracking).
"""

from __future__ import annotations

from ._result import Alarm, TrackResult
from ._tracker import Tracker, track

__all__ = ["Alarm", "TrackResult", "Tracker", "track"]
