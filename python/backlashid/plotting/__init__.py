"""Figures of the results that draw themselves (``FitResult.plot``, ``Metrics.plot``,
``WienerHammersteinFit.plot``) and of records and models: trajectories of the iterations,
backlash characteristics, simulations, residuals. Below the result classes that call them
(python-control's ``timeplot`` beside ``TimeResponseData.plot`` is the pattern); also reached
as ``backlashid.app.plot_*``. Needs matplotlib (``pip install backlashid[plot]``).
"""

from __future__ import annotations

from ._figures import plot_branches_comparison, plot_characteristic, plot_residuals, plot_simulation, plot_trajectories

__all__ = ["plot_branches_comparison", "plot_characteristic", "plot_residuals", "plot_simulation", "plot_trajectories"]
