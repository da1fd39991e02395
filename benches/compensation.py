"""Feedforward compensation of the backlash on the paper's examples (issue 19).

    python benches/compensation.py            # N = 1500, SNR 25, seed 0
    python benches/compensation.py --n 3000 --seed 4
    python benches/compensation.py --png docs/figures/compensation_example1.png   # also the figure

For Example 1 (cascade) and Example 2 (sandwich), and for each of two compensator models -
the TRUE model and the model identified by fit_cascade / fit_sandwich from a noisy record
(N samples of uniform input, SNR 25, fixed seed) - the compensator's input drives the TRUE
model (the plant), on two smooth references:

- multisine: three sines at 0.004, 0.011 and 0.023 cycles/sample;
- trapezoid: a reversing motion profile (ramp up, dwell, ramp down, dwell).

Both are scaled to 0.9 of the half range of the example's output on its identification record
and centred on that range (the region the identified branches were fitted on).

"Uncompensated" is the same feedforward with the backlash ignored: ``compensate`` on the
same model with its backlash replaced by the straight line through the origin whose slope is
the branches' mean slope (the least-squares slope through the origin of L(x) and R(x) on the
range of x that the compensator drives), i.e. the linear blocks are still inverted, only the
dead band and the branch curvature are left out. The RMSE of the plant's output against the
reference is taken from the preview delay D on (the first D outputs are fixed by the rest
state); the ratio uncompensated / compensated is printed, and must be at least 20.

Then PI loops (the controller seeing y(t-1)) around the true Example 1 on the trapezoid,
alone and with the identified model's compensator as their feedforward (``closed_loop``), RMSE
from sample 100 on (the trapezoid starts away from the plant's rest output: the first samples
are a transient with or without the compensator). ``--png`` draws Example 1's trapezoid case
with the identified model.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np

import backlashid as bid


def multisine(n: int, centre: float, half: float) -> np.ndarray:
    """Three sines below 0.05 cycles/sample, peak ``half`` about ``centre``."""
    t = np.arange(n)
    s = np.sin(2 * np.pi * 0.004 * t) + 0.5 * np.sin(2 * np.pi * 0.011 * t + 1.0) + 0.3 * np.sin(2 * np.pi * 0.023 * t + 2.0)
    return centre + half * s / np.max(np.abs(s))


def trapezoid(n: int, centre: float, half: float, ramp: int = 120, dwell: int = 60) -> np.ndarray:
    """A reversing trapezoidal motion: ramp up, dwell, ramp down, dwell, repeated."""
    up = np.linspace(-1.0, 1.0, ramp, endpoint=False)
    period = np.concatenate([up, np.ones(dwell), -up, -np.ones(dwell)])
    s = np.concatenate([np.full(dwell // 2, -1.0), np.tile(period, n // period.size + 1)])[:n]
    return centre + half * s


def straight_backlash(bl: bid.GeneralBacklash, x: np.ndarray) -> bid.GeneralBacklash:
    """The line through the origin with the branches' mean slope over the range of ``x``."""
    grid = np.linspace(np.min(x), np.max(x), 401)
    values = np.concatenate([bl.left(grid), bl.right(grid)])
    xs = np.concatenate([grid, grid])
    k = float(xs @ values / (xs @ xs))
    return bid.GeneralBacklash(0.0, 0.0, [k], [k])


def with_backlash(model, bl):
    if isinstance(model, bid.CascadeModel):
        return bid.CascadeModel(model.linear, bl)
    return bid.SandwichModel(model.input_linear, bl, model.output_linear)


def internal_x(model, u: np.ndarray) -> np.ndarray:
    return model.simulate(u, internals=True).x


def _rmse(y: np.ndarray, r: np.ndarray, start: int) -> float:
    return float(np.sqrt(np.mean((y[start:] - r[start:]) ** 2)))


@dataclass
class Row:
    example: str
    compensator: str
    reference: str
    rmse_comp: float
    rmse_unc: float

    @property
    def ratio(self) -> float:
        return self.rmse_unc / self.rmse_comp


def measure(n: int = 1500, seed: int = 0, snr: float = 25.0, length: int = 2000) -> list[Row]:
    """Every (example, compensator model, reference) case's RMSEs."""
    rows = []
    cases = (
        ("Example 1", bid.example1(), lambda d: bid.fit_cascade(d.u, d.noisy, na=2, nb=2, degree=3)),
        ("Example 2", bid.example2(), lambda d: bid.fit_sandwich(d.u, d.noisy, na=2, nb=2, nr=2, ns=2, degree=3)),
    )
    for name, true, fit in cases:
        data = bid.example_data(true, n, snr=snr, seed=seed)
        lo, hi = float(np.min(data.clean)), float(np.max(data.clean))
        centre, half = 0.5 * (lo + hi), 0.45 * (hi - lo)
        identified = fit(data).model
        references = {"multisine": multisine(length, centre, half), "trapezoid": trapezoid(length, centre, half)}
        for label, model in (("true", true), ("identified", identified)):
            delay = bid.Compensator(model).delay
            for ref_name, r in references.items():
                u = bid.compensate(model, r)
                y = true.simulate(u)
                plain = with_backlash(model, straight_backlash(model.backlash, internal_x(model, u)))
                y_unc = true.simulate(bid.compensate(plain, r))
                rows.append(Row(name, label, ref_name, _rmse(y, r, delay), _rmse(y_unc, r, delay)))
    return rows


