"""Structure-selection benchmark of issue 17: does ``select_structure`` pick the true linear
orders (na, nb) and branch degree n of random cascades?

The systems are drawn and simulated here, independently of the package (NumPy, SciPy's
``lfilter`` for the linear block (eq 16) and a per-sample loop of the general backlash written
from the paper's definition, eq 1-13, with the case order of eq 1: left branch first, then the
right, else hold). The package only fits them, with ``select_structure``'s defaults: the grid
na, nb in 1..3 and degree 1..4 (36 candidates), the last 30 % held out.

One system per seed (``numpy.random.default_rng(seed)``):

- true orders na, nb and degree n, each uniform on {1, 2, 3};
- nb stable poles (with probability 1/2 a complex pair when nb >= 2, radius U[0.3, 0.85],
  angle U[0.3, 2.5] rad; real poles U[0.3, 0.85] with a random sign) and na - 1 zeros (a
  complex pair with probability 1/2 when na >= 3, radius U[0.3, 1.2]; real zeros U[0.2, 1.2]
  with a random sign); a = poly(zeros), b = poly(poles)[1:], a scaled so that std(x) = 1;
- input (``--input``): white, uniform on [-1, 1] (default), or a random-phase multisine with
  equal amplitudes on every frequency k / N, k = 1..0.4 N (one period of N samples), scaled to
  a peak of 1; N = 5000 samples;
- branches L(x) = sum m_Li (x + c_L)^i, R(x) = sum m_Ri (x - c_R)^i (eq 4-5) with m_L1 = 1,
  m_R1 U[0.6, 1.5], c_L, c_R U[0.1, 0.5]; degree 2: m_L2, m_R2 = +-U[0.04, 0.1]; degree 3:
  m_2 U[-0.08, 0.08], m_3 U[0.02, 0.06];
- output noise: white Gaussian, std = std(clean y) / SNR, SNR 50 (``--snr``; an amplitude ratio).

A draw is rejected, and drawn again from the same generator, by these rules, fixed before any
run (the counts are printed): the true structure must be the minimal one and every part of it
must show in the data.

- ``top_b``: ``abs(b_nb) < 0.05`` (a denominator whose top coefficient is tiny is effectively of
  lower order);
- ``top_a``: ``abs(a_na) < 0.1 max(abs(a))`` (likewise for the numerator);
- ``cancel``: a pole and a zero closer than 0.25 (near pole-zero cancellation: not minimal);
- ``monotone``: a branch's slope below 0.2 m_1 somewhere on the visited range of x (from the
  smallest to the largest x(t), widened by the widths);
- ``cross``: L(x) - R(x) < 0.05 somewhere on the visited range (branches that touch or cross);
- ``top_degree``: for n >= 2, the top term m_n (x +- c)^n of a branch varies over the visited
  range by less than 5 % of the branch's own variation (the degree would not show).

Printed: the pick rate of the orders, of the degree and of both, the misses with their chosen
structure, the rejections per rule, and the time per selection. ``--json`` writes every
system's truth, choice and table, from which other decision rules are re-scored
(``--rescore FILE`` prints the pick rates of a few alternative rules on a saved run).

    python benches/select_structure.py --systems 50 --seed-base 0 --json tune.json
    python benches/select_structure.py --systems 50 --seed-base 100000 --json fresh.json
"""

from __future__ import annotations

import argparse
import json
import math
import time
from typing import Any

import numpy as np
from scipy.signal import lfilter

N = 5000
SNR = 50.0
TARGET = 0.90


# -- the independent generator ---------------------------------------------------------------------


def _real(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi) * rng.choice([-1.0, 1.0]))


def _roots(rng: np.random.Generator, count: int, lo: float, hi: float, pair_from: int) -> list[complex]:
    roots: list[complex] = []
    if count >= pair_from and rng.random() < 0.5:
        r, phi = rng.uniform(lo, hi), rng.uniform(0.3, 2.5)
        roots += [r * np.exp(1j * phi), r * np.exp(-1j * phi)]
    while len(roots) < count:
        roots.append(complex(_real(rng, lo, hi)))
    return roots


def branch(m: np.ndarray, shift: float, x: np.ndarray) -> np.ndarray:
    """sum_i m_i (x + shift)^i, i = 1..n (eq 4 with shift c_L, eq 5 with shift -c_R)."""
    xi = x + shift
    return sum(mi * xi ** (i + 1) for i, mi in enumerate(m))


def play(x: np.ndarray, m_l: np.ndarray, c_l: float, m_r: np.ndarray, c_r: float) -> np.ndarray:
    """The general backlash of eq 1-13, sample by sample from y(0) = 0: f1 = h[L(x) - y(t-1)]
    (eq 12), f2 = h[y(t-1) - R(x)] (eq 13) with h(s) = 1 for s <= 0 (eq 11); L if f1, else R
    if f2, else hold y(t-1) (the case order of eq 1)."""
    left, right = branch(m_l, c_l, x), branch(m_r, -c_r, x)
    y = np.empty_like(x)
    prev = 0.0
    for t in range(x.size):
        if left[t] - prev <= 0.0:
            prev = left[t]
        elif prev - right[t] <= 0.0:
            prev = right[t]
        y[t] = prev
    return y


