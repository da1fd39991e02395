"""A model's state at the start of a record: estimated from the first measured samples, or
converted from the core's parameters of a fit with ``initial_state="estimate"``.

The core parametrises a record's initial state minimally (identify/_structure.py,
rust/core/src/identify/initial.rs): the input block's observer-canonical values x0_1..x0_n
(the part of x(k) its past contributes), the backlash memory y_prev and, for the sandwich, the
output block's w0_1..w0_m. A model simulates from its own physical state (past inputs and
outputs of each block, :class:`~backlashid.CascadeState`, :class:`~backlashid.SandwichState`),
which over-parametrises that free response: many pasts give the same one. :func:`model_state`
picks the one of minimum norm that reproduces the free response exactly, so that
``model.simulate(u, initial_state=model_state(model, state))`` is the core's simulation.

:func:`estimate_state` fits those values to a record's first samples; with few samples it
takes the maximum a posteriori estimate under a Gaussian prior of the states the model visits
on the record's input (its docstring says how), so that a state fitted exactly to a handful of
noisy samples does not carry a slow mode's error through the record.

A block with a direct feedthrough is fitted as the same block one sample later (the core's
record starts one sample earlier per feedthrough); the conversion undoes that shift.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .._docstrings import fill
from .._validation import check_int, check_noise_std, one_record
from ..errors import BacklashIdError, DataError, ModelError, NotIdentifiableError
from ..models import CascadeModel, CascadeState, LinearBlock, Model, SandwichModel, SandwichSimulation, SandwichState
from ._refine import levenberg_marquardt
from ._structure import Structure, normalise

__all__ = ["estimate_state", "model_state", "refine_values", "simulate_from_samples"]

# a conversion is exact when the free responses agree to this, relative to their size
_EXACT = 1e-9
# the start search of the state: grid points of the first internal value (x0_1, and y_prev)
_GRID = 21
# and seeded random starts of the whole state; the Levenberg-Marquardt search runs from the
# _SEARCHED cheapest of them all
_RANDOM = 200
_SEARCHED = 20
_SCREEN = 200
# the maximum a posteriori search runs from the _MAP_SEARCHED cheapest starts
_MAP_SEARCHED = 6
# the prior acts up to this many samples per state value (beyond, the data's estimate)
_PRIOR_SAMPLES = 2
# the prior's covariance: eigenvalues floored at this fraction of the largest
_FLOOR = 1e-6
# the start's final damped Gauss-Newton steps on the model's own state (refine_values), and the
# share of the estimate's error over the samples below which the refined state is kept
_GN_STEPS = 6
_REFINED = 0.25
# the default noise level with no residual degrees of freedom: this fraction of the spread
# of the model's output (a signal-to-noise ratio of 20 dB)
_NOISE = 0.1


def _check_model(model: Any) -> None:
    if not isinstance(model, (CascadeModel, SandwichModel)):
        raise DataError(f"model must be a CascadeModel or SandwichModel, got {type(model).__name__}")


def _structure(model: Model) -> Structure:
    """The model's structure with the initial state as parameters."""
    return Structure.of(model, initial_state=True)


def _scales(model: Model) -> tuple[float, float]:
    """(k, g) of :func:`normalise`: the normalised model's x is k x and its y is g y."""
    g = float(model.r[0]) if isinstance(model, SandwichModel) else 1.0
    return float(model.backlash.m_left[0]) * g, g


def _free_response(block: LinearBlock, length: int) -> NDArray[np.float64]:
    """Columns: the block's free response over ``length`` samples from each unit past value
    (its u_past, then its x_past), the block's own simulation."""
    zeros = np.zeros(length)
    cols = []
    for k in range(block.na + block.nb):
        e = np.zeros(block.na + block.nb)
        e[k] = 1.0
        cols.append(block.simulate(zeros, u_past=e[: block.na], x_past=e[block.na :]))
    return np.column_stack(cols) if cols else np.zeros((length, 0))


def _canonical(values: NDArray[np.float64], b: NDArray[np.float64], forced: NDArray[np.float64], length: int) -> NDArray[np.float64]:
    """The core's recursion from rest with the state's values added: h(t) = v(t) - sum_j
    b_j h(t-j), v = the values (at t = 1..) plus ``forced``, over ``length`` samples."""
    v = np.zeros(length)
    v[: min(len(values), length)] += values[:length]
    v[: min(len(forced), length)] += forced[:length]
    return LinearBlock([1.0, 0.0], b, feedthrough=True).simulate(v)


