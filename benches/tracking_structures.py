"""Online identification of the sandwich (Example 2) and of an input-backlash drive (issue 33's
"Done when"), each with its own generator written from the plant's physics (numpy and
scipy.signal, not the package's simulators), SNR 25.

    python benches/tracking_structures.py                   # the quoted seeds 0..19
    python benches/tracking_structures.py --seeds 100-102   # development
    python benches/tracking_structures.py --png figs        # also the figures of the first seed

The rules, frozen before the quoted seeds were run (developed on seeds >= 100):

- Plants (generators below, per-sample loops for the play, ``scipy.signal.lfilter`` for the
  linear blocks, from rest):
  - sandwich: the paper's Example 2 (input block a = (0.8, 0.2), b = (0.2, -0.2); backlash
    c_L 0.4, c_R 0.5, cubic branches m_L = (1, 0.1, 0.3), m_R = (0.75, 0.2, 0.6); output
    block r = (1, 0.15), s = (-0.2, 0.35));
  - input backlash: a motor angle u(t-1) -> a play of half-widths gamma_L = 0.3, gamma_R =
    0.25 (in the motor's units) with slightly curved contacts L(v) = (v + gamma_L) + 0.15 (v +
    gamma_L)^2, R(v) = 1.05 (v - gamma_R) - 0.1 (v - gamma_R)^2 -> a load lag of unit static
    gain w = (0.08 q^-1 + 0.04 q^-2) / (1 - 1.3 q^-1 + 0.42 q^-2) y (poles 0.7, 0.6). Its
    true model parameters (the sandwich with x(t) = a_1 u(t-1), m_L1 = r_1 = 1) are mapped
    here from the physics: a_1 = beta_1 lambda_1, c = a_1 gamma, m_i = beta_1 lambda_i /
    a_1^i, r_2 = beta_2 / beta_1.
  Input: uniform white in [-1, 1]. Noise: Gaussian, std = std(clean output) / 25.
- Drift: both widths grow linearly by 50 % over N = 1e6 samples (sample by sample; the truth
  is that trajectory). Tracker: the recursive prediction-error method, forgetting 0.999,
  started from the batch fit on the record's first 5000 samples (``fit_sandwich(.., 2, 2, 2,
  2, 3)`` / ``fit_hammerstein_backlash(.., 2, 2, 2)``: its model, covariance and noise level)
  and run over the whole record from sample 0. The regression (eq 33 by RLS) beside it for
  comparison. Settling 10000 samples. Pass: every parameter within 3 of its reported
  standard errors of the true trajectory on >= 95 % of the samples after the settling, for
  every seed.

Measured 2026-11-29 on the shared 2-core machine (quoted seeds 0..19, rules as above):

- sandwich: lowest per-parameter share within 3 s.e. after the settling 0.9873 (median over
  seeds 0.9929), 20/20 seeds pass; the regression (eq 33 by RLS) 0.45-0.52 on c_R, 0/20;
- input backlash: lowest 0.9941 (median 0.9953), 20/20 pass; the regression 0.000 on s_1,
  0/20 (the measured w lags in eq 33's row: an equation error, biased by the noise through
  the load's slow poles).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from scipy.signal import lfilter

import backlashid as bid

N = 1_000_000
LAMBDA = 0.999
START = 5000
SETTLE = 10_000
SNR = 25.0


def seeds(text: str) -> list[int]:
    lo, _, hi = text.partition("-")
    return list(range(int(lo), int(hi or lo) + 1))


def play(x: np.ndarray, c_left: np.ndarray, c_right: np.ndarray, left: list[float], right: list[float]) -> np.ndarray:
    """The driven side of a play with curved contacts, from rest: it stays where it is until
    the driver x reaches a contact; pushed down it follows the lower contact curve L(x) =
    sum_i left[i-1] (x + c_left)^i, pushed up the upper one R(x) = sum_i right[i-1] (x -
    c_right)^i (widths per sample)."""
    out = np.empty(x.size)
    held = 0.0
    for t, xt in enumerate(x.tolist()):
        s = xt + c_left[t]
        lower = sum(m * s ** (i + 1) for i, m in enumerate(left))
        if lower <= held:
            held = lower
        else:
            s = xt - c_right[t]
            upper = sum(m * s ** (i + 1) for i, m in enumerate(right))
            if upper >= held:
                held = upper
        out[t] = held
    return out


def noisy(w: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    return w + w.std() / SNR * rng.standard_normal(w.size)


def growing(base: float, n: int) -> np.ndarray:
    """A width growing linearly by 50 % over n samples."""
    return base * (1.0 + 0.5 * np.arange(n) / n)


class Sandwich:
    """Example 2 (eq 29), sample t's input block x(t) = sum a_i u(t-i) - sum b_j x(t-j)."""

    name = "sandwich (Example 2)"
    a, b = (0.8, 0.2), (0.2, -0.2)
    c_left, c_right = 0.4, 0.5
    left, right = [1.0, 0.1, 0.3], [0.75, 0.2, 0.6]
    r, s = (1.0, 0.15), (-0.2, 0.35)
    names = bid.identify.Structure(2, 2, 3, 2, 2).names

    def output(self, u: np.ndarray, c_left: np.ndarray, c_right: np.ndarray) -> np.ndarray:
        x = lfilter([0.0, *self.a], [1.0, *self.b], u)
        y = play(x, c_left, c_right, self.left, self.right)
        return lfilter([0.0, *self.r], [1.0, *self.s], y)

    def truth(self, c_left: np.ndarray, c_right: np.ndarray) -> np.ndarray:
        row = [*self.a, *self.b, 0.0, *self.left[1:], self.right[0], 0.0, *self.right[1:], *self.r[1:], *self.s]
        true = np.tile(row, (c_left.size, 1))
        true[:, self.names.index("c_L")] = c_left
        true[:, self.names.index("c_R")] = c_right
        return true

    def fit(self, u: np.ndarray, w: np.ndarray) -> bid.FitResult:
        return bid.fit_sandwich(u, w, 2, 2, 2, 2, 3)


