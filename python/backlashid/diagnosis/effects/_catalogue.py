"""Candidate effects for the diagnosis: augmentations of a nominal cascade.

Each effect of :data:`EFFECTS` is an augmentation of the nominal cascade (linear block, eq 16
-> general backlash, eq 1) that gives exactly the nominal model at zero size (the Rust core's
``simulate_augmented``; definitions in ``rust/core/src/augmented.rs``). :func:`fit_effect`
refits the nominal parameters together with the effect's own parameters on the estimation
record by output-error least squares (free-run simulation error after the warm-up), starting
from the nominal fit; discrete or non-smooth parameters (dead time d, quantiser step q) are
searched directly. :func:`screen` orders the candidates cheaply before any refit: a score
(Lagrange multiplier) test of the nominal residual against each effect's predicted change.

Time: drift rates are per ``TIME_SCALE`` samples of the continuous record (the validation
record follows the estimation record, so it starts at t0 = len(u_est)).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import stats

from ... import _core
from ..._validation import as_signal
from ...errors import BacklashIdError, DataError, ModelError
from ...identify import Structure
from ...models import CascadeModel, LinearBlock

__all__ = ["EFFECTS", "AUGMENTATIONS", "Augmentation", "AugmentedModel", "Screening", "fit_effect", "screen"]

EFFECTS: tuple[str, ...] = (
    "dead_time",
    "saturation",
    "friction",
    "width_drift",
    "output_offset",
    "branch_degree",
    "linear_order",
    "compliance",
    "quantization",
    "hysteresis_memory",
    "colored_noise",
)

TIME_SCALE = 1000.0  # samples per time unit of the drift rates
MAX_DELAY = 6  # dead times searched: 1..MAX_DELAY extra samples
N_PLAYS = 2  # extra plays of hysteresis_memory
MAX_AR = 4  # highest order of the colored_noise AR model

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Augmentation:
    """An effect's own parameters, their values at zero size (the nominal model) and what
    they mean."""

    effect: str
    names: tuple[str, ...]
    zero: tuple[float, ...]
    description: str


AUGMENTATIONS: dict[str, Augmentation] = {
    a.effect: a
    for a in (
        Augmentation("dead_time", ("d",), (0,), "extra input delay of d samples: u(t - d)"),
        Augmentation("saturation", ("lo", "hi"), (-np.inf, np.inf), "drive input clipped to [lo, hi]"),
        Augmentation("friction", ("F_c", "F_v"), (0.0, 0.0), "u - F_c sign(v) - F_v v, v = x(t) - x(t-1)"),
        Augmentation("width_drift", ("dc_L", "dc_R"), (0.0, 0.0), f"c_L, c_R change by dc per {TIME_SCALE:g} samples"),
        Augmentation("output_offset", ("o_0", "o_1"), (0.0, 0.0), f"y + o_0 + o_1 t / {TIME_SCALE:g}"),
        Augmentation("branch_degree", ("extra_degree",), (0,), "branches of degree n + 2 (higher terms from 0)"),
        Augmentation("linear_order", ("extra_order",), (0,), "linear block of orders na + 1, nb + 1"),
        Augmentation("compliance", ("k", "omega", "zeta"), (0.0, 0.5, 0.1), "y = (1 - k) f + k H f, H a unit-DC resonance"),
        Augmentation("quantization", ("q",), (0.0,), "y quantised to steps of q"),
        Augmentation(
            "hysteresis_memory",
            tuple(n for k in range(1, N_PLAYS + 1) for n in (f"r_{k}", f"w_{k}")),
            tuple(v for _ in range(N_PLAYS) for v in (0.1, 0.0)),
            "y + sum_k w_k play_{r_k}(x)",
        ),
        Augmentation("colored_noise", tuple(f"phi_{k}" for k in range(1, MAX_AR + 1)), (0.0,) * MAX_AR, "AR noise model on the output error"),
    )
}


def _structure_of(model: CascadeModel) -> Structure:
    return Structure(model.linear.na, model.linear.nb, model.backlash.degree)


def _effect_kwargs(effect: str, p: dict[str, float]) -> dict[str, Any]:
    """Keyword arguments of ``_core.simulate_augmented`` for an effect's parameters."""
    if effect == "dead_time":
        return {"delay": int(p["d"])}
    if effect == "saturation":
        return {"sat_lo": p["lo"], "sat_hi": p["hi"]}
    if effect == "friction":
        return {"f_c": p["F_c"], "f_v": p["F_v"]}
    if effect == "width_drift":
        return {"drift_left": p["dc_L"], "drift_right": p["dc_R"]}
    if effect == "output_offset":
        return {"offset": p["o_0"], "offset_rate": p["o_1"]}
    if effect == "compliance":
        return {"compliance": p["k"], "omega": p["omega"], "zeta": p["zeta"]}
    if effect == "quantization":
        return {"quantum": p["q"]}
    if effect == "hysteresis_memory":
        return {
            "play_r": [p[f"r_{k}"] for k in range(1, N_PLAYS + 1)],
            "play_w": [p[f"w_{k}"] for k in range(1, N_PLAYS + 1)],
        }
    return {}