def _solve(
    columns: NDArray[np.float64], target: NDArray[np.float64], what: str
) -> NDArray[np.float64]:
    """The minimum-norm past whose free response is ``target``; ModelError if none is exact."""
    solution = np.asarray(np.linalg.lstsq(columns, target, rcond=None)[0] if columns.shape[1] else np.zeros(0), dtype=np.float64)
    miss = float(np.max(np.abs(columns @ solution - target), initial=0.0))
    if miss > _EXACT * (1.0 + float(np.max(np.abs(target), initial=0.0))):
        raise ModelError(
            f"the {what}'s free response of this state is no free response of the model's {what} "
            f"(off by {miss:.3g}): its orders cannot hold it (e.g. a sandwich output block with ns = 0, "
            "or a last coefficient that is zero)"
        )
    return solution


def _normalised_state(model: Model, x0: NDArray[np.float64], y_prev: float, w0: NDArray[np.float64]) -> CascadeState | SandwichState:
    """The state of the normalised ``model`` (m_L1 = 1, r_1 = 1) from the core's values."""
    lin = model.input_linear if isinstance(model, SandwichModel) else model.linear
    shift_in = int(lin.feedthrough)
    length = 2 * (lin.na + lin.nb) + 8
    g = _canonical(x0, lin.b, np.zeros(0), length + shift_in)
    past = _solve(_free_response(lin, length), g[shift_in : shift_in + length], "input block")
    u_past, x_past = tuple(past[: lin.na].tolist()), tuple(past[lin.na :].tolist())
    # y(0): the core's memory, or with a feedthrough one backlash step on from it at x(0) = g(1)
    y0 = float(model.backlash.simulate([g[0]], y0=y_prev)[0]) if shift_in else y_prev
    if isinstance(model, CascadeModel):
        return CascadeState(u_past, x_past, y0)
    out = model.output_linear
    shift = shift_in + int(out.feedthrough)
    length = 2 * (out.na + out.nb) + 8
    # with an input feedthrough the core's output block sees y(0) as its first input
    forced = np.concatenate([[0.0], out.a * y0]) if shift_in else np.zeros(0)
    h = _canonical(w0, out.b, forced, length + shift)
    columns = _free_response(out, length)
    rest = _solve(columns[:, 1:], h[shift : shift + length] - y0 * columns[:, 0], "output block")
    return SandwichState(u_past, x_past, (y0, *rest[: out.na - 1].tolist()), tuple(rest[out.na - 1 :].tolist()))


def _scaled(model: Model, state: CascadeState | SandwichState) -> CascadeState | SandwichState:
    """The normalised model's state as the state of ``model`` (x = x' / k, y = y' / g)."""
    k, g = _scales(model)
    x_past = tuple(v / k for v in state.x_past)
    if isinstance(state, CascadeState):
        return CascadeState(state.u_past, x_past, state.y_prev / g)
    return SandwichState(state.u_past, x_past, tuple(v / g for v in state.y_past), state.w_past)


def model_state(model: Model, state: dict[str, float]) -> CascadeState | SandwichState:
    """The model's own state from the core's initial-state values, e.g. a fit's
    ``FitResult.initial_state``.

    The core's values (x0_1..x0_n, y_prev, and for a sandwich w0_1..w0_m; see
    :class:`Structure`) fix each linear block's free response; the returned state is the
    past of minimum norm with exactly that free response (each block's pasts over-parametrise
    it), so that ``model.simulate(u, initial_state=model_state(model, state))`` reproduces the
    fit's simulation of its record. The values are in the units of ``normalise(model)`` (a
    fit's model is normalised: m_L1 = 1, r_1 = 1); another scaling of the same model gets its
    state scaled accordingly.

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The model the state belongs to.
    state : dict of str to float
        The core's values by name: x0_1..x0_n with n = max(na, nb) (one more with a
        feedthrough), y_prev, and w0_1..w0_m for a sandwich.

    Returns
    -------
    CascadeState or SandwichState
        The model's state before the first sample.

    Raises
    ------
    DataError
        If ``model`` is not a model, or ``state`` misses a value or has one it does not use.
    ModelError
        If the model's orders cannot hold the free response (a sandwich whose output block has
        ns = 0 has one value fewer than the core's w0, so only some w0 are representable; a
        block whose last coefficient is zero).

    Examples
    --------
    >>> import backlashid as bid
    >>> from backlashid.identify import model_state
    >>> model = bid.example1()
    >>> s = model_state(model, {"x0_1": 0.3, "x0_2": -0.1, "y_prev": 0.05})
    >>> y = model.simulate([0.0, 0.0], initial_state=s)
    >>> bool(abs(y[0] - model.backlash.simulate([0.3], y0=0.05)[0]) < 1e-12)  # x(1) = x0_1
    True
    """
    _check_model(model)
    if not isinstance(state, dict):
        raise DataError(f"state must be a dict of the core's values by name, got {type(state).__name__}")
    structure = _structure(model)
    names = structure.names[structure.model_size :]
    if set(state) != set(names):
        raise DataError(f"state has the values {sorted(state)}; this model's are {names}")
    theta = np.concatenate([np.zeros(structure.model_size), [float(state[k]) for k in names]])
    if not np.all(np.isfinite(theta)):
        raise DataError("state: every value must be a finite number")
    x0, y_prev, w0 = structure.initial(theta)
    return _scaled(model, _normalised_state(normalise(model), np.asarray(x0), y_prev, np.asarray(w0)))


