"""Wiener-Hammerstein fit on the SYSID 2009 benchmark: the package's fit against today's path.

Data: /work/shared/data/wiener_hammerstein_2009/wh2009.npz (or --data), the loader split:
train = [5200:105200], test = [105200:184000]. The figure is the RMS of the free-run
simulation error on test[50:] (the model simulated from rest on the test input alone, the
first 50 samples only initialising its state), in mV.

    python benches/wiener_hammerstein.py                  # the package's fit, degree 29, lag-0 term in G2, nb = ns = 3
    python benches/wiener_hammerstein.py --old            # and today's path (before issue 16) in the same run
    python benches/wiener_hammerstein.py --old --repeats 2   # each twice, interleaved, best time
    python benches/wiener_hammerstein.py --degree 25 --lag0 none   # the structure of the earlier default
    python benches/wiener_hammerstein.py --feedthrough --no-output-feedthrough   # a lag-0 term in G1 only
    python benches/wiener_hammerstein.py --validate       # choose the structure on the estimation data

The default structure (degree 29, a lag-0 term in G2 only: ``output_feedthrough=True``) was
chosen on the estimation data alone (``--validate``: each candidate fitted on train[:80000],
free-run RMSE on train[80000:], the state carried over from the fit's part): degree 25
without lag-0 terms 0.512 mV, degree 25 / 27 with a lag-0 term in G1 0.352 / 0.313 mV,
degree 27 / 29 / 31 with a lag-0 term in G2 0.304 / 0.288 / 0.294 mV (2026-11-24). Beyond the range of x on the estimation data the fitted
f continues along its tangent (``WienerHammersteinFit.x_range``). The split search runs on
10 000 samples (``--split-samples``; the package's default is 20 000): for that structure the
training RMSE is the same (0.2775 against 0.2773 mV), the fit about a fifth faster.

"Old" is a frozen copy of fit_wiener_hammerstein as it was before the one engine (commit
b27a3c5): scipy.signal.lfilter simulations, its own Jacobian, scipy.optimize.least_squares.
It lives here, outside the package, only for the side-by-side comparison; needs scipy. It runs
with today's default settings (degree 25, nb = ns = 3, no lag-0 terms; ``--old-degree``,
``--feedthrough`` change them), whatever structure the new fit has.
"""

from __future__ import annotations

import argparse
import itertools
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.polynomial import chebyshev
from numpy.typing import NDArray
from scipy.optimize import least_squares
from scipy.signal import lfilter

import backlashid as bid
from backlashid.errors import NotConvergedError
from backlashid.identify import wiener_hammerstein_model

DATA = Path("/work/shared/data/wiener_hammerstein_2009/wh2009.npz")
_UNSTABLE = 0.9999
_PENALTY = 10.0


def _delayed(v: NDArray[np.float64], k: int) -> NDArray[np.float64]:
    if k == 0:
        return v
    out = np.zeros_like(v)
    out[k:] = v[:-k]
    return out


def _radius(den: NDArray[np.float64]) -> float:
    return float(np.abs(np.roots(den)).max()) if len(den) > 1 else 0.0


# -- frozen copy of today's path (b27a3c5 python/backlashid/identify/_wiener_hammerstein.py) ------


