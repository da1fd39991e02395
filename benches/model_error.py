"""The model-error model of the diagnosis on out-of-catalogue effects: shares of the gap closed and
the groups named, per effect and seed, and the time per call.

The records are those of tests/diagnosis/test_model_error.py (its independent NumPy generators:
example 1's cascade driven by a slow random input, plus an effect outside the catalogue, noise
std 0.02, 2 estimation + 2 validation records of 4000 samples). Two nominal models: the cascade
``fit_cascade`` finds on the first estimation record (it absorbs part of the effect, as on real
data), and the true cascade (what a model of the signals could close at best).

    python benches/model_error.py --seeds 5
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

import backlashid as bid
from backlashid.diagnosis.analyses import model_error

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "diagnosis"))
import test_model_error as gen  # the test's generators


def true_records(effect: str, seed: int) -> tuple[list[dict], list[dict]]:
    """The same records with the true cascade as the nominal model."""
    est, val, _ = gen.nominal_records(effect, seed)
    truth = bid.example1()
    out = []
    for r in est + val:
        y = r["y_sim"] + r["residual"]
        y_sim = truth.simulate(r["u"])
        out.append({"u": r["u"], "x": truth.linear.simulate(r["u"]), "y_sim": y_sim, "residual": y - y_sim})
    return out[: len(est)], out[len(est) :]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    args = parser.parse_args()
    print("| effect | share, fitted nominal (per seed) | median | first group named (seeds) | share, true nominal (median) |")
    print("|---|---|---|---|---|")
    times = []
    for effect in [*gen.EFFECTS, "none"]:
        shares, firsts, ceiling = [], [], []
        for seed in range(args.seeds):
            est, val, _ = gen.nominal_records(effect, seed)
            t = time.process_time()
            m = model_error(est, val, warmup=gen.WARMUP, noise_floor=None if effect == "none" else gen.NOISE**2)
            times.append(time.process_time() - t)
            shares.append(m.closable_share)
            firsts.append(m.groups[0] if m.groups else "-")
            est_t, val_t = true_records(effect, seed)
            floor = None if effect == "none" else gen.NOISE**2
            ceiling.append(model_error(est_t, val_t, warmup=gen.WARMUP, noise_floor=floor).closable_share)
        named = ", ".join(f"{g} x{firsts.count(g)}" for g in dict.fromkeys(firsts))
        print(
            f"| {effect} | {' '.join(f'{s:.2f}' for s in shares)} | {np.median(shares):.2f} | {named} | {np.nanmedian(ceiling):.2f} |"
        )
    print(f"\nCPU time per call (2 x 4000 + 2 x 4000 samples): median {1e3 * np.median(times):.0f} ms, max {1e3 * max(times):.0f} ms")


if __name__ == "__main__":
    main()
