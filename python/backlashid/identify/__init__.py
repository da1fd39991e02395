"""Identification: from measured input/output data to a model with standard errors.

The paper's iterative algorithms (Section 3, eq 17-28, and Section 4, eq 29-36) run first,
each iteration one call into the Rust core; an output-error Levenberg-Marquardt refinement with
exact sensitivities then removes their bias under noise. Also here: the parameter layout
(:class:`Structure`), the Wiener-Hammerstein fit, validation metrics and the scaling of
measured records to model units.
"""

from __future__ import annotations

from ._fit import FitResult, fit_cascade, fit_sandwich
from ._hammerstein import as_hammerstein, fit_hammerstein_backlash, hammerstein_backlash
from ._metrics import Metrics, evaluate, fit_percent, nrmse, one_step_prediction, rmse
from ._refine import OutputErrorFit, levenberg_marquardt
from ._scaling import Scaling, evaluate_scaled, simulate_scaled
from ._selection import StructureSelection, select_structure
from ._state import estimate_state, model_state, refine_values, simulate_from_samples
from ._structure import Estimate, Structure, normalise
from ._wiener_hammerstein import LinearBaseline, WienerHammersteinFit, fit_wiener_hammerstein, wiener_hammerstein_model

__all__ = [
    "Estimate",
    "FitResult",
    "LinearBaseline",
    "Metrics",
    "OutputErrorFit",
    "Scaling",
    "Structure",
    "StructureSelection",
    "WienerHammersteinFit",
    "as_hammerstein",
    "evaluate",
    "estimate_state",
    "evaluate_scaled",
    "fit_cascade",
    "fit_hammerstein_backlash",
    "fit_percent",
    "fit_sandwich",
    "fit_wiener_hammerstein",
    "hammerstein_backlash",
    "levenberg_marquardt",
    "model_state",
    "nrmse",
    "normalise",
    "one_step_prediction",
    "refine_values",
    "rmse",
    "select_structure",
    "simulate_from_samples",
    "simulate_scaled",
    "wiener_hammerstein_model",
]
