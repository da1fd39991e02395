"""Models: the general backlash (eq 1-15), the linear block (eq 16 / 29), the cascade (Fig. 2)
and sandwich (Fig. 3) chains built from them, and their dict / JSON form.

Every model is frozen, simulated sample by sample in the Rust core, and round-trips through
``to_dict`` / ``to_json`` and :func:`model_from_dict` / :func:`model_from_json`.
"""

from __future__ import annotations

from ._backlash import BacklashState, BranchCheck, GeneralBacklash, SwitchingSignals
from ._cascade import CascadeModel, CascadeSimulation, CascadeState
from ._export_c import to_c
from ._export_python_control import to_python_control
from ._linear import LinearBlock
from ._prediction import ParameterCovariance, Prediction, sample_band
from ._sandwich import SandwichModel, SandwichSimulation, SandwichState
from ._serialization import Model, check_model, model_from_dict, model_from_json
from ._state_vector import state_from_vector, state_names, state_vector

__all__ = [
    "BacklashState",
    "BranchCheck",
    "CascadeModel",
    "CascadeSimulation",
    "CascadeState",
    "GeneralBacklash",
    "LinearBlock",
    "Model",
    "ParameterCovariance",
    "Prediction",
    "SandwichModel",
    "SandwichSimulation",
    "SandwichState",
    "SwitchingSignals",
    "check_model",
    "model_from_dict",
    "model_from_json",
    "sample_band",
    "state_from_vector",
    "state_names",
    "state_vector",
    "to_c",
    "to_python_control",
]
