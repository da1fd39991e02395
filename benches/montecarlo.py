"""Monte Carlo of the paper's Examples 1 and 2: the paper's plain algorithm vs the default.

Prints, per example, noise level and algorithm: how many seeds end with max |error| < 0.1
("in basin") and < 0.02, the median and worst max |error|, failures, and per-parameter mean,
std and max |error|. Errors are estimate minus truth over all free parameters (m_L1 = r_1 = 1).

    python benches/montecarlo.py --seeds 100 --per-parameter
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import backlashid as bid

CASES = {
    "ex1": (bid.example1, bid.fit_cascade, (25.0, None)),
    "ex2": (bid.example2, bid.fit_sandwich, (100.0, None)),
}


def run(example: str, snr: float | None, paper: bool, seeds: int, n: int) -> dict[str, object]:
    make, fit, _ = CASES[example]
    model = make()
    errors, failures, seconds = [], 0, 0.0
    names: list[str] = []
    for seed in range(seeds):
        data = bid.example_data(model, n, snr=snr, seed=seed)
        t0 = time.perf_counter()
        try:
            result = fit(data.u, data.noisy, paper=paper)
            err = result.errors(model)
        except bid.NotConvergedError as exc:
            best = exc.best
            if best is None:
                failures += 1
                continue
            truth = bid.identify.Structure(*_orders(model)).pack(model)
            values = np.array(list(best.parameters.values()))
            err = dict(zip(best.parameters, values - truth))
        except bid.BacklashIdError:
            failures += 1
            continue
        finally:
            seconds += time.perf_counter() - t0
        names = list(err)
        errors.append([err[k] for k in names])
    e = np.abs(np.array(errors)) if errors else np.zeros((0, 0))
    worst = e.max(axis=1) if errors else np.array([np.inf])
    return {
        "errors": np.array(errors),
        "names": names,
        "worst": worst,
        "failures": failures,
        "seconds": seconds / seeds,
    }


def _orders(model: bid.CascadeModel | bid.SandwichModel) -> tuple[int, ...]:
    if isinstance(model, bid.SandwichModel):
        lin = model.input_linear
        return lin.na, lin.nb, model.backlash.degree, model.output_linear.na, model.output_linear.nb
    return model.linear.na, model.linear.nb, model.backlash.degree


def standard_error_check(seeds: int, n: int = 100_000, snr: float = 5.0) -> None:
    """Example 1 at large N and low SNR: is every error within 3 reported standard errors?"""
    model = bid.example1()
    print(f"\nExample 1, N = {n}, SNR {snr:g}: error / standard error per parameter (|z| <= 3 wanted)")
    for seed in range(seeds):
        data = bid.example_data(model, n, snr=snr, seed=seed)
        t0 = time.perf_counter()
        default = bid.fit_cascade(data.u, data.noisy)
        seconds = time.perf_counter() - t0
        z = {k: e / default.standard_errors[k] for k, e in default.errors(model).items()}
        plain = bid.fit_cascade(data.u, data.noisy, paper=True)
        zp = {k: e / default.standard_errors[k] for k, e in plain.errors(model).items()}
        worst = max(z, key=lambda k: abs(z[k]))
        worst_p = max(zp, key=lambda k: abs(zp[k]))
        print(
            f"  seed {seed}: default max |z| = {abs(z[worst]):.2f} ({worst}), {seconds:.1f} s; "
            f"paper's algorithm max |z| = {abs(zp[worst_p]):.1f} ({worst_p})"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=100)
    ap.add_argument("--n", type=int, default=1500)
    ap.add_argument("--examples", nargs="+", default=["ex1", "ex2"])
    ap.add_argument("--per-parameter", action="store_true", help="print per-parameter statistics")
    ap.add_argument("--large-seeds", type=int, default=3, help="seeds of the N = 1e5, SNR 5 check (0 skips it)")
    args = ap.parse_args()
    print(f"Monte Carlo: N = {args.n}, {args.seeds} seeds, |u| < 1; error = max over parameters of |estimate - true|")
    print(f"{'case':<26}{'algorithm':<10}{'<0.1':>6}{'<0.02':>7}{'median':>10}{'worst':>10}{'failed':>8}{'s/fit':>8}")
    for ex in args.examples:
        for snr in CASES[ex][2]:
            for paper in (True, False):
                r = run(ex, snr, paper, args.seeds, args.n)
                w = r["worst"]
                label = f"{ex} SNR {snr:g}" if snr else f"{ex} noise-free"
                print(
                    f"{label:<26}{'paper' if paper else 'default':<10}{int(np.sum(w < 0.1)):>6}{int(np.sum(w < 0.02)):>7}"
                    f"{np.median(w):>10.2e}{np.max(w):>10.2e}{r['failures']:>8}{r['seconds']:>8.3f}"
                )
                if args.per_parameter and len(r["errors"]):
                    e = r["errors"]
                    for k, name in enumerate(r["names"]):
                        print(f"    {name:<6} mean {e[:, k].mean():+.2e}  std {e[:, k].std():.2e}  max {np.abs(e[:, k]).max():.2e}")
    if args.large_seeds:
        standard_error_check(args.large_seeds)


if __name__ == "__main__":
    main()