def figure(path: str, n: int, seed: int, snr: float, length: int = 2000) -> None:
    """Example 1, identified compensator, trapezoid: outputs, errors and inputs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    true = bid.example1()
    data = bid.example_data(true, n, snr=snr, seed=seed)
    model = bid.fit_cascade(data.u, data.noisy).model
    lo, hi = float(np.min(data.clean)), float(np.max(data.clean))
    r = trapezoid(length, 0.5 * (lo + hi), 0.45 * (hi - lo))[:800]
    u = bid.compensate(model, r)
    plain = with_backlash(model, straight_backlash(model.backlash, internal_x(model, u)))
    u_unc = bid.compensate(plain, r)
    y, y_unc = true.simulate(u), true.simulate(u_unc)
    t = np.arange(r.size)
    fig, axes = plt.subplots(3, 1, figsize=(11, 7.5), sharex=True)
    axes[0].plot(t, r, color="k", lw=1.4, label="reference")
    axes[0].plot(t, y_unc, color="C3", lw=1.0, label="backlash ignored (linear inverse only)")
    axes[0].plot(t, y, color="C0", lw=1.0, ls="--", label="compensated (identified model)")
    axes[0].set_ylabel("plant output y")
    axes[1].plot(t[1:], (y_unc - r)[1:], color="C3", lw=1.0, label=f"backlash ignored, RMSE {_rmse(y_unc, r, 1):.3f}")
    axes[1].plot(t[1:], (y - r)[1:], color="C0", lw=1.0, label=f"compensated, RMSE {_rmse(y, r, 1):.4f}")
    axes[1].set_ylabel("tracking error")
    axes[2].plot(t, u_unc, color="C3", lw=1.0, label="input, backlash ignored")
    axes[2].plot(t, u, color="C0", lw=1.0, label="input, compensated")
    axes[2].set_ylabel("input u")
    axes[2].set_xlabel("sample")
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    fig.suptitle(f"Example 1 (true plant), trapezoid: compensator of the model identified from N = {n}, SNR {snr:g} (simulation)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    print(f"wrote {path}")


def closed_loops(n: int, seed: int, snr: float, length: int = 2000) -> None:
    """A PI around the true Example 1 on the trapezoid, alone and with the identified model's
    compensator as feedforward."""
    true = bid.example1()
    data = bid.example_data(true, n, snr=snr, seed=seed)
    model = bid.fit_cascade(data.u, data.noisy).model
    lo, hi = float(np.min(data.clean)), float(np.max(data.clean))
    r = trapezoid(length, 0.5 * (lo + hi), 0.45 * (hi - lo))
    for kp, ki in ((0.1, 0.02), (0.3, 0.1)):
        alone = bid.closed_loop(true, r, kp=kp, ki=ki, warmup=100)
        both = bid.closed_loop(true, r, kp=kp, ki=ki, compensator=model, warmup=100)
        print(f"PI (kp {kp}, ki {ki}) around the true Example 1, trapezoid, from sample 100: RMSE {alone.rmse:.3e} alone, "
              f"{both.rmse:.3e} with the identified compensator ({alone.rmse / both.rmse:.3g} x)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=1500, help="identification record length")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--snr", type=float, default=25.0)
    ap.add_argument("--png", help="also draw Example 1's trapezoid case (identified compensator) here")
    args = ap.parse_args()
    t = time.perf_counter()
    rows = measure(args.n, args.seed, args.snr)
    print(f"{'example':<11}{'model':<12}{'reference':<11}{'RMSE comp':>12}{'RMSE uncomp':>13}{'ratio':>10}")
    for r in rows:
        flag = "" if r.ratio >= 20 else "  < 20"
        print(f"{r.example:<11}{r.compensator:<12}{r.reference:<11}{r.rmse_comp:>12.3e}{r.rmse_unc:>13.3e}{r.ratio:>10.3g}{flag}")
    closed_loops(args.n, args.seed, args.snr)
    if args.png:
        figure(args.png, args.n, args.seed, args.snr)
    print(f"({time.perf_counter() - t:.1f} s)")


if __name__ == "__main__":
    main()