def held_x(block: LinearBlock, u0: float) -> float:
    """x of the linear block (16) at rest after the input was held at u0: static gain x u0."""
    gain = block.static_gain()
    if not np.isfinite(gain):
        raise ModelError(
            f"the linear block {block.a.tolist()}, {block.b.tolist()} has a pole at z = 1, so no equilibrium "
            "holds it at a constant input: start from rest (initial_state='rest')"
        )
    return gain * u0


def _simulate(
    structure: Structure, theta: Array, kwargs: dict[str, Any], u: Array, t0: float, y_prev: float = 0.0, held: bool = False
) -> Array:
    """``held``: the linear block starts at its equilibrium with u[0] (the input held before
    the record) instead of at rest; ``y_prev`` is the backlash memory y(0)."""
    a, b, *rest = structure.unpack(theta).chain()
    state: dict[str, Any] = {}
    if held:
        x_eq = held_x(LinearBlock(a, b), float(u[0]))
        state = {"u_past": [float(u[0])] * len(a), "x_past": [x_eq] * len(b)}
    return _core.simulate_augmented(a, b, *rest, u, t0=float(t0), time_scale=TIME_SCALE, y_prev=float(y_prev), **state, **kwargs)


def _ar_predict(residual: Array, phi: Array) -> Array:
    """One-step prediction of an AR process from its past (zero before the record)."""
    pred = np.zeros_like(residual)
    for k, c in enumerate(phi, 1):
        pred[k:] += c * residual[:-k]
    return pred


@dataclass(frozen=True)
class AugmentedModel:
    """A nominal cascade refitted together with one effect."""

    effect: str
    structure: Structure
    theta: Array = field(repr=False)  # nominal parameters (Structure's physical vector)
    params: dict[str, float]  # the effect's own parameters
    kwargs: dict[str, Any] = field(repr=False)
    ar: Array = field(default_factory=lambda: np.zeros(0), repr=False)  # colored_noise only
    n_extra: int = 0

    def simulate(self, u: ArrayLike, t0: float = 0.0, *, y_prev: float = 0.0, held: bool = False) -> Array:
        """Free-run output for the input u; u[0] is sample t0 of the record. From rest, or with
        ``held=True`` from the linear block's equilibrium with u[0]; ``y_prev`` is the backlash
        memory before the first sample."""
        u_arr = as_signal(u, "u").ravel()
        return _simulate(self.structure, self.theta, self.kwargs, u_arr, t0, y_prev, held)

    def predict(self, u: ArrayLike, y: ArrayLike, t0: float = 0.0) -> Array:
        """One-step prediction: the simulation plus the noise model's prediction of the output
        error from its measured past (equals ``simulate`` without a noise model)."""
        return self.predict_from(self.simulate(u, t0), y)

    def predict_from(self, simulated: Array, y: ArrayLike) -> Array:
        """One-step prediction from this model's free-run output ``simulated`` of the record."""
        y_arr = as_signal(y, "y").ravel()
        if y_arr.shape != simulated.shape:
            raise DataError(f"u has {simulated.size} samples and y {y_arr.size}: give one record")
        return simulated + _ar_predict(y_arr - simulated, self.ar) if self.ar.size else simulated

    @property
    def nominal(self) -> CascadeModel | None:
        """The refitted nominal part as a model, None if it is not a valid backlash."""
        try:
            return self.structure.model(self.theta)  # type: ignore[return-value]
        except ModelError:
            return None

    def to_dict(self) -> dict[str, Any]:
        nominal = self.nominal
        return {
            "effect": self.effect,
            "params": {k: _json_float(v) for k, v in self.params.items()},
            "n_extra": self.n_extra,
            "nominal_parameters": dict(zip(self.structure.names, map(float, self.theta))),
            "nominal_model": nominal.to_dict() if nominal is not None else None,
            "ar": self.ar.tolist(),
            "time_scale": TIME_SCALE,
        }


