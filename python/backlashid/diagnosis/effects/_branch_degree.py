"""branch_degree: branches of degree n + 2 (eq 4-5 with two more terms, from 0)."""

from __future__ import annotations

from ... import _core
from ...identify import Structure
from ._base import Array, AugmentedModel, Effect, Problem, ScreenContext

STEP = 1e-4  # finite-difference step of the screening


def fit_bigger(effect: Effect, prob: Problem, theta0: Array, bigger: Structure) -> tuple[Structure, Array, float]:
    """Refit in a larger structure that embeds the nominal one (new terms start at 0)."""
    import numpy as np

    s = prob.structure
    old = dict(zip(s.names, theta0))
    start = np.array([old.get(name, 0.0) for name in bigger.names])
    big = Problem(bigger, prob.u, prob.y, prob.warmup, prob.t0)
    theta, _, cost = effect._refit(big, start, np.zeros(0), np.zeros(0), np.zeros(0), max_iter=40, names=())
    return bigger, theta, cost


class BranchDegree(Effect):
    """Branches of two more degrees than the nominal ones."""

    name = "branch_degree"
    rank = 5
    parameters = ("extra_degree",)
    zero = (0,)
    description = "branches of degree n + 2 (higher terms from 0)"
    simulated = False  # a bigger structure, not a term of the simulation

    def fit(self, prob: Problem, theta0: Array) -> AugmentedModel:
        """Refit in the structure of degree n + 2."""
        s = prob.structure
        bigger, theta, _ = fit_bigger(self, prob, theta0, Structure(s.na, s.nb, s.degree + 2))
        return AugmentedModel(self.name, bigger, theta, {"extra_degree": 2.0}, n_extra=4)

    def directions(self, screen: ScreenContext) -> list[Array]:
        """Derivatives in the next power of each branch."""
        est = screen.structure.unpack(screen.theta)
        out = []
        for side in (0, 1):
            m_l, m_r = est.m_left + [0.0], est.m_right + [0.0]
            (m_l if side == 0 else m_r)[-1] = STEP
            y = _core.simulate_augmented(est.a, est.b, est.c_left, est.c_right, m_l, m_r, screen.u, t0=screen.t0)
            out.append((y - screen.y_sim) / STEP)
        return out