def _record(model: Model, structure: Structure, u: NDArray[np.float64], y: NDArray[np.float64]) -> Any:
    """The core's problem of the model's structure on (u, y), shifted for the feedthroughs
    (zeros after u, before y: the core's output at t + shift is the measured output at t)."""
    shift = structure.shift
    z = np.zeros(shift)
    return structure.problem(np.concatenate([u, z]), np.concatenate([z, y]), shift)


def _estimate_checked(
    model: Any, u: ArrayLike, y: ArrayLike, samples: Any, name: str, noise_std: Any, *, none_is_whole: bool = False
) -> tuple[NDArray[np.float64], NDArray[np.float64], Structure, NDArray[np.float64]]:
    """The public entries' checks (the model, the record, ``samples`` under the argument's
    ``name``, with ``none_is_whole`` None for the whole record, and ``noise_std``), then
    :func:`_estimate`: the record as arrays, the structure and the vector with the estimated
    state."""
    _check_model(model)
    u_arr, y_arr = one_record(u, y, flatten=True)
    n = _samples(len(u_arr) if samples is None and none_is_whole else samples, len(u_arr), name)
    structure, theta = _estimate(model, u_arr, y_arr, n, _noise_std(noise_std))
    return u_arr, y_arr, structure, theta


def _estimate(
    model: Model, u: NDArray[np.float64], y: NDArray[np.float64], samples: int, noise_std: float | None = None
) -> tuple[Structure, NDArray[np.float64]]:
    """The parameter vector of the normalised model with the state estimated on the first
    ``samples`` samples: the model's parameters held (lower == upper), the state free; the
    data-only estimate, then with few samples the maximum a posteriori one (:class:`_Posterior`)."""
    structure = _structure(model)
    p0 = structure.model_size
    prob = _record(model, structure, u[:samples], y[:samples])
    lo, hi = (np.asarray(b, dtype=np.float64) for b in prob.bounds())
    lo[:p0] = hi[:p0] = structure.pack(model)[:p0]  # the model's parameters held
    theta, candidates = _data_only(model, structure, prob, u, y, samples, lo, hi)
    size = structure.size - p0
    if samples > _PRIOR_SAMPLES * size:  # the data determine the state (see _ESTIMATE_DOC)
        return structure, theta
    mu, root = _prior(model, u)
    sigma = _noise(model, u, prob, theta, samples, size, noise_std)
    if sigma == 0.0:  # an exact fit of more samples than state values: nothing to add
        return structure, theta
    posterior = _Posterior(prob, p0, mu, root, sigma)
    i_y = structure.names.index("y_prev")
    rest = theta.copy()
    rest[p0:] = 0.0
    prior_mean = theta.copy()
    prior_mean[p0:] = mu
    # with more samples than state values the data decide the basin: the posterior is searched
    # from the data's estimate only, what they leave undetermined there (e.g. y_prev when the
    # first sample moves: it acts on nothing) keeping the data's value; with fewer also from
    # the prior's mean, rest and the data's cheapest starts (the data alone leave a valley of
    # exact fits)
    if samples > size:
        starts = [theta]
        lo, hi = lo.copy(), hi.copy()
        for i in _dependent(prob, theta, p0):
            lo[i] = hi[i] = theta[i]
    else:
        starts = [theta, prior_mean, rest, *candidates]
    costs = np.array([_cost(posterior, t) for t in starts])
    best = None
    for k in np.argsort(costs)[:_MAP_SEARCHED]:
        if not np.isfinite(costs[k]):
            break
        fit = _held_lm(posterior, starts[k], lo, hi, p0, i_y, hold=False)
        if best is None or fit[1] < best[1]:
            best = fit
    return structure, theta if best is None else best[0]


