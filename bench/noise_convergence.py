"""Do the noise statistics depend on the simulator's own sampling? (issue 9)

Static scenes (dark, lit, bright) on a 32 x 32 window of the DAVIS346 pixel with the
photoreceptor pole, at a base sample rate and 4x finer, and optionally the built-in
`mcreynolds` scenario at its own sampling, 4x finer (rate x 4, max_shift_px / 4) and dense
(no sparse sub-sampling), each over several seeds. Prints event counts, their relative change
and the spread between seeds, for both noise models.

    python bench/noise_convergence.py [--duration 20] [--seeds 1,2,3] [--factor 4] [--mcreynolds 5]

With --preset, instead: a camera preset's own pixel (64 x 64 px, uniform light of each
--background level) stepped at each of --rates, down to steps far longer than its noise's
correlation time: how long a step a static pixel of that camera may take before its
statistics move (the question per-pixel time steps ask). Prints ON and OFF counts (mean over
the seeds), their change from the finest rate against the seeds' spread, and the share of
pixels with 0, 1, 2 and 3+ events.

    python bench/noise_convergence.py --preset imx636 --rates 1000,200,50,20,5 --background 0,1e5 \
        --duration 5 --seeds 1,2
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from evstwin import PixelParams, Sensor, simulate
from evstwin.presets import get_preset
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


def preset_stats(preset: str, photon_rate: float, rate_hz: float, duration_s: float,
                 seed: int) -> tuple[int, int, np.ndarray]:
    """ON and OFF counts and the share of pixels with 0, 1, 2, 3+ events of a preset's pixel
    under uniform light, stepped at rate_hz (one call a second of sensor time)."""
    side = 64
    sensor = Sensor(side, side, get_preset(preset).pixel_params(), seed=seed, num_threads=1)
    n = int(round(duration_s * rate_hz))
    per = max(1, int(rate_hz))
    on = off = 0
    counts = np.zeros(side * side, np.int64)
    frame = np.full((1, side, side), photon_rate)
    # The first sample, at t = 0, only sets the steady state (Sensor.run): every rate then
    # simulates the whole duration.
    for k0 in range(0, n + 1, per):
        t = np.arange(k0, min(n + 1, k0 + per)) / rate_hz
        ev = sensor.run(np.broadcast_to(frame, (len(t), side, side)), t)
        n_on = int(np.count_nonzero(ev["p"]))
        on += n_on
        off += len(ev) - n_on
        counts += np.bincount(ev["y"].astype(np.int64) * side + ev["x"], minlength=side * side)
    return on, off, np.bincount(np.minimum(counts, 3), minlength=4) / counts.size


def preset_table(args: argparse.Namespace, seeds: list[int]) -> None:
    rates = sorted((float(r) for r in args.rates.split(",")), reverse=True)
    print(f"{args.preset}: 64 x 64 px, uniform light, {args.duration:g} s, seeds {seeds}; change from "
          f"{rates[0]:g} Hz against the seeds' spread (sd of one seed's count / mean)")
    for level in (float(b) for b in args.background.split(",")):
        print(f"\nbackground {level:g} photons/s a pixel\n")
        print("| step rate | ON | OFF | ON change | OFF change | spread ON / OFF | pixels 0 / 1 / 2 / 3+ events |")
        print("|---|---|---|---|---|---|---|")
        ref: tuple[float, float] | None = None
        for rate in rates:
            runs = [preset_stats(args.preset, level, rate, args.duration, s) for s in seeds]
            on = statistics.mean(r[0] for r in runs)
            off = statistics.mean(r[1] for r in runs)
            ref = (on, off) if ref is None else ref
            share = np.mean([r[2] for r in runs], axis=0)

            def pct(a: float, b: float) -> str:
                return f"{(a - b) / b * 100:+.1f} %" if b else "n/a"

            def spread(i: int) -> str:
                vals = [r[i] for r in runs]
                m = statistics.mean(vals)
                return f"{statistics.stdev(vals) / m * 100:.1f} %" if len(vals) > 1 and m else "n/a"

            print(f"| {rate:g} Hz | {on:,.0f} | {off:,.0f} | {pct(on, ref[0])} | {pct(off, ref[1])} | "
                  f"{spread(0)} / {spread(1)} | " + " / ".join(f"{x:.4f}" for x in share) + " |", flush=True)


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
    ap.add_argument("--preset", help="instead: a camera preset's pixel at each of --rates")
    ap.add_argument("--rates", default="1000,200,50,20,5", help="with --preset: step rates [Hz], comma-separated")
    ap.add_argument("--background", default="0", help="with --preset: photons/s on each pixel, comma-separated")
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    start = time.perf_counter()
    if args.preset:
        preset_table(args, seeds)
        print(f"\n({time.perf_counter() - start:.0f} s)")
        return
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
