"""Detectability ceiling of the chains benchmark (issues 29 and 30): an oracle for its missed rows.

``benches/detectability_ceiling.py`` asks, for the cascade rows of ``independent_effects.py``,
whether an oracle that KNOWS the withheld effect could tell it from no effect at all. This
script asks the same of ``benches/independent_chains.py``'s rows whose targets the diagnosis
misses: sandwich and input-backlash single effects (target rank-1 >= 85 % at ENR 3), the
integrating plants (>= 80 % at ENR 3), the new physics (>= 85 % per effect at ENR 3) and the two
effects at once (both named on >= 80 % at ENR 3). Its generator, nominal fits and diagnosis call
are the benchmark's own, imported unmodified.

    python benches/chain_ceiling.py --jobs 2 --log ceiling.jsonl         # tune seeds + null cases
    python benches/chain_ceiling.py --from-log ceiling.jsonl             # re-summarise
    python benches/chain_ceiling.py --rows sandwich:dead_time --index 0  # one case

The ``final`` seed set is refused: it is quoted once and never used for tuning.

Per case
--------
The case ``make_case(row, level, index, seeds)``, the family's nominal fit (``fit_nominal``), then

1. ONE call of ``bid.diagnose`` with the benchmark's options (every candidate; composition on):
   the verdict, and every candidate's first-step refit from the nominal model (a candidate's
   refit and its score do not depend on the other candidates), read as in
   detectability_ceiling.py: mse0 = nominal validation MSE, per candidate its MSE (free run;
   one-step prediction for colored_noise), p-value p_c, z_c = Phi^-1(1 - p_c),
   R_c = 1 - mse_c / mse0; the noise energy s2 = mean of e^2 on the same samples, e the
   generator's noise (y - y_effect; quantization and sensor_clip act after the noise, so there
   s2 = sigma^2).
2. On effect rows, a second call told the truth: ``candidates`` = the row's catalogue
   verdict(s) only, composition on ("attribution oracle"): the diagnosis that never confuses
   one effect with another, its own significance and naming rules unchanged.

Decision rule (fixed before the first run; the rule of detectability_ceiling.py per family)
--------------------------------------------------------------------------------------------
1. Null cases per nominal family: the benchmark's 20 tune 'none' cases of the family (sandwich,
   hammerstein, integrating) plus ``--null-extra`` (default 40) more from a seed set of their
   own, "null" (first entropy word NULL_SEED = 35_303, disjoint from tune 35_101 and final
   35_202). The cascade family (the physics and pair rows) has no 'none' row in the benchmark:
   its null cases are ``--null-extra`` draws of a row "cascade:none" added in this process, the
   benchmark's cascade plant with no effect.
2. Threshold T_f of family f: the k-th smallest of its n null maxima over every candidate of z,
   k = ceil(0.95 (n + 1)): a diagnoser that says "none" unless the best z exceeds T_f keeps
   "none" on >= 95 % of the family's no-effect cases (distribution-free, exchangeability).
   Likewise T_R for R.
3. A single-effect case is DETECTABLE if its true candidate's z > T_f (primary; the R rule
   beside it); quantization: the diagnoser's lattice rule (as in detectability_ceiling.py).
4. Ceiling of a row = share detectable; it bounds rank-1 from above for any diagnoser whose
   "none" rule is a threshold on the best candidate's z with 'none' >= 95 % (it assumes perfect
   attribution). It is a bound for this statistic and this refit of the candidate.
5. Added after the first run (as in detectability_ceiling.py): "ideal", the share an exact
   model of the effect could detect by the R rule, R_ideal = 1 - (1 + delta_f) s2 / mse0 >
   T_R,f, delta_f the family's null median of mse0 / s2 - 1 (what a right refit leaves above
   the noise). It bounds what a better candidate could reach, not what an attribution rule does.
6. Pairs: VISIBLE if each member's candidate, refitted alone from the nominal, has z > T_cascade
   (quantization: the lattice rule); and the attribution oracle's share naming both. Neither
   bounds every diagnoser (a member may hide behind the other and appear once it is modelled),
   so the pair figures are reported as measurements, not as proven ceilings.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import detectability_ceiling as dc  # threshold, quantile_interval, _z
import independent_chains as ic  # the benchmark's generator and nominal fits, unmodified

NULL_SET = "null"
NULL_SEED = 35_303
assert NULL_SEED not in ic.SEED_SETS.values()
ic.SEED_SETS.setdefault(NULL_SET, NULL_SEED)
CASCADE_NONE = "cascade:none"
ic.ROWS.setdefault(CASCADE_NONE, ic.Row("cascade", (), (0.0,), "cascade"))
MISSED = [r for r in ic.ROWS if r.split(":")[0] in ("sandwich", "hammerstein", "integrating", "physics", "pair") and not r.endswith(":none")]
NULL_ROWS = {"sandwich": "sandwich:none", "hammerstein": "hammerstein:none", "integrating": "integrating:none", "cascade": CASCADE_NONE}
POST_NOISE = ("quantization", "sensor_clip")  # applied to the measured output after the noise


def _candidates(rep: Any, mse0: float) -> dict[str, dict[str, float]]:
    out = {}
    for cand in rep.ranking:
        rmse = float(cand.prediction_rmse) if math.isfinite(float(cand.prediction_rmse)) else float(cand.validation_rmse)
        out[cand.effect] = {"p": float(cand.p_value), "z": dc._z(float(cand.p_value)), "R": 1.0 - rmse**2 / mse0 if mse0 > 0 else 0.0}
    return out


def oracle_case(row: str, level: float, index: int, seeds: str) -> dict[str, Any]:
    """Generate, fit the family's nominal, diagnose (all candidates, then only the true ones)."""
    import backlashid as bid
    from backlashid.diagnosis._diagnose import LATTICE_MATERIAL
    from backlashid.diagnosis.effects._quantization import lattice

    if seeds == "final":
        raise ValueError("the final seeds are not run by the oracle")
    spec = ic.ROWS[row]
    out: dict[str, Any] = {"row": row, "family": spec.family, "level": float(level), "index": int(index), "seeds": seeds}
    t0 = time.perf_counter()
    try:
        c = ic.make_case(row, level, index, seeds)
        out.update(input_class=c.input_class, noise_std=float(c.noise_std), enr_realised=float(c.enr_realised))
        est, val = (c.u[: ic.N_EST], c.y[: ic.N_EST]), (c.u[ic.N_EST :], c.y[ic.N_EST :])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = ic.fit_nominal(c)
            rep = bid.diagnose(fit.model, est, val)
            told = bid.diagnose(fit.model, est, val, candidates=list(spec.verdicts)) if spec.effects else None
    except Exception as exc:  # a result, not a crash
        out.update(error=f"{type(exc).__name__}: {exc}", seconds=time.perf_counter() - t0)
        return out
    w = int(rep.warmup)
    mse0 = float(rep.nominal_validation_rmse) ** 2
    if set(spec.effects) & set(POST_NOISE):
        s2 = float(c.noise_std) ** 2
    else:
        e = (c.y - c.y_effect)[ic.N_EST :][w:]
        s2 = float(np.mean(e * e))
    grid = lattice(np.concatenate([c.y[: ic.N_EST], c.y[ic.N_EST :]]))
    share = grid.q**2 / 12.0 / mse0 if grid is not None and mse0 > 0 else 0.0
    out.update(
        warmup=w, mse0=mse0, noise_energy=s2, residual_enr=math.sqrt(max(mse0 / s2 - 1.0, 0.0)), reported=rep.best_effect,
        effects=list(rep.effects), lattice_material=bool(grid is not None and share >= LATTICE_MATERIAL),
        candidates=_candidates(rep, mse0), told_effects=None if told is None else list(told.effects),
        told_reported=None if told is None else told.best_effect, seconds=time.perf_counter() - t0,
    )  # fmt: skip
    return out


