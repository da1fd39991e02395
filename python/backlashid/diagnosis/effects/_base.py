"""The one base of the effect catalogue: :class:`Effect`, the augmented model it refits, and
the shared refit machinery.

Each effect of the catalogue is an augmentation of the nominal chain (linear block, eq 16
-> general backlash, eq 1, and for the sandwich its output block, eq 29; the input backlash is
the sandwich with input block 1) that gives exactly the nominal model at zero size (the Rust
core's ``simulate_augmented``; each effect's definition and its stage in
``rust/core/src/effects/``). An effect's
module (one per effect in this package) subclasses :class:`Effect` with its parameters, their
start values and bounds, how it is refitted and screened, and its place in the ranking order;
the registry (``_registry``) finds the modules itself.

Time: drift rates are per ``TIME_SCALE`` samples of the continuous record (the validation
record follows the estimation record, so it starts at t0 = len(u_est)).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ... import _core
from ..._json import json_float
from ..._validation import as_signal, check_same_length
from ...errors import BacklashIdError, DataError, ModelError
from ...identify import Structure, levenberg_marquardt
from ...models import CascadeModel, LinearBlock

__all__ = ["Augmentation", "AugmentedModel", "Effect", "Screening", "TIME_SCALE"]

TIME_SCALE = 1000.0  # samples per time unit of the drift rates
MAX_ITER = 40  # most iterations of a refit to convergence

Array = NDArray[np.float64]
CoreEffects = tuple[tuple[str, tuple[float, ...]], ...]  # (name, parameters) for _core.simulate_augmented
# An explicit start (any of u_past, x_past, y_past, w_past: lists, most recent first; the
# others at rest), the keywords of _core.simulate_augmented and _core.AugmentedProblem.
Start = dict[str, list[float]]
Fitted = tuple[Array, dict[str, float], float]  # nominal parameters, the effect's, cost


@dataclass(frozen=True)
class Augmentation:
    """An effect's own parameters, their values at zero size (the nominal model) and what they
    mean.

    Attributes
    ----------
    effect : str
        The effect's name, one of ``EFFECTS``.
    names : tuple of str
        Its parameters' names.
    zero : tuple of float
        Their values at zero size.
    description : str
        What the effect does to the nominal cascade.

    Examples
    --------
    >>> from backlashid.diagnosis.effects import AUGMENTATIONS
    >>> AUGMENTATIONS["friction"].names
    ('F_c', 'F_v')
    """

    effect: str
    names: tuple[str, ...]
    zero: tuple[float, ...]
    description: str


def held_x(block: LinearBlock, u0: float) -> float:
    """x of the linear block (16) at rest after the input was held at u0: static gain x u0."""
    gain = block.static_gain()
    if not np.isfinite(gain):
        raise ModelError(
            f"the linear block {block.a.tolist()}, {block.b.tolist()} has a pole at z = 1, so no equilibrium "
            "holds it at a constant input: start from rest (initial_state='rest')"
        )
    return gain * u0


def held_past(block: LinearBlock, u0: float, hold: int | None = None) -> tuple[list[float], list[float]]:
    """The pasts (u_past, x_past, most recent first) of the linear block (16) after the input
    was held at u0: for ``hold`` samples from rest, or for ever if None (its equilibrium,
    :func:`held_x`).

    A finite hold is what a record of that length can vouch for: the block's step response
    over ``hold`` samples is its response to an input the record has shown, while its
    equilibrium is its static gain, which a slow pole almost cancelled by a zero at z = 1 leaves
    undetermined by the record (a pole at 1 - 1e-8 makes the gain anything from its fast part
    to +-1e8 times the pole's residue; the validation start from it ran away to 1e5 times the
    output's range, issue 18)."""
    if hold is None:
        x_eq = held_x(block, u0)
        return [u0] * block.na, [x_eq] * block.nb
    x = block.simulate(np.full(hold, u0)) if hold > 0 else np.zeros(0)
    x_past = [float(v) for v in x[::-1][: block.nb]]
    return [u0] * min(hold, block.na) + [0.0] * max(block.na - hold, 0), x_past + [0.0] * (block.nb - len(x_past))


def simulate(
    structure: Structure,
    theta: Array,
    effects: CoreEffects,
    u: Array,
    t0: float,
    y_prev: float = 0.0,
    held: bool = False,
    start: Start | None = None,
) -> Array:
    """The augmented chain's output (``_core.simulate_augmented``; a sandwich structure runs
    its output block too). ``held``: the linear block starts at its equilibrium with u[0] (the
    input held before the record for ever), a sandwich's output block at its equilibrium with
    y_prev, instead of at rest; ``start``: an explicit state instead; ``y_prev`` is the
    backlash memory y(0)."""
    return Simulator(structure, theta, effects, t0)(u, y_prev, held, start)


class Simulator:
    """One augmented chain's simulation, unpacked once: ``(u, y_prev, held, start) -> output``,
    for the many runs of one model that differ in the start only (the validation start's
    search). ``hold``: the held start holds the input (and a sandwich's output block its input
    y_prev) for that many samples from rest (None: for ever, the equilibrium),
    :func:`held_past`."""

    def __init__(self, structure: Structure, theta: Array, effects: CoreEffects, t0: float, hold: int | None = None) -> None:
        est = structure.unpack(theta)
        self.chain = est.chain()
        self.output: dict[str, list[float]] = {"r": est.r, "s": est.s} if structure.is_sandwich else {}
        self.effects = list(effects)
        self.t0 = float(t0)
        self.hold = hold
        self._held: dict[tuple[float, float], dict[str, Any]] = {}

    def held_state(self, u0: float, y_prev: float = 0.0) -> dict[str, Any]:
        """The linear block's past after the input was held at u0, and a sandwich's output
        block's after its input was held at y_prev (:func:`held_past`)."""
        key = (u0, y_prev if self.output else 0.0)
        if key not in self._held:
            u_past, x_past = held_past(LinearBlock(self.chain[0], self.chain[1]), u0, self.hold)
            state: dict[str, Any] = {"u_past": u_past, "x_past": x_past}
            if self.output:
                y_past, w_past = held_past(LinearBlock(self.output["r"], self.output["s"]), y_prev, self.hold)
                state.update(y_past=[y_prev, *y_past[1:]], w_past=w_past)
            self._held[key] = state
        return self._held[key]

    def __call__(self, u: Array, y_prev: float = 0.0, held: bool = False, start: Start | None = None) -> Array:
        if held and start is not None:
            raise DataError("held=True and an explicit start both given: give one of them")
        state = self.held_state(float(u[0]), float(y_prev)) if held else dict(start or {})
        return _core.simulate_augmented(
            *self.chain, u, r=self.output.get("r"), s=self.output.get("s"), effects=self.effects, t0=self.t0,
            time_scale=TIME_SCALE, y_prev=float(y_prev), u_past=state.get("u_past"), x_past=state.get("x_past"),
            y_past=state.get("y_past"), w_past=state.get("w_past"),
        )  # fmt: skip


def ar_predict(residual: Array, phi: Array) -> Array:
    """One-step prediction of an AR process from its past (zero before the record)."""
    pred = np.zeros_like(residual)
    for k, c in enumerate(phi, 1):
        pred[k:] += c * residual[:-k]
    return pred


@dataclass(frozen=True)
class AugmentedModel:
    """A nominal cascade refitted together with one effect.

    Attributes
    ----------
    effect : str
        The effect's name.
    structure : Structure
        The nominal structure (bigger for branch_degree and linear_order).
    theta : ndarray
        The refitted nominal parameters (the structure's physical vector).
    params : dict of str to float
        The effect's own fitted parameters.
    core : tuple
        The effect as (name, parameters) pairs of ``_core.simulate_augmented`` (empty where it
        does not act on the simulation).
    ar : ndarray
        The AR noise model's coefficients (colored_noise only).
    n_extra : int
        The number of parameters over the nominal model.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> from backlashid.identify import Structure
    >>> from backlashid.diagnosis.effects import AugmentedModel
    >>> m = bid.example1()
    >>> s = Structure(2, 2, 3)
    >>> aug = AugmentedModel("dead_time", s, s.pack(m), {"d": 1.0}, (("dead_time", (1.0,)),), n_extra=1)
    >>> u = np.ones(5)
    >>> bool(np.allclose(aug.simulate(u)[1:], m.simulate(np.r_[0.0, u[:-1]])[1:]))
    True
    """

    effect: str
    structure: Structure
    theta: Array = field(repr=False)
    params: dict[str, float]
    core: CoreEffects = field(default=(), repr=False)
    ar: Array = field(default_factory=lambda: np.zeros(0), repr=False)
    n_extra: int = 0

    def simulate(self, u: ArrayLike, t0: float = 0.0, *, y_prev: float = 0.0, held: bool = False, start: Start | None = None) -> Array:
        """Free-run output for the input u.

        Parameters
        ----------
        u : array_like
            Input, 1-D; u[0] is sample ``t0`` of the continuous record.
        t0 : float, default 0.0
            Time of u[0] in samples (drifts only).
        y_prev : float, default 0.0
            The backlash memory before the first sample.
        held : bool, default False
            Start the linear block at its equilibrium with u[0] (a sandwich's output block at
            its equilibrium with ``y_prev``) instead of at rest.
        start : dict, optional
            An explicit start instead: any of ``u_past``, ``x_past`` (the input block's past,
            most recent first) and for a sandwich ``y_past`` (``y_past[0] = y_prev``),
            ``w_past`` (the output block's); the others at rest.

        Returns
        -------
        ndarray
            The simulated output.

        Raises
        ------
        ModelError
            If the augmented model diverges or the linear block has a pole at 1 with ``held``.
        DataError
            If a past of ``start`` has the wrong length or a non-finite value.
        """
        u_arr = as_signal(u, "u").ravel()
        return self.simulator(t0)(u_arr, y_prev, held, start)

    def simulator(self, t0: float = 0.0, hold: int | None = None) -> Simulator:
        """This model's simulation unpacked once, ``(u, y_prev, held) -> output`` (u checked by
        the caller), for many runs that differ in the start.

        Parameters
        ----------
        t0 : float, default 0.0
            Time of u[0] in samples (drifts only).
        hold : int, optional
            The held start (``held=True``) holds u[0] for this many samples from rest (the
            diagnosis: the estimation record's length); default for ever (the equilibrium).

        Returns
        -------
        Simulator
            Callable ``(u, y_prev=0.0, held=False, start=None) -> ndarray``, as :meth:`simulate`.
        """
        return Simulator(self.structure, self.theta, self.core, t0, hold)

    def predict(self, u: ArrayLike, y: ArrayLike, t0: float = 0.0) -> Array:
        """One-step prediction: the simulation plus the noise model's prediction of the output
        error from its measured past (equals ``simulate`` without a noise model).

        Parameters
        ----------
        u : array_like
            Input, 1-D.
        y : array_like
            Measured output of the same record.
        t0 : float, default 0.0
            Time of u[0] in samples.

        Returns
        -------
        ndarray
            The one-step prediction of y.
        """
        return self.predict_from(self.simulate(u, t0), y)

    def predict_from(self, simulated: Array, y: ArrayLike) -> Array:
        """One-step prediction from this model's free-run output of the record.

        Parameters
        ----------
        simulated : ndarray
            This model's free-run output of the record.
        y : array_like
            Measured output of the same record.

        Returns
        -------
        ndarray
            The one-step prediction of y.

        Raises
        ------
        DataError
            If ``simulated`` and ``y`` differ in length.
        """
        y_arr = as_signal(y, "y").ravel()
        check_same_length(("u", simulated), ("y", y_arr))
        return simulated + ar_predict(y_arr - simulated, self.ar) if self.ar.size else simulated

    @property
    def nominal(self) -> CascadeModel | None:
        """The refitted nominal part as a model, None if it is not a valid backlash."""
        try:
            return self.structure.model(self.theta)  # type: ignore[return-value]
        except ModelError:
            return None

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe description (parameters, refitted nominal model, noise model).

        Returns
        -------
        dict
            ``json.dumps`` works on it.
        """
        nominal = self.nominal
        return {
            "effect": self.effect,
            "params": {k: json_float(v) for k, v in self.params.items()},
            "n_extra": self.n_extra,
            "nominal_parameters": dict(zip(self.structure.names, map(float, self.theta))),
            "nominal_model": nominal.to_dict() if nominal is not None else None,
            "ar": self.ar.tolist(),
            "time_scale": TIME_SCALE,
        }


@dataclass(frozen=True)
class Screening:
    """Score test of the nominal residual against an effect's predicted change.

    The change is the effect's direction at a small, finite size; the statistic is N R^2 of that
    regression with a chi-square p-value.

    Attributes
    ----------
    effect : str
        The effect's name.
    statistic : float
        N R^2.
    p_value : float
        Its chi-square p-value.
    n_directions : int
        Degrees of freedom (directions regressed on).

    Examples
    --------
    >>> from backlashid.diagnosis.effects import Screening
    >>> Screening("dead_time", 12.0, 0.002, 3).to_dict()["p_value"]
    0.002
    """

    effect: str
    statistic: float
    p_value: float
    n_directions: int

    def to_dict(self) -> dict[str, Any]:
        """The fields as a dict.

        Returns
        -------
        dict
            effect, statistic, p_value, n_directions.
        """
        return {"effect": self.effect, "statistic": self.statistic, "p_value": self.p_value, "n_directions": self.n_directions}


# -- the refits ----------------------------------------------------------------------------------


@dataclass
class Problem:
    """The estimation record an effect is refitted on (output-error least squares): from rest,
    or from an explicit ``start`` (``Start``'s pasts and the backlash memory ``y_prev``)."""

    structure: Structure
    u: Array
    y: Array
    warmup: int
    t0: float
    start: Start | None = None
    y_prev: float = 0.0

    def __post_init__(self) -> None:
        self.big = 1e3 * (float(np.std(self.y)) + 1.0)  # the residual of a diverging model

    def simulate(self, theta: Array, effects: CoreEffects = ()) -> Array:
        """The augmented chain on this record."""
        return simulate(self.structure, theta, effects, self.u, self.t0, self.y_prev, start=self.start)

    def output_residual(self, y_hat: Array) -> Array:
        """Output error of the output y_hat after the warm-up (a large constant where it diverges)."""
        r = (self.y - y_hat)[self.warmup :]
        return r if np.all(np.abs(r) < 1e3 * self.big) else np.full(r.size, self.big)

    def output_cost(self, y_hat: Array) -> float:
        """Sum of squared output errors of the output y_hat after the warm-up."""
        r = self.output_residual(y_hat)
        return float(r @ r)

    def cost(self, theta: Array, effects: CoreEffects) -> float:
        """Sum of squared output errors after the warm-up (large where the model diverges)."""
        try:
            y_hat = self.simulate(theta, effects)
        except BacklashIdError:
            return float(self.big**2 * (self.y.size - self.warmup))
        return self.output_cost(y_hat)

    def compiled(self, effects: CoreEffects, free: Sequence[str]) -> _core.AugmentedProblem:
        """The core's compiled refit of the nominal parameters and the effects' parameters
        ``free`` (the others held at their values in ``effects``): theta is the structure's
        vector (a sandwich's too) followed by the free parameters; exact sensitivities."""
        s, start = self.structure, self.start or {}
        return _core.AugmentedProblem(
            self.u, self.y, s.na, s.nb, s.degree, [(n, list(p)) for n, p in effects], list(free),
            nr=s.nr, ns=s.ns, warmup=self.warmup, t0=self.t0, time_scale=TIME_SCALE, y_prev=self.y_prev,
            u_past=start.get("u_past"), x_past=start.get("x_past"), y_past=start.get("y_past"), w_past=start.get("w_past"),
        )  # fmt: skip


class Effect:
    """One unmodelled effect of the catalogue: an augmentation of the nominal cascade.

    A subclass (one module per effect in this package) declares its ``augmentation`` (name,
    parameters, zero values, description) and its ``rank`` as class keywords, e.g.
    ``class DeadTime(Effect, rank=0, augmentation=Augmentation("dead_time", ...))``, and
    overrides what differs from the defaults: a refit of the nominal parameters together with
    the effect's continuous parameters from ``zero`` within ``bounds`` (:meth:`refit`, from
    :meth:`starts`), and a score-test screening on finite-size changes (:meth:`directions`).
    The registry finds every subclass in this package and orders them by ``rank``.

    Attributes
    ----------
    name : str
        The effect's name (its key in ``EFFECTS``).
    rank : int
        Its position in ``EFFECTS`` (and so in reports and ties).
    parameters : tuple of str
        Its own parameters, in the order of the Rust counterpart's parameter list.
    zero : tuple of float
        Their values at zero size (the nominal model).
    description : str
        What the effect does.
    simulated : bool
        Whether the effect acts on the simulation through its Rust counterpart
        (``rust/core/src/effects/<name>.rs``); False for those that change the structure or
        the noise model.
    intercept : bool
        Whether the screening regression adds a constant to the directions.

    Examples
    --------
    >>> from backlashid.diagnosis.effects import REGISTRY
    >>> REGISTRY["saturation"].core({"lo": -1.0, "hi": 2.0})
    (('saturation', (-1.0, 2.0)),)
    """

    name: ClassVar[str] = ""
    rank: ClassVar[int] = 0
    parameters: ClassVar[tuple[str, ...]] = ()
    zero: ClassVar[tuple[float, ...]] = ()
    description: ClassVar[str] = ""
    simulated: ClassVar[bool] = True
    intercept: ClassVar[bool] = True
    augmentation: ClassVar[Augmentation]

    def __init_subclass__(
        cls, *, rank: int = 0, augmentation: Augmentation | None = None, simulated: bool = True, intercept: bool = True, **kw: Any
    ) -> None:
        super().__init_subclass__(**kw)
        cls.rank, cls.simulated, cls.intercept = rank, simulated, intercept
        if augmentation is not None:
            cls.augmentation = augmentation
            cls.name, cls.parameters, cls.zero, cls.description = (
                augmentation.effect,
                augmentation.names,
                augmentation.zero,
                augmentation.description,
            )

    def __repr__(self) -> str:
        return f"<effect {self.name}>"

    def core(self, params: dict[str, float]) -> CoreEffects:
        """The effect as ``_core.simulate_augmented`` takes it.

        Parameters
        ----------
        params : dict of str to float
            The effect's parameters by name.

        Returns
        -------
        tuple
            ((name, parameters),) in the Rust counterpart's order, or () for an effect that
            does not act on the simulation.
        """
        if not self.simulated:
            return ()
        return ((self.name, tuple(float(params[n]) for n in self.parameters)),)

    def bounds(self, prob: Problem) -> tuple[Array, Array]:
        """Lower and upper bounds of the continuous parameters on this record.

        Parameters
        ----------
        prob : Problem
            The record the bounds may depend on (e.g. the input's range).

        Returns
        -------
        lower, upper : ndarray
            One bound per parameter (default: unbounded).
        """
        n = len(self.parameters)
        return np.full(n, -np.inf), np.full(n, np.inf)

    def starts(self, prob: Problem, theta0: Array) -> list[tuple[Array, dict[str, float]]]:
        """Starts of the refit (default: the zero size).

        Parameters
        ----------
        prob : Problem
            The estimation record, nominal structure and warm-up.
        theta0 : ndarray
            Nominal parameters to start from.

        Returns
        -------
        list of (ndarray, dict)
            Start values of the continuous parameters and the parameters held fixed.
        """
        return [(np.array(self.zero, dtype=np.float64), {})]

    def refit(self, prob: Problem, theta0: Array) -> Fitted:
        """Output-error refit of the nominal and the effect's parameters from :meth:`starts`.

        One start is refitted to convergence; from several, a short refit from each, then the
        best one to convergence (the package's Levenberg-Marquardt on the core's compiled
        refit, exact sensitivities, within :meth:`bounds`).

        Parameters
        ----------
        prob : Problem
            Record, structure and warm-up of the output-error criterion.
        theta0 : ndarray
            The nominal fit, where every start begins.

        Returns
        -------
        theta : ndarray
            The refitted nominal parameters.
        params : dict of str to float
            The effect's parameters.
        cost : float
            The sum of squared output errors after the warm-up.
        """
        lb, ub = self.bounds(prob)
        starts = self.starts(prob, theta0)
        if len(starts) == 1:
            e0, fixed = starts[0]
            return self._refit(prob, theta0, e0, lb, ub, fixed)
        return self._multi_start(prob, theta0, starts, lb, ub)

    def fit(self, prob: Problem, theta0: Array) -> AugmentedModel:
        """The refitted augmented model.

        Parameters
        ----------
        prob : Problem
            What the refit runs on.
        theta0 : ndarray
            Nominal parameters (the structure's physical vector).

        Returns
        -------
        AugmentedModel
            The nominal model refitted with this effect.
        """
        theta, params, _ = self.refit(prob, theta0)
        return AugmentedModel(self.name, prob.structure, theta, params, self.core(params), n_extra=len(self.parameters))

    def directions(self, screen: ScreenContext) -> list[Array]:
        """Changes of the nominal output that a small amount of the effect makes.

        Finite differences with the augmented simulator; for non-smooth or discrete
        parameters a finite step.

        Parameters
        ----------
        screen : ScreenContext
            The nominal fit on the estimation record.

        Returns
        -------
        list of ndarray
            One change per direction (default: none).
        """
        return []

    # -- shared refit machinery for subclasses
    def _refit(
        self,
        prob: Problem,
        theta0: Array,
        e0: Array,
        lb: Array,
        ub: Array,
        fixed: dict[str, float] | None = None,
        max_iter: int = 30,
        names: Sequence[str] | None = None,
    ) -> Fitted:
        """Output-error least squares over the nominal parameters and the effect's continuous
        parameters ``names`` (default: all but ``fixed``) from (theta0, e0), within bounds;
        ``fixed`` effect parameters held: the core's AugmentedProblem (exact sensitivities)
        searched by ``identify.levenberg_marquardt`` within the effect's bounds and the core's
        domains."""
        n = theta0.size
        fixed = fixed or {}
        names = tuple(n_ for n_ in self.parameters if n_ not in fixed) if names is None else tuple(names)

        def params(p: Array) -> dict[str, float]:
            return {**fixed, **dict(zip(names, map(float, p[n:])))}

        x0 = np.concatenate([theta0, np.clip(e0, lb, ub)])
        problem = prob.compiled(self.core(params(x0)), names)
        low, high = problem.bounds()
        lower = np.maximum(np.asarray(low, dtype=np.float64), np.concatenate([np.full(n, -np.inf), lb]))
        upper = np.minimum(np.asarray(high, dtype=np.float64), np.concatenate([np.full(n, np.inf), ub]))
        try:
            fit = levenberg_marquardt(problem, x0, lower=lower, upper=upper, max_iter=max_iter)
        except BacklashIdError:  # the start diverges: no refit from it
            return theta0, params(x0), prob.cost(theta0, self.core(params(x0)))
        p = fit.theta
        return p[:n], params(p), float(fit.cost)

    def _multi_start(self, prob: Problem, theta0: Array, starts: list[tuple[Array, dict[str, float]]], lb: Array, ub: Array) -> Fitted:
        """A short refit from each start (effect values, fixed parameters), then the best one
        refitted to convergence."""
        short = [(self._refit(prob, theta0, e0, lb, ub, fixed, max_iter=5), fixed) for e0, fixed in starts]
        (theta, params, _), fixed = min(short, key=lambda s: s[0][2])
        names = tuple(n_ for n_ in self.parameters if n_ not in fixed)
        e = np.array([params[k] for k in names])
        return self._refit(prob, theta, e, lb, ub, fixed)


@dataclass
class ScreenContext:
    """What the screening of every effect shares: the nominal fit on the estimation record."""

    structure: Structure
    theta: Array
    u: Array
    y: Array
    t0: float
    y_sim: Array  # the nominal simulation

    def change(self, effects: CoreEffects) -> Array:
        """The augmented simulation minus the nominal one."""
        return simulate(self.structure, self.theta, effects, self.u, self.t0) - self.y_sim


class StructureEffect(Effect):
    """An effect that is a bigger nominal structure whose new terms start at 0: refitted in
    that structure, screened by the derivatives in its first new terms (a subclass gives
    :meth:`bigger`, :meth:`first_terms`, ``extra`` and ``n_extra``)."""

    extra: ClassVar[dict[str, float]] = {}  # the effect's reported parameters
    n_extra: ClassVar[int] = 0  # parameters over the nominal model
    step: ClassVar[float] = 1e-4  # finite-difference step of the screening

    def bigger(self, s: Structure) -> Structure:
        """The bigger structure."""
        raise NotImplementedError

    def first_terms(self, est: Any, h: float) -> list[tuple[list[float], list[float], list[float], list[float]]]:
        """(a, b, m_L, m_R) of the nominal estimate ``est`` with one new term at ``h``, per direction."""
        raise NotImplementedError

    def fit(self, prob: Problem, theta0: Array) -> AugmentedModel:
        """Refit in the bigger structure, the new terms from 0: the cascade's compiled problem
        searched by the package's Levenberg-Marquardt (exact sensitivities)."""
        s, bigger = prob.structure, self.bigger(prob.structure)
        old = dict(zip(s.names, theta0))
        start = np.array([old.get(name, 0.0) for name in bigger.names])
        try:
            theta = levenberg_marquardt(bigger.problem(prob.u, prob.y, prob.warmup), start, max_iter=MAX_ITER).theta
        except BacklashIdError:  # the start diverges: the nominal model with the new terms at 0
            theta = start
        return AugmentedModel(self.name, bigger, theta, dict(self.extra), n_extra=self.n_extra)

    def directions(self, screen: ScreenContext) -> list[Array]:
        """Derivatives in the first new terms, by finite differences."""
        est = screen.structure.unpack(screen.theta)
        output = {"r": est.r, "s": est.s} if screen.structure.is_sandwich else {}
        out = []
        for a, b, m_l, m_r in self.first_terms(est, self.step):
            y = _core.simulate_augmented(a, b, est.c_left, est.c_right, m_l, m_r, screen.u, t0=screen.t0, **output)
            out.append((y - screen.y_sim) / self.step)
        return out
