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
from scipy.optimize import brentq

from ..errors import DataError, ModelError
from ..models import CascadeModel, GeneralBacklash, LinearBlock

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

# The contract's catalogue, spelled out here so that the benchmark does not import the diagnoser.
CATALOGUE = (
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
OUT_OF_CATALOGUE = ("output_gain_drift", "input_gain_drift")
ALL_EFFECTS = ("none",) + CATALOGUE + OUT_OF_CATALOGUE

PREROLL = 500  # samples simulated from rest and dropped
MIN_MOVING = 0.3  # share of recorded samples on which the nominal backlash must move
MAX_ATTEMPTS = 50
ENR_RTOL = 1e-9  # a size-scaled ENR further than this from the target falls back to the noise

Array = NDArray[np.float64]


# ------------------------------------------------------------------------- plain simulators
def _filter(num: Sequence[float], den: Sequence[float], u: Array) -> Array:
    """y(t) = sum_{k>=0} num[k] u(t-k) - sum_{j>=1} den[j-1] y(t-j), from rest (eq 16 with
    num = [0, a_1, .., a_na], den = b)."""
    num, den = [float(v) for v in num], [float(v) for v in den]
    uu = [0.0] * len(num) + u.tolist()
    yy = [0.0] * len(den)
    ku, kd = len(num), len(den)
    for t in range(len(u)):
        acc = 0.0
        for k, c in enumerate(num):
            acc += c * uu[ku + t - k]
        for j, c in enumerate(den, 1):
            acc -= c * yy[kd + t - j]
        yy.append(acc)
    return np.array(yy[kd:], dtype=np.float64)


def _linear_with_friction(a: Sequence[float], b: Sequence[float], u: Array, f_c: float, f_v: float) -> Array:
    """Eq (16) driven by u_eff(t) = u(t) - F_c sign(v(t)) - F_v v(t), v(t) = x(t) - x(t-1)
    (sign(0) = 0): x(t) needs u_eff up to t - 1 only, so u_eff(t) follows x(t)."""
    a, b = [float(v) for v in a], [float(v) for v in b]
    na, nb = len(a), len(b)
    ue = [0.0] * na  # u_eff(t-na) .. u_eff(t-1), oldest first
    xx = [0.0] * max(nb, 1)
    out = np.empty(len(u))
    for t, ut in enumerate(u.tolist()):
        x = 0.0
        for i in range(1, na + 1):
            x += a[i - 1] * ue[-i]
        for j in range(1, nb + 1):
            x -= b[j - 1] * xx[-j]
        v = x - xx[-1]
        sign = 1.0 if v > 0.0 else (-1.0 if v < 0.0 else 0.0)
        ue.append(ut - f_c * sign - f_v * v)
        xx.append(x)
        out[t] = x
    return out


def _branch(m: Sequence[float], xi: Array) -> Array:
    """sum_{i=1}^n m_i xi^i (eq 4-5) by Horner's rule."""
    acc = np.zeros_like(xi)
    for c in reversed([float(v) for v in m]):
        acc = (acc + c) * xi
    return acc


def _backlash(left: Array, right: Array, y0: float = 0.0) -> Array:
    """Eq (1) with the exclusive case order: L if L(x) <= y(t-1), else R if R(x) >= y(t-1),
    else hold. ``left``, ``right`` are the branch values L(x(t)), R(x(t)) per sample."""
    y_prev, out = float(y0), np.empty(len(left))
    for t, (lv, rv) in enumerate(zip(left.tolist(), right.tolist())):
        if lv <= y_prev:
            y_prev = lv
        elif rv >= y_prev:
            y_prev = rv
        out[t] = y_prev
    return out


def _play(x: Array, r: float) -> Array:
    """Play operator of radius r: p(t) = max(x(t) - r, min(x(t) + r, p(t-1))), p = 0 at rest."""
    p, out = 0.0, np.empty(len(x))
    for t, xt in enumerate(x.tolist()):
        p = max(xt - r, min(xt + r, p))
        out[t] = p
    return out


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
    """(x, y): the internal signal and the noise-free output of the nominal cascade with one
    effect (``effect="none"`` or a size-0 effect give the nominal), over the full record from
    rest; ``t`` is the continuous time of each sample, ``horizon`` = T. For "colored_noise" the
    output is the nominal one (the effect is in the noise)."""
    if isinstance(nom, CascadeModel):
        nom = _Nominal.of(nom)
    u = np.asarray(u, dtype=np.float64)
    p = params
    # input stage
    if effect == "dead_time":
        d = int(p["d"])
        u = np.r_[np.zeros(d), u[: len(u) - d]]
    elif effect == "saturation":
        u = np.clip(u, p["lo"], p["hi"])
    elif effect == "input_gain_drift":
        u = (1.0 + p["s"] * np.sin(2.0 * np.pi * p["cycles"] * t / horizon + p["phase"])) * u
    # linear block (16)
    a, b = list(nom.a), list(nom.b)
    if effect == "linear_order":
        a, b = _lag_block(a, b, p["p"])
    if effect == "friction":
        x = _linear_with_friction(a, b, u, p["F_c"], p["F_v"])
    else:
        x = _filter([0.0, *a], b, u)
    # backlash (1), (4)-(5)
    c_l: Any = nom.c_left
    c_r: Any = nom.c_right
    m_l, m_r = list(nom.m_left), list(nom.m_right)
    if effect == "width_drift":
        c_l = nom.c_left + p["dc_L"] * t / horizon
        c_r = nom.c_right + p["dc_R"] * t / horizon
    elif effect == "branch_degree":
        n = int(p["degree"])
        m_l = m_l + [0.0] * (n - 1 - len(m_l)) + [p["m_L_extra"]]
        m_r = m_r + [0.0] * (n - 1 - len(m_r)) + [p["m_R_extra"]]
    y = _backlash(_branch(m_l, x + c_l), _branch(m_r, x - c_r))
    # output stage
    if effect == "hysteresis_memory":
        y = y + sum(w * _play(x, r) for w, r in zip(p["weights"], p["radii"]))
    elif effect == "compliance":
        num, den = _resonance(p["omega"], p["zeta"])
        y = y + p["s"] * (_filter(num, den, y) - y)
    elif effect == "output_offset":
        y = y + p["o_0"] + p["o_1"] * t / horizon
    elif effect == "output_gain_drift":
        y = (1.0 + p["s"] * np.sin(2.0 * np.pi * p["cycles"] * t / horizon + p["phase"])) * y
    elif effect == "quantization" and p["q"] > 0.0:  # q = 0: no quantiser
        y = p["q"] * np.round(y / p["q"])
    return x, y


# ------------------------------------------------------------------------- drawing a case
@dataclass(frozen=True)
class CaseSpec:
    """What identifies a case: ``make_case(*spec)`` rebuilds it."""

    effect: str
    level: float
    seed: int


@dataclass(frozen=True)
class Case:
    """One benchmark case. The user sees u_est, y_est, u_val, y_val and the nominal structure
    (na, nb, degree); the rest is the truth behind them."""

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
        return self.effect in CATALOGUE

    @property
    def spec(self) -> CaseSpec:
        return CaseSpec(self.effect, self.level, self.seed)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe description without the signals."""
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
    u: Array  # full record, pre-roll included
    t: Array
    horizon: float
    rec: slice  # the recorded samples
    x_nom: Array
    y_nom: Array  # noise-free nominal output, full record


# Each effect: a shape drawn once, then its physical parameters at size s (s = 0: nominal).
# _SHAPES[effect](ctx) -> (shape, s_start, s_max).
def _shape_saturation(ctx: _Context) -> tuple[dict[str, Any], float, float]:
    u = ctx.u
    med = float(np.median(u))
    k_hi, k_lo = ctx.rng.uniform(0.5, 1.0, 2)
    return {"u_max": float(u.max()), "u_min": float(u.min()), "span_hi": k_hi * (u.max() - med), "span_lo": k_lo * (med - u.min())}, 0.2, 0.95


def _params_saturation(sh: dict[str, Any], s: float) -> dict[str, Any]:
    return {"lo": sh["u_min"] + s * sh["span_lo"], "hi": sh["u_max"] - s * sh["span_hi"]}


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


def _shape_gain_drift(ctx: _Context) -> tuple[dict[str, Any], float, float]:
    return {"cycles": float(ctx.rng.uniform(0.4, 1.2)), "phase": float(ctx.rng.uniform(0.0, 2.0 * np.pi))}, 0.05, 0.8


def _params_gain_drift(sh: dict[str, Any], s: float) -> dict[str, Any]:
    return {"cycles": sh["cycles"], "phase": sh["phase"], "s": s}


_SCALED: dict[str, tuple[Callable[[_Context], tuple[dict[str, Any], float, float]], Callable[[dict[str, Any], float], dict[str, Any]]]] = {
    "saturation": (_shape_saturation, _params_saturation),
    "friction": (_shape_friction, _params_friction),
    "width_drift": (_shape_width_drift, _params_width_drift),
    "output_offset": (_shape_output_offset, _params_output_offset),
    "branch_degree": (_shape_branch_degree, _params_branch_degree),
    "linear_order": (_shape_linear_order, _params_linear_order),
    "compliance": (_shape_compliance, _params_compliance),
    "quantization": (_shape_quantization, _params_quantization),
    "hysteresis_memory": (_shape_hysteresis_memory, _params_hysteresis_memory),
    "output_gain_drift": (_shape_gain_drift, _params_gain_drift),
    "input_gain_drift": (_shape_gain_drift, _params_gain_drift),
}


def _true_backlashes(nom: _Nominal, effect: str, params: dict[str, Any], horizon: float, t: Array) -> list[GeneralBacklash]:
    """The backlash(es) the true system passes through (both ends of a width drift)."""
    if effect == "width_drift":
        ends = [(nom.c_left + params["dc_L"] * tt / horizon, nom.c_right + params["dc_R"] * tt / horizon) for tt in (t[0], t[-1])]
        if min(min(e) for e in ends) < 0.0:
            raise _Redraw("a width drifts below zero")
        return [GeneralBacklash(cl, cr, nom.m_left, nom.m_right) for cl, cr in ends]
    if effect == "branch_degree":
        n = int(params["degree"])
        m_l = list(nom.m_left) + [0.0] * (n - 1 - len(nom.m_left)) + [params["m_L_extra"]]
        m_r = list(nom.m_right) + [0.0] * (n - 1 - len(nom.m_right)) + [params["m_R_extra"]]
        return [GeneralBacklash(nom.c_left, nom.c_right, m_l, m_r)]
    return [GeneralBacklash(nom.c_left, nom.c_right, nom.m_left, nom.m_right)]


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
    ctx = _Context(rng, nom, u, t, horizon, rec, x_nom, y_nom)

    params: dict[str, Any] = {}
    size, by = 0.0, "size"
    change = np.zeros(m)
    if effect == "none":
        pass
    elif effect == "colored_noise":
        # coloured part: AR(1) or lightly resonant AR(2) filtered white noise, scaled exactly
        if rng.random() < 0.5:
            den = [-float(rng.uniform(0.7, 0.95))]
        else:
            r, phi = rng.uniform(0.8, 0.95), rng.uniform(0.2, 1.2)
            den = [-2.0 * r * np.cos(phi), r * r]
        raw = _filter([1.0], den, rng.standard_normal(m))
        size = level * sigma / _rms(raw[rec])
        change = size * raw
        params = {"ar": [float(v) for v in den], "scale": size}
    elif effect == "dead_time":
        d = int(rng.integers(1, 3))
        params = {"d": d}
        x_true, y_true = simulate_true(nom, effect, params, u, t, horizon)
        change = y_true - y_nom
        size, by = float(d), "noise"
        sigma = _rms(change[rec]) / level
        if not _valid(nominal.backlash, x_true):
            raise _Redraw("branches invalid on the true x range")
    else:
        shape_of, params_of = _SCALED[effect]
        shape, s0, s_max = shape_of(ctx)
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
        size = float(brentq(lambda s: rms_change(s) - target, lo, hi, xtol=1e-15 * hi, rtol=1e-14, maxiter=200))
        params = params_of(shape, size)
        x_true, y_true = simulate_true(nom, effect, params, u, t, horizon)
        change = y_true - y_nom
        for bl in _true_backlashes(nom, effect, params, horizon, t):
            if not _valid(bl, x_true):
                raise _Redraw("true branches invalid on the true x range")
        achieved = _rms(change[rec])
        if abs(achieved - target) > ENR_RTOL * target:  # a jump in the change (quantiser, Coulomb sign)
            sigma, by = achieved / level, "noise"
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
    """One case: a random nominal cascade with ``effect`` withheld at ENR ``level`` (ignored for
    "none"), reproducible from ``seed``. Draws that give no usable case (invalid branches, too
    little motion, an effect that cannot reach the ENR) are redrawn from seeds derived from
    ``seed``."""
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
            effect_params=_json_safe(d["params"]), size=d["size"], noise_std=float(d["sigma"]),
            enr=float(d["enr"]), enr_scaled_by=d["by"],
            y_nominal_est=d["y_nom"][est], y_nominal_val=d["y_nom"][val],
            change_est=d["change"][est], change_val=d["change"][val], u_preroll=d["u"][:preroll],
            moving_fraction=d["moving"], attempts=attempt + 1,
        )  # fmt: skip
    raise DataError(f"no usable {effect} case from seed {seed} in {MAX_ATTEMPTS} draws (last: {reasons[-1]})")


def _json_safe(params: dict[str, Any]) -> dict[str, Any]:
    def conv(v: Any) -> Any:
        if isinstance(v, (list, tuple, np.ndarray)):
            return [conv(w) for w in v]
        if isinstance(v, (int, np.integer)) and not isinstance(v, bool):
            return int(v)
        return float(v)

    return {k: conv(v) for k, v in params.items()}


def case_specs(
    levels: Sequence[float] = (3.0, 1.0),
    per_effect: int = 5,
    seed: int = 0,
    effects: Sequence[str] | None = None,
) -> list[CaseSpec]:
    """The benchmark's cases: ``per_effect`` per effect and level (catalogue and out of
    catalogue), and ``per_effect * len(levels)`` "none" cases. A case's seed depends only on
    (seed, effect, level, index), so a subset of effects or levels gives the same cases."""
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
    """The cases of :func:`case_specs`, built one at a time (``kwargs`` go to :func:`make_case`)."""
    for spec in case_specs(levels, per_effect, seed, effects):
        yield make_case(spec.effect, spec.level, spec.seed, **kwargs)
