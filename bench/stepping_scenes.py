"""Time steps per pixel against every pixel at the base rate, on a whole scene, many seeds
(issue 33's "the same physics": per-pixel count histograms, ON/OFF rates and the timing-bias
statistics agree with the dense run within seed-to-seed noise).

Runs ``evstwin.simulate(scenario)`` once per seed with ``sampling.static_step_s=0`` (every
pixel at the base rate, the fine rate where a source moves) and once with
``sampling.static_step_s=STEP`` (a pixel whose light is constant advances in long exact steps).
For each run it takes the events (ON, OFF), the share of the frame's pixels with 0, 1, ...
events, and the event-timing bias against the run's ground truth
(:func:`evstwin.validation.timing_attribution`): per polarity the events attributed to a
crossing, their mean and median delay, and the events no crossing explains. Prints each
path's mean over the seeds, and the difference of the two means in standard errors (the
seeds' spread, Welch). The noise model advances a pixel exactly over any interval, so no
difference should stand out of the noise; the seeds' spread itself should match too.

    python bench/stepping_scenes.py [--scenario mcreynolds] [--duration 10] [--seeds 1-6]
                                    [--step 0.5] [--threads 2] [--set KEY=VALUE ...]

``--set`` changes the scenario for both paths (``pointing.at_s=2``, ``sensor.preset=imx636``).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

import evstwin
from evstwin.simulate import SimulationResult
from evstwin.validation import timing_attribution

sys.path.insert(0, str(Path(__file__).resolve().parent))
from stepping_statistics import BINS, count_shares, difference_in_se  # noqa: E402


def seeds_of(text: str) -> list[int]:
    """'1-6' or '1,4,9' -> the seeds."""
    out: list[int] = []
    for part in text.split(","):
        lo, sep, hi = part.partition("-")
        out.extend(range(int(lo), int(hi) + 1) if sep else [int(lo)])
    return out


def statistics(result: SimulationResult, radius_px: float) -> dict[str, float]:
    """One run's figures, by name."""
    ev = result.events
    shares = count_shares(ev, int(result.meta["width"]), int(result.meta["height"]))
    on = int(np.count_nonzero(ev["p"] == 1))
    row: dict[str, float] = {"ON": on, "OFF": len(ev) - on}
    row.update({f"share {k}" + ("+" if k == BINS - 1 else ""): float(s) for k, s in enumerate(shares)})
    table, counts = timing_attribution(ev, result.meta["truth"], radius_px=radius_px)
    for name, pol in (("ON", 1), ("OFF", 0)):
        delay = np.asarray(table["delay_s"][table["p"] == pol], dtype=np.float64)
        row[f"{name} attributed"] = delay.size
        row[f"{name} mean delay ms"] = 1e3 * float(delay.mean()) if delay.size else math.nan
        row[f"{name} median delay ms"] = 1e3 * float(np.median(delay)) if delay.size else math.nan
    row["unexplained"] = counts["unexplained"]  # on crossed pixels, before or long after a crossing
    row["off track"] = counts["off_track"]  # on pixels no source crossed
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default="mcreynolds")
    ap.add_argument("--duration", type=float, default=None, help="sensor time [s] (default: the scenario's)")
    ap.add_argument("--seeds", default="1-6", help="'1-6' or '1,4,9' (at least 2)")
    ap.add_argument("--step", type=float, default=0.5, help="sampling.static_step_s of the stepped path [s]")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--radius-px", type=float, default=1.0, help="timing attribution's radius [px]")
    ap.add_argument("--set", dest="sets", action="append", default=[], help="KEY=VALUE, for both paths")
    args = ap.parse_args()
    try:
        seeds = seeds_of(args.seeds)
    except ValueError:
        ap.error(f"--seeds must be like 1-6 or 1,4,9; got --seeds={args.seeds}")
    if len(seeds) < 2:
        ap.error(f"--seeds must name at least 2 seeds; got --seeds={args.seeds}")
    if not args.step > 0:
        ap.error(f"--step must be > 0; got --step={args.step}")
    if args.duration is not None and not args.duration > 0:
        ap.error(f"--duration must be > 0; got --duration={args.duration}")
    extra = list(args.sets) + ([f"duration_s={args.duration}"] if args.duration is not None else [])
    paths = {"base rate": ["sampling.static_step_s=0"], "long steps": [f"sampling.static_step_s={args.step}"]}
    rows: dict[str, list[dict[str, float]]] = {label: [] for label in paths}
    wall: dict[str, float] = {label: 0.0 for label in paths}
    for seed in seeds:
        for label, sets in paths.items():  # alternated, so a change in the machine's load hits both
            r = evstwin.simulate(args.scenario, seed=seed, num_threads=args.threads, sets=extra + sets)
            wall[label] += r.wall_s
            rows[label].append(statistics(r, args.radius_px))
            print(f"seed {seed} {label}: {r.n_events:,} events, {r.wall_s:.2f} s", flush=True)
    changed = f" ({', '.join(extra)})" if extra else ""
    print(f"\n{args.scenario}{changed}, seeds {args.seeds}, long steps {args.step:g} s, {args.threads} threads; "
          f"mean wall time a run: base rate {wall['base rate'] / len(seeds):.2f} s, "
          f"long steps {wall['long steps'] / len(seeds):.2f} s")
    # A statistic with nothing to compare (no event attributed to a crossing: a source that
    # crosses no pixel) is left out rather than printed as NaN.
    names = [n for n in rows["base rate"][0]
             if not all(math.isnan(r[n]) or r[n] == 0 for path in rows.values() for r in path)]
    if len(names) < len(rows["base rate"][0]):
        print("(left out, zero or undefined in every run: "
              f"{', '.join(n for n in rows['base rate'][0] if n not in names)})")
    print(f"{'':22s} {'base rate':>24s} {'long steps':>24s} {'diff / SE':>9s} {'sd ratio':>8s}")
    for name in names:
        a = np.array([r[name] for r in rows["base rate"]], dtype=np.float64)
        b = np.array([r[name] for r in rows["long steps"]], dtype=np.float64)
        sa, sb = a.std(ddof=1), b.std(ddof=1)
        z = float(difference_in_se(a, b))
        cell = "{:>12.6g} +- {:<9.3g}"
        print(f"{name:22s} {cell.format(a.mean(), sa)} {cell.format(b.mean(), sb)} {z:>+9.2f} "
              f"{sb / sa if sa > 0 else math.nan:>8.2f}")
    print("(mean +- the seeds' standard deviation; diff / SE: long steps - base rate over the standard error of "
          "the difference of the means; sd ratio: long steps' sd over the base rate's)")


if __name__ == "__main__":
    main()
