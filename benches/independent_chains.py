"""Independent withheld-effect benchmark, second part: other chains, two effects, new physics.

Extends ``benches/independent_effects.py`` (read its docstring first: plant, noise, ENR, rejection
rules, inputs) and shares its helpers by import. Like it, this generator was written without
reading the diagnoser's effect models (``backlashid.diagnosis.effects``, the core's ``effects``)
or the first withheld-effect benchmark's generator: each plant and effect below is simulated in
NumPy/SciPy from its own continuous-time physics, then only the package's public API is called:
a nominal fit (``bid.fit_cascade``, ``bid.fit_sandwich`` or ``bid.fit_hammerstein_backlash``)
and ``bid.diagnose`` (which effect did it miss?).

    python benches/independent_chains.py --check --jobs 2                 # generator + nominal fits only
    python benches/independent_chains.py --seeds tune --jobs 2 --json out.json
    python benches/independent_chains.py --rows sandwich:friction --levels 3 --index 4   # one case

Plants (families; time in samples, T = 1; records of N = 8000 samples, the first 4000 the
estimation record, the next 4000 the validation record; inputs, noise and ENR as in
independent_effects)
------------------------------------------------------------------------------------------
- cascade: independent_effects' plant, the drive x'' = w^2 (u - x) - 2 z w x' (exact under the
  zero-order hold) -> gear play with cubic branches -> y. Nominal: ``fit_cascade(na=2, nb=2,
  degree=3)``.
- sandwich: a two-mass drive with the play between the masses: the same motor drive -> play
  -> load, the load a second-order system driven by the play's output p,
  y'' = w_l^2 (p - y) - 2 z_l w_l y', w_l log-uniform in W_RANGE, z_l uniform in [0.3, 1.0],
  p held over each sample (the zero-order hold the sandwich's output block holds exactly; a
  first-order hold would add a lag-0 term). Nominal: ``fit_sandwich(na=2, nb=2, degree=3,
  nr=2, ns=2)``.
- hammerstein (input backlash): a position-controlled motor whose angle follows the command
  within one sample, x(t) = u(t-1), -> play on the motor angle -> the same second-order load.
  Nominal: ``fit_hammerstein_backlash(nr=2, ns=2, degree=3)``.
- integrating: the drive's output is a position: a velocity-controlled motor,
  v' = (u - v) / tau_m, x' = v (tau_m log-uniform in [1, 20] samples; poles z = 1 and
  exp(-1 / tau_m), exact under the hold), -> play -> y. The motor starts at x0 (chosen so that
  the record's mean position is 0) and runs PRE = 500 samples of the same input before the
  record starts: records start mid-motion. s = std(x) over the record. Nominal:
  ``fit_cascade(na=2, nb=2, degree=3, initial_state="estimate")``; the diagnosis uses the
  default ``initial_state="estimate"``; each case also records ``bid.evaluate(model, u_val,
  y_val, init_samples=INIT_SAMPLES)`` (INIT_SAMPLES = 100) beside the report's
  ``nominal_validation_rmse``.

Effects (physics name -> the catalogue verdict that counts; "size" is the parameter solved for
the ENR as in independent_effects)
------------------------------------------------------------------------------------------
- dead_time, saturation, output_offset, quantization, colored_noise, width_drift, compliance:
  as in independent_effects (saturation clips the command u, for hammerstein the motor's
  angle command; output_offset and the sensor effects act on the measured output).
- friction: Coulomb + viscous friction (Karnopp stick-slip, SUBSTEPS substeps) where the plant
  has a force balance that the motor drives: on the motor for cascade and sandwich
  (independent_effects' form); on the LOAD for hammerstein (the motor is position-controlled:
  y'' = w_l^2 (p - y) - 2 z_l w_l y' - F_c sign(y') - F_v y', F_c = lam phi w_l^2 std(p),
  F_v = lam nu 2 z_l w_l); for integrating on the motor's velocity balance
  v' = (u - v) / tau_m - F_c sign(v) - F_v v, F_c = lam phi / tau_m, F_v = lam nu / tau_m
  (stuck at rest while abs(u) / tau_m <= F_c). phi in [0.05, 0.3], nu in [0.1, 0.5], size lam in
  [0.01, 4] (integrating: [1e-4, 4]: the position integrates every lost velocity, so the ENR
  needs a far smaller friction).
- saturation on an integrating plant: the clipped share in [0.003, 0.3] and its rule 0.3-30 %
  of the samples (a velocity clipped on 3 % of the samples already drifts the position far
  beyond ENR 3 at realistic noise).
- lugre -> dynamic_friction: a damper-like plant, displacement in, force out: the play's output
  p is a piston position, the load cell measures k p (k = 1: the nominal) plus the LuGre friction
  force of the moving piston, F = sigma0 zb + sigma1 zb' + sigma2 v, zb' = v - sigma0 abs(v) zb / g(v),
  g(v) = F_c + (F_s - F_c) exp(-(v / v_s)^2); v the piston velocity on a grid of SUBSTEPS
  substeps per sample (the drive simulated exactly on that grid, the play applied there), zb
  integrated exactly per substep with v held. F_c = lam r s, F_s / F_c uniform in [1.2, 2],
  presliding distance F_s / sigma0 uniform in [0.005, 0.05] r s, sigma1 = sigma0 times uniform
  [0.05, 0.5] samples, sigma2 = lam nu r s / RMS(v), nu uniform in [0.1, 0.5], v_s = uniform
  [0.1, 1] RMS(v). The force does not move the piston (position-driven): F is linear in lam,
  the size.
- bouc_wen -> feedback_hysteresis: a hysteretic restoring force in the motor's force balance,
  x'' = w^2 (u - x - h zeta) - 2 z w x', zeta Bouc-Wen in x (n = 1, A = 1, zeta_max = lam std(x),
  lam uniform [0.2, 0.5], beta / (beta + gamma) uniform [0.5, 0.9]); size h in [1e-3, 3].
- duffing -> feedback_hysteresis: a hardening spring in the balance, x'' = w^2 (u - x - k3 x^3 / s^2)
  - 2 z w x'; size k3 in [1e-3, 0.5] (larger would need finer substeps). Integrated with
  SUBSTEPS substeps, the nonlinear force held over each (exact ZOH drive without it).
- creep -> creep: piezo-like creep of the actuator, Kelvin-Voigt elements in series: the
  actuator's displacement x_c = x + lam sum_i g_i m_i, m_i' = (x - m_i) / tau_i, three slow
  modes tau_i = (30, 300, 3000) samples times a factor uniform [0.5, 2], g_i = 1/3 (a
  logarithmic-looking creep after each step or dwell), then the play. Size lam in [1e-3, 2].
- travel_stop -> state_saturation: the motor hits hard stops x_lo < 0 < x_hi (inelastic: the
  position is clamped and the velocity zeroed, it stays while the force pushes into the stop);
  the stops at the nominal motor position's quantiles a f_s and 1 - a (1 - f_s), f_s uniform
  [0.3, 0.7]; size a in [0.03, 0.8] (the motor leaves a stop as soon as the force turns, so it
  sits there on about a third of the share the nominal spends beyond it); rejected unless the
  motor sits at a stop on 0.5-30 % of the samples (at 3 %, 11 of the 20 tune cases found no
  draw: a stop the motor touches on 1 % of the samples already carries ENR 3).
- sensor_clip -> sensor_saturation: the measured output (after the noise) clipped to the
  sensor's range [y_lo, y_hi], the nominal output's quantiles a f_s and 1 - a (1 - f_s); d (for
  the ENR) is the noise-free clip error; size a in [0.03, 0.3]; rejected unless 3-30 % of the
  noise-free samples are clipped.
- eccentric_gear -> unexplained: a position-dependent gear ratio (an eccentric wheel): both
  branches gain r eps (P / 2 pi) sin(2 pi x / P + phase), i.e. the ratio r (1 + eps cos(..)),
  P = pf s, pf uniform [0.3, 1]; size eps in [1e-3, 0.9] (the branches keep increasing).
- supply_ripple -> unexplained: the drive's torque constant modulated by a supply ripple,
  the drive sees u (1 + eps sin(2 pi f_r t + phase)), f_r uniform [0.002, 0.02] cycles/sample;
  size eps in [1e-3, 0.5].

For the out-of-catalogue rows the generator also records ``exact_closable_truth``: with y_meas
the measured validation output, (R0^2 - R1^2) / (R0^2 - sigma^2), R0 = RMS(y_meas - y_nominal),
R1 = RMS(y_meas - y_effect) (the true simulation with the effect vs without, nothing refitted);
the runner records ``exact_closable``: the same with R0 = RMS(y_meas - y_fit) and
R1 = RMS(y_meas - y_fit - d), d = y_effect - y_nominal, the share of the FITTED nominal's gap
that an exact model of the withheld effect closes on top of it (the nominal refit absorbed the
rest, or made it worse).

Rows (name family:effect; ENR 3 and 1 unless said; ``--per-effect`` cases, 10 by default, per
row and level, twice as many for the 'none' rows)
------------------------------------------------------------------------------------------
- sandwich: none, dead_time, saturation, friction, output_offset, quantization, colored_noise;
- hammerstein: the same;
- integrating (ENR 3): none, friction, dead_time, saturation, output_offset;
- pair (cascade, two effects at once, each scaled alone to the level): dead_time+output_offset,
  friction+quantization, saturation+width_drift, compliance+colored_noise; the noise is set by
  the noise-scaled member if there is one (dead_time, output_offset), else drawn, and the other
  member solved to the level; each member's ENR alone is recorded (``params[effect]["enr_alone"]``); when
  both are noise-scaled (dead_time+output_offset) sigma = sqrt(RMS(d_1) RMS(d_2)) / level, and
  the draw is rejected unless RMS(d_1) / RMS(d_2) lies in [1/3, 3] (each member's ENR alone
  then within a factor 1.73 of the level);
- physics (cascade): lugre, bouc_wen, duffing, creep, travel_stop, sensor_clip;
- ooc (cascade): eccentric_gear, supply_ripple. (gain_drift and cogging stay in
  independent_effects.)

Rejection: independent_effects' rules (branches must not cross, sigma / std(y_nominal) in
SIGMA_RATIO, saturation and clip shares, offset beyond the widths, >= 20 quantised levels,
moving >= 30 % for friction) and its absorption rule with the family's own nominal
parametrisation (kappa: sensitivities of the generator's nominal to its parameters at the truth,
a Gauss-Newton step; cascade 12 parameters, sandwich 16, hammerstein 13, integrating 12 plus the
integrator's initial position) for every effect but output_offset (where kappa is recorded only;
on an integrating plant a constant offset is, to first order, a shift of the integrator's
initial state, which the nominal estimates). A pair needs kappa >= KAPPA_MIN for each member.
MAX_DRAWS = 60 draws, else the least absorbed draw, marked ``params["kappa_rule"]``.

Decision rules (frozen before any final run)
--------------------------------------------
- single-effect rows: correct iff ``report.best_effect`` is the row's verdict (table above);
  'none' rows: iff 'none'; ooc rows: iff 'unexplained'. fit_error and diagnose_error are wrong.
- pair rows: "both named" iff both members' verdicts are in ``report.effects``; also reported:
  rank-1 (best_effect is one of the two).
- per row and level: the share correct; per family and level: rank-1 over the catalogue rows.
- ooc: the share 'unexplained'; and the closable rule: among the ooc cases with
  exact_closable >= 0.5, the share whose ``report.details.model_error.closable_share`` >= 0.5
  (target >= 80 %).
- integrating: the ratio evaluate(.., init_samples=100).simulation_rmse /
  report.nominal_validation_rmse per case; target: within [0.9, 1.1] on every case.
- gap_closed: every candidate's gap_closed over all cases; target inside [-10, 1].
- raises: cases with fit_error or diagnose_error, each listed (target 0); time: median
  diagnosis time (target <= 2 s).

Seeds: ``--seeds tune`` and ``--seeds final`` (never run while tuning), new names for these rows:
a case's generator is ``numpy.random.default_rng([SEED_SETS[set], crc32(row), round(100 * level),
index])`` with SEED_SETS = {"tune": 35_101, "final": 35_202} (disjoint from
independent_effects' 18_101 / 18_202 and from each other); the input class is
INPUT_CLASSES[index % 5].
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import zlib
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import scipy.signal

sys.path.insert(0, str(Path(__file__).resolve().parent))
import independent_effects as ie  # the first part's helpers, unmodified

Array = np.ndarray
N, N_EST, WARMUP = ie.N, ie.N_EST, ie.WARMUP
SUBSTEPS = ie.SUBSTEPS
PRE = 500  # integrating plants: samples run before the record starts
INIT_SAMPLES = 100  # integrating plants: samples that initialise evaluate's state
MAX_DRAWS = ie.MAX_DRAWS
KAPPA_MIN = ie.KAPPA_MIN
SEED_SETS = {"tune": 35_101, "final": 35_202}
FAMILIES = ("cascade", "sandwich", "hammerstein", "integrating")
NOISE_SCALED = ("dead_time", "output_offset")

# physics name -> the verdict that counts (frozen)
VERDICT = {
    "dead_time": "dead_time", "saturation": "saturation", "friction": "friction", "output_offset": "output_offset",
    "quantization": "quantization", "colored_noise": "colored_noise", "width_drift": "width_drift",
    "compliance": "compliance", "lugre": "dynamic_friction", "bouc_wen": "feedback_hysteresis",
    "duffing": "feedback_hysteresis", "creep": "creep", "travel_stop": "state_saturation",
    "sensor_clip": "sensor_saturation", "eccentric_gear": "unexplained", "supply_ripple": "unexplained",
}  # fmt: skip
OUT_OF_CATALOGUE = ("eccentric_gear", "supply_ripple")
_CHAIN_EFFECTS = ("none", "dead_time", "saturation", "friction", "output_offset", "quantization", "colored_noise")
_PAIRS = ("dead_time+output_offset", "friction+quantization", "saturation+width_drift", "compliance+colored_noise")
_PHYSICS = ("lugre", "bouc_wen", "duffing", "creep", "travel_stop", "sensor_clip")


@dataclass(frozen=True)
class Row:
    """One row: a plant family and the effects withheld from its nominal model."""

    family: str
    effects: tuple[str, ...]  # () for 'none'
    levels: tuple[float, ...]
    group: str

    @property
    def name(self) -> str:
        return f"{self.group}:{'+'.join(self.effects) or 'none'}"

    @property
    def verdicts(self) -> tuple[str, ...]:
        return tuple(VERDICT[e] for e in self.effects)


def _rows() -> dict[str, Row]:
    rows = [
        Row(fam, () if e == "none" else (e,), (0.0,) if e == "none" else (3.0, 1.0), fam)
        for fam in ("sandwich", "hammerstein")
        for e in _CHAIN_EFFECTS
    ]
    rows += [Row("integrating", () if e == "none" else (e,), (0.0,) if e == "none" else (3.0,), "integrating")
             for e in ("none", "friction", "dead_time", "saturation", "output_offset")]  # fmt: skip
    rows += [Row("cascade", tuple(p.split("+")), (3.0, 1.0), "pair") for p in _PAIRS]
    rows += [Row("cascade", (e,), (3.0, 1.0), "physics") for e in _PHYSICS]
    rows += [Row("cascade", (e,), (3.0, 1.0), "ooc") for e in OUT_OF_CATALOGUE]
    return {r.name: r for r in rows}


ROWS = _rows()


# -- plants ---------------------------------------------------------------------------------------


def velocity_drive(u: Array, tau: float) -> Array:
    """Position x of the velocity-controlled motor v' = (u - v) / tau, x' = v, from rest, exact under the hold."""
    a, b = np.array([[0.0, 1.0], [0.0, -1.0 / tau]]), np.array([0.0, 1.0 / tau])
    num, den = ie.discrete_tf(a, b, np.array([1.0, 0.0]))
    return np.asarray(scipy.signal.lfilter(num, den, u), dtype=float)


def velocity_drive_friction(u: Array, tau: float, coulomb: float, viscous: float) -> tuple[Array, float]:
    """The velocity drive with v' = (u - v) / tau - coulomb sign(v) - viscous v (Karnopp stick-slip),
    SUBSTEPS substeps per sample, each exact for the linear part with the friction force held;
    the position error of the friction force's sign within a reversing substep is O(coulomb h^2),
    so the trajectory tends to the frictionless one as coulomb -> 0."""
    h = 1.0 / SUBSTEPS
    phi, gam = ie.zoh(np.array([[0.0, 1.0], [0.0, -(1.0 / tau + viscous)]]), np.array([0.0, 1.0]), h)
    p00, p01, p10, p11 = (float(v) for v in phi.ravel())
    g0, g1 = float(gam[0]), float(gam[1])
    out = np.empty(u.size)
    pos, vel, moving = 0.0, 0.0, 0
    for t in range(u.size):
        out[t] = pos
        drive_force = float(u[t]) / tau
        moved = False
        for _ in range(SUBSTEPS):
            if vel == 0.0:
                if abs(drive_force) <= coulomb:
                    continue  # stuck
                fric = -coulomb if drive_force > 0.0 else coulomb
            else:
                fric = -coulomb if vel > 0.0 else coulomb
            force = drive_force + fric
            new_pos = pos + p01 * vel + g0 * force
            new_vel = p11 * vel + g1 * force
            if coulomb and vel != 0.0 and new_vel * vel < 0.0 and abs(drive_force) <= coulomb:
                # the velocity would reverse within the substep and the drive cannot overcome the
                # static friction: it sticks (Karnopp). With a larger drive force it passes through
                # zero (an integrator keeps every velocity lost at a stop, so none is invented here)
                new_vel = 0.0
            pos, vel, moved = new_pos, new_vel, True
        moving += moved
    return out, moving / u.size


def spring_drive_ode(
    u: Array,
    w: float,
    z: float,
    *,
    bw: tuple[float, float, float] | None = None,
    duffing: float = 0.0,
    s: float = 1.0,
    stops: tuple[float, float] | None = None,
) -> tuple[Array, float]:
    """The motor drive x'' = w^2 (u - x - h zeta - k3 x^3 / s^2) - 2 z w x' with hard stops.

    bw = (h, zeta_max, beta_share): a Bouc-Wen force, zeta driven by x; duffing = k3; stops =
    (x_lo, x_hi): inelastic travel stops. SUBSTEPS substeps per sample, each exact for the linear
    part with the nonlinear force held over it. Returns x at the sample instants and the share of
    samples at a stop.
    """
    h = 1.0 / SUBSTEPS
    phi, gam = ie.zoh(*ie.drive_matrices(w, z), h)
    p00, p01, p10, p11 = (float(v) for v in phi.ravel())
    g0, g1 = float(gam[0]), float(gam[1])
    hb, beta, gamma = 0.0, 0.0, 0.0
    if bw is not None:
        hb, zmax, share = bw
        beta, gamma = share / zmax, (1.0 - share) / zmax
    k3 = duffing / (s * s)
    lo, hi = stops if stops is not None else (-math.inf, math.inf)
    out = np.empty(u.size)
    pos, vel, zeta, at_stop = 0.0, 0.0, 0.0, 0
    for t in range(u.size):
        out[t] = pos
        at_stop += pos <= lo or pos >= hi
        ut = float(u[t])
        for _ in range(SUBSTEPS):
            v = ut - hb * zeta - k3 * pos * pos * pos  # the input besides the linear spring, held
            new_pos = p00 * pos + p01 * vel + g0 * v
            new_vel = p10 * pos + p11 * vel + g1 * v
            if new_pos >= hi:
                new_pos, new_vel = hi, 0.0
            elif new_pos <= lo:
                new_pos, new_vel = lo, 0.0
            if hb:
                dx = new_pos - pos
                sgn = 1.0 if dx * zeta > 0.0 else -1.0 if dx * zeta < 0.0 else 0.0
                zeta += dx - (beta * sgn + gamma) * abs(zeta) * dx
            pos, vel = new_pos, new_vel
    return out, at_stop / u.size


def fine_drive(u: Array, w: float, z: float) -> Array:
    """The drive's position on a grid of SUBSTEPS points per sample (exact, u held): x_f[k SUBSTEPS] = x(k)."""
    a, b = ie.drive_matrices(w, z)
    phi, gam = ie.zoh(a, b, 1.0 / SUBSTEPS)
    num, den = scipy.signal.ss2tf(phi, gam.reshape(-1, 1), np.array([[1.0, 0.0]]), np.zeros((1, 1)))
    return np.asarray(scipy.signal.lfilter(np.asarray(num[0]), np.asarray(den), np.repeat(u, SUBSTEPS)), dtype=float)


