"""Engine throughput on the DAVIS346 reference load (issue 2).

346 x 260 pixels, 1 kHz samples, 10 s, five point sources on circles, every noise source
on (photon shot noise, Poisson dark current, leak, statistical shot noise, threshold
mismatch, the 10 Hz low-pass, 1 ms refractory). Prints pixel-updates/s and events/s of the
C++ engine with 1 and 2 threads, and of the vectorised NumPy implementation of the same
model (bench/numpy_reference.py) run in the same process on a shorter stretch, and the
ratio. Only the engine's run() calls are timed; the input is rendered beforehand per chunk.

    python bench/bench_engine.py [--duration 10] [--numpy-duration 0.5] [--threads 1,2]
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import numpy_reference  # noqa: E402

from evstwin import PixelParams, Sensor  # noqa: E402
from evstwin._core import has_openmp  # noqa: E402

WIDTH, HEIGHT, RATE_HZ = 346, 260, 1000.0


def render_chunk(t: np.ndarray) -> np.ndarray:
    """Five Gaussian spots (sigma 1.2 px) turning on circles over a dim uniform background."""
    out = np.full((len(t), HEIGHT, WIDTH), 2e6, dtype=np.float32)
    cx, cy = WIDTH / 2, HEIGHT / 2
    for j, radius in enumerate([20, 45, 70, 95, 120]):
        phase = 2 * math.pi * t / 2.0 + j  # one turn in 2 s
        xs, ys = cx + radius * np.cos(phase), cy + radius * np.sin(phase)
        for k in range(len(t)):
            x0, y0 = int(xs[k]) - 5, int(ys[k]) - 5
            yy, xx = np.mgrid[y0 : y0 + 11, x0 : x0 + 11]
            out[k, y0 : y0 + 11, x0 : x0 + 11] += 1e9 * np.exp(-((xx - xs[k]) ** 2 + (yy - ys[k]) ** 2) / (2 * 1.2**2))
    return out


def bench_engine(params: PixelParams, threads: int, chunks: list[tuple[np.ndarray, np.ndarray]]) -> tuple[float, int]:
    sensor = Sensor(WIDTH, HEIGHT, params, seed=1, num_threads=threads)
    elapsed, n_events = 0.0, 0
    for rate, t in chunks:
        start = time.perf_counter()
        n_events += len(sensor.run(rate, t))
        elapsed += time.perf_counter() - start
    return elapsed, n_events


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--duration", type=float, default=10.0, help="sensor time for the C++ engine [s]")
    ap.add_argument("--numpy-duration", type=float, default=0.5, help="sensor time for NumPy [s]")
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--chunk", type=int, default=250, help="samples per run() call")
    ap.add_argument("--noise-model", choices=["continuous", "sampled"], default="continuous",
                    help="the engine's shot-noise model (the NumPy reference implements 'sampled')")
    args = ap.parse_args()
    params = PixelParams(threshold_sigma=0.03, noise_model=args.noise_model)

    n = int(round(args.duration * RATE_HZ))
    t_all = np.arange(n) / RATE_HZ
    # One period of the motion is 2 s: render it once and replay it (the sensor sees the same
    # scene as rendering all 10 s, and the benchmark does not wait on the renderer).
    period = min(n, int(2 * RATE_HZ))
    frames = np.concatenate([render_chunk(t_all[a : a + args.chunk]) for a in range(0, period, args.chunk)])
    chunks = [(frames[a % period : a % period + min(args.chunk, n - a)], t_all[a : a + args.chunk])
              for a in range(0, n, args.chunk)]
    updates = n * WIDTH * HEIGHT
    print(f"machine: {platform.processor() or platform.machine()}, {len(__import__('os').sched_getaffinity(0))} cores; "
          f"OpenMP: {has_openmp()}")
    print(f"load: DAVIS346 {WIDTH}x{HEIGHT}, {RATE_HZ:.0f} Hz, {args.duration:g} s, 5 sources, all noise on, "
          f"noise_model={args.noise_model}")
    results = {}
    for threads in [int(x) for x in args.threads.split(",")]:
        elapsed, n_ev = bench_engine(params, threads, chunks)
        results[threads] = updates / elapsed
        print(f"C++ engine, {threads} thread(s): {elapsed:7.2f} s  {updates / elapsed / 1e6:8.1f} M pixel-updates/s  "
              f"{n_ev / elapsed / 1e6:6.2f} M events/s  ({n_ev} events)")

    m = int(round(args.numpy_duration * RATE_HZ))
    ref = numpy_reference.NumpySensor(WIDTH, HEIGHT, params.replace(noise_model="sampled"), seed=1)
    start = time.perf_counter()
    n_ev = 0
    for a in range(0, m, args.chunk):
        n_ev += len(ref.run(frames[a : min(a + args.chunk, m)].astype(np.float64), t_all[a : min(a + args.chunk, m)]))
    elapsed = time.perf_counter() - start
    np_rate = m * WIDTH * HEIGHT / elapsed
    print(f"NumPy reference ({args.numpy_duration:g} s):  {elapsed:7.2f} s  {np_rate / 1e6:8.1f} M pixel-updates/s  "
          f"{n_ev / elapsed / 1e6:6.2f} M events/s  ({n_ev} events)")
    for threads, rate in results.items():
        print(f"speed-up over NumPy, {threads} thread(s): {rate / np_rate:6.1f}x")


if __name__ == "__main__":
    main()
