"""The one base of the effect catalogue: :class:`Effect`, the augmented model it refits, and
the shared refit machinery.

Each effect of the catalogue is an augmentation of the nominal cascade (linear block, eq 16
-> general backlash, eq 1) that gives exactly the nominal model at zero size (the Rust core's
``simulate_augmented``; each effect's definition in ``rust/core/src/effects/``). An effect's
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
from ..._numerics import r_factor
from ..._validation import as_signal, check_same_length
from ...errors import BacklashIdError, DataError, ModelError
from ...identify import Structure, estimate_state, levenberg_marquardt, refine_values
from ...models import LinearBlock

__all__ = ["Augmentation", "AugmentedModel", "Effect", "Screening", "TIME_SCALE"]

TIME_SCALE = 1000.0  # samples per time unit of the drift rates
MAX_ITER = 40  # most iterations of a refit to convergence

Array = NDArray[np.float64]
CoreEffects = tuple[tuple[str, tuple[float, ...]], ...]  # (name, parameters) for _core.simulate_augmented
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


Start = dict[str, Any]  # a record's start as _core.simulate_augmented takes it: u_past, x_past, y_prev (, y_past, w_past)


def start_of(state: Any) -> Start:
    """A model state (``CascadeState``, ``SandwichState``, a ``Start`` dict or None for rest)
    as the keywords of ``_core.simulate_augmented`` / ``_core.AugmentedProblem``.

    A sandwich's ``y_past[0]`` is also the backlash memory (``SandwichState``)."""
    if state is None:
        return {}
    if isinstance(state, dict):
        return dict(state)
    out: Start = {"u_past": [float(v) for v in state.u_past], "x_past": [float(v) for v in state.x_past]}
    if hasattr(state, "w_past"):
        y_past = [float(v) for v in state.y_past]
        out.update(y_prev=y_past[0] if y_past else 0.0, y_past=y_past, w_past=[float(v) for v in state.w_past])
    else:
        out["y_prev"] = float(state.y_prev)
    return out


def _internal(start: Start) -> tuple[list[str], Array]:
    """The start's internal values (everything but the input's past) as one vector."""
    keys = [k for k in ("x_past", "y_past", "w_past") if k in start]
    values = [np.asarray(start[k], dtype=np.float64) for k in keys]
    if "y_past" not in start:
        keys.append("y_prev")
        values.append(np.array([float(start.get("y_prev", 0.0))]))
    return keys, np.concatenate(values) if values else np.zeros(0)


def _with(start: Start, keys: list[str], v: Array) -> Start:
    out = dict(start)
    k = 0
    for key in keys:
        n = 1 if key == "y_prev" else len(start[key])
        part = v[k : k + n]
        out[key] = float(part[0]) if key == "y_prev" else part.tolist()
        k += n
    if "y_past" in out and out["y_past"]:
        out["y_prev"] = float(out["y_past"][0])  # the sandwich's y(0) is the backlash memory
    return out


def refined_start(simulate: Any, u: Array, y: Array, samples: int, start: Start) -> Start:
    """An augmented model's start: the internal values of ``start`` refitted to the record's
    first ``samples`` samples (:func:`~backlashid.identify.refine_values`, damped Gauss-Newton on
    the core's simulation); ``start`` itself where that does not lower the error.

    Parameters
    ----------
    simulate : callable
        ``simulate(u, start) -> output`` of the augmented model.
    u, y : ndarray
        The record.
    samples : int
        Samples the start is fitted to.
    start : dict
        The nominal's start (:func:`nominal_start`); empty: rest, kept.

    Returns
    -------
    dict
        The refitted start.
    """
    if not start:
        return start
    n = max(1, min(samples, u.size))
    u_n, y_n = u[:n], y[:n]
    keys, v0 = _internal(start)

    def residual(v: Array) -> Array | None:
        try:
            r = y_n - simulate(u_n, _with(start, keys, v))
        except BacklashIdError:
            return None
        return r if np.all(np.isfinite(r)) else None

    return _with(start, keys, refine_values(residual, v0))


