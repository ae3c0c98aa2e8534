"""Do the noise statistics depend on the simulator's own sampling? (issue 9)

Static scenes (dark, lit, bright) on a 32 x 32 window of the DAVIS346 pixel with the
photoreceptor pole, at a base sample rate and 4x finer, and optionally the built-in
`mcreynolds` scenario at its own sampling, 4x finer (rate x 4, max_shift_px / 4) and dense
(no sparse sub-sampling), each over several seeds. Prints event counts, their relative change
and the spread between seeds, for both noise models.

    python bench/noise_convergence.py [--duration 20] [--seeds 1,2,3] [--factor 4] [--mcreynolds 5]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from evstwin import PixelParams, Sensor, simulate
from evstwin.simulate import resolve_scenario

SCENES = {
    # name: (photons/s on each pixel, thresholds)
    "dark": (0.0, 0.08, 0.06),
    "lit (3e7 ph/s)": (3e7, 0.06, 0.05),
    "bright (1e10 ph/s)": (1e10, 0.008, 0.008),
}


def static_count(model: str, photon_rate: float, theta_on: float, theta_off: float, rate_hz: float,
                 duration_s: float, seed: int) -> int:
    params = PixelParams(pr_pole=True, theta_on=theta_on, theta_off=theta_off, leak_rate_hz=0.0,
                         shot_noise_rate_hz=0.0, noise_model=model)
    sensor = Sensor(32, 32, params, seed=seed, num_threads=1)
    n = int(round(duration_s * rate_hz))
    per = int(rate_hz)
    total = 0
    for k0 in range(0, n + 1, per):
        t = np.arange(k0, min(n + 1, k0 + per)) / rate_hz
        total += len(sensor.run(np.broadcast_to(np.full((1, 32, 32), photon_rate), (len(t), 32, 32)), t))
    return total


def row(name: str, base: list[int], fine: list[int]) -> str:
    b, f = statistics.mean(base), statistics.mean(fine)
    spread = statistics.stdev(base) / b * 100 if len(base) > 1 and b else float("nan")
    change = (f - b) / b * 100 if b else float("nan")
    return f"| {name} | {b:,.0f} | {f:,.0f} | {change:+.1f} % | {spread:.1f} % |"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=20.0, help="sensor time of the static scenes [s]")
    ap.add_argument("--seeds", default="1,2,3", help="comma-separated seeds")
    ap.add_argument("--rate", type=float, default=250.0, help="base sample rate of the static scenes [Hz]")
    ap.add_argument("--factor", type=float, default=4.0, help="how much finer the second sampling is (default 4)")
    ap.add_argument("--mcreynolds", type=float, default=0.0, help="also run mcreynolds for this many seconds")
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    start = time.perf_counter()
    print(f"static scenes, 32 x 32 px, {args.duration:g} s, seeds {seeds}: mean events at {args.rate:g} Hz "
          f"and {args.factor * args.rate:g} Hz")
    for model in ("continuous", "sampled"):
        print(f"\nnoise_model = {model}\n")
        print(f"| scene | {args.rate:g} Hz | {args.factor * args.rate:g} Hz | change | seed spread |")
        print("|---|---|---|---|---|")
        for name, (ph, on, off) in SCENES.items():
            base = [static_count(model, ph, on, off, args.rate, args.duration, s) for s in seeds]
            fine = [static_count(model, ph, on, off, args.factor * args.rate, args.duration, s) for s in seeds]
            print(row(name, base, fine), flush=True)
    if args.mcreynolds > 0:
        print(f"\nmcreynolds, {args.mcreynolds:g} s, seeds {seeds}\n")
        print("| sampling | events (mean) | change | seed spread |")
        print("|---|---|---|---|")
        configs = {
            "its own (250 Hz, max_shift_px 0.25, sparse)": [],
            "4x finer (1000 Hz, max_shift_px 0.0625)": ["sampling.rate_hz=1000", "sampling.max_shift_px=0.0625"],
            "dense (sparse = false)": ["sampling.sparse=false"],
        }
        ref = None
        for name, sets in configs.items():
            counts = [simulate(resolve_scenario("mcreynolds", sets), duration_s=args.mcreynolds, seed=s,
                               num_threads=2).n_events for s in seeds]
            m = statistics.mean(counts)
            ref = m if ref is None else ref
            spread = statistics.stdev(counts) / m * 100 if len(counts) > 1 else float("nan")
            print(f"| {name} | {m:,.0f} | {(m - ref) / ref * 100:+.2f} % | {spread:.2f} % |", flush=True)
    print(f"\n({time.perf_counter() - start:.0f} s)")


if __name__ == "__main__":
    main()
