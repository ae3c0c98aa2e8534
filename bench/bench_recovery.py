"""Recovery of hidden twin parameters by ``tune.fit`` on a full-size DAVIS346 scene.

    PYTHONPATH=python python bench/bench_recovery.py [--settings 10] [--budget 60]
        [--samplers ls,nm] [--duration 0.5] [--runs-per-trial 2] [--seed 0] [--csv FILE]
    PYTHONPATH=python python bench/bench_recovery.py --profile [--settings 3]
    PYTHONPATH=python python bench/bench_recovery.py --default-command [--statistics timing,counts]

The scene is ``mcreynolds`` (346 x 260 px, five rotating LEDs, the default continuous noise
model and the photoreceptor pole) shortened to --duration. Each hidden setting is drawn from
a generator seeded with (--seed, setting) within RANGES: both thresholds, the dark rate and
the ON and OFF background rates of eq. 12. The "real" recording is that setting simulated
with a hidden engine seed (1000 + setting) that no fit trial uses; each optimiser then fits
the five parameters with --budget trials of --runs-per-trial seeds from a perturbed start
(thresholds x exp(+-U(0.15, 0.35)), rates x or / U(2, 3), signs drawn) and succeeds when
both thresholds are within 10 % and the three rates within x1.5 of the hidden values.
Prints a row per (setting, optimiser) and a summary; no asserts. A sampler may name its
distance: ``nm:chi2``, ``cmaes:chi2`` (default: each sampler's own, see ``tune.fit``).

``--default-command`` measures issue 34's goal instead: the command a user runs, ``evstwin fit
REAL --scenario mcreynolds --budget 60`` (the default parameters ``tune.DEFAULT_FIT_PARAMS``, FitOptions' defaults:
one run per trial, the start at the scenario's values) on a 1 s recording (--duration 1 unless
given) of each setting's hidden thresholds and dark rate (drawn as above; the other parameters
keep the scenario's values, as ``--set`` would leave them). Success: both thresholds within 10 %
and the dark rate within x1.5. ``--statistics`` lists the chi-square's statistics compared
(``timing``, ``counts``; default both); each row also gives the identifiability report's
correlation of theta_on and the dark rate, and why the fit stopped.

``--profile`` instead measures the two distances themselves on each setting: at the hidden
values and with each threshold 10 % higher, over --profile-pairs pairs of engine seeds (the
same pairs at every point), the mean and standard deviation of compare's distance (mean of
the pair's two) and of the chi-square (of the pair's mean statistics); for each change, how
many standard deviations of the distance at the hidden values it moves the mean ("sd"), and
its mean over the standard deviation of the change itself with the same seed pairs ("paired":
what a search with common seeds sees).
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import sys
import time
from typing import Any

import numpy as np

from evstwin import tune
from evstwin.scenario import load, set_value
from evstwin.simulate import simulate

PARAMS = (
    "pixel.theta_on",
    "pixel.theta_off",
    "pixel.dark_rate_e_per_s",
    "pixel.shot_noise_on_rate_hz",
    "pixel.shot_noise_off_rate_hz",
)
SHORT = {"pixel.theta_on": "th_on", "pixel.theta_off": "th_off", "pixel.dark_rate_e_per_s": "dark",
         "pixel.shot_noise_on_rate_hz": "bg_on", "pixel.shot_noise_off_rate_hz": "bg_off"}
RANGES: dict[str, tuple[float, float]] = {
    "pixel.theta_on": (0.15, 0.45),            # ln units, log-uniform
    "pixel.theta_off": (0.15, 0.45),
    "pixel.dark_rate_e_per_s": (2e3, 5e4),     # e-/s, log-uniform around iniVation's 18000
    "pixel.shot_noise_on_rate_hz": (0.02, 0.5),  # Hz, log-uniform around the paper's 0.05
    "pixel.shot_noise_off_rate_hz": (0.02, 0.5),
}
"""Where the hidden values are drawn (log-uniform): thresholds of the DAVIS346 settings in
use, dark rates a decade either side of the datasheet's, background rates that make from
about a tenth to most of the scene's events."""
THRESHOLD_TOL = 0.10
RATE_FACTOR = 1.5


