"""Records cut from the middle of a run, fitted with ``initial_state="estimate"`` (issue 17).

On each seed a run of the paper's Example 1 (cascade) or Example 2 (sandwich) is simulated from
rest on white uniform input in [-1, 1], and only the N samples after a random cut (100-600
samples in) are kept: the record starts mid-motion, with the linear blocks' past and the
backlash memory unknown. ``fit_cascade`` / ``fit_sandwich`` fit it whole (no warm-up) with
``initial_state="estimate"`` and, for comparison, assuming rest. Printed per example: on how
many seeds every parameter is within 3 standard errors of the truth, the largest |error| / se
of each seed, and what an exactly Gaussian estimator would give (each parameter outside 3
standard errors with probability 0.27 %, so "every one of p parameters on every one of 20
seeds" holds with probability 0.9973 ** (20 p)).

The generator is independent of the code under test: the examples' coefficients typed from the
paper (Section 5), the linear blocks by ``scipy.signal.lfilter`` and the backlash by its own
per-sample loop over eq (1)-(13). backlashid only fits and packs the true model for the
comparison.

    python benches/initial_state.py                      # 20 seeds each, from seed 300000
    python benches/initial_state.py --seeds 150 --seed-base 500000   # also checks the standard errors
"""

from __future__ import annotations

import argparse
import math
import time
import warnings

import numpy as np
from scipy.signal import lfilter

import backlashid as bid

N = 1000
SNR = 50.0  # noise std = std(clean) / SNR

# Example 1 (cascade) and Example 2 (sandwich) of the paper: x(t) = sum a_i u(t-i) - sum b_i x(t-i)
EXAMPLE1 = {"a": [0.7, 0.5], "b": [-0.2, 0.35], "c_l": 0.6, "c_r": 0.5, "m_l": [1.0, -0.3, 0.3], "m_r": [1.5, 0.4, 0.2]}
EXAMPLE2 = {
    "a": [0.8, 0.2], "b": [0.2, -0.2], "c_l": 0.4, "c_r": 0.5, "m_l": [1.0, 0.1, 0.3], "m_r": [0.75, 0.2, 0.6],
    "r": [1.0, 0.15], "s": [-0.2, 0.35],
}


def branch(m: list[float], shift: float, x: np.ndarray) -> np.ndarray:
    """sum_i m_i (x + shift)^i (eq 4 with shift c_L, eq 5 with shift -c_R)."""
    return sum(mi * (x + shift) ** (i + 1) for i, mi in enumerate(m))


def play(x: np.ndarray, sysm: dict) -> np.ndarray:
    """The general backlash (eq 1-13) from y(0) = 0: the left branch when it is at or below
    y(t-1) (f1), the right branch when it is at or above (f2), else hold."""
    left, right = branch(sysm["m_l"], sysm["c_l"], x), branch(sysm["m_r"], -sysm["c_r"], x)
    y, prev = np.empty_like(x), 0.0
    for t in range(x.size):
        if left[t] <= prev:
            prev = left[t]
        elif right[t] >= prev:
            prev = right[t]
        y[t] = prev
    return y


def simulate(sysm: dict, u: np.ndarray) -> np.ndarray:
    y = play(lfilter([0.0, *sysm["a"]], [1.0, *sysm["b"]], u), sysm)
    if "r" in sysm:
        y = lfilter([0.0, *sysm["r"]], [1.0, *sysm["s"]], y)
    return y


def cut_record(sysm: dict, seed: int) -> tuple[np.ndarray, np.ndarray, int]:
    rng = np.random.default_rng(seed)
    cut = int(rng.integers(100, 601))
    u = rng.uniform(-1.0, 1.0, cut + N)
    clean = simulate(sysm, u)[cut:]
    return u[cut:], clean + rng.standard_normal(N) * np.std(clean) / SNR, cut


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=20)
    parser.add_argument("--seed-base", type=int, default=300_000)
    args = parser.parse_args()
    warnings.simplefilter("ignore", bid.FitWarning)
    print(f"records of N = {N} cut mid-run, SNR {SNR:g} (noise std = std(clean) / SNR), white uniform input, "
          f"seeds {args.seed_base}..{args.seed_base + args.seeds - 1}")
    for name, sysm, truth, fit in (
        ("Example 1 (cascade)", EXAMPLE1, bid.example1(), bid.fit_cascade),
        ("Example 2 (sandwich)", EXAMPLE2, bid.example2(), bid.fit_sandwich),
    ):
        worst, worst_rest, seconds, raised, errors, ses = [], [], [], [], [], []
        for seed in range(args.seed_base, args.seed_base + args.seeds):
            u, y, _cut = cut_record(sysm, seed)
            start = time.perf_counter()
            try:
                est = fit(u, y, initial_state="estimate")
            except bid.BacklashIdError as exc:
                raised.append((seed, f"{type(exc).__name__}: {exc}"))
                continue
            seconds.append(time.perf_counter() - start)
            err, se = est.errors(truth), est.standard_errors
            worst.append(max(abs(err[k]) / se[k] for k in err))
            errors.append([err[k] for k in est.names])
            ses.append([se[k] for k in est.names])
            try:
                worst_rest.append(max(abs(v) for v in fit(u, y).errors(truth).values()))
            except bid.BacklashIdError:
                worst_rest.append(math.inf)
        p = len(bid.identify.Structure(2, 2, 3, *((2, 2) if "r" in sysm else ())).names)
        within = sum(w < 3.0 for w in worst)
        print(f"\n{name}: {p} parameters")
        print(f"  every parameter within 3 standard errors on {within} of {args.seeds} seeds "
              f"(an exactly Gaussian estimator: all {args.seeds} with probability {0.9973 ** (args.seeds * p):.2f}, "
              f"expected {args.seeds * 0.9973 ** p:.1f} seeds)")
        print(f"  largest |error| / se per seed: {' '.join(f'{w:.1f}' for w in worst)}")
        print(f"  raised: {len(raised)}" + "".join(f"\n    seed {s}: {m}" for s, m in raised))
        if len(errors) >= 50:  # enough seeds to check the standard errors themselves
            ratio = np.std(errors, axis=0) / np.median(ses, axis=0)
            print(f"  spread of the estimates over the seeds / median reported standard error: "
                  f"{' '.join(f'{k} {r:.2f}' for k, r in zip(est.names, ratio))}")
        print(f"  median fit time {np.median(seconds):.2f} s; the fit assuming rest: median of the largest |error| "
              f"{np.median(worst_rest):.3f}")


if __name__ == "__main__":
    main()