def _json_float(v: float) -> float | None:
    v = float(v)
    return v if np.isfinite(v) else None


# -- the refits ----------------------------------------------------------------------------------


@dataclass
class _Problem:
    structure: Structure
    u: Array
    y: Array
    warmup: int
    t0: float

    def residual(self, theta: Array, kwargs: dict[str, Any]) -> Array:
        try:
            y_hat = _simulate(self.structure, theta, kwargs, self.u, self.t0)
        except BacklashIdError:
            return np.full(self.y.size - self.warmup, 1e3 * (np.std(self.y) + 1.0))
        r = (self.y - y_hat)[self.warmup :]
        big = 1e3 * (np.std(self.y) + 1.0)
        return r if np.all(np.abs(r) < 1e3 * big) else np.full(r.size, big)

    def cost(self, theta: Array, kwargs: dict[str, Any]) -> float:
        r = self.residual(theta, kwargs)
        return float(r @ r)


def _levenberg_marquardt(fun: Callable[[Array], Array], x0: Array, lower: Array, upper: Array, max_iter: int) -> Array:
    """Levenberg-Marquardt with a forward-difference Jacobian, Marquardt's scaling and steps
    projected onto the bounds. Small p (<= ~20), long residual vectors: the normal equations
    J^T J (p x p) are cheap where a dense SVD of J is not."""
    x = np.clip(x0, lower, upper)
    r = fun(x)
    cost = float(r @ r)
    lam = 1e-3
    for _ in range(max_iter):
        h = 1e-6 * np.maximum(np.abs(x), 1e-2)
        h = np.where(x + h > upper, -h, h)
        jac = np.empty((r.size, x.size))
        for i in range(x.size):
            xi = x.copy()
            xi[i] += h[i]
            jac[:, i] = (fun(xi) - r) / h[i]
        a = jac.T @ jac
        g = jac.T @ r
        d = np.diag(a).copy()
        d[d <= 0] = 1.0
        accepted = False
        for _ in range(8):
            try:
                step = -np.linalg.solve(a + lam * np.diag(d), g)
            except np.linalg.LinAlgError:
                lam *= 10
                continue
            x_new = np.clip(x + step, lower, upper)
            r_new = fun(x_new)
            c_new = float(r_new @ r_new)
            if c_new < cost:
                accepted = True
                done = cost - c_new < 1e-8 * cost
                x, r, cost = x_new, r_new, c_new
                lam = max(lam / 3, 1e-9)
                break
            lam *= 4
        if not accepted or done:
            break
    return x


def _refit(
    prob: _Problem,
    theta0: Array,
    names: tuple[str, ...],
    e0: Array,
    lb: Array,
    ub: Array,
    effect: str,
    fixed: dict[str, float] | None = None,
    max_iter: int = 30,
) -> tuple[Array, dict[str, float], float]:
    """Output-error least squares over the nominal parameters and the effect's (continuous)
    parameters ``names`` from (theta0, e0), within bounds; ``fixed`` effect parameters held."""
    n = theta0.size
    fixed = fixed or {}

    def params(p: Array) -> dict[str, float]:
        return {**fixed, **dict(zip(names, map(float, p[n:])))}

    x0 = np.concatenate([theta0, np.clip(e0, lb, ub)])
    lower = np.concatenate([np.full(n, -np.inf), lb])
    upper = np.concatenate([np.full(n, np.inf), ub])
    fun = lambda p: prob.residual(p[:n], _effect_kwargs(effect, params(p)))  # noqa: E731
    p = _levenberg_marquardt(fun, x0, lower, upper, max_iter)
    return p[:n], params(p), prob.cost(p[:n], _effect_kwargs(effect, params(p)))


