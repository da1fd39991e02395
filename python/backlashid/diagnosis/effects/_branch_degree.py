"""branch_degree: branches of degree n + 2 (eq 4-5 with two more terms, from 0)."""

from __future__ import annotations

from typing import Any

from ...identify import Structure
from ._base import Augmentation, StructureEffect

AUGMENTATION = Augmentation("branch_degree", ("extra_degree",), (0,), "branches of degree n + 2 (higher terms from 0)")


class BranchDegree(StructureEffect, rank=5, augmentation=AUGMENTATION, simulated=False):
    """Branches of two more degrees than the nominal ones."""

    extra = {"extra_degree": 2.0}
    n_extra = 4

    def bigger(self, s: Structure) -> Structure:
        """Degree n + 2."""
        return Structure(s.na, s.nb, s.degree + 2, s.nr, s.ns)

    def first_terms(self, est: Any, h: float) -> list[tuple[list[float], list[float], list[float], list[float]]]:
        """The next power of each branch."""
        out = []
        for side in (0, 1):
            m_l, m_r = est.m_left + [0.0], est.m_right + [0.0]
            (m_l if side == 0 else m_r)[-1] = h
            out.append((est.a, est.b, m_l, m_r))
        return out