class InputBacklash:
    """Motor angle -> play with curved contacts -> load lag of unit static gain (module header)."""

    name = "input backlash (motor -> play -> load)"
    gamma_left, gamma_right = 0.3, 0.25
    lam, rho = [1.0, 0.15], [1.05, -0.1]
    beta, alpha = (0.08, 0.04), (-1.3, 0.42)
    names = bid.identify.Structure(1, 0, 2, 2, 2).names

    def output(self, u: np.ndarray, g_left: np.ndarray, g_right: np.ndarray) -> np.ndarray:
        v = np.concatenate([[0.0], u[:-1]])  # the play acts on u(t-1)
        y = play(v, g_left, g_right, self.lam, self.rho)
        return lfilter([0.0, *self.beta], [1.0, *self.alpha], y)

    def truth(self, g_left: np.ndarray, g_right: np.ndarray) -> np.ndarray:
        b1 = self.beta[0]
        a1 = b1 * self.lam[0]
        row = [a1, 0.0, b1 * self.lam[1] / a1**2, b1 * self.rho[0] / a1, 0.0, b1 * self.rho[1] / a1**2, self.beta[1] / b1, *self.alpha]
        true = np.tile(row, (g_left.size, 1))
        true[:, self.names.index("c_L")] = a1 * g_left
        true[:, self.names.index("c_R")] = a1 * g_right
        return true

    def fit(self, u: np.ndarray, w: np.ndarray) -> bid.FitResult:
        return bid.fit_hammerstein_backlash(u, w, 2, 2, 2)

    @property
    def c_left(self) -> float:
        return self.gamma_left

    @property
    def c_right(self) -> float:
        return self.gamma_right


PLANTS = {"sandwich": Sandwich(), "input_backlash": InputBacklash()}


def drift_case(key: str, seed: int, png: Path | None) -> dict[str, np.ndarray]:
    """Per method, the share of samples after the settling with each parameter within 3
    standard errors of the true trajectory."""
    plant = PLANTS[key]
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1.0, 1.0, N)
    c_left, c_right = growing(plant.c_left, N), growing(plant.c_right, N)
    w = noisy(plant.output(u, c_left, c_right), rng)
    true = plant.truth(c_left, c_right)
    fit = plant.fit(u[:START], w[:START])
    out = {}
    for method in ("prediction_error", "regression"):
        r = bid.track(u, w, fit, method=method, forgetting=LAMBDA, detector=False)
        z = np.abs(r.theta - true) / r.standard_errors
        out[method] = (z[SETTLE:] <= 3).mean(axis=0)
        if png is not None and method == "prediction_error":
            png.mkdir(parents=True, exist_ok=True)
            step = 1000
            thin = bid.tracking.TrackResult(r.names, r.samples[::step], r.theta[::step], r.standard_errors[::step], r.alarms, r.noise_std)
            thin.plot(truth=true[::step], reference=fit, path=str(png / f"tracking_drift_{key}.png"))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", default="0-19", help="seed range, e.g. 0-19 (quoted) or 100-102 (development)")
    parser.add_argument("--plants", default="sandwich,input_backlash", help="comma-separated: sandwich, input_backlash")
    parser.add_argument("--png", type=Path, default=None, help="folder for the figures of the first seed")
    args = parser.parse_args()
    chosen = seeds(args.seeds)
    for key in args.plants.split(","):
        plant = PLANTS[key]
        print(f"{plant.name}, SNR {SNR:g}, seeds {args.seeds}; tracker: prediction error, lambda {LAMBDA}, start = fit on {START} samples")
        t0 = time.perf_counter()
        worst = {m: [] for m in ("prediction_error", "regression")}
        for k, s in enumerate(chosen):
            cov = drift_case(key, s, args.png if k == 0 else None)
            for m in worst:
                worst[m].append(cov[m].min())
            pe = cov["prediction_error"]
            low = ", ".join(f"{plant.names[i]} {pe[i]:.3f}" for i in np.argsort(pe)[:2])
            reg = cov["regression"]
            print(f"  drift seed {s}: lowest coverage {low}; regression's lowest {reg.min():.3f} ({plant.names[int(reg.argmin())]})")
        pe = np.array(worst["prediction_error"])
        reg = np.array(worst["regression"])
        print(
            f"DRIFT {key} (widths +50 % over 1e6, settling {SETTLE}): lowest per-parameter share within 3 s.e. "
            f"{pe.min():.4f} (median over seeds {np.median(pe):.4f}); seeds passing (>= 0.95): {(pe >= 0.95).sum()}/{pe.size}; "
            f"regression: lowest {reg.min():.3f}, passing {(reg >= 0.95).sum()}/{pe.size}  [{time.perf_counter() - t0:.0f} s]"
        )


if __name__ == "__main__":
    main()
