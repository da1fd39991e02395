"""Case study protocol: the LuGre friction model of the damper, fitted and scored as this page
fits and scores our models, to see what the data README's LuGre NRMSE measures.

    python docs/case_studies/friction_damper_lugre.py

Run time about 45 s on the project's 2-core machine (a per-sample reference loop in
NumPy, vectorised over the records, inside SciPy's least squares). Deterministic.

The model is the companion repository's LuGre cell (``training reproduction/lugre.py``,
``callv`` 3 with a constant sigma_0 in place of its neural network), written here from its
equations and not from any code of this package:

    g(v)   = F_c + (F_s - F_c) exp(-(v / v_s)^2)
    s(k+1) = g sgn(v) + (s(k) - g sgn(v)) exp(-dt sigma_0 |v| / g)     (s = sigma_0 z, a force)
    F      = s + sigma_1 (v - s |v| / g) + sigma_2 v + F_0

with the velocity v the record's ``v_in_s``. The companion chooses F_c, F_s between a positive and
a negative level by the sign of the **measured** force at each sample
(``train_experimental_model.py``, ``run_validation.py``: ``F_c_test = F_cneg * (F_test < 0) +
F_cpos * (F_test >= 0)``) and starts each record from the measured force at its first sample. Two
protocols are scored here:

- **free run** (this page's protocol for every model): the level follows the sign of the model's
  own friction state s; no measured force enters after the start. The start: s at the window's
  first sample from the measured force just before it (the companion's inversion of F = s +
  sigma_1 zdot + sigma_2 v).
- **levels from the measured force** (the companion's protocol): the same fitted parameters, the
  level chosen by the measured force's sign at each sample.

Fit: the six 36 lb harmonic tests at 0.25 and 1 Hz, decimated by 8 (128 Hz) as on the page,
each from its measured first force; scored on the page's four harmonic validation tests (from
sample 64, as the page) and on the four earthquake windows (NRMSE = RMSE / range). The
earthquakes choose nothing.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from friction_damper import DECIMATE, DT, FIT_FREQS, INIT, LUGRE_NRMSE, WINDOWS, nrmse  # the page's protocol, beside this script
from scipy.optimize import least_squares

import backlashid as bid
from backlashid.app import decimate, load_record

NAMES = ("sigma_0", "sigma_1", "sigma_2", "F_c+", "F_c-", "F_s+ - F_c+", "F_s- - F_c-", "v_s", "F_0")


def levels(theta: np.ndarray) -> tuple[float, float, float, float]:
    _, _, _, fcp, fcm, dsp, dsm, _, _ = theta
    return fcp, fcm, fcp + dsp, fcm + dsm


def lugre(theta: np.ndarray, v: np.ndarray, f_start: np.ndarray, f_sign: np.ndarray | None = None) -> np.ndarray:
    """Forces of the LuGre model along velocities ``v`` (steps x records), each record started
    from its measured force ``f_start``; the level follows the sign of ``f_sign`` (measured
    forces, steps x records) when given, else of the model's own state."""
    s0, s1, s2, _, _, _, _, vs, f0 = theta
    fcp, fcm, fsp, fsm = levels(theta)

    def g_of(vk: np.ndarray, positive: np.ndarray) -> np.ndarray:
        fc, fs = np.where(positive, fcp, fcm), np.where(positive, fsp, fsm)
        return fc + (fs - fc) * np.exp(-((vk / vs) ** 2))

    out = np.empty_like(v)
    # the start: s from F = s (1 - sigma_1 |v| / g) + (sigma_1 + sigma_2) v + F_0 at the first sample
    pos = (f_start - f0 >= 0) if f_sign is None else (f_sign[0] >= 0)
    g = g_of(v[0], pos)
    s = (f_start - f0 - (s1 + s2) * v[0]) / (1.0 - s1 * np.abs(v[0]) / g)
    for k in range(v.shape[0]):
        vk = v[k]
        pos = (s >= 0) if f_sign is None else (f_sign[k] >= 0)
        g = g_of(vk, pos)
        out[k] = s + s1 * (vk - s * np.abs(vk) / g) + s2 * vk + f0
        target = g * np.sign(vk)
        s = target + (s - target) * np.exp(-DT * s0 * np.abs(vk) / g)
    return out


