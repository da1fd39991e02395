"""Case study: the friction damper with backlash. A nominal model chosen among cascades,
sandwiches and an input backlash by its error on harmonic records not used for fitting, the gap
of the best cascade diagnosed on those records, and every model scored on the four earthquake
records beside the LuGre baseline.

Regenerates the figures of docs/case_study_friction_damper.md and prints its tables in Markdown:

    python docs/case_studies/friction_damper.py     # writes docs/figures/friction_damper_*.png

Run time 30 to 45 s on the project's 2-core machine (the eight structure fits take most of it).
Deterministic: no random starts, the same numbers on every run of the same code.

Data: shared/data/friction_damper_backlash (read in place; $BACKLASHID_DATA overrides), CC BY-SA
4.0, Coble et al. 2022. Input: imposed displacement x_in [in]; output: friction force F_kip [kip];
decimated by 8 (1024 Hz to 128 Hz).

- Fit: the six 36 lb harmonic tests at 0.25 and 1 Hz (0.5, 1 and 1.5 in), one model of the six
  records (``fit_cascade([u1, ..], [y1, ..])``, each record from its own estimated state).
- Selection and diagnosis: the four 36 lb harmonic tests at 0.5 and 2 Hz, never used in a fit.
  The structure with the lowest mean validation NRMSE is the nominal model; ``diagnose`` takes it
  (any chain) with the six fit records as estimation and the four validation records as
  validation, each record started from its own estimated state (lists of records, not joined).
- Scores: NRMSE = RMSE / range of the measured force, of the free-run simulation, on the
  companion paper's evaluation windows of the four earthquake records, beside the LuGre
  baseline of the data folder's README. The state at the window's start comes from the
  samples before it only, as the diagnosis starts a record: the nominal models by
  ``simulate_from_samples`` on them, the diagnosed model (``report.model``) from its nominal
  part's estimated state with its own internal state refitted to the same samples. The
  earthquake windows choose nothing.
"""

from __future__ import annotations

import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from _fits import fit_structure, print_candidates  # docs/case_studies/_fits.py, beside this script

import backlashid as bid
from backlashid.app import Record, decimate, load_record
from backlashid.identify import Scaling

DECIMATE = 8  # 1024 Hz -> 128 Hz: the motion is slow, the identification needs samples that change
DT = DECIMATE / 1024.0
WARMUP = 20
INIT = 64  # samples (0.5 s) that set the state of a harmonic validation record, left out of its score
PREVIOUS = "1Hz36lbtension0.5amplitude"  # the previous page's one estimation record
FIT_FREQS = ("0.25Hz", "1Hz")  # the 36 lb tests at these frequencies are fitted, the others validate
# the companion paper's scored windows (samples at 1024 Hz) and the LuGre NRMSE there (data README)
WINDOWS = {"ImperialValleyDBE": (3072, 7680), "ImperialValleyMCE": (3072, 7680), "KocaeliDBE": (6144, 14336), "KocaeliMCE": (6144, 14336)}
LUGRE_NRMSE = {"ImperialValleyDBE": 0.058, "ImperialValleyMCE": 0.076, "KocaeliDBE": 0.121, "KocaeliMCE": 0.094}
# the structures compared (fixed before any earthquake window was scored)
STRUCTURES: list[tuple[str, str, dict[str, int]]] = [
    ("cascade 2/2, degree 1", "cascade", dict(na=2, nb=2, degree=1)),
    ("cascade 2/2, degree 2", "cascade", dict(na=2, nb=2, degree=2)),
    ("cascade 3/3, degree 2", "cascade", dict(na=3, nb=3, degree=2)),
    ("input backlash, 3/3, degree 2", "hammerstein", dict(nr=3, ns=3, degree=2)),
    ("sandwich 2/2-2/2, degree 1", "sandwich", dict(na=2, nb=2, nr=2, ns=2, degree=1)),
    ("sandwich 2/2-2/2, degree 2", "sandwich", dict(na=2, nb=2, nr=2, ns=2, degree=2)),
    ("sandwich 2/2-2/2, degree 3", "sandwich", dict(na=2, nb=2, nr=2, ns=2, degree=3)),
    ("sandwich 3/3-2/2, degree 2", "sandwich", dict(na=3, nb=3, nr=2, ns=2, degree=2)),
]


