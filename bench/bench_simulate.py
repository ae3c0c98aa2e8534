"""End-to-end throughput: `evstwin simulate mcreynolds` for 10 s of sensor time (issue 3).

Prints wall time, peak memory, events/s, and the split between the Python scene layer
(trajectories, PSF rendering, hot-pixel bookkeeping) and the C++ engine.

    python bench/bench_simulate.py [--scenario mcreynolds] [--duration 10] [--threads 2]
                                   [--unit-samples N]

--unit-samples sets simulate.SUB_SAMPLED_UNIT_SAMPLES for the run (the figures in its
docstring: `--duration 4 --threads 2 --unit-samples 50`, 100, ... 250).
"""

from __future__ import annotations

import argparse
import importlib
import os
import resource
import tempfile
import time
from pathlib import Path

from evstwin.io import write_events
from evstwin.simulate import simulate

runner_module = importlib.import_module("evstwin._runner")  # where the chunk loop reads its unit


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default="mcreynolds")
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--threads", type=int, default=None)
    ap.add_argument("--set", dest="sets", action="append", default=[])
    ap.add_argument("--unit-samples", type=int, default=None,
                    help="fine samples in a unit of the fine-sampling decision (default: the package's)")
    args = ap.parse_args()
    if args.unit_samples is not None:
        if args.unit_samples < 1:
            ap.error(f"--unit-samples must be >= 1; got {args.unit_samples}")
        runner_module.SUB_SAMPLED_UNIT_SAMPLES = args.unit_samples
    start = time.perf_counter()
    result = simulate(args.scenario, duration_s=args.duration, num_threads=args.threads, sets=args.sets)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        path = Path(tmp) / "out.h5"
        write_events(path, result.events, result.meta)
        write_s = time.perf_counter() - t0
        size_mb = path.stat().st_size / 1e6
    wall = time.perf_counter() - start
    usage = resource.getrusage(resource.RUSAGE_SELF)
    peak_mb = usage.ru_maxrss / 1024
    cpu_s = usage.ru_utime + usage.ru_stime  # all threads, the imports included
    n = len(result.events)
    print(f"machine: {os.cpu_count()} cores; scenario {args.scenario}, {args.duration:g} s of sensor time")
    print(f"wall time: {wall:.2f} s  (simulate {result.wall_s:.2f} s, write .h5 {write_s:.2f} s, {size_mb:.1f} MB)")
    print(f"  engine (C++): {result.engine_s:.2f} s  {result.pixel_updates / result.engine_s / 1e6:.1f} M pixel-updates/s")
    other = result.wall_s - result.engine_s - result.scene_s
    print(f"  scene (Python): {result.scene_s:.2f} s   other: {other:.2f} s")
    print(f"events: {n}  ({n / wall:.3g} events per wall second; {n / args.duration:.3g} per sensor second)")
    print(f"pixel-updates: {result.pixel_updates:.3g}  sub-sampled chunks: {result.sub_sampled_chunks}")
    print(f"peak memory (max RSS): {peak_mb:.0f} MB")
    print(f"CPU time (all threads, with the imports): {cpu_s:.2f} s, {result.wall_s / args.duration:.3g} s of "
          f"simulate wall time per sensor second")


if __name__ == "__main__":
    main()
