"""How far the right structure's own fit can go on a family of ``benches/structure_classes.py``:
a parametric bootstrap with the truth in the model class by construction.

    python benches/structure_bootstrap.py                                   # hammerstein_position, third seeds, 20 records x 10 refits
    python benches/structure_bootstrap.py --family sandwich_position --records 5

Per record of the family (the same records as ``structure_classes.py --seeds third``): the right
structure is fitted to the estimation record as that bench's selection fits it
(``initial_state="estimate"``, warm-up 20; input backlash 2/2 degree 3, sandwich 2/2-2/2 degree 3);
that fitted model is taken as the plant. Its noise-free output over the whole record (from the
state the real record's first 100 samples imply) plus white noise of the record's std gives B new
records; each is refitted on its estimation part and scored, as the bench scores, on its
validation part from the state its first 100 samples imply. The share of refits within 1.5 noise
stds is what this estimator reaches on this input and noise when the structure cannot be wrong.
Run time about 1.5 min per record with B = 10 on one core. Deterministic.

``--optimum`` also asks whether each refit found the optimum: its estimation record's cost
(the simulation RMSE from the state estimated over the whole estimation record, after the
warm-up) beside the cost of the plant's own parameters on the same noisy record. A refit whose
cost is clearly above the plant's stopped in a worse local minimum: a better search would
reach a model at least as good as the plant on that record.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import backlashid as bid
import independent_chains as ic
import structure_classes as sc

RIGHT = {
    "hammerstein_position": (bid.fit_hammerstein_backlash, dict(nr=2, ns=2, degree=3)),
    "sandwich_position": (bid.fit_sandwich, dict(na=2, nb=2, nr=2, ns=2, degree=3)),
}


def estimation_cost(model: object, u: np.ndarray, y: np.ndarray) -> float:
    """The simulation RMSE of ``model`` on a record from the state estimated over all of it,
    after the bench's warm-up of 20 samples."""
    state = bid.estimate_state(model, u, y, samples=u.size)
    return float(np.sqrt(np.mean((model.simulate(u, initial_state=state) - y)[20:] ** 2)))


def bootstrap(family: str, index: int, seeds: str, refits: int, optimum: bool = False) -> tuple[str, float, np.ndarray, np.ndarray]:
    """(input class, the real fit's validation RMSE / sigma, the refits' ratios, and with
    ``optimum`` each refit's estimation cost over the plant's on the same record, else NaN)."""
    fit_right, orders = RIGHT[family]
    rec = sc.make_record(family, index, seeds)
    n = ic.N_EST
    u, y, sigma = rec["u"], rec["y"], rec["sigma"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plant = fit_right(u[:n], y[:n], initial_state="estimate", warmup=20, **orders).model
    real = bid.evaluate(plant, u[n:], y[n:], init_samples=sc.INIT_SAMPLES).simulation_rmse / sigma
    clean = np.asarray(bid.simulate_from_samples(plant, u, y, sc.INIT_SAMPLES))
    rng = np.random.default_rng(1000 + index)
    ratios, costs = [], []
    for _ in range(refits):
        yb = clean + sigma * rng.standard_normal(y.size)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                refit = fit_right(u[:n], yb[:n], initial_state="estimate", warmup=20, **orders).model
            ratios.append(bid.evaluate(refit, u[n:], yb[n:], init_samples=sc.INIT_SAMPLES).simulation_rmse / sigma)
            costs.append(estimation_cost(refit, u[:n], yb[:n]) / estimation_cost(plant, u[:n], yb[:n]) if optimum else np.nan)
        except bid.errors.BacklashIdError:
            ratios.append(np.inf)
            costs.append(np.nan)
    return rec["input_class"], real, np.array(ratios), np.array(costs)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--family", choices=list(RIGHT), default="hammerstein_position")
    ap.add_argument("--seeds", choices=list(sc.SEED_SETS), default="third")
    ap.add_argument("--records", type=int, default=20)
    ap.add_argument("--refits", type=int, default=10)
    ap.add_argument("--optimum", action="store_true", help="also each refit's estimation cost over the plant's (module doc)")
    args = ap.parse_args()
    shares, all_ratios, all_costs = [], [], []
    for i in range(args.records):
        kind, real, ratios, costs = bootstrap(args.family, i, args.seeds, args.refits, args.optimum)
        shares.append(float(np.mean(ratios <= sc.ACCURATE)))
        all_ratios += list(ratios)
        all_costs += list(costs)
        extra = f"; cost over the plant's {', '.join(f'{c:.3f}' for c in costs)}" if args.optimum else ""
        print(f"#{i} {kind:9s} the real record's fit {real:6.2f} | refits within {sc.ACCURATE}: {shares[-1]:.2f}, median {np.median(ratios):.2f}{extra}", flush=True)
    print(f"{args.family}, seeds {args.seeds}: refits within {sc.ACCURATE} noise stds {100 * np.mean(shares):.0f} % "
          f"(records where most refits are: {sum(s > 0.5 for s in shares)}/{len(shares)})")
    if args.optimum:
        r, c = np.array(all_ratios), np.array(all_costs)
        for label, sel in (("at the plant's cost (within 2 %)", c <= 1.02), ("above it (a worse local minimum)", c > 1.02)):
            print(f"refits {label}: {sel.sum()}, within {sc.ACCURATE} noise stds {int((r[sel] <= sc.ACCURATE).sum())}")


if __name__ == "__main__":
    main()
