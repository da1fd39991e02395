"""backlashid: identification of systems with general backlash.

Models of Vörös, "Modeling and identification of nonlinear cascade and sandwich systems with
general backlash": :class:`GeneralBacklash` (eq 1-15), :class:`LinearBlock` (eq 16 / 29),
:class:`CascadeModel` (Fig. 2) and :class:`SandwichModel` (Fig. 3), simulated in Rust.
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("backlashid")
except PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0"

from .backlash import BranchCheck, GeneralBacklash, SwitchingSignals
from .diagnosis import DiagnosisReport, diagnose
from .effects import EFFECTS, fit_effect
from .errors import BacklashIdError, DataError, ModelError, NotConvergedError, NotIdentifiableError
from .examples import ExampleData, example1, example2, example_data, shared_data_folder
from .identification import FitResult, fit_cascade, fit_sandwich
from .linear import LinearBlock
from .metrics import Metrics, evaluate
from .models import (
    CascadeModel,
    CascadeSimulation,
    CascadeState,
    SandwichModel,
    SandwichSimulation,
    SandwichState,
    model_from_dict,
    model_from_json,
)
from .parallel import diagnose_many, fit_many
from .wiener_hammerstein import LinearBaseline, WienerHammersteinFit, fit_wiener_hammerstein, wiener_hammerstein_model

__all__ = [
    "BacklashIdError",
    "BranchCheck",
    "CascadeModel",
    "CascadeSimulation",
    "CascadeState",
    "DiagnosisReport",
    "EFFECTS",
    "DataError",
    "ExampleData",
    "FitResult",
    "GeneralBacklash",
    "LinearBaseline",
    "LinearBlock",
    "Metrics",
    "ModelError",
    "NotConvergedError",
    "NotIdentifiableError",
    "SandwichModel",
    "SandwichSimulation",
    "SandwichState",
    "SwitchingSignals",
    "WienerHammersteinFit",
    "__version__",
    "diagnose",
    "example1",
    "example2",
    "evaluate",
    "example_data",
    "fit_cascade",
    "fit_effect",
    "diagnose_many",
    "fit_many",
    "fit_sandwich",
    "model_from_dict",
    "model_from_json",
    "fit_wiener_hammerstein",
    "wiener_hammerstein_model",
    "shared_data_folder",
]