def nrmse(measured: np.ndarray, simulated: np.ndarray) -> float:
    e = simulated - measured
    return float(np.sqrt(np.mean(e**2)) / np.ptp(measured))


def tests_36lb(folder: Path) -> dict[str, Record]:
    names = sorted(p.name for p in folder.glob("d2_char_*36lbtension*.npz"))
    return {n.removeprefix("d2_char_").removesuffix(".npz"): decimate(load_record(folder / n, "x_in", "F_kip"), DECIMATE) for n in names}


def simulate(model: Any, u: np.ndarray, y: np.ndarray, init: int) -> np.ndarray:
    """Free run over the whole record, the state at sample 0 set from the first ``init`` samples
    only: ``simulate_from_samples`` for a cascade, a sandwich and the diagnosed model (which starts
    from its nominal part's estimated state, its own internal state refitted, as the diagnosis
    starts a record)."""
    return np.asarray(bid.simulate_from_samples(model, u, y, init))


def main() -> None:
    start_all = time.perf_counter()
    folder = bid.benchmarks.shared_data_folder(Path(__file__).parent) / "friction_damper_backlash"
    out = Path(__file__).resolve().parents[1] / "figures"
    tests = tests_36lb(folder)
    fit_names = [n for n in tests if n.split("36lb")[0] in FIT_FREQS]
    val_names = [n for n in tests if n not in fit_names]
    quakes = {name: decimate(load_record(folder / f"d2_eq_{name}.npz", "x_in", "F_kip"), DECIMATE) for name in WINDOWS}
    scaling = Scaling.auto(np.concatenate([tests[n].u for n in fit_names]), np.concatenate([tests[n].y for n in fit_names]))
    to_u, to_y = scaling.input_to_model, scaling.output_to_model
    U, Y = [to_u(tests[n].u) for n in fit_names], [to_y(tests[n].y) for n in fit_names]
    print("fitted:", ", ".join(fit_names))
    print("validation:", ", ".join(val_names))
    print(f"scaling: {scaling.to_dict()}\n")

    def validation_scores(model: Any, sc: Scaling = scaling) -> list[float]:
        scores = []
        for n in val_names:
            u, y = sc.input_to_model(tests[n].u), sc.output_to_model(tests[n].y)
            scores.append(nrmse(y[INIT:], simulate(model, u, y, INIT)[INIT:]))
        return scores

    def quake_scores(model: Any, sc: Scaling = scaling) -> dict[str, float]:
        scores = {}
        for name, (a, b) in WINDOWS.items():
            rec = quakes[name]
            a, b = a // DECIMATE, b // DECIMATE
            u, y = sc.input_to_model(rec.u), sc.output_to_model(rec.y)
            scores[name] = nrmse(y[a:b], simulate(model, u, y, a)[a:b])
        return scores

    # 1. the structures, chosen by the validation records' NRMSE
    print("| structure | parameters | valid backlash | fit time [s] | " + " | ".join(n.replace("36lbtension", " ") for n in val_names) + " | mean |")
    print("|---|---|---|---|" + "---|" * (len(val_names) + 1))
    fits: dict[str, tuple[bid.FitResult, float]] = {}
    for label, kind, kw in STRUCTURES:
        t = time.perf_counter()
        result, valid = fit_structure(kind, U, Y, kw, WARMUP)
        seconds = time.perf_counter() - t
        scores = validation_scores(result.model)
        fits[label] = (result, float(np.mean(scores)))
        print(f"| {label} | {len(result.parameters)} | {'yes' if valid else 'no'} | {seconds:.1f} | " + " | ".join(f"{s:.3f}" for s in scores) + f" | {np.mean(scores):.3f} |")
    # the previous page's nominal model: one harmonic test (1 Hz, 0.5 in), its own scaling
    one = tests[PREVIOUS]
    sc_one = Scaling.auto(one.u, one.y)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        previous = bid.fit_cascade(sc_one.input_to_model(one.u), sc_one.output_to_model(one.y), na=2, nb=2, degree=3, warmup=WARMUP).model
    prev_scores = validation_scores(previous, sc_one)
    print(f"| previous: cascade 2/2, degree 3, on {PREVIOUS} alone | 9 | | | " + " | ".join(f"{x:.3f}" for x in prev_scores) + f" | {np.mean(prev_scores):.3f} |")
    best_label = min(fits, key=lambda k: fits[k][1])
    best_cascade = min((k for k, (_, kind, _) in zip(fits, STRUCTURES) if kind == "cascade"), key=lambda k: fits[k][1])
    nominal = fits[best_label][0].model
    cascade = fits[best_cascade][0].model
    print(f"\nnominal model (lowest mean validation NRMSE): {best_label}; best cascade (diagnosed): {best_cascade}\n")

    # 2. the diagnosis of the nominal model on the validation records (each its own record)
    est = [(to_u(tests[n].u), to_y(tests[n].y)) for n in fit_names]
    val = [(to_u(tests[n].u), to_y(tests[n].y)) for n in val_names]
    t = time.perf_counter()
    report = bid.diagnose(nominal, estimation=est, validation=val, init_samples=INIT)
    print(report.summary())
    print(f"\ndiagnosis took {time.perf_counter() - t:.2f} s (model units: output / {scaling.output_scale:.4g} kip)\n")
    scale = abs(scaling.output_scale)
    top = print_candidates(report, best_label, scale, "the validation records", "validation RMSE [kip]")
    named = " + ".join(report.effects)
    diagnosed_label = f"{best_label} + {named}" if named else f"{best_label} + {top.effect} (not named)"
    print(f"\ndiagnosed model: {diagnosed_label} ({report.verdict()})\n")

    # 3. the earthquake records, scored only now
    models = {best_cascade: cascade, diagnosed_label: report.model if named else top.model, best_label: nominal}
    scores = {label: quake_scores(m) for label, m in models.items()}
    labels = list(models)
    prev_quakes = quake_scores(previous, sc_one)
    print("| earthquake record (window, 1024 Hz samples) | previous nominal | " + " | ".join(labels) + " | LuGre (data README) |")
    print("|---|---|" + "---|" * (len(labels) + 1))
    for name, (a, b) in WINDOWS.items():
        cells = " | ".join(f"{scores[k][name]:.3f}" for k in labels)
        print(f"| {name} [{a}:{b}] | {prev_quakes[name]:.3f} | {cells} | {LUGRE_NRMSE[name]:.3f} |")
    for k in labels:
        ratio = np.mean([scores[k][n] / LUGRE_NRMSE[n] for n in WINDOWS])
        print(f"mean NRMSE / LuGre NRMSE, {k}: {ratio:.2f}")
    aug = labels[1]
    for n in WINDOWS:
        print(
            f"{n}: {aug} / LuGre = {scores[aug][n] / LUGRE_NRMSE[n]:.2f}; "
            f"{best_label} / LuGre = {scores[best_label][n] / LUGRE_NRMSE[n]:.2f}"
        )
    print(f"regime sample shares of the diagnosis add up to {100 * sum(r.sample_share for r in report.regimes.regimes):.0f} %")

    # 4. figures
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    report.plot(out / "friction_damper_dashboard.png", scaling=scaling, output="friction force [kip]", sample_time=DT, window=400)
    fig, axes = plt.subplots(2, 1, figsize=(10, 9))
    for ax, name in zip(axes, ("ImperialValleyDBE", "KocaeliDBE")):
        a, b = (i // DECIMATE for i in WINDOWS[name])
        rec = quakes[name]
        u, y = to_u(rec.u), to_y(rec.y)
        tt = np.arange(len(y))[a:b] * DT
        ax.plot(tt, rec.y[a:b], "k", lw=1.4, label="measured")
        styles = {best_cascade: ("C0", "-"), diagnosed_label: ("C2", "--"), best_label: ("C3", "-")}
        for label, m in models.items():
            sim = scaling.output_from_model(simulate(m, u, y, a))
            color, ls = styles[label]
            ax.plot(tt, sim[a:b], color=color, ls=ls, lw=1.0, label=f"{label} (NRMSE {scores[label][name]:.3f})")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("friction force [kip]")
        ax.set_title(f"{name}: free-run simulation on the scored window (LuGre NRMSE {LUGRE_NRMSE[name]:.3f})", fontsize=10)
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.16), fontsize=8, ncol=2)
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out / "friction_damper_simulation.png", dpi=110)
    plt.close(fig)
    print(f"\nwrote {out / 'friction_damper_dashboard.png'} and {out / 'friction_damper_simulation.png'}")
    print(f"total {time.perf_counter() - start_all:.0f} s")


if __name__ == "__main__":
    main()