def _multi_start(
    prob: _Problem,
    theta0: Array,
    names: tuple[str, ...],
    starts: list[tuple[Array, dict[str, float]]],
    lb: Array,
    ub: Array,
    effect: str,
) -> tuple[Array, dict[str, float], float]:
    """A short refit from each start (effect values, fixed parameters), then the best one
    refitted to convergence."""
    short = [(_refit(prob, theta0, names, e0, lb, ub, effect, fixed, max_iter=5), fixed) for e0, fixed in starts]
    (theta, params, _), fixed = min(short, key=lambda s: s[0][2])
    e = np.array([params[k] for k in names])
    return _refit(prob, theta, names, e, lb, ub, effect, fixed)


def _fit_dead_time(prob: _Problem, theta0: Array) -> tuple[Array, dict[str, float], float]:
    # d is discrete: refit the nominal parameters at each d, keep the best
    none = np.zeros(0)
    return _multi_start(prob, theta0, (), [(none, {"d": d}) for d in range(1, MAX_DELAY + 1)], none, none, "dead_time")


def _fit_saturation(prob: _Problem, theta0: Array) -> tuple[Array, dict[str, float], float]:
    u = prob.u
    lb = np.array([u.min(), np.median(u)])
    ub = np.array([np.median(u), u.max()])
    # the gradient vanishes at the record's range: start from a few clipping levels
    starts = [(qlo, qhi) for qlo in (0.0, 0.05, 0.15) for qhi in (0.0, 0.05, 0.15) if qlo or qhi]
    scored = []
    for qlo, qhi in starts:
        e0 = np.array([np.quantile(u, qlo), np.quantile(u, 1 - qhi)])
        e0 = e0 + np.array([1e-9, -1e-9])
        scored.append((prob.cost(theta0, _effect_kwargs("saturation", {"lo": e0[0], "hi": e0[1]})), tuple(e0)))
    scored.sort()
    return _multi_start(prob, theta0, ("lo", "hi"), [(np.array(e0), {}) for _, e0 in scored[:3]], lb, ub, "saturation")


def _fit_friction(prob: _Problem, theta0: Array) -> tuple[Array, dict[str, float], float]:
    s = float(np.std(prob.u))
    lb, ub = np.zeros(2), np.array([2.0 * s + 1e-12, 2.0])
    # the error is not convex in (F_c, F_v): short refits from a few corners first
    starts = [(np.array([fc * s, fv]), {}) for fc, fv in ((0.02, 0.0), (0.15, 0.0), (0.05, 0.3), (0.3, 0.6))]
    return _multi_start(prob, theta0, ("F_c", "F_v"), starts, lb, ub, "friction")


def _fit_smooth(effect: str, bound: float) -> Callable[[_Problem, Array], tuple[Array, dict[str, float], float]]:
    def fit(prob: _Problem, theta0: Array) -> tuple[Array, dict[str, float], float]:
        names = AUGMENTATIONS[effect].names
        b = np.full(len(names), bound)
        return _refit(prob, theta0, names, np.zeros(len(names)), -b, b, effect)

    return fit


def _fit_compliance(prob: _Problem, theta0: Array) -> tuple[Array, dict[str, float], float]:
    names = ("k", "omega", "zeta")
    lb, ub = np.array([0.0, 0.02, 0.005]), np.array([1.5, 3.0, 0.9])
    # k = 0 leaves omega and zeta without a gradient. At fixed (omega, zeta) the output is
    # linear in k (y = y_nom + k (H f - f)): fit k to the nominal residual on a grid, then refit
    # everything from the best two grid points
    y_nom = _simulate(prob.structure, theta0, {}, prob.u, prob.t0)
    r0 = (prob.y - y_nom)[prob.warmup :]
    scored = []
    for omega in np.geomspace(0.04, 2.8, 16):
        for zeta in (0.02, 0.06, 0.15, 0.35):
            d = (_simulate(prob.structure, theta0, {"compliance": 1.0, "omega": omega, "zeta": zeta}, prob.u, prob.t0) - y_nom)[prob.warmup :]
            k = float(np.clip((d @ r0) / max(float(d @ d), 1e-300), 0.0, 1.5))
            scored.append((float(np.sum((r0 - k * d) ** 2)), (max(k, 1e-3), float(omega), zeta)))
    scored.sort()
    return _multi_start(prob, theta0, names, [(np.array(e0), {}) for _, e0 in scored[:3]], lb, ub, "compliance")