def lugre_force(v: Array, f_c: float, f_s: float, v_s: float, sigma0: float, sigma1: float, sigma2: float, h: float) -> Array:
    """LuGre friction force for the velocity v on a grid of step h (zb exact per step with v held)."""
    out = np.empty(v.size)
    zb = 0.0
    for k in range(v.size):
        vk = float(v[k])
        if vk != 0.0:
            g = f_c + (f_s - f_c) * math.exp(-((vk / v_s) ** 2))
            a = sigma0 * abs(vk) / g
            z_ss = vk / a
            new = z_ss + (zb - z_ss) * math.exp(-a * h)
        else:
            new = zb
        out[k] = sigma0 * new + sigma1 * (new - zb) / h + sigma2 * vk
        zb = new
    return out


def first_order(x: Array, tau: float) -> Array:
    """m' = (x - m) / tau from rest, x held over each sample."""
    a = math.exp(-1.0 / tau)
    return np.asarray(scipy.signal.lfilter([0.0, 1.0 - a], [1.0, -a], x), dtype=float)


def branches(x: Array, c_l: Any, c_r: Any, r: float, k_l: float, k_r: float, s: float) -> tuple[Array, Array]:
    """The play's up and down branches R(x), L(x) (independent_effects' cubic mesh)."""
    up, dn = x - c_r, x + c_l
    return r * (up + k_r * up**3 / s**2), r * (dn + k_l * dn**3 / s**2)


