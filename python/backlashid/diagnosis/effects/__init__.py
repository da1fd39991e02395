"""The effect catalogue: unmodelled effects a fitted cascade may miss, each an augmentation of
the nominal model that is screened, refitted and scored by :func:`backlashid.diagnose`.

One module per effect, each an :class:`Effect` subclass; :data:`REGISTRY` finds them and
:data:`EFFECTS` lists their names in ranking order.
"""

from __future__ import annotations

from ._base import Augmentation, AugmentedModel, Effect, Screening
from ._registry import AUGMENTATIONS, EFFECTS, REGISTRY, fit_effect, screen

__all__ = ["AUGMENTATIONS", "EFFECTS", "REGISTRY", "Augmentation", "AugmentedModel", "Effect", "Screening", "fit_effect", "screen"]