def _branch_coefficients(rng: np.random.Generator, n: int, m1: float) -> np.ndarray:
    if n == 1:
        return np.array([m1])
    if n == 2:
        return np.array([m1, _real(rng, 0.04, 0.1)])
    return np.array([m1, rng.uniform(-0.08, 0.08), rng.uniform(0.02, 0.06)])


def _rejected(sys: dict[str, Any], x: np.ndarray) -> str | None:
    """The first rejection rule the draw breaks (module docstring), or None."""
    a, b, poles, zeros = sys["a"], sys["b"], sys["poles"], sys["zeros"]
    if abs(b[-1]) < 0.05:
        return "top_b"
    if abs(a[-1]) < 0.1 * np.max(np.abs(a)):
        return "top_a"
    if zeros and min(abs(p - z) for p in poles for z in zeros) < 0.25:
        return "cancel"
    lo, hi = float(x.min()) - max(sys["c_L"], sys["c_R"]), float(x.max()) + max(sys["c_L"], sys["c_R"])
    grid = np.linspace(lo, hi, 2001)
    for m, shift in ((sys["m_L"], sys["c_L"]), (sys["m_R"], -sys["c_R"])):
        slope = sum((i + 1) * mi * (grid + shift) ** i for i, mi in enumerate(m))
        if slope.min() < 0.2 * m[0]:
            return "monotone"
    if np.min(branch(sys["m_L"], sys["c_L"], grid) - branch(sys["m_R"], -sys["c_R"], grid)) < 0.05:
        return "cross"
    n = len(sys["m_L"])
    if n >= 2:
        for m, shift in ((sys["m_L"], sys["c_L"]), (sys["m_R"], -sys["c_R"])):
            top = m[-1] * (grid + shift) ** n
            if np.ptp(top) < 0.05 * np.ptp(branch(m, shift, grid)):
                return "top_degree"
    return None


def make_input(rng: np.random.Generator, kind: str) -> np.ndarray:
    """The input signal: 'white' (uniform on [-1, 1]) or 'multisine' (module docstring)."""
    if kind == "white":
        return rng.uniform(-1.0, 1.0, N)
    lines = np.arange(1, int(0.4 * N) + 1)
    phases = rng.uniform(0.0, 2.0 * np.pi, lines.size)
    t = np.arange(N)
    u = np.cos(2.0 * np.pi * np.outer(t, lines) / N + phases).sum(axis=1)
    return u / np.max(np.abs(u))


def draw_system(seed: int, rejections: dict[str, int], input_kind: str = "white", snr: float = SNR) -> tuple[dict[str, Any], np.ndarray, np.ndarray]:
    """One accepted random cascade and its record (u, noisy y); rejected draws are counted."""
    rng = np.random.default_rng(seed)
    u = make_input(rng, input_kind)
    while True:
        na, nb, n = (int(v) for v in rng.integers(1, 4, size=3))
        poles = _roots(rng, nb, 0.3, 0.85, pair_from=2)
        zeros = _roots(rng, na - 1, 0.2, 1.2, pair_from=2)
        a = np.real(np.poly(zeros)) if zeros else np.array([1.0])
        b = np.real(np.poly(poles))[1:]
        x = lfilter(np.concatenate([[0.0], a]), np.concatenate([[1.0], b]), u)
        scale = 1.0 / np.std(x)
        a, x = a * scale, x * scale
        m_r1 = rng.uniform(0.6, 1.5)
        sys = {
            "na": na, "nb": nb, "degree": n, "a": a, "b": b, "poles": poles, "zeros": zeros,
            "c_L": float(rng.uniform(0.1, 0.5)), "c_R": float(rng.uniform(0.1, 0.5)),
            "m_L": _branch_coefficients(rng, n, 1.0), "m_R": _branch_coefficients(rng, n, m_r1),
        }  # fmt: skip
        reason = _rejected(sys, x)
        if reason is None:
            break
        rejections[reason] = rejections.get(reason, 0) + 1
    y = play(x, sys["m_L"], sys["c_L"], sys["m_R"], sys["c_R"])
    noisy = y + rng.normal(0.0, np.std(y) / snr, N)
    return sys, u, noisy


# -- the benchmark ---------------------------------------------------------------------------------


def run(seed: int, rejections: dict[str, int], input_kind: str = "white", snr: float = SNR) -> dict[str, Any]:
    import backlashid as bid

    sys, u, y = draw_system(seed, rejections, input_kind, snr)
    truth = (sys["na"], sys["nb"], sys["degree"])
    t0 = time.perf_counter()
    try:
        sel = bid.select_structure(u, y)
    except bid.BacklashIdError as exc:
        return {"seed": seed, "truth": truth, "chosen": None, "error": f"{type(exc).__name__}: {exc}", "seconds": time.perf_counter() - t0}
    s = sel.structure
    return {
        "seed": seed, "truth": truth, "chosen": (s.na, s.nb, s.degree), "seconds": sel.seconds,
        "rows": [{k: r[k] for k in ("na", "nb", "degree", "parameters", "estimation_rmse", "validation_rmse", "bic", "raised")} for r in sel.rows],
        "system": {k: (np.asarray(v).real.tolist() if k in ("a", "b", "m_L", "m_R") else v) for k, v in sys.items() if k not in ("poles", "zeros")},
        "poles": [[p.real, p.imag] for p in sys["poles"]], "zeros": [[z.real, z.imag] for z in sys["zeros"]],
    }  # fmt: skip