# -- summary --------------------------------------------------------------------------------------


def _best(x: dict[str, Any], key: str) -> float:
    return max(c[key] for c in x["candidates"].values())


def _member_detectable(x: dict[str, Any], verdict: str, thr: dict[str, float]) -> tuple[bool, bool]:
    if verdict == "quantization":
        return x["lattice_material"], x["lattice_material"]
    c = x["candidates"].get(verdict)
    return (False, False) if c is None else (c["z"] > thr["z"], c["R"] > thr["R"])


def thresholds(ok: list[dict[str, Any]]) -> dict[str, dict[str, float]]:
    """T_f for z and R per family from its null cases (rule 2), and delta_f (rule 5)."""
    out: dict[str, dict[str, float]] = {}
    print("== null cases per family: the best candidate's z and R; T = order statistic k of n")
    for fam, name in NULL_ROWS.items():
        null = [x for x in ok if x["row"] == name]
        if not null:
            continue
        out[fam] = {}
        for key in ("z", "R"):
            vals = [_best(x, key) for x in null]
            t, k, n = dc.threshold(vals)
            lo, hi = dc.quantile_interval(vals)
            out[fam][key] = t
            print(f"  {fam:<12} {key}: median {np.median(vals):.3g}, T = {t:.3g} ({k} of {n}; 90 % interval [{lo:.3g}, {hi:.3g}])")
        out[fam]["delta"] = float(np.median([x["mse0"] / x["noise_energy"] - 1.0 for x in null]))
        said_none = np.mean([x["reported"] == "none" for x in null])
        print(f"  {fam:<12} diagnoser says 'none' on {dc._pct(said_none)} of {len(null)}")
    return out


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    ok = [x for x in rows if "error" not in x]
    for x in rows:
        if "error" in x:
            print(f"error: {x['row']} ENR {x['level']:g} #{x['index']} ({x['seeds']}): {x['error']}")
    thr = thresholds(ok)
    summary: dict[str, Any] = {"thresholds": thr, "rows": {}, "groups": {}}
    print("\n== per row and level (tune seeds): resENR median; det z / det R: share detectable by the true")
    print("   candidate (pairs: both members, each refitted alone from the nominal); told: the attribution")
    print("   oracle names the truth (pairs: both); rank-1: the diagnoser right (pairs: both named)")
    print("   ideal: share an exact model of the effect could detect (rule 5)")
    print(f"{'row':<36}{'ENR':>4}{'n':>4}{'resENR':>8}{'det z':>8}{'det R':>8}{'ideal':>8}{'told':>8}{'rank-1':>8}")
    groups: dict[str, list[tuple[bool, ...]]] = {}
    for name in MISSED:
        spec = ic.ROWS[name]
        for level in sorted({x["level"] for x in ok if x["row"] == name}, reverse=True):
            sub = [x for x in ok if x["row"] == name and x["level"] == level]
            t = thr.get(spec.family)
            if t is None:
                continue
            flags = []
            for x in sub:
                det = [_member_detectable(x, v, t) for v in spec.verdicts]
                told = all(v in (x["told_effects"] or []) for v in spec.verdicts)
                right = all(v in x["effects"] for v in spec.verdicts) if len(spec.verdicts) > 1 else x["reported"] == spec.verdicts[0]
                ideal = 1.0 - (1.0 + t["delta"]) * x["noise_energy"] / x["mse0"] > t["R"]
                flags.append((all(d[0] for d in det), all(d[1] for d in det), ideal, told, right))
            share = [float(np.mean([f[j] for f in flags])) for j in range(5)]
            res = float(np.median([x["residual_enr"] for x in sub]))
            summary["rows"][f"{name} {level:g}"] = dict(zip(("det_z", "det_R", "ideal", "told", "right"), share), n=len(sub), residual_enr=res)
            print(f"{name:<36}{level:>4g}{len(sub):>4}{res:>8.2f}" + "".join(f"{dc._pct(s):>8}" for s in share))
            groups.setdefault(f"{spec.group} {level:g}", []).extend(flags)
    print("\n== per group and level")
    for key, flags in groups.items():
        share = [float(np.mean([f[j] for f in flags])) for j in range(5)]
        summary["groups"][key] = dict(zip(("det_z", "det_R", "ideal", "told", "right"), share), n=len(flags))
        print(f"{key:<20} n {len(flags):>3}: det z {dc._pct(share[0])}, det R {dc._pct(share[1])}, ideal {dc._pct(share[2])}, "
              f"told {dc._pct(share[3])}, diagnoser {dc._pct(share[4])}")  # fmt: skip
    return summary


