"""Detectability ceiling of the independent withheld-effect benchmark (issue 18): an oracle.

Are the targets of ``benches/independent_effects.py`` (rank-1 >= 95 % at ENR 3, >= 80 % at
ENR 1, with "none" on >= 95 % of the no-effect cases) reachable by construction of its cases?
The generator states the ENR of each effect before any fit; the nominal fit absorbs part of
it. This script measures, on the tune seeds only, how much is left, and whether an oracle that
KNOWS the true effect could tell it from no effect at all.

    python benches/detectability_ceiling.py --json ceiling.json            # tune seeds + null cases
    python benches/detectability_ceiling.py --effects dead_time --levels 3 --index 4 --null-extra 0
    python benches/detectability_ceiling.py --from-json ceiling.json       # re-summarise

The ``final`` seed set is refused: it is quoted once and never used for tuning.

Per case (the benchmark's own generator, nominal fit and diagnosis call)
-------------------------------------------------------------------------
The case is ``make_case(effect, level, index, "tune")`` of the benchmark, the nominal fit
``bid.fit_cascade(u_est, y_est, na=2, nb=2, degree=3)`` and ONE call of ``bid.diagnose`` with
the benchmark's defaults (every candidate, noise unknown). ``diagnose`` refits each candidate
on its own (``diagnosis.fit_effect``: the nominal parameters and that effect's, from the
nominal model; a candidate's refit and its validation score do not depend on the other
candidates), so one call gives both the oracle's refit of the true effect and every
candidate's refit for the null. Read from the report (validation record after the
diagnoser's warm-up w, every model started from the diagnoser's estimated initial state):

- mse0 = nominal_validation_rmse^2, and per candidate c its validation MSE mse_c (free-run
  simulation; one-step prediction for colored_noise) and the diagnoser's p-value p_c of the
  improvement (one-sided paired test on the squared errors, Newey-West; ``Candidate.p_value``).
- Noise energy s2 = mean of e^2 over the same samples, e = y - y_effect the generator's own
  noise realisation (quantization: the measured output is Q(y_effect + e) and e is not
  stored, so s2 = sigma^2).

Statistics
----------
- residual ENR = sqrt(max(mse0 - s2, 0) / s2): the effect's energy-to-noise ratio left in the
  nominal model's validation error, in the generator's amplitude units (compare with the
  level 3 or 1); "share" = residual ENR / realised ENR.
- z_c = Phi^-1(1 - p_c) (the diagnoser's own improvement statistic; inf when p_c underflows)
  and R_c = 1 - mse_c / mse0 (plain relative reduction of the validation MSE).
- Oracle statistic of an effect case: z and R of the TRUE effect's candidate only.
- Null statistic of a no-effect case: max over EVERY candidate of z_c (and of R_c): what the
  best of the catalogue gains when nothing is missing.

Decision rule of the ceiling (fixed before the first run)
---------------------------------------------------------
1. Null cases: the benchmark's 20 tune "none" cases (indices 0-19) plus ``--null-extra``
   (default 200) further "none" cases from a seed set of their own, "null": the benchmark's
   seed scheme ``default_rng([SEED_SETS[set], crc32(effect), round(100 level), index])`` with
   the first word NULL_SEED = 18_303, which differs from tune (18_101) and final (18_202), so
   the streams are disjoint from both.
2. Threshold T (for z; likewise T_R for R): the k-th smallest of the n null maxima,
   k = ceil(0.95 (n + 1)). Exchangeability of the null cases makes P(a new no-effect case's
   best statistic > T) <= 1 - k / (n + 1) <= 5 %, without any distribution assumed: a
   diagnoser that says "none" unless the best improvement exceeds T keeps "none" on >= 95 % of
   no-effect cases in expectation. With the 20 tune cases alone k = 20: T is their maximum
   (4.8 %). A 90 % distribution-free interval for the null's 95th percentile (order statistics,
   binomial) is printed beside it.
3. An effect case is DETECTABLE if its true candidate's z > T (primary; the R rule is printed
   as a second column). quantization is the exception: the diagnoser names it from the lattice
   of the measured values, not from a refit (rounding after the noise is white-like; no model
   of the noise-free output removes it), so its oracle is the diagnoser's lattice rule: a
   lattice on both records whose rounding variance q^2 / 12 is at least LATTICE_MATERIAL of
   mse0 (its false-alarm rate on the null cases is printed).
4. Ceiling per effect and level = share of detectable cases; overall ceiling per level = share
   over the 11 catalogue effects x 10 cases. Any diagnoser whose "none" rule is a threshold on
   the best candidate's z and keeps "none" >= 95 % names at most the detectable cases right:
   the ceiling bounds rank-1 from above (it assumes perfect attribution, no confusion). It is
   a bound for this statistic and this refit; another statistic or a better refit of a
   candidate could detect more.
5. Out-of-catalogue effects (gain_drift, cogging; to be "unexplained"): detectable if the
   larger of the best candidate's z and the black-box residual model's z
   (``details.black_box_p_value``) exceeds the same quantile of that statistic on the null.

Added after the first run (not part of the rule above): an "ideal" column, the share of cases
an exact model of the effect could detect by the R rule: R_ideal = 1 - (1 + delta) s2 / mse0 >
T_R, where delta is the null cases' median of mse0 / s2 - 1 (what a correct refit leaves above
the noise: on a no-effect case the nominal model IS the true model refitted). It bounds what a
better candidate model could reach; it is optimistic by the spread of delta (with the null's
95th percentile of delta instead of its median the ideal ceiling drops by 2-4 points).

Beside the ceiling the script prints, from the same run, the diagnoser's verdict (which must
equal the benchmark's: same code, same case) and sorts every miss into "not detectable"
(below T: no diagnoser keeping "none" >= 95 % names it) and "detectable but named wrong"
(a confusion or a decision rule that says "none" above T), with the verdict it got.

Result on the tune seeds (480 cases: 260 effect + 20 tune no-effect + 200 "null"; 1216 s
serial on the shared 2-core machine, 2.5 s per case)
---------------------------------------------------------------------------------------------
Null: the best candidate's z exceeds T = 2.70 (90 % interval [2.37, 3.02]) and its R exceeds
T_R = 0.27 % (interval [0.21 %, 0.35 %]) on 5 % of the 220 no-effect cases; the diagnoser's own
level (z > 3.14) is crossed on 1.4 % of them, and it says "none" on 219 of 220. Ceilings of the
catalogue rank-1 (110 cases per level): ENR 3: z rule 83.6 %, R rule 91.8 %, ideal 95.5 %
(today's rank-1 76.4 %, target 95 %); ENR 1: 69.1 %, 77.3 %, 89.1 % (today 62.7 %, target 80 %).
The diagnoser's verdicts in this run equal those of the benchmark's tune run case by case.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from scipy import stats

sys.path.insert(0, str(Path(__file__).resolve().parent))
import independent_effects as ie  # the benchmark's generator, unmodified

NULL_SET = "null"
NULL_SEED = 18_303  # first entropy word of the extra no-effect cases: disjoint from tune and final
QUANTILE = 0.95
assert NULL_SEED not in ie.SEED_SETS.values()
ie.SEED_SETS.setdefault(NULL_SET, NULL_SEED)  # in this process only: make_case accepts the set


def _z(p: float) -> float:
    """Phi^-1(1 - p), +inf for p = 0."""
    return float(stats.norm.isf(p)) if p > 0.0 else math.inf


def oracle_case(effect: str, level: float, index: int, seeds: str = "tune", candidates: list[str] | None = None) -> dict[str, Any]:
    """Generate one case, fit the nominal cascade, diagnose; return the oracle's statistics.

    Never raises: an error is recorded under ``"error"``.
    """
    import backlashid as bid
    from backlashid.diagnosis._diagnose import LATTICE_MATERIAL
    from backlashid.diagnosis.effects._quantization import lattice

    if seeds == "final":
        raise ValueError("the final seeds are not run by the oracle")
    out: dict[str, Any] = {"effect": effect, "level": float(level), "index": int(index), "seeds": seeds}
    t0 = time.perf_counter()
    try:
        c = ie.make_case(effect, level, index, seeds)
        out.update(input_class=c.input_class, enr_realised=float(c.enr_realised), noise_std=float(c.noise_std))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            fit = bid.fit_cascade(c.u_est, c.y_est, na=2, nb=2, degree=3)
            rep = bid.diagnose(fit.model, (c.u_est, c.y_est), (c.u_val, c.y_val), candidates=candidates)
    except Exception as exc:  # a result, not a crash
        out["error"] = f"{type(exc).__name__}: {exc}"
        out["seconds"] = time.perf_counter() - t0
        return out
    w = int(rep.warmup)
    mse0 = float(rep.nominal_validation_rmse) ** 2
    if effect == "quantization":
        s2, exact = float(c.noise_std) ** 2, False
    else:
        e = (c.y - c.y_effect)[ie.N_EST :][w:]
        s2, exact = float(np.mean(e * e)), True
    grid = lattice(np.concatenate([c.y_est, c.y_val]))
    share = grid.q**2 / 12.0 / mse0 if grid is not None and mse0 > 0 else 0.0
    cands = {}
    for cand in rep.ranking:
        # a noise model's error is its one-step prediction (its free run is the nominal's)
        rmse = float(cand.prediction_rmse) if math.isfinite(float(cand.prediction_rmse)) else float(cand.validation_rmse)
        mse = rmse**2
        cands[cand.effect] = {
            "p": float(cand.p_value), "z": _z(float(cand.p_value)), "R": 1.0 - mse / mse0 if mse0 > 0 else 0.0,
            "gap_closed_true": (mse0 - mse) / (mse0 - s2) if mse0 > s2 else float("nan"), "bic": float(cand.criterion),
        }  # fmt: skip
    excess = (mse0 - s2) / s2
    out.update(
        warmup=w, mse0=mse0, noise_energy=s2, noise_exact=exact, excess_energy=excess,
        residual_enr=math.sqrt(max(excess, 0.0)), reported=rep.best_effect, level_p=float(rep.details.significance_level),
        black_box_z=_z(float(rep.details.black_box_p_value)), lattice_material=bool(grid is not None and share >= LATTICE_MATERIAL),
        lattice_share=float(share), candidates=cands, seconds=time.perf_counter() - t0,
    )  # fmt: skip
    return out


# -- summary --------------------------------------------------------------------------------------


def threshold(null: list[float], q: float = QUANTILE) -> tuple[float, int, int]:
    """(T, k, n): the k-th smallest of the n null values, k = ceil(q (n + 1)) (capped at n)."""
    v = np.sort(np.asarray(null, dtype=float))
    n = v.size
    k = min(math.ceil(q * (n + 1)), n)
    return float(v[k - 1]), k, n


def quantile_interval(null: list[float], q: float = QUANTILE, conf: float = 0.90) -> tuple[float, float]:
    """Distribution-free interval [X_(l), X_(u)] for the q-quantile with coverage >= conf."""
    v = np.sort(np.asarray(null, dtype=float))
    n = v.size
    a = (1.0 - conf) / 2.0
    lo = int(stats.binom.ppf(a, n, q))  # P(B <= lo) >= a: X_(lo) lies below with prob <= a
    hi = int(stats.binom.ppf(1.0 - a, n, q)) + 1
    return (float(v[lo - 1]) if lo >= 1 else -math.inf, float(v[hi - 1]) if hi <= n else math.inf)


def null_stats(x: dict[str, Any]) -> dict[str, float]:
    cz = [c["z"] for c in x["candidates"].values()]
    cr = [c["R"] for c in x["candidates"].values()]
    return {"z": max(cz), "R": max(cr), "any": max(max(cz), x["black_box_z"])}


def oracle_stat(x: dict[str, Any]) -> dict[str, float]:
    c = x["candidates"].get(x["effect"])
    return {"z": c["z"], "R": c["R"]} if c else {"z": -math.inf, "R": -math.inf}


def _med(v: list[float]) -> float:
    f = [a for a in v if np.isfinite(a)]
    return float(np.median(f)) if f else float("nan")


def _pct(a: float) -> str:
    return f"{100 * a:5.1f} %" if np.isfinite(a) else "  n/a"


def summarise(rows: list[dict[str, Any]], tune_json: str | None) -> dict[str, Any]:
    ok = [x for x in rows if "error" not in x]
    for x in rows:
        if "error" in x:
            print(f"error: {x['effect']} ENR {x['level']:g} #{x['index']} ({x['seeds']}): {x['error']}")
    none_tune = [x for x in ok if x["effect"] == "none" and x["seeds"] == "tune"]
    none_all = [x for x in ok if x["effect"] == "none"]
    summary: dict[str, Any] = {"null_cases": len(none_all), "null_tune_cases": len(none_tune)}
    print(f"== null: {len(none_all)} no-effect cases ({len(none_tune)} tune, {len(none_all) - len(none_tune)} from seed set {NULL_SET!r})")
    thr: dict[str, float] = {}
    for key in ("z", "R", "any"):
        vals = [null_stats(x)[key] for x in none_all]
        if not vals:
            continue
        t, k, n = threshold(vals)
        lo, hi = quantile_interval(vals)
        thr[key] = t
        tt = threshold([null_stats(x)[key] for x in none_tune])[0] if none_tune else float("nan")
        summary[f"threshold_{key}"] = {"T": t, "k": k, "n": n, "ci90": [lo, hi], "T_tune_only": tt, "median": _med(vals)}
        print(f"best-candidate {key:>3} on the null: median {_med(vals):.3g}, T = {t:.3g} (order statistic {k} of {n}; "
              f"90 % interval of the 95th percentile [{lo:.3g}, {hi:.3g}]; from the 20 tune cases alone: {tt:.3g})")  # fmt: skip
    if none_all:
        lv = ok[0]["level_p"] if ok else float("nan")
        zl = _z(lv)
        fa = np.mean([null_stats(x)["z"] > zl for x in none_all])
        print(f"diagnoser's own level (p < {lv:.2g}, z > {zl:.2f}): best candidate significant on {_pct(fa)} of the null cases")
        lat = np.mean([x["lattice_material"] for x in none_all])
        print(f"lattice rule on the null: {_pct(lat)} (quantization's oracle)")
        exc = [x["excess_energy"] for x in none_all]
        print(f"nominal validation MSE over the noise energy - 1 on the null: median {np.median(exc):+.4f}, "
              f"5-95 % [{np.quantile(exc, 0.05):+.4f}, {np.quantile(exc, 0.95):+.4f}]")  # fmt: skip
        summary["null_excess_energy_median"] = float(np.median(exc))
        summary["null_false_alarm_at_own_level"] = float(fa)
    if "z" not in thr:
        return summary

    delta = float(np.median([x["excess_energy"] for x in none_all]))  # what a correct refit leaves

    def detect(x: dict[str, Any]) -> tuple[bool, bool, bool]:
        """(z rule, R rule, ideal model): detectable by the true candidate's z, its R, and by the
        true model (R_ideal = 1 - (1 + delta) s2 / mse0, delta the null's median excess)."""
        ideal = 1.0 - (1.0 + delta) * x["noise_energy"] / x["mse0"] > thr["R"]
        if x["effect"] == "quantization":
            return x["lattice_material"], x["lattice_material"], x["lattice_material"]
        if x["effect"] in ie.OUT_OF_CATALOGUE:
            s = null_stats(x)
            return s["any"] > thr["any"], s["any"] > thr["any"], ideal
        s = oracle_stat(x)
        return s["z"] > thr["z"], s["R"] > thr["R"], ideal

    tune_reported: dict[tuple[str, float, int], str] = {}
    if tune_json and os.path.exists(tune_json):
        for x in json.load(open(tune_json))["cases"]:
            tune_reported[(x["effect"], float(x["level"]), int(x["index"]))] = str(x.get("reported"))
    eff_rows = [x for x in ok if x["effect"] != "none"]
    print("\n== per effect and level: residual ENR left after the nominal fit, oracle detection")
    print("   resENR: sqrt((mse0 - s2) / s2), median; share: resENR / ENR, median; z/R: oracle's true-candidate")
    print("   statistic (median); det z / det R: share detectable (z > T, R > T_R); rank-1: diagnoser's share right")
    print("   ideal: share detectable by the true model itself, R_ideal = 1 - (1 + delta) s2 / mse0 > T_R")
    head = f"{'effect':<18}{'ENR':>4}{'n':>4}{'resENR':>8}{'share':>7}{'z med':>8}{'R med':>8}{'det z':>8}{'det R':>8}{'ideal':>8}{'rank-1':>8}"
    print(head)
    table: dict[str, Any] = {}
    for level in sorted({x["level"] for x in eff_rows}, reverse=True):
        for e in (*ie.CATALOGUE, *ie.OUT_OF_CATALOGUE):
            sub = [x for x in eff_rows if x["effect"] == e and x["level"] == level]
            if not sub:
                continue
            det = [detect(x) for x in sub]
            st = [oracle_stat(x) if e not in ie.OUT_OF_CATALOGUE else {"z": null_stats(x)["any"], "R": null_stats(x)["R"]} for x in sub]
            row = {
                "n": len(sub), "residual_enr_median": _med([x["residual_enr"] for x in sub]),
                "share_median": _med([x["residual_enr"] / x["enr_realised"] for x in sub]),
                "z_median": _med([s["z"] for s in st]) if not all(math.isinf(s["z"]) for s in st) else math.inf,
                "R_median": _med([s["R"] for s in st]), "detect_z": float(np.mean([d[0] for d in det])),
                "detect_R": float(np.mean([d[1] for d in det])), "detect_ideal": float(np.mean([d[2] for d in det])),
                "rank1": float(np.mean([x["reported"] == ie.CORRECT[e] for x in sub])),
            }  # fmt: skip
            table[f"{e} {level:g}"] = row
            print(f"{e:<18}{level:>4g}{len(sub):>4}{row['residual_enr_median']:>8.2f}{row['share_median']:>7.2f}"
                  f"{row['z_median']:>8.2f}{row['R_median']:>8.3f}{_pct(row['detect_z']):>8}{_pct(row['detect_R']):>8}"
                  f"{_pct(row['detect_ideal']):>8}{_pct(row['rank1']):>8}")  # fmt: skip
        cat = [x for x in eff_rows if x["level"] == level and x["effect"] in ie.CATALOGUE]
        if cat:
            cz = float(np.mean([detect(x)[0] for x in cat]))
            cr = float(np.mean([detect(x)[1] for x in cat]))
            ci = float(np.mean([detect(x)[2] for x in cat]))
            r1 = float(np.mean([x["reported"] == ie.CORRECT[x["effect"]] for x in cat]))
            tgt = ie.TARGET_RANK1.get(level, float("nan"))
            summary[f"ceiling_{level:g}"] = {"z": cz, "R": cr, "ideal": ci, "rank1": r1, "target": tgt, "cases": len(cat)}
            print(f"{'CEILING catalogue':<22}{len(cat):>4}{'':>38}{_pct(cz):>8}{_pct(cr):>8}{_pct(ci):>8}{_pct(r1):>8}"
                  f"   target {_pct(tgt)}\n")  # fmt: skip
    summary["table"] = table

    # misses: not detectable vs detectable but named wrong
    print("== misses of the diagnoser (this run), sorted by the oracle")
    mism = [
        x
        for x in eff_rows + none_tune
        if tune_reported and tune_reported.get((x["effect"], x["level"], x["index"])) not in (None, x["reported"]) and x["seeds"] == "tune"
    ]
    if tune_reported:
        print(f"verdicts differing from {tune_json}: {len(mism)}")
        for x in mism:
            print(
                f"  {x['effect']} ENR {x['level']:g} #{x['index']}: now {x['reported']}, then {tune_reported[(x['effect'], x['level'], x['index'])]}"
            )
    cost: dict[str, dict[str, int]] = {}
    print("flags: z / R / i = detectable by the z rule / the R rule / the ideal model ('-' not)")
    for level in sorted({x["level"] for x in eff_rows}, reverse=True):
        for group, names in (("catalogue", ie.CATALOGUE), ("out of catalogue", ie.OUT_OF_CATALOGUE)):
            cat = [x for x in eff_rows if x["level"] == level and x["effect"] in names]
            miss = [x for x in cat if x["reported"] != ie.CORRECT[x["effect"]]]
            flags = [detect(x) for x in miss]
            n_any = sum(any(f[:2]) for f in flags)
            print(f"ENR {level:g} {group}: {len(miss)} misses of {len(cat)}: {len(miss) - n_any} detectable by neither the z nor the R "
                  f"rule, {n_any} by at least one (named wrong); {sum(f[2] for f in flags)} by the ideal model")  # fmt: skip
            for x, f in sorted(zip(miss, flags), key=lambda xf: (xf[0]["effect"], xf[0]["index"])):
                s = oracle_stat(x) if x["effect"] not in ie.OUT_OF_CATALOGUE else {"z": null_stats(x)["any"], "R": null_stats(x)["R"]}
                tag = "".join(c if b else "-" for c, b in zip("zRi", f))
                if any(f[:2]):
                    key = f"{x['effect']} -> {x['reported']}"
                    cost.setdefault(f"{level:g}", {})[key] = cost.get(f"{level:g}", {}).get(key, 0) + 1
                print(f"  {tag} {x['effect']:<18} #{x['index']:<2} {x['input_class']:<9} resENR {x['residual_enr']:5.2f}  "
                      f"z {s['z']:7.2f}  R {s['R']:8.3g}  -> {x['reported']}")  # fmt: skip
    summary["detectable_misses"] = cost
    print("\nmisses detectable by the z or the R rule, by confusion (true -> reported):")
    for level, d in cost.items():
        print(f"  ENR {level}: " + ", ".join(f"{k} {v}" for k, v in sorted(d.items(), key=lambda kv: -kv[1])))
    return summary


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--effects", nargs="+", default=list(ie.ALL_EFFECTS), choices=ie.ALL_EFFECTS, metavar="EFFECT")
    ap.add_argument("--levels", type=float, nargs="+", default=[3.0, 1.0])
    ap.add_argument("--per-effect", type=int, default=10)
    ap.add_argument("--index", type=int, default=None)
    ap.add_argument("--null-extra", type=int, default=200, help="extra no-effect cases from the 'null' seed set (default 200)")
    ap.add_argument("--tune-json", default=None, help="the benchmark's tune-run JSON, to compare verdicts and sort misses")
    ap.add_argument("--json", metavar="PATH", help="write per-case results and the summary")
    ap.add_argument("--from-json", metavar="PATH", help="re-summarise a previous run without running cases")
    args = ap.parse_args()
    if args.from_json:
        rows = json.load(open(args.from_json))["cases"]
        summarise(rows, args.tune_json)
        return 0
    cases = [(e, lv, i, "tune") for e, lv, i in ie.case_list(args.effects, args.levels, args.per_effect, args.index)]
    cases += [("none", 0.0, i, NULL_SET) for i in range(args.null_extra)]
    print(f"detectability ceiling: {len(cases)} cases (tune seeds + {args.null_extra} null), run serially")
    t0 = time.perf_counter()
    rows = []
    progress = open(args.json + ".partial.jsonl", "w") if args.json else None
    for j, case in enumerate(cases):
        x = oracle_case(*case)
        rows.append(x)
        if progress:
            progress.write(json.dumps(x, default=float) + "\n")
            progress.flush()
        if (j + 1) % 20 == 0:
            print(f"  {j + 1}/{len(cases)} cases, {time.perf_counter() - t0:.0f} s", flush=True)
    wall = time.perf_counter() - t0
    summary = summarise(rows, args.tune_json)
    summary["wall_seconds"] = wall
    print(f"\nwall time {wall:.0f} s ({wall / max(len(cases), 1):.2f} s per case, serial)")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"args": vars(args), "summary": summary, "cases": rows}, fh, indent=1, default=float)
        if progress:
            progress.close()
            os.remove(args.json + ".partial.jsonl")
        print(f"wrote {os.path.abspath(args.json)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
