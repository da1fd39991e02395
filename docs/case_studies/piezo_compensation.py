"""Case study: compensating the piezoelectric actuator's hysteresis with the identified model
(Aye & Ang 2018's test trajectory), in simulation.

Prints the table of the "Compensation" section of docs/case_study_piezo_actuator.md and draws
docs/figures/piezo_compensation.png:

    python docs/case_studies/piezo_compensation.py

Data: shared/data/piezo_actuator_hysteresis/piezo.npz (read in place; $BACKLASHID_DATA
overrides), MIT licence. The model is the case study's chosen cascade (1/1, degree 3), fitted
on the whole identification record as ``piezo_actuator.py`` fits it (model units: the
identification record's mean removed, unit standard deviation).

What is a simulation and what a measurement:

- Published (measured on the device): 1.68 µm without compensation (run 2: the voltage
  proportional to the desired displacement) and 0.58 µm with the authors' inverse
  discrete-backlash-operator feedforward (run 3). Both compare the measured displacement with
  the desired one (column 9), means removed.
- Compensated, simulated: ``bid.compensate`` computes the voltage that makes the IDENTIFIED
  model follow the desired trajectory of each run; the model's own simulated output is then
  compared with the trajectory. This measures how well the compensator inverts the model, not
  how the device would follow: only applying the voltage to the device would say that.
- Cross-check on a second model: the same voltage applied to the case study's sandwich 2/2-2/2
  (the structure that simulates the test record best) - a model the compensator does not know,
  so its error is a (model-based) hint of what model error does to the compensation.
- Uncompensated, simulated: the authors' run-2 voltage (proportional to the desired
  displacement) through the identified model, to set beside the measured 1.68 µm.
- Free-run error on the compensated run: run 3's applied voltage in (the authors' inverse
  model's output), the identified model's simulated displacement against the measured one.

The desired trajectory is centred on zero; the target is placed at the run's measured mean
level (the device's operating point). Errors are RMSE in µm with the means removed, as the
published ones, after the first INIT samples (the state is estimated on them from the measured
run).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from _fits import fit_structure  # docs/case_studies/_fits.py, beside this script

import backlashid as bid
from backlashid.identify import Scaling

FS = 200.0
WARMUP = 200  # as piezo_actuator.py: the identification record starts on the loading curve
INIT = 50  # samples that set the state at the start of a run
RUNS = {"run 2 (open loop)": (5052, 10100), "run 3 (with inverse)": (11152, 14155)}
PUBLISHED = {"run 2 (open loop)": 1.68, "run 3 (with inverse)": 0.58}


def rmse_centred(a: np.ndarray, b: np.ndarray) -> float:
    """RMSE of a - b with both means removed (how the published errors are computed)."""
    e = (a - a.mean()) - (b - b.mean())
    return float(np.sqrt(np.mean(e**2)))


def main() -> None:
    t0 = time.perf_counter()
    data = np.load(bid.benchmarks.shared_data_folder(Path(__file__).parent) / "piezo_actuator_hysteresis" / "piezo.npz")
    u_id, y_id = data["model_u_V"], data["model_y"]
    u_t, y_t, desired = data["test_u_V"], data["test_y"], data["test_col9"]
    scaling = Scaling.auto(u_id, y_id)
    um = abs(scaling.output_scale)
    U, Y = scaling.input_to_model(u_id), scaling.output_to_model(y_id)
    cascade = fit_structure("cascade", U, Y, dict(na=1, nb=1, degree=3), WARMUP)[0].model
    sandwich = fit_structure("sandwich", U, Y, dict(na=2, nb=2, nr=2, ns=2, degree=3), WARMUP)[0].model
    print(f"identified on the identification record ({U.size} samples): {cascade!r}\n")

    print("| test run | tracking error on the device, published [µm] | uncompensated, simulated on the identified cascade [µm] "
          "| compensated, simulated on the identified cascade [µm] | compensated, simulated on the sandwich 2/2-2/2 [µm] "
          "| voltage range of the compensator [V] | free-run simulation error of the cascade, measured voltage in [µm] |")
    print("|---|---|---|---|---|---|---|")
    shown = {}
    for name, (a, b) in RUNS.items():
        TU, TY = scaling.input_to_model(u_t[a:b]), scaling.output_to_model(y_t[a:b])
        state = bid.estimate_state(cascade, TU[:INIT], TY[:INIT])
        target = scaling.output_to_model(desired[a:b] + y_t[a:b].mean())  # the run's operating point
        u_comp = bid.compensate(cascade, target, initial_state=state)
        sim = cascade.simulate(u_comp, initial_state=state)
        other = sandwich.simulate(u_comp, initial_state=bid.estimate_state(sandwich, TU[:INIT], TY[:INIT]))
        open_loop = cascade.simulate(TU, initial_state=state)  # the authors' applied voltage, this run
        free_run = bid.simulate_from_samples(cascade, TU, TY, INIT)
        volts = scaling.input_from_model(u_comp)
        keep = slice(INIT, None)
        row = [
            f"{PUBLISHED[name]:.2f}",
            f"{um * rmse_centred(open_loop[keep], target[keep]):.3f}" if name.startswith("run 2") else "- (their inverse applied)",
            f"{um * rmse_centred(sim[keep], target[keep]):.2e}",
            f"{um * rmse_centred(other[keep], target[keep]):.3f}",
            f"{volts.min():.2f} to {volts.max():.2f}",
            f"{um * float(np.sqrt(np.mean((free_run - TY)[keep] ** 2))):.3f}",
        ]
        print(f"| {name} [{a}:{b}] | " + " | ".join(row) + " |")
        shown[name] = (a, b, volts, scaling.output_from_model(sim), scaling.output_from_model(other), scaling.output_from_model(open_loop))

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    a, b, volts, sim, other, open_loop = shown["run 2 (open loop)"]
    tt = np.arange(b - a) / FS
    level = y_t[a:b].mean()
    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    axes[0].plot(tt, desired[a:b], color="k", lw=1.2, label="desired displacement")
    axes[0].plot(tt, open_loop - level, color="C3", lw=0.8, label="uncompensated (authors' voltage), simulated")
    axes[0].plot(tt, sim - level, color="C0", lw=0.8, ls="--", label="compensated, simulated on the identified cascade")
    axes[0].set_ylabel("displacement [µm]")
    axes[0].legend(fontsize=8, loc="upper left")
    axes[1].plot(tt, open_loop - level - desired[a:b], color="C3", lw=0.8, label="uncompensated, cascade")
    axes[1].plot(tt, other - other.mean() - (desired[a:b] - desired[a:b].mean()), color="C2", lw=0.8, label="compensated, on the sandwich 2/2-2/2")
    axes[1].plot(tt, sim - level - desired[a:b], color="C0", lw=0.8, label="compensated, on the cascade")
    axes[1].set_ylabel("tracking error [µm]\n(simulation)")
    axes[1].legend(fontsize=8, loc="upper left")
    axes[2].plot(tt, u_t[a:b], color="C3", lw=0.8, label="authors' open-loop voltage")
    axes[2].plot(tt, volts, color="C0", lw=0.8, label="compensator's voltage")
    axes[2].set_ylabel("voltage [V]")
    axes[2].set_xlabel("time [s] (test run 2)")
    axes[2].legend(fontsize=8, loc="upper left")
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.suptitle("Piezo actuator, test run 2: compensation simulated on the identified model", fontsize=11)
    fig.tight_layout()
    out = Path(__file__).resolve().parents[1] / "figures" / "piezo_compensation.png"
    fig.savefig(out, dpi=110)
    plt.close(fig)
    print(f"\nwrote {out}; total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