def _rates(results: list[dict[str, Any]], chosen_key: str = "chosen") -> tuple[float, float, float]:
    n = len(results)
    orders = sum(1 for r in results if r[chosen_key] is not None and tuple(r[chosen_key][:2]) == tuple(r["truth"][:2]))
    degree = sum(1 for r in results if r[chosen_key] is not None and r[chosen_key][2] == r["truth"][2])
    both = sum(1 for r in results if r[chosen_key] is not None and tuple(r[chosen_key]) == tuple(r["truth"]))
    return orders / n, degree / n, both / n


def _rule(rows: list[dict[str, Any]], name: str, tol: float) -> tuple[int, int, int] | None:
    ok = [r for r in rows if not r["raised"] and r["validation_rmse"] is not None and math.isfinite(r["validation_rmse"])]
    if not ok:
        return None
    best = min(r["validation_rmse"] for r in ok)
    band = [r for r in ok if r["validation_rmse"] <= (1 + tol) * best]
    if name == "band+bic":
        r = min(band, key=lambda r: (r["bic"], r["parameters"]))
    elif name == "band+fewest":
        r = min(band, key=lambda r: (r["parameters"], r["bic"]))
    elif name == "bic":
        r = min(ok, key=lambda r: (r["bic"], r["parameters"]))
    else:  # "validation": the smallest validation error alone
        r = min(ok, key=lambda r: r["validation_rmse"])
    return (r["na"], r["nb"], r["degree"])


def rescore(path: str) -> None:
    """Pick rates of alternative decision rules on a saved run (for tuning)."""
    results = [r for r in json.load(open(path))["results"] if r.get("rows")]
    print(f"{len(results)} systems from {path}: pick rates (orders, degree, both)")
    for name in ("band+bic", "band+fewest"):
        for tol in (0.0, 0.005, 0.01, 0.02, 0.05, 0.1):
            for r in results:
                r["alt"] = _rule(r["rows"], name, tol)
            print(f"  {name:<12} tolerance {tol:<6}" + "  ".join(f"{v:6.1%}" for v in _rates(results, "alt")))
    for name in ("bic", "validation"):
        for r in results:
            r["alt"] = _rule(r["rows"], name, 0.0)
        print(f"  {name:<25}" + "  ".join(f"{v:6.1%}" for v in _rates(results, "alt")))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--systems", type=int, default=50, help="number of random systems")
    ap.add_argument("--seed-base", type=int, default=0, help="system k uses seed seed-base + k (tuning: 0..999)")
    ap.add_argument("--input", dest="input_kind", choices=["white", "multisine"], default="white", help="the input signal")
    ap.add_argument("--snr", type=float, default=SNR, help="std(clean y) / noise std")
    ap.add_argument("--json", help="write every system's truth, choice and table here")
    ap.add_argument("--rescore", metavar="FILE", help="only print alternative rules' pick rates on a saved --json run")
    args = ap.parse_args()
    if args.rescore:
        rescore(args.rescore)
        return
    rejections: dict[str, int] = {}
    results = []
    t_all = time.perf_counter()
    for k in range(args.systems):
        seed = args.seed_base + k
        r = run(seed, rejections, args.input_kind, args.snr)
        results.append(r)
        mark = "ok  " if r["chosen"] is not None and tuple(r["chosen"]) == tuple(r["truth"]) else "MISS"
        print(f"{mark} seed {seed}: true (na, nb, n) = {tuple(r['truth'])}, chosen {r['chosen'] if r['chosen'] else r['error']}"
              f"  ({r['seconds']:.1f} s)", flush=True)
    orders, degree, both = _rates(results)
    seconds = np.array([r["seconds"] for r in results])
    print(f"\n{args.systems} systems, seeds {args.seed_base}..{args.seed_base + args.systems - 1}, N = {N} ({args.input_kind} input), SNR {args.snr:g}")
    print(f"pick rate: orders {orders:.1%}, degree {degree:.1%}, both {both:.1%} (target >= {TARGET:.0%} both)")
    print(f"rejected draws: {sum(rejections.values())} ({', '.join(f'{k} {v}' for k, v in sorted(rejections.items())) or 'none'})")
    print(f"time per selection: mean {seconds.mean():.2f} s, median {np.median(seconds):.2f} s, max {seconds.max():.2f} s"
          f" (36 candidate fits + 1 refit; total {time.perf_counter() - t_all:.0f} s)")
    print("PASS" if both >= TARGET else "FAIL")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"input": args.input_kind, "snr": args.snr, "seed_base": args.seed_base, "systems": args.systems, "rejections": rejections, "results": results}, f)
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()
