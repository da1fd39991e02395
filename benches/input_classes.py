"""Identification under five classes of excitation (issue 17): random CRLB-identifiable
cascades (and sandwiches) of orders 2 with cubic branches, N = 5000, SNR 50.

The generator is independent of the code under test: it draws its own systems (stable poles
and zeros, monotone cubic branches, dead-band widths c_L, c_R > 0) and simulates them in plain
NumPy (``scipy.signal.lfilter`` for the linear blocks, the backlash by a per-sample loop over
the paper's eq (1)-(6)). backlashid is used only to fit, and, for the comparison and the
Cramér-Rao check, to pack the true system into the package's normalised parameters
(m_L1 = 1, r_1 = 1) through the public API.

Input classes (levels or peaks within about [-1, 1]):

- ``white``: uniform white noise in [-1, 1] (the paper's excitation);
- ``lowpass``: white Gaussian noise through a 4th-order Butterworth low-pass (cut-off 0.03-0.15
  of the sampling frequency), unit std, scaled by 0.6;
- ``multisine``: 10-40 sinusoids with random (Schroeder-free) phases on a random band of
  harmonics of the record, scaled to peak 1;
- ``ramps``: slow random ramps/triangles: straight segments of 20-200 samples between random
  levels in [-1, 1] (as position-controlled drives move);
- ``steps``: step sequences: random levels in [-1, 1] held 20-200 samples.

SNR is the paper's and ``example_data``'s: the square root of the ratio of output and noise
variances, noise std = std(clean output) / SNR (``--snr-power`` reads SNR as the variance ratio
instead). A system is CRLB-identifiable when every parameter's Cramér-Rao standard deviation
at the truth, from the output-error Jacobian on the record (J^T J = R^T R,
``Structure.problem(u, y_clean).oe_factor(theta_true)``), is at most 0.02; draws that fail
(or move the backlash on less than 20 % of samples, or whose branches are not valid on the
data's range) are redrawn and counted.

A fit is "in basin" when max |estimate - truth| < 0.1 over all parameters (m_L1 = r_1 = 1).

    python benches/input_classes.py --systems 30 --seed-base 100000
    python benches/input_classes.py --sandwich --systems 30 --seed-base 100000
    python benches/input_classes.py --systems 10 --seed-base 0 --diagnose   # tuning seeds
"""

from __future__ import annotations

import argparse
import time
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy import signal

import backlashid as bid
from backlashid.identify import Structure

CLASSES = ("white", "lowpass", "multisine", "ramps", "steps")
N = 5000
SNR = 50.0
CRLB_SD = 0.02
BASIN = 0.1
MIN_MOVING = 0.2

# ------------------------------------------------------------------------------------ inputs


def draw_input(rng: np.random.Generator, kind: str, n: int) -> np.ndarray:
    """One input record of class ``kind``."""
    if kind == "white":
        return rng.uniform(-1.0, 1.0, n)
    if kind == "lowpass":
        cut = rng.uniform(0.03, 0.15)
        b, a = signal.butter(4, 2.0 * cut)
        e = rng.standard_normal(n + 500)
        v = signal.lfilter(b, a, e)[500:]
        return 0.6 * v / v.std()
    if kind == "multisine":
        k = int(rng.integers(10, 41))
        lo = int(rng.integers(1, 50))
        hi = int(rng.integers(lo + k, max(lo + k + 1, int(n * rng.uniform(0.02, 0.4)))))
        harmonics = rng.choice(np.arange(lo, hi + 1), size=k, replace=False)
        t = np.arange(n)
        v = np.sum([np.cos(2 * np.pi * h * t / n + rng.uniform(0, 2 * np.pi)) for h in harmonics], axis=0)
        return v / np.max(np.abs(v))
    if kind in ("ramps", "steps"):
        lengths = []
        while sum(lengths) < n:
            lengths.append(int(rng.integers(20, 201)))
        levels = rng.uniform(-1.0, 1.0, len(lengths) + 1)
        if kind == "steps":
            return np.repeat(levels[1:], lengths)[:n]
        pieces = [np.linspace(levels[i], levels[i + 1], m, endpoint=False) for i, m in enumerate(lengths)]
        return np.concatenate(pieces)[:n]
    raise ValueError(kind)


# ------------------------------------------------------------------------- the true systems