def _data_only(
    model: Model,
    structure: Structure,
    prob: Any,
    u: NDArray[np.float64],
    y: NDArray[np.float64],
    samples: int,
    lo: NDArray[np.float64],
    hi: NDArray[np.float64],
) -> tuple[NDArray[np.float64], list[NDArray[np.float64]]]:
    """The state that fits the ``samples`` samples best (the output error alone), and the
    cheapest starts of its search."""
    p0, size = structure.model_size, structure.size
    theta = np.concatenate([structure.pack(model)[:p0], np.zeros(size - p0)])
    names = structure.names
    # starts: rest, and a grid over x(1) (x0_1) and the memory y_prev over the ranges the
    # model's simulation from rest visits; the backlash makes the cost piecewise, with
    # local minima where it holds
    norm = normalise(model)
    sim = norm.simulate(u, internals=True)
    inner = sim.y if isinstance(sim, SandwichSimulation) else sim.output
    grid_x = np.linspace(*_widened(sim.x), _GRID)
    grid_y = np.linspace(*_widened(inner), _GRID) if isinstance(norm, SandwichModel) else np.array([0.0, float(y[0])])
    # x(1) is x0_1, or with an input feedthrough (the core's record one sample earlier) x0_2
    first = f"x0_{1 + int(structure.feedthrough)}"
    i_x, i_y = names.index(first if first in names else "x0_1"), names.index("y_prev")
    candidates = [theta]
    for gx in grid_x:
        for gy in grid_y:
            t = theta.copy()
            t[i_x] = gx
            t[i_y] = gy
            candidates.append(t)
    # and seeded random states over those ranges (x0 from x's, w0 from w's)
    rng = np.random.default_rng(0)
    spans = {"x0": _widened(sim.x), "y_prev": _widened(inner), "w0": _widened(sim.output)}
    kinds = [next(k for k in spans if n.startswith(k)) for n in names[p0:]]
    for _ in range(_RANDOM):
        t = theta.copy()
        t[p0:] = [rng.uniform(*spans[k]) for k in kinds]
        candidates.append(t)
    # ranked on the first _SCREEN samples at most (the state acts at the start of the record)
    screen = prob if samples <= _SCREEN else _record(model, structure, u[:_SCREEN], y[:_SCREEN])
    costs = np.array([_cost(screen, t) for t in candidates])
    best = None
    order = np.argsort(costs)[:_SEARCHED]
    for k in order:
        if not np.isfinite(costs[k]):
            break
        fit = _held_lm(prob, candidates[k], lo, hi, p0, i_y)
        if best is None or fit[1] < best[1]:
            best = fit
    if best is None:
        raise ModelError("the model's simulation from every start of the state diverges on these samples")
    return best[0], [candidates[k] for k in order[:_MAP_SEARCHED] if np.isfinite(costs[k])]


def _free_terms(block: LinearBlock, u: NDArray[np.float64], x: NDArray[np.float64], cuts: NDArray[np.int64]) -> NDArray[np.float64]:
    """Rows: the block's observer-canonical values x0_k = sum_(i>=k) a_i u(k-i) - sum_(j>=k)
    b_j x(k-j) (rust/core/src/identify/initial.rs) of a record starting at each index of
    ``cuts`` of the signals u -> x (lags 1.., the core's form; before index 0 at rest)."""
    a, b = np.asarray(block.a), np.asarray(block.b)
    n = max(a.size, b.size)
    up, xp = np.concatenate([np.zeros(n + 1), u]), np.concatenate([np.zeros(n + 1), x])
    at = cuts + n  # index into the padded signals of sample cut - 1
    out = np.zeros((cuts.size, n))
    for k in range(1, n + 1):
        for i in range(k, a.size + 1):
            out[:, k - 1] += a[i - 1] * up[at + k - i]
        for j in range(k, b.size + 1):
            out[:, k - 1] -= b[j - 1] * xp[at + k - j]
    return out


def _visited(model: Model, u: NDArray[np.float64]) -> NDArray[np.float64]:
    """Rows: the core's initial-state values (x0, y_prev, w0 in the units of the normalised
    model) of a record starting at each sample 1..N-1 of the model's simulation from rest on
    ``u``: the states the model visits on this input."""
    norm = normalise(model)
    lin = norm.input_linear if isinstance(norm, SandwichModel) else norm.linear
    core_in = LinearBlock(lin.a, lin.b)  # the core's form: a feedthrough's a_0 at lag 1
    x = np.asarray(core_in.simulate(u))
    inner = np.asarray(norm.backlash.simulate(x))
    cuts = np.arange(1, u.size)
    parts = [_free_terms(core_in, u, x, cuts), inner[cuts - 1, None]]
    if isinstance(norm, SandwichModel):
        out = norm.output_linear
        core_out = LinearBlock(out.a, out.b)
        parts.append(_free_terms(core_out, inner, np.asarray(core_out.simulate(inner)), cuts))
    return np.hstack(parts)


