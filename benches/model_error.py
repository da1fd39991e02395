"""The model-error model of the diagnosis on out-of-catalogue effects: shares of the gap closed and
the groups named, per effect and seed, and the time per call.

The records are those of tests/diagnosis/test_model_error.py (its independent NumPy generators:
example 1's cascade driven by a slow random input, plus an effect outside the catalogue, noise
std 0.02, 2 estimation + 2 validation records of 4000 samples). Two nominal models: the cascade
``fit_cascade`` finds on the first estimation record (it absorbs part of the effect, as on real
data), and the true cascade (what a model of the signals could close at best).

    python benches/model_error.py --seeds 5
    python benches/model_error.py --seeds 0 --piezo   # the real piezo records only

``--piezo``: the piezoelectric actuator of shared/data/piezo_actuator_hysteresis (the case study's
cascade 1/1 of degree 3 fitted on the identification record, model units, each record's free run
from the state estimated on its first 50 samples, warm-up 200, the noise floor the diagnosis
estimated there, 0.009264^2): the identification record against the three test runs, test run 1
against runs 2 and 3, and runs 1 and 2 against run 3.
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


def piezo() -> None:
    import warnings

    from backlashid.identify import Scaling

    data = np.load(bid.benchmarks.shared_data_folder(Path(__file__).parent) / "piezo_actuator_hysteresis" / "piezo.npz")
    scaling = Scaling.auto(data["model_u_V"], data["model_y"])
    u_id, y_id = scaling.input_to_model(data["model_u_V"]), scaling.output_to_model(data["model_y"])
    u_t, y_t = scaling.input_to_model(data["test_u_V"]), scaling.output_to_model(data["test_y"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", bid.FitWarning)  # the branches cross near the turning points
        nominal = bid.fit_cascade(u_id, y_id, initial_state="estimate", warmup=200, na=1, nb=1, degree=3).model

    def record(u: np.ndarray, y: np.ndarray) -> dict[str, np.ndarray]:
        y_sim = bid.simulate_from_samples(nominal, u, y, 50)
        return {"u": u, "x": nominal.linear.simulate(u), "y_sim": y_sim, "residual": y - y_sim}

    runs = [record(u_t[a:b], y_t[a:b]) for a, b in ((50, 3900), (5052, 10100), (11152, 14155))]
    cases = {
        "identification -> test runs 1-3": ([record(u_id, y_id)], runs),
        "test run 1 -> runs 2, 3": (runs[:1], runs[1:]),
        "test runs 1, 2 -> run 3": (runs[:2], runs[2:]),
    }
    for label, (est, val) in cases.items():
        t = time.process_time()
        mem = model_error(est, val, warmup=200, noise_floor=0.009264**2)
        print(f"\npiezo, {label} ({1e3 * (time.process_time() - t):.0f} ms CPU):\n{mem}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--piezo", action="store_true", help="also the real piezo records")
    args = parser.parse_args()
    if args.seeds == 0:
        piezo()
        return
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
    if args.piezo:
        piezo()


if __name__ == "__main__":
    main()
