"""The application layer: reading records (CSV, NPZ, MAT), figures, fleets of fits on Dask, and
the ``backlashid`` command line (``backlashid.app._cli``).
"""

from __future__ import annotations

from ..diagnosis import plot_diagnosis
from ..plotting import plot_branches_comparison, plot_characteristic, plot_residuals, plot_simulation, plot_trajectories
from ._io import Record, Selection, concatenate, decimate, load_record, parse_range, read_signals, select_records, split_fraction
from ._parallel import diagnose_many, fit_many, track_many

__all__ = [
    "Record",
    "Selection",
    "concatenate",
    "decimate",
    "diagnose_many",
    "fit_many",
    "load_record",
    "parse_range",
    "plot_branches_comparison",
    "plot_characteristic",
    "plot_diagnosis",
    "plot_residuals",
    "plot_simulation",
    "plot_trajectories",
    "read_signals",
    "select_records",
    "split_fraction",
    "track_many",
]
