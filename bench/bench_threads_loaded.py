"""The default thread count on a busy machine (issue 8, defect 2).

Runs `evstwin.simulate` of a built-in scenario in a fresh process with `--threads 1` and with
the default thread count, first on a quiet machine and then while a competing process keeps
one core busy (a Python spin loop), and prints the wall times. The default must never be
slower than one thread. Each configuration runs `--repeats` times, alternating, and the
median is printed (the machine is shared, single runs are noisy).

    python bench/bench_threads_loaded.py [--scenario mcreynolds] [--duration 3] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys

CHILD = """
import sys, time
from evstwin.simulate import simulate
threads = None if sys.argv[3] == "default" else int(sys.argv[3])
start = time.perf_counter()
simulate(sys.argv[1], duration_s=float(sys.argv[2]), num_threads=threads)
print(time.perf_counter() - start)
"""

BUSY = "import time\nend = time.time() + 3600\nwhile time.time() < end: pass\n"


def run_once(scenario: str, duration: float, threads: str) -> float:
    out = subprocess.run([sys.executable, "-c", CHILD, scenario, str(duration), threads],
                         check=True, capture_output=True, text=True)
    return float(out.stdout.strip().splitlines()[-1])


def measure(scenario: str, duration: float, repeats: int) -> dict[str, float]:
    times: dict[str, list[float]] = {"1": [], "default": []}
    for _ in range(repeats):
        for threads in times:
            times[threads].append(run_once(scenario, duration, threads))
    return {k: statistics.median(v) for k, v in times.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default="mcreynolds")
    ap.add_argument("--duration", type=float, default=3.0, help="sensor time per run [s] (default 3)")
    ap.add_argument("--repeats", type=int, default=3, help="runs per configuration (default 3)")
    args = ap.parse_args()
    print(f"machine: {os.cpu_count()} cores; {args.scenario}, {args.duration:g} s of sensor time; "
          f"OMP_WAIT_POLICY={os.environ.get('OMP_WAIT_POLICY', '(evstwin default: PASSIVE)')}")
    quiet = measure(args.scenario, args.duration, args.repeats)
    busy = subprocess.Popen([sys.executable, "-c", BUSY])
    try:
        loaded = measure(args.scenario, args.duration, args.repeats)
    finally:
        busy.kill()
        busy.wait()
    print(f"{'':28s} {'--threads 1':>12s} {'default':>12s} {'default/1':>10s}")
    for name, t in (("quiet", quiet), ("one core busy elsewhere", loaded)):
        print(f"{name:28s} {t['1']:11.2f}s {t['default']:11.2f}s {t['default'] / t['1']:10.2f}")


if __name__ == "__main__":
    main()