def scene(duration_s: float) -> dict[str, Any]:
    s = load("mcreynolds")
    return set_value(s, "duration_s", duration_s)


def draw(seed: int, setting: int) -> tuple[dict[str, float], dict[str, float]]:
    """(hidden values, starting values) of one setting."""
    rng = np.random.default_rng([seed, setting])
    hidden, start = {}, {}
    for key in PARAMS:
        lo, hi = RANGES[key]
        hidden[key] = float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
        sign = 1.0 if rng.random() < 0.5 else -1.0
        if "theta" in key:
            factor = math.exp(sign * rng.uniform(0.15, 0.35))
        else:
            factor = rng.uniform(2.0, 3.0) ** sign
        b = tune.FIT_BOUNDS[key]
        start[key] = min(max(hidden[key] * factor, b.low), b.high)
    return hidden, start


def success(hidden: dict[str, float], found: dict[str, float]) -> bool:
    for key in PARAMS:
        if "theta" in key:
            if abs(found[key] / hidden[key] - 1.0) > THRESHOLD_TOL:
                return False
        elif not 1.0 / RATE_FACTOR <= found[key] / hidden[key] <= RATE_FACTOR:
            return False
    return True


def profile(base: dict[str, Any], seed: int, setting: int, pairs: int) -> None:
    """The --profile table of one setting (see the module docstring)."""
    from evstwin.tune.counts import CountsObjective

    hidden, _ = draw(seed, setting)
    s = base
    for key, v in hidden.items():
        s = set_value(s, key, v)
    real = simulate(s, seed=1000 + setting, num_threads=os.cpu_count() or 1)
    match = tune.MatchObjective(real.events, real.meta)
    counts = CountsObjective(real.events, real.meta, base)
    points = {"hidden": {}, "th_on x1.1": {"pixel.theta_on": 1.1}, "th_off x1.1": {"pixel.theta_off": 1.1}}
    values: dict[str, dict[str, list[float]]] = {}
    for name, factors in points.items():
        sp = s
        for key, f in factors.items():
            sp = set_value(sp, key, hidden[key] * f)
        w1, chi2 = [], []
        for k in range(pairs):
            runs = [simulate(sp, seed=2 * k + j, num_threads=os.cpu_count() or 1) for j in (0, 1)]
            w1.append(float(np.mean([match.evaluate(r)["distance"] for r in runs])))
            chi2.append(counts.trial_distance([counts.evaluate(r)["stats"] for r in runs]))
        values[name] = {"compare": w1, "chi2": chi2}
    print(f"setting {setting} ({pairs} seed pairs):")
    for dist in ("compare", "chi2"):
        ref = values["hidden"][dist]
        sd = float(np.std(ref, ddof=1))
        cells = []
        for name in points:
            v = values[name][dist]
            cell = f"{name} {np.mean(v):.4f} +- {np.std(v, ddof=1):.4f}"
            if name != "hidden":
                diff = np.array(v) - np.array(ref)
                cell += (f" ({np.mean(diff) / sd:+.1f} sd, paired {np.mean(diff) / np.std(diff, ddof=1):+.1f})"
                         if sd > 0 else "")
            cells.append(cell)
        print(f"  {dist:8s} " + "; ".join(cells), flush=True)


GOAL_PARAMS = ("pixel.theta_on", "pixel.theta_off", "pixel.dark_rate_e_per_s")
"""What --default-command hides (the issue's ``--set`` of the thresholds and the dark rate)."""