def _exact(v: float) -> float | str:
    """A parameter for JSON without loss: a float (JSON keeps its 17 digits), an infinity (an
    open clip) as "inf" / "-inf", which ``float`` reads back."""
    f = float(v)
    return f if np.isfinite(f) else ("inf" if f > 0 else "-inf")


def _core_chain(structure: Structure, theta: Array) -> tuple[tuple[Any, ...], dict[str, Any]]:
    """The chain's arguments of ``_core.simulate_augmented``: (a, b, c_L, c_R, m_L, m_R) and,
    for a sandwich, the output block's r and s as keywords."""
    est = structure.unpack(theta)
    extra: dict[str, Any] = {"r": list(est.r), "s": list(est.s)} if structure.is_sandwich else {}
    return tuple(est.chain()), extra


def _fitted_start(structure: Structure, start: Start) -> Start:
    """``start`` with each past cut or padded (by its oldest value) to the structure's orders: a
    bigger structure (linear_order) starts from the nominal's state."""
    if not start:
        return {}
    est_orders = {"u_past": structure.na, "x_past": structure.nb, "y_past": structure.nr, "w_past": structure.ns}
    out = dict(start)
    for key, n in est_orders.items():
        if key in out:
            v = list(out[key])
            out[key] = (v + [v[-1] if v else 0.0] * n)[:n]
    if not structure.is_sandwich:
        out.pop("y_past", None)
        out.pop("w_past", None)
    return out


def simulate(
    structure: Structure, theta: Array, effects: CoreEffects, u: Array, t0: float, y_prev: float = 0.0, held: bool = False,
    start: Start | None = None,
) -> Array:
    """The augmented chain's output (``_core.simulate_augmented``). ``held``: the linear block
    starts at its equilibrium with u[0] (the input held before the record for ever) instead of
    at rest; ``y_prev`` is the backlash memory y(0); ``start`` an explicit state (:func:`start_of`)
    that overrides both."""
    return Simulator(structure, theta, effects, t0)(u, y_prev, held, start=start)


class Simulator:
    """One augmented chain's simulation, unpacked once: ``(u, y_prev, held, start=None) ->
    output``, for the many runs of one model that differ in the start only (the validation
    start's search). ``hold``: the held start holds the input for that many samples from rest
    (None: for ever, the equilibrium), :func:`held_past`."""

    def __init__(self, structure: Structure, theta: Array, effects: CoreEffects, t0: float, hold: int | None = None) -> None:
        self.structure = structure
        self.chain, self.output_block = _core_chain(structure, theta)
        self.effects = list(effects)
        self.t0 = float(t0)
        self.hold = hold
        self._held: dict[float, dict[str, Any]] = {}

    def held_state(self, u0: float, y_prev: float = 0.0) -> dict[str, Any]:
        """The linear block's past after the input was held at u0 (:func:`held_past`); a
        sandwich's output block at its equilibrium with the backlash memory y_prev."""
        if u0 not in self._held:
            u_past, x_past = held_past(LinearBlock(self.chain[0], self.chain[1]), u0, self.hold)
            self._held[u0] = {"u_past": u_past, "x_past": x_past}
        state = dict(self._held[u0])
        if self.output_block:
            r, s = self.output_block["r"], self.output_block["s"]
            w = sum(r) / (1.0 + sum(s)) * y_prev  # eq (29) at rest with its input held at y_prev
            state.update(y_past=[y_prev] * len(r), w_past=[w] * len(s))
        return state

    def __call__(self, u: Array, y_prev: float = 0.0, held: bool = False, *, start: Start | None = None) -> Array:
        if start and held:
            raise DataError("a held start and a given start exclude each other: give held=True or start=..., not both")
        if start:
            state = _fitted_start(self.structure, start)
        else:
            state = dict(self.held_state(float(u[0]), float(y_prev)) if held else {}, y_prev=float(y_prev))
        return _core.simulate_augmented(
            *self.chain, u, effects=self.effects, t0=self.t0, time_scale=TIME_SCALE, **self.output_block, **state
        )