@dataclass
class Plant:
    """One drawn plant of a family; ``simulate(mods)`` is its noise-free output with the effects in mods."""

    family: str
    u: Array  # the whole input (with the pre-roll for integrating)
    p: dict[str, float]
    start: int = 0  # first sample of the record

    def motor(self, u: Array, mods: dict[str, dict[str, Any]]) -> tuple[Array, dict[str, float]]:
        """The motor position x (the play's input) and bookkeeping."""
        p, info = self.p, {}
        if "supply_ripple" in mods:
            m = mods["supply_ripple"]
            u = u * (1.0 + m["size"] * np.sin(2 * np.pi * m["f_r"] * np.arange(u.size) + m["phase"]))
        if self.family == "hammerstein":
            return np.r_[0.0, u[:-1]], info
        if self.family == "integrating":
            if "friction" in mods:
                m = mods["friction"]
                x, info["moving"] = velocity_drive_friction(u, p["tau_m"], m["F_c"] * m["size"], m["F_v"] * m["size"])
            else:
                x = velocity_drive(u, p["tau_m"])
            return x + p["x0"], info
        w, z = p["w"], p["z"]
        if self.family in ("cascade", "sandwich") and "friction" in mods:
            m = mods["friction"]
            x, info["moving"] = ie.drive_ode(u, w, z, coulomb=m["F_c"] * m["size"], viscous=m["F_v"] * m["size"])
        elif "bouc_wen" in mods or "duffing" in mods or "travel_stop" in mods:
            bw = mods.get("bouc_wen")
            st = mods.get("travel_stop")
            stops = None
            if st is not None:
                stops = (
                    float(np.quantile(st["x_nom"], st["size"] * st["f_s"])),
                    float(np.quantile(st["x_nom"], 1.0 - st["size"] * (1.0 - st["f_s"]))),
                )
            x, info["at_stop"] = spring_drive_ode(
                u, w, z, bw=None if bw is None else (bw["size"], bw["zeta_max"], bw["beta_share"]),
                duffing=mods["duffing"]["size"] if "duffing" in mods else 0.0, s=p["s"], stops=stops,
            )  # fmt: skip
        else:
            x = ie.drive(u, w, z)
        if "creep" in mods:
            m = mods["creep"]
            x = x + m["size"] * sum(first_order(x, tau) for tau in m["taus"]) / len(m["taus"])
        return x, info

    def simulate(self, mods: dict[str, dict[str, Any]]) -> tuple[Array, dict[str, float]]:
        """Noise-free output over the record (sensor effects after the noise excepted: see measure)."""
        p = self.p
        u = self.u
        if "dead_time" in mods:
            d = mods["dead_time"]["d"]
            u = np.r_[np.zeros(d), u[:-d]]
        if "saturation" in mods:
            umax = mods["saturation"]["u_max"](mods["saturation"]["size"])
            u = np.clip(u, -umax, umax)
        x, info = self.motor(u, mods)
        c_l, c_r = p["c_L"], p["c_R"]
        if "width_drift" in mods:
            ramp = mods["width_drift"]["size"] * np.arange(x.size) / x.size
            c_l, c_r = c_l * (1.0 + ramp), c_r * (1.0 + ramp)
        rr, ll = branches(x, c_l, c_r, p["r"], p["k_L"], p["k_R"], p["s"])
        if "eccentric_gear" in mods:
            m = mods["eccentric_gear"]
            ripple = p["r"] * m["size"] * m["period"] / (2 * np.pi) * np.sin(2 * np.pi * x / m["period"] + m["phase"])
            rr, ll = rr + ripple, ll + ripple
        y = ie.clip_play(rr, ll)
        if "compliance" in mods:
            y = _compliance(y, mods["compliance"]["size"], mods["compliance"]["z_l"])
        if self.family in ("sandwich", "hammerstein"):
            if self.family == "hammerstein" and "friction" in mods:
                m = mods["friction"]
                y, info["moving"] = ie.drive_ode(y, p["w_l"], p["z_l"], coulomb=m["F_c"] * m["size"], viscous=m["F_v"] * m["size"])
            else:
                y = ie.drive(y, p["w_l"], p["z_l"])
        if "lugre" in mods:
            m = mods["lugre"]
            y = y + m["size"] * m["force"]
        if "output_offset" in mods:
            y = y + mods["output_offset"]["o"]
        if "colored_noise" in mods:
            y = y + mods["colored_noise"]["size"] * mods["colored_noise"]["v"]
        y = y[self.start :]
        if "quantization" in mods:
            q = mods["quantization"]["range"] / mods["quantization"]["size"]
            y = q * np.round(y / q)
        if "sensor_clip" in mods:
            lo, hi = _clip_range(mods["sensor_clip"])
            y = np.clip(y, lo, hi)
        return y, info