def _fit_quantization(prob: _Problem, theta0: Array) -> tuple[Array, dict[str, float], float]:
    # The error is piecewise constant in q with a minimum far narrower than any practical grid
    # of q (q off by 1 % moves level k by k %). The measured output itself shows the steps: its
    # values cluster at multiples of q, so mean cos(2 pi y / q) peaks at the step (the noise
    # after the quantiser only damps the peak). Candidates from that fine scan and from a
    # coarse scan of the error; the one of lowest error, then a fine scan of the error near it.
    y_sim = _simulate(prob.structure, theta0, {}, prob.u, prob.t0)
    spread = float(np.std(y_sim)) + 1e-12
    y = prob.y[prob.warmup :]
    grid = spread * np.geomspace(0.005, 1.0, 3000)
    score = np.array([np.mean(np.cos(2.0 * np.pi * y / q)) for q in grid])
    peaks = grid[np.argsort(score)[-3:]]
    coarse = spread * np.geomspace(0.005, 1.0, 60)
    candidates = list(peaks) + [coarse[int(np.argmin([prob.cost(theta0, {"quantum": q}) for q in coarse]))]]
    best_q, best_cost = 0.0, prob.cost(theta0, {})
    for q0 in candidates:
        for q in q0 * np.linspace(0.99, 1.01, 21):
            c = prob.cost(theta0, {"quantum": q})
            if c < best_cost:
                best_q, best_cost = float(q), c
    return theta0, {"q": best_q}, best_cost


def _fit_hysteresis(prob: _Problem, theta0: Array) -> tuple[Array, dict[str, float], float]:
    names = AUGMENTATIONS["hysteresis_memory"].names
    est = prob.structure.unpack(theta0)
    x = _core.LinearBlock(est.a, est.b).simulate(prob.u, [0.0] * len(est.a), [0.0] * len(est.b))
    sx = float(np.std(x)) + 1e-12
    r0 = prob.y - _simulate(prob.structure, theta0, {}, prob.u, prob.t0)

    def play(r: float) -> Array:
        p, out = 0.0, np.empty_like(x)
        for t, xt in enumerate(x):
            p = max(xt - r, min(xt + r, p))
            out[t] = p
        return out

    # the weights enter linearly at fixed half-widths: pick the pair of half-widths whose
    # plays explain most of the nominal residual, then refit everything from there
    radii = sx * np.geomspace(0.01, 2.0, 10)
    plays = [play(r)[prob.warmup :] for r in radii]
    target = r0[prob.warmup :]
    pairs = []
    for i in range(len(radii)):
        for j in range(i + 1, len(radii)):
            a = np.column_stack([plays[i], plays[j]])
            w, *_ = np.linalg.lstsq(a, target, rcond=None)
            rss = float(np.sum((target - a @ w) ** 2))
            pairs.append((rss, (float(radii[i]), float(w[0]), float(radii[j]), float(w[1]))))
    pairs.sort()
    lb = np.array([0.0, -np.inf] * N_PLAYS)
    ub = np.array([5 * sx, np.inf] * N_PLAYS)
    return _multi_start(prob, theta0, names, [(np.array(e0), {}) for _, e0 in pairs[:3]], lb, ub, "hysteresis_memory")


def _fit_bigger(prob: _Problem, theta0: Array, bigger: Structure, effect: str) -> tuple[Structure, Array, float]:
    """Refit in a larger structure that embeds the nominal one (new terms start at 0)."""
    s = prob.structure
    old = dict(zip(s.names, theta0))
    start = np.array([old.get(name, 0.0) for name in bigger.names])
    big = _Problem(bigger, prob.u, prob.y, prob.warmup, prob.t0)
    theta, _, cost = _refit(big, start, (), np.zeros(0), np.zeros(0), np.zeros(0), effect, max_iter=40)
    return bigger, theta, cost


def _fit_ar(prob: _Problem, theta0: Array) -> tuple[Array, float]:
    """AR(p) model of the nominal output error, p <= MAX_AR chosen by BIC (least squares)."""
    r = (prob.y - _simulate(prob.structure, theta0, {}, prob.u, prob.t0))[prob.warmup :]
    n = r.size
    best: tuple[float, Array] = (n * np.log(np.mean(r * r) + 1e-300), np.zeros(0))
    for p in range(1, MAX_AR + 1):
        a = np.column_stack([r[p - k : n - k] for k in range(1, p + 1)])
        phi, *_ = np.linalg.lstsq(a, r[p:], rcond=None)
        e = r[p:] - a @ phi
        bic = (n - p) * np.log(np.mean(e * e) + 1e-300) + p * np.log(n)
        if bic < best[0]:
            best = (bic, np.asarray(phi, dtype=np.float64))
    phi = best[1]
    e = r - _ar_predict(r, phi)
    return phi, float(e @ e)


