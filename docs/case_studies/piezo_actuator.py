"""Case study: a piezoelectric actuator (voltage to displacement, Aye & Ang 2018). Structures
fitted on the identification record (a single-amplitude 1 Hz sine), chosen on its held-out
tail, simulated free-run on the test record (amplitude rising and falling: minor loops), the gap
of the best cascade diagnosed on the test record, and the simulation error in µm beside the
published tracking errors of the device.

Regenerates the figures of docs/case_study_piezo_actuator.md and prints its tables in Markdown:

    python docs/case_studies/piezo_actuator.py      # writes docs/figures/piezo_*.png

Run time 25 to 40 s on the project's 2-core machine (the twelve fits take most of it). Deterministic (no random starts).

Data: shared/data/piezo_actuator_hysteresis/piezo.npz (read in place; $BACKLASHID_DATA
overrides), MIT licence, Y. N. Aye and W. T. Ang 2018 (GitHub yan9a/DiscreteBacklashOperator).
Input: actuator voltage [V]; output: capacitive sensor reading, its mean over the identification
record removed, read as µm (as the authors do); 200 Hz.

- Choice: every structure is fitted on the first 70 % of the identification record and scored
  on the rest (free run, state from the first INIT samples of the tail); the lowest RMSE within
  2 % with the fewest parameters wins and is refitted on the whole record. The test record
  chooses nothing.
- Test: free-run simulation of the whole test record (its three runs), the state estimated on
  its first INIT samples; RMSE in µm per run. This is a simulation error of the model (the
  measured voltage in, the modelled displacement out), not a tracking error.
- Reference: the published 1.68 µm (no compensation) and 0.58 µm (inverse-model feedforward)
  are tracking errors of the device (desired displacement, column 9, against the measured one).
  The script recomputes them from the record (runs 2 and 3, means removed, with and without the
  authors' one-sample lag) so the page can say what they are.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np
from _fits import fit_structure, print_candidates  # docs/case_studies/_fits.py, beside this script

import backlashid as bid
from backlashid.identify import Scaling

FS = 200.0
WARMUP = 200  # the first period: the record starts on the initial loading curve
INIT = 50  # samples that set the state of a record's free run (left out of its score)
SPLIT = 5000  # test run 1 (fading amplitude: minor loops) before, runs 2 and 3 after
HEAD = 0.7  # share of the identification record fitted when choosing the structure
# the test record's three runs (sample ranges, README): 1 as recorded, 2 open loop ("no H inv"),
# 3 with the authors' inverse-model feedforward ("with H inv"); 1 and 2 fade out at their ends
RUNS = {"run 1": (INIT, 3900), "run 2 (open loop)": (5052, 10100), "run 3 (with inverse)": (11152, 14155)}
PUBLISHED = {"run 2 (open loop)": 1.68, "run 3 (with inverse)": 0.58}
STRUCTURES: list[tuple[str, str, dict[str, int]]] = [
    ("cascade 1/1, degree 2", "cascade", dict(na=1, nb=1, degree=2)),
    ("cascade 1/1, degree 3", "cascade", dict(na=1, nb=1, degree=3)),
    ("cascade 2/2, degree 3", "cascade", dict(na=2, nb=2, degree=3)),
    ("input backlash 1/1, degree 3", "hammerstein", dict(nr=1, ns=1, degree=3)),
    ("sandwich 1/1-1/1, degree 3", "sandwich", dict(na=1, nb=1, nr=1, ns=1, degree=3)),
    ("sandwich 2/2-2/2, degree 3", "sandwich", dict(na=2, nb=2, nr=2, ns=2, degree=3)),
]


def free_run(model: Any, u: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The free run of a record from the state estimated on its first INIT samples."""
    if isinstance(model, (bid.CascadeModel, bid.SandwichModel)):
        return bid.simulate_from_samples(model, u, y, INIT)
    from backlashid.diagnosis import estimated_start

    sim = model.simulator(0.0)
    _, y0 = estimated_start(lambda v, y0, held: sim(v, y0, True), u[:INIT], y[:INIT], (float(y.min()), float(y.max())))
    return sim(u, y0, True)


def rmse(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e**2)))


