"""Which effect did the nominal cascade miss? ``diagnose`` (issue 4).

1. The nominal model is simulated (free run, from rest) on the validation record; its error
   after the warm-up is the residual the analyses look at (residual tests, regimes, spectrum,
   drift).
2. Every candidate effect is screened by a score test on the estimation record (ordering,
   reported), then refitted together with the nominal parameters on the estimation record
   (``effects.fit_effect``) and scored on the validation record: free-run simulation error
   (one-step prediction error for colored_noise), the fraction of the gap above the noise floor
   it closes, the p-value of its improvement over the nominal model (one-sided paired test on
   the squared errors, Newey-West standard error), and BIC = n ln(MSE) + k ln(n) with k its
   extra parameters.
3. Decision (family-wise level ALPHA, Bonferroni over the candidates):
   - "none" if neither a candidate nor a black-box correction of the residual improves the
     validation error significantly, or if the gap is under 1 % of the noise variance (a
     consistent but immaterial improvement, e.g. a refit that lands nearer the optimum);
   - else the significant deterministic candidate of lowest BIC, if it closes at least half of
     the gap (and, when the nominal residual is a slowly modulated copy of the output, leaves
     no such modulation in its own residual);
   - else colored_noise if no significant deterministic candidate closes a quarter (noise is
     independent of the input), its noise model predicts the residual significantly better,
     and the residual is neither explained by the input (a cross-validated black box of input
     features), nor modulated by the model's output (a drifting gain: prewhitened F-test),
     nor a function of the drive's position (a cogging torque: bin means of x and of the
     output fitted on the estimation record predict the validation residual);
   - else "unexplained".
   Where none of these names a deterministic candidate ("none", colored_noise, "unexplained"),
   quantization is named if the measured outputs of both records lie on one lattice
   {o + k q} (a quantiser after the noise, e.g. the A/D converter; ``effects._quantization.
   lattice``), q read off the data, and its rounding error is material (q^2 / 12 at least
   ``LATTICE_MATERIAL`` of the nominal validation MSE). Such rounding is white-like noise that
   no model of the noise-free output can remove, so it shows in the values, not in the gap.

Caveat: with the floor estimated, the winner's gap closed is 1 by construction whenever it
is the best model of all (the floor is then its own validation MSE); give ``noise_std`` for a
gap closed measured against the true noise.

Noise floor when ``noise_std`` is None: the validation MSE of the best model of the output error
we can fit without knowing the truth, i.e. the smallest of (a) a black-box linear regression
of the nominal residual on lagged inputs, the model's internal signal x and its velocity, powers
of the nominal output, time and output x time, and the residual's own past (fitted on the
estimation record, evaluated on the validation record, so over-fitting cannot lower it), and
(b) every refitted candidate's validation MSE. Both are upper bounds of the white-noise
variance in expectation, so the gap is, if anything, underestimated.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._numerics import lstsq, minimize_bounded
from .._validation import check_flag, check_noise_std, check_seed, check_signals, shown
from ..errors import DataError, ModelError
from ..models import CascadeModel, CascadeState, LinearBlock
from ._report import Candidate, DiagnosisDetails, DiagnosisReport
from .analyses import frequency_analysis, regime_shares, residual_tests, time_analysis
from .effects import EFFECTS, AugmentedModel, fit_effect, screen
from .effects._base import held_past
from .effects._dead_time import MAX_DELAY
from .effects._quantization import lattice

__all__ = ["diagnose", "ALPHA", "CLOSE_ENOUGH", "default_warmup", "estimated_start", "held_state"]

ALPHA = 0.01  # family-wise significance level of "the validation error improved"
CLOSE_ENOUGH = 0.5  # a candidate must close at least this fraction of the gap
MATERIAL = 0.25  # a significant deterministic candidate closing this much rules out colored noise
POSITION_BINS = 32  # bins of x and of y_nom in the test of a position-dependent residual
MATERIAL_GAP = 0.01  # a gap under this fraction of the noise variance is "none", however significant
HAC_LAGS = 20  # Newey-West lags of the paired test
SIGNATURE_Z = 3.0  # |z| of the residual against the effect's change after augmentation
LATTICE_MATERIAL = 0.1  # a lattice's rounding variance q^2 / 12 over this share of the nominal MSE is named
NOT_CONVERGED = "nominal fit did not converge; diagnosed from its best iterate"


Array = NDArray[np.float64]


# -- input checks --------------------------------------------------------------------------------


def _record(pair: Any, name: str) -> tuple[Array, Array]:
    if not isinstance(pair, (tuple, list)) or len(pair) != 2:
        raise DataError(f"{name} must be a pair (u, y) of 1-D signals, e.g. {name}=(u, y)")
    u, y = check_signals((f"{name}[0] (u)", pair[0]), (f"{name}[1] (y)", pair[1]))
    return u, y


def default_warmup(model: CascadeModel, n: int) -> int:
    """The default warm-up of a record: samples until the model forgets its start.

    The slowest pole's transient decays to 1e-4, plus the block's memory and the longest dead
    time searched; at least 20, at most n // 5.

    Parameters
    ----------
    model : CascadeModel
        The nominal cascade.
    n : int
        Samples of the shorter record.

    Returns
    -------
    int
        The warm-up in samples.

    Examples
    --------
    >>> import backlashid as bid
    >>> from backlashid.diagnosis import default_warmup
    >>> default_warmup(bid.example1(), 100)
    20
    """
    rho = model.linear.spectral_radius()
    settle = math.ceil(math.log(1e-4) / math.log(rho)) if 0.0 < rho < 1.0 else 0
    w = settle + model.linear.na + model.linear.nb + MAX_DELAY
    return int(min(max(w, 20), n // 5))


def _without_feedthrough(model: CascadeModel, u_e: Array, u_v: Array) -> tuple[CascadeModel, Array, Array]:
    """A block with a lag-0 term a_0 u(t) is the same coefficients at lags 1..na+1 driven by the
    input one sample ahead, u'(t) = u(t + 1): the augmentations are written for the latter. The
    validation record follows the estimation record, so u_e' ends with u_v[0]; the last sample of
    u_v' (a repeat) would only reach an output after the record. The outputs are the same but
    for the start (a_0 u(0) becomes part of the initial state), which the warm-up absorbs."""
    shifted = CascadeModel(LinearBlock(model.linear.a, model.linear.b), model.backlash)
    return shifted, np.r_[u_e[1:], u_v[:1]], np.r_[u_v[1:], u_v[-1:]]


INITIAL_STATES = ("estimate", "rest")
MEMORY_GRID = 33  # backlash memories tried before the 1-D refinement
MEMORY_PREFIX = 256  # first prefix of the record tried for the memory search (doubled until settled)


def held_state(model: CascadeModel, u0: float, y_prev: float, hold: int | None = None) -> CascadeState:
    """The cascade after the input was held at u0.

    The linear block (16) after the input u0 held for ``hold`` samples from rest, or for ever
    (its equilibrium x = sum a / (1 + sum b) u0), and the backlash memory y_prev. ``diagnose``
    holds for the estimation record's length: the equilibrium of a slow pole almost cancelled
    by a zero at z = 1 is a static gain the records do not determine.

    Parameters
    ----------
    model : CascadeModel
        The cascade.
    u0 : float
        The input held before the record.
    y_prev : float
        The backlash memory y(0).
    hold : int, optional
        Samples the input is held for, from rest; default for ever (the equilibrium).

    Returns
    -------
    CascadeState
        The state to start a simulation from.

    Raises
    ------
    ModelError
        If the linear block has a pole at z = 1 and ``hold`` is None (no equilibrium).

    Examples
    --------
    >>> import backlashid as bid
    >>> from backlashid.diagnosis import held_state
    >>> held_state(bid.example1(), 0.0, 0.5).y_prev
    0.5
    """
    u_past, x_past = held_past(model.linear, float(u0), hold)
    return CascadeState(u_past=tuple(u_past), x_past=tuple(x_past), y_prev=float(y_prev))


def estimated_start(simulate: Any, u: Array, y: Array, memory_range: tuple[float, float]) -> tuple[Array, float]:
    """A simulation of the record from the backlash memory y(0) that best fits it.

    ``simulate(u, y_prev, True)`` is tried on a grid over the output's range, then a bounded
    1-D search around the best point. The memory acts only until the backlash first moves,
    which may be long after the warm-up, so it is fitted on the whole record (one parameter for
    every model alike, as initial conditions are estimated for validation in common practice);
    fitted on the warm-up alone, its error persists over a long hold and the paired test would
    read the differences between models' memories as significant.

    Once the backlash has moved, the simulation no longer depends on the memory: the search runs
    on the shortest prefix (``MEMORY_PREFIX`` samples, doubled) over whose second half the
    simulations from both ends of the range agree exactly. The backlash orders its outputs by
    their memories, so every memory in between agrees there too, and the record's cost differs
    between memories only within the prefix.

    Parameters
    ----------
    simulate : callable
        ``simulate(u, y_prev, held)`` -> output of the record.
    u : ndarray
        Input of the record.
    y : ndarray
        Measured output of the record.
    memory_range : tuple of float
        (lo, hi), the range of memories searched.

    Returns
    -------
    output : ndarray
        The simulation from the best memory.
    y_prev : float
        That memory.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> from backlashid.diagnosis import estimated_start, held_state
    >>> m = bid.example1()
    >>> u = np.r_[np.zeros(50), np.sin(0.05 * np.arange(150))]
    >>> def sim(u, y0, held):
    ...     return m.simulate(u, initial_state=held_state(m, u[0], y0))
    >>> _, y0 = estimated_start(sim, u, sim(u, 0.3, True), (-1.0, 1.0))
    >>> round(y0, 6)
    0.3
    """

    lo, hi = memory_range
    m = _settled(simulate, u, lo, hi)
    u_m, y_m = u[:m], y[:m]

    def cost(y0: float) -> float:
        r = y_m - simulate(u_m, y0, True)
        return float(r @ r)

    # the cost is flat where the memory lies outside the dead band (it is clamped onto a branch
    # at once) and quadratic inside: a coarse grid, a fine grid around its best point, then Brent
    best, best_cost = lo, math.inf
    for _ in range(2):
        grid = np.linspace(lo, hi, MEMORY_GRID)
        costs = [cost(g) for g in grid]
        k = int(np.argmin(costs))
        if costs[k] < best_cost:
            best, best_cost = float(grid[k]), costs[k]
        lo, hi = float(grid[max(k - 1, 0)]), float(grid[min(k + 1, grid.size - 1)])
    x, fx, converged = minimize_bounded(cost, lo, hi, xatol=1e-9 * max(hi - lo, 1e-12))
    if converged and fx < best_cost:
        best = float(x)
    return simulate(u, best, True), best


def _settled(simulate: Any, u: Array, lo: float, hi: float) -> int:
    """Length of the shortest prefix (MEMORY_PREFIX doubled) over whose second half the
    simulations from the memories lo and hi agree exactly; the record's length if none."""
    m = MEMORY_PREFIX
    while m < u.size:
        if np.array_equal(simulate(u[:m], lo, True)[m // 2 :], simulate(u[:m], hi, True)[m // 2 :]):
            return m
        m *= 2
    return int(u.size)


# -- statistics ----------------------------------------------------------------------------------


def _paired_p(r0: Array, r1: Array) -> float:
    """One-sided p-value of E[r0^2 - r1^2] > 0 (Newey-West standard error)."""
    d = r0 * r0 - r1 * r1
    n = d.size
    dc = d - d.mean()
    var = float(dc @ dc) / n
    for k in range(1, min(HAC_LAGS, n - 1) + 1):
        var += 2.0 * (1.0 - k / (HAC_LAGS + 1)) * float(dc[k:] @ dc[:-k]) / n
    if var <= 0.0:
        return 0.0 if d.mean() > 0 else 1.0
    from scipy import stats  # imported when first needed: import backlashid stays fast

    return float(stats.norm.sf(d.mean() / math.sqrt(var / n)))


def _lag(s: Array, k: int) -> Array:
    return np.concatenate([np.zeros(k), s[:-k]]) if k else s


def _features(u: Array, x: Array, y_nom: Array, resid: Array | None, t0: float, total: float) -> Array:
    """Regressors of the black-box residual model (see the module docstring); x is the nominal
    linear block's output."""
    dx = x - _lag(x, 1)
    tau = (t0 + np.arange(u.size)) / total
    cols = [np.ones(u.size), tau, y_nom * tau, y_nom, y_nom**2, y_nom**3, dx, np.sign(dx), np.abs(dx)]
    cols += [_lag(u, k) for k in range(0, 11)] + [_lag(x, k) for k in range(0, 3)]
    if resid is not None:
        cols += [_lag(resid, k) for k in range(1, 5)]
    return np.column_stack(cols)


def _black_box(u_e, x_e, y_e, ynom_e, u_v, x_v, y_v, ynom_v, warmup, n_est, with_past):
    """Validation residual of the black-box residual model fitted on the estimation record."""
    total = float(n_est + u_v.size)
    r_e, r_v = y_e - ynom_e, y_v - ynom_v
    a_e = _features(u_e, x_e, ynom_e, r_e if with_past else None, 0.0, total)[warmup:]
    a_v = _features(u_v, x_v, ynom_v, r_v if with_past else None, n_est, total)[warmup:]
    scale = np.maximum(np.std(a_e, axis=0), 1e-12)
    coef = lstsq(a_e / scale, r_e[warmup:])
    return r_v[warmup:] - (a_v / scale) @ coef


def _modulation_p(residual: Array, y_nom: Array, phi: Array, order: int = 4) -> float:
    """Is the residual a slowly modulated copy of the model's output (a drifting gain), rather
    than noise independent of the input? F-test of the residual on y_nom(t) P_k(tau), k = 1..order
    (Legendre polynomials over the record), both prewhitened by the AR noise model A(q) so that
    colored noise leaves the test valid (GLS)."""
    n = residual.size
    tau = np.linspace(-1.0, 1.0, n)
    basis = np.polynomial.legendre.legvander(tau, order)[:, 1:]
    z = basis * y_nom[:, None]

    def whiten(s: Array) -> Array:
        out = s.copy()
        for k, c in enumerate(phi, 1):
            out[k:] -= c * s[:-k]
        return out[phi.size :]

    e, zw = whiten(residual), whiten(z)
    zw = np.column_stack([zw, np.ones(e.size)])
    coef = lstsq(zw, e)
    rss1 = float(np.sum((e - zw @ coef) ** 2))
    rss0 = float(np.sum((e - e.mean()) ** 2))
    m, dof = order, e.size - order - 1
    if rss1 <= 0.0 or dof <= 0:
        return 1.0
    from scipy import stats

    return float(stats.f.sf(((rss0 - rss1) / m) / (rss1 / dof), m, dof))


def _position_bins(x: Array, y_nom: Array, edges: tuple[Array, Array]) -> Array:
    """Indicators of the bins of x and of y_nom (the first bin of each is the base), and ones."""
    cols = [np.ones(x.size)]
    for s, e in zip((x, y_nom), edges):
        idx = np.searchsorted(e, s, side="right")
        cols.append((idx[:, None] == np.arange(1, e.size + 1)[None, :]).astype(float))
    return np.column_stack(cols)


def _position_p(x_e: Array, ynom_e: Array, r_e: Array, x_v: Array, ynom_v: Array, r_v: Array, bins: int = POSITION_BINS) -> float:
    """Is the residual a function of where the drive is, rather than noise? The nominal
    residual's mean in each quantile bin of x(t) and of y_nom(t) (a cogging torque, a
    position-dependent load: periodic or irregular in the position, so bins and not a
    polynomial), fitted on the estimation record, must predict the validation residual
    (paired test of the squared errors): cross-validated, so slow colored noise, whose bin means
    on one record say nothing of the next, leaves the test valid."""
    q = np.linspace(0.0, 1.0, bins + 1)[1:-1]
    edges = (np.quantile(x_e, q), np.quantile(ynom_e, q))
    coef = lstsq(_position_bins(x_e, ynom_e, edges), r_e)
    return _paired_p(r_v, r_v - _position_bins(x_v, ynom_v, edges) @ coef)


def _signature_removed(residual: Array, change: Array) -> bool:
    """The candidate's residual no longer correlates with the change the effect makes."""
    nc = float(np.linalg.norm(change))
    nr = float(np.linalg.norm(residual))
    if nc == 0.0 or nr == 0.0:
        return True
    z = float(residual @ change) / (nr * nc) * math.sqrt(residual.size)
    return abs(z) < SIGNATURE_Z


# -- the diagnosis -------------------------------------------------------------------------------


@dataclass
class _Scored:
    effect: str
    model: AugmentedModel
    output: Array  # on the validation record (one-step prediction for colored_noise)
    residual: Array
    change: Array
    mse: float
    est_rmse: float
    p_value: float
    criterion: float


def diagnose(
    model: CascadeModel,
    estimation: tuple[ArrayLike, ArrayLike],
    validation: tuple[ArrayLike, ArrayLike],
    candidates: Sequence[str] | None = None,
    noise_std: float | None = None,
    warmup: int | None = None,
    initial_state: str = "estimate",
    seed: int = 0,
    nominal_converged: bool = True,
) -> DiagnosisReport:
    """Which effect beyond the nominal cascade explains its validation error?

    Every candidate effect is screened and refitted together with the nominal parameters on
    the estimation record, then scored on the validation record (see the module doc for the
    decision rule).

    Parameters
    ----------
    model : CascadeModel
        The nominal cascade, e.g. ``fit_cascade(...).model``.
    estimation : tuple of array_like
        (u_est, y_est), the record the effects are refitted on (typically the one the nominal
        model was fitted on).
    validation : tuple of array_like
        (u_val, y_val), the record that directly follows it in time, where they are scored.
    candidates : sequence of str, optional
        The effects to try (default: every one of ``EFFECTS``).
    noise_std : float, optional
        The measurement noise standard deviation if known (else estimated, see the module
        doc).
    warmup : int, optional
        Samples at the start of each record left out of every criterion (default from the
        slowest pole, :func:`default_warmup`).
    initial_state : {"estimate", "rest"}, default "estimate"
        How every model (nominal and augmented) starts the validation record. "estimate": the
        linear block after u_val[0] held from rest for as long as the estimation record (a
        hold the records vouch for; the equilibrium unless a pole is that slow) and the
        backlash memory y(0) that best fits the record (one parameter, for every model
        alike), so a record that starts with the device holding a force is not read as model
        error; "rest": from zero, as the paper assumes.
    seed : int, default 0
        Passed to :func:`fit_effect` (no random starts are used).
    nominal_converged : bool, default True
        False when ``model`` is the best stable iterate of a nominal fit that raised
        ``NotConvergedError`` (its ``best_stable``): the diagnosis runs the same and the
        report says so (``details.nominal_fit`` and the verdict).

    Returns
    -------
    DiagnosisReport
        The verdict, the ranked candidates and where the nominal model's error lies.

    Raises
    ------
    DataError
        If a record is unusable (not a pair, lengths, NaN, too short), a candidate is unknown,
        or an option is out of range.
    ModelError
        If ``model`` is not a CascadeModel.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> m = bid.example1()
    >>> rng = np.random.default_rng(0)
    >>> u = rng.uniform(-1.5, 1.5, 1200)
    >>> y = m.simulate(np.r_[0.0, 0.0, u[:-2]]) + 0.02 * rng.standard_normal(1200)
    >>> report = bid.diagnose(m, (u[:600], y[:600]), (u[600:], y[600:]), candidates=["dead_time", "output_offset"])
    >>> report.best_effect, report.best.params["d"]
    ('dead_time', 2)
    """
    start = time.perf_counter()
    if not isinstance(model, CascadeModel):
        raise ModelError(
            f"diagnose needs the nominal CascadeModel (e.g. fit_cascade(...).model), got {type(model).__name__}"
        )
    u_e, y_e = _record(estimation, "estimation")
    u_v, y_v = _record(validation, "validation")
    if model.linear.feedthrough:
        model, u_e, u_v = _without_feedthrough(model, u_e, u_v)
    if candidates is None:
        candidates = EFFECTS
    else:
        if isinstance(candidates, str):
            candidates = (candidates,)
        if not isinstance(candidates, (list, tuple)):
            raise DataError(f"candidates = {shown(candidates)}: give a list of effect names from {', '.join(EFFECTS)}")
        unknown = [c for c in candidates if not isinstance(c, str) or c not in EFFECTS]
        if unknown or not candidates:
            raise DataError(f"unknown candidate effects {unknown}: choose from {', '.join(EFFECTS)}")
    candidates = tuple(dict.fromkeys(candidates))
    if not isinstance(initial_state, str) or initial_state not in INITIAL_STATES:
        raise DataError(f"initial_state = {shown(initial_state)}: choose one of {', '.join(map(repr, INITIAL_STATES))}")
    if noise_std is not None:
        check_noise_std(noise_std, "noise_std (the noise standard deviation, or None to estimate it)")
    check_seed(seed)
    check_flag(nominal_converged, "nominal_converged")
    n_min = min(u_e.size, u_v.size)
    warmup_given = warmup is not None
    if warmup is None:
        warmup = default_warmup(model, n_min)
    elif isinstance(warmup, (bool, np.bool_)) or not isinstance(warmup, (int, np.integer)) or not 0 <= warmup <= n_min - 200:
        raise DataError(f"warmup = {warmup!r}: give a whole number >= 0 that leaves at least 200 samples of each record")
    warmup = int(warmup)
    if n_min - warmup < 200:
        raise DataError(
            f"records of {u_e.size} and {u_v.size} samples leave fewer than 200 after the warm-up of {warmup}: "
            "give longer estimation and validation records (thousands of samples)"
        )
    n_est = u_e.size

    # the nominal model
    ynom_e = model.simulate(u_e)
    memory_range = (float(min(y_v.min(), y_e.min())), float(max(y_v.max(), y_e.max())))
    estimate_state = initial_state == "estimate"

    def on_validation(simulate: Any) -> tuple[Array, float]:
        """simulate(u, y_prev, held) on the validation record, from rest or the estimated state."""
        if not estimate_state:
            return simulate(u_v, 0.0, False), 0.0
        return estimated_start(simulate, u_v, y_v, memory_range)

    ynom_v, y0_nominal = on_validation(
        lambda u, y0, held: model.simulate(u, initial_state=held_state(model, u[0], y0, n_est) if held else None)
    )
    r0 = (y_v - ynom_v)[warmup:]
    n = r0.size
    mse0 = float(r0 @ r0) / n

    # screen, refit, score
    screening = screen(model, u_e, y_e, warmup=warmup, t0=0.0, candidates=candidates)
    order = [s.effect for s in screening]
    scored: dict[str, _Scored] = {}
    for effect in order:
        aug = fit_effect(effect, model, u_e, y_e, warmup=warmup, t0=0.0, seed=seed)
        sim_v, _ = on_validation(aug.simulator(t0=n_est, hold=n_est))
        if effect == "colored_noise":
            y_hat_v = aug.predict_from(sim_v, y_v)
            y_hat_e = aug.predict(u_e, y_e, t0=0.0)
        else:
            y_hat_v = sim_v
            y_hat_e = aug.simulate(u_e, t0=0.0)
        r = (y_v - y_hat_v)[warmup:]
        mse = float(r @ r) / n
        re = (y_e - y_hat_e)[warmup:]
        scored[effect] = _Scored(
            effect=effect,
            model=aug,
            output=y_hat_v,
            residual=r,
            change=(y_hat_v - ynom_v)[warmup:],
            mse=mse,
            est_rmse=float(np.sqrt(np.mean(re * re))),
            p_value=_paired_p(r0, r),
            criterion=n * math.log(max(mse, 1e-300)) + aug.n_extra * math.log(n),
        )

    # the noise floor and the gap (x: the nominal linear block's output, simulated once)
    x_e, x_v = model.linear.simulate(u_e), model.linear.simulate(u_v)
    r_bb_in = _black_box(u_e, x_e, y_e, ynom_e, u_v, x_v, y_v, ynom_v, warmup, n_est, with_past=False)
    r_bb = _black_box(u_e, x_e, y_e, ynom_e, u_v, x_v, y_v, ynom_v, warmup, n_est, with_past=True)
    p_input = _paired_p(r0, r_bb_in)
    p_black_box = _paired_p(r0, r_bb)
    if noise_std is not None:
        floor, estimated = float(noise_std) ** 2, False
    else:
        floor = min([float(r_bb @ r_bb) / n, mse0] + [s.mse for s in scored.values()])
        estimated = True
    phi = scored["colored_noise"].model.ar if "colored_noise" in scored else np.zeros(0)
    p_modulation = _modulation_p(r0, ynom_v[warmup:], phi)
    p_position = _position_p(x_e[warmup:], ynom_e[warmup:], (y_e - ynom_e)[warmup:], x_v[warmup:], ynom_v[warmup:], r0)
    gap = max(mse0 - floor, 0.0)
    gap_closed = {e: (mse0 - s.mse) / gap if gap > 0 else 0.0 for e, s in scored.items()}

    # the measured values' lattice (a quantiser after the noise)
    grid = lattice(np.concatenate([y_e, y_v])) if "quantization" in scored else None
    lattice_share = grid.q**2 / 12.0 / mse0 if grid is not None and mse0 > 0 else 0.0

    # decide
    level = ALPHA / (len(scored) + 1)
    significant = {e for e, s in scored.items() if s.p_value < level}
    gap_significant = bool(significant) or p_black_box < level
    deterministic = sorted((s for e, s in scored.items() if e in significant and e != "colored_noise"), key=lambda s: s.criterion)
    best = "none"
    not_named: dict[str, str] = {}  # why a significant candidate closing half the gap is not named
    if gap_significant and gap > MATERIAL_GAP * floor:
        best = "unexplained"
        closing = [s for s in deterministic if gap_closed[s.effect] >= CLOSE_ENOUGH]
        if closing and p_modulation < level:
            # the nominal residual is a slowly modulated copy of the output: the effect named
            # must leave no such modulation behind (a drifting gain is no width drift)
            kept = []
            for s in closing:
                p_left = _modulation_p(s.residual, ynom_v[warmup:], phi)
                if p_left >= level:
                    kept.append(s)
                else:
                    not_named[s.effect] = f"its residual is still modulated by the output (p {p_left:.2g})"
            closing = kept
        if closing and closing[0] is deterministic[0]:
            best = closing[0].effect
        elif closing:
            not_named[closing[0].effect] = f"{deterministic[0].effect} has the lower BIC"
        elif (
            "colored_noise" in significant
            and not any(gap_closed[s.effect] >= MATERIAL for s in deterministic)
            and p_input >= level
            and p_modulation >= level
            and p_position >= level
        ):
            # noise independent of the input: no deterministic candidate may improve the
            # validation error materially
            # no "closes half" here: a noise model predicts only the predictable part of colored
            # noise (its innovations are as unpredictable as white noise), so against a known
            # white-noise floor it can close well under half of a genuine colored-noise gap
            best = "colored_noise"

    lattice_named = grid is not None and lattice_share >= LATTICE_MATERIAL and best in ("none", "colored_noise", "unexplained")
    if lattice_named:
        best = "quantization"

    if best == "unexplained":
        for e, sc in scored.items():
            if e != "colored_noise" and e not in significant and gap_closed[e] >= CLOSE_ENOUGH:
                not_named[e] = f"its improvement is not significant (p {sc.p_value:.2g} >= {level:.2g})"

    ruled_out = []  # why colored_noise was not named, for the report's verdict
    if best != "colored_noise" and "colored_noise" in scored:
        if "colored_noise" not in significant:
            ruled_out.append("its noise model does not predict significantly better")
        if p_input < level:
            ruled_out.append(f"the residual depends on the input (p {p_input:.2g})")
        if p_modulation < level:
            ruled_out.append(f"the residual is modulated by the output (p {p_modulation:.2g})")
        if p_position < level:
            ruled_out.append(f"the residual depends on the drive's position (p {p_position:.2g})")
        material = [s.effect for s in deterministic if gap_closed[s.effect] >= MATERIAL]
        if material:
            ruled_out.append(f"{material[0]} closes over a quarter of the gap")

    ranking = []
    for s in sorted(scored.values(), key=lambda s: (s.effect != best, s.criterion)):
        ranking.append(
            Candidate(
                effect=s.effect,
                gap_closed=float(gap_closed[s.effect]),
                p_value=float(s.p_value),
                model=s.model,
                params=dict(s.model.params),
                n_extra=int(s.model.n_extra),
                estimation_rmse=s.est_rmse,
                validation_rmse=float(math.sqrt(s.mse)),
                criterion=float(s.criterion),
                signature_removed=_signature_removed(s.residual, s.change),
            )
        )
    y_best = ynom_v
    if best in scored:
        y_best = scored[best].output

    noise = math.sqrt(floor)
    residual_full = y_v - ynom_v
    details = DiagnosisDetails(
        screening=tuple(screening),
        black_box_p_value=p_black_box,
        input_p_value=p_input,
        modulation_p_value=p_modulation,
        position_p_value=p_position,
        significance_level=level,
        noise_floor=(
            "given noise_std"
            if not estimated
            else "estimated: lowest validation MSE of a cross-validated black-box residual model and the refitted candidates"
        ),
        warmup_rule="given" if warmup_given else "slowest pole's transient to 1e-4 plus the block memory and dead-time search",
        screened_order=tuple(order),
        initial_state=(
            f"estimated: linear block after u_val[0] held for {n_est} samples from rest, backlash memory y(0) = {y0_nominal:.6g} fitted on the record"
            if estimate_state
            else "from rest"
        ),
        colored_noise_ruled_out=tuple(ruled_out),
        closing_not_named=not_named,
        lattice=(
            ""
            if grid is None
            else f"the measured output lies on a lattice of step q = {grid.q:.6g} ({grid.occupied} of {grid.levels} levels "
            f"occupied); its rounding variance q^2/12 is {100 * lattice_share:.3g} % of the nominal validation MSE"
            + ("" if lattice_named else " (not named: " + (
                "immaterial)" if lattice_share < LATTICE_MATERIAL else f"{best} explains the gap)"))
        ),
        nominal_fit="converged" if nominal_converged else NOT_CONVERGED,
    )
    tests = residual_tests(residual_full[warmup:], u_v[warmup:], x_v[warmup:])
    regimes = regime_shares(
        model, u_v, residual_full, warmup=warmup,
        initial_state=held_state(model, u_v[0], y0_nominal, n_est) if estimate_state else None,
    )
    spectrum = frequency_analysis(residual_full[warmup:], u_v[warmup:], noise_std=noise)
    drift = time_analysis(residual_full[warmup:])
    report = DiagnosisReport(
        best_effect=best,
        ranking=ranking,
        regimes=regimes,
        tests=tests,
        spectrum=spectrum,
        drift=drift,
        noise_std=noise,
        noise_std_estimated=estimated,
        nominal_validation_rmse=math.sqrt(mse0),
        gap=gap,
        warmup=warmup,
        u_val=u_v,
        y_val=y_v,
        y_nominal=ynom_v,
        y_best=y_best,
        elapsed=time.perf_counter() - start,
        details=details,
    )
    return report
