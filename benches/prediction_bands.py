"""Coverage of the 95 % prediction bands over Monte Carlo seeds of Example 1 (issue 19).

    python benches/prediction_bands.py                       # the quoted run: seeds 20000..20199
    python benches/prediction_bands.py --first 10000 --seeds 20   # the development seeds

The rule, frozen before the quoted run:

- record: ``bid.example_data(bid.example1(), 1500, snr=25, seed=s)``, fitted by
  ``bid.fit_cascade(d.u, d.noisy)`` (defaults: from rest, no warm-up);
- band: ``fit.predict(u, band=0.95)`` ("linear", first order), from rest, every sample
  counted (no warm-up: the model and the system both start at rest);
- estimation input: u = d.u, truth = d.clean (the noise-free output);
- validation input: a fresh record of the same kind, ``example_data(.., seed=s + 1_000_000)``:
  its u and clean output;
- a sample is covered when lower <= truth <= upper; the coverage is the fraction over all
  samples of all seeds; the first samples before the backlash first moves have a band of
  zero width around an exact output (both 0) and are reported apart;
- "sampling" (200 draws, seed s) on the first ``--sampled`` seeds, the same rule.

Also printed, to tell a miscalibrated covariance from bias or the switching samples: the
mean of z^2 = ((truth - output) / std)^2 over the samples (1 for a calibrated band), the
parameters' NEES (theta - truth)^T Sigma^-1 (theta - truth) averaged over seeds (p for a
calibrated covariance), the noise level the fit implies over the true one, and the coverage
on the samples where the backlash moves and where it holds.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import backlashid as bid

VALIDATION_OFFSET = 1_000_000


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--first", type=int, default=20_000, help="first seed")
    ap.add_argument("--seeds", type=int, default=200, help="number of seeds")
    ap.add_argument("--sampled", type=int, default=20, help="seeds also run with method='sampling'")
    args = ap.parse_args()
    truth = bid.example1()
    seeds = range(args.first, args.first + args.seeds)
    per_seed: dict[str, list[float]] = {"estimation": [], "validation": []}
    inside = {"estimation": 0, "validation": 0}
    total = {"estimation": 0, "validation": 0}
    zero_width = {"estimation": 0, "validation": 0}
    z2: dict[str, list[float]] = {"estimation": [], "validation": []}
    by_case = {"moving": [0, 0], "holding": [0, 0]}
    nees, noise_ratio, sampled, ratios = [], [], [0, 0], []
    t_fit = t_lin = t_smp = 0.0
    for k, s in enumerate(seeds):
        d = bid.example_data(truth, 1500, snr=25, seed=s)
        v = bid.example_data(truth, 1500, snr=25, seed=s + VALIDATION_OFFSET)
        t = time.perf_counter()
        fit = bid.fit_cascade(d.u, d.noisy)
        t_fit += time.perf_counter() - t
        e = np.array(list(fit.errors(truth).values()))
        nees.append(float(e @ np.linalg.solve(fit.covariance, e)))
        noise_ratio.append(fit.noise_std / float(np.std(d.noisy - d.clean)))
        for name, u, clean in (("estimation", d.u, d.clean), ("validation", v.u, v.clean)):
            t = time.perf_counter()
            pred = fit.predict(u, band=0.95)
            t_lin += time.perf_counter() - t
            hit = (pred.lower <= clean) & (clean <= pred.upper)
            inside[name] += int(hit.sum())
            total[name] += hit.size
            zero_width[name] += int(np.sum(pred.std == 0))
            per_seed[name].append(float(hit.mean()))
            positive = pred.std > 0
            z2[name].extend((((clean - pred.output)[positive] / pred.std[positive]) ** 2).tolist())
            if name == "estimation":
                sim = fit.model.simulate(u, internals=True)
                moving = sim.f1 | sim.f2
                for case, mask in (("moving", moving), ("holding", ~moving & positive)):
                    by_case[case][0] += int(hit[mask].sum())
                    by_case[case][1] += int(mask.sum())
            if name == "estimation" and k < args.sampled:
                t = time.perf_counter()
                smp = fit.predict(u, band=0.95, method="sampling", draws=200, seed=s)
                t_smp += time.perf_counter() - t
                shit = (smp.lower <= clean) & (clean <= smp.upper)
                sampled[0] += int(shit.sum())
                sampled[1] += shit.size
                ratios.append(float(np.median(smp.std[positive] / pred.std[positive])))
    n = len(seeds)
    print(f"Example 1, N = 1500, SNR 25, seeds {args.first}..{args.first + n - 1}; 95 % band, first order")
    print(f"{'input':<12}{'coverage':>10}{'w/o zero-width':>16}{'mean z^2':>10}   per-seed coverage: min / 5 % / median / 95 % / max, std")
    for name in ("estimation", "validation"):
        ps = np.array(per_seed[name])
        nonzero = (inside[name] - zero_width[name]) / (total[name] - zero_width[name])
        q = np.percentile(ps, [0, 5, 50, 95, 100])
        print(
            f"{name:<12}{100 * inside[name] / total[name]:>9.2f}%{100 * nonzero:>15.2f}%{np.mean(z2[name]):>10.3f}   "
            + " / ".join(f"{100 * x:.1f}" for x in q) + f" %, {100 * ps.std():.1f} %"
        )
    for case, (hit, count) in by_case.items():
        print(f"  estimation input, samples where the backlash is {case}: {100 * hit / max(count, 1):.2f} % of {count}")
    p = bid.identify.Structure(2, 2, 3).size
    print(f"parameter NEES mean {np.mean(nees):.2f} (p = {p}), median {np.median(nees):.2f}; "
          f"implied / true noise std {np.mean(noise_ratio):.4f}")
    if sampled[1]:
        print(f"sampling (200 draws) on {min(args.sampled, n)} seeds, estimation input: coverage "
              f"{100 * sampled[0] / sampled[1]:.2f} %; median std ratio sampling / linear {np.median(ratios):.3f} "
              f"(per seed {min(ratios):.3f} .. {max(ratios):.3f})")
    print(f"time: fit {t_fit / n * 1e3:.0f} ms, linear band {t_lin / (2 * n) * 1e3:.2f} ms, "
          f"sampled band {t_smp / max(min(args.sampled, n), 1) * 1e3:.0f} ms per record (shared machine: ratios only)")


if __name__ == "__main__":
    main()