def _clip_range(m: dict[str, Any]) -> tuple[float, float]:
    return float(np.quantile(m["y_nom"], m["size"] * m["f_s"])), float(np.quantile(m["y_nom"], 1.0 - m["size"] * (1.0 - m["f_s"])))


def _compliance(p: Array, wl: float, zl: float) -> Array:
    """independent_effects' compliance: y = (2 z_l w_l s + w_l^2) / (s^2 + 2 z_l w_l s + w_l^2) p, first-order hold."""
    a = np.array([[0.0, 1.0], [-(wl**2), -2.0 * zl * wl]])
    sys_d = scipy.signal.cont2discrete(
        (a, np.array([[0.0], [1.0]]), np.array([[wl**2, 2.0 * zl * wl]]), np.zeros((1, 1))), 1.0, method="foh"
    )
    num, den = scipy.signal.ss2tf(*sys_d[:4])
    return np.asarray(scipy.signal.lfilter(np.asarray(num[0]), np.asarray(den), p), dtype=float)


def draw_plant(family: str, kind: str, rng: np.random.Generator) -> Plant:
    """A plant of the family (module doc); raises ie.Degenerate if its branches cross."""
    start = PRE if family == "integrating" else 0
    u = ie.make_input(kind, rng, N + start)
    if family == "integrating":  # a velocity command: the rate of change of a position profile of the class
        u = np.diff(u, prepend=0.0)
        u *= 0.6 / float(np.std(u))
    p: dict[str, float] = {}
    if family == "integrating":
        p["tau_m"] = float(np.exp(rng.uniform(np.log(1.0), np.log(20.0))))
        x = velocity_drive(u, p["tau_m"])
        p["x0"] = -float(np.mean(x[start:]))
        x = x + p["x0"]
    elif family == "hammerstein":
        x = np.r_[0.0, u[:-1]]
    else:
        p["w"] = float(np.exp(rng.uniform(*np.log(ie.W_RANGE))))
        p["z"] = float(rng.uniform(0.4, 1.0))
        x = ie.drive(u, p["w"], p["z"])
    s = float(np.std(x[start + WARMUP :]))
    p.update(s=s, r=float(np.exp(rng.uniform(np.log(0.5), np.log(2.0)))), c_L=float(rng.uniform(0.1, 0.4) * s),
             c_R=float(rng.uniform(0.1, 0.4) * s), k_L=float(rng.uniform(0.02, 0.15)))  # fmt: skip
    p["k_R"] = p["k_L"] * float(rng.uniform(0.8, 1.25))
    if family in ("sandwich", "hammerstein"):
        p["w_l"] = float(np.exp(rng.uniform(*np.log(ie.W_RANGE))))
        p["z_l"] = float(rng.uniform(0.3, 1.0))
    xs = x[start:]
    span = float(np.ptp(xs))
    grid = np.linspace(float(xs.min()) - span / 2, float(xs.max()) + span / 2, 2001)
    rr, ll = branches(grid, p["c_L"], p["c_R"], 1.0, p["k_L"], p["k_R"], s)
    if np.min(ll - rr) <= 0.0:
        raise ie.Degenerate("the play's branches cross")
    return Plant(family, u, p, start)


# -- the nominal structure in the generator's own terms (for the absorption rule) ----------------


def _poly_play(x: Array, c_l: float, c_r: float, lc: Array, rc: Array) -> Array:
    up, dn = x - c_r, x + c_l
    return ie.clip_play(up * (rc[0] + up * (rc[1] + up * rc[2])), dn * (lc[0] + dn * (lc[1] + dn * lc[2])))


def nominal_output(plant: Plant, theta: Array) -> Array:
    """The family's nominal structure at theta (the absorption rule's parametrisation), over the record.

    cascade, integrating: (n1, n2, d1, d2, c_L, c_R, l1..l3, r1..r3[, x0]); sandwich: the cascade's
    12 then (b1, b2, a1, a2) of the load; hammerstein: (g, c_L, c_R, l1..l3, r1..r3, b1, b2, a1, a2)
    with x(t) = g u(t-1).
    """
    u = plant.u
    if plant.family == "hammerstein":
        x = theta[0] * np.r_[0.0, u[:-1]]
        y = _poly_play(x, theta[1], theta[2], theta[3:6], theta[6:9])
        load = theta[9:13]
    else:
        x = scipy.signal.lfilter([0.0, theta[0], theta[1]], [1.0, theta[2], theta[3]], u)
        if plant.family == "integrating":
            x = x + theta[12]
        y = _poly_play(x, theta[4], theta[5], theta[6:9], theta[9:12])
        load = theta[12:16] if plant.family == "sandwich" else None
    if load is not None:
        y = scipy.signal.lfilter([0.0, load[0], load[1]], [1.0, load[2], load[3]], y)
    return np.asarray(y, dtype=float)[plant.start :]


def nominal_theta(plant: Plant) -> tuple[Array, Array]:
    """(theta, scales) of the plant's truth in nominal_output's parametrisation."""
    p = plant.p
    r, s = p["r"], p["s"]
    bl = [p["c_L"], p["c_R"], r, 0.0, r * p["k_L"] / s**2, r, 0.0, r * p["k_R"] / s**2]
    bl_sc = [s, s, r, r / s, r / s**2, r, r / s, r / s**2]
    if plant.family == "hammerstein":
        theta, sc = [1.0, *bl], [1.0, *bl_sc]
    else:
        if plant.family == "integrating":
            num, den = ie.discrete_tf(
                np.array([[0.0, 1.0], [0.0, -1.0 / p["tau_m"]]]), np.array([0.0, 1.0 / p["tau_m"]]), np.array([1.0, 0.0])
            )
        else:
            num, den = ie.discrete_tf(*ie.drive_matrices(p["w"], p["z"]), np.array([1.0, 0.0]))
        theta = [num[1], num[2], den[1], den[2], *bl]
        sc = [abs(num[1]), abs(num[2]), 1.0, 1.0, *bl_sc]
        if plant.family == "integrating":
            theta, sc = [*theta, p["x0"]], [*sc, s]
    if plant.family in ("sandwich", "hammerstein"):
        num, den = ie.discrete_tf(*ie.drive_matrices(p["w_l"], p["z_l"]), np.array([1.0, 0.0]))
        theta, sc = [*theta, num[1], num[2], den[1], den[2]], [*sc, abs(num[1]), abs(num[2]), 1.0, 1.0]
    return np.array(theta, dtype=float), np.array(sc, dtype=float)


def unabsorbed_share(plant: Plant, d: Array) -> float:
    """independent_effects' kappa for the family's nominal: d fitted on the estimation record by the
    nominal's sensitivities at the truth (central differences), RMS of the rest / RMS(d) on validation."""
    theta, scales = nominal_theta(plant)
    cols = []
    for i, sc in enumerate(scales):
        h = 1e-5 * float(sc)
        tp, tm = theta.copy(), theta.copy()
        tp[i] += h
        tm[i] -= h
        cols.append((nominal_output(plant, tp) - nominal_output(plant, tm)) / (2.0 * h))
    sens = np.column_stack(cols)
    est, val = slice(WARMUP, N_EST), slice(N_EST, N)
    beta = np.linalg.lstsq(sens[est], d[est], rcond=1e-10)[0]
    rest = d[val] - sens[val] @ beta
    if plant.family == "integrating":  # the validation record's own state, estimated as the nominal's
        state = _state_columns(plant, theta)[val]
        rest = rest - state @ np.linalg.lstsq(state, rest, rcond=1e-10)[0]
    return ie.rms(rest) / max(ie.rms(d[val]), 1e-300)


def _state_columns(plant: Plant, theta: Array) -> Array:
    """Integrating plants: the output's sensitivities to the motor's state at the validation
    record's start, its two free modes (a position step, 1, and a velocity step's decaying part,
    lambda^k, lambda = exp(-1 / tau_m)) added to x from sample N_EST of the record on."""
    x = scipy.signal.lfilter([0.0, theta[0], theta[1]], [1.0, theta[2], theta[3]], plant.u) + theta[12]
    k = np.arange(x.size) - (plant.start + N_EST)
    lam = math.exp(-1.0 / plant.p["tau_m"])
    h = 1e-5 * plant.p["s"]
    base = _poly_play(x, theta[4], theta[5], theta[6:9], theta[9:12])
    cols = []
    for mode in (np.ones(x.size), lam ** np.maximum(k, 0)):
        xp = x + h * np.where(k >= 0, mode, 0.0)
        cols.append((_poly_play(xp, theta[4], theta[5], theta[6:9], theta[9:12]) - base) / h)
    return np.column_stack(cols)[plant.start :]


