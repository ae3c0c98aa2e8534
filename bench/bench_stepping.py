"""Time steps per pixel against every pixel at the base rate, scene by scene (issue 33).

Runs ``bench/bench_simulate.py`` for each scene twice, with ``sampling.static_step_s`` at the
given step and at 0 (every pixel at the base rate; the fine rate near fast sources), each in
its own process (its peak memory is its own), and prints one Markdown table: simulate wall
time, seconds of it per sensor second, the engine's and the scene layer's share, pixel-updates,
peak memory and events. The two runs' events differ (different time grids) but their counts
agree within seed noise; the per-pixel statistics are tested in tests/python/test_stepping.py.

    python bench/bench_stepping.py [--threads 2] [--step 0.5] [--quick]

The scenes are the issue's: leo-pass on the IMX636 (4 s and 16 s: the second gives the cost
per sensor second with the fixed costs of building the sky and the sensor spread out),
leo-pass on its DAVIS346, a GEO stare on the IMX636 (geo-stare-imx636) and mcreynolds;
geo-stare as it ships, on its DAVIS346, whose dark pixel is noisier (long steps pay less
there); and geo-belt on its DAVIS346. leo-pass, geo-stare-imx636 and geo-belt take long steps
by default. --quick runs shorter durations (a check that
the script works, not figures).
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
from pathlib import Path

BENCH = Path(__file__).resolve().parent / "bench_simulate.py"

SCENES: list[tuple[str, str, float, list[str]]] = [
    # (label, scenario, duration_s, --set assignments)
    ("leo-pass, IMX636", "leo-pass", 4.0, ["pointing.at_s=2", "sensor.preset=imx636"]),
    ("leo-pass, IMX636", "leo-pass", 16.0, ["pointing.at_s=2", "sensor.preset=imx636"]),
    ("leo-pass, DAVIS346", "leo-pass", 10.0, ["pointing.at_s=2"]),
    ("geo-stare-imx636", "geo-stare-imx636", 10.0, []),
    ("geo-stare, DAVIS346", "geo-stare", 10.0, []),
    ("geo-belt, DAVIS346", "geo-belt", 10.0, []),
    ("mcreynolds", "mcreynolds", 10.0, []),
]

FIELDS = {
    "simulate_s": r"simulate ([0-9.]+) s",
    "engine_s": r"engine \(C\+\+\): ([0-9.]+) s",
    "scene_s": r"scene \(Python\): ([0-9.]+) s",
    "events": r"events: ([0-9]+)",
    "updates": r"pixel-updates: ([0-9.e+]+)",
    "peak_mb": r"peak memory \(max RSS\): ([0-9]+) MB",
}


def run(scenario: str, duration_s: float, sets: list[str], step_s: float, threads: int) -> dict[str, float]:
    cmd = [sys.executable, str(BENCH), "--scenario", scenario, "--duration", f"{duration_s:g}",
           "--threads", str(threads)]
    for s in [*sets, f"sampling.static_step_s={step_s:g}"]:
        cmd += ["--set", s]
    out = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if out.returncode != 0:
        raise SystemExit(f"bench_stepping: {' '.join(cmd)} failed (exit {out.returncode}):\n{out.stderr[-2000:]}")
    found: dict[str, float] = {}
    for name, pattern in FIELDS.items():
        m = re.search(pattern, out.stdout)
        if m is None:
            raise SystemExit(f"bench_stepping: no {name!r} in bench_simulate's output:\n{out.stdout}")
        found[name] = float(m.group(1))
    return found


def cell(r: dict[str, float], duration_s: float) -> str:
    return (f"{r['simulate_s']:.2f} s ({r['simulate_s'] / duration_s:.3f} s/s; engine {r['engine_s']:.2f}, "
            f"scene {r['scene_s']:.2f}), {r['updates']:.2g} updates, {r['peak_mb']:.0f} MB, {r['events']:,.0f} events")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--step", type=float, default=0.5, help="sampling.static_step_s of the stepped runs [s]")
    ap.add_argument("--quick", action="store_true", help="short durations: checks the script, not figures")
    args = ap.parse_args()
    if not args.step > 0:
        ap.error(f"--step must be > 0 s; got {args.step}")
    if args.threads < 1:
        ap.error(f"--threads must be >= 1; got {args.threads}")
    print(f"| scene | sensor time | time steps per pixel ({args.step:g} s) | every pixel at the base rate | "
          "speed-up |")
    print("|---|---|---|---|---|")
    for label, scenario, duration_s, sets in SCENES:
        d = min(duration_s, 0.6) if args.quick else duration_s
        if args.quick:  # the pointing must aim within the shortened run
            sets = [f"pointing.at_s={d / 2:g}" if a.startswith("pointing.at_s=") else a for a in sets]
        stepped = run(scenario, d, sets, args.step, args.threads)
        dense = run(scenario, d, sets, 0.0, args.threads)
        print(f"| {label} | {d:g} s | {cell(stepped, d)} | {cell(dense, d)} | "
              f"{dense['simulate_s'] / stepped['simulate_s']:.1f}x |", flush=True)


if __name__ == "__main__":
    main()