def _check(model: CascadeModel, u_est: ArrayLike, y_est: ArrayLike, warmup: int) -> tuple[Array, Array]:
    if not isinstance(model, CascadeModel):
        raise ModelError(
            f"effects augment a CascadeModel (linear block -> backlash), got {type(model).__name__}: "
            "fit the nominal model with fit_cascade"
        )
    u = as_signal(u_est, "u_est").ravel()
    y = as_signal(y_est, "y_est").ravel()
    if u.shape != y.shape:
        raise DataError(f"u_est has {u.size} samples and y_est {y.size}: give one record (same length)")
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(y))):
        raise DataError("u_est or y_est holds NaN or inf: remove or interpolate those samples")
    if not isinstance(warmup, (int, np.integer)) or warmup < 0:
        raise DataError(f"warmup = {warmup!r}: give a whole number of samples >= 0")
    if u.size - warmup < 50:
        raise DataError(
            f"{u.size} estimation samples with warmup = {warmup} leave {u.size - warmup} to fit on: "
            "give a longer record (hundreds of samples at least) or a shorter warm-up"
        )
    return u, y


def fit_effect(
    effect: str,
    model: CascadeModel,
    u_est: ArrayLike,
    y_est: ArrayLike,
    *,
    warmup: int = 0,
    t0: float = 0.0,
    seed: int = 0,
) -> AugmentedModel:
    """Refit the nominal cascade ``model`` together with ``effect`` on the estimation record
    (free-run simulation error after ``warmup`` samples; colored_noise: an AR model of the
    output error, judged by one-step prediction). ``t0`` is the time of u_est[0] in the
    continuous record. Deterministic for a given input (``seed`` is accepted for API
    stability; no random starts are used)."""
    if effect not in EFFECTS:
        raise DataError(f"unknown effect {effect!r}: choose one of {', '.join(EFFECTS)}")
    u, y = _check(model, u_est, y_est, warmup)
    structure = _structure_of(model)
    theta0 = structure.pack(model)
    prob = _Problem(structure, u, y, int(warmup), float(t0))
    if effect == "colored_noise":
        phi, _ = _fit_ar(prob, theta0)
        params = {f"phi_{k}": float(phi[k - 1]) if k <= phi.size else 0.0 for k in range(1, MAX_AR + 1)}
        return AugmentedModel(effect, structure, theta0, params, {}, phi, n_extra=int(phi.size))
    if effect == "branch_degree":
        bigger = Structure(structure.na, structure.nb, structure.degree + 2)
        s, theta, _ = _fit_bigger(prob, theta0, bigger, effect)
        return AugmentedModel(effect, s, theta, {"extra_degree": 2.0}, {}, n_extra=4)
    if effect == "linear_order":
        bigger = Structure(structure.na + 1, structure.nb + 1, structure.degree)
        s, theta, _ = _fit_bigger(prob, theta0, bigger, effect)
        return AugmentedModel(effect, s, theta, {"extra_order": 1.0}, {}, n_extra=2)
    fitters: dict[str, Callable[[_Problem, Array], tuple[Array, dict[str, float], float]]] = {
        "dead_time": _fit_dead_time,
        "saturation": _fit_saturation,
        "friction": _fit_friction,
        "width_drift": _fit_smooth("width_drift", 50.0),
        "output_offset": _fit_smooth("output_offset", 1e3 * (float(np.std(y)) + 1.0)),
        "compliance": _fit_compliance,
        "quantization": _fit_quantization,
        "hysteresis_memory": _fit_hysteresis,
    }
    theta, params, _ = fitters[effect](prob, theta0)
    return AugmentedModel(effect, structure, theta, params, _effect_kwargs(effect, params), n_extra=len(AUGMENTATIONS[effect].names))


# -- screening -----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Screening:
    """Score test of the nominal residual against an effect's predicted change (its direction
    at a small, finite size): N R^2 of that regression, chi-square p-value."""

    effect: str
    statistic: float
    p_value: float
    n_directions: int

    def to_dict(self) -> dict[str, Any]:
        return {"effect": self.effect, "statistic": self.statistic, "p_value": self.p_value, "n_directions": self.n_directions}


