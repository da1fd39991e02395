"""Case study: a cascade fitted to the friction damper with backlash, validated on earthquake
records, its gap diagnosed, and the error once the best candidate effect is added.

Regenerates the figures of docs/case_study_friction_damper.md and prints its tables:

    python docs/case_studies/friction_damper.py            # writes docs/figures/friction_damper_*.png

Data: shared/data/friction_damper_backlash (read in place; $BACKLASHID_DATA overrides), CC BY-SA
4.0, Coble et al. 2022. Input: imposed displacement x_in [in]; output: friction force F_kip [kip].
Estimation: the harmonic test at 1 Hz, 0.5 in and 36 lb (the earthquake tests' band tension);
validation and diagnosis: the Imperial Valley DBE earthquake record; the other three earthquake
records of the snapshot score the models too. Scores: NRMSE = RMSE / range of the measured force
on the companion paper's evaluation window, of the free-run simulation (the model driven by the
displacement alone, from the state diagnose estimates: linear block at equilibrium, the force held
at standstill fitted), beside the LuGre baseline listed in the data folder's README.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

import backlashid as bid
from backlashid.app import decimate, load_record
from backlashid.diagnosis import estimated_start, held_state
from backlashid.identify import Scaling

DECIMATE = 8  # 1024 Hz -> 128 Hz: the motion is slow, the identification needs samples that change
WARMUP = 20
ESTIMATION = "d2_char_1Hz36lbtension0.5amplitude.npz"
DIAGNOSED = "ImperialValleyDBE"
# the companion paper's scored windows (samples at 1024 Hz) and the LuGre NRMSE there (data README)
WINDOWS = {"ImperialValleyDBE": (3072, 7680), "ImperialValleyMCE": (3072, 7680), "KocaeliDBE": (6144, 14336), "KocaeliMCE": (6144, 14336)}
LUGRE_NRMSE = {"ImperialValleyDBE": 0.058, "ImperialValleyMCE": 0.076, "KocaeliDBE": 0.121, "KocaeliMCE": 0.094}


def nrmse(measured: np.ndarray, simulated: np.ndarray, window: slice) -> float:
    e = simulated[window] - measured[window]
    return float(np.sqrt(np.mean(e**2)) / np.ptp(measured[window]))


def free_runs(model: bid.CascadeModel, augmented: object, scaling: Scaling, rec: object) -> tuple[np.ndarray, np.ndarray]:
    """Free-run simulations of the nominal and the augmented model on a record, in kip, each from
    the state diagnose uses: the linear block at equilibrium with the first displacement and the
    backlash memory (the force the damper holds at standstill) fitted to the record."""
    u, y = scaling.input_to_model(rec.u), scaling.output_to_model(rec.y)
    span = (float(y.min()), float(y.max()))
    nominal, _ = estimated_start(lambda v, y0, held: model.simulate(v, initial_state=held_state(model, v[0], y0)), u, y, span)
    aug, _ = estimated_start(lambda v, y0, held: augmented.simulate(v, y_prev=y0, held=True), u, y, span)
    return scaling.output_from_model(nominal), scaling.output_from_model(aug)


def main() -> None:
    folder = bid.shared_data_folder(Path(__file__).parent) / "friction_damper_backlash"
    out = Path(__file__).resolve().parents[1] / "figures"
    est = decimate(load_record(folder / ESTIMATION, "x_in", "F_kip"), DECIMATE)
    quakes = {name: decimate(load_record(folder / f"d2_eq_{name}.npz", "x_in", "F_kip"), DECIMATE) for name in WINDOWS}
    scaling = Scaling.auto(est.u, est.y)  # zero mean, unit std on the estimation record
    u_e, y_e = scaling.input_to_model(est.u), scaling.output_to_model(est.y)
    fit = bid.fit_cascade(u_e, y_e, na=2, nb=2, degree=3, warmup=WARMUP)
    print(fit.summary(), "\n")

    val = quakes[DIAGNOSED]
    start = time.perf_counter()
    report = bid.diagnose(fit.model, estimation=(u_e, y_e), validation=(scaling.input_to_model(val.u), scaling.output_to_model(val.y)))
    print(report.summary())
    print(f"\ndiagnosis took {time.perf_counter() - start:.2f} s\n")
    # the best candidate that changes the simulation (colored_noise only changes the one-step prediction)
    best = next(c for c in report.ranking if c.effect != "colored_noise")

    print("| earthquake record (window, 1024 Hz samples) | nominal cascade | cascade + " + best.effect + " | LuGre (data README) |")
    print("|---|---|---|---|")
    rows = {}
    for name, (a, b) in WINDOWS.items():
        rec = quakes[name]
        window = slice(a // DECIMATE, b // DECIMATE)
        nominal, augmented = free_runs(fit.model, best.model, scaling, rec)
        rows[name] = (nrmse(rec.y, nominal, window), nrmse(rec.y, augmented, window))
        tag = " (diagnosed)" if name == DIAGNOSED else ""
        print(f"| {name}{tag} [{a}:{b}] | {rows[name][0]:.3f} | {rows[name][1]:.3f} | {LUGRE_NRMSE[name]:.3f} |")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    report.plot(out / "friction_damper_dashboard.png")
    a, b = WINDOWS[DIAGNOSED]
    window = slice(a // DECIMATE, b // DECIMATE)
    t = np.arange(len(val.y)) * DECIMATE / 1024.0
    nominal, augmented = free_runs(fit.model, best.model, scaling, val)
    fig, ax = plt.subplots(figsize=(10, 4))
    ax.plot(t[window], val.y[window], "k", lw=1.2, label="measured")
    ax.plot(t[window], nominal[window], lw=1, label=f"nominal cascade (NRMSE {rows[DIAGNOSED][0]:.3f})")
    ax.plot(t[window], augmented[window], lw=1, label=f"cascade + {best.effect} (NRMSE {rows[DIAGNOSED][1]:.3f})")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("friction force [kip]")
    ax.set_title(f"{DIAGNOSED}: free-run simulation on the scored window (LuGre NRMSE {LUGRE_NRMSE[DIAGNOSED]:.3f})")
    ax.legend(loc="lower right", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "friction_damper_simulation.png", dpi=110)
    print(f"\nwrote {out / 'friction_damper_dashboard.png'} and {out / 'friction_damper_simulation.png'}")


if __name__ == "__main__":
    main()
