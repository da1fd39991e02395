"""Analyses of a simulation residual: where the error lies.

Whiteness and independence tests (:func:`residual_tests`), the error's share per backlash
regime (:func:`regime_shares`), its spectrum against the noise floor
(:func:`frequency_analysis`), its trends and change points over time (:func:`time_analysis`), and
a model of the error in the nominal model's own signals: how much of the gap is predictable, and
from what (:func:`model_error`).
"""

from __future__ import annotations

from ._drift import ChangePoint, TimeAnalysis, time_analysis
from ._model_error import GROUPS, ModelErrorModel, NominalSignals, model_error
from ._regimes import REGIMES, RegimeShare, RegimeShares, regime_masks, regime_shares
from ._residual_tests import TEST_NAMES, CorrelationTest, ResidualTests, residual_tests
from ._spectral import Band, FrequencyAnalysis, frequency_analysis

__all__ = [
    "Band",
    "ChangePoint",
    "CorrelationTest",
    "FrequencyAnalysis",
    "GROUPS",
    "ModelErrorModel",
    "NominalSignals",
    "REGIMES",
    "RegimeShare",
    "RegimeShares",
    "ResidualTests",
    "TEST_NAMES",
    "TimeAnalysis",
    "frequency_analysis",
    "model_error",
    "regime_masks",
    "regime_shares",
    "residual_tests",
    "time_analysis",
]