def truth_model(plant: Plant) -> Any:
    """The plant without effects as the package's model (the nominal structure holds it exactly;
    integrating plants start at x0 mid-motion, which a model simulated from rest does not)."""
    import backlashid as bid

    p = plant.p
    r, s = p["r"], p["s"]
    backlash = bid.GeneralBacklash(p["c_L"], p["c_R"], [r, 0.0, r * p["k_L"] / s**2], [r, 0.0, r * p["k_R"] / s**2])
    if plant.family in ("sandwich", "hammerstein"):
        num, den = ie.discrete_tf(*ie.drive_matrices(p["w_l"], p["z_l"]), np.array([1.0, 0.0]))
        load = bid.LinearBlock(num[1:], den[1:])
        if plant.family == "hammerstein":
            return bid.SandwichModel(bid.LinearBlock([1.0]), backlash, load)
    theta = nominal_theta(plant)[0]
    drive_block = bid.LinearBlock(theta[:2], theta[2:4])
    if plant.family == "sandwich":
        return bid.SandwichModel(drive_block, backlash, load)
    return bid.CascadeModel(drive_block, backlash)


# -- effects --------------------------------------------------------------------------------------

# (lo, hi) of each scalable effect's size; None: not scalable (the noise is scaled)
SIZE_RANGE: dict[str, tuple[float, float] | None] = {
    "dead_time": None, "output_offset": None, "saturation": (0.03, 0.3), "friction": (0.01, 4.0),
    "quantization": (4.0, 1e5), "colored_noise": None, "width_drift": (0.01, 3.0), "compliance": None,
    "lugre": None, "bouc_wen": (1e-3, 3.0), "duffing": (1e-3, 0.5), "creep": (1e-3, 2.0),
    "travel_stop": (0.03, 0.8), "sensor_clip": (0.03, 0.3), "eccentric_gear": (1e-3, 0.9), "supply_ripple": (1e-3, 0.5),
}  # fmt: skip
# integrating plants: an input-side effect's error integrates into a drift of the position, so
# the ENR needs far smaller sizes than on a plant that forgets
INTEGRATING_RANGE = {"friction": (1e-4, 4.0), "saturation": (0.003, 0.3)}
INTEGRATING_ACTIVE = (0.003, 0.30)  # the saturation rule there


def size_range(effect: str, family: str) -> tuple[float, float]:
    rng = INTEGRATING_RANGE.get(effect) if family == "integrating" else None
    return rng or SIZE_RANGE[effect]  # type: ignore[return-value]


STOP_SHARE = (0.005, 0.30)  # travel_stop: share of the samples the motor sits at a stop

LINEAR = ("colored_noise", "lugre")  # d is linear in the size: solved in one step


def effect_params(effect: str, plant: Plant, y0: Array, rng: np.random.Generator) -> dict[str, Any]:
    """The effect's drawn parameters (all but its size); raises ie.Degenerate where a rule refuses."""
    p, u = plant.p, plant.u
    if effect == "dead_time":
        return {"d": int(rng.integers(1, 4))}
    if effect == "output_offset":
        side = float(rng.choice([-1.0, 1.0]))
        o = side * float(rng.uniform(*ie.OFFSET_RANGE)) * p["r"] * (p["c_R"] if side > 0 else p["c_L"])
        if p["c_R"] - o / p["r"] >= 0.0 and p["c_L"] + o / p["r"] >= 0.0:
            raise ie.Degenerate("offset absorbable by the play widths")
        return {"o": o}
    if effect == "saturation":
        au = np.abs(u)
        return {"u_max": lambda share: float(np.quantile(au, 1.0 - share))}
    if effect == "friction":
        phi, nu = float(rng.uniform(0.05, 0.3)), float(rng.uniform(0.1, 0.5))
        if plant.family == "integrating":
            return {"phi": phi, "nu": nu, "F_c": phi / p["tau_m"], "F_v": nu / p["tau_m"]}
        if plant.family == "hammerstein":  # on the load, driven by the play's output
            sp = float(np.std(plant.simulate({})[0][WARMUP:]))  # scale of the load: its nominal output
            return {"phi": phi, "nu": nu, "F_c": phi * p["w_l"] ** 2 * sp, "F_v": nu * 2 * p["z_l"] * p["w_l"]}
        return {"phi": phi, "nu": nu, "F_c": phi * p["w"] ** 2 * p["s"], "F_v": nu * 2 * p["z"] * p["w"]}
    if effect == "quantization":
        return {"range": float(np.ptp(y0))}
    if effect == "colored_noise":
        rho = float(rng.uniform(0.85, 0.98))
        e = rng.standard_normal(plant.u.size)
        v_start = float(rng.standard_normal()) / np.sqrt(1.0 - rho**2)
        v = np.asarray(scipy.signal.lfilter([1.0], [1.0, -rho], e, zi=[rho * v_start])[0])
        return {"rho": rho, "v": v / ie.rms(v[plant.start + WARMUP :])}
    if effect == "width_drift":
        return {}
    if effect == "compliance":
        return {"z_l": float(rng.uniform(0.1, 0.5))}
    if effect == "lugre":
        rs = p["r"] * p["s"]
        xf = fine_drive(u, p["w"], p["z"])
        rr, ll = branches(xf, p["c_L"], p["c_R"], p["r"], p["k_L"], p["k_R"], p["s"])
        v = np.diff(ie.clip_play(rr, ll), prepend=0.0) * SUBSTEPS
        v_rms = max(ie.rms(v), 1e-12)
        f_s = float(rng.uniform(1.2, 2.0))
        sigma0 = f_s / float(rng.uniform(0.005, 0.05))  # F_s / sigma0: the presliding distance, in units of r s
        par = {"F_s_over_F_c": f_s, "sigma0": sigma0, "sigma1": sigma0 * float(rng.uniform(0.05, 0.5)),
               "sigma2": float(rng.uniform(0.1, 0.5)) * rs / v_rms, "v_s": float(rng.uniform(0.1, 1.0)) * v_rms}  # fmt: skip
        # the force for lam = 1 (F_c = r s), sampled at the sample instants
        f = lugre_force(v, rs, f_s * rs, par["v_s"], par["sigma0"], par["sigma1"], par["sigma2"], 1.0 / SUBSTEPS)
        return {**par, "force": f[::SUBSTEPS]}  # F(t): grid point t SUBSTEPS, the end of interval t - 1
    if effect == "bouc_wen":
        x = ie.drive(u, p["w"], p["z"])
        return {"zeta_max": float(rng.uniform(0.2, 0.5)) * float(np.std(x[WARMUP:])), "beta_share": float(rng.uniform(0.5, 0.9))}
    if effect == "duffing":
        return {}
    if effect == "creep":
        return {"taus": [t * float(np.exp(rng.uniform(np.log(0.5), np.log(2.0)))) for t in (30.0, 300.0, 3000.0)]}
    if effect == "travel_stop":
        return {"f_s": float(rng.uniform(0.3, 0.7)), "x_nom": ie.drive(u, p["w"], p["z"])[WARMUP:]}
    if effect == "sensor_clip":
        return {"f_s": float(rng.uniform(0.3, 0.7)), "y_nom": y0[WARMUP:]}
    if effect == "eccentric_gear":
        return {"period": float(rng.uniform(0.3, 1.0)) * p["s"], "phase": float(rng.uniform(0, 2 * np.pi))}
    if effect == "supply_ripple":
        return {"f_r": float(rng.uniform(0.002, 0.02)), "phase": float(rng.uniform(0, 2 * np.pi))}
    raise ValueError(f"unknown effect {effect!r}")


def _wl_range(plant: Plant) -> tuple[float, float]:
    return 1.2 * plant.p["w"], 2.5


def _sized(effect: str, plant: Plant, par: dict[str, Any], y0: Array, target: float) -> tuple[dict[str, Any], Array, dict[str, float]]:
    """The effect's size solved for RMS(d) = target (or fixed); returns (mods entry, y1, info)."""

    def run(size: float) -> tuple[Array, dict[str, float]]:
        return plant.simulate({effect: {**par, "size": size}})

    def d_rms(size: float) -> float:
        return ie.rms((run(size)[0] - y0)[WARMUP:])

    if effect in LINEAR:
        unit = d_rms(1.0)
        size = target / max(unit, 1e-300)
    elif effect == "compliance":
        size = ie._solve_size(d_rms, target, *_wl_range(plant))
    elif SIZE_RANGE[effect] is None:
        size = 1.0
    else:
        size = ie._solve_size(d_rms, target, *size_range(effect, plant.family))
    y1, info = run(size)
    return {**par, "size": size}, y1, info


