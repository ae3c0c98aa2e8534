"""The event-heavy load's pixel at several sample rates: its counts, and the CPU time they cost.

`bench_engine.py --load event-heavy` times the engine on a pixel whose 200 Hz source follower
lets the 18,000 e-/s dark current's shot noise cross the thresholds ~900 times a second. Its
1 kHz samples are long against that follower (b dt = 1.26), so the engine cuts each interval
where a crossing is plausible into pieces of b h <= 1/8 (`refine_and_compare`). This script
runs the same pixel in the dark (48 x 48 px, 1 s, seeds 1-4, one thread) at each of --rates
and prints the events per pixel per second and the process CPU time per event: whether the
count at 1 kHz is the converged one (that of a rate where no interval needs cutting, b dt <
1/8 from 1.6 kHz up), and what the events cost at each rate.

    python bench/event_heavy_convergence.py [--rates 1000,4000,16000] [--side 48] [--duration 1]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from evstwin import PixelParams, Sensor

SEEDS = (1, 2, 3, 4)
CHUNK = 500  # samples a run() call


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rates", default="1000,4000,16000", help="sample rates [Hz], comma-separated")
    ap.add_argument("--side", type=int, default=48, help="pixels a side")
    ap.add_argument("--duration", type=float, default=1.0, help="sensor time [s]")
    args = ap.parse_args()
    try:
        rates = [float(r) for r in args.rates.split(",")]
    except ValueError:
        ap.error(f"--rates must be numbers, comma-separated; got --rates={args.rates}")
    if not all(r > 0 for r in rates):
        ap.error(f"--rates must be > 0; got --rates={args.rates}")
    if args.side < 1:
        ap.error(f"--side must be at least 1; got --side={args.side}")
    if not args.duration > 0:
        ap.error(f"--duration must be > 0; got --duration={args.duration}")
    params = PixelParams(threshold_sigma=0.03, cutoff_hz=200.0)  # bench_engine.py's event-heavy pixel
    side = args.side
    print(f"event-heavy pixel in the dark, {side} x {side} px, {args.duration:g} s, seeds {SEEDS}, 1 thread")
    for rate in rates:
        on = off = 0
        cpu = 0.0
        for seed in SEEDS:
            sensor = Sensor(side, side, params, seed=seed, num_threads=1)
            t = np.arange(int(round(args.duration * rate)) + 1) / rate
            dark = np.zeros((CHUNK, side, side))
            for a in range(0, t.size, CHUNK):
                times = t[a : a + CHUNK]
                c0 = time.process_time()
                ev = sensor.run(dark[: times.size], times)
                cpu += time.process_time() - c0
                k = int(np.count_nonzero(ev["p"]))
                on, off = on + k, off + len(ev) - k
        px_s = side * side * args.duration * len(SEEDS)
        print(f"{rate:8.0f} Hz: events a pixel a second {(on + off) / px_s:8.2f} (ON {on / px_s:.2f}, "
              f"OFF {off / px_s:.2f}); CPU {cpu:.2f} s, {1e9 * cpu / max(on + off, 1):.0f} ns an event", flush=True)


if __name__ == "__main__":
    main()