def _prior(model: Model, u: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(mu, L): the mean and a root of the inverse covariance (Sigma^-1 = L^T L) of the states
    the model visits on ``u``; Sigma's eigenvalues floored at _FLOOR of the largest (a state
    value the input never moves, or two that move together, gets a finite weight)."""
    states = _visited(model, u)
    mu = states.mean(axis=0)
    if states.shape[0] < 2:
        return mu, np.eye(mu.size)
    values, vectors = np.linalg.eigh(np.atleast_2d(np.cov(states, rowvar=False)))
    top = float(np.max(values, initial=0.0))
    floor = _FLOOR * top if top > 0.0 else 1.0
    return mu, (vectors / np.sqrt(np.maximum(values, floor))).T


def _noise(
    model: Model, u: NDArray[np.float64], prob: Any, theta: NDArray[np.float64], samples: int, size: int, noise_std: float | None
) -> float:
    """The output error's standard deviation sigma of the posterior: ``noise_std`` if given;
    else the data-only fit's residual sqrt(cost / (samples - size)) when the samples outnumber
    the state's values (zero for an exact fit); else _NOISE of the spread of the model's output
    on ``u`` from rest."""
    if noise_std is not None:
        return float(noise_std)
    if samples > size:
        return float(np.sqrt(max(_cost(prob, theta), 0.0) / (samples - size)))
    return _NOISE * float(np.std(normalise(model).simulate(u)))


class _Posterior:
    """The core's state problem divided by sigma with the prior as extra residual rows: cost =
    sum (y - y_sim)^2 / sigma^2 + ||L (mu - s)||^2 over the state s = theta[p0:] (twice the
    negative log posterior); the factor [R | Q^T r] / sigma of the core re-triangularised with
    the rows [L | L (mu - s)] below it. Otherwise the core's problem (the protocol of
    :func:`levenberg_marquardt`)."""

    def __init__(self, core: Any, p0: int, mu: NDArray[np.float64], root: NDArray[np.float64], sigma: float) -> None:
        self.core, self.p0, self.mu, self.root, self.sigma = core, p0, mu, root, sigma
        self.names = list(core.names)
        self.samples = int(core.samples) + root.shape[0]
        self.warmup = int(core.warmup)

    def _rows(self, theta: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(self.root @ (self.mu - np.asarray(theta)[self.p0 :]))

    def simulate(self, theta: NDArray[np.float64]) -> Any:
        return self.core.simulate(theta)

    def feasible(self, theta: NDArray[np.float64]) -> bool:
        return bool(self.core.feasible(theta))

    def bounds(self) -> tuple[list[float], list[float]]:
        return self.core.bounds()  # type: ignore[no-any-return]

    def cost(self, theta: NDArray[np.float64]) -> float:
        r = self._rows(theta)
        return float(self.core.cost(theta)) / self.sigma**2 + float(r @ r)

    def gradient(self, theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
        g, c = self.core.gradient(theta)
        r = self._rows(theta)
        g = np.array(g, dtype=np.float64) / self.sigma**2
        g[self.p0 :] += self.root.T @ r
        return g, float(c) / self.sigma**2 + float(r @ r)

    def oe_factor(self, theta: NDArray[np.float64]) -> tuple[NDArray[np.float64], float]:
        r_aug, c = self.core.oe_factor(theta)
        p = len(self.names)
        r = self._rows(theta)
        rows = np.zeros((r.size, p + 1))
        rows[:, self.p0 : p] = self.root
        rows[:, p] = r
        factor = np.asarray(np.linalg.qr(np.vstack([np.asarray(r_aug, dtype=np.float64)[: p + 1] / self.sigma, rows]), mode="r"))
        return factor, float(c) / self.sigma**2 + float(r @ r)


def _widened(values: NDArray[np.float64]) -> tuple[float, float]:
    lo, hi = float(np.min(values)), float(np.max(values))
    pad = 0.1 * (hi - lo) + 1e-12
    return lo - pad, hi + pad


def _cost(prob: Any, theta: NDArray[np.float64]) -> float:
    try:
        return float(prob.cost(theta))
    except BacklashIdError:
        return np.inf


def _held_lm(
    prob: Any, theta: NDArray[np.float64], lo: NDArray[np.float64], hi: NDArray[np.float64], p0: int, y_prev: int, hold: bool = True
) -> tuple[NDArray[np.float64], float]:
    """The one LM over the state's determined part. State values whose columns of the factor
    are zero or a combination of earlier ones at the start are held (x0 and w0 at rest where
    that costs nothing); a column that vanishes on the way (the backlash starts holding, or
    stops) ends the search with the core's NotIdentifiableError naming it, and the search is
    repeated from the start with that value held too. ``hold=False`` holds none at the start
    (a posterior's prior determines them all)."""
    names = list(prob.names)
    held = set(_dependent(prob, theta, p0)) if hold else set()
    for _ in range(len(theta) - p0 + 1):
        start = theta.copy()
        lo_k, hi_k = lo.copy(), hi.copy()
        for i in sorted(held):
            if i != y_prev:  # the undetermined part of x0 and w0 at rest, where that costs nothing
                rest = start.copy()
                rest[i] = 0.0
                if _cost(prob, rest) <= _cost(prob, start) * (1.0 + 1e-12):
                    start = rest
            lo_k[i] = hi_k[i] = start[i]
        if len(held) == len(theta) - p0:
            return start, _cost(prob, start)
        try:
            fit = levenberg_marquardt(prob, start, lower=lo_k, upper=hi_k)
        except NotIdentifiableError as exc:
            named = [i for i in range(p0, len(theta)) if i not in held and f" {names[i]} " in f" {exc} "]
            if not named:
                return start, _cost(prob, start)
            held.add(named[0])
            continue
        except BacklashIdError:
            return start, _cost(prob, start)
        return fit.theta, float(fit.cost)
    return theta, _cost(prob, theta)


def lm_holding_vanishing(prob: Any, theta: NDArray[np.float64], p0: int, lower: NDArray[np.float64] | None = None, upper: NDArray[np.float64] | None = None) -> Any:
    """:func:`levenberg_marquardt` on a problem with the initial state as parameters (from
    index ``p0``): a state value whose column vanishes on the way (y_prev once the backlash
    moves at the first sample, x0_k masked by a backlash that holds) is held at its start and
    the search repeated, instead of ending in the core's NotIdentifiableError. An error that
    names no state value is raised as it is."""
    names = list(prob.names)
    lo, hi = (np.asarray(b, dtype=np.float64).copy() for b in prob.bounds()) if lower is None else (lower.copy(), upper.copy())  # type: ignore[union-attr]
    theta = np.clip(np.asarray(theta, dtype=np.float64), lo, hi)
    while True:
        try:
            return levenberg_marquardt(prob, theta, lower=lo, upper=hi)
        except NotIdentifiableError as exc:
            named = [i for i in range(p0, len(theta)) if lo[i] < hi[i] and f" {names[i]} " in f" {exc} "]
            if not named:
                raise
            lo[named[0]] = hi[named[0]] = theta[named[0]]


def lm_state_first(prob: Any, theta: NDArray[np.float64], p0: int) -> Any:
    """:func:`lm_holding_vanishing` over the state alone, the model's parameters (before
    ``p0``) held at their values in ``theta``: a start's state fitted before the model moves."""
    lo, hi = (np.asarray(b, dtype=np.float64).copy() for b in prob.bounds())
    lo[:p0] = hi[:p0] = theta[:p0]
    return lm_holding_vanishing(prob, theta, p0, lo, hi)


def _dependent(prob: Any, theta: NDArray[np.float64], p0: int) -> list[int]:
    """Indices of the state's columns of the factor at theta that add nothing to the earlier
    state columns (zero, or a combination of them)."""
    try:
        r = prob.oe_factor(theta)[0][:-1, :-1]
    except BacklashIdError:
        return []
    cols = r[:, p0:]
    scale = float(np.max(np.linalg.norm(cols, axis=0), initial=0.0))
    kept: list[NDArray[np.float64]] = []
    out = []
    for j in range(cols.shape[1]):
        v = cols[:, j].copy()
        for q in kept:
            v -= q * float(q @ v)
        norm = float(np.linalg.norm(v))
        if scale == 0.0 or norm <= 1e-8 * scale:
            out.append(p0 + j)
        else:
            kept.append(v / norm)
    return out


def _noise_std(noise_std: Any) -> float | None:
    return None if noise_std is None else check_noise_std(noise_std)


def _samples(init_samples: Any, n: int, name: str) -> int:
    k = check_int(init_samples, name, 1)
    if k > n:
        raise DataError(f"{name} = {k}: the record has only {n} samples")
    return k


_ESTIMATE_DOC = """The state is estimated by the package's one Levenberg-Marquardt search
(:func:`levenberg_marquardt`) on the core's problem with the initial state as parameters
(``Structure(..., initial_state=True)``), the model's parameters held (lower == upper), from
rest and from a grid of starts over the first internal value x(1) (and the backlash memory),
the backlash making the output error piecewise with local minima. What the samples do not
determine keeps its start (a state value whose column is zero or a combination of earlier
ones is held; the backlash memory y_prev acts on nothing once the first sample moves the
backlash).

With few samples (at most twice the state's dimension d, the number of the core's values:
max(na, nb) + 1, plus max(nr, ns) for a sandwich) the samples alone fit a whole valley of
states, and a state that fits n <= d noisy samples exactly can carry a slow mode's error
through the record. The estimate is then the maximum a posteriori one: it minimises
sum (y - y_sim)^2 / sigma^2 over the samples plus (s - mu)^T Sigma^-1 (s - mu), where mu and
Sigma are the mean and covariance of the states s the model itself visits on the given input
(its simulation from rest over the whole record, the state of a record starting at each of
its samples; Sigma's eigenvalues floored at 1e-6 of the largest). sigma is ``noise_std``;
by default the data's own residual sqrt(cost / (n - d)) of the data-only estimate when
n > d (zero, and the prior without effect, on a record the model fits exactly), else 0.1 of
the standard deviation of the model's output on the input (a 20 dB signal-to-noise ratio:
with no residual degrees of freedom the samples cannot tell their noise). The prior enters
the same search as extra residual rows (its square root L, Sigma^-1 = L^T L). With more
than 2 d samples the data determine the state and the data-only estimate is returned.

Last, the state's model-dependent values in the model's own pasts (x_past and the memory; a
sandwich's y_past and w_past; u_past is the input's and stays) are refined by damped
Gauss-Newton steps on the samples (:func:`refine_values`), and the refined state is kept where
its error over the samples is at most a quarter of the estimate's: the search's starts lie
around the states the model visits from rest, which a drive whose output is a position (an
integrator, far from its rest level) does not reach."""


def refine_values(residual: Any, v0: NDArray[np.float64], steps: int = _GN_STEPS) -> NDArray[np.float64]:
    """Damped Gauss-Newton steps on a few state values: ``residual(v)`` (measured minus
    simulated over the samples, None where the simulation fails) from ``v0``, forward-difference
    Jacobian; returns the values of the lowest error found (``v0`` if none is lower).

    The core's search runs in the minimal (observer-canonical) values from starts around the
    states the model visits from rest; a drive whose output is a position (an integrator) sits
    far from those, and its state in the model's own pasts (x_past, the memory) is then found
    by these steps from the core's estimate.

    Parameters
    ----------
    residual : callable
        ``residual(v) -> ndarray or None``.
    v0 : ndarray
        The values to start from.
    steps : int, default 6
        Gauss-Newton steps at most.

    Returns
    -------
    ndarray
        The refined values.

    Examples
    --------
    >>> import numpy as np
    >>> from backlashid.identify import refine_values
    >>> t = np.arange(5.0)
    >>> np.round(refine_values(lambda v: 3.0 + 2.0 * t - (v[0] + v[1] * t), np.zeros(2)), 6).tolist()
    [3.0, 2.0]
    """
    v = np.array(v0, dtype=np.float64)
    r = residual(v)
    if r is None or v.size == 0:
        return v
    cost = float(r @ r)
    lam = 1e-3
    for _ in range(steps):
        h = 1e-6 * (1.0 + np.abs(v))
        cols = []
        for k in range(v.size):
            vk = v.copy()
            vk[k] += h[k]
            rk = residual(vk)
            if rk is None:
                return v
            cols.append((r - rk) / h[k])  # d(simulation) / dv
        jac = np.column_stack(cols)
        jtj, jtr = jac.T @ jac, jac.T @ r
        step = np.zeros_like(v)
        improved = False
        for _ in range(8):
            step = np.linalg.solve(jtj + lam * (np.diag(np.diag(jtj)) + 1e-12 * np.eye(v.size)), jtr)
            trial = v + step
            rt = residual(trial)
            if rt is not None and float(rt @ rt) < cost:
                v, r, cost = trial, rt, float(rt @ rt)
                lam = max(lam / 10.0, 1e-9)
                improved = True
                break
            lam *= 10.0
        if not improved or float(np.max(np.abs(step))) <= 1e-10 * (1.0 + float(np.max(np.abs(v)))):
            break
    return v


def _internal_values(state: CascadeState | SandwichState) -> NDArray[np.float64]:
    """The state's values that depend on the model (not the input's past u_past)."""
    if isinstance(state, SandwichState):
        return np.array([*state.x_past, *state.y_past, *state.w_past], dtype=np.float64)
    return np.array([*state.x_past, state.y_prev], dtype=np.float64)


def _with_values(state: CascadeState | SandwichState, v: NDArray[np.float64]) -> CascadeState | SandwichState:
    nx = len(state.x_past)
    if isinstance(state, SandwichState):
        ny = len(state.y_past)
        return SandwichState(state.u_past, tuple(v[:nx].tolist()), tuple(v[nx : nx + ny].tolist()), tuple(v[nx + ny :].tolist()))
    return CascadeState(state.u_past, tuple(v[:nx].tolist()), float(v[nx]))


def _refined_state(model: Model, u: NDArray[np.float64], y: NDArray[np.float64], samples: int, state: CascadeState | SandwichState) -> CascadeState | SandwichState | None:
    """The state refined by :func:`refine_values` on the first samples, if its error there is at
    most ``_REFINED`` of the estimate's (else None: the estimate stands)."""
    u_n, y_n = u[:samples], y[:samples]

    def residual(v: NDArray[np.float64]) -> NDArray[np.float64] | None:
        try:
            r = y_n - model.simulate(u_n, initial_state=_with_values(state, v))
        except BacklashIdError:
            return None
        return r if np.all(np.isfinite(r)) else None

    v0 = _internal_values(state)
    r0 = residual(v0)
    if r0 is None:
        return None
    v = refine_values(residual, v0)
    r = residual(v)
    if r is None or float(r @ r) > _REFINED * float(r0 @ r0):
        return None
    return _with_values(state, v)


@fill(estimate=_ESTIMATE_DOC)
def estimate_state(
    model: Model, u: ArrayLike, y: ArrayLike, *, samples: int | None = None, noise_std: float | None = None
) -> CascadeState | SandwichState:
    """The model's state before the first sample, estimated from the first measured samples
    (the benchmark protocols' "n samples to initialise the state").

    {estimate}

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The model, its parameters fixed.
    u : array_like
        Input u(t), 1-D, finite.
    y : array_like
        Measured output (w for a sandwich), as long as ``u``.
    samples : int, optional
        Estimate from the first ``samples`` samples only (default: the whole record).
    noise_std : float, optional
        The standard deviation sigma of the output error (noise and model error) weighing the
        samples against the prior of the state; default as described above.

    Returns
    -------
    CascadeState or SandwichState
        The state (see :func:`model_state`) to pass to ``model.simulate(..,
        initial_state=..)``.

    Raises
    ------
    DataError
        If the record is not finite, u and y differ in length, ``samples`` is not in 1..N, or
        ``noise_std`` is not a positive number.
    ModelError
        As :func:`model_state`, or if the model's simulation diverges from every start.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> from backlashid.identify import estimate_state
    >>> model = bid.example1()
    >>> d = bid.example_data(model, 300, snr=None, seed=1)
    >>> u, y = d.u[100:], d.noisy[100:]  # cut from the middle of the run
    >>> state = estimate_state(model, u, y, samples=30)
    >>> bool(np.max(np.abs(model.simulate(u, initial_state=state) - y)) < 1e-8)
    True
    """
    u_arr, y_arr, structure, theta = _estimate_checked(model, u, y, samples, "samples", noise_std, none_is_whole=True)
    x0, y_prev, w0 = structure.initial(theta)
    state = _scaled(model, _normalised_state(normalise(model), np.asarray(x0), y_prev, np.asarray(w0)))
    n = len(u_arr) if samples is None else int(samples)
    refined = _refined_state(model, u_arr, y_arr, n, state)
    return state if refined is None else refined


@fill(estimate=_ESTIMATE_DOC)
def simulate_from_samples(
    model: Model, u: ArrayLike, y: ArrayLike, init_samples: int, *, noise_std: float | None = None
) -> NDArray[np.float64]:
    """The free-run simulation of the whole record from the state estimated on its first
    ``init_samples`` measured samples.

    {estimate}

    The simulation is the core's, from the estimated values themselves (exact also where the
    model's own state cannot hold them, see :func:`model_state`).

    Parameters
    ----------
    model : CascadeModel or SandwichModel
        The model, its parameters fixed.
    u : array_like
        Input u(t), 1-D, finite.
    y : array_like
        Measured output (w for a sandwich), as long as ``u``; only its first
        ``init_samples`` samples are used.
    init_samples : int
        Samples that initialise the state, 1..N.
    noise_std : float, optional
        The standard deviation sigma of the output error (noise and model error) weighing the
        samples against the prior of the state; default as described above.

    Returns
    -------
    numpy.ndarray
        The model's output for every sample of u (in the model's units).

    Raises
    ------
    DataError
        As :func:`estimate_state`.
    ModelError
        If the model's simulation diverges.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> from backlashid.identify import simulate_from_samples
    >>> model = bid.example2()
    >>> d = bid.example_data(model, 300, snr=None, seed=2)
    >>> sim = simulate_from_samples(model, d.u[150:], d.noisy[150:], 40)
    >>> bool(np.max(np.abs(sim - d.noisy[150:])) < 1e-8)
    True
    """
    if not isinstance(model, (CascadeModel, SandwichModel)) and callable(getattr(model, "simulate_from_samples", None)):
        return np.asarray(model.simulate_from_samples(u, y, init_samples), dtype=np.float64)  # a diagnosed model
    return started_from_samples(model, u, y, init_samples, noise_std=noise_std)[0]


def started_from_samples(
    model: Model, u: ArrayLike, y: ArrayLike, init_samples: int, *, noise_std: float | None = None
) -> tuple[NDArray[np.float64], CascadeState | SandwichState | None]:
    """:func:`simulate_from_samples` and the state it started from (None where that state is
    the core's values, which the model's own pasts cannot hold)."""
    u_arr, y_arr, structure, theta = _estimate_checked(model, u, y, init_samples, "init_samples", noise_std)
    state: CascadeState | SandwichState | None = None
    try:
        x0, y_prev, w0 = structure.initial(theta)
        state = _scaled(model, _normalised_state(normalise(model), np.asarray(x0), y_prev, np.asarray(w0)))
        refined = _refined_state(model, u_arr, y_arr, int(init_samples), state)
    except ModelError:  # a free response the model's own pasts cannot hold: the core's values
        refined = None
    if refined is not None:
        return np.asarray(model.simulate(u_arr, initial_state=refined), dtype=np.float64), refined
    whole = _record(model, structure, u_arr, y_arr)
    # normalisation leaves the output unchanged: the core's output is the model's (and the
    # model's from the converted state, model_state's exact conversion)
    return np.asarray(whole.simulate(theta))[structure.shift :], state