@dataclass(frozen=True)
class _Param:
    """theta = [a (lags d..nb), b (nb), c_1..c_n (Chebyshev coefficients of f in x / k),
    r (lags d..ns), s (ns)], with f(x) = sum_i c_i (T_i(x / k) - T_i(0)) so that f(0) = 0;
    the first lag d is 0 with feedthrough, else 1."""

    nb: int
    ns: int
    degree: int
    feedthrough: bool = False
    k: float = 1.0

    @property
    def delay(self) -> int:
        return 0 if self.feedthrough else 1

    @property
    def sizes(self) -> list[int]:
        d = self.delay
        return [self.nb + 1 - d, self.nb, self.degree, self.ns + 1 - d, self.ns]

    def numerator(self, coefficients: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.r_[np.zeros(self.delay), coefficients]

    def split(self, theta: NDArray[np.float64]) -> list[NDArray[np.float64]]:
        return np.split(theta, np.cumsum(self.sizes)[:-1])

    def basis(self, x: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """T_i(z) - T_i(0) and d/dx T_i(z), i = 1..n, z = x / k (three-term recurrences)."""
        z = x / self.k
        n = self.degree
        t = np.empty((len(z), n + 1))
        dt = np.empty((len(z), n + 1))
        t[:, 0], dt[:, 0] = 1.0, 0.0
        t[:, 1], dt[:, 1] = z, 1.0
        for i in range(1, n):
            t[:, i + 1] = 2.0 * z * t[:, i] - t[:, i - 1]
            dt[:, i + 1] = 2.0 * t[:, i] + 2.0 * z * dt[:, i] - dt[:, i - 1]
        t0 = chebyshev.chebval(0.0, np.eye(n + 1))  # T_i(0)
        return t[:, 1:] - t0[1:], dt[:, 1:] / self.k

    def stable(self, theta: NDArray[np.float64]) -> bool:
        _, b, _, _, s = self.split(theta)
        return max(_radius(np.r_[1.0, b]), _radius(np.r_[1.0, s])) < _UNSTABLE

    def simulate(self, theta: NDArray[np.float64], u: NDArray[np.float64]) -> tuple[NDArray[np.float64], ...]:
        a, b, c, r, s = self.split(theta)
        x = lfilter(self.numerator(a), np.r_[1.0, b], u)
        basis, dbasis = self.basis(x)
        f = basis @ c
        w = lfilter(self.numerator(r), np.r_[1.0, s], f)
        return x, basis, dbasis, f, w

    def residuals(self, theta: NDArray[np.float64], u: NDArray[np.float64], y: NDArray[np.float64], warmup: int) -> NDArray[np.float64]:
        if not self.stable(theta):
            return np.full(len(y) - warmup, _PENALTY)
        with np.errstate(over="ignore", invalid="ignore"):
            e = (self.simulate(theta, u)[-1] - y)[warmup:]
        return e if np.all(np.isfinite(e)) else np.full(len(y) - warmup, _PENALTY)

    def jacobian(self, theta: NDArray[np.float64], u: NDArray[np.float64], y: NDArray[np.float64], warmup: int) -> NDArray[np.float64]:
        """d w / d theta: G1's sensitivities (filtered by 1/B) scaled by f'(x) and passed
        through G2; f's basis functions through G2; G2's own sensitivities."""
        if not self.stable(theta):
            return np.zeros((len(y) - warmup, len(theta)))
        a, b, c, r, s = self.split(theta)
        x, basis, dbasis, f, w = self.simulate(theta, u)
        d = self.delay
        den1, num2, den2 = np.r_[1.0, b], self.numerator(r), np.r_[1.0, s]
        u_f, x_f = lfilter([1.0], den1, u), lfilter([1.0], den1, x)
        dx = np.column_stack(
            [_delayed(u_f, i) for i in range(d, self.nb + 1)] + [-_delayed(x_f, j) for j in range(1, self.nb + 1)]
        )
        j_g1 = lfilter(num2, den2, dx * (dbasis @ c)[:, None], axis=0)
        j_f = lfilter(num2, den2, basis, axis=0)
        f_f, w_f = lfilter([1.0], den2, f), lfilter([1.0], den2, w)
        j_g2 = np.column_stack(
            [_delayed(f_f, i) for i in range(d, self.ns + 1)] + [-_delayed(w_f, j) for j in range(1, self.ns + 1)]
        )
        return np.hstack([j_g1, j_f, j_g2])[warmup:]

    def fit(self, theta: NDArray[np.float64], u: NDArray[np.float64], y: NDArray[np.float64], warmup: int, max_nfev: int) -> Any:
        return least_squares(
            self.residuals, theta, jac=self.jacobian, args=(u, y, warmup), method="lm", max_nfev=max_nfev,
            ftol=1e-10, xtol=1e-10,
        )

    def monomials(self, c: NDArray[np.float64]) -> NDArray[np.float64]:
        """m_1..m_n of f(x) = sum_i m_i x^i."""
        t0 = chebyshev.chebval(0.0, np.eye(self.degree + 1))
        full = np.r_[-float(c @ t0[1:]), c]  # the constant that makes f(0) = 0
        p = chebyshev.cheb2poly(full)  # in z = x / k
        p = np.r_[p, np.zeros(self.degree + 1 - len(p))]
        return p[1:] / self.k ** np.arange(1, self.degree + 1)


# -- best linear approximation and its splits ----------------------------------------------------


def _best_linear(u: NDArray[np.float64], y: NDArray[np.float64], order: int, delay: int, warmup: int) -> tuple[NDArray[np.float64], NDArray[np.float64], float]:
    """Output-error model num/den of the given order (numerator lags delay..order) plus an
    output offset: an ARX start, then Levenberg-Marquardt on the simulation error."""
    n_num = order + 1 - delay
    cols = [_delayed(u, delay + i) for i in range(n_num)] + [-_delayed(y, j) for j in range(1, order + 1)]
    lag = order + 1
    arx = np.linalg.lstsq(np.column_stack(cols + [np.ones_like(u)])[lag:], y[lag:], rcond=None)[0]
    if _radius(np.r_[1.0, arx[n_num : n_num + order]]) >= _UNSTABLE:  # keep the ARX numerator, damp the poles
        arx[n_num : n_num + order] = np.poly(0.9 * np.exp(1j * np.linspace(0.3, 2.5, order))).real[1:]

    def residuals(th: NDArray[np.float64]) -> NDArray[np.float64]:
        den = np.r_[1.0, th[n_num : n_num + order]]
        if _radius(den) >= _UNSTABLE:
            return np.full(len(y) - warmup, _PENALTY)
        return (lfilter(np.r_[np.zeros(delay), th[:n_num]], den, u) + th[-1] - y)[warmup:]

    th = least_squares(residuals, arx, method="lm").x
    return np.r_[np.zeros(delay), th[:n_num]], np.r_[1.0, th[n_num : n_num + order]], float(th[-1])


def _conjugate_groups(roots: NDArray[np.complex128]) -> list[list[complex]]:
    """Real roots alone, complex roots with their conjugates."""
    left = list(roots)
    groups = []
    while left:
        r = left.pop(0)
        if abs(r.imag) > 1e-9 * max(1.0, abs(r)) and left:
            j = int(np.argmin([abs(q - np.conj(r)) for q in left]))
            groups.append([r, left.pop(j)])
        else:
            groups.append([complex(r.real, 0.0)])
    return groups


def _subsets(roots: NDArray[np.complex128], sizes: range) -> list[tuple[list[complex], list[complex]]]:
    """(chosen, rest) for every choice of whole conjugate groups with a size in ``sizes``."""
    groups = _conjugate_groups(roots)
    out = []
    for m in range(len(groups) + 1):
        for pick in itertools.combinations(range(len(groups)), m):
            chosen = [q for g in pick for q in groups[g]]
            if len(chosen) in sizes:
                out.append((chosen, [q for g in range(len(groups)) if g not in pick for q in groups[g]]))
    return out


def _splits(poles: NDArray[np.complex128], zeros: NDArray[np.complex128], nb: int, ns: int, room: tuple[int, int]) -> list[tuple[list[complex], ...]]:
    """(G1 poles, G2 poles, G1 zeros, G2 zeros) with nb poles in G1, ns in G2, and at most
    nb and ns zeros (n - 1 when the block keeps a one-sample delay). Only when no split keeps
    every zero (e.g. a complex pair when each block has room for one zero) are zeros left out:
    the refinement moves the numerators anyway."""
    whole, partial = [], []
    for p1, p2 in _subsets(poles, range(nb, nb + 1)):
        for z1, rest in _subsets(zeros, range(0, room[0] + 1)):
            if len(rest) <= room[1]:
                whole.append((p1, p2, z1, rest))
                continue
            fits = [z2 for z2, _ in _subsets(np.asarray(rest), range(0, room[1] + 1))]
            most = max(len(z2) for z2 in fits)
            partial += [(p1, p2, z1, z2) for z2 in fits if len(z2) == most]
    return whole or partial


def _theta_from_split(param: _Param, u: NDArray[np.float64], split: tuple[list[complex], ...], gain: float) -> NDArray[np.float64]:
    """G1 = Z1/P1 (lagged to its order) scaled so that max |x| = k, f(x) = x, G2 carries the gain."""
    p1, p2, z1, z2 = split
    d = param.delay
    b, s = np.poly(p1).real, np.poly(p2).real
    a = np.r_[np.zeros(param.nb - d - len(z1)), np.poly(z1).real]
    r = np.r_[np.zeros(param.ns - d - len(z2)), np.poly(z2).real] * gain
    x = lfilter(param.numerator(a), b, u)
    scale = np.max(np.abs(x)) / param.k
    c = np.zeros(param.degree)
    c[0] = param.k  # c_1 T_1(x / k) = x
    return np.r_[a / scale, b[1:], c, r * scale, s[1:]]


def old_fit_wiener_hammerstein(
    u: NDArray[np.float64], y: NDArray[np.float64], *, nb: int = 3, ns: int = 3, degree: int = 20, warmup: int = 100,
    max_iter: int = 200, split_samples: int = 20_000, split_degree: int = 3, split_iter: int = 15, feedthrough: bool = False,
) -> tuple[Any, int]:
    """Today's fit (frozen): (the SandwichModel, evaluations of the final LM)."""
    u_arr, y_arr = np.asarray(u, dtype=np.float64), np.asarray(y, dtype=np.float64)
    delay = 0 if feedthrough else 2
    num, den, offset = _best_linear(u_arr, y_arr, nb + ns, delay, warmup)
    lead = np.trim_zeros(num, "f")
    poles, zeros = np.roots(den), np.roots(lead)

    short = _Param(nb, ns, min(split_degree, degree), feedthrough)
    n_short = min(len(u_arr), max(split_samples, warmup + 10 * (2 * (nb + ns) + short.degree)))
    u_s, y_s = u_arr[:n_short], y_arr[:n_short]
    ranked = []
    room = (nb - short.delay, ns - short.delay)
    for split in _splits(poles, zeros, nb, ns, room):
        theta = _theta_from_split(short, u_s, split, float(lead[0]))
        if not short.stable(theta):
            continue
        res = short.fit(theta, u_s, y_s, warmup, split_iter)
        rmse = float(np.sqrt(np.mean(res.fun**2)))
        if short.stable(res.x) and np.isfinite(rmse):
            ranked.append((rmse, res.x, split))
    if not ranked:
        raise NotConvergedError("no split of the best linear approximation's poles and zeros gives a stable start")
    ranked.sort(key=lambda item: item[0])
    _, theta_short, split = ranked[0]

    full = _Param(nb, ns, degree, feedthrough)
    a, b, c_short, r, s = short.split(theta_short)
    c = np.zeros(degree)
    c[: short.degree] = c_short
    res = full.fit(np.r_[a, b, c, r, s], u_arr, y_arr, warmup, max_iter)
    a, b, c, r, s = full.split(res.x)
    m = full.monomials(c)
    if m[0] < 0:
        a, m = -a, m * (-1.0) ** np.arange(1, degree + 1)
    return wiener_hammerstein_model(a, b, m, r, s, feedthrough=feedthrough), int(res.nfev)


# -- the benchmark ----------------------------------------------------------------------------------


def test_rmse_mv(model: Any, u_test: NDArray[np.float64], y_test: NDArray[np.float64], n_init: int) -> float:
    """RMS of the free-run simulation error on test[n_init:], in mV (``model.simulate``: the
    sandwich of today's path, the fit with its output offset of the new one)."""
    e = (model.simulate(u_test) - y_test)[n_init:]
    return 1e3 * float(np.sqrt(np.mean(e**2)))


CANDIDATES: list[dict[str, Any]] = [
    {"degree": 25},
    {"degree": 25, "feedthrough": True, "output_feedthrough": False},
    {"degree": 27, "feedthrough": True, "output_feedthrough": False},
    {"degree": 27, "output_feedthrough": True},
    {"degree": 29, "output_feedthrough": True},
    {"degree": 31, "output_feedthrough": True},
]


def validate(u: NDArray[np.float64], y: NDArray[np.float64], nb: int, ns: int, warmup: int, cut: int = 80_000) -> None:
    """Each candidate structure fitted on the estimation data's first ``cut`` samples; the
    free-run RMSE on the rest of the estimation data (the model simulated over the whole
    estimation input, so the state carries over). No test data are used."""
    print(f"validation: fit on train[:{cut}], free-run RMSE on train[{cut}:] (estimation data only)")
    for cand in CANDIDATES:
        t0 = time.perf_counter()
        fit = bid.fit_wiener_hammerstein(u[:cut], y[:cut], nb=nb, ns=ns, warmup=warmup, **cand)
        e = (fit.simulate(u) - y)[cut:]
        print(f"  {str(cand):60s} fit {1e3 * fit.simulation_rmse:.4f} mV   validation {1e3 * float(np.sqrt(np.mean(e**2))):.4f} mV"
              f"   ({time.perf_counter() - t0:.1f} s)", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", type=Path, default=DATA)
    parser.add_argument("--degree", type=int, default=29)
    parser.add_argument("--old-degree", type=int, default=25, help="the old path's degree")
    parser.add_argument("--split-samples", type=int, default=10_000,
                        help="the new fit's split search on this many samples (the package's default: 20000)")
    parser.add_argument("--lag0", choices=["g2", "g1", "both", "none"], default="g2",
                        help="lag-0 terms of the new fit (default g2); --feedthrough overrides it")
    parser.add_argument("--validate", action="store_true",
                        help="fit the candidate structures on train[:80000], RMSE on train[80000:]")
    parser.add_argument("--nb", type=int, default=3)
    parser.add_argument("--ns", type=int, default=3)
    parser.add_argument("--warmup", type=int, default=100)
    parser.add_argument("--feedthrough", action="store_true", help="a lag-0 term in G1 (and G2 unless --no-output-feedthrough)")
    parser.add_argument("--no-output-feedthrough", action="store_true", help="with --feedthrough: G1 only (the new fit only)")
    parser.add_argument("--max-iter", type=int, default=None, help="the new fit's final iterations on the whole record")
    parser.add_argument("--segment-iter", type=int, default=None,
                        help="the new fit's iterations on the 20 000-sample segment (a private constant, default 30)")
    parser.add_argument("--repeats", type=int, default=1, help="fits of each, interleaved; the best time is shown")
    parser.add_argument("--old", action="store_true", help="also run today's path (frozen copy, scipy)")
    parser.add_argument("--no-new", action="store_true", help="only today's path")
    args = parser.parse_args()
    d = np.load(args.data)
    u, y = d["u"], d["y"]
    tr = slice(int(d["train_start"]), int(d["train_stop"]))
    te = slice(int(d["test_start"]), int(d["test_stop"]))
    n_init = int(d["test_n_init"])
    if args.validate:
        validate(u[tr], y[tr], args.nb, args.ns, args.warmup)
        return
    settings = dict(nb=args.nb, ns=args.ns, degree=args.degree, warmup=args.warmup, feedthrough=args.feedthrough)
    old_settings = {**settings, "degree": args.old_degree}
    extra: dict[str, Any] = {"output_feedthrough": False} if args.no_output_feedthrough else {}
    if not args.feedthrough:
        settings["feedthrough"] = args.lag0 in ("g1", "both")
        extra["output_feedthrough"] = args.lag0 in ("g2", "both")
    if args.max_iter is not None:
        extra["max_iter"] = args.max_iter
    extra["split_samples"] = args.split_samples
    if args.segment_iter is not None:
        from backlashid.identify import _wiener_hammerstein

        _wiener_hammerstein._SEGMENT_ITER = args.segment_iter
    print(f"SYSID 2009 Wiener-Hammerstein, train [{tr.start}:{tr.stop}], test [{te.start}:{te.stop}], "
          f"free-run simulation RMSE on test[{n_init}:]; {settings} {extra}"
          + (f"; old path {old_settings}" if args.old or args.no_new else ""))
    old_fit, new_fit = None, None
    old_times, new_times = [], []
    for _ in range(args.repeats):  # interleaved, so both see the same load; the best time counts
        if args.old or args.no_new:
            t0 = time.perf_counter()
            old_fit = old_fit_wiener_hammerstein(u[tr], y[tr], **old_settings)
            old_times.append(time.perf_counter() - t0)
        if not args.no_new:
            t0 = time.perf_counter()
            new_fit = bid.fit_wiener_hammerstein(u[tr], y[tr], **settings, **extra)
            new_times.append(time.perf_counter() - t0)
    rows = []
    if old_fit is not None:
        model, nfev = old_fit
        rows.append(("today (scipy least_squares + lfilter)", min(old_times), test_rmse_mv(model, u[te], y[te], n_init),
                     f"{nfev} evaluations; times {', '.join(f'{t:.2f}' for t in old_times)} s"))
    if new_fit is not None:
        knobs = {**extra, **({"segment_iter": args.segment_iter} if args.segment_iter is not None else {})}
        rows.append(("backlashid (Rust problem + one LM)", min(new_times), test_rmse_mv(new_fit, u[te], y[te], n_init),
                     f"{new_fit.iterations} final iterations {knobs or ''}; times {', '.join(f'{t:.2f}' for t in new_times)} s"))
    for name, seconds, rmse, effort in rows:
        print(f"{name:42s} {seconds:7.2f} s   test RMSE {rmse:.4f} mV   ({effort})")
    if len(rows) == 2:
        print(f"speed-up {rows[0][1] / rows[1][1]:.1f}x (best times)")


if __name__ == "__main__":
    main()
