"""Time steps per pixel against every pixel at the base rate: a dark pixel's statistics, many
seeds (issue 33's "the same physics").

A scenario's pixel (mcreynolds' by default: the paper's DAVIS346 photodiode, the photoreceptor
pole, 18,000 e-/s dark current, leak 0.1 Hz, shot noise 0.05 Hz) on a square sensor in the
dark, run twice per seed: every pixel at the base rate (``Sensor.run``) and in long steps
(``Sensor.run_sparse`` with no light, one call per step). Prints the events (ON, OFF) and the
share of pixels with 0, 1, ... events, each path's mean over the seeds, and their difference in
standard errors (the seeds' spread): the noise model advances a pixel exactly over any
interval, so no difference should stand out of the noise.

    python bench/stepping_statistics.py [--seeds 20] [--side 192] [--duration 10] [--rate 250]
                                        [--step 0.5] [--scenario mcreynolds] [--set pixel.FIELD=VALUE ...]

``--set pixel.leak_rate_hz=0`` (or ``pixel.shot_noise_rate_hz=0``) switches one noise source
off, to find which one a difference comes with.
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from evstwin import PixelParams, Sensor
from evstwin.scenario import build
from evstwin.simulate import resolve_scenario

BINS = 6  # shares of pixels with 0 .. BINS - 2 events, and BINS - 1 or more


def pixel_params(scenario: str, sets: list[str]) -> PixelParams:
    params = build(resolve_scenario(scenario, [])).params
    changes = {}
    for item in sets:
        key, _, value = item.partition("=")
        if not key.startswith("pixel.") or not value:
            raise SystemExit(f"stepping_statistics: --set must be pixel.FIELD=VALUE; got --set {item}")
        changes[key.removeprefix("pixel.")] = float(value)
    fields = {f.name for f in dataclasses.fields(params)}
    for key in changes:
        if key not in fields:
            raise SystemExit(f"stepping_statistics: PixelParams has no field {key!r} (--set pixel.{key}=...)")
    return dataclasses.replace(params, **changes)


def count_shares(events: np.ndarray, width: int, height: int) -> np.ndarray:
    """The share of the width x height pixels with 0 .. BINS - 2 events, and BINS - 1 or more."""
    per_pixel = np.bincount(events["y"].astype(np.int64) * width + events["x"], minlength=width * height)
    return np.bincount(np.minimum(per_pixel, BINS - 1), minlength=BINS) / per_pixel.size


def difference_in_se(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(mean of b - mean of a) over the standard error of that difference (Welch), column by
    column of two (seeds x statistics) tables; NaN where neither varies."""
    se = np.sqrt(a.var(axis=0, ddof=1) / len(a) + b.var(axis=0, ddof=1) / len(b))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(se > 0, (b.mean(axis=0) - a.mean(axis=0)) / se, np.nan)


def counts(events: np.ndarray, side: int) -> tuple[np.ndarray, int, int]:
    on = int(np.count_nonzero(events["p"] == 1))
    return count_shares(events, side, side), on, len(events) - on


def run(params: PixelParams, seed: int, side: int, duration_s: float, rate_hz: float, step_s: float,
        stepped: bool) -> tuple[np.ndarray, int, int]:
    sensor = Sensor(side, side, params, seed=seed, num_threads=2)
    dark = np.zeros((side, side))
    parts = [sensor.run(dark[None], np.array([0.0]))]  # the first sample sets the steady state
    n = round(duration_s * rate_hz)
    per = max(1, round(step_s * rate_hz)) if stepped else 250
    for j in range(1, n + 1, per):
        t = np.arange(j, min(j + per, n + 1)) / rate_hz
        if stepped:
            parts.append(sensor.run_sparse(dark, t, base_every=1, group_base_samples=t.size))
        else:
            parts.append(sensor.run(np.broadcast_to(dark, (t.size, side, side)).copy(), t))
    return counts(np.concatenate(parts), side)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--side", type=int, default=192, help="pixels a side")
    ap.add_argument("--duration", type=float, default=10.0, help="sensor time [s]")
    ap.add_argument("--rate", type=float, default=250.0, help="base rate [Hz]")
    ap.add_argument("--step", type=float, default=0.5, help="long step [s]")
    ap.add_argument("--scenario", default="mcreynolds", help="whose pixel")
    ap.add_argument("--set", dest="sets", action="append", default=[], help="pixel.FIELD=VALUE")
    args = ap.parse_args()
    for name in ("seeds", "side"):
        if getattr(args, name) < 2:
            ap.error(f"--{name} must be at least 2; got --{name}={getattr(args, name)}")
    for name in ("duration", "rate", "step"):
        if not getattr(args, name) > 0:
            ap.error(f"--{name} must be > 0; got --{name}={getattr(args, name)}")
    params = pixel_params(args.scenario, args.sets)
    start = time.perf_counter()
    rows = {}
    for label, stepped in (("base rate", False), ("long steps", True)):
        rows[label] = [run(params, seed, args.side, args.duration, args.rate, args.step, stepped)
                       for seed in range(1, args.seeds + 1)]
    changed = f" ({', '.join(args.sets)})" if args.sets else ""
    print(f"{args.scenario}'s pixel{changed} in the dark, {args.side} x {args.side} px, {args.duration:g} s, "
          f"base rate {args.rate:g} Hz, long steps {args.step:g} s, seeds 1-{args.seeds} "
          f"({time.perf_counter() - start:.0f} s)")
    tables = {}
    for label, runs in rows.items():
        table = tables[label] = np.array([[*shares, on, off] for shares, on, off in runs])
        on, off = int(table[:, BINS].sum()), int(table[:, BINS + 1].sum())
        shares = " ".join(f"{v:.5f}" for v in table.mean(axis=0)[:BINS])
        print(f"{label:11s} events {on + off:,} (ON {on:,}, OFF {off:,}); pixels with 0..{BINS - 1}+ events: {shares}")
    z = np.nan_to_num(difference_in_se(tables["base rate"], tables["long steps"]))  # 0 where both agree exactly
    names = [f"share {k}" for k in range(BINS - 1)] + [f"share {BINS - 1}+", "ON", "OFF"]
    print("long steps - base rate, in standard errors: " + ", ".join(f"{n} {v:+.1f}" for n, v in zip(names, z)))


if __name__ == "__main__":
    main()
