"""creep: slow relaxation of the output after the input stops changing (piezo actuators): the
output so far f passes through slow first-order modes, y = f + sum_k g_k (c_k - f),
c_k(t) = p_k c_k(t-1) + (1 - p_k) f(t), p_k = exp(-1 / T_k), T_k = exp(l_k) samples in
[10, 1e5]: after a step the output jumps to (1 - sum g_k) of it and creeps to it. Rust:
``rust/core/src/effects/creep.rs``."""

from __future__ import annotations

import math

import numpy as np

from ..._numerics import lstsq, r_factor
from ._base import Array, Augmentation, Effect, Fitted, RefitRecords, ScreenContext

N_MODES = 2  # creep modes
T_MIN, T_MAX = 10.0, 1e5  # time constants' range in samples (the core's domain)
N_GRID = 10  # time constants of the start grid

AUGMENTATION = Augmentation(
    "creep",
    tuple(n for k in range(1, N_MODES + 1) for n in (f"g_{k}", f"l_{k}")),
    tuple(v for k in range(N_MODES) for v in (0.0, math.log(30.0 * 10**k))),
    "y = f + sum_k g_k (c_k - f), c_k f through a unit-DC first-order mode of time constant exp(l_k) samples",
)


class Creep(Effect, rank=13, augmentation=AUGMENTATION):
    """Slow first-order modes on the output: it creeps after the input stops changing."""

    def bounds(self, prob: RefitRecords) -> tuple[Array, Array]:
        """-0.5 <= g_k <= 0.9; ln 10 <= l_k <= ln 1e5."""
        return np.array([-0.5, math.log(T_MIN)] * N_MODES), np.array([0.9, math.log(T_MAX)] * N_MODES)

    def refit(self, prob: RefitRecords, theta0: Array) -> Fitted:
        """The shares enter linearly at fixed time constants: pick the pairs of time constants
        (a grid from 10 samples to ten records) whose modes explain most of the nominal
        residual, then refit everything from the best three."""
        y_nom = prob.simulate(theta0)
        r0 = (prob.y - y_nom)[prob.warmup :]
        taus = np.geomspace(T_MIN, min(T_MAX, 10.0 * prob.u.size + T_MIN), N_GRID)
        idle = {f"{n}_{k}": v for k in range(2, N_MODES + 1) for n, v in (("g", 0.0), ("l", math.log(T_MIN)))}
        modes = [(prob.simulate(theta0, self.core({"g_1": 1.0, "l_1": math.log(tau), **idle})) - y_nom)[prob.warmup :] for tau in taus]
        # every pair's least squares on the R factor of [modes | residual] (N_GRID + 1 rows)
        r = r_factor(np.column_stack([*modes, r0]))
        target = r[:, -1]
        lb, ub = self.bounds(prob)
        pairs = []
        for i in range(N_GRID):
            for j in range(i + 1, N_GRID):
                a = r[:, [i, j]]
                g = np.clip(lstsq(a, target), lb[0], ub[0])
                rss = float(np.sum((target - a @ g) ** 2))
                pairs.append((rss, (float(g[0]), math.log(taus[i]), float(g[1]), math.log(taus[j]))))
        pairs.sort()
        return self._multi_start(prob, theta0, [(np.array(e0), {}) for _, e0 in pairs[:3]], lb, ub)

    def directions(self, screen: ScreenContext) -> list[Array]:
        """One mode of unit share at time constants of 30 and 300 samples."""
        return [screen.change((("creep", (1.0, math.log(tau))),)) for tau in (30.0, 300.0)]