def padded(series: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    n = max(len(s) for s in series)
    arr = np.zeros((n, len(series)))
    mask = np.zeros((n, len(series)), dtype=bool)
    for j, s in enumerate(series):
        arr[: len(s), j], mask[: len(s), j] = s, True
    return arr, mask


def main() -> None:
    t0 = time.perf_counter()
    folder = bid.benchmarks.shared_data_folder(Path(__file__).parent) / "friction_damper_backlash"

    def record(name: str) -> tuple[np.ndarray, np.ndarray]:
        rec = decimate(load_record(folder / name, "v_in_s", "F_kip"), DECIMATE)
        return np.asarray(rec.u), np.asarray(rec.y)

    names = sorted(p.name for p in folder.glob("d2_char_*36lbtension*.npz"))
    fit_names = [n for n in names if n.removeprefix("d2_char_").split("36lb")[0] in FIT_FREQS]
    val_names = [n for n in names if n not in fit_names]
    fit = [record(n) for n in fit_names]
    v_fit, mask = padded([v for v, _ in fit])
    f_fit, _ = padded([f for _, f in fit])
    scale = np.sqrt(np.mean(np.concatenate([f for _, f in fit]) ** 2))

    def residual(theta: np.ndarray) -> np.ndarray:
        sim = lugre(theta, v_fit, f_fit[0])
        return ((sim - f_fit) / scale)[mask]

    # starts: the force's plateaus (the sliding levels), a stiff bristle, a small Stribeck velocity
    f_all = np.concatenate([f for _, f in fit])
    fcp, fcm = float(np.percentile(f_all, 95)), float(-np.percentile(f_all, 5))
    lower = [1e-2, 0.0, 0.0, 1e-2, 1e-2, -5.0, -5.0, 1e-3, -5.0]
    upper = [1e5, 50.0, 50.0, 20.0, 20.0, 5.0, 5.0, 20.0, 5.0]
    best = None
    for s0 in (5.0, 30.0, 200.0):
        for vs in (0.05, 0.5):
            x0 = np.array([s0, 0.0, 0.0, fcp, fcm, 0.0, 0.0, vs, 0.0])
            sol = least_squares(residual, x0, bounds=(lower, upper), x_scale="jac", max_nfev=400)
            print(f"start sigma_0 {s0:g}, v_s {vs:g}: cost {sol.cost:.4g} ({sol.nfev} evaluations)")
            if best is None or sol.cost < best.cost:
                best = sol
    assert best is not None
    theta = best.x
    print("\nfitted LuGre (kip, in, s): " + ", ".join(f"{n} {x:.4g}" for n, x in zip(NAMES, theta)))

    def score(v: np.ndarray, f: np.ndarray, a: int, b: int, measured_levels: bool) -> float:
        """NRMSE over [a, b), the model started at a - 1 from the measured force there."""
        sim = lugre(theta, v[a - 1 : b, None], f[a - 1 : a], f[a - 1 : b, None] if measured_levels else None)[:, 0]
        return nrmse(f[a:b], sim[1:])

    print("\n| record | LuGre, free run | LuGre, levels from the measured force |")
    print("|---|---|---|")
    for n in val_names:
        v, f = record(n)
        print(f"| {n.removeprefix('d2_char_').removesuffix('.npz')} | {score(v, f, INIT, len(f), False):.3f} | {score(v, f, INIT, len(f), True):.3f} |")

    print("\n| earthquake record (window, 1024 Hz samples) | LuGre fitted here, free run | LuGre fitted here, levels from the measured force | LuGre (data README) |")
    print("|---|---|---|---|")
    for name, (a, b) in WINDOWS.items():
        v, f = record(f"d2_eq_{name}.npz")
        a8, b8 = a // DECIMATE, b // DECIMATE
        free, told = score(v, f, a8, b8, False), score(v, f, a8, b8, True)
        print(f"| {name} [{a}:{b}] | {free:.3f} | {told:.3f} | {LUGRE_NRMSE[name]:.3f} |")
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
