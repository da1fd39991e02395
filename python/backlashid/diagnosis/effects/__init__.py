"""The effect catalogue: unmodelled effects a fitted cascade may miss, each an augmentation of
the nominal model that is screened, refitted and scored by :func:`backlashid.diagnose`.
"""

from __future__ import annotations

from ._catalogue import AUGMENTATIONS, EFFECTS, Augmentation, AugmentedModel, Screening, fit_effect, screen

__all__ = ["AUGMENTATIONS", "EFFECTS", "Augmentation", "AugmentedModel", "Screening", "fit_effect", "screen"]
