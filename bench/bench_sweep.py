"""Throughput of `evstwin sweep` (trials per minute) with 1 and 2 local worker processes.

    PYTHONPATH=python python bench/bench_sweep.py [--workers 1 2] [--runs 2] [--duration 1]
                                                  [--size 160x120] [--dask]

A fixed small grid (3 ON thresholds x 3 dark rates, detect objective on a spinning source
plus a drifting one) x --runs seeds; each trial is one simulation + its metrics. The wall time
includes starting the worker pool, as a user's sweep does. --dask adds an in-process Dask
LocalCluster with the largest --workers count. Prints a table; no asserts.
"""

from __future__ import annotations

import argparse
import os
import time
from typing import Any

from evstwin import tune

GRID: dict[str, list[Any]] = {
    "pixel.theta_on": [0.15, 0.25, 0.4],
    "pixel.dark_rate_e_per_s": [500.0, 2000.0, 8000.0],
}


def scenario(width: int, height: int, duration_s: float) -> dict[str, Any]:
    return {
        "name": "bench-sweep",
        "duration_s": duration_s,
        "background": {"photon_rate_ph_s": 2e6},
        "sensor": {"preset": "davis346", "width": width, "height": height},
        "optics": {"extra_blur_sigma_px": 0.8},
        "sampling": {"rate_hz": 500.0},
        "targets": [
            {
                "kind": "linear",
                "label": "drift",
                "x0_px": 2.0,
                "y0_px": height / 3,
                "vx_px_s": width / duration_s / 1.5,
                "vy_px_s": 0.0,
                "flux_ph_s": 2e9,
            },
            {
                "kind": "circular",
                "label": "spin",
                "centre_x_px": width / 2,
                "centre_y_px": height / 2,
                "radius_px": min(width, height) / 4,
                "period_s": 0.5,
                "flux_ph_s": 4e9,
            },
        ],
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--workers", type=int, nargs="+", default=[1, 2], help="local worker counts (default 1 2)"
    )
    ap.add_argument("--runs", type=int, default=2, help="seeds per grid point (default 2)")
    ap.add_argument("--duration", type=float, default=1.0, help="sensor time per trial [s] (default 1)")
    ap.add_argument("--size", default="160x120", help="sensor window WxH [px] (default 160x120)")
    ap.add_argument("--dask", action="store_true", help="also run on an in-process Dask LocalCluster")
    args = ap.parse_args()
    width, height = (int(v) for v in args.size.lower().split("x"))
    scen = scenario(width, height, args.duration)
    n = len(GRID["pixel.theta_on"]) * len(GRID["pixel.dark_rate_e_per_s"]) * args.runs
    print(
        f"grid 3 x 3 x {args.runs} seeds = {n} trials; {width}x{height} px, {args.duration:g} s each; "
        f"{os.cpu_count()} CPU(s)"
    )
    print(f"{'executor':34s} {'wall [s]':>9s} {'trials/min':>11s}")
    baseline = None
    runs: list[tuple[str, Any, int]] = [(f"local, {w} worker(s)", None, w) for w in args.workers]
    if args.dask:
        w = max(args.workers)
        runs.append((f"dask LocalCluster, {w} worker(s)", "local", w))
    for label, scheduler, workers in runs:
        t0 = time.perf_counter()
        result = tune.sweep(
            scen, GRID, objective="detect", runs=args.runs, scheduler=scheduler, workers=workers
        )
        wall = time.perf_counter() - t0
        rate = len(result.rows) / wall * 60.0
        baseline = baseline or rate
        print(f"{label:34s} {wall:9.2f} {rate:11.1f}   (x{rate / baseline:.2f})")


if __name__ == "__main__":
    main()
