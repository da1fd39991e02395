"""Withheld-effect benchmark cases (issue 4): random nominal cascades with one effect that the
nominal model leaves out, at a stated effect-to-noise ratio.

Each case is one continuous record, simulated sample by sample in plain NumPy (independently of
the diagnoser's augmentations), from rest at the start of a pre-roll that is then dropped, so
that neither the estimation record nor the validation record that directly follows it starts at
rest. Time t = 0 is the first estimation sample, T = n_est + n_val; drifts are functions of t/T.

    y = y_nominal + change + e,   e ~ N(0, noise_std^2) white,

where ``change`` is the effect's change of the noise-free output (for "colored_noise" the
coloured part of the noise) and ENR = RMS(change) / noise_std over both records. The effect's
size is scaled (by a bracketing root search) so that ENR hits the target at noise_std =
``noise_ratio`` * std(y_nominal); where the change is discrete in the size (dead_time) or jumps
(quantisation, Coulomb friction), noise_std is instead set from the change, RMS(change) / ENR.

Effects (the contract's definitions): dead_time u(t - d); saturation clip(u, lo, hi) before the
linear block; friction u_eff = u - F_c sign(v) - F_v v with v(t) = x(t) - x(t-1); width_drift
c_L(t), c_R(t) linear in t; output_offset o_0 + o_1 t / T; branch_degree one more branch term
(x + c_L)^(n+1), (x - c_R)^(n+1); linear_order one more (lag) pole; compliance y = H(q) f with H a
unit-DC-gain lightly damped resonance; quantization q round(y / q) before the noise;
hysteresis_memory f + sum_k w_k play_{r_k}(x); colored_noise AR(1)/AR(2) noise on top of the white
noise. Outside the catalogue: output_gain_drift (1 + s g(t)) y and input_gain_drift (1 + s g(t)) u
with g a slow sinusoid, which the diagnoser should call "unexplained".
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np
from numpy.typing import NDArray

from .._json import json_number
from .._numerics import find_root
from ..diagnosis import EFFECTS
from ..errors import DataError, ModelError
from ..models import CascadeModel, GeneralBacklash, LinearBlock
from ._reference import backlash as _backlash
from ._reference import bouc_wen as _bouc_wen
from ._reference import branch as _branch
from ._reference import creep as _creep
from ._reference import dahl_friction as _dahl_friction
from ._reference import difference_equation as _filter
from ._reference import linear_with_friction as _linear_with_friction
from ._reference import play as _play

__all__ = [
    "CATALOGUE",
    "OUT_OF_CATALOGUE",
    "ALL_EFFECTS",
    "Case",
    "CaseSpec",
    "make_case",
    "case_specs",
    "cases",
    "simulate_true",
]


PREROLL = 500  # samples simulated from rest and dropped
MIN_MOVING = 0.3  # share of recorded samples on which the nominal backlash must move
MAX_ATTEMPTS = 50
ENR_RTOL = 1e-9  # a size-scaled ENR further than this from the target falls back to the noise

Array = NDArray[np.float64]


# ------------------------------------------------------------------------- the true system
@dataclass(frozen=True)
class _Nominal:
    a: tuple[float, ...]
    b: tuple[float, ...]
    c_left: float
    c_right: float
    m_left: tuple[float, ...]
    m_right: tuple[float, ...]

    @classmethod
    def of(cls, model: CascadeModel) -> _Nominal:
        lin, bl = model.linear, model.backlash
        return cls(tuple(lin.a.tolist()), tuple(lin.b.tolist()), bl.c_left, bl.c_right, tuple(bl.m_left.tolist()), tuple(bl.m_right.tolist()))

    def model(self) -> CascadeModel:
        return CascadeModel(LinearBlock(self.a, self.b), GeneralBacklash(self.c_left, self.c_right, self.m_left, self.m_right))


def _lag_block(a: Sequence[float], b: Sequence[float], p: float) -> tuple[list[float], list[float]]:
    """Eq (16) followed by the unit-DC-gain lag (1 - p) / (1 - p q^-1): one more pole."""
    a_true = [(1.0 - p) * v for v in a]
    b_true = np.convolve(np.r_[1.0, np.asarray(b, dtype=float)], [1.0, -p])[1:]
    return a_true, b_true.tolist()


def _resonance(omega: float, zeta: float) -> tuple[list[float], list[float]]:
    """H(q) = K / (1 - 2 r cos(theta) q^-1 + r^2 q^-2), K = H's denominator at q = 1 (unit DC
    gain), poles r e^{+-j theta}, r = exp(-zeta omega), theta = omega sqrt(1 - zeta^2)."""
    r = np.exp(-zeta * omega)
    theta = omega * np.sqrt(1.0 - zeta * zeta)
    den = [-2.0 * r * np.cos(theta), r * r]
    return [1.0 + den[0] + den[1]], den


def simulate_true(
    nom: _Nominal | CascadeModel, effect: str, params: dict[str, Any], u: Array, t: Array, horizon: float
) -> tuple[Array, Array]:
    """The internal signal and the noise-free output of the true system: the nominal cascade
    with one effect.

    The record is simulated from rest by the per-sample NumPy reference (``_reference``),
    independently of the diagnoser's augmentations. For "colored_noise" the output is the
    nominal one (the effect is in the noise).

    Parameters
    ----------
    nom : CascadeModel
        The nominal cascade.
    effect : str
        "none" or a name from ``ALL_EFFECTS`` (a size-0 effect gives the nominal too).
    params : dict
        The effect's physical parameters (as in ``Case.effect_params``).
    u : ndarray
        Input over the full record.
    t : ndarray
        Continuous time of each sample.
    horizon : float
        T, the time scale of the drifts.

    Returns
    -------
    x : ndarray
        The linear block's output.
    y : ndarray
        The noise-free output.

    Examples
    --------
    >>> import numpy as np, backlashid as bid
    >>> from backlashid.benchmarks import simulate_true
    >>> u = np.sin(0.1 * np.arange(50))
    >>> _, y = simulate_true(bid.example1(), "none", {}, u, np.arange(50.0), 50.0)
    >>> bool(np.allclose(y, bid.example1().simulate(u)))
    True
    """
    if effect not in ALL_EFFECTS:
        raise DataError(f"unknown effect {effect!r}: choose one of {', '.join(ALL_EFFECTS)}")
    if isinstance(nom, CascadeModel):
        nom = _Nominal.of(nom)
    g = _NOMINAL if effect == "none" else _GENERATORS[effect]
    p = params
    u = np.asarray(u, dtype=np.float64)
    if g.drive is not None:  # input stage
        u = g.drive(u, p, t, horizon)
    a, b = list(nom.a), list(nom.b)  # linear block (16)
    if g.block is not None:
        a, b = g.block(a, b, p)
    x = g.linear(a, b, u, p) if g.linear is not None else _filter([0.0, *a], b, u)
    c_l, c_r, m_l, m_r = g.branches(nom, p, t, horizon) if g.branches is not None else _nominal_branches(nom)
    y = _backlash(_branch(m_l, x + c_l), _branch(m_r, x - c_r))  # backlash (1), (4)-(5)
    if g.output is not None:  # output stage
        y = g.output(y, x, p, t, horizon)
    return x, y


def _nominal_branches(nom: _Nominal) -> tuple[Any, Any, list[float], list[float]]:
    return nom.c_left, nom.c_right, list(nom.m_left), list(nom.m_right)


# ------------------------------------------------------------------------- drawing a case
@dataclass(frozen=True)
class CaseSpec:
    """What identifies a case: ``make_case(spec.effect, spec.level, spec.seed)`` rebuilds it.

    Attributes
    ----------
    effect : str
        The withheld effect, or "none".
    level : float
        The target effect-to-noise ratio (0 for "none").
    seed : int
        The seed the case is reproducible from.

    Examples
    --------
    >>> from backlashid.benchmarks import CaseSpec, make_case
    >>> spec = CaseSpec("none", 0.0, 3)
    >>> make_case(spec.effect, spec.level, spec.seed, n_est=300, n_val=300, preroll=50).effect
    'none'
    """

    effect: str
    level: float
    seed: int


@dataclass(frozen=True)
class Case:
    """One benchmark case. The user sees u_est, y_est, u_val, y_val and the nominal structure
    (na, nb, degree); the rest is the truth behind them.

    Attributes
    ----------
    effect : str
        The effect's name.
    level : float
        Target ENR (0 for "none").
    seed : int
        The seed the case is reproducible from.
    u_est : ndarray
        Estimation input.
    y_est : ndarray
        Estimation output (with the effect and the noise).
    u_val : ndarray
        Validation input (directly after the estimation record).
    y_val : ndarray
        Validation output.
    na : int
        Order of the numerator of the linear block (eq 16).
    nb : int
        Order of its denominator.
    degree : int
        Degree n of the backlash branches (eq 4-5).
    nominal : CascadeModel
        The true nominal cascade (m_L1 = 1).
    effect_params : dict
        Physical parameters of the effect (JSON-safe).
    size : float
        The scaled size knob of the effect (0 for "none").
    noise_std : float
        Standard deviation of the white noise e.
    enr : float
        Measured RMS(change) / noise_std over both records.
    enr_scaled_by : str
        "size" (noise_std = noise_ratio std(y_nominal)) or "noise" (from the change).
    y_nominal_est : ndarray
        Noise-free nominal output of the estimation record.
    y_nominal_val : ndarray
        The same of the validation record.
    change_est : ndarray
        The effect's change of the estimation output (the coloured noise for colored_noise).
    change_val : ndarray
        The same on the validation record.
    u_preroll : ndarray
        The dropped pre-roll input (the record starts from rest before it).
    moving_fraction : float
        Share of the samples on which the nominal backlash moves, over both records.
    attempts : int
        Draws until a usable case.

    Examples
    --------
    >>> from backlashid.benchmarks import make_case
    >>> c = make_case("output_offset", 2.0, 4, n_est=300, n_val=300, preroll=50)
    >>> c.structure == (c.na, c.nb, c.degree), c.in_catalogue
    (True, True)
    """

    effect: str
    level: float  # target ENR (0 for "none")
    seed: int
    u_est: Array
    y_est: Array
    u_val: Array
    y_val: Array
    na: int
    nb: int
    degree: int
    nominal: CascadeModel  # the true nominal cascade (m_L1 = 1)
    effect_params: dict[str, Any]  # physical parameters of the effect (JSON-safe)
    size: float  # the scaled size knob of the effect (0 for "none")
    noise_std: float  # of the white noise e
    enr: float  # measured RMS(change) / noise_std over both records
    enr_scaled_by: str  # "size" (noise_std = noise_ratio std(y_nominal)) or "noise" (from the change)
    y_nominal_est: Array = field(repr=False)  # noise-free nominal output
    y_nominal_val: Array = field(repr=False)
    change_est: Array = field(repr=False)  # effect's change (coloured noise for colored_noise)
    change_val: Array = field(repr=False)
    u_preroll: Array = field(repr=False)  # the dropped pre-roll input (the record starts from rest before it)
    moving_fraction: float = 0.0  # of the nominal backlash over both records
    attempts: int = 1  # draws until a usable case

    @property
    def structure(self) -> tuple[int, int, int]:
        """(na, nb, degree) the user assumes."""
        return self.na, self.nb, self.degree

    @property
    def u_full(self) -> Array:
        """The whole input from rest: pre-roll, estimation, validation."""
        return np.concatenate([self.u_preroll, self.u_est, self.u_val])

    @property
    def time(self) -> Array:
        """Continuous time t of every sample of ``u_full`` (t = 0 at the first estimation sample)."""
        return np.arange(len(self.u_preroll) + len(self.u_est) + len(self.u_val), dtype=np.float64) - len(self.u_preroll)

    @property
    def horizon(self) -> float:
        """T = n_est + n_val, the time scale of the drifts."""
        return float(len(self.u_est) + len(self.u_val))

    @property
    def in_catalogue(self) -> bool:
        """Whether the effect is one of the diagnoser's catalogue."""
        return self.effect in CATALOGUE

    @property
    def spec(self) -> CaseSpec:
        """(effect, level, seed), what rebuilds this case with :func:`make_case`."""
        return CaseSpec(self.effect, self.level, self.seed)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe description without the signals.

        Returns
        -------
        dict
            ``json.dumps`` works on it.
        """
        return {
            "effect": self.effect,
            "level": self.level,
            "seed": self.seed,
            "structure": {"na": self.na, "nb": self.nb, "degree": self.degree},
            "nominal": self.nominal.to_dict(),
            "effect_params": self.effect_params,
            "size": self.size,
            "noise_std": self.noise_std,
            "enr": self.enr,
            "enr_scaled_by": self.enr_scaled_by,
            "moving_fraction": self.moving_fraction,
            "n_est": len(self.u_est),
            "n_val": len(self.u_val),
        }


class _Redraw(Exception):
    """This draw cannot give a usable case (invalid branches, too little motion, the effect
    cannot reach the target ENR): draw again."""


def _draw_linear(rng: np.random.Generator) -> tuple[list[float], list[float]]:
    nb = int(rng.integers(1, 3))
    na = int(rng.integers(1, 3))
    if nb == 1:
        poles = [rng.uniform(-0.5, 0.9)]
    elif rng.random() < 0.5:
        r, phi = rng.uniform(0.3, 0.9), rng.uniform(0.2, 1.5)
        poles = [r * np.exp(1j * phi), r * np.exp(-1j * phi)]
    else:
        poles = list(rng.uniform(-0.5, 0.9, 2))
    b = np.real(np.poly(poles))[1:]
    a = np.array([1.0, rng.uniform(-0.5, 0.8)][:na])
    gain = rng.uniform(0.8, 1.5)
    a *= gain * (1.0 + b.sum()) / a.sum()  # static gain sum(a) / (1 + sum(b)) = gain
    return a.tolist(), b.tolist()


def _draw_input(rng: np.random.Generator, n: int) -> Array:
    """Random multi-level steps (geometric hold times) mixed with white noise, low-pass
    filtered by a first-order filter, unit std."""
    mean_hold = rng.uniform(2.0, 8.0)
    holds = rng.geometric(1.0 / mean_hold, size=n)
    levels = rng.uniform(-1.0, 1.0, size=n)
    steps = np.repeat(levels, holds)[:n]
    w = rng.uniform(0.1, 0.5)
    u = (1.0 - w) * steps + w * rng.uniform(-1.0, 1.0, size=n)
    alpha = rng.uniform(0.0, 0.5)
    u = _filter([1.0 - alpha], [-alpha], u)
    return (u - u.mean()) / u.std()


def _draw_branches(rng: np.random.Generator, degree: int, reach: float) -> tuple[list[float], list[float]]:
    def higher(m1: float) -> list[float]:
        return [m1] + [m1 * rng.uniform(-1.0, 1.0) * 0.6 / (i * reach ** (i - 1)) for i in range(2, degree + 1)]

    return higher(1.0), higher(rng.uniform(0.6, 1.6))


def _valid(backlash: GeneralBacklash, x: Array, margin: float = 0.05) -> bool:
    lo, hi = float(x.min()), float(x.max())
    pad = margin * (hi - lo)
    return backlash.check_branches(lo - pad, hi + pad).is_valid


def _rms(v: Array) -> float:
    return float(np.sqrt(np.mean(v * v)))


@dataclass
class _Context:
    rng: np.random.Generator
    nom: _Nominal
    nominal: CascadeModel  # the same as a model
    u: Array  # full record, pre-roll included
    t: Array
    horizon: float
    rec: slice  # the recorded samples
    x_nom: Array
    y_nom: Array  # noise-free nominal output, full record


# Each effect: a shape drawn once, then its physical parameters at size s (s = 0: nominal).
# _SHAPES[effect](ctx) -> (shape, s_start, s_max).
def _clip_shape(v: Array, rng: np.random.Generator, name: str) -> tuple[dict[str, Any], float, float]:
    """A clip of the signal ``v`` (named ``name`` in the shape's keys) on one or both sides: at
    size s each limit sits s of the way from the range's end towards its median, the two ends'
    spans drawn in [0.5, 1] of the way there."""
    med = float(np.median(v))
    k_hi, k_lo = rng.uniform(0.5, 1.0, 2)
    return {f"{name}_max": float(v.max()), f"{name}_min": float(v.min()), "span_hi": k_hi * (v.max() - med), "span_lo": k_lo * (med - v.min())}, 0.2, 0.95


def _clip_params(name: str) -> Callable[[dict[str, Any], float], dict[str, Any]]:
    """The limits (lo, hi) at size s of a :func:`_clip_shape` of the signal ``name``."""

    def params(sh: dict[str, Any], s: float) -> dict[str, Any]:
        return {"lo": sh[f"{name}_min"] + s * sh["span_lo"], "hi": sh[f"{name}_max"] - s * sh["span_hi"]}

    return params


def _shape_saturation(ctx: _Context) -> tuple[dict[str, Any], float, float]:
    """The actuator's saturation of the input u."""
    return _clip_shape(ctx.u, ctx.rng, "u")


def _shape_friction(ctx: _Context) -> tuple[dict[str, Any], float, float]:
    return {"u_std": float(ctx.u.std()), "viscous_ratio": float(ctx.rng.uniform(0.0, 1.0))}, 0.05, 1.0


def _params_friction(sh: dict[str, Any], s: float) -> dict[str, Any]:
    return {"F_c": s * sh["u_std"], "F_v": s * sh["viscous_ratio"]}


def _shape_width_drift(ctx: _Context) -> tuple[dict[str, Any], float, float]:
    k = ctx.rng.uniform(0.5, 1.0, 2)
    sign = 1.0 if ctx.rng.random() < 0.75 else -1.0  # wear widens, heat may narrow
    return {"kL": sign * k[0] * ctx.nom.c_left, "kR": sign * k[1] * ctx.nom.c_right}, 0.2, 0.9 if sign < 0 else 4.0


def _params_width_drift(sh: dict[str, Any], s: float) -> dict[str, Any]:
    return {"dc_L": s * sh["kL"], "dc_R": s * sh["kR"]}  # c(t) = c + dc t / T


def _shape_output_offset(ctx: _Context) -> tuple[dict[str, Any], float, float]:
    sd = float(ctx.y_nom[ctx.rec].std())
    sign = ctx.rng.choice([-1.0, 1.0], 2)
    k0, k1 = ctx.rng.uniform(0.2, 1.0), ctx.rng.uniform(0.5, 1.5)
    return {"k0": sign[0] * k0 * sd, "k1": sign[1] * k1 * sd}, 0.1, 10.0


def _params_output_offset(sh: dict[str, Any], s: float) -> dict[str, Any]:
    return {"o_0": s * sh["k0"], "o_1": s * sh["k1"]}


def _shape_branch_degree(ctx: _Context) -> tuple[dict[str, Any], float, float]:
    reach = float(np.abs(ctx.x_nom).max()) + max(ctx.nom.c_left, ctx.nom.c_right)
    n = len(ctx.nom.m_left) + 1
    sign = ctx.rng.choice([-1.0, 1.0], 2)
    k = ctx.rng.uniform(0.5, 1.0, 2)
    scale = 1.0 / (n * reach ** (n - 1))
    return {"degree": n, "kL": sign[0] * k[0] * scale, "kR": sign[1] * k[1] * scale * ctx.nom.m_right[0]}, 0.1, 1.0


def _params_branch_degree(sh: dict[str, Any], s: float) -> dict[str, Any]:
    return {"degree": sh["degree"], "m_L_extra": s * sh["kL"], "m_R_extra": s * sh["kR"]}


def _shape_linear_order(ctx: _Context) -> tuple[dict[str, Any], float, float]:
    return {}, 0.2, 0.9


def _params_linear_order(sh: dict[str, Any], s: float) -> dict[str, Any]:
    return {"p": s}


def _shape_compliance(ctx: _Context) -> tuple[dict[str, Any], float, float]:
    return {"omega": float(ctx.rng.uniform(0.3, 1.2)), "zeta": float(ctx.rng.uniform(0.02, 0.2))}, 0.1, 1.0


def _params_compliance(sh: dict[str, Any], s: float) -> dict[str, Any]:
    return {"omega": sh["omega"], "zeta": sh["zeta"], "s": s}  # H_s = 1 + s (H - 1)


def _shape_quantization(ctx: _Context) -> tuple[dict[str, Any], float, float]:
    return {"y_std": float(ctx.y_nom[ctx.rec].std())}, 0.1, 3.0


def _params_quantization(sh: dict[str, Any], s: float) -> dict[str, Any]:
    return {"q": s * sh["y_std"]}


def _shape_hysteresis_memory(ctx: _Context) -> tuple[dict[str, Any], float, float]:
    k = int(ctx.rng.integers(2, 4))
    x_std = float(ctx.x_nom[ctx.rec].std())
    radii = np.sort(ctx.rng.uniform(0.1, 1.0, k)) * x_std
    shape = ctx.rng.uniform(0.3, 1.0, k) * ctx.nom.m_right[0]
    return {"radii": radii.tolist(), "shape": shape.tolist()}, 0.1, 10.0


def _params_hysteresis_memory(sh: dict[str, Any], s: float) -> dict[str, Any]:
    return {"radii": sh["radii"], "weights": [s * w for w in sh["shape"]]}


def _shape_dynamic_friction(ctx: _Context) -> tuple[dict[str, Any], float, float]:
    """A Dahl friction force on the output: presliding travel 5-50 % of std(x), relaxation time
    20-300 samples; size s: the sliding force in std(y)."""
    x_std, y_std = float(ctx.x_nom[ctx.rec].std()), float(ctx.y_nom[ctx.rec].std())
    return {"y_std": y_std, "z_s": float(ctx.rng.uniform(0.05, 0.5)) * x_std, "tau": float(ctx.rng.uniform(20.0, 300.0))}, 0.05, 3.0


def _params_dynamic_friction(sh: dict[str, Any], s: float) -> dict[str, Any]:
    return {"F_c": s * sh["y_std"], "z_s": sh["z_s"], "tau": sh["tau"]}


def _shape_feedback_hysteresis(ctx: _Context) -> tuple[dict[str, Any], float, float]:
    """A Bouc-Wen restoring force (nu = 1, |gamma| < beta) and a hardening cubic spring in the
    drive's balance; size s: their stiffness in the loop's (1 / |static gain|)."""
    a, b = np.array(ctx.nom.a), np.array(ctx.nom.b)
    gain = abs(float(a.sum() / (1.0 + b.sum())))
    x = ctx.x_nom[ctx.rec]
    x_std, v_max = float(x.std()), float(np.max(np.abs(np.diff(x)))) + 1e-12
    beta = float(ctx.rng.uniform(0.2, 0.8)) / v_max
    shape = {
        "k": 1.0 / max(gain, 1e-6), "beta": beta, "gamma": float(ctx.rng.uniform(-0.5, 0.5)) * beta,
        "cubic": float(ctx.rng.uniform(0.0, 0.5)) / x_std**2,
    }  # fmt: skip
    return shape, 0.05, 1.0


def _params_feedback_hysteresis(sh: dict[str, Any], s: float) -> dict[str, Any]:
    return {"alpha": s * sh["k"], "beta": sh["beta"], "gamma": sh["gamma"], "k_3": s * sh["k"] * sh["cubic"]}


def _shape_creep(ctx: _Context) -> tuple[dict[str, Any], float, float]:
    """Two creep modes, 20-200 and 300-3000 samples, the slow one's share 30-100 % of the fast
    one's; size s: the fast mode's share."""
    ratio = float(ctx.rng.uniform(0.3, 1.0))
    taus = [float(ctx.rng.uniform(20.0, 200.0)), float(ctx.rng.uniform(300.0, 3000.0))]
    return {"ratio": ratio, "taus": taus}, 0.02, 0.9 / (1.0 + ratio)


def _params_creep(sh: dict[str, Any], s: float) -> dict[str, Any]:
    return {"shares": [s, s * sh["ratio"]], "taus": sh["taus"]}


def _shape_gain_drift(ctx: _Context) -> tuple[dict[str, Any], float, float]:
    return {"cycles": float(ctx.rng.uniform(0.4, 1.2)), "phase": float(ctx.rng.uniform(0.0, 2.0 * np.pi))}, 0.05, 0.8


def _params_gain_drift(sh: dict[str, Any], s: float) -> dict[str, Any]:
    return {"cycles": sh["cycles"], "phase": sh["phase"], "s": s}


# Stages of the true system, per effect: the input, the linear block, the backlash, the output.
def _dead_time_drive(u: Array, p: dict[str, Any], t: Array, horizon: float) -> Array:
    d = int(p["d"])
    return np.r_[np.zeros(d), u[: len(u) - d]]


def _saturation_drive(u: Array, p: dict[str, Any], t: Array, horizon: float) -> Array:
    return np.clip(u, p["lo"], p["hi"])


def _gain(p: dict[str, Any], t: Array, horizon: float) -> Array:
    """1 + s sin(2 pi cycles t / T + phase): a slowly drifting gain."""
    return 1.0 + p["s"] * np.sin(2.0 * np.pi * p["cycles"] * t / horizon + p["phase"])


def _input_gain_drive(u: Array, p: dict[str, Any], t: Array, horizon: float) -> Array:
    return _gain(p, t, horizon) * u


def _lag_order_block(a: list[float], b: list[float], p: dict[str, Any]) -> tuple[list[float], list[float]]:
    return _lag_block(a, b, p["p"])


def _shape_state_saturation(ctx: _Context) -> tuple[dict[str, Any], float, float]:
    """A travel stop of x on one or both sides (as the actuator's saturation)."""
    return _clip_shape(ctx.x_nom[ctx.rec], ctx.rng, "x")


def _shape_sensor_saturation(ctx: _Context) -> tuple[dict[str, Any], float, float]:
    """A sensor range narrower than the output's (as the actuator's saturation)."""
    return _clip_shape(ctx.y_nom[ctx.rec], ctx.rng, "y")


def _state_saturation_linear(a: list[float], b: list[float], u: Array, p: dict[str, Any]) -> Array:
    return _linear_with_friction(a, b, u, 0.0, 0.0, stop=(p["lo"], p["hi"]))


def _sensor_saturation_output(y: Array, x: Array, p: dict[str, Any], t: Array, horizon: float) -> Array:
    return np.clip(y, p["lo"], p["hi"])


def _friction_linear(a: list[float], b: list[float], u: Array, p: dict[str, Any]) -> Array:
    return _linear_with_friction(a, b, u, p["F_c"], p["F_v"])


def _feedback_hysteresis_linear(a: list[float], b: list[float], u: Array, p: dict[str, Any]) -> Array:
    return _linear_with_friction(a, b, u, 0.0, 0.0, restoring=_bouc_wen(p["alpha"], p["beta"], p["gamma"], p["k_3"]))


def _width_drift_branches(nom: _Nominal, p: dict[str, Any], t: Array, horizon: float) -> tuple[Any, Any, list[float], list[float]]:
    c_l = nom.c_left + p["dc_L"] * t / horizon
    c_r = nom.c_right + p["dc_R"] * t / horizon
    return c_l, c_r, list(nom.m_left), list(nom.m_right)


def _branch_degree_branches(nom: _Nominal, p: dict[str, Any], t: Array, horizon: float) -> tuple[Any, Any, list[float], list[float]]:
    n = int(p["degree"])
    m_l = list(nom.m_left) + [0.0] * (n - 1 - len(nom.m_left)) + [p["m_L_extra"]]
    m_r = list(nom.m_right) + [0.0] * (n - 1 - len(nom.m_right)) + [p["m_R_extra"]]
    return nom.c_left, nom.c_right, m_l, m_r


def _hysteresis_output(y: Array, x: Array, p: dict[str, Any], t: Array, horizon: float) -> Array:
    return y + sum(w * _play(x, r) for w, r in zip(p["weights"], p["radii"]))


def _compliance_output(y: Array, x: Array, p: dict[str, Any], t: Array, horizon: float) -> Array:
    num, den = _resonance(p["omega"], p["zeta"])
    return y + p["s"] * (_filter(num, den, y) - y)


def _dynamic_friction_output(y: Array, x: Array, p: dict[str, Any], t: Array, horizon: float) -> Array:
    return _dahl_friction(y, x, p["F_c"], p["z_s"], 1.0 / p["tau"]) if p["F_c"] != 0.0 else y


def _creep_output(y: Array, x: Array, p: dict[str, Any], t: Array, horizon: float) -> Array:
    return _creep(y, [(g, float(np.log(tau))) for g, tau in zip(p["shares"], p["taus"]) if g != 0.0])


def _offset_output(y: Array, x: Array, p: dict[str, Any], t: Array, horizon: float) -> Array:
    return y + p["o_0"] + p["o_1"] * t / horizon


def _output_gain_output(y: Array, x: Array, p: dict[str, Any], t: Array, horizon: float) -> Array:
    return _gain(p, t, horizon) * y


def _quantization_output(y: Array, x: Array, p: dict[str, Any], t: Array, horizon: float) -> Array:
    return p["q"] * np.round(y / p["q"]) if p["q"] > 0.0 else y  # q = 0: no quantiser


def _width_drift_backlashes(nom: _Nominal, p: dict[str, Any], t: Array, horizon: float) -> list[GeneralBacklash]:
    """Both ends of the drift."""
    ends = [(nom.c_left + p["dc_L"] * tt / horizon, nom.c_right + p["dc_R"] * tt / horizon) for tt in (t[0], t[-1])]
    if min(min(e) for e in ends) < 0.0:
        raise _Redraw("a width drifts below zero")
    return [GeneralBacklash(cl, cr, nom.m_left, nom.m_right) for cl, cr in ends]


# What a draw gives: the effect's parameters, its size, the change of the output (full record),
# the noise std and how the ENR was met ("size" or "noise").
_Drawn = tuple[dict[str, Any], float, Array, float, str]


def _draw_nothing(g: _Generator, ctx: _Context, effect: str, level: float, sigma: float) -> _Drawn:
    return {}, 0.0, np.zeros(ctx.u.size), sigma, "size"


def _draw_colored_noise(g: _Generator, ctx: _Context, effect: str, level: float, sigma: float) -> _Drawn:
    """AR(1) or lightly resonant AR(2) filtered white noise, scaled exactly."""
    rng = ctx.rng
    if rng.random() < 0.5:
        den = [-float(rng.uniform(0.7, 0.95))]
    else:
        r, phi = rng.uniform(0.8, 0.95), rng.uniform(0.2, 1.2)
        den = [-2.0 * r * np.cos(phi), r * r]
    raw = _filter([1.0], den, rng.standard_normal(ctx.u.size))
    size = level * sigma / _rms(raw[ctx.rec])
    return {"ar": [float(v) for v in den], "scale": size}, size, size * raw, sigma, "size"


def _draw_dead_time(g: _Generator, ctx: _Context, effect: str, level: float, sigma: float) -> _Drawn:
    """d is discrete: the noise std is set from the change."""
    d = int(ctx.rng.integers(1, 3))
    params = {"d": d}
    x_true, y_true = simulate_true(ctx.nom, effect, params, ctx.u, ctx.t, ctx.horizon)
    change = y_true - ctx.y_nom
    sigma = _rms(change[ctx.rec]) / level
    if not _valid(ctx.nominal.backlash, x_true):
        raise _Redraw("branches invalid on the true x range")
    return params, float(d), change, sigma, "noise"


def _draw_scaled(g: _Generator, ctx: _Context, effect: str, level: float, sigma: float) -> _Drawn:
    """A shape drawn once, then the size scaled (bracketing root search) to the target ENR."""
    if g.shape is None or g.params is None:
        raise TypeError(f"{effect}: a generator scaled by size needs a shape and its parameters")
    nom, u, t, horizon, rec, y_nom = ctx.nom, ctx.u, ctx.t, ctx.horizon, ctx.rec, ctx.y_nom
    params_of = g.params
    shape, s0, s_max = g.shape(ctx)
    target = level * sigma
    cache: dict[float, tuple[Array, Array]] = {}

    def rms_change(s: float) -> float:
        if s not in cache:
            with np.errstate(over="ignore", invalid="ignore"):
                cache[s] = simulate_true(nom, effect, params_of(shape, s), u, t, horizon)
        value = _rms(cache[s][1][rec] - y_nom[rec])
        return value if np.isfinite(value) else np.inf

    lo, hi = 0.0, min(s0, s_max)
    while rms_change(hi) < target:
        if hi >= s_max or not np.isfinite(rms_change(hi)):
            raise _Redraw(f"{effect} cannot reach ENR {level} within its size range")
        lo, hi = hi, min(2.0 * hi, s_max)
    if not np.isfinite(rms_change(hi)):
        raise _Redraw(f"{effect} of size {hi:.3g} makes the system unstable")
    size = find_root(lambda s: rms_change(s) - target, lo, hi, xtol=1e-15 * hi, rtol=1e-14, max_iter=200)
    params = params_of(shape, size)
    x_true, y_true = simulate_true(nom, effect, params, u, t, horizon)
    change = y_true - y_nom
    for bl in g.true_backlashes(nom, params, t, horizon):
        if not _valid(bl, x_true):
            raise _Redraw("true branches invalid on the true x range")
    by = "size"
    achieved = _rms(change[rec])
    if abs(achieved - target) > ENR_RTOL * target:  # a jump in the change (quantiser, Coulomb sign)
        sigma, by = achieved / level, "noise"
    return params, size, change, sigma, by


@dataclass(frozen=True)
class _Generator:
    """How one effect's true system is drawn and simulated: its stages (None: nominal) and,
    for an effect scaled by size, its shape (drawn once: shape, s_start, s_max) and its
    physical parameters at size s (s = 0: nominal)."""

    shape: Callable[[_Context], tuple[dict[str, Any], float, float]] | None = None
    params: Callable[[dict[str, Any], float], dict[str, Any]] | None = None
    draw: Callable[[_Generator, _Context, str, float, float], _Drawn] = _draw_scaled
    drive: Callable[[Array, dict[str, Any], Array, float], Array] | None = None
    block: Callable[[list[float], list[float], dict[str, Any]], tuple[list[float], list[float]]] | None = None
    linear: Callable[[list[float], list[float], Array, dict[str, Any]], Array] | None = None
    branches: Callable[[_Nominal, dict[str, Any], Array, float], tuple[Any, Any, list[float], list[float]]] | None = None
    output: Callable[[Array, Array, dict[str, Any], Array, float], Array] | None = None
    backlashes: Callable[[_Nominal, dict[str, Any], Array, float], list[GeneralBacklash]] | None = None

    def true_backlashes(self, nom: _Nominal, params: dict[str, Any], t: Array, horizon: float) -> list[GeneralBacklash]:
        """The backlash(es) the true system passes through (both ends of a width drift)."""
        if self.backlashes is not None:
            return self.backlashes(nom, params, t, horizon)
        c_l, c_r, m_l, m_r = self.branches(nom, params, t, horizon) if self.branches is not None else _nominal_branches(nom)
        return [GeneralBacklash(c_l, c_r, m_l, m_r)]


_NOMINAL = _Generator(draw=_draw_nothing)

# The benchmark's truth, one generator per effect (the catalogue's and two outside it).
_GENERATORS: dict[str, _Generator] = {
    "dead_time": _Generator(draw=_draw_dead_time, drive=_dead_time_drive),
    "saturation": _Generator(_shape_saturation, _clip_params("u"), drive=_saturation_drive),
    "friction": _Generator(_shape_friction, _params_friction, linear=_friction_linear),
    "width_drift": _Generator(
        _shape_width_drift, _params_width_drift, branches=_width_drift_branches, backlashes=_width_drift_backlashes
    ),
    "output_offset": _Generator(_shape_output_offset, _params_output_offset, output=_offset_output),
    "branch_degree": _Generator(_shape_branch_degree, _params_branch_degree, branches=_branch_degree_branches),
    "linear_order": _Generator(_shape_linear_order, _params_linear_order, block=_lag_order_block),
    "compliance": _Generator(_shape_compliance, _params_compliance, output=_compliance_output),
    "quantization": _Generator(_shape_quantization, _params_quantization, output=_quantization_output),
    "hysteresis_memory": _Generator(_shape_hysteresis_memory, _params_hysteresis_memory, output=_hysteresis_output),
    "colored_noise": _Generator(draw=_draw_colored_noise),
    "dynamic_friction": _Generator(_shape_dynamic_friction, _params_dynamic_friction, output=_dynamic_friction_output),
    "feedback_hysteresis": _Generator(_shape_feedback_hysteresis, _params_feedback_hysteresis, linear=_feedback_hysteresis_linear),
    "creep": _Generator(_shape_creep, _params_creep, output=_creep_output),
    "state_saturation": _Generator(_shape_state_saturation, _clip_params("x"), linear=_state_saturation_linear),
    "sensor_saturation": _Generator(_shape_sensor_saturation, _clip_params("y"), output=_sensor_saturation_output),
    "output_gain_drift": _Generator(_shape_gain_drift, _params_gain_drift, output=_output_gain_output),
    "input_gain_drift": _Generator(_shape_gain_drift, _params_gain_drift, drive=_input_gain_drive),
}

# The diagnoser's effects that this module can generate, in the catalogue's order (an effect
# added to the catalogue joins the benchmark once it has a generator here); how each is
# generated is this module's own truth, independent of the diagnoser's parametrisation.
CATALOGUE: tuple[str, ...] = tuple(e for e in EFFECTS if e in _GENERATORS)
OUT_OF_CATALOGUE = ("output_gain_drift", "input_gain_drift")
ALL_EFFECTS = ("none",) + CATALOGUE + OUT_OF_CATALOGUE


def _draw(effect: str, level: float, rng: np.random.Generator, n_est: int, n_val: int, noise_ratio: float, preroll: int) -> dict[str, Any]:
    n_rec = n_est + n_val
    m = preroll + n_rec
    t = np.arange(m, dtype=np.float64) - preroll
    horizon = float(n_rec)
    rec = slice(preroll, m)
    # nominal cascade and input
    a, b = _draw_linear(rng)
    u = _draw_input(rng, m) * rng.uniform(0.8, 1.5)
    x_nom = _filter([0.0, *a], b, u)
    x_sd = float(x_nom[rec].std())
    c_l, c_r = rng.uniform(0.15, 0.6, 2) * x_sd
    degree = int(rng.integers(1, 4))
    reach = float(np.abs(x_nom).max()) + max(c_l, c_r)
    m_l, m_r = _draw_branches(rng, degree, reach)
    nom = _Nominal(tuple(a), tuple(b), float(c_l), float(c_r), tuple(m_l), tuple(m_r))
    try:
        nominal = nom.model()
    except ModelError as exc:
        raise _Redraw(str(exc)) from None
    if not _valid(nominal.backlash, x_nom):
        raise _Redraw("nominal branches invalid on the x range")
    _, y_nom = simulate_true(nom, "none", {}, u, t, horizon)
    moving = float(np.mean(np.diff(y_nom[preroll - 1 :]) != 0.0))
    if moving < MIN_MOVING:
        raise _Redraw(f"the backlash moves on {moving:.2f} of the samples only")
    sigma = noise_ratio * float(y_nom[rec].std())
    ctx = _Context(rng, nom, nominal, u, t, horizon, rec, x_nom, y_nom)
    g = _NOMINAL if effect == "none" else _GENERATORS[effect]
    params, size, change, sigma, by = g.draw(g, ctx, effect, level, sigma)
    e = sigma * rng.standard_normal(m)
    y = y_nom + change + e
    enr = _rms(change[rec]) / sigma if effect != "none" else 0.0
    return {
        "u": u, "y": y, "y_nom": y_nom, "change": change, "nom": nom, "params": params, "size": size,
        "sigma": sigma, "enr": enr, "by": by, "moving": moving,
    }  # fmt: skip


def make_case(
    effect: str,
    level: float,
    seed: int,
    *,
    n_est: int = 4000,
    n_val: int = 4000,
    noise_ratio: float = 0.03,
    preroll: int = PREROLL,
) -> Case:
    """One benchmark case: a random nominal cascade with one effect withheld.

    Draws that give no usable case (invalid branches, too little motion, an effect that
    cannot reach the ENR) are redrawn from seeds derived from ``seed``.

    Parameters
    ----------
    effect : str
        "none" or a name from ``ALL_EFFECTS``.
    level : float
        Target effect-to-noise ratio (ignored for "none").
    seed : int
        The case is reproducible from it.
    n_est : int, default 4000
        Samples of the estimation record.
    n_val : int, default 4000
        Samples of the validation record.
    noise_ratio : float, default 0.03
        Noise std relative to std(y_nominal) when the size is scaled.
    preroll : int, default 500
        Samples simulated from rest and dropped before the estimation record.

    Returns
    -------
    Case
        The records the user sees and the truth behind them.

    Raises
    ------
    DataError
        If the effect is unknown, a number is out of range, or no usable case is found in
        ``MAX_ATTEMPTS`` draws.

    Examples
    --------
    >>> from backlashid.benchmarks import make_case
    >>> c = make_case("saturation", 3.0, 1, n_est=300, n_val=300, preroll=50)
    >>> round(c.enr, 6), c.u_est.size
    (3.0, 300)
    """
    if effect not in ALL_EFFECTS:
        raise DataError(f"unknown effect {effect!r}: choose one of {', '.join(ALL_EFFECTS)}")
    if effect != "none" and not level > 0:
        raise DataError(f"level = {level}: give a positive effect-to-noise ratio")
    if n_est < 1 or n_val < 1 or preroll < 1:
        raise DataError(f"n_est = {n_est}, n_val = {n_val}, preroll = {preroll}: give positive lengths")
    if not noise_ratio > 0:
        raise DataError(f"noise_ratio = {noise_ratio}: give a positive noise std relative to std(y)")
    level = 0.0 if effect == "none" else float(level)
    reasons = []
    for attempt in range(MAX_ATTEMPTS):
        rng = np.random.default_rng(np.random.SeedSequence([int(seed), attempt]))
        try:
            d = _draw(effect, level, rng, n_est, n_val, noise_ratio, preroll)
        except _Redraw as exc:
            reasons.append(str(exc))
            continue
        est, val = slice(preroll, preroll + n_est), slice(preroll + n_est, None)
        nom: _Nominal = d["nom"]
        return Case(
            effect=effect, level=level, seed=int(seed),
            u_est=d["u"][est], y_est=d["y"][est], u_val=d["u"][val], y_val=d["y"][val],
            na=len(nom.a), nb=len(nom.b), degree=len(nom.m_left), nominal=nom.model(),
            effect_params=json_number(d["params"]), size=d["size"], noise_std=float(d["sigma"]),
            enr=float(d["enr"]), enr_scaled_by=d["by"],
            y_nominal_est=d["y_nom"][est], y_nominal_val=d["y_nom"][val],
            change_est=d["change"][est], change_val=d["change"][val], u_preroll=d["u"][:preroll],
            moving_fraction=d["moving"], attempts=attempt + 1,
        )  # fmt: skip
    raise DataError(f"no usable {effect} case from seed {seed} in {MAX_ATTEMPTS} draws (last: {reasons[-1]})")


def case_specs(
    levels: Sequence[float] = (3.0, 1.0),
    per_effect: int = 5,
    seed: int = 0,
    effects: Sequence[str] | None = None,
) -> list[CaseSpec]:
    """The benchmark's cases: which effect, level and seed each has.

    ``per_effect`` cases per effect and level (catalogue and out of catalogue), and
    ``per_effect * len(levels)`` "none" cases. A case's seed depends only on (seed, effect,
    level, index), so a subset of effects or levels gives the same cases.

    Parameters
    ----------
    levels : sequence of float, default (3.0, 1.0)
        The effect-to-noise ratios.
    per_effect : int, default 5
        Cases per effect and level.
    seed : int, default 0
        Seed of the whole set.
    effects : sequence of str, optional
        The effects (default: ``ALL_EFFECTS``).

    Returns
    -------
    list of CaseSpec
        ``make_case(spec.effect, spec.level, spec.seed)`` builds each.

    Raises
    ------
    DataError
        If an effect is unknown or ``per_effect`` < 1.

    Examples
    --------
    >>> from backlashid.benchmarks import case_specs
    >>> [s.effect for s in case_specs(levels=(1.0,), per_effect=1, effects=["none", "friction"])]
    ['none', 'friction']
    """
    chosen = ALL_EFFECTS if effects is None else tuple(effects)
    for e in chosen:
        if e not in ALL_EFFECTS:
            raise DataError(f"unknown effect {e!r}: choose from {', '.join(ALL_EFFECTS)}")
    if per_effect < 1:
        raise DataError(f"per_effect = {per_effect}: ask for at least one case per effect")

    def case_seed(effect: str, level_code: int, k: int) -> int:
        return int(np.random.SeedSequence([int(seed), ALL_EFFECTS.index(effect), level_code, k]).generate_state(1)[0])

    specs = []
    if "none" in chosen:
        specs += [CaseSpec("none", 0.0, case_seed("none", 0, k)) for k in range(per_effect * len(levels))]
    for level in levels:
        code = int(round(float(level) * 1000))
        for effect in chosen:
            if effect != "none":
                specs += [CaseSpec(effect, float(level), case_seed(effect, code, k)) for k in range(per_effect)]
    return specs


def cases(
    levels: Sequence[float] = (3.0, 1.0),
    per_effect: int = 5,
    seed: int = 0,
    effects: Sequence[str] | None = None,
    **kwargs: Any,
) -> Iterator[Case]:
    """The cases of :func:`case_specs`, built one at a time.

    Parameters
    ----------
    levels : sequence of float, default (3.0, 1.0)
        Effect-to-noise ratios, as for :func:`case_specs`.
    per_effect : int, default 5
        How many cases of each effect at each level.
    seed : int, default 0
        The seed all the cases derive from.
    effects : sequence of str, optional
        Which effects (default: all of ``ALL_EFFECTS``).
    **kwargs
        Passed to :func:`make_case` (record lengths, noise ratio, pre-roll).

    Yields
    ------
    Case
        One case after the other.

    Examples
    --------
    >>> from backlashid.benchmarks import cases
    >>> c = next(cases(levels=(2.0,), per_effect=1, effects=["dead_time"], n_est=300, n_val=300, preroll=50))
    >>> c.effect, c.enr_scaled_by
    ('dead_time', 'noise')
    """
    for spec in case_specs(levels, per_effect, seed, effects):
        yield make_case(spec.effect, spec.level, spec.seed, **kwargs)
