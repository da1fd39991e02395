"""Coupled electric drives (Wigren & Schoukens 2017) under the ``nonlinear_benchmarks`` loader
protocol (issue 17): does every cascade / sandwich a user would try fit, and how well does it
simulate the test record?

Protocol: DATAUNIF, records u11 -> z11 (CED1, low amplitude) and u12 -> z12 (CED2, high),
scored separately; train = samples [0:400], test = [400:500]; the test simulation starts from
the state estimated on the first 4 test samples (``evaluate(..., init_samples=4)``, the model
held) and the RMSE is over test[4:]. Published simulation RMSEs (MDCHAMP/nonlinear_baselines):
polynomial NARX 0.100 / 0.141, ARX 0.291 / 0.331.

For every setting (model, orders, branch degree 1-3, initial state 'rest' or 'estimate') it
prints either the exception a fit raised (class and message) or the test RMSE, the test RMSE
from rest, the fit's own simulation RMSE on the training record, the fraction of samples that
move the backlash, the dead-band widths, the seconds taken and how many FitWarnings the fit gave
(crossing or turning branches, uncertain parameters).

The output is the pulley's speed measured without its sign (``abs(speed)``): a backlash
between linear blocks can produce an output that stays on one side of zero only through its
branches' offsets; it cannot fold the sign of the speed (docs/real_records.md).

    python benches/coupled_electric_drives.py
    python benches/coupled_electric_drives.py --data /path/to/coupled_electric_drives --records CED1
"""

from __future__ import annotations

import argparse
import os
import time
import warnings
from pathlib import Path

import numpy as np

import backlashid as bid

DATA = Path(os.environ.get("BACKLASHID_SHARED_DATA", "/work/shared/data")) / "coupled_electric_drives"
PUBLISHED = {"CED1": {"NARX": 0.100, "ARX": 0.291}, "CED2": {"NARX": 0.141, "ARX": 0.331}}
RECORDS = {"CED1": ("u11", "z11"), "CED2": ("u12", "z12")}
# (model, orders): what a user would try first; cascade (na, nb), sandwich (na, nb, nr, ns)
SETTINGS = [
    ("cascade", (2, 2)),
    ("cascade", (3, 3)),
    ("cascade", (4, 4)),
    ("sandwich", (2, 2, 1, 1)),
    ("sandwich", (2, 2, 2, 2)),
]


def load(folder: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """DATAUNIF's two records: name -> (u, y)."""
    table = np.genfromtxt(folder / "DATAUNIF.csv", delimiter=",", names=True)
    return {name: (np.asarray(table[u], float), np.asarray(table[y], float)) for name, (u, y) in RECORDS.items()}


def run_one(kind: str, orders: tuple[int, ...], degree: int, state: str, u: np.ndarray, y: np.ndarray) -> dict[str, object]:
    """Fit on [0:400], score on [400:500] initialised from 4 samples."""
    u_tr, y_tr, u_te, y_te = u[:400], y[:400], u[400:], y[400:]
    start = time.perf_counter()
    try:
        with warnings.catch_warnings(record=True) as caught:  # counted in the table, not printed
            warnings.simplefilter("always", bid.FitWarning)
            result = _fit(kind, orders, degree, state, u_tr, y_tr)
        metrics = bid.evaluate(result.model, u_te, y_te, init_samples=4)
        # the test RMSE from rest over the same samples, for comparison
        rest = bid.evaluate(result.model, u_te, y_te, warmup=4)
    except Exception as exc:  # the point is to report every failure
        return {"error": f"{type(exc).__name__}: {exc}", "seconds": time.perf_counter() - start}
    return {
        "test_rmse": metrics.simulation_rmse,
        "test_rmse_rest": rest.simulation_rmse,
        "train_rmse": result.simulation_rmse,
        "moving": result.moving_fraction,
        "c": (result.model.backlash.c_left, result.model.backlash.c_right),
        "seconds": time.perf_counter() - start,
        "warnings": sum(issubclass(w.category, bid.FitWarning) for w in caught),
    }


def _fit(kind: str, orders: tuple[int, ...], degree: int, state: str, u_tr: np.ndarray, y_tr: np.ndarray) -> bid.FitResult:
    if kind == "cascade":
        return bid.fit_cascade(u_tr, y_tr, *orders, degree=degree, initial_state=state)
    na, nb, nr, ns = orders
    return bid.fit_sandwich(u_tr, y_tr, na, nb, nr, ns, degree=degree, initial_state=state)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--data", type=Path, default=DATA)
    parser.add_argument("--records", nargs="+", default=list(RECORDS), choices=list(RECORDS))
    parser.add_argument("--degrees", nargs="+", type=int, default=[1, 2, 3])
    args = parser.parse_args()
    records = load(args.data)
    raised = 0
    for name in args.records:
        u, y = records[name]
        pub = PUBLISHED[name]
        print(f"\n{name}: published polynomial NARX {pub['NARX']:.3f}, ARX {pub['ARX']:.3f} (test RMSE, 4 samples initialise)")
        print(f"{'model':9} {'orders':10} {'deg':>3} {'state':8} {'test':>7} {'rest':>7} {'train':>7} {'moving':>6} {'c_L, c_R':>16} {'s':>5} {'warned':>6}")
        for kind, orders in SETTINGS:
            for degree in args.degrees:
                for state in ("rest", "estimate"):
                    r = run_one(kind, orders, degree, state, u, y)
                    head = f"{kind:9} {str(orders):10} {degree:3d} {state:8}"
                    if "error" in r:
                        raised += 1
                        print(f"{head} RAISED {r['error']} ({r['seconds']:.1f} s)")
                    else:
                        c = r["c"]
                        print(
                            f"{head} {r['test_rmse']:7.3f} {r['test_rmse_rest']:7.3f} {r['train_rmse']:7.3f} "
                            f"{r['moving']:6.2f} {c[0]:7.3f}, {c[1]:7.3f} {r['seconds']:5.1f} {r['warnings']:6d}"
                        )
    print(f"\nsettings that raised: {raised}")


if __name__ == "__main__":
    main()
