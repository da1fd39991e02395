"""backlashid against plain NumPy/SciPy implementations, side by side on the same data.

Data: Example 1 (backlashid.example1()), example_data(model, N, snr=25, seed=0).

1. paper:   fit_cascade(u, y, paper=True, max_iter=K, tol=0) against the same algorithm in NumPy
            (benches/numpy_reference.py), both K iterates counting the ARX start (K = 20):
            "loop" = x and f1, f2 in a per-sample Python loop; "vectorised" = lfilter and array
            expressions (possible because the switching uses the *measured* y(t-1)).
2. default: fit_cascade(u, y) (iterations + output-error LM with exact sensitivities) against
            scipy.optimize.least_squares on the simulation error y - y_sim(theta) (2-point
            finite-difference Jacobian, y_sim = lfilter + Python backlash loop), started from
            the paper algorithm's ARX start (ARX a, b; m_R1 = 1, c_L = c_R = 0.001).
            Also fit_cascade(u, y, restarts=0): the default minus its 4 perturbed LM restarts,
            closer to the single scipy run (--no-restart-row leaves it out), and where the
            default ran its coarse stage (N >= 5e4), fit_cascade(u, y, coarse=0): the whole
            record throughout.
3. simulate: CascadeModel.simulate against lfilter + Python backlash loop.

Every (comparison, implementation, N) runs in a fresh spawned process, so the peak resident
memory (ru_maxrss) of each is its own; "base" is the peak before the timed work (interpreter,
imports and data). Times are time.perf_counter, best of --repeats for runs under 5 s.
Accuracy: max |estimate - truth| over the 11 parameters (m_L1 = 1 fixed); for the paper rows
also the agreement max |theta_lib - theta_numpy|, for simulate max |y_lib - y_numpy|.

    python benches/compare.py                    # fits at N = 1e4, 1e5; simulate at 1e5, 1e6
    python benches/compare.py --sizes 10000      # quick (about a minute)
    python benches/compare.py --profile 100000   # also cProfile of the default fit at N = 1e5
    python benches/compare.py --parts default --sizes 100000 1000000 --oe-max-n 1000000 --oe-methods trf

Needs the bench extra (pip install -e ".[bench]") for scipy.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import resource
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from typing import Any, Callable

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
if HERE not in sys.path:
    sys.path.insert(0, HERE)

SNR, SEED = 25.0, 0


# -- phases (each runs in its own process) -------------------------------------------------------


def _rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: KiB


def _data(n: int) -> tuple[Any, Any, np.ndarray]:
    import backlashid as bid

    model = bid.example1()
    data = bid.example_data(model, n, snr=SNR, seed=SEED)
    truth = bid.identify.Structure(2, 2, 3).pack(model)
    return model, data, truth


def _timed(fn: Callable[[], Any], repeats: int) -> tuple[float, Any, int]:
    """Best time of up to ``repeats`` calls; one call when the first takes over 5 s."""
    best, out, done = np.inf, None, 0
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
        done += 1
        if best > 5.0:
            break
    return best, out, done


# fit_cascade's default and the two variants compared beside it
DEFAULT_FITS: dict[str, dict[str, int]] = {"default-lib": {}, "default-lib-c0": {"coarse": 0}, "default-lib-r0": {"restarts": 0}}


def phase(kind: str, n: int, opts: dict[str, Any]) -> dict[str, Any]:
    _model, data, truth = _data(n)
    u, y = data.u, data.noisy
    import backlashid as bid
    import numpy_reference as ref

    if kind in ("paper-np-vec", "oe-scipy", "sim-np"):
        import scipy.optimize
        import scipy.signal  # noqa: F401
    base = _rss_mb()
    repeats = opts["repeats"]
    info: dict[str, Any] = {}
    if kind == "paper-lib":
        sec, res, reps = _timed(lambda: bid.fit_cascade(u, y, paper=True, max_iter=opts["k"], tol=0.0), repeats)
        theta = res.theta
        info["note"] = f"{res.iterations} iterates, {res.reason}"
    elif kind in ("paper-np-loop", "paper-np-vec"):
        loop = kind == "paper-np-loop"
        sec, res, reps = _timed(lambda: ref.fit_paper(u, y, iterations=opts["k"], loop=loop), repeats)
        theta = res[0]
        info["note"] = f"{len(res[1])} iterates"
    elif kind in DEFAULT_FITS:
        options = DEFAULT_FITS[kind]
        sec, res, reps = _timed(lambda: bid.fit_cascade(u, y, **options), repeats)
        theta = res.theta
        on = f" on the first {res.coarse_samples} samples" if res.coarse_samples else ""
        given = "".join(f" ({k}={v})" for k, v in options.items())
        info["note"] = f"{res.iterations} iterates{on} + {res.refinement_steps} LM steps{given}"
    elif kind == "oe-scipy":
        theta0 = ref.arx_start(u, y, 2, 2, 3, (1.0, 0.001, 0.001))
        run = lambda: ref.fit_output_error(  # noqa: E731
            u, y, theta0, method=opts["method"], max_nfev=opts["max_nfev"], timeout=opts["timeout"]
        )
        sec, res, reps = _timed(run, repeats)
        theta = res.theta
        info["note"] = f"{opts['method']}, {res.nfev} simulations; {res.status}"
        info["capped"] = res.status.startswith("stopped")
    elif kind == "sim-lib":
        sec, out, reps = _timed(lambda: data.model.simulate(u), repeats)
        return {"seconds": sec, "repeats": reps, "base": base, "peak": _rss_mb(), "y": out}
    elif kind == "sim-np":
        sec, out, reps = _timed(lambda: ref.simulate(truth, u), repeats)
        return {"seconds": sec, "repeats": reps, "base": base, "peak": _rss_mb(), "y": out}
    else:
        raise ValueError(kind)
    return {
        "seconds": sec,
        "repeats": reps,
        "base": base,
        "peak": _rss_mb(),
        "theta": np.asarray(theta),
        "max_err": float(np.max(np.abs(np.asarray(theta) - truth))),
        **info,
    }


def in_fresh_process(kind: str, n: int, opts: dict[str, Any]) -> dict[str, Any]:
    with ProcessPoolExecutor(max_workers=1, mp_context=mp.get_context("spawn")) as pool:
        return pool.submit(phase, kind, n, opts).result()


# -- report --------------------------------------------------------------------------------------


def fmt_s(sec: float) -> str:
    return f"{sec * 1e3:.1f} ms" if sec < 1.0 else f"{sec:.2f} s"


def row(label: str, n: int, lib: dict[str, Any], other: dict[str, Any], acc_lib: str, acc_ref: str) -> str:
    ratio = other["seconds"] / lib["seconds"]
    mem = f"{lib['peak']:.0f} ({lib['base']:.0f}) / {other['peak']:.0f} ({other['base']:.0f})"
    return (
        f"{label:<30}{n:>9}{fmt_s(lib['seconds']):>11}{fmt_s(other['seconds']):>11}{ratio:>9.1f}x"
        f"{acc_lib:>12}{acc_ref:>12}   {mem}"
    )


HEADER = (
    f"{'comparison':<30}{'N':>9}{'library':>11}{'reference':>11}{'ref/lib':>10}"
    f"{'acc lib':>12}{'acc ref':>12}   peak RSS MB lib / ref (base)"
)


def profile_default(n: int, top: int) -> None:
    import cProfile
    import pstats

    _model, data, _truth = _data(n)
    import backlashid as bid

    bid.fit_cascade(data.u, data.noisy)  # warm up
    prof = cProfile.Profile()
    prof.enable()
    bid.fit_cascade(data.u, data.noisy)
    prof.disable()
    print(f"\ncProfile of fit_cascade(u, y) (default) at N = {n}, top {top} by own time:")
    pstats.Stats(prof).sort_stats("tottime").print_stats(top)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000], help="N for the fits")
    ap.add_argument("--sim-sizes", type=int, nargs="+", default=[100_000, 1_000_000], help="N for simulate")
    ap.add_argument("--iterations", type=int, default=20, help="K, iterates of the paper algorithm")
    ap.add_argument("--repeats", type=int, default=3, help="best of this many runs (runs under 5 s)")
    ap.add_argument("--oe-methods", nargs="+", default=["trf", "lm"], choices=["trf", "lm", "dogbox"])
    ap.add_argument("--oe-max-nfev", type=int, default=3000, help="cap on least_squares evaluations")
    ap.add_argument("--oe-timeout", type=float, default=240.0, help="wall-clock cap (s) per scipy fit")
    ap.add_argument("--oe-max-n", type=int, default=100_000, help="largest N for the scipy fit")
    ap.add_argument(
        "--no-restart-row", dest="restart_row", action="store_false",
        help="leave out fit_cascade(restarts=0) (one LM refinement per candidate, like the scipy fit)",
    )
    ap.add_argument(
        "--parts", nargs="+", default=["paper", "default", "simulate"], choices=["paper", "default", "simulate"],
        help="which comparisons to run (default all three)",
    )
    ap.add_argument("--profile", type=int, default=0, metavar="N", help="cProfile the default fit at N")
    ap.add_argument("--top", type=int, default=15)
    args = ap.parse_args()

    import scipy

    import backlashid

    print(
        f"backlashid {backlashid.__version__} ({os.path.dirname(backlashid.__file__)}), numpy {np.__version__}, scipy {scipy.__version__}, "
        f"python {sys.version.split()[0]}, {os.cpu_count()} CPUs"
    )
    print(f"Example 1, SNR {SNR:g}, seed {SEED}; times best of up to {args.repeats} (single run when > 5 s)")
    print(
        f"scipy output-error fits: 2-point FD Jacobian, max_nfev = {args.oe_max_nfev}, "
        f"time cap {args.oe_timeout:g} s, N <= {args.oe_max_n}; start = ARX start of the paper algorithm\n"
    )
    print(HEADER)
    print("-" * len(HEADER))
    notes: list[str] = []
    base = {"repeats": args.repeats, "k": args.iterations}

    for n in args.sizes if "paper" in args.parts else []:
        lib = in_fresh_process("paper-lib", n, base)
        notes.append(f"paper/library N={n}: {lib['note']}")
        for kind, label in (("paper-np-loop", "paper K=%d vs NumPy loop"), ("paper-np-vec", "paper K=%d vs NumPy vectorised")):
            ref = in_fresh_process(kind, n, base)
            agree = float(np.max(np.abs(lib["theta"] - ref["theta"])))
            print(row(label % args.iterations, n, lib, ref, f"{lib['max_err']:.2e}", f"{ref['max_err']:.2e}"))
            notes.append(f"{label % args.iterations} N={n}: max |theta_lib - theta_numpy| = {agree:.1e}")
        sys.stdout.flush()

    for n in args.sizes if "default" in args.parts else []:
        lib = in_fresh_process("default-lib", n, base)
        notes.append(f"default/library N={n}: {lib['note']}")
        if n > args.oe_max_n:
            notes.append(f"scipy OE skipped at N={n} (> --oe-max-n)")
            continue
        lib0 = in_fresh_process("default-lib-r0", n, base) if args.restart_row else None
        if lib0 is not None:
            notes.append(f"default restarts=0/library N={n}: {lib0['note']}")
        whole = in_fresh_process("default-lib-c0", n, base) if "first" in lib["note"] else None
        if whole is not None:
            notes.append(f"default coarse=0/library N={n}: {whole['note']}")
        for method in args.oe_methods:
            opts = {**base, "method": method, "max_nfev": args.oe_max_nfev, "timeout": args.oe_timeout}
            ref = in_fresh_process("oe-scipy", n, opts)
            acc_ref = f"{ref['max_err']:.2e}" + ("*" if ref["capped"] else "")
            print(row(f"default vs scipy OE ({method})", n, lib, ref, f"{lib['max_err']:.2e}", acc_ref))
            if lib0 is not None:
                label = f"restarts=0 vs scipy OE ({method})"
                print(row(label, n, lib0, ref, f"{lib0['max_err']:.2e}", acc_ref))
            if whole is not None:
                label = f"coarse=0 vs scipy OE ({method})"
                print(row(label, n, whole, ref, f"{whole['max_err']:.2e}", acc_ref))
            notes.append(f"scipy OE ({method}) N={n}: {ref['note']}")
        sys.stdout.flush()

    for n in args.sim_sizes if "simulate" in args.parts else []:
        lib = in_fresh_process("sim-lib", n, base)
        ref = in_fresh_process("sim-np", n, base)
        agree = float(np.max(np.abs(lib["y"] - ref["y"])))
        print(row("simulate vs lfilter + loop", n, lib, ref, "-", "-"))
        notes.append(f"simulate N={n}: max |y_lib - y_numpy| = {agree:.1e}")
        sys.stdout.flush()

    print("\nacc = max |estimate - true| over the 11 parameters; * = the scipy fit hit its cap")
    for note in notes:
        print("  " + note)
    if args.profile:
        profile_default(args.profile, args.top)


if __name__ == "__main__":
    main()
