"""What building a sensor costs in a fresh process: the first touch of its state (176 bytes a
pixel, 162 MB for the IMX636) and each pixel's initial state.

    python bench/bench_sensor_build.py [--preset imx636] [--threads 2] [--runs 10]

Each run is its own Python process (a fresh address space, as ``evstwin simulate`` starts
with), timed around the ``Sensor`` constructor alone; prints every run's seconds and their
range. On a virtual machine the first touch of memory the hypervisor has not backed yet
dominates, and varies from process to process: read the range, not one run.
"""

from __future__ import annotations

import argparse
import subprocess
import sys

CHILD = """
import sys, time
from evstwin import Sensor
from evstwin.presets import get_preset
p = get_preset(sys.argv[1])
t0 = time.perf_counter()
Sensor(p.width, p.height, p.pixel, seed=1, num_threads=int(sys.argv[2]))
print(time.perf_counter() - t0)
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--preset", default="imx636")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--runs", type=int, default=10)
    args = ap.parse_args()
    if args.threads < 1:
        ap.error(f"--threads must be >= 1; got --threads={args.threads}")
    if args.runs < 1:
        ap.error(f"--runs must be >= 1; got --runs={args.runs}")
    times = []
    for _ in range(args.runs):
        out = subprocess.run([sys.executable, "-c", CHILD, args.preset, str(args.threads)], capture_output=True,
                             text=True, check=False)
        if out.returncode != 0:
            raise SystemExit(f"bench_sensor_build: the child failed (exit {out.returncode}):\n{out.stderr[-2000:]}")
        times.append(float(out.stdout.split()[-1]))
    print(f"{args.preset}, {args.threads} thread(s), {args.runs} fresh processes: "
          + " ".join(f"{t:.3f}" for t in times) + f" s; {min(times):.3f}-{max(times):.3f} s")


if __name__ == "__main__":
    main()
