"""What a long step costs against the base rate, for one scene's pixel under its own sky.

    python bench/bench_long_steps.py [--scenario geo-stare] [--set sensor.preset=imx636 --set sensor.bias_set=none ...]
        [--side 256] [--duration 16] [--rates 400,100,4,0.25] [--threads 1] [--seed 3]

Takes the resolved scenario's pixel parameters and its sky background (photons/s on a pixel),
and runs a side x side sensor of that pixel under that constant light for --duration seconds
at each step rate (a first sample at t = 0, then one every 1 / rate seconds; 0.25 Hz is one
4 s step, as ``simulate``'s sync period). Prints one Markdown row per rate: wall time, ns of
it per pixel-second, and the ON and OFF counts. The counts agree within seed noise at every
rate (the statistics do not depend on the step; tests/python/test_stepping.py tests it); the
cost is what ``Sensor.run_sparse`` weighs when it gives a pixel long steps or the base
samples (``PixelModel::long_steps_cut_below``). A long step where a crossing is plausible is
cut adaptively (refine.hpp): its cost follows how long the noise stays within reach of a
threshold, not the step's length.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from evstwin import Sensor
from evstwin.scenario.building import build
from evstwin.simulate import resolve_scenario


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default="geo-stare")
    ap.add_argument("--set", action="append", default=None, metavar="KEY=VALUE",
                    help="scenario assignments (default: none, the scenario as it ships)")
    ap.add_argument("--side", type=int, default=256, help="sensor side [px]")
    ap.add_argument("--duration", type=float, default=16.0, help="sensor time [s]")
    ap.add_argument("--rates", default="400,100,4,0.25", help="step rates [Hz], comma-separated")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seed", type=int, default=3)
    args = ap.parse_args()
    rates = [float(r) for r in args.rates.split(",")]
    if args.side < 1:
        ap.error(f"--side must be >= 1; got {args.side}")
    if not args.duration > 0:
        ap.error(f"--duration must be > 0 s; got {args.duration}")
    if not all(r > 0 for r in rates):
        ap.error(f"--rates must all be > 0 Hz; got {args.rates!r}")
    sets = args.set if args.set is not None else []
    # Only the pixel and its sky are taken from the scene, neither of which depends on the
    # run's length: a short build (long enough for leo-pass's pointing.at_s=2).
    scene = build(resolve_scenario(args.scenario, sets), duration_s=min(args.duration, 4.0))
    sky_ph_s = float(np.median(np.asarray(scene.background_ph_s, np.float64)))
    n = args.side
    print(f"{args.scenario} ({', '.join(sets) or 'as it ships'}): sky {sky_ph_s:.4g} photons/s a pixel, {n} x {n} px, "
          f"{args.duration:g} s, {args.threads} thread(s), seed {args.seed}")
    print("| step rate | wall | per pixel-second | ON | OFF |")
    print("|---|---|---|---|---|")
    for rate_hz in rates:
        sensor = Sensor(n, n, scene.params, seed=args.seed, num_threads=args.threads)
        t = np.arange(0, round(args.duration * rate_hz) + 1) / rate_hz
        light = np.broadcast_to(np.full((1, n, n), sky_ph_s), (t.size, n, n))
        start = time.perf_counter()
        events = sensor.run(light, t)
        wall_s = time.perf_counter() - start
        on = int(np.count_nonzero(events["p"]))
        print(f"| {rate_hz:g} Hz | {wall_s:.2f} s | {wall_s / (n * n * args.duration) * 1e9:,.0f} ns | {on:,} | "
              f"{len(events) - on:,} |", flush=True)


if __name__ == "__main__":
    main()
