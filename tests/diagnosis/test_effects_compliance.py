"""Compliance of every effect's Rust simulation with the independent per-sample NumPy reference
(``backlashid.benchmarks._reference``), at random non-zero sizes: the model is tsdownsample's
``test_algos_python_compliance.py``. For every effect of the registry (and every pair of them):
random nominal cascades (orders 1-2, branch degree 1-3, increasing branches), random parameters
inside the effect's bounds, several input classes and record lengths (down to one sample), from
rest, from the input held before the record and from a random past; the augmented model as the diagnosis simulates it
(``AugmentedModel``, or the core simulator it calls from a random past) equals the reference to 1e-10 relative."""

from __future__ import annotations

import copy
import itertools
from collections.abc import Callable

import numpy as np
import pytest
from scipy import signal

import backlashid as bx
from backlashid import _core
from backlashid.benchmarks import _reference as ref
from backlashid.diagnosis import effects as fx
from backlashid.diagnosis.effects import _base
from backlashid.diagnosis.effects._colored_noise import MAX_AR
from backlashid.diagnosis.effects._dead_time import MAX_DELAY
from backlashid.identify import Structure

RTOL = 1e-10
LENGTHS = (1, 2, 3, 5, 17, 64, 300, 1500)
INPUTS = ("white", "lowpass", "triangle")
CASES_ALONE = 40  # random cases per effect
CASES_PAIR = 8  # random cases per pair of effects


class Case:
    """A random nominal cascade (as coefficient lists), a record, a start state and the effects
    put on it: the structure, the library's augmented model and the reference's arguments."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.na, self.nb, self.degree = int(rng.integers(1, 3)), int(rng.integers(1, 3)), int(rng.integers(1, 4))
        self.a = list(rng.choice([-1.0, 1.0]) * rng.uniform(0.2, 1.0, self.na))
        poles = rng.uniform(-0.85, 0.85, self.nb)
        if self.nb == 2 and rng.random() < 0.5:  # a complex pair
            r, phi = rng.uniform(0.3, 0.9), rng.uniform(0.2, 2.5)
            poles = np.array([r * np.exp(1j * phi), r * np.exp(-1j * phi)])
        self.b = list(np.real(np.poly(poles))[1:])
        while True:
            self.m_left = [1.0] + list(self._higher())
            self.m_right = [float(rng.uniform(0.5, 1.5))] + list(self._higher())
            self.c_left, self.c_right = float(rng.uniform(0.01, 0.8)), float(rng.uniform(0.01, 0.8))
            try:
                bx.GeneralBacklash(self.c_left, self.c_right, self.m_left, self.m_right)
                break
            except bx.ModelError:
                continue
        n = int(rng.choice(LENGTHS))
        self.u = _input(rng, str(rng.choice(INPUTS)), n)
        self.t0 = float(rng.integers(0, 3000))
        self.start = str(rng.choice(["rest", "held", "past"]))  # past: a random state of the core simulator
        self.y_prev = float(rng.uniform(-1.0, 1.0)) if self.start != "rest" else 0.0
        self.u_past, self.x_past = list(rng.standard_normal(self.na)), list(rng.standard_normal(self.nb))
        self.core: list[tuple[str, tuple[float, ...]]] = []
        self.ar = np.zeros(0)

    def _higher(self) -> list[float]:
        """m_2 (small) and m_3 (small, positive: the cubic stays increasing) to the degree."""
        terms = [float(self.rng.uniform(-0.1, 0.1)), float(self.rng.uniform(0.04, 0.1))]
        return terms[: self.degree - 1]

    def structure(self) -> Structure:
        """The structure of the current coefficient lists."""
        return Structure(len(self.a), len(self.b), len(self.m_left))

    def model(self) -> fx.AugmentedModel:
        """The library's augmented model of the case (theta packed from the coefficient lists)."""
        s = self.structure()
        cascade = bx.CascadeModel(bx.LinearBlock(self.a, self.b), bx.GeneralBacklash(self.c_left, self.c_right, self.m_left, self.m_right))
        return fx.AugmentedModel("case", s, s.pack(cascade), {}, tuple(self.core), ar=self.ar)

    def problem(self) -> _base.RefitRecords:
        """The record as a refit sees it (bounds that depend on the record)."""
        y = ref.augmented_cascade(self.a, self.b, self.c_left, self.c_right, self.m_left, self.m_right, self.u)
        return _base.RefitRecords(self.structure(), self.u, y, 0, self.t0)

    def at_rest(self) -> Case:
        """The same case started from rest."""
        rest = copy.copy(self)
        rest.start, rest.y_prev = "rest", 0.0
        return rest

    def state(self) -> tuple[list[float], list[float]]:
        """u_past, x_past of the start: rest, the input u[0] held before the record, or a random
        past (extended with zeros where linear_order lengthened the block)."""
        if self.start == "past":
            return self.u_past + [0.0] * (len(self.a) - self.na), self.x_past + [0.0] * (len(self.b) - self.nb)
        if self.start == "rest":
            return [0.0] * len(self.a), [0.0] * len(self.b)
        x_eq = _base.held_x(bx.LinearBlock(self.a, self.b), float(self.u[0]))
        return [float(self.u[0])] * len(self.a), [x_eq] * len(self.b)

    def reference(self) -> np.ndarray:
        """The reference's free-run output from the case's state."""
        u_past, x_past = self.state()
        return ref.augmented_cascade(
            self.a, self.b, self.c_left, self.c_right, self.m_left, self.m_right, self.u,
            effects=self.core, t0=self.t0, time_scale=_base.TIME_SCALE, u_past=u_past, x_past=x_past, y_prev=self.y_prev,
        )  # fmt: skip