def linear_x(structure: Structure, theta: Array, u: Array) -> Array:
    """x, the output of the nominal linear block (16) of ``theta`` on the input u, from rest
    (the signal on which the effects of x act: their scales)."""
    est = structure.unpack(theta)
    return np.asarray(_core.LinearBlock(est.a, est.b).simulate(u, [0.0] * len(est.a), [0.0] * len(est.b)), dtype=np.float64)


def load_f(structure: Structure, theta: Array, u: Array) -> Array:
    """f, the backlash's output (eq 1) of the nominal chain of ``theta`` on the input u, from
    rest: the load's motion (before a sandwich's output block)."""
    chain, _ = _core_chain(structure, theta)
    return np.asarray(_core.simulate_augmented(*chain, u, effects=[], t0=0.0, time_scale=TIME_SCALE), dtype=np.float64)


def ar_predict(residual: Array, phi: Array) -> Array:
    """One-step prediction of an AR process from its past (zero before the record)."""
    pred = np.zeros_like(residual)
    for k, c in enumerate(phi, 1):
        pred[k:] += c * residual[:-k]
    return pred


@dataclass(frozen=True)
class AugmentedModel:
    """A nominal chain (cascade or sandwich) refitted together with one or more effects.

    Attributes
    ----------
    effect : str
        The effect added last (the candidate's name).
    structure : Structure
        The nominal structure (bigger for branch_degree and linear_order).
    theta : ndarray
        The refitted nominal parameters (the structure's physical vector).
    params : dict of str to float
        The last effect's own fitted parameters.
    core : tuple
        Every effect of the model as (name, parameters) pairs of ``_core.simulate_augmented``
        (empty where none acts on the simulation).
    ar : ndarray
        The AR noise model's coefficients (colored_noise only).
    n_extra : int
        The number of parameters over the nominal model.
    effects : tuple of str
        The catalogue effects of the model in the order added (default: ``(effect,)``).
    base_params : dict of str to dict
        The fitted parameters of the effects added before the last one, by effect.

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
    effects: tuple[str, ...] = ()
    base_params: dict[str, dict[str, float]] = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        if not self.effects and self.effect:
            object.__setattr__(self, "effects", (self.effect,))

    def simulate(
        self, u: ArrayLike, t0: float = 0.0, *, y_prev: float = 0.0, held: bool = False, initial_state: Any = None
    ) -> Array:
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
            Start the linear block at its equilibrium with u[0] instead of at rest.
        initial_state : CascadeState, SandwichState or dict, optional
            The nominal chain's state before the first sample, in the normalised model's
            units (m_L1 = 1, r_1 = 1: :meth:`nominal`'s); overrides ``y_prev`` and ``held``.
            The effects start at rest on it.

        Returns
        -------
        ndarray
            The simulated output.

        Raises
        ------
        ModelError
            If the augmented model diverges or the linear block has a pole at 1 with ``held``.
        """
        u_arr = as_signal(u, "u").ravel()
        return self.simulator(t0)(u_arr, y_prev, held, start=start_of(initial_state))

    def simulator(self, t0: float = 0.0, hold: int | None = None) -> Simulator:
        """This model's simulation unpacked once, ``(u, y_prev, held, start=None) -> ndarray``
        (u checked by the caller), for many runs that differ in the start.

        Parameters
        ----------
        t0 : float, default 0.0
            Time of u[0] in samples (drifts only).
        hold : int, optional
            The held start (``held=True``) holds u[0] for this many samples from rest;
            default for ever (the equilibrium).

        Returns
        -------
        Simulator
            Callable ``(u, y_prev=0.0, held=False, start=None) -> ndarray``, as :meth:`simulate`.
        """
        return Simulator(self.structure, self.theta, self.core, t0, hold)

    def simulate_from_samples(self, u: ArrayLike, y: ArrayLike, init_samples: int) -> Array:
        """The free-run simulation of the whole record from the state estimated on its first
        ``init_samples`` measured samples, as the diagnosis starts a record: the nominal part's
        state (:func:`~backlashid.identify.estimate_state`), its internal values refitted to the
        same samples with the effects (which start at rest on it). ``evaluate`` and
        ``simulate_from_samples`` of :mod:`backlashid.identify` take this model too.

        Parameters
        ----------
        u : array_like
            Input, 1-D (advanced by the nominal's feedthroughs, as the diagnosis drives it).
        y : array_like
            Measured output, as long as ``u``; only its first ``init_samples`` are used.
        init_samples : int
            Samples that set the state, 1..N.

        Returns
        -------
        ndarray
            The model's output for every sample of u.

        Raises
        ------
        DataError
            If the record is unusable or ``init_samples`` is not in 1..N.
        ModelError
            If the refitted nominal part is no valid model or the simulation diverges.
        """
        u_arr = as_signal(u, "u").ravel()
        y_arr = as_signal(y, "y").ravel()
        check_same_length(("u", u_arr), ("y", y_arr))
        if isinstance(init_samples, bool) or not isinstance(init_samples, (int, np.integer)) or not 1 <= init_samples <= u_arr.size:
            raise DataError(f"init_samples = {init_samples!r}: give a whole number of samples from 1 to the record's {u_arr.size}")
        nominal = self.nominal
        if nominal is None:
            raise ModelError("the refitted nominal part is no valid backlash model: its state cannot be estimated")
        n = int(init_samples)
        sim = self.simulator(0.0)
        start = start_of(estimate_state(nominal, u_arr, y_arr, samples=n))
        start = refined_start(lambda v, st: sim(v, start=st), u_arr, y_arr, n, start)
        return np.asarray(sim(u_arr, start=start), dtype=np.float64)

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
    def nominal(self) -> Any:
        """The refitted nominal part as a model (CascadeModel or SandwichModel), None if it is
        not a valid backlash."""
        try:
            return self.structure.model(self.theta)
        except ModelError:
            return None

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe description: every effect with its parameters, the refitted nominal
        parameters and model, the noise model; :meth:`from_dict` rebuilds the model.

        Returns
        -------
        dict
            ``json.dumps`` works on it.
        """
        nominal = self.nominal
        s = self.structure
        return {
            "kind": "augmented",
            "effect": self.effect,
            "effects": list(self.effects),
            "params": {k: json_float(v) for k, v in self.params.items()},
            "base_params": {e: {k: json_float(v) for k, v in p.items()} for e, p in self.base_params.items()},
            "core": [[name, [_exact(v) for v in values]] for name, values in self.core],
            "n_extra": self.n_extra,
            "structure": {"na": s.na, "nb": s.nb, "degree": s.degree, "nr": s.nr, "ns": s.ns},
            "nominal_parameters": dict(zip(s.names, map(float, self.theta))),
            "nominal_model": nominal.to_dict() if nominal is not None else None,
            "ar": self.ar.tolist(),
            "time_scale": TIME_SCALE,
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> AugmentedModel:
        """The model of :meth:`to_dict` (e.g. after a JSON round trip): it simulates bit for
        bit as the original.

        Parameters
        ----------
        d : dict
            What :meth:`to_dict` returned.

        Returns
        -------
        AugmentedModel
            The model.

        Raises
        ------
        DataError
            If ``d`` is not such a description.

        Examples
        --------
        >>> import json, numpy as np, backlashid as bid
        >>> from backlashid.identify import Structure
        >>> from backlashid.diagnosis.effects import AugmentedModel
        >>> s = Structure(2, 2, 3)
        >>> aug = AugmentedModel("output_offset", s, s.pack(bid.example1()), {"o_0": 0.1, "o_1": 0.0}, (("output_offset", (0.1, 0.0)),))
        >>> back = AugmentedModel.from_dict(json.loads(json.dumps(aug.to_dict())))
        >>> u = np.sin(0.1 * np.arange(50))
        >>> bool(np.array_equal(back.simulate(u), aug.simulate(u)))
        True
        """
        if not isinstance(d, dict) or d.get("kind") != "augmented":
            raise DataError("not the description of an augmented model: give what AugmentedModel.to_dict() returned")
        try:
            st = d["structure"]
            structure = Structure(int(st["na"]), int(st["nb"]), int(st["degree"]), int(st["nr"]), int(st["ns"]))
            theta = np.array([float(d["nominal_parameters"][n]) for n in structure.names], dtype=np.float64)
            core = tuple((str(name), tuple(float(v) for v in values)) for name, values in d["core"])
            return cls(
                effect=str(d["effect"]),
                structure=structure,
                theta=theta,
                params={str(k): float(v) for k, v in d["params"].items()},
                core=core,
                ar=np.asarray(d.get("ar", []), dtype=np.float64),
                n_extra=int(d["n_extra"]),
                effects=tuple(str(e) for e in d["effects"]),
                base_params={str(e): {str(k): float(v) for k, v in p.items()} for e, p in d.get("base_params", {}).items()},
            )
        except (KeyError, TypeError, ValueError) as err:
            raise DataError(f"the augmented model's description lacks or mangles {err}: give what AugmentedModel.to_dict() returned") from None


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


class RefitRecords:
    """The estimation records an effect is refitted on (output-error least squares).

    One record (u, y arrays) or several (lists of arrays: separate records of one system, each
    started from its own state, never joined); the criterion sums over the records after each
    one's warm-up. ``starts`` gives each record's state (:func:`start_of`; default rest) and
    ``t0s`` each record's time (drifts); ``base`` the effects already in the model (the
    composition's earlier steps), held at their values in every refit on this problem.

    For the effects' statistics ``u`` and ``y`` are the records' samples one after the other,
    ``simulate`` returns the records' outputs one after the other, and :meth:`scored` keeps the
    samples after each record's warm-up.
    """

    def __init__(
        self,
        structure: Structure,
        u: Array | Sequence[Array],
        y: Array | Sequence[Array],
        warmup: int,
        t0: float | Sequence[float] = 0.0,
        starts: Sequence[Start] | None = None,
        base: CoreEffects = (),
        base_params: dict[str, dict[str, float]] | None = None,
    ) -> None:
        us = [np.asarray(v, dtype=np.float64) for v in u] if isinstance(u, (list, tuple)) else [np.asarray(u, dtype=np.float64)]
        ys = [np.asarray(v, dtype=np.float64) for v in y] if isinstance(y, (list, tuple)) else [np.asarray(y, dtype=np.float64)]
        self.structure = structure
        self.records = list(zip(us, ys))
        self.warmup = int(warmup)
        self.t0s = [float(v) for v in t0] if isinstance(t0, (list, tuple)) else [float(t0)] * len(us)
        self.t0 = self.t0s[0]
        self.starts: list[Start] = [dict(s) for s in starts] if starts is not None else [{} for _ in us]
        self.base: CoreEffects = tuple(base)
        self.base_params = dict(base_params or {})
        self.u = np.concatenate(us)
        self.y = np.concatenate(ys)
        self._keep = np.concatenate([np.arange(v.size) >= self.warmup for v in us])
        self.big = 1e3 * (float(np.std(self.y)) + 1.0)  # the residual of a diverging model

    @property
    def n_scored(self) -> int:
        """Samples in the criterion (after each record's warm-up)."""
        return int(self._keep.sum())

    def scored(self, v: Array) -> Array:
        """The samples of a signal over the records (as ``simulate`` returns it) after each
        record's warm-up."""
        return np.asarray(v)[self._keep]

    def simulate(self, theta: Array, effects: CoreEffects = ()) -> Array:
        """The augmented chain (the base effects, then ``effects``) on every record from its
        start, the outputs one after the other."""
        out = [
            simulate(self.structure, theta, (*effects, *self.base), u, t0, start=start)
            for (u, _), t0, start in zip(self.records, self.t0s, self.starts)
        ]
        return np.concatenate(out)

    def linear_output(self, theta: Array) -> Array:
        """x of the (input) linear block of theta on every record from its start, one after the other."""
        est = self.structure.unpack(theta)
        out = []
        for (u, _), start in zip(self.records, self.starts):
            st = _fitted_start(self.structure, start)
            u_past = st.get("u_past", [0.0] * len(est.a))
            x_past = st.get("x_past", [0.0] * len(est.b))
            out.append(_core.LinearBlock(est.a, est.b).simulate(u, u_past, x_past))
        return np.concatenate(out)

    def output_residual(self, y_hat: Array) -> Array:
        """Output error of the output y_hat after the warm-ups (a large constant where it diverges)."""
        r = self.scored(self.y - y_hat)
        return r if np.all(np.abs(r) < 1e3 * self.big) else np.full(r.size, self.big)

    def output_cost(self, y_hat: Array) -> float:
        """Sum of squared output errors of the output y_hat after the warm-ups."""
        r = self.output_residual(y_hat)
        return float(r @ r)

    def cost(self, theta: Array, effects: CoreEffects) -> float:
        """Sum of squared output errors after the warm-ups (large where the model diverges)."""
        try:
            y_hat = self.simulate(theta, effects)
        except BacklashIdError:
            return float(self.big**2 * self.n_scored)
        return self.output_cost(y_hat)

    def compiled(self, effects: CoreEffects, free: Sequence[str], structure: Structure | None = None) -> Any:
        """The core's compiled refit of the nominal parameters and the effects' parameters
        ``free`` (the others, and the base effects, held at their values): theta is the
        structure's vector followed by the free parameters; exact sensitivities. ``effects``
        come first, so a free name that a base effect shares (lo, hi) is the new effect's. On
        several records: their sum (:class:`Records`)."""
        s = structure or self.structure
        listed = [(n, list(p)) for n, p in (*effects, *self.base)]
        parts = []
        for (u, y), t0, start in zip(self.records, self.t0s, self.starts):
            st = _fitted_start(s, start)
            kw: dict[str, Any] = {k: v for k, v in st.items() if k != "y_prev"}
            if s.is_sandwich:
                kw.update(nr=s.nr, ns=s.ns)
            parts.append(
                _core.AugmentedProblem(
                    u, y, s.na, s.nb, s.degree, listed, list(free),
                    warmup=min(self.warmup, u.size - 1), t0=t0, time_scale=TIME_SCALE, y_prev=float(st.get("y_prev", 0.0)), **kw,
                )
            )  # fmt: skip
        return parts[0] if len(parts) == 1 else Records(parts)

    def model(
        self, effect: str, structure: Structure, theta: Array, params: dict[str, float], core: CoreEffects, n_extra: int, ar: Array | None = None
    ) -> AugmentedModel:
        """The augmented model of a refit on this problem: the base effects, then ``effect``."""
        effects = tuple(self.base_params) + ((effect,) if effect not in self.base_params else ())
        return AugmentedModel(
            effect, structure, theta, params, (*core, *self.base), np.zeros(0) if ar is None else ar,
            n_extra + sum(len(p) for p in self.base_params.values()), effects, dict(self.base_params),
        )  # fmt: skip


class Records:
    """Several compiled refits of one model, one per record, as one problem for
    :func:`levenberg_marquardt`: the costs and gradients add, the output-error factors are
    joined exactly (the R factor of their stack); each record runs from its own start."""

    def __init__(self, parts: list[Any]) -> None:
        self.parts = parts

    @property
    def names(self) -> list[str]:
        return list(self.parts[0].names)

    @property
    def samples(self) -> int:
        return int(sum(p.samples for p in self.parts))

    @property
    def warmup(self) -> int:
        return int(sum(p.warmup for p in self.parts))

    def cost(self, theta: Array) -> float:
        return float(sum(p.cost(theta) for p in self.parts))

    def oe_factor(self, theta: Array) -> tuple[Array, float]:
        factors = [p.oe_factor(theta) for p in self.parts]
        return r_factor(np.vstack([np.asarray(f, dtype=np.float64) for f, _ in factors])), float(sum(c for _, c in factors))

    def gradient(self, theta: Array) -> tuple[Array, float]:
        grads = [p.gradient(theta) for p in self.parts]
        return np.sum([np.asarray(g, dtype=np.float64) for g, _ in grads], axis=0), float(sum(c for _, c in grads))

    def feasible(self, theta: Array) -> bool:
        return all(p.feasible(theta) for p in self.parts)

    def bounds(self) -> tuple[list[float], list[float]]:
        return self.parts[0].bounds()  # type: ignore[no-any-return]


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

    def bounds(self, prob: RefitRecords) -> tuple[Array, Array]:
        """Lower and upper bounds of the continuous parameters on this record.

        Parameters
        ----------
        prob : RefitRecords
            The record the bounds may depend on (e.g. the input's range).

        Returns
        -------
        lower, upper : ndarray
            One bound per parameter (default: unbounded).
        """
        n = len(self.parameters)
        return np.full(n, -np.inf), np.full(n, np.inf)

    def starts(self, prob: RefitRecords, theta0: Array) -> list[tuple[Array, dict[str, float]]]:
        """Starts of the refit (default: the zero size).

        Parameters
        ----------
        prob : RefitRecords
            The estimation record, nominal structure and warm-up.
        theta0 : ndarray
            Nominal parameters to start from.

        Returns
        -------
        list of (ndarray, dict)
            Start values of the continuous parameters and the parameters held fixed.
        """
        return [(np.array(self.zero, dtype=np.float64), {})]

    def refit(self, prob: RefitRecords, theta0: Array) -> Fitted:
        """Output-error refit of the nominal and the effect's parameters from :meth:`starts`.

        One start is refitted to convergence; from several, a short refit from each, then the
        best one to convergence (the package's Levenberg-Marquardt on the core's compiled
        refit, exact sensitivities, within :meth:`bounds`).

        Parameters
        ----------
        prob : RefitRecords
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

    def fit(self, prob: RefitRecords, theta0: Array) -> AugmentedModel:
        """The refitted augmented model.

        Parameters
        ----------
        prob : RefitRecords
            What the refit runs on.
        theta0 : ndarray
            Nominal parameters (the structure's physical vector).

        Returns
        -------
        AugmentedModel
            The nominal model refitted with this effect.
        """
        theta, params, _ = self.refit(prob, theta0)
        return prob.model(self.name, prob.structure, theta, params, self.core(params), len(self.parameters))

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
        prob: RefitRecords,
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

    def _multi_start(self, prob: RefitRecords, theta0: Array, starts: list[tuple[Array, dict[str, float]]], lb: Array, ub: Array) -> Fitted:
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
    y_sim: Array  # the simulation of the step's model (the nominal, or it with ``base``)
    start: Start = field(default_factory=dict)  # the record's start (rest if empty)
    base: CoreEffects = ()  # effects already in the step's model (the composition's earlier steps)

    def change(self, effects: CoreEffects) -> Array:
        """The augmented simulation (``effects`` on top of ``base``) minus the step's."""
        return simulate(self.structure, self.theta, (*effects, *self.base), self.u, self.t0, start=self.start) - self.y_sim


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

    def fit(self, prob: RefitRecords, theta0: Array) -> AugmentedModel:
        """Refit in the bigger structure, the new terms from 0: the core's compiled refit of
        that structure (with the base effects held, on every record from its start) searched
        by the package's Levenberg-Marquardt (exact sensitivities)."""
        s, bigger = prob.structure, self.bigger(prob.structure)
        old = dict(zip(s.names, theta0))
        start = np.array([old.get(name, 0.0) for name in bigger.names])
        try:
            theta = levenberg_marquardt(prob.compiled((), (), structure=bigger), start, max_iter=MAX_ITER).theta
        except BacklashIdError:  # the start diverges: the nominal model with the new terms at 0
            theta = start
        return prob.model(self.name, bigger, theta, dict(self.extra), (), self.n_extra)

    def directions(self, screen: ScreenContext) -> list[Array]:
        """Derivatives in the first new terms, by finite differences."""
        est = screen.structure.unpack(screen.theta)
        block = {"r": list(est.r), "s": list(est.s)} if screen.structure.is_sandwich else {}
        out = []
        for a, b, m_l, m_r in self.first_terms(est, self.step):
            st = _fitted_start(Structure(len(a), len(b), len(m_l), screen.structure.nr, screen.structure.ns), screen.start)
            y = _core.simulate_augmented(
                a, b, est.c_left, est.c_right, m_l, m_r, screen.u, effects=list(screen.base), t0=screen.t0, **block, **st
            )
            out.append((y - screen.y_sim) / self.step)
        return out
