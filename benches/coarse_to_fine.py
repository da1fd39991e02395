"""The default coarse stage against the whole-record search, over seeds.

    python benches/coarse_to_fine.py            # 20 seeds, N = 5e4 and 1e5, Examples 1 and 2

For each record: fit_cascade / fit_sandwich by default (iterations and LM candidates on the
first max(5000, 200 p) samples, LM on the whole record) and with coarse=0 (the whole record
throughout). Prints the largest difference of any parameter in standard errors of the
whole-record fit, the relative difference of the simulation cost, the largest relative
difference of any standard error, and the mean time of each.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

import backlashid as bid


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--sizes", type=int, nargs="+", default=[50_000, 100_000])
    args = ap.parse_args()
    cases = (("ex1 SNR 25", bid.example1(), bid.fit_cascade, 25.0), ("ex2 SNR 100", bid.example2(), bid.fit_sandwich, 100.0))
    print(
        f"{'case':<12}{'N':>8}  {'max |diff| / se':>16}{'median':>9}  {'cost ratio - 1 (min, max)':>26}"
        f"  {'max |se ratio - 1|':>18}  {'coarse':>8}{'whole':>8}"
    )
    for name, model, fit, snr in cases:
        for n in args.sizes:
            devs, costs, ses, t_coarse, t_whole = [], [], [], 0.0, 0.0
            for seed in range(args.seeds):
                d = bid.example_data(model, n, snr=snr, seed=100 + seed)
                t = time.perf_counter()
                fast = fit(d.u, d.noisy)
                t_coarse += time.perf_counter() - t
                t = time.perf_counter()
                whole = fit(d.u, d.noisy, coarse=0)
                t_whole += time.perf_counter() - t
                se = whole.standard_errors
                devs.append(max(abs(fast.parameters[k] - whole.parameters[k]) / se[k] for k in se))
                costs.append(fast.simulation_rmse**2 / whole.simulation_rmse**2 - 1)
                ses.append(max(abs(fast.standard_errors[k] / se[k] - 1) for k in se))
            print(
                f"{name:<12}{n:>8}  {max(devs):>16.3f}{np.median(devs):>9.4f}  {min(costs):>12.1e}, {max(costs):>11.1e}  {max(ses):>18.1e}  "
                f"{t_coarse / args.seeds * 1e3:>6.0f}ms{t_whole / args.seeds * 1e3:>6.0f}ms"
            )


if __name__ == "__main__":
    main()