def default_command(args: argparse.Namespace) -> None:
    """--default-command: issue 34's goal (see the module docstring)."""
    duration_s = 1.0 if "--duration" not in sys.argv else args.duration
    base = scene(duration_s)
    statistics = [s.strip() for s in args.statistics.split(",") if s.strip()]
    budget = args.budget
    print(f"default command: mcreynolds {duration_s:g} s, budget {budget}, {len(tune.DEFAULT_FIT_PARAMS)} default parameters, "
          f"FitOptions' runs per trial ({tune.FitOptions().runs_per_trial}), start at the scenario's values; "
          f"{os.cpu_count()} cores", flush=True)
    rows: list[dict[str, Any]] = []
    for i in range(args.first, args.first + args.settings):
        hidden = {k: v for k, v in draw(args.seed, i)[0].items() if k in GOAL_PARAMS}
        s = base
        for key, v in hidden.items():
            s = set_value(s, key, v)
        real = simulate(s, seed=1000 + i, num_threads=os.cpu_count() or 1)
        print(f"setting {i}: " + ", ".join(f"{SHORT[k]} {hidden[k]:.4g}" for k in GOAL_PARAMS)
              + f"; {real.events.size} events", flush=True)
        for stats in statistics:
            t0 = time.perf_counter()
            res = tune.fit(real.events, real.meta, base, tune.FitOptions(budget=budget, statistics=stats),
                           workers=args.workers)
            elapsed = time.perf_counter() - t0
            found = res.best_params
            ok = (all(abs(found[k] / hidden[k] - 1.0) <= THRESHOLD_TOL for k in GOAL_PARAMS if "theta" in k)
                  and 1.0 / RATE_FACTOR <= found["pixel.dark_rate_e_per_s"] / hidden["pixel.dark_rate_e_per_s"]
                  <= RATE_FACTOR)
            rep = res.identifiability
            r = math.nan if rep is None else float(rep.correlation[rep.params.index("pixel.theta_on"),
                                                                   rep.params.index("pixel.dark_rate_e_per_s")])
            rows.append({"setting": i, "statistics": stats, "ok": ok, "seconds": elapsed, "r": r})
            ratios = " ".join(f"{SHORT[k]} {found[k] / hidden[k]:.3f}" for k in GOAL_PARAMS)
            print(f"  {stats:7s} {'ok  ' if ok else 'FAIL'} d={res.best_distance:.4f} {elapsed:6.1f} s  found/hidden: "
                  f"{ratios}; r(th_on, dark) {r:+.2f}; stopped: {res.stop_reason}, {len(res.history)} trials",
                  flush=True)
    if args.csv:
        with open(args.csv, "w", newline="", encoding="utf-8") as fh:
            w = csv.DictWriter(fh, fieldnames=["setting", "statistics", "ok", "seconds", "r"])
            w.writeheader()
            w.writerows(rows)
    print()
    print("| statistics | recovered | median r(theta_on, dark) | mean time per fit |")
    print("|---|---|---|---|")
    for stats in statistics:
        mine = [r for r in rows if r["statistics"] == stats]
        print(f"| {stats} | {sum(r['ok'] for r in mine)}/{len(mine)} | {np.nanmedian([r['r'] for r in mine]):+.2f} | "
              f"{np.mean([r['seconds'] for r in mine]):.1f} s |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--settings", type=int, default=10, help="hidden settings (default 10)")
    ap.add_argument("--first", type=int, default=0, help="first setting's number (default 0)")
    ap.add_argument("--budget", type=int, default=60, help="trials per fit (default 60)")
    ap.add_argument("--samplers", default="ls,nm",
                    help="optimisers compared, each optionally with its distance (e.g. cmaes:chi2; default ls,nm)")
    ap.add_argument("--duration", type=float, default=0.5, help="recording length [s] (default 0.5)")
    ap.add_argument("--runs-per-trial", type=int, default=2, help="seeds per trial (default 2)")
    ap.add_argument("--workers", type=int, default=None, help="worker processes (default: cores)")
    ap.add_argument("--batch-size", type=int, default=4, help="Optuna samplers' trials per round (default 4)")
    ap.add_argument("--seed", type=int, default=0, help="generator seed of the hidden settings")
    ap.add_argument("--csv", default=None, help="also write the rows to this CSV file")
    ap.add_argument("--score-hidden", action="store_true",
                    help="also print each setting's hidden values' distance with the fits' seeds (one trial)")
    ap.add_argument("--profile", action="store_true", help="measure the distances' noise and sensitivity instead")
    ap.add_argument("--default-command", action="store_true",
                    help="issue 34's goal: the default fit command (the default parameters, 1 run per trial, the scenario's "
                         "start) on hidden thresholds and dark rate, 1 s (see the module docstring)")
    ap.add_argument("--statistics", default="timing,counts",
                    help="the chi-square's statistics compared with --default-command (default timing,counts; "
                         "otherwise the first is used)")
    ap.add_argument("--profile-pairs", type=int, default=5, help="seed pairs per point of --profile (default 5)")
    args = ap.parse_args()
    if args.default_command:
        default_command(args)
        return
    if args.profile:
        for i in range(args.first, args.first + args.settings):
            profile(scene(args.duration), args.seed, i, args.profile_pairs)
        return
    samplers = [s.strip() for s in args.samplers.split(",") if s.strip()]
    base = scene(args.duration)
    print(f"mcreynolds {args.duration:g} s, 346 x 260 px, budget {args.budget} x {args.runs_per_trial} seed(s), "
          f"{os.cpu_count()} cores", flush=True)
    header = ["setting", "sampler", "ok", "distance", "seconds",
              *[f"{SHORT[k]}_{w}" for k in PARAMS for w in ("hidden", "start", "found")]]
    rows: list[dict[str, Any]] = []
    for i in range(args.first, args.first + args.settings):
        hidden, start = draw(args.seed, i)
        s = base
        for key, v in hidden.items():
            s = set_value(s, key, v)
        real = simulate(s, seed=1000 + i, num_threads=os.cpu_count() or 1)
        print(f"setting {i}: " + ", ".join(f"{SHORT[k]} {hidden[k]:.4g} (start {start[k]:.4g})" for k in PARAMS)
              + f"; {real.events.size} events", flush=True)
        for sampler in samplers:
            t0 = time.perf_counter()
            name, _, distance = sampler.partition(":")
            opts = tune.FitOptions(params=PARAMS, budget=args.budget, runs_per_trial=args.runs_per_trial, seed=0,
                                   sampler=name, start=start, distance=distance or None, batch_size=args.batch_size,
                                   statistics=args.statistics.split(",")[0])
            res = tune.fit(real.events, real.meta, base, opts, workers=args.workers)
            elapsed = time.perf_counter() - t0
            found = res.best_params
            ok = success(hidden, found)
            row: dict[str, Any] = {"setting": i, "sampler": sampler, "ok": ok, "distance": res.best_distance,
                                   "seconds": elapsed}
            for k in PARAMS:
                row.update({f"{SHORT[k]}_hidden": hidden[k], f"{SHORT[k]}_start": start[k],
                            f"{SHORT[k]}_found": found[k]})
            rows.append(row)
            ratios = " ".join(f"{SHORT[k]} {found[k] / hidden[k]:.3f}" for k in PARAMS)
            print(f"  {sampler:11s} {'ok  ' if ok else 'FAIL'} d={res.best_distance:.4f} {elapsed:5.1f} s  "
                  f"found/hidden: {ratios}", flush=True)
            if args.score_hidden:  # the hidden values as the one trial of a fit: same seeds, same distance
                at = tune.fit(real.events, real.meta, base,
                              tune.FitOptions(params=PARAMS, budget=1, runs_per_trial=args.runs_per_trial, seed=0,
                                              sampler=name, start=hidden, distance=distance or None,
                                              statistics=args.statistics.split(",")[0]), workers=args.workers)
                print(f"  {'':11s} the hidden values score d={at.history[0].distance:.4f}", flush=True)
    if args.csv:
        with open(args.csv, "w", newline="", encoding="utf-8") as fh:
            w = csv.DictWriter(fh, fieldnames=header)
            w.writeheader()
            w.writerows(rows)
    print()
    print("| optimiser | recovered | thresholds within 10 % | rates within x1.5 | mean time per fit |")
    print("|---|---|---|---|---|")
    for sampler in samplers:
        mine = [r for r in rows if r["sampler"] == sampler]
        th = sum(all(abs(r[f"{SHORT[k]}_found"] / r[f"{SHORT[k]}_hidden"] - 1) <= THRESHOLD_TOL
                     for k in PARAMS if "theta" in k) for r in mine)
        rt = sum(all(1 / RATE_FACTOR <= r[f"{SHORT[k]}_found"] / r[f"{SHORT[k]}_hidden"] <= RATE_FACTOR
                     for k in PARAMS if "theta" not in k) for r in mine)
        n = len(mine)
        print(f"| {sampler} | {sum(r['ok'] for r in mine)}/{n} | {th}/{n} | {rt}/{n} | "
              f"{np.mean([r['seconds'] for r in mine]):.1f} s |")
    sys.stdout.flush()


if __name__ == "__main__":
    main()
