"""backlashid: identification of systems with general backlash.

Models of Vörös, "Modeling and identification of nonlinear cascade and sandwich systems with
general backlash": :class:`GeneralBacklash` (eq 1-15), :class:`LinearBlock` (eq 16 / 29),
:class:`CascadeModel` (Fig. 2) and :class:`SandwichModel` (Fig. 3), simulated in Rust.

The top-level names, by what they are for (``import backlashid as bid``):

**Models** (:mod:`backlashid.models`): :class:`GeneralBacklash`, :class:`LinearBlock`,
:class:`CascadeModel`, :class:`SandwichModel`; their states and simulations
(:class:`BacklashState`, :class:`CascadeState`, :class:`SandwichState`, :class:`CascadeSimulation`,
:class:`SandwichSimulation`, :class:`SwitchingSignals`, :class:`BranchCheck`);
:func:`model_from_dict`, :func:`model_from_json`.

**Identification** (:mod:`backlashid.identify`): :func:`fit_cascade`, :func:`fit_sandwich`,
:func:`fit_hammerstein_backlash`, :func:`fit_wiener_hammerstein` (with
:func:`wiener_hammerstein_model`), :func:`select_structure`, :func:`fit_many`; their results
:class:`FitResult`, :class:`StructureSelection`, :class:`WienerHammersteinFit`,
:class:`LinearBaseline`.

**Evaluation and the state a record starts in**: :func:`evaluate` (:class:`Metrics`),
:func:`estimate_state`, :func:`simulate_from_samples`.

**Diagnosis** (:mod:`backlashid.diagnosis`): :func:`diagnose`, :func:`diagnose_many`,
:class:`DiagnosisReport`, the effect catalogue :data:`EFFECTS` and :func:`fit_effect`.

**Using a model**: :func:`compensate`, :class:`Compensator`, :func:`closed_loop`
(:class:`ClosedLoopResult`) from :mod:`backlashid.compensation`; :mod:`backlashid.export` for
python-control and C99; :class:`Tracker`, :func:`track`, :func:`track_many` (:class:`TrackResult`)
from :mod:`backlashid.tracking`.

**Examples and data**: :func:`example1`, :func:`example2`, :func:`example_data`
(:class:`ExampleData`) from :mod:`backlashid.benchmarks`, which also finds the shared benchmark
records (``$BACKLASHID_DATA``, else ``shared/data`` beside a checkout).

**Errors** (:mod:`backlashid.errors`): :class:`BacklashIdError` and its :class:`DataError`,
:class:`ModelError`, :class:`NotIdentifiableError`, :class:`NotConvergedError`; the warning
:class:`FitWarning`.

Below them: :mod:`backlashid.plotting` (the figures the results draw) and :mod:`backlashid.app`
(record files, Dask fleets, the command line). The numerics run in the compiled Rust core,
``backlashid._core``.

Examples
--------
Simulate the paper's Example 1 and identify it from its noisy output:

>>> import backlashid as bid
>>> data = bid.example_data(bid.example1(), 1500, snr=25, seed=0)
>>> result = bid.fit_cascade(data.u, data.noisy, na=2, nb=2, degree=3)
>>> result.converged, sorted(result.parameters)[:4]
(True, ['a1', 'a2', 'b1', 'b2'])
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from .compensation import ClosedLoopResult, Compensator, closed_loop, compensate
from .errors import BacklashIdError, DataError, FitWarning, ModelError, NotConvergedError, NotIdentifiableError
from .identify import (
    FitResult,
    LinearBaseline,
    Metrics,
    StructureSelection,
    WienerHammersteinFit,
    estimate_state,
    evaluate,
    fit_cascade,
    fit_hammerstein_backlash,
    fit_sandwich,
    fit_wiener_hammerstein,
    select_structure,
    simulate_from_samples,
    wiener_hammerstein_model,
)
from .models import (
    BacklashState,
    BranchCheck,
    CascadeModel,
    CascadeSimulation,
    CascadeState,
    GeneralBacklash,
    LinearBlock,
    SandwichModel,
    SandwichSimulation,
    SandwichState,
    SwitchingSignals,
    model_from_dict,
    model_from_json,
)
from .tracking import Tracker, TrackResult, track

if TYPE_CHECKING:  # imported on first use (``__getattr__`` below); named here for type checkers
    from .app import diagnose_many, fit_many, track_many
    from .benchmarks import ExampleData, example1, example2, example_data
    from .diagnosis import EFFECTS, DiagnosisReport, diagnose, fit_effect

    __version__: str

# The diagnosis (scipy.stats, scipy.signal), the benchmarks and the application layer (figures,
# Dask fleets) load when one of their names is first used, so ``import backlashid`` and
# ``backlashid --help`` stay fast; ``backlashid.X`` is the same object either way.
_LAZY = {
    "diagnose_many": "app",
    "fit_many": "app",
    "track_many": "app",
    "ExampleData": "benchmarks",
    "example1": "benchmarks",
    "example2": "benchmarks",
    "example_data": "benchmarks",
    "EFFECTS": "diagnosis",
    "DiagnosisReport": "diagnosis",
    "diagnose": "diagnosis",
    "fit_effect": "diagnosis",
}
_SUBPACKAGES = ("app", "benchmarks", "compensation", "diagnosis", "export", "identify", "models", "plotting", "tracking")


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    elif name == "__version__":
        from ._version import __version__ as value
    elif name in _SUBPACKAGES:
        return importlib.import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value  # found once
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__) | set(_SUBPACKAGES))


__all__ = [
    "BacklashIdError",
    "BacklashState",
    "BranchCheck",
    "CascadeModel",
    "CascadeSimulation",
    "CascadeState",
    "ClosedLoopResult",
    "Compensator",
    "DiagnosisReport",
    "EFFECTS",
    "DataError",
    "ExampleData",
    "FitResult",
    "FitWarning",
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
    "StructureSelection",
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
    "track_many",
    "fit_sandwich",
    "select_structure",
    "estimate_state",
    "simulate_from_samples",
    "fit_hammerstein_backlash",
    "model_from_dict",
    "model_from_json",
    "fit_wiener_hammerstein",
    "wiener_hammerstein_model",
    "closed_loop",
    "compensate",
    "TrackResult",
    "Tracker",
    "track",
]