@dataclass
class System:
    a: np.ndarray  # x(t) = sum a_i u(t-i) - sum b_j x(t-j)   (eq 16)
    b: np.ndarray
    c_left: float
    c_right: float
    m_left: np.ndarray  # L(x) = sum m_Li (x + c_L)^i          (eq 4)
    m_right: np.ndarray  # R(x) = sum m_Ri (x - c_R)^i         (eq 5)
    r: np.ndarray = field(default_factory=lambda: np.zeros(0))  # w(t) = sum r_i y(t-i) - sum s_j w(t-j)  (eq 29)
    s: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def model(self) -> bid.CascadeModel | bid.SandwichModel:
        """The system through the public API (for packing the truth only)."""
        bl = bid.GeneralBacklash(self.c_left, self.c_right, self.m_left, self.m_right)
        lin = bid.LinearBlock(self.a, self.b)
        if len(self.r):
            return bid.SandwichModel(lin, bl, bid.LinearBlock(self.r, self.s))
        return bid.CascadeModel(lin, bl)


def _stable_den(rng: np.random.Generator) -> np.ndarray:
    """Second-order denominator 1 + b1 q^-1 + b2 q^-2: a complex pair or two real poles."""
    if rng.random() < 0.5:
        rad, phi = rng.uniform(0.3, 0.9), rng.uniform(0.2, 1.5)
        poles = [rad * np.exp(1j * phi), rad * np.exp(-1j * phi)]
    else:
        poles = list(rng.uniform(-0.5, 0.9, 2))
    return np.real(np.poly(poles))


def _numerator(rng: np.random.Generator, den: np.ndarray, gain: float) -> np.ndarray:
    """a1 q^-1 + a2 q^-2 with its zero -a2/a1 in (-0.7, 0.7) and static gain ``gain``."""
    zero = rng.uniform(-0.7, 0.7)
    a = np.array([1.0, -zero])
    return a * gain * den.sum() / a.sum()


def _polynomial(c: np.ndarray, s: np.ndarray) -> np.ndarray:
    return sum(ci * s ** (i + 1) for i, ci in enumerate(c))


def _slope(c: np.ndarray, s: np.ndarray) -> np.ndarray:
    return sum((i + 1) * ci * s**i for i, ci in enumerate(c))