def main() -> None:
    start_all = time.perf_counter()
    data = np.load(bid.benchmarks.shared_data_folder(Path(__file__).parent) / "piezo_actuator_hysteresis" / "piezo.npz")
    out = Path(__file__).resolve().parents[1] / "figures"
    u_id, y_id = data["model_u_V"], data["model_y"]
    u_t, y_t, desired = data["test_u_V"], data["test_y"], data["test_col9"]
    assert float(data["fs"]) == FS
    # model units: zero mean, unit std on the identification record; errors * output_scale are µm
    scaling = Scaling.auto(u_id, y_id)
    um = abs(scaling.output_scale)
    U, Y = scaling.input_to_model(u_id), scaling.output_to_model(y_id)
    TU, TY = scaling.input_to_model(u_t), scaling.output_to_model(y_t)
    head = int(HEAD * U.size)
    print(f"identification {U.size} samples (head {head} fitted for the choice), test {TU.size}; 1 model unit = {um:.4g} µm\n")

    # 1. the structures: chosen on the identification record's tail, scored on the test record
    print("| structure | parameters | valid backlash | RMSE on the identification tail [µm] | " + " | ".join(f"test {k} [µm]" for k in RUNS) + " |")
    print("|---|---|---|---|" + "---|" * len(RUNS))
    rows = []
    for label, kind, kw in STRUCTURES:
        result, valid = fit_structure(kind, U[:head], Y[:head], kw, WARMUP)
        tail = um * rmse((free_run(result.model, U[head:], Y[head:]) - Y[head:])[INIT:])
        whole, _ = fit_structure(kind, U, Y, kw, WARMUP)
        e_t = um * (free_run(whole.model, TU, TY) - TY)
        test = {k: rmse(e_t[a:b]) for k, (a, b) in RUNS.items()}
        rows.append((label, kind, len(result.parameters), tail, whole.model, test))
        print(f"| {label} | {len(result.parameters)} | {'yes' if valid else 'no'} | {tail:.3f} | " + " | ".join(f"{v:.3f}" for v in test.values()) + " |")
    lowest = min(r[3] for r in rows)
    chosen = min((r for r in rows if r[3] <= 1.02 * lowest), key=lambda r: (r[2], r[3]))
    cascades = [r for r in rows if r[1] == "cascade"]
    best_cascade = min((r for r in cascades if r[3] <= 1.02 * min(c[3] for c in cascades)), key=lambda r: (r[2], r[3]))
    print(f"\nchosen (lowest tail RMSE within 2 %, fewest parameters): {chosen[0]}; diagnosed cascade: {best_cascade[0]}\n")

    # 2. the diagnosis of the cascade: estimation = identification record, validation = test record
    cascade = best_cascade[4]
    t = time.perf_counter()
    report = bid.diagnose(cascade, estimation=(U, Y), validation=(TU, TY))
    print(report.summary())
    print(f"\ndiagnosis took {time.perf_counter() - t:.2f} s (model units; 1 unit = {um:.4g} µm)\n")
    top = print_candidates(report, best_cascade[0], um, "the test record", "test RMSE [µm]")
    print(f"\nbest augmented model: {best_cascade[0]} + {top.effect} ({'named' if report.best else 'not named: ' + report.best_effect})\n")

    # 2b. the same diagnosis with minor loops in the estimation record: test run 1 (its amplitude
    # fades to zero) estimates the candidates, runs 2 and 3 validate (never fitted, never chosen on)
    t = time.perf_counter()
    report1 = bid.diagnose(cascade, estimation=(TU[:SPLIT], TY[:SPLIT]), validation=(TU[SPLIT:], TY[SPLIT:]))
    print(report1.summary())
    print(f"\ndiagnosis took {time.perf_counter() - t:.2f} s\n")
    top1 = print_candidates(report1, best_cascade[0], um, "runs 2 and 3", "RMSE on runs 2 and 3 [µm]")
    print(f"\nbest augmented model, estimated on run 1: {top1.effect} ({'named' if report1.best else 'not named: ' + report1.best_effect})\n")

    # 3. simulation error per run beside the device's tracking errors
    late = np.full(TY.size, np.nan)
    late[SPLIT:] = free_run(top1.model, TU[SPLIT:], TY[SPLIT:])
    run1_label = f"{best_cascade[0]} + {top1.effect} (estimated on run 1)"
    sims = {
        best_cascade[0]: free_run(cascade, TU, TY),
        f"{best_cascade[0]} + {top.effect}": free_run(top.model, TU, TY),
        run1_label: late,
    }
    if chosen[0] != best_cascade[0]:
        sims[chosen[0]] = free_run(chosen[4], TU, TY)
    print("| test run | tracking error, published [µm] | tracking error from the record, lag 0 / 1 [µm] | " + " | ".join(f"simulation error, {k} [µm]" for k in sims) + " |")
    print("|---|---|---|" + "---|" * len(sims))
    for name, (a, b) in RUNS.items():
        tracking = []
        for lag in (0, 1):
            y, r = y_t[a + lag : b], desired[a : b - lag]
            tracking.append(rmse((y - y.mean()) - (r - r.mean())))
        pub = f"{PUBLISHED[name]:.2f}" if name in PUBLISHED else "-"
        cells = " | ".join("-" if np.isnan(s[a]) else f"{um * rmse((s - TY)[a:b]):.3f}" for s in sims.values())
        print(f"| {name} [{a}:{b}] | {pub} | {tracking[0]:.2f} / {tracking[1]:.2f} | {cells} |")
    for name, (a, b) in RUNS.items():
        e = um * (list(sims.values())[0] - TY)[a:b]
        print(f"{name}: simulation error of {best_cascade[0]} with the run's mean error removed {float(np.std(e)):.3f} µm (mean of simulated - measured {float(np.mean(e)):+.3f} µm)")
    for name, rep in (("identification record", report), ("run 1", report1)):
        print(f"estimation on the {name}: regime sample shares add up to {100 * sum(r.sample_share for r in rep.regimes.regimes):.0f} %")
    e_id = um * (free_run(cascade, U, Y) - Y)[WARMUP:]
    print(f"\nsimulation error of {best_cascade[0]} on the identification record after the warm-up: {rmse(e_id):.3f} µm")

    # 4. figures
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    shown = Scaling(scaling.input_offset, scaling.input_scale, 0.0, scaling.output_scale)  # µm, mean removed
    report.plot(out / "piezo_dashboard.png", scaling=shown, output="displacement [µm]", sample_time=1 / FS, window=600)
    report1.plot(out / "piezo_dashboard_run1.png", scaling=shown, output="displacement [µm]", sample_time=1 / FS, window=600)
    labels = list(sims)[:3]
    nominal, augmented, minor = (scaling.output_from_model(sims[k]) - scaling.output_offset for k in labels)
    measured = y_t - scaling.output_offset
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.6), gridspec_kw=dict(width_ratios=[1.5, 1]))
    a, b = 5052, 6652  # run 2: the amplitude rising over the first 8 s
    tt = np.arange(a, b) / FS
    ax = axes[0]
    ax.plot(tt, 0.1 * measured[a:b], color="0.7", lw=0.8, label="measured displacement / 10 (for the phase)")
    ax.plot(tt, measured[a:b] - nominal[a:b], color="C0", lw=1.0, label=f"measured - {labels[0]}")
    ax.plot(tt, measured[a:b] - augmented[a:b], color="C1", lw=0.8, label=f"measured - {labels[1]}")
    ax.plot(tt, measured[a:b] - minor[a:b], color="C2", lw=1.0, label=f"measured - {labels[2]}")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("simulation error [µm]")
    ax.set_title("Test run 2, amplitude rising: simulation error", fontsize=10)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=1)
    ax.grid(alpha=0.3)
    ax = axes[1]
    sl = slice(5452, 6252)  # four periods of the rising amplitude: minor loops
    ax.plot(u_t[sl], measured[sl], color="k", lw=1.2, label="measured")
    ax.plot(u_t[sl], nominal[sl], color="C0", lw=1.0, label=labels[0])
    ax.plot(u_t[sl], minor[sl], color="C2", lw=1.0, ls="--", label=labels[2])
    ax.set_xlabel("voltage [V]")
    ax.set_ylabel("displacement [µm]")
    ax.set_title(f"Minor loops (test run 2, {sl.start / FS:.1f}-{sl.stop / FS:.1f} s)", fontsize=10)
    ax.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=1)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "piezo_simulation.png", dpi=110)
    plt.close(fig)
    print(f"\nwrote {out / 'piezo_dashboard.png'}, {out / 'piezo_dashboard_run1.png'} and {out / 'piezo_simulation.png'}")
    print(f"total {time.perf_counter() - start_all:.0f} s")


if __name__ == "__main__":
    main()