def _rules(effect: str, mods: dict[str, Any], y1: Array, y0: Array, info: dict[str, float], plant: Plant) -> dict[str, Any]:
    """The effect's rejection rules on the drawn case; returns what to record."""
    out: dict[str, Any] = {}
    if effect == "saturation":
        umax = mods["u_max"](mods["size"])
        active = float(np.mean(np.abs(plant.u[plant.start + WARMUP :]) > umax))
        out.update(u_max=umax, active=active)
        lo, hi = INTEGRATING_ACTIVE if plant.family == "integrating" else (0.03, 0.30)
        if not lo <= active <= hi:
            raise ie.Degenerate(f"saturation active on {active:.3f} of the samples")
    if effect in ("friction",) and info.get("moving", 1.0) < 0.3:
        raise ie.Degenerate(f"the drive moves on {info['moving']:.3f} of the samples")
    if effect == "travel_stop":
        out["at_stop"] = info["at_stop"]
        if not STOP_SHARE[0] <= info["at_stop"] <= STOP_SHARE[1]:
            raise ie.Degenerate(f"at a stop on {info['at_stop']:.3f} of the samples")
    if effect == "sensor_clip":
        lo, hi = _clip_range(mods)
        share = float(np.mean((y0[WARMUP:] <= lo) | (y0[WARMUP:] >= hi)))
        out.update(clip_low=lo, clip_high=hi, clipped=share)
        if not 0.03 <= share <= 0.30:
            raise ie.Degenerate(f"sensor clipped on {share:.3f} of the samples")
    if effect == "quantization":
        q = mods["range"] / mods["size"]
        out.update(q=q, levels_visited=int(np.unique(y1[WARMUP:]).size))
        if out["levels_visited"] < 20:
            raise ie.Degenerate(f"{out['levels_visited']} quantised levels visited")
    if effect == "bouc_wen" and mods["size"] >= SIZE_RANGE["bouc_wen"][1]:  # type: ignore[index]
        out["size_at_end"] = True
    return out


_BULKY = ("u_max", "force", "v", "x_nom", "y_nom", "taus")