def _directions(effect: str, structure: Structure, theta: Array, u: Array, t0: float, y_sim: Array) -> list[Array]:
    """Changes of the output that a small amount of the effect makes (finite differences with
    the augmented simulator; for non-smooth or discrete parameters a finite step)."""
    sim = lambda kw: _simulate(structure, theta, kw, u, t0) - y_sim  # noqa: E731
    su, sy = float(np.std(u)) + 1e-12, float(np.std(y_sim)) + 1e-12
    h = 1e-4
    if effect == "dead_time":
        return [sim({"delay": 1}), sim({"delay": 2})]
    if effect == "saturation":
        return [sim({"sat_lo": float(np.quantile(u, 0.1))}), sim({"sat_hi": float(np.quantile(u, 0.9))})]
    if effect == "friction":
        return [sim({"f_c": h * su}) / h, sim({"f_v": h}) / h]
    if effect == "width_drift":
        return [sim({"drift_left": h}) / h, sim({"drift_right": h}) / h]
    if effect == "output_offset":
        t = np.asarray((t0 + np.arange(u.size)) / TIME_SCALE, dtype=np.float64)
        return [np.ones(u.size), t]
    if effect == "compliance":
        return [sim({"compliance": 1.0, "omega": w, "zeta": 0.1}) for w in (0.1, 0.4, 1.5)]
    if effect == "quantization":
        return [sim({"quantum": q * sy}) for q in (0.1, 0.3)]
    if effect == "hysteresis_memory":
        return [sim({"play_r": [r * su], "play_w": [1.0]}) for r in (0.05, 0.3)]
    if effect == "branch_degree":
        est = structure.unpack(theta)
        out = []
        for side in (0, 1):  # the next power of each branch
            m_l, m_r = est.m_left + [0.0], est.m_right + [0.0]
            (m_l if side == 0 else m_r)[-1] = h
            y = _core.simulate_augmented(est.a, est.b, est.c_left, est.c_right, m_l, m_r, u, t0=t0)
            out.append((y - y_sim) / h)
        return out
    if effect == "linear_order":
        est = structure.unpack(theta)
        out = []
        for a, b in ((est.a + [h], est.b + [0.0]), (est.a + [0.0], est.b + [h])):
            y = _core.simulate_augmented(a, b, est.c_left, est.c_right, est.m_left, est.m_right, u, t0=t0)
            out.append((y - y_sim) / h)
        return out
    return []


def screen(
    model: CascadeModel,
    u_est: ArrayLike,
    y_est: ArrayLike,
    *,
    warmup: int = 0,
    t0: float = 0.0,
    candidates: tuple[str, ...] = EFFECTS,
) -> list[Screening]:
    """Score tests of every candidate on the estimation record, most significant first. For
    colored_noise the directions are the residual's own past (a Ljung-Box-like LM test)."""
    u, y = _check(model, u_est, y_est, warmup)
    structure = _structure_of(model)
    theta = structure.pack(model)
    y_sim = _simulate(structure, theta, {}, u, t0)
    r = (y - y_sim)[warmup:]
    out = []
    for effect in candidates:
        if effect == "colored_noise":
            full = y - y_sim
            dirs = [np.concatenate([np.zeros(k), full[:-k]]) for k in range(1, MAX_AR + 1)]
        else:
            dirs = _directions(effect, structure, theta, u, t0, y_sim)
        a = np.column_stack([d[warmup:] for d in dirs]) if dirs else np.zeros((r.size, 0))
        a = a[:, np.std(a, axis=0) > 1e-12 * (np.abs(a).max() + 1e-300)] if a.size else a
        if effect != "output_offset":
            a = np.column_stack([a, np.ones(r.size)]) if a.size else a
        if a.shape[1] == 0:
            out.append(Screening(effect, 0.0, 1.0, 0))
            continue
        coef, *_ = np.linalg.lstsq(a, r, rcond=None)
        fitted = a @ coef
        r2 = float(1.0 - np.sum((r - fitted) ** 2) / max(float(r @ r), 1e-300))
        dof = a.shape[1]
        stat = r.size * max(r2, 0.0)
        out.append(Screening(effect, stat, float(stats.chi2.sf(stat, dof)), dof))
    return sorted(out, key=lambda s: (s.p_value, -s.statistic))
