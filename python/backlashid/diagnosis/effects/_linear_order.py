"""linear_order: a linear block of orders na + 1, nb + 1."""

from __future__ import annotations

from ... import _core
from ...identify import Structure
from ._base import Array, AugmentedModel, Effect, Problem, ScreenContext
from ._branch_degree import fit_bigger

STEP = 1e-4  # finite-difference step of the screening


class LinearOrder(Effect):
    """A linear block of one more order in each polynomial."""

    name = "linear_order"
    rank = 6
    parameters = ("extra_order",)
    zero = (0,)
    description = "linear block of orders na + 1, nb + 1"
    simulated = False  # a bigger structure, not a term of the simulation

    def fit(self, prob: Problem, theta0: Array) -> AugmentedModel:
        """Refit in the structure of orders na + 1, nb + 1."""
        s = prob.structure
        bigger, theta, _ = fit_bigger(self, prob, theta0, Structure(s.na + 1, s.nb + 1, s.degree))
        return AugmentedModel(self.name, bigger, theta, {"extra_order": 1.0}, n_extra=2)

    def directions(self, screen: ScreenContext) -> list[Array]:
        """Derivatives in the next a and the next b coefficient."""
        est = screen.structure.unpack(screen.theta)
        out = []
        for a, b in ((est.a + [STEP], est.b + [0.0]), (est.a + [0.0], est.b + [STEP])):
            y = _core.simulate_augmented(a, b, est.c_left, est.c_right, est.m_left, est.m_right, screen.u, t0=screen.t0)
            out.append((y - screen.y_sim) / STEP)
        return out