def _record(mods: dict[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in mods.items() if k not in _BULKY} | ({"taus": list(mods["taus"])} if "taus" in mods else {})


def _draw(row: Row, level: float, kind: str, rng: np.random.Generator) -> dict[str, Any]:
    """One draw of plant, input and effects; raises ie.Degenerate if a rule refuses it."""
    plant = draw_plant(row.family, kind, rng)
    y0, _ = plant.simulate({})
    scale = float(np.std(y0[WARMUP:]))
    ratio = float(np.exp(rng.uniform(*np.log(ie.NOISE_RATIO))))
    params: dict[str, Any] = {}
    mods: dict[str, Any] = {}
    sigma = ratio * scale
    effects = sorted(row.effects, key=lambda e: e not in NOISE_SCALED)  # a noise-scaled member sets sigma
    noise_scaled = False
    d_alone: dict[str, Array] = {}
    for e in effects:
        par = effect_params(e, plant, y0, rng)
        m, y1, info = _sized(e, plant, par, y0, level * sigma)
        d = (y1 - y0)[WARMUP:]
        if e in NOISE_SCALED:
            if not noise_scaled:  # the first noise-scaled member sets the noise (two: see below)
                sigma = ie.rms(d) / level
            noise_scaled = True
        elif not 0.98 * level * sigma <= ie.rms(d) <= 1.02 * level * sigma:
            noise_scaled = True  # the size hit its range: the noise follows the effect
            sigma = ie.rms(d) / level
        rec = _record(m) | _rules(e, m, y1, y0, info, plant) | {k: v for k, v in info.items()}
        rec["unabsorbed"] = unabsorbed_share(plant, y1 - y0)
        params[e] = rec
        mods[e] = m
        d_alone[e] = y1 - y0
    if len(effects) == 2:  # the second member was solved to level * sigma of the first: re-check both
        if all(e in NOISE_SCALED for e in effects):  # neither scales: the noise sits between them
            rms_a, rms_b = (ie.rms(d_alone[e][WARMUP:]) for e in effects)
            if not 1.0 / 3.0 <= rms_a / rms_b <= 3.0:
                raise ie.Degenerate(f"the members' sizes differ by a factor {max(rms_a / rms_b, rms_b / rms_a):.1f} > 3")
            sigma = math.sqrt(rms_a * rms_b) / level
        for e in effects:
            params[e]["enr_alone"] = ie.rms(d_alone[e][WARMUP:]) / sigma
    y1, info = plant.simulate(mods) if mods else (y0, {})
    if not ie.SIGMA_RATIO[0] <= sigma / scale <= ie.SIGMA_RATIO[1]:
        raise ie.Degenerate(f"sigma / std(y) = {sigma / scale:.4f} out of {ie.SIGMA_RATIO}")
    e_noise = rng.standard_normal(y0.size)
    e_noise *= sigma / ie.rms(e_noise[WARMUP:])
    # sensor effects after the noise: the clean part (without them) plus noise, then quantised / clipped
    post = {k: v for k, v in mods.items() if k not in ("quantization", "sensor_clip")}
    y_pre = plant.simulate(post)[0] if len(post) < len(mods) else y1
    y_meas = y_pre + e_noise
    if "quantization" in mods:
        q = mods["quantization"]["range"] / mods["quantization"]["size"]
        y_meas = q * np.round(y_meas / q)
    if "sensor_clip" in mods:
        y_meas = np.clip(y_meas, *_clip_range(mods["sensor_clip"]))
    dd = (y1 - y0)[WARMUP:]
    enr = ie.rms(dd) / sigma if mods else 0.0
    params["noise_scaled"] = noise_scaled
    if set(row.effects) & set(OUT_OF_CATALOGUE):
        val = slice(N_EST, N)
        r0, r1 = ie.rms((y_meas - y0)[val]), ie.rms((y_meas - y1)[val])
        params["exact_closable_truth"] = (r0**2 - r1**2) / max(r0**2 - sigma**2, 1e-300)
    got = {"u": plant.u[plant.start :], "y": y_meas, "y0": y0, "y1": y1, "sigma": sigma, "plant": plant.p,
           "params": params, "enr": enr, "plant_object": plant}  # fmt: skip
    kept = min((params[e]["unabsorbed"] for e in row.effects if e != "output_offset"), default=1.0)
    params["unabsorbed"] = kept
    if kept < KAPPA_MIN:
        raise ie.Absorbed(f"the nominal structure absorbs all but {kept:.2f} of the effect", got)
    return got


@dataclass
class Case:
    """One generated case of a row (records of N samples: estimation then validation)."""

    row: str
    level: float
    index: int
    seeds: str
    input_class: str
    u: Array
    y: Array
    y_nominal: Array
    y_effect: Array
    noise_std: float
    plant: dict[str, float]
    params: dict[str, Any] = field(default_factory=dict)
    draws: int = 1
    enr_realised: float = float("nan")
    plant_object: Plant | None = None

    @property
    def family(self) -> str:
        return ROWS[self.row].family

    def describe(self) -> dict[str, Any]:
        return {
            "row": self.row, "level": self.level, "index": self.index, "seeds": self.seeds, "input_class": self.input_class,
            "noise_std": self.noise_std, "plant": self.plant, "params": self.params, "draws": self.draws,
            "enr_realised": self.enr_realised,
        }  # fmt: skip


def case_rng(row: str, level: float, index: int, seeds: str) -> np.random.Generator:
    """The case's generator: from (seed set, row, level, index) only."""
    return np.random.default_rng([SEED_SETS[seeds], zlib.crc32(row.encode()), int(round(100 * level)), int(index)])


def make_case(row: str, level: float, index: int, seeds: str = "tune") -> Case:
    """The case (row, level, index) of a seed set, redrawn until no rejection rule refuses it."""
    if seeds not in SEED_SETS:
        raise ValueError(f"seed set {seeds!r}: choose from {', '.join(SEED_SETS)}")
    spec = ROWS[row]
    rng = case_rng(row, level, index, seeds)
    kind = ie.INPUT_CLASSES[index % len(ie.INPUT_CLASSES)]
    last, best = "", None
    for attempt in range(1, MAX_DRAWS + 1):
        try:
            got = _draw(spec, level, kind, rng)
        except ie.Absorbed as exc:
            last = str(exc)
            if best is None or exc.got["params"]["unabsorbed"] > best[0]["params"]["unabsorbed"]:
                best = (exc.got, attempt)
            continue
        except ie.Degenerate as exc:
            last = str(exc)
            continue
        return _case(row, level, index, seeds, kind, got, attempt)
    if best is not None:
        best[0]["params"]["kappa_rule"] = f"best of {MAX_DRAWS} draws"
        return _case(row, level, index, seeds, kind, best[0], MAX_DRAWS)
    raise RuntimeError(f"no acceptable draw of {row} ENR {level:g} index {index} in {MAX_DRAWS} ({last})")


def _case(row: str, level: float, index: int, seeds: str, kind: str, got: dict[str, Any], draws: int) -> Case:
    return Case(row, float(level), int(index), seeds, kind, got["u"], got["y"], got["y0"], got["y1"], got["sigma"],
                got["plant"], got["params"], draws, got["enr"], got["plant_object"])  # fmt: skip


def case_list(rows: list[str], levels: list[float] | None, per_row: int, index: int | None = None) -> list[tuple[str, float, int]]:
    """(row, level, index) of every case: per_row per row and level, 2 per_row for 'none' rows."""
    out: list[tuple[str, float, int]] = []
    for name in rows:
        spec = ROWS[name]
        if not spec.effects:
            out += [(name, 0.0, i) for i in ([index] if index is not None else range(2 * per_row))]
            continue
        for level in spec.levels:
            if levels is not None and level not in levels:
                continue
            out += [(name, level, i) for i in ([index] if index is not None else range(per_row))]
    return out


# -- running --------------------------------------------------------------------------------------


def fit_nominal(c: Case) -> Any:
    """The family's nominal fit on the estimation record (module doc)."""
    import backlashid as bid

    u, y = c.u[:N_EST], c.y[:N_EST]
    if c.family == "sandwich":
        return bid.fit_sandwich(u, y, na=2, nb=2, degree=3, nr=2, ns=2)
    if c.family == "hammerstein":
        return bid.fit_hammerstein_backlash(u, y, nr=2, ns=2, degree=3)
    if c.family == "integrating":
        return bid.fit_cascade(u, y, na=2, nb=2, degree=3, initial_state="estimate")
    return bid.fit_cascade(u, y, na=2, nb=2, degree=3)


def _closable(y: Array, y_fit: Array, d: Array, sigma: float) -> float:
    """Share of the fitted nominal's validation gap that adding the true effect d closes, nothing refitted."""
    val = slice(N_EST, N)
    r0, r1 = ie.rms((y - y_fit)[val]), ie.rms((y - y_fit - d)[val])
    return (r0**2 - r1**2) / max(r0**2 - sigma**2, 1e-300)


def _report_fields(report: Any) -> dict[str, Any]:
    """The report's fields the summary reads (the rewritten diagnosis's specification)."""
    details = getattr(report, "details", None)
    model_error = getattr(details, "model_error", None)
    closable = getattr(model_error, "closable_share", None)
    return {
        "reported": report.best_effect,
        "effects": list(getattr(report, "effects", ())),
        "ranking": [[cand.effect, float(cand.gap_closed), float(getattr(cand, "validation_rmse", np.nan))] for cand in report.ranking],
        "nominal_validation_rmse": float(getattr(report, "nominal_validation_rmse", np.nan)),
        "report_noise_std": float(getattr(report, "noise_std", np.nan)),
        "noise_std_estimated": getattr(report, "noise_std_estimated", None),
        "closable_share": None if closable is None else float(closable),
    }


def run_case(row: str, level: float, index: int, seeds: str, check: bool) -> dict[str, Any]:
    """Generate, fit, (diagnose). Never raises: errors are results."""
    import backlashid as bid

    out: dict[str, Any] = {"row": row, "level": level, "index": index, "seeds": seeds}
    t0 = time.perf_counter()
    try:
        c = make_case(row, level, index, seeds)
    except Exception as exc:
        out.update(reported="generate_error", error=f"{type(exc).__name__}: {exc}")
        return out
    out.update(c.describe())
    out["generate_seconds"] = time.perf_counter() - t0
    fit = ie.recorded(out, "fit", lambda: fit_nominal(c))
    if fit is None:
        return out
    u_val, y_val = c.u[N_EST:], c.y[N_EST:]
    try:
        if c.family == "integrating":  # mid-motion: the state estimated on the first samples
            out["evaluate_rmse"] = float(bid.evaluate(fit.model, u_val, y_val, init_samples=INIT_SAMPLES).simulation_rmse)
            out["val_rmse_over_sigma"] = out["evaluate_rmse"] / c.noise_std
            # the same for the true plant: how much of it is the state estimate's, not the fit's
            truth = truth_model(c.plant_object)
            out["truth_rmse_over_sigma"] = float(bid.evaluate(truth, u_val, y_val, init_samples=INIT_SAMPLES).simulation_rmse) / c.noise_std
        else:
            y_fit = np.asarray(fit.model.simulate(c.u), dtype=float)
            out["val_rmse_over_sigma"] = ie.rms((c.y - y_fit)[N_EST:]) / c.noise_std
            if set(ROWS[row].effects) & set(OUT_OF_CATALOGUE):
                out["exact_closable"] = _closable(c.y, y_fit, c.y_effect - c.y_nominal, c.noise_std)
    except Exception as exc:
        out["val_rmse_over_sigma"] = float("nan")
        out["simulate_error"] = f"{type(exc).__name__}: {exc}"
    if check:
        out["reported"] = None
        return out
    options: dict[str, Any] = {"compose": True} if len(ROWS[row].effects) > 1 else {}
    fields = ie.recorded(out, "diagnose", lambda: _report_fields(bid.diagnose(fit.model, (c.u[:N_EST], c.y[:N_EST]), (u_val, y_val), **options)))
    if fields is not None:
        out.update(fields)
    return out


# -- summaries ------------------------------------------------------------------------------------


def _share(flags: list[bool]) -> float:
    return float(np.mean(flags)) if flags else float("nan")


def _pct(x: float) -> str:
    return "  n/a" if not np.isfinite(x) else f"{100 * x:5.1f} %"


def correct(x: dict[str, Any]) -> bool:
    """The frozen decision rule: best_effect is the row's verdict (pairs: both named in effects)."""
    spec = ROWS[x["row"]]
    if not spec.effects:
        return x.get("reported") == "none"
    if len(spec.effects) > 1:
        return all(v in (x.get("effects") or []) for v in spec.verdicts)
    return x.get("reported") == spec.verdicts[0]


def _rank1(x: dict[str, Any]) -> bool:
    return x.get("reported") in ROWS[x["row"]].verdicts


RAISED = ("fit_error", "diagnose_error", "generate_error")


def summarise(results: list[dict[str, Any]]) -> dict[str, Any]:
    """Per row and level: the share correct (and for pairs rank-1); the integrating RMSE ratio,
    the closable rule, the gap_closed range, raises, time."""
    summary: dict[str, Any] = {"cases": len(results), "rows": {}}
    print(f"{'row':<34} {'ENR':>4} {'n':>3} {'correct':>8} {'rank-1':>8}  verdicts")
    for name in ROWS:
        for level in sorted({x["level"] for x in results if x["row"] == name}, reverse=True):
            sub = [x for x in results if x["row"] == name and x["level"] == level]
            ok, r1 = _share([correct(x) for x in sub]), _share([_rank1(x) for x in sub])
            counts: dict[str, int] = {}
            for x in sub:
                counts[str(x.get("reported"))] = counts.get(str(x.get("reported")), 0) + 1
            verdicts = ", ".join(f"{k} {v}" for k, v in sorted(counts.items(), key=lambda kv: -kv[1]))
            print(f"{name:<34} {level:>4g} {len(sub):>3} {_pct(ok):>8} {_pct(r1) if ROWS[name].effects else '':>8}  {verdicts}")
            summary["rows"][f"{name} {level:g}"] = {"n": len(sub), "correct": ok, "rank1": r1, "verdicts": counts}
    print("\n== per family and level: catalogue single-effect rows' rank-1, 'none', 'unexplained', pairs both named")
    for fam_group in ("sandwich", "hammerstein", "integrating", "physics", "pair", "ooc"):
        for level in sorted({x["level"] for x in results if x["row"].startswith(fam_group + ":")}, reverse=True):
            sub = [x for x in results if x["row"].startswith(fam_group + ":") and x["level"] == level]
            label = {"pair": "both named", "ooc": "unexplained"}.get(fam_group, "none" if level == 0.0 else "rank-1")
            share = _share([correct(x) for x in sub])
            print(f"{fam_group:<12} ENR {level:g}: {label} {_pct(share)} of {len(sub)}")
            summary[f"{fam_group} {level:g}"] = {"label": label, "share": share, "n": len(sub)}
    # integrating: evaluate(init_samples) vs the report's nominal validation RMSE
    ratios = [x["evaluate_rmse"] / x["nominal_validation_rmse"] for x in results
              if "evaluate_rmse" in x and np.isfinite(x.get("nominal_validation_rmse", np.nan)) and x["nominal_validation_rmse"] > 0]  # fmt: skip
    if ratios:
        inside = _share([0.9 <= v <= 1.1 for v in ratios])
        summary["integrating_rmse_ratio"] = {
            "median": float(np.median(ratios)),
            "min": float(min(ratios)),
            "max": float(max(ratios)),
            "within_10pct": inside,
        }
        print(f"\nintegrating: evaluate(init_samples={INIT_SAMPLES}) / nominal_validation_rmse: median {np.median(ratios):.3f}, "
              f"range [{min(ratios):.3f}, {max(ratios):.3f}], within 10 %: {_pct(inside)} of {len(ratios)} (target: all)")  # fmt: skip
    # out of catalogue: the closable rule
    ooc = [x for x in results if set(ROWS[x["row"]].effects) & set(OUT_OF_CATALOGUE)]
    if ooc:
        eligible = [x for x in ooc if x.get("exact_closable", -np.inf) >= 0.5]
        met = _share([(x.get("closable_share") is not None and x["closable_share"] >= 0.5) for x in eligible])
        summary["closable_rule"] = {"eligible": len(eligible), "of": len(ooc), "share": met}
        print(f"out of catalogue: exact model closes >= 0.5 on {len(eligible)} of {len(ooc)}; of those, "
              f"report closable_share >= 0.5 on {_pct(met)} (target >= 80 %)")  # fmt: skip
    gaps = [g for x in results for _, g, _ in x.get("ranking", []) if np.isfinite(g)]
    if gaps:
        inside = _share([-10.0 <= g <= 1.0 for g in gaps])
        summary["gap_closed"] = {"min": float(min(gaps)), "max": float(max(gaps)), "inside": inside, "n": len(gaps)}
        print(f"gap_closed of every candidate: [{min(gaps):.3g}, {max(gaps):.3g}], inside [-10, 1]: {_pct(inside)} of {len(gaps)}")
    raises = [x for x in results if x.get("reported") in RAISED]
    summary["raises"] = len(raises)
    print(f"cases that raised: {len(raises)} (target 0)")
    for x in raises:
        print(f"  {x['reported']}: {x['row']} ENR {x['level']:g} #{x['index']}: {x.get('error', '')[:200]}")
    diag_t = [x["diagnose_seconds"] for x in results if "diagnose_seconds" in x and x.get("reported") not in RAISED]
    if diag_t:
        summary["diagnose_seconds_median"] = float(np.median(diag_t))
        print(f"diagnosis time: median {np.median(diag_t):.2f} s, max {np.max(diag_t):.2f} s (target median <= 2 s)")
    misses = [x for x in results if not correct(x)]
    summary["misses"] = len(misses)
    print(f"\n== misses ({len(misses)}): row, ENR, input class, index: reported [effects] [top-3 gap closed]")
    for x in misses:
        top = ", ".join(f"{e} {g:.2f}" for e, g, _ in x.get("ranking", [])[:3])
        print(
            f"  {x['row']:<34} ENR {x['level']:g} {x.get('input_class', '?'):<9} #{x['index']:<3}: {x.get('reported')!s:<20} {x.get('effects')} [{top}]"
        )
    return summary


def _median(v: list[float]) -> float:
    fin = [x for x in v if np.isfinite(x)]
    return float(np.median(fin)) if fin else float("nan")


def check_report(results: list[dict[str, Any]]) -> dict[str, Any]:
    """--check: per row and level, the realised ENR, rejections, kappa, the nominal fit's
    validation RMSE over sigma, the time per case."""
    print("RMSE/sigma: the nominal fit's validation simulation RMSE over sigma (integrating: evaluate with "
          f"init_samples={INIT_SAMPLES}); 1 = the noise floor, sqrt(1 + ENR^2) = the effect not absorbed at all")  # fmt: skip
    print("redraws: draws beyond one per case (rejections); kappa*: cases that took the least absorbed of 60 draws")
    head = f"{'row':<34} {'ENR':>4} {'n':>3} {'ENR real':>13} {'redraws':>7} {'kappa*':>6} {'kappa med':>9}"
    print(head + f" {'RMSE/sigma med':>14} {'min':>6} {'max':>6} {'gen s':>6} {'fit s':>6}")
    out: dict[str, Any] = {}
    for name in ROWS:
        for level in sorted({x["level"] for x in results if x["row"] == name}, reverse=True):
            sub = [x for x in results if x["row"] == name and x["level"] == level]
            enr = [x.get("enr_realised", np.nan) for x in sub]
            ratio = [v for v in (x.get("val_rmse_over_sigma", np.nan) for x in sub) if np.isfinite(v)]
            redraws = sum(x.get("draws", 1) - 1 for x in sub)
            kstar = sum("kappa_rule" in x.get("params", {}) for x in sub)
            kap = [min((x["params"][e]["unabsorbed"] for e in ROWS[name].effects), default=np.nan) for x in sub if "params" in x]
            gen = _median([x.get("generate_seconds", np.nan) for x in sub])
            fit = _median([x.get("fit_seconds", np.nan) for x in sub])
            med = float(np.median(ratio)) if ratio else float("nan")
            lo, hi = (min(ratio), max(ratio)) if ratio else (np.nan, np.nan)
            k_med = float(np.nanmedian(kap)) if np.isfinite(kap).any() else float("nan")
            erange = f"{np.nanmin(enr):.2f}-{np.nanmax(enr):.2f}" if np.isfinite(enr).any() else "n/a"
            print(f"{name:<34} {level:>4g} {len(sub):>3} {erange:>13} {redraws:>7} {kstar:>6} {k_med:>9.2f} {med:>14.3f} {lo:>6.2f} {hi:>6.2f} "
                  f"{gen:>6.1f} {fit:>6.2f}")  # fmt: skip
            out[f"{name} {level:g}"] = {
                "n": len(sub), "ratio_median": med, "ratio_min": lo, "ratio_max": hi, "redraws": redraws, "kappa_rule": kstar,
                "kappa_median": k_med, "generate_seconds_median": float(gen), "fit_seconds_median": float(fit),
            }  # fmt: skip
    integ = [x for x in results if "truth_rmse_over_sigma" in x]
    if integ:
        fit_r = [x["val_rmse_over_sigma"] for x in integ if x["row"] == "integrating:none"]
        tru_r = [x["truth_rmse_over_sigma"] for x in integ if x["row"] == "integrating:none"]
        if fit_r:
            print(f"\nintegrating:none: evaluate(init_samples={INIT_SAMPLES}) RMSE / sigma of the nominal fit: median {np.median(fit_r):.3f}, "
                  f"max {max(fit_r):.2f}; of the TRUE plant (the package's state estimate only): median {np.median(tru_r):.3f}, "
                  f"max {max(tru_r):.2f}; > 1.1 on {sum(v > 1.1 for v in tru_r)} of {len(tru_r)}")  # fmt: skip
            out["integrating_truth_ratio"] = {
                "median": float(np.median(tru_r)),
                "max": float(max(tru_r)),
                "above_1_1": sum(v > 1.1 for v in tru_r),
            }
    ooc = [x for x in results if "exact_closable" in x]
    if ooc:
        ex = [x["exact_closable"] for x in ooc]
        tr = [x["params"]["exact_closable_truth"] for x in ooc]
        print(f"\nout of catalogue: exact model's closable share of the fitted nominal's gap: median {np.median(ex):.2f}, "
              f">= 0.5 on {sum(v >= 0.5 for v in ex)} of {len(ex)}; of the true nominal's gap: median {np.median(tr):.3f}")  # fmt: skip
    for x in results:
        if x.get("reported") in RAISED or "simulate_error" in x:
            print(
                f"  {x.get('reported') or 'simulate_error'}: {x['row']} ENR {x['level']:g} #{x['index']}: {x.get('error') or x.get('simulate_error')}"
            )
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", choices=list(SEED_SETS), default="tune", help="seed set (default tune; 'final' is the final quote)")
    ap.add_argument("--levels", type=float, nargs="+", default=None, help="ENRs (default each row's: 3 1, integrating 3)")
    ap.add_argument("--per-effect", type=int, default=10, help="cases per row and level (default 10; 'none' rows twice as many)")
    ap.add_argument("--rows", nargs="+", default=list(ROWS), metavar="ROW", help=f"rows (default all: {' '.join(ROWS)})")
    ap.add_argument("--index", type=int, default=None, help="run only this case index")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    ap.add_argument("--check", action="store_true", help="generator and nominal fits only (no diagnosis)")
    ap.add_argument("--json", metavar="PATH", help="write per-case results and the summary as JSON")
    ap.add_argument("--log", metavar="PATH", help="append each case's result as one JSON line as it finishes")
    ap.add_argument("--from-log", metavar="PATH", help="print the summary (with --check: the check report) of a --log file; run nothing")
    args = ap.parse_args()
    if args.from_log:
        with open(args.from_log) as fh:
            by_case = {}  # a case run twice (a restarted run): its last result
            for line in fh:
                if line.strip():
                    res = json.loads(line)
                    by_case[(res["row"], res["level"], res["index"], res["seeds"])] = res
            logged = list(by_case.values())
        print(f"{len(logged)} cases from {args.from_log}")
        check_report(logged) if args.check else summarise(logged)
        return 0
    unknown = [r for r in args.rows if r not in ROWS]
    if unknown:
        ap.error(f"unknown rows {unknown}; choose from {' '.join(ROWS)}")
    cases = case_list(args.rows, args.levels, args.per_effect, args.index)
    mode = "check (no diagnosis)" if args.check else "diagnosis"
    print(f"independent withheld-effect benchmark, chains: {len(cases)} cases, seeds {args.seeds!r}, {mode}, {args.jobs} job(s)")
    t0 = time.perf_counter()
    cols = list(zip(*cases)) if cases else [[], [], []]
    call = (cols[0], cols[1], cols[2], [args.seeds] * len(cases), [args.check] * len(cases))
    log = open(args.log, "a") if args.log else None
    results = []
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for res in pool.map(run_case, *call) if args.jobs > 1 else map(run_case, *call):
            results.append(res)
            if log is not None:
                log.write(json.dumps(res, default=float) + "\n")
                log.flush()
    if log is not None:
        log.close()
    wall = time.perf_counter() - t0
    summary = check_report(results) if args.check else summarise(results)
    summary["wall_seconds"] = wall
    print(f"\nwall time {wall:.1f} s ({wall / max(len(cases), 1):.2f} s per case, {args.jobs} job(s))")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"args": vars(args), "summary": summary, "cases": results}, fh, indent=1, default=float)
        print(f"wrote {os.path.abspath(args.json)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
