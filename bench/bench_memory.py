"""Peak memory of `evstwin simulate` against the duration (issue 8: memory flat however long).

Runs `evstwin simulate SCENARIO -o OUT --duration D` in a fresh process for each duration and
prints its peak resident memory (the child's max RSS), the events written and the file size.
With events and ground truth streamed into the file the peak should not grow with D.

    python bench/bench_memory.py [--scenario mcreynolds] [--durations 1,10,100] [--format h5]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# The command runs in a fresh interpreter that prints its own peak resident memory at the end.
CHILD = (
    "import resource, sys\n"
    "from evstwin.cli import main\n"
    "rc = main(sys.argv[1:])\n"
    "print('peak_kb', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)\n"
    "sys.exit(rc)\n"
)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default="mcreynolds")
    ap.add_argument("--durations", default="1,10,100", help="sensor seconds, comma list (default 1,10,100)")
    ap.add_argument("--format", default="h5", help="output suffix (default h5)")
    ap.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()
    print(f"machine: {os.cpu_count()} cores; evstwin simulate {args.scenario} -o out.{args.format}")
    print(f"{'duration [s]':>12s} {'wall [s]':>9s} {'peak RSS [MB]':>14s} {'events':>11s} {'file [MB]':>10s}")
    with tempfile.TemporaryDirectory() as tmp:
        for text in args.durations.split(","):
            out = Path(tmp) / f"out_{text}.{args.format}"
            cmd = [sys.executable, "-c", CHILD, "simulate", args.scenario, "-o", str(out),
                   "--duration", text, "--no-progress"]
            for s in args.sets:
                cmd += ["--set", s]
            start = time.perf_counter()
            proc = subprocess.run(cmd, check=True, capture_output=True, text=True)
            wall = time.perf_counter() - start
            lines = proc.stdout.splitlines()
            peak_kb = int(next(line.split()[1] for line in lines if line.startswith("peak_kb")))
            events = next(line.split()[1] for line in lines if line.startswith("events:"))
            print(f"{float(text):12g} {wall:9.1f} {peak_kb / 1024:14.0f} {events:>11s} "
                  f"{out.stat().st_size / 1e6:10.1f}", flush=True)
            out.unlink()


if __name__ == "__main__":
    main()
