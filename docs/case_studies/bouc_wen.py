"""Case study protocol: the Bouc-Wen hysteretic benchmark (Noël & Schoukens 2016). Nominal
structures fitted on the noise-free training record, scored by free-run simulation on the
official test sets beside the published results.

Prints the table in Markdown:

    python docs/case_studies/bouc_wen.py

Run time 6 to 16 s on the project's 2-core machine (the five fits take most of it). Deterministic.

Data: shared/data/bouc_wen (read in place; $BACKLASHID_DATA overrides). The records are
SIMULATED by the benchmark's own Newmark integrator, not measured. Input: force u [N]; output:
displacement y [m]; 750 Hz, not decimated (the multisines reach 150 Hz, a fifth of the rate).

- Fit: ``bw_train_forgione_noisefree.npz``, 5 periods of a random-phase multisine (40 960
  samples, M. Forgione's record, no output noise added), the state at its start estimated.
- Score (the benchmark's figure of merit): e_RMS = sqrt(mean((y_model - y_test)^2)) in m, of the
  free-run simulation (input only). The multisine test set is one steady-state period, so the
  model runs two periods of it from rest and the second is scored; the sine sweep starts from
  zero initial conditions, so it is simulated from rest and scored whole.
- Reference: the multisine RMS simulation errors quoted in the data folder's README (PNLSS with
  decoupling 1.87e-5 m, dynoNet 4.52e-5 m, NFIR 16.3e-5 m).

The physics is m y'' + c y' + k y + z = u with a Bouc-Wen force z: the hysteresis sits in a
feedback loop around the mass-spring, not after a linear block as in a cascade. The nominal
structures here are the package's cascades, sandwich and input backlash as they are.

Then the diagnosis: the nominal cascade 2/2, degree 1 (a straight play: the Bouc-Wen system has
none) is diagnosed with the training record's first half as estimation and its second half as
validation (nothing of the test sets), every catalogue effect a candidate; the model it returns
(``report.model``: the nominal with the named effects, refitted) is scored on the test sets
like the nominal structures.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from _fits import fit_structure  # docs/case_studies/_fits.py, beside this script

import backlashid as bid
from backlashid.identify import Scaling

FS = 750.0
WARMUP = 200  # samples of the training record not scored by the fit (the estimated start settles)
PUBLISHED = {
    "PNLSS with decoupling (Esfahani et al. 2017)": 1.87e-5,
    "dynoNet (Forgione & Piga 2021)": 4.52e-5,
    "NFIR (Belz et al. 2017)": 16.3e-5,
}
STRUCTURES: list[tuple[str, str, dict[str, int]]] = [
    ("cascade 2/2, degree 1", "cascade", dict(na=2, nb=2, degree=1)),
    ("cascade 3/3, degree 1", "cascade", dict(na=3, nb=3, degree=1)),
    ("cascade 3/3, degree 3", "cascade", dict(na=3, nb=3, degree=3)),
    ("input backlash 3/3, degree 1", "hammerstein", dict(nr=3, ns=3, degree=1)),
    ("sandwich 2/2-2/2, degree 1", "sandwich", dict(na=2, nb=2, nr=2, ns=2, degree=1)),
]


def rmse(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e**2)))


def multisine_error(model: bid.Model, scaling: Scaling, u: np.ndarray, y: np.ndarray) -> float:
    """e_RMS [m] on the steady-state multisine period: two periods from rest, the second scored."""
    sim = scaling.output_from_model(model.simulate(scaling.input_to_model(np.concatenate([u, u]))))
    return rmse(sim[u.size :] - y)


def sweep_error(model: bid.Model, scaling: Scaling, u: np.ndarray, y: np.ndarray) -> float:
    """e_RMS [m] on the sine sweep, simulated from rest (zero initial conditions)."""
    return rmse(scaling.output_from_model(model.simulate(scaling.input_to_model(u))) - y)


def main() -> None:
    start_all = time.perf_counter()
    folder = bid.benchmarks.shared_data_folder(Path(__file__).parent) / "bouc_wen"
    train = np.load(folder / "bw_train_forgione_noisefree.npz")
    test = np.load(folder / "bw_test.npz")
    assert float(train["fs"]) == FS and float(test["fs"]) == FS
    u, y = train["u"], train["y"]
    scaling = Scaling.auto(u, y)
    U, Y = scaling.input_to_model(u), scaling.output_to_model(y)
    ms_u, ms_y = test["u_multisine"], test["y_multisine"]
    sw_u, sw_y = test["u_sinesweep"], test["y_sinesweep"]
    print(f"training {u.size} samples ({int(train['period'])} per period), multisine test {ms_u.size}, sine sweep {sw_u.size}")
    print(f"test output RMS: multisine {rmse(ms_y):.3e} m, sine sweep {rmse(sw_y):.3e} m\n")

    print("| model | parameters | fit time [s] | training e_RMS [m] | multisine test e_RMS [m] | sine sweep e_RMS [m] |")
    print("|---|---|---|---|---|---|")
    for label, kind, kw in STRUCTURES:
        t = time.perf_counter()
        result, _ = fit_structure(kind, U, Y, kw, WARMUP)
        seconds = time.perf_counter() - t
        model = result.model
        e_train = rmse(scaling.output_from_model(model.simulate(U))[WARMUP:] - y[WARMUP:])
        e_ms, e_sw = multisine_error(model, scaling, ms_u, ms_y), sweep_error(model, scaling, sw_u, sw_y)
        print(f"| {label} | {len(result.parameters)} | {seconds:.1f} | {e_train:.3e} | {e_ms:.3e} | {e_sw:.3e} |")
    # the diagnosis, on the training record alone: which effect does the cascade 2/2 miss?
    t = time.perf_counter()
    nominal = fit_structure("cascade", U, Y, dict(na=2, nb=2, degree=1), WARMUP)[0].model
    half = U.size // 2
    report = bid.diagnose(nominal, (U[:half], Y[:half]), (U[half:], Y[half:]))
    seconds = time.perf_counter() - t
    diagnosed = report.model
    e_train = rmse(scaling.output_from_model(diagnosed.simulate(U))[WARMUP:] - y[WARMUP:])
    e_ms, e_sw = multisine_error(diagnosed, scaling, ms_u, ms_y), sweep_error(diagnosed, scaling, sw_u, sw_y)
    label = "diagnosed: cascade 2/2, degree 1 + " + " + ".join(report.effects or ("nothing",))
    print(f"| {label} | {diagnosed.structure.size + diagnosed.n_extra} | {seconds:.1f} | {e_train:.3e} | {e_ms:.3e} | {e_sw:.3e} |")
    for name, value in PUBLISHED.items():
        print(f"| {name}, published | | | | {value:.3e} | |")
    print(f"\nverdict: {report.verdict()}")
    print(f"fitted effect parameters (model units): {report.best.params if report.best else {}}")
    print(f"noise std estimated on the noise-free record: {report.noise_std:.4g} model units ({100 * report.noise_std / np.std(Y):.2f} % of the output's std)")
    print(f"\ntotal {time.perf_counter() - start_all:.0f} s")


if __name__ == "__main__":
    main()
