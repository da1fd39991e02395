"""linear_order: a linear block of orders na + 1, nb + 1."""

from __future__ import annotations

from typing import Any

from ...identify import Structure
from ._base import Augmentation, StructureEffect

AUGMENTATION = Augmentation("linear_order", ("extra_order",), (0,), "linear block of orders na + 1, nb + 1")


class LinearOrder(StructureEffect, rank=6, augmentation=AUGMENTATION, simulated=False):
    """A linear block of one more order in each polynomial."""

    extra = {"extra_order": 1.0}
    n_extra = 2

    def bigger(self, s: Structure) -> Structure:
        """Orders na + 1, nb + 1 of the (input) linear block; a sandwich's output block kept."""
        return Structure(s.na + 1, s.nb + 1, s.degree, s.nr, s.ns)

    def first_terms(self, est: Any, h: float) -> list[tuple[list[float], list[float], list[float], list[float]]]:
        """The next a and the next b coefficient."""
        return [(est.a + [h], est.b + [0.0], est.m_left, est.m_right), (est.a + [0.0], est.b + [h], est.m_left, est.m_right)]