def case_list(rows: list[str], levels: list[float], per_row: int, null_extra: int, index: int | None) -> list[tuple[str, float, int, str]]:
    cases = [(r, lv, i, "tune") for r, lv, i in ic.case_list(rows, levels, per_row, index)]
    families = {ic.ROWS[r].family for r in rows}
    for fam in sorted(families):
        null = NULL_ROWS[fam]
        if fam != "cascade" and index is None:
            cases += [(null, 0.0, i, "tune") for i in range(2 * per_row)]
        cases += [(null, 0.0, i, NULL_SET) for i in ([index] if index is not None else range(null_extra))]
    return cases


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rows", nargs="+", default=MISSED, metavar="ROW", help="effect rows (default: every missed row)")
    ap.add_argument("--levels", type=float, nargs="+", default=[3.0], help="ENRs (default 3, where the targets are)")
    ap.add_argument("--per-effect", type=int, default=10)
    ap.add_argument("--null-extra", type=int, default=40, help="no-effect cases per family from the 'null' seed set (default 40)")
    ap.add_argument("--index", type=int, default=None)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--log", metavar="PATH", help="append each case's result as one JSON line")
    ap.add_argument("--from-log", metavar="PATH", help="summarise a --log file; run nothing")
    args = ap.parse_args()
    if args.from_log:
        with open(args.from_log) as fh:
            got = {(r["row"], r["level"], r["index"], r["seeds"]): r for r in map(json.loads, filter(str.strip, fh))}
        print(f"{len(got)} cases from {args.from_log}")
        summarise(list(got.values()))
        return 0
    unknown = [r for r in args.rows if r not in MISSED]
    if unknown:
        ap.error(f"unknown rows {unknown}; choose from {' '.join(MISSED)}")
    cases = case_list(args.rows, args.levels, args.per_effect, args.null_extra, args.index)
    print(f"chain ceiling: {len(cases)} cases (tune seeds + null), {args.jobs} job(s)", flush=True)
    t0 = time.perf_counter()
    log = open(args.log, "a") if args.log else None
    results = []
    cols = [list(c) for c in zip(*cases)]
    with ProcessPoolExecutor(max_workers=args.jobs) as pool:
        for j, res in enumerate(pool.map(oracle_case, *cols) if args.jobs > 1 else map(oracle_case, *cols)):
            results.append(res)
            if log is not None:
                log.write(json.dumps(res, default=float) + "\n")
                log.flush()
            if (j + 1) % 20 == 0:
                print(f"  {j + 1}/{len(cases)} cases, {time.perf_counter() - t0:.0f} s", flush=True)
    if log is not None:
        log.close()
    summarise(results)
    print(f"\nwall time {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