def _branches(rng: np.random.Generator, x_lo: float, x_hi: float, c_l: float, c_r: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Cubic branches, each increasing on the data's range (slope >= 0.25 m_1 there), the left
    one above the right one (a dead band everywhere on the range)."""
    grid = np.linspace(x_lo, x_hi, 401)
    out = []
    for shift in (c_l, -c_r):
        s = grid + shift
        reach = max(abs(s).max(), 1e-3)
        m1 = rng.uniform(0.5, 1.6)
        c = np.array([m1, m1 * rng.uniform(-0.5, 0.5) / reach, m1 * rng.uniform(-0.35, 0.35) / reach**2])
        if _slope(c, s).min() < 0.25 * m1:
            return None
        out.append(c)
    if np.min(_polynomial(out[0], grid + c_l) - _polynomial(out[1], grid - c_r)) <= 0.0:
        return None
    return out[0], out[1]


def simulate_backlash(x: np.ndarray, c_l: float, c_r: float, m_l: np.ndarray, m_r: np.ndarray) -> np.ndarray:
    """The general backlash by its definition, eq (1)-(6), sample by sample from y(0) = 0:
    on the left branch when x(t) <= z_L (i.e. L(x(t)) <= y(t-1) for an increasing L), on the
    right one when x(t) >= z_R (R(x(t)) >= y(t-1)), else holding."""
    y = np.empty_like(x)
    prev = 0.0
    lefts, rights = _polynomial(m_l, x + c_l).tolist(), _polynomial(m_r, x - c_r).tolist()
    for t, (left, right) in enumerate(zip(lefts, rights)):
        if left <= prev:
            prev = left
        elif right >= prev:
            prev = right
        y[t] = prev
    return y


def simulate(sysm: System, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(x, clean output) from rest: every signal is 0 before the first sample."""
    x = signal.lfilter(np.r_[0.0, sysm.a], np.r_[1.0, sysm.b], u)
    y = simulate_backlash(x, sysm.c_left, sysm.c_right, sysm.m_left, sysm.m_right)
    if len(sysm.r):
        y = signal.lfilter(np.r_[0.0, sysm.r], np.r_[1.0, sysm.s], y)
    return x, y


def structure(sandwich: bool) -> Structure:
    return Structure(2, 2, 3, 2, 2) if sandwich else Structure(2, 2, 3)


def crlb_sd(sysm: System, u: np.ndarray, y_clean: np.ndarray, noise_std: float, sandwich: bool) -> np.ndarray:
    """Cramér-Rao standard deviations of the packed parameters at the truth (output error)."""
    st = structure(sandwich)
    theta = st.pack(sysm.model())
    r_aug, _cost = st.problem(u, y_clean).oe_factor(theta)
    r = np.asarray(r_aug)[:-1, :-1]
    try:
        inv = np.linalg.inv(r)
    except np.linalg.LinAlgError:
        return np.full(st.size, np.inf)
    return noise_std * np.sqrt(np.sum(inv * inv, axis=1))


@dataclass
class Case:
    kind: str
    seed: int
    system: System
    u: np.ndarray
    clean: np.ndarray
    noisy: np.ndarray
    rejected: int
    crlb_max: float


def draw_case(kind: str, seed: int, sandwich: bool, n: int = N, snr: float = SNR, snr_power: bool = False) -> Case:
    """A CRLB-identifiable system and its record: draw until one passes."""
    rng = np.random.default_rng([seed, CLASSES.index(kind), int(sandwich)])
    rejected = 0
    while True:
        u = draw_input(rng, kind, n)
        den = _stable_den(rng)
        a = _numerator(rng, den, rng.uniform(0.8, 1.5))
        x = signal.lfilter(np.r_[0.0, a], den, u)
        sx = float(x.std())
        c_l, c_r = rng.uniform(0.1, 0.6, 2) * sx
        drawn = _branches(rng, float(x.min()), float(x.max()), c_l, c_r)
        if drawn is None:
            rejected += 1
            continue
        r = s = np.zeros(0)
        if sandwich:
            s_den = _stable_den(rng)
            r = np.array([1.0, rng.uniform(-0.6, 0.6)])
            s = s_den[1:]
        sysm = System(a, den[1:], float(c_l), float(c_r), drawn[0], drawn[1], r, s)
        y_bl = simulate_backlash(x, sysm.c_left, sysm.c_right, sysm.m_left, sysm.m_right)
        moving = np.mean(np.abs(np.diff(np.r_[0.0, y_bl])) > 0)
        _, clean = simulate(sysm, u)
        sd = float(np.std(clean)) / (np.sqrt(snr) if snr_power else snr)
        if moving < MIN_MOVING:
            rejected += 1
            continue
        crlb = crlb_sd(sysm, u, clean, sd, sandwich)
        if not np.all(crlb <= CRLB_SD):
            rejected += 1
            continue
        noisy = clean + sd * rng.standard_normal(n)
        return Case(kind, seed, sysm, u, clean, noisy, rejected, float(crlb.max()))


# ------------------------------------------------------------------------------------ fits


@dataclass
class Outcome:
    kind: str
    seed: int
    max_error: float
    seconds: float
    raised: str | None
    note: str


def fit_case(case: Case, sandwich: bool, diagnose: bool = False) -> Outcome:
    fit = bid.fit_sandwich if sandwich else bid.fit_cascade
    truth = case.system.model()
    t0 = time.perf_counter()
    raised, note, err = None, "", np.inf
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            res = fit(case.u, case.noisy)
            err = max(abs(e) for e in res.errors(truth).values())
            note = f"{res.reason}/{res.iterations} it, LM {res.refinement_steps} ({res.refinement_converged})"
        except bid.BacklashIdError as exc:
            raised = f"{type(exc).__name__}: {exc}"
            best = getattr(exc, "best", None)
            if best is not None:
                err = float(np.max(np.abs(best.theta - structure(sandwich).pack(truth))))
    seconds = time.perf_counter() - t0
    if diagnose and not err < BASIN:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            note += "; " + _diagnosis(case, sandwich, res if raised is None else None)
    return Outcome(case.kind, case.seed, err, seconds, raised, note)


def _diagnosis(case: Case, sandwich: bool, res: bid.FitResult | None) -> str:
    """Why a fit missed: the cost at the estimate vs. at LM started from the truth."""
    st = structure(sandwich)
    theta_true = st.pack(case.system.model())
    prob = st.problem(case.u, case.noisy)
    parts = []
    try:
        oracle = bid.identify.levenberg_marquardt(prob, theta_true)
        parts.append(f"truth-LM cost {oracle.cost:.4g} err {np.max(np.abs(oracle.theta - theta_true)):.3f}")
    except bid.BacklashIdError as exc:
        parts.append(f"truth-LM raised {exc}")
    if res is not None:
        parts.append(f"estimate cost {prob.cost(res.theta):.4g}")
        try:
            it = bid.fit_sandwich(case.u, case.noisy, refine=False) if sandwich else bid.fit_cascade(case.u, case.noisy, refine=False)
            parts.append(f"iterations alone err {max(abs(e) for e in it.errors(case.system.model()).values()):.3f}")
        except bid.BacklashIdError as exc:
            parts.append(f"iterations alone raised {type(exc).__name__}")
    return ", ".join(parts)


class Baseline:
    """Fits by another checkout of backlashid (``--baseline DIR``, e.g. main's python/), in a
    worker process, case by case alternating with this one's, so that the two are timed on
    the same machine load. The worker returns theta (or the exception) and the time."""

    WORKER = (
        "import pickle, sys, time, warnings\n"
        "import backlashid as bid\n"
        "warnings.simplefilter('ignore')\n"
        "while True:\n"
        "    try:\n"
        "        u, y, sandwich = pickle.load(sys.stdin.buffer)\n"
        "    except EOFError:\n"
        "        break\n"
        "    t0 = time.perf_counter()\n"
        "    try:\n"
        "        out = ((bid.fit_sandwich if sandwich else bid.fit_cascade)(u, y).theta, None)\n"
        "    except bid.BacklashIdError as exc:\n"
        "        best = getattr(exc, 'best', None)\n"
        "        out = (None if best is None else best.theta, f'{type(exc).__name__}: {exc}')\n"
        "    pickle.dump((out, time.perf_counter() - t0), sys.stdout.buffer)\n"
        "    sys.stdout.buffer.flush()\n"
    )

    def __init__(self, path: str) -> None:
        import os
        import subprocess
        import sys

        env = dict(os.environ, PYTHONPATH=path)
        self.proc = subprocess.Popen([sys.executable, "-c", self.WORKER], stdin=subprocess.PIPE, stdout=subprocess.PIPE, env=env)

    def fit(self, case: Case, sandwich: bool) -> Outcome:
        import pickle

        assert self.proc.stdin is not None and self.proc.stdout is not None
        pickle.dump((case.u, case.noisy, sandwich), self.proc.stdin)
        self.proc.stdin.flush()
        (theta, raised), seconds = pickle.load(self.proc.stdout)
        truth = structure(sandwich).pack(case.system.model())
        err = float(np.max(np.abs(theta - truth))) if theta is not None else np.inf
        return Outcome(case.kind, case.seed, err, seconds, raised, "")

    def close(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.close()
        self.proc.wait()


def _row(kind: str, outcomes: list[Outcome], rejected: int) -> str:
    inb = sum(o.max_error < BASIN for o in outcomes)
    raised = sum(o.raised is not None for o in outcomes)
    times = [o.seconds for o in outcomes]
    errs = [o.max_error for o in outcomes]
    return (f"{kind:<10}{inb:>5}/{len(outcomes):<4}{raised:>8}{np.median(times):>10.2f}{np.max(times):>8.2f}"
            f"{rejected:>10}{np.median(errs):>12.3g}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--systems", type=int, default=30, help="systems per input class")
    ap.add_argument("--seed-base", type=int, default=100_000, help="first seed (tuning used 0..999)")
    ap.add_argument("--classes", default=",".join(CLASSES))
    ap.add_argument("--sandwich", action="store_true", help="sandwiches (fit_sandwich) instead of cascades")
    ap.add_argument("--snr-power", action="store_true", help="read SNR as var(clean)/var(noise)")
    ap.add_argument("--diagnose", action="store_true", help="explain every miss (slower)")
    ap.add_argument("--verbose", action="store_true", help="one line per fit")
    ap.add_argument("--baseline", metavar="DIR", help="also fit every case with the backlashid found in DIR "
                    "(e.g. /work/main/python), alternating, and print its rows beside")
    args = ap.parse_args()
    kinds = args.classes.split(",")
    baseline = Baseline(args.baseline) if args.baseline else None
    print(f"{'sandwiches' if args.sandwich else 'cascades'}, N = {N}, SNR {SNR:g} "
          f"({'power' if args.snr_power else 'amplitude'}), seeds {args.seed_base}..{args.seed_base + args.systems - 1}")
    head = f"{'class':<10}{'in basin':>10}{'raised':>8}{'median s':>10}{'max s':>8}{'rejected':>10}{'median err':>12}"
    print(head + ("   | baseline: in basin, raised, median s, max s" if baseline else ""))
    for kind in kinds:
        outcomes, before, rejected = [], [], 0
        for seed in range(args.seed_base, args.seed_base + args.systems):
            case = draw_case(kind, seed, args.sandwich, snr_power=args.snr_power)
            rejected += case.rejected
            out = fit_case(case, args.sandwich, args.diagnose)
            outcomes.append(out)
            if baseline is not None:
                before.append(baseline.fit(case, args.sandwich))
            if args.verbose or (args.diagnose and not out.max_error < BASIN):
                print(f"  {kind} seed {seed}: err {out.max_error:.3g} {out.seconds:.2f} s crlb {case.crlb_max:.4f} "
                      f"{out.raised or ''} {out.note}", flush=True)
        row = _row(kind, outcomes, rejected)
        if baseline is not None:
            b = before
            row += (f"   | {sum(o.max_error < BASIN for o in b):>3}/{len(b)} {sum(o.raised is not None for o in b):>3} "
                    f"{np.median([o.seconds for o in b]):>6.2f} {np.max([o.seconds for o in b]):>6.2f}")
        print(row, flush=True)
    if baseline is not None:
        baseline.close()


if __name__ == "__main__":
    main()
