"""Per-sample NumPy reference of the paper's models, written as a reader of the paper would.

Plain Python loops over the samples (this is a reference, not a fast path): the linear block
(eq 16) as a difference equation from rest, the same block driven through Coulomb and viscous
friction, the branches (eq 4-5) by Horner's rule, the general backlash (eq 1) in its case
order, and the play operator. The withheld-effect generator builds its true systems from these,
independently of the Rust core, and ``benches/numpy_reference.py`` simulates with them.

The augmented cascade of the diagnosis catalogue (``augmented_cascade``) is built the same way,
one function per effect from its definition (``rust/core/src/effects/*.rs``): the drive stage
(dead time, saturation, friction) on the linear block's input, the width drift on the
dead-band widths, then the output stage in its order (compliance, extra plays, output offset
and drift, quantiser); ``ar_prediction`` is the colored-noise model's one-step prediction.
``tests/diagnosis/test_effects_compliance.py`` checks the Rust simulation against it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "ar_prediction", "augmented_cascade", "backlash", "bouc_wen", "branch", "compliance", "creep", "dahl_friction", "dead_time",
    "difference_equation", "linear_with_friction", "linear_with_stick_slip", "output_offset", "play", "plays", "quantiser",
    "saturation", "width_drift",
]  # fmt: skip

Array = NDArray[np.float64]


def difference_equation(num: Sequence[float], den: Sequence[float], u: Array) -> Array:
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


def linear_with_friction(
    a: Sequence[float],
    b: Sequence[float],
    u: Array,
    f_c: float,
    f_v: float,
    u_past: Sequence[float] = (),
    x_past: Sequence[float] = (),
    restoring: Callable[[float, float, float], float] | None = None,
    stop: tuple[float, float] = (-math.inf, math.inf),
) -> Array:
    """Eq (16) driven by u_eff(t) = u(t) - F_c sign(v(t)) - F_v v(t), v(t) = x(t) - x(t-1)
    (sign(0) = 0): x(t) needs u_eff up to t - 1 only, so u_eff(t) follows x(t). From rest, or
    from the past u_past = [u(-1), u(-2), ..] and x_past = [x(-1), x(-2), ..] (x(-1) is also
    x(t-1) of v at t = 0; 0 without it). ``restoring(drive, x(t), x(t-1))``: the drive less a
    restoring force, after the friction (:func:`bouc_wen`). ``stop`` = (lo, hi) holds x(t) in
    [lo, hi] as it is computed, before the recursion remembers it (a travel stop of the state)."""
    a, b = [float(v) for v in a], [float(v) for v in b]
    na, nb = len(a), len(b)
    ue = [float(v) for v in reversed(u_past)] if len(u_past) else [0.0] * na  # u_eff(t-na) .. u_eff(t-1), oldest first
    xx = [float(v) for v in reversed(x_past)] if len(x_past) else [0.0] * max(nb, 1)
    out = np.empty(len(u))
    for t, ut in enumerate(u.tolist()):
        x = 0.0
        for i in range(1, na + 1):
            x += a[i - 1] * ue[-i]
        for j in range(1, nb + 1):
            x -= b[j - 1] * xx[-j]
        x = stop[0] if x < stop[0] else (stop[1] if x > stop[1] else x)
        v = x - xx[-1]
        sign = 1.0 if v > 0.0 else (-1.0 if v < 0.0 else 0.0)
        drive = ut - f_c * sign - f_v * v if f_c != 0.0 or f_v != 0.0 else ut
        ue.append(restoring(drive, x, xx[-1]) if restoring is not None else drive)
        xx.append(x)
        out[t] = x
    return out


def linear_with_stick_slip(
    a: Sequence[float],
    b: Sequence[float],
    u: Array,
    f_c: float,
    f_v: float,
    f_s: float,
    v_s: float,
    u_past: Sequence[float] = (),
    x_past: Sequence[float] = (),
    restoring: Callable[[float, float, float], float] | None = None,
    stop: tuple[float, float] = (-math.inf, math.inf),
) -> Array:
    """Eq (16) with stick-slip friction in its force balance (Karnopp's rule, a Stribeck dip):
    x(t+1) = a_1 u_eff(t) + x_free; w = u(t) - F_v v, v = x(t) - x(t-1); u_stay = (x(t) -
    x_free) / a_1 holds x(t+1) = x(t), F_hold = w - u_stay; stuck (u_eff = u_stay) while
    abs(F_hold) <= F_c + F_s, else u_eff = w - (F_c + F_s exp(-(v / v_s)^2)) sign(F_hold). At
    F_c = F_v = F_s = 0 (or a_1 = 0: no sticking) u_eff = w. From rest or from the past, with
    the state's ``stop``, as :func:`linear_with_friction`; ``restoring`` subtracted after the
    friction, as there."""
    a, b = [float(v) for v in a], [float(v) for v in b]
    na, nb = len(a), len(b)
    ue = [float(v) for v in reversed(u_past)] if len(u_past) else [0.0] * na  # oldest first
    xx = [float(v) for v in reversed(x_past)] if len(x_past) else [0.0] * max(nb, 1)
    active = f_c != 0.0 or f_v != 0.0 or f_s != 0.0
    out = np.empty(len(u))
    for t, ut in enumerate(u.tolist()):
        x = 0.0
        for i in range(1, na + 1):
            x += a[i - 1] * ue[-i]
        for j in range(1, nb + 1):
            x -= b[j - 1] * xx[-j]
        x = stop[0] if x < stop[0] else (stop[1] if x > stop[1] else x)
        v = x - xx[-1]
        x_prev = xx[-1]
        xx.append(x)
        w = ut - f_v * v
        if not active:
            ue.append(ut)
        elif a[0] == 0.0:
            ue.append(w)
        else:
            # x(t+1) without u_eff(t): a_2 u_eff(t-1) + ... - b_1 x(t) - ..., summed in that order
            free = 0.0
            for i in range(2, na + 1):
                free += a[i - 1] * ue[-(i - 1)]
            for j in range(1, nb + 1):
                free -= b[j - 1] * xx[-j]
            stay = (x - free) / a[0]
            hold = w - stay
            if abs(hold) <= f_c + f_s:
                ue.append(stay)
            else:
                ue.append(w - (f_c + f_s * math.exp(-((v / v_s) ** 2))) * math.copysign(1.0, hold))
        if restoring is not None:
            ue[-1] = restoring(ue[-1], x, x_prev)
        out[t] = x
    return out


def branch(m: Sequence[float], xi: Array) -> Array:
    """sum_{i=1}^n m_i xi^i (eq 4-5) by Horner's rule."""
    acc = np.zeros_like(xi)
    for c in reversed([float(v) for v in m]):
        acc = (acc + c) * xi
    return acc


def backlash(left: Array, right: Array, y0: float = 0.0) -> Array:
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


def play(x: Array, r: float, p0: float = 0.0) -> Array:
    """Play operator of radius r: p(t) = max(x(t) - r, min(x(t) + r, p(t-1))), p(-1) = p0
    (0 at rest)."""
    p, out = float(p0), np.empty(len(x))
    for t, xt in enumerate(x.tolist()):
        p = max(xt - r, min(xt + r, p))
        out[t] = p
    return out


# -- the augmented cascade of the diagnosis catalogue ---------------------------------------------


def dead_time(u: Array, d: int) -> Array:
    """u(t - d), 0 before the record (rest)."""
    return np.concatenate([np.zeros(min(d, len(u))), u[: max(len(u) - d, 0)]])


def saturation(u: Array, lo: float, hi: float) -> Array:
    """The drive input clipped to [lo, hi]."""
    return np.array([lo if v < lo else (hi if v > hi else v) for v in u.tolist()])


def width_drift(c: float, dc: float, tau: Array) -> Array:
    """A dead-band width drifting linearly in time: c(t) = c + dc tau(t)."""
    return c + dc * tau


def compliance(f: Array, k: float, omega: float, zeta: float, f0: float = 0.0) -> Array:
    """y = (1 - k) f + k H(q) f, H(q) = g / (1 + d1 q^-1 + d2 q^-2) with the poles
    exp(omega (-zeta +- j sqrt(1 - zeta^2))) and unit DC gain g = 1 + d1 + d2, its memory at
    rest on f(-1) = f0."""
    rho = math.exp(-zeta * omega)
    d1, d2 = -2.0 * rho * math.cos(omega * math.sqrt(1.0 - zeta * zeta)), rho * rho
    g = 1.0 + d1 + d2
    h1 = h2 = float(f0)
    out = np.empty(len(f))
    for t, ft in enumerate(f.tolist()):
        h = g * ft - d1 * h1 - d2 * h2
        h1, h2 = h, h1
        out[t] = (1.0 - k) * ft + k * h
    return out


def plays(y: Array, x: Array, pairs: Sequence[tuple[float, float]], x0: float = 0.0) -> Array:
    """y + sum_k w_k play_{r_k}(x), each play at rest on x(-1) = x0."""
    out = y.copy()
    for r, w in pairs:
        out = out + w * play(x, r, x0)
    return out


def output_offset(y: Array, o_0: float, o_1: float, tau: Array) -> Array:
    """y + o_0 + o_1 tau(t)."""
    return y + (o_0 + o_1 * tau)


def quantiser(y: Array, q: float) -> Array:
    """q round(y / q), halves away from zero (q = 0: none)."""
    if q == 0.0:
        return y.copy()
    z = y / q
    return q * np.copysign(np.floor(np.abs(z) + 0.5), z)


def bouc_wen(alpha: float, beta: float, gamma: float, k_3: float) -> Callable[[float, float, float], float]:
    """The drive less the restoring force z(t) + k_3 x(t)^3 of a Bouc-Wen element (nu = 1),
    as a function of (drive, x(t), x(t-1)) called once a sample in order, z at rest (0) first.
    z solves dz/dtau = v (alpha - beta sign(v) z - gamma |z|) over the sample, x moving at
    v = x(t) - x(t-1) a sample: while z keeps its sign s_z, z(tau) = z_eq + (z0 - z_eq)
    e^(-k tau), k = v (beta sign(v) + gamma s_z), z_eq = v alpha / k (z0 + v alpha tau where
    k = 0); where that reaches 0 inside the sample (at e^(-k tau0) = z_eq / (z_eq - z0)), the
    rest of the sample from 0 with s_z = sign(v)."""
    z = 0.0

    def sgn(a: float) -> float:
        return 1.0 if a > 0.0 else (-1.0 if a < 0.0 else 0.0)

    def keep_sign(z0: float, v: float, s_z: float, tau: float) -> tuple[float, float]:
        """z after tau, and the time z reaches 0 (inf if it does not before tau)."""
        k = v * (beta * sgn(v) + gamma * s_z)
        if k == 0.0:
            end = z0 + v * alpha * tau
            return end, (-z0 / (v * alpha) if v * alpha != 0.0 and end * z0 < 0.0 else math.inf)
        z_eq = v * alpha / k
        end = z_eq + (z0 - z_eq) * math.exp(-k * tau)
        if z0 != 0.0 and end * z0 < 0.0:
            return end, math.log((z_eq - z0) / z_eq) / k
        return end, math.inf

    def drive_less(drive: float, x: float, x_prev: float) -> float:
        nonlocal z
        v = x - x_prev
        if v != 0.0:
            s_z = sgn(z) if z != 0.0 else sgn(v)
            end, tau0 = keep_sign(z, v, s_z, 1.0)
            z = keep_sign(0.0, v, sgn(v), 1.0 - tau0)[0] if tau0 < 1.0 else end
        return drive - z - k_3 * x * x * x

    return drive_less


def dahl_friction(y: Array, q: Array, k_f: float, z_s: float, lam: float, q0: float = 0.0) -> Array:
    """y + k_f w, w the normalised bristle state of dw/dtau = q'/z_s - (|q'|/z_s + lambda) w
    with the motion q moving at constant speed v(t) = q(t) - q(t-1) over the sample: w(t) =
    e^-kappa w(t-1) + (v / z_s)(1 - e^-kappa) / kappa, kappa = |v| / z_s + lambda; w at rest
    and q(-1) = q0 before the record."""
    out, w, prev = y.copy(), 0.0, float(q0)
    for t, xt in enumerate(q.tolist()):
        v = xt - prev
        kappa = abs(v) / z_s + lam
        gain = -math.expm1(-kappa) / kappa if kappa > 0.0 else 1.0
        w = math.exp(-kappa) * w + v / z_s * gain
        out[t] += k_f * w
        prev = xt
    return out


def creep(y: Array, modes: Sequence[tuple[float, float]], y0: float = 0.0) -> Array:
    """y + sum_k g_k (c_k - y), c_k(t) = p_k c_k(t-1) + (1 - p_k) y(t), p_k = exp(-exp(-l_k))
    for the modes (g_k, l_k), each at rest on y0 before the record."""
    out = y.copy()
    for g, log_t in modes:
        p, c = math.exp(-math.exp(-log_t)), float(y0)
        for t, yt in enumerate(y.tolist()):
            c = p * c + (1.0 - p) * yt
            out[t] += g * (c - yt)
    return out


def augmented_cascade(
    a: Sequence[float],
    b: Sequence[float],
    c_left: float,
    c_right: float,
    m_left: Sequence[float],
    m_right: Sequence[float],
    u: Array,
    effects: Sequence[tuple[str, Sequence[float]]] = (),
    t0: float = 0.0,
    time_scale: float = 1000.0,
    u_past: Sequence[float] = (),
    x_past: Sequence[float] = (),
    y_prev: float = 0.0,
) -> Array:
    """The nominal cascade (eq 16 -> eq 1) with the catalogue's effects, each given as
    (name, parameters) in the Python catalogue's order: u(t - d), clipped to [lo, hi], through
    friction (or stick-slip friction) and the Bouc-Wen restoring force into eq (16) from its
    past, x(t) held in the state's stop; the backlash (eq 1) on x(t) with the widths
    c + dc tau(t), tau(t) = (t0 + t) / time_scale, from y(0) = y_prev; then compliance, the
    dynamic (Dahl) friction (driven by x, u or f), the extra plays (at rest on x_past[0]), creep (at rest on y_prev),
    the output offset and drift, the sensor's clip and the quantiser."""
    p = {name: [float(v) for v in params] for name, params in effects}
    known = {
        "dead_time", "saturation", "friction", "stick_slip", "feedback_hysteresis", "width_drift", "compliance",
        "dynamic_friction", "hysteresis_memory", "creep", "output_offset", "quantization", "state_saturation",
        "sensor_saturation",
    }  # fmt: skip
    if set(p) - known:
        raise ValueError(
            f"no reference for {sorted(set(p) - known)}: add each effect's function here, from its definition, and its place below"
        )
    tau = (t0 + np.arange(len(u), dtype=np.float64)) / time_scale
    v = dead_time(u, int(p["dead_time"][0])) if "dead_time" in p else u
    v = saturation(v, *p["saturation"]) if "saturation" in p else v
    fh = p.get("feedback_hysteresis", (0.0, 0.0, 0.0, 0.0))
    restoring = bouc_wen(*fh) if fh[0] != 0.0 or fh[3] != 0.0 else None
    lo, hi = p.get("state_saturation", (-math.inf, math.inf))
    if "stick_slip" in p:
        f_c, f_v, f_s, v_s = p["stick_slip"]
        x = linear_with_stick_slip(a, b, v, f_c, f_v, f_s, v_s, u_past, x_past, restoring, stop=(lo, hi))
    else:
        f_c, f_v = p.get("friction", (0.0, 0.0))
        x = linear_with_friction(a, b, v, f_c, f_v, u_past, x_past, restoring, stop=(lo, hi))
    x0 = float(x_past[0]) if len(x_past) else 0.0
    dc_l, dc_r = p.get("width_drift", (0.0, 0.0))
    left = branch(m_left, x + width_drift(c_left, dc_l, tau))
    right = branch(m_right, x - width_drift(c_right, dc_r, tau))
    y = backlash(left, right, y_prev)
    f = y  # the backlash's output, the load's motion
    if "compliance" in p and p["compliance"][0] != 0.0:
        y = compliance(y, *p["compliance"], f0=y_prev)
    if "dynamic_friction" in p and p["dynamic_friction"][0] != 0.0:
        k_f, z_s, lam, *source = p["dynamic_friction"]
        if source and source[0] == 1.0:  # driven by the measured input, u(-1) the latest past input
            y = dahl_friction(y, np.asarray(u, dtype=np.float64), k_f, z_s, lam, q0=float(u_past[0]) if len(u_past) else 0.0)
        elif source and source[0] == 2.0:  # driven by the backlash's output, f(-1) its memory
            y = dahl_friction(y, f, k_f, z_s, lam, q0=y_prev)
        else:
            y = dahl_friction(y, x, k_f, z_s, lam, q0=x0)
    if "hysteresis_memory" in p:
        hm = p["hysteresis_memory"]
        y = plays(y, x, list(zip(hm[0::2], hm[1::2])), x0)
    if "creep" in p:
        cr = p["creep"]
        y = creep(y, [(g, log_t) for g, log_t in zip(cr[0::2], cr[1::2]) if g != 0.0], y_prev)
    if "output_offset" in p:
        y = output_offset(y, *p["output_offset"], tau)
    if "sensor_saturation" in p:
        y = saturation(y, *p["sensor_saturation"])
    if "quantization" in p:
        y = quantiser(y, p["quantization"][0])
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(x), y, np.nan)  # a diverged x (eq (1) would hold on NaN)


def ar_prediction(residual: Array, phi: Sequence[float]) -> Array:
    """One-step prediction of an AR process, sum_k phi_k r(t - k), 0 before the record."""
    r, out = residual.tolist(), np.empty(len(residual))
    for t in range(len(r)):
        acc = 0.0
        for k, c in enumerate(phi, 1):
            acc += float(c) * r[t - k] if t >= k else 0.0
        out[t] = acc
    return out