def _input(rng: np.random.Generator, kind: str, n: int) -> np.ndarray:
    """White, low-pass filtered white, or a slow ramp/triangle."""
    if kind == "white":
        return rng.uniform(-1.5, 1.5, n)
    if kind == "lowpass":
        p = rng.uniform(0.7, 0.98)
        return np.asarray(signal.lfilter([1.0 - p], [1.0, -p], rng.standard_normal(n) * 3.0), dtype=np.float64)
    period, phase = rng.uniform(40.0, 600.0), rng.uniform()
    return 1.5 * (2.0 * np.abs(2.0 * ((np.arange(n) / period + phase) % 1.0) - 1.0) - 1.0) + rng.uniform(-0.3, 0.3)


def _within(rng: np.random.Generator, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Uniform inside [lower, upper]."""
    return lower + rng.uniform(0.0, 1.0, lower.size) * (upper - lower)


def _simulated(name: str, sample: Callable[[Case, _base.RefitRecords], list[float]]) -> Callable[[Case], None]:
    """Put a simulated effect with sampled parameters (in the catalogue's order) on a case."""

    def put(case: Case) -> None:
        params = [float(v) for v in sample(case, case.problem())]
        effect = fx.REGISTRY[name]
        # every size non-zero (dynamic friction's source is a choice: 0 is driven by x)
        assert all(v != 0.0 for k, v in zip(effect.parameters, params) if k != "source"), f"{name}: zero-size parameters {params}"
        case.core.extend(effect.core(dict(zip(effect.parameters, params))))

    return put


def _saturation(case: Case, prob: _base.RefitRecords) -> list[float]:
    lower, upper = fx.REGISTRY["saturation"].bounds(prob)
    lo, hi = _within(case.rng, lower, upper)
    return [lo, hi] if lo < hi else [lo - 0.1, hi + 0.1]  # a record of one value: bounds around it


def _clip(name: str) -> Callable[[Case, _base.RefitRecords], list[float]]:
    """(lo, hi) of a clipping effect inside its bounds on the record (around a record of one
    value; a level of exactly 0, an output resting in the dead band, moved off it)."""

    def sample(case: Case, prob: _base.RefitRecords) -> list[float]:
        lower, upper = fx.REGISTRY[name].bounds(prob)
        lo, hi = _within(case.rng, lower, upper)
        lo, hi = (lo, hi) if lo < hi else (lo - 0.1, hi + 0.1)
        return [lo or -1e-3, hi or 1e-3]

    return sample


def _friction(case: Case, prob: _base.RefitRecords) -> list[float]:
    lower, upper = fx.REGISTRY["friction"].bounds(prob)
    f_c, f_v = _within(case.rng, lower, upper)
    return [f_c if f_c > 0 else 0.05, f_v]


def _compliance(case: Case, prob: _base.RefitRecords) -> list[float]:
    lower, upper = fx.REGISTRY["compliance"].bounds(prob)
    return list(_within(case.rng, np.maximum(lower, 1e-3), upper))  # k > 0


def _hysteresis(case: Case, prob: _base.RefitRecords) -> list[float]:
    sx = float(np.std(ref.difference_equation([0.0, *case.a], case.b, case.u))) + 0.05
    r = case.rng.uniform(0.01, 5.0, 2) * sx  # inside [0, 5 std(x)]
    w = case.rng.standard_normal(2)
    return [r[0], w[0], r[1], w[1]]


def _dynamic_friction(case: Case, prob: _base.RefitRecords) -> list[float]:
    k_f, z_s, lam = _within(case.rng, *fx.REGISTRY["dynamic_friction"].bounds(prob))
    return [k_f, z_s, lam or 0.01, float(case.rng.integers(3))]  # driven by x, u or f


def _feedback_hysteresis(case: Case, prob: _base.RefitRecords) -> list[float]:
    """A restoring force up to half the drive's scale, saturating within about one std(x);
    some cases run away (the core's refusal is then checked)."""
    alpha, beta = case.rng.uniform(0.01, 0.5), case.rng.uniform(0.0, 2.0)
    gamma, k_3 = case.rng.uniform(-0.5, 0.5) * beta, case.rng.uniform(-0.05, 0.2)
    return [alpha, beta or 0.5, gamma or 0.1, k_3 or 0.01]


def _creep(case: Case, prob: _base.RefitRecords) -> list[float]:
    return list(_within(case.rng, *fx.REGISTRY["creep"].bounds(prob)))


def _quantization(case: Case, prob: _base.RefitRecords) -> list[float]:
    spread = float(np.std(prob.y)) + 0.05
    return [spread * float(np.exp(case.rng.uniform(np.log(0.005), 0.0)))]


def _branch_degree(case: Case) -> None:
    """Two more terms of each branch, non-zero (and small, so the branches stay increasing)."""
    for m in (case.m_left, case.m_right):
        m.extend(float(v) for v in case.rng.choice([-1.0, 1.0]) * case.rng.uniform(1e-3, 5e-3, 2))


def _linear_order(case: Case) -> None:
    """One more coefficient in a and in b, non-zero."""
    case.a.append(float(case.rng.uniform(-0.3, 0.3)) or 0.1)
    case.b.append(float(case.rng.choice([-1.0, 1.0]) * case.rng.uniform(0.01, 0.05)))


def _colored_noise(case: Case) -> None:
    """An AR model of order 1..MAX_AR, non-zero coefficients."""
    p = int(case.rng.integers(1, MAX_AR + 1))
    case.ar = case.rng.choice([-1.0, 1.0], p) * case.rng.uniform(0.05, 0.4, p)


# How each effect of the registry is put on a random case, at a random non-zero size. A new
# effect needs its reference in backlashid.benchmarks._reference and its line here.
PUT: dict[str, Callable[[Case], None]] = {
    "dead_time": _simulated("dead_time", lambda case, prob: [int(case.rng.integers(1, MAX_DELAY + 1))]),
    "saturation": _simulated("saturation", _saturation),
    "friction": _simulated("friction", _friction),
    "width_drift": _simulated("width_drift", lambda case, prob: list(_within(case.rng, *fx.REGISTRY["width_drift"].bounds(prob)))),
    "output_offset": _simulated(  # the first 1 % of the bounds (+-1000 (std(y) + 1)), so 1e-10 of the output still sees the cascade
        "output_offset", lambda case, prob: list(_within(case.rng, *fx.REGISTRY["output_offset"].bounds(prob)) * 0.01)
    ),
    "branch_degree": _branch_degree,
    "linear_order": _linear_order,
    "compliance": _simulated("compliance", _compliance),
    "quantization": _simulated("quantization", _quantization),
    "hysteresis_memory": _simulated("hysteresis_memory", _hysteresis),
    "colored_noise": _colored_noise,
    "dynamic_friction": _simulated("dynamic_friction", _dynamic_friction),
    "feedback_hysteresis": _simulated("feedback_hysteresis", _feedback_hysteresis),
    "creep": _simulated("creep", _creep),
    "state_saturation": _simulated("state_saturation", _clip("state_saturation")),
    "sensor_saturation": _simulated("sensor_saturation", _clip("sensor_saturation")),
}


def _equal(run: Callable[[], np.ndarray], want: np.ndarray, label: str) -> None:
    """``run()`` equals ``want`` to RTOL relative, or, where the reference diverges (friction's
    feedback of F_v within its bounds can be unstable), ``run()`` refuses the divergence."""
    if not np.all(np.isfinite(want)):
        with pytest.raises(bx.ModelError, match="diverged"):
            run()
        return
    scale = max(1.0, float(np.max(np.abs(want))))
    np.testing.assert_allclose(run(), want, rtol=RTOL, atol=RTOL * scale, err_msg=label)


def _check(case: Case, label: str) -> None:
    """The library's augmented model equals the reference: free run from the case's state, and
    the one-step prediction (the noise model on the output error) from rest."""
    model = case.model()
    with np.errstate(over="ignore", invalid="ignore"):
        want, rest = case.reference(), case.at_rest().reference()
    if case.start == "past":  # the core simulator AugmentedModel calls, from any state
        u_past, x_past = case.state()
        chain = (case.a, case.b, case.c_left, case.c_right, case.m_left, case.m_right)

        def run() -> np.ndarray:
            return _core.simulate_augmented(
                *chain, case.u, effects=case.core, t0=case.t0, time_scale=_base.TIME_SCALE, u_past=u_past, x_past=x_past, y_prev=case.y_prev
            )
    else:

        def run() -> np.ndarray:
            return model.simulate(case.u, case.t0, y_prev=case.y_prev, held=case.start == "held")

    _equal(run, want, f"{label}: simulation")
    if not np.all(np.isfinite(rest)):  # no finite record to predict: from rest it diverges too
        _equal(lambda: model.simulate(case.u, case.t0), rest, f"{label}: simulation from rest")
        return
    y = rest + 0.1 * case.rng.standard_normal(rest.size)
    want = rest + ref.ar_prediction(y - rest, case.ar)
    _equal(lambda: model.predict(case.u, y, case.t0), want, f"{label}: prediction")


def test_every_effect_of_the_registry_has_a_reference() -> None:
    missing = sorted(set(fx.REGISTRY) - set(PUT))
    assert not missing, (
        f"effects without a compliance reference: {missing}: add each one's per-sample reference to "
        "backlashid/benchmarks/_reference.py (augmented_cascade) and its sampler to PUT in this file"
    )


@pytest.mark.parametrize("effect", fx.EFFECTS)
def test_each_effect_equals_the_reference(effect: str) -> None:
    if effect not in PUT:
        pytest.fail(f"{effect} has no reference: add it to backlashid/benchmarks/_reference.py and PUT here")
    rng = np.random.default_rng([16, fx.EFFECTS.index(effect)])
    for i in range(CASES_ALONE):
        case = Case(rng)
        PUT[effect](case)
        _check(case, f"{effect} case {i} (na={case.na}, nb={case.nb}, n={case.degree}, N={case.u.size}, start={case.start})")


@pytest.mark.parametrize("pair", list(itertools.combinations(fx.EFFECTS, 2)), ids="+".join)
def test_effects_two_at_a_time_equal_the_reference(pair: tuple[str, str]) -> None:
    for effect in pair:
        if effect not in PUT:
            pytest.fail(f"{effect} has no reference: add it to backlashid/benchmarks/_reference.py and PUT here")
    rng = np.random.default_rng([16, 99, fx.EFFECTS.index(pair[0]), fx.EFFECTS.index(pair[1])])
    for i in range(CASES_PAIR):
        case = Case(rng)
        for effect in pair:
            PUT[effect](case)
        _check(case, f"{'+'.join(pair)} case {i} (N={case.u.size}, start={case.start})")


def test_stick_slip_friction_equals_the_reference() -> None:
    """The stick-slip form of friction (``rust/core/src/effects/stick_slip.rs``, no catalogue
    entry of its own: the friction effect refits it), alone and after a dead time and a
    saturation, at random sizes inside the refit's bounds, from every start."""
    rng = np.random.default_rng([16, 99])
    for i in range(CASES_ALONE):
        case = Case(rng)
        if rng.random() < 0.3:
            PUT["dead_time"](case)
            PUT["saturation"](case)
        s = float(np.std(case.u)) + 0.05
        f_c, f_v, f_s = rng.uniform(0.0, 2.0 * s), rng.uniform(0.0, 2.0), rng.uniform(0.0, 2.0 * s) * (rng.random() < 0.7)
        case.core.append(("stick_slip", (float(f_c), float(f_v), float(f_s), float(rng.uniform(0.01, 1.0) * s))))
        _check(case, f"stick_slip case {i} (na={case.na}, nb={case.nb}, N={case.u.size}, start={case.start})")
