"""A full default cascade fit on a long record: wall time and peak memory.

    python benches/large_fit.py 1e7 1e8

Example 1 driven by uniform |u| < 1, output SNR 25. "coarse": the samples the iterations ran
on (0 = the whole record); LM: the refinement's steps on the whole record. Each size runs in a fresh process so that
its memory is its own: "+fit MB" is the peak resident memory during the fit (VmHWM, reset
just before it through /proc/self/clear_refs, Linux) minus the resident memory before it,
which holds u and y: what the fit itself adds.
"""

from __future__ import annotations

import subprocess
import sys

CHILD = r"""
import sys, time
import numpy as np
import backlashid as bid


def status(field):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) / 1024 for line in f if line.startswith(field + ":"))


n = int(float(sys.argv[1]))
model = bid.example1()
rng = np.random.default_rng(0)
u = rng.uniform(-1, 1, n)
y = model.simulate(u)
y += np.std(y) / 25 * rng.standard_normal(n)
before = status("VmRSS")
with open("/proc/self/clear_refs", "w") as f:  # the peak (VmHWM) restarts from here
    f.write("5")
t0 = time.perf_counter()
result = bid.fit_cascade(u, y)
seconds = time.perf_counter() - t0
peak = status("VmHWM")
err = max(abs(v) for v in result.errors(model).values())
print(f"{n:>12.0e} {seconds:>9.2f} {result.iterations:>6} {result.coarse_samples:>7} {result.refinement_steps:>5} "
      f"{err:>10.2e} {peak:>9.0f} {peak - before:>9.0f}")
"""


def main() -> None:
    sizes = sys.argv[1:] or ["1e6", "1e7"]
    print(
        f"{'N':>12} {'fit [s]':>9} {'iters':>6} {'coarse':>7} {'LM':>5} {'max err':>10} {'peak MB':>9} {'+fit MB':>9}"
    )
    for n in sizes:
        subprocess.run([sys.executable, "-c", CHILD, n], check=True)


if __name__ == "__main__":
    main()
