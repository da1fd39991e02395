"""Sim-to-real gap diagnosis: given a fitted model (cascade, sandwich, input backlash) and new data, where the simulation error
lies, which unmodelled effect causes it, and how far adding that effect shrinks it.

:func:`diagnose` runs the residual analyses (:mod:`backlashid.diagnosis.analyses`), screens and
refits every candidate of the effect catalogue (:mod:`backlashid.diagnosis.effects`) and returns
a :class:`DiagnosisReport`.
"""

from __future__ import annotations

from ._dashboard import plot_diagnosis
from ._diagnose import default_warmup, diagnose, estimated_start, held_state
from ._report import Candidate, CompositionStep, DiagnosisDetails, DiagnosisReport
from .effects import EFFECTS, REGISTRY, Effect, fit_effect, screen

__all__ = [
    "Candidate",
    "CompositionStep",
    "DiagnosisDetails",
    "DiagnosisReport",
    "EFFECTS",
    "Effect",
    "REGISTRY",
    "default_warmup",
    "diagnose",
    "estimated_start",
    "fit_effect",
    "held_state",
    "plot_diagnosis",
    "screen",
]
