"""Engine throughput (issues 2 and 15) on three loads.

reference (default): DAVIS346, 346 x 260 pixels, 1 kHz samples, 10 s, five point sources on
circles, every noise source on (photon shot noise, Poisson dark current, leak, statistical
shot noise, threshold mismatch, the 10 Hz low-pass, 1 ms refractory).
event-heavy: the same scene with a 200 Hz source follower, so the 18,000 e-/s dark current's
shot noise crosses the thresholds hundreds of times a pixel a second (as bright star fields,
fast slews, flicker and hot-pixel-rich sensors do); the cost of each event.
imx636: the IMX636 preset's pixel (1280 x 720) at 1 kHz, the sources spread over the frame;
pixel-updates/s and seconds of wall time per second of sensor time. Its scene is rendered
for --period seconds and replayed (the full frame's 2 s would need 7 GB of rates).

Prints pixel-updates/s, events/s, events per pixel per second and CPU time per event
(process CPU time, all threads) of the C++ engine for each thread count, and, for the
reference load, of the vectorised NumPy implementation of the same model
(bench/numpy_reference.py) run in the same process on a shorter stretch, and the ratio; and of
a vectorised NumPy ideal log-difference pixel (no noise, no filter: numpy_ideal) on the same
frames, the comparison the issue asks for, and of the engine set up as that same ideal pixel
(ideal_pixel_params) on those frames: the like-for-like ratio.
Only the engine's run() calls are timed; the input is rendered beforehand per chunk.

    python bench/bench_engine.py [--load reference|event-heavy|imx636] [--duration 10]
                                 [--numpy-duration 0.5] [--threads 1,2]
    python bench/bench_engine.py --call-overhead 20000   # Python's cost per run() call
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
from evstwin.presets import IMX636  # noqa: E402

try:
    from evstwin.sensor import simd_level
except ImportError:  # an engine from before issue 15 (for before/after figures): scalar only

    def simd_level() -> str:
        return "none (before issue 15)"

RATE_HZ = 1000.0
SIZES = {"reference": (346, 260), "event-heavy": (346, 260), "imx636": (1280, 720)}
WIDTH, HEIGHT = SIZES["reference"]


def render_chunk(t: np.ndarray, width: int = WIDTH, height: int = HEIGHT) -> np.ndarray:
    """Five Gaussian spots (sigma 1.2 px) turning on circles over a dim uniform background."""
    out = np.full((len(t), height, width), 2e6, dtype=np.float32)
    cx, cy = width / 2, height / 2
    scale = min(width, height) / HEIGHT
    for j, radius in enumerate(np.array([20, 45, 70, 95, 120]) * scale):
        phase = 2 * math.pi * t / 2.0 + j  # one turn in 2 s
        xs, ys = cx + radius * np.cos(phase), cy + radius * np.sin(phase)
        for k in range(len(t)):
            x0, y0 = int(xs[k]) - 5, int(ys[k]) - 5
            yy, xx = np.mgrid[y0 : y0 + 11, x0 : x0 + 11]
            out[k, y0 : y0 + 11, x0 : x0 + 11] += 1e9 * np.exp(-((xx - xs[k]) ** 2 + (yy - ys[k]) ** 2) / (2 * 1.2**2))
    return out


def bench_engine(params: PixelParams, threads: int, chunks: list[tuple[np.ndarray, np.ndarray]],
                 width: int = WIDTH, height: int = HEIGHT) -> tuple[float, float, int]:
    """Wall seconds, CPU seconds (the process's, all threads) and events of the run() calls."""
    sensor = Sensor(width, height, params, seed=1, num_threads=threads)
    elapsed, cpu, n_events = 0.0, 0.0, 0
    for rate, t in chunks:
        start, start_cpu = time.perf_counter(), time.process_time()
        n_events += len(sensor.run(rate, t))
        elapsed += time.perf_counter() - start
        cpu += time.process_time() - start_cpu
    return elapsed, cpu, n_events


def numpy_ideal(frames: np.ndarray, theta_on: float, theta_off: float) -> tuple[float, int]:
    """Wall seconds and event count of the ideal pixel as simulators such as ESIM model it,
    vectorised with NumPy over the (n, H, W) float32 frames: the log of each frame against a
    per-pixel reference, as many ON (OFF) events as whole theta_on (theta_off) steps the log
    has risen (fallen) past it, the reference moved by those steps. No noise, no filter, no
    timestamps: the floor under any physical model, which the issue compares the engine with."""
    inv_on, inv_off = np.float32(1.0 / theta_on), np.float32(1.0 / theta_off)
    on_step, off_step = np.float32(theta_on), np.float32(theta_off)
    start = time.perf_counter()
    ref = np.log(frames[0])
    n_ev = 0
    for frame in frames[1:]:
        d = np.log(frame) - ref
        n_on = np.floor(np.maximum(d, 0) * inv_on)
        n_off = np.floor(np.maximum(-d, 0) * inv_off)
        ref += n_on * on_step - n_off * off_step
        n_ev += int(n_on.sum()) + int(n_off.sum())
    return time.perf_counter() - start, n_ev


def ideal_pixel_params(params: PixelParams) -> dict[str, PixelParams]:
    """The engine set up as numpy_ideal's pixel, to compare like with like: no photon or dark
    shot noise, no leak, no background, no refractory period, no mismatch; "no filter" is
    that model exactly (it gives numpy_ideal's events but for timestamps, which NumPy does not
    compute), "10 Hz filter" keeps the reference load's source follower."""
    ideal = params.replace(photon_shot_noise=False, dark_model="none", shot_noise_rate_hz=0.0,
                           leak_rate_hz=0.0, refractory_s=0.0, threshold_sigma=0.0)
    return {"no filter": ideal.replace(cutoff_hz=None), "10 Hz filter": ideal}


def call_overhead(n_calls: int) -> None:
    """Microseconds per run() call through Sensor.run and through the binding alone (_core),
    on one pixel and one sample a call: what a call costs besides its pixels and events."""
    rate = np.full((1, 1, 1), 2e6, dtype=np.float32)
    for name in ("Sensor.run", "_core.run"):
        sensor = Sensor(1, 1, PixelParams(), seed=1, num_threads=1)
        run = sensor.run if name == "Sensor.run" else sensor._core.run
        times = [np.array([k * 1e-3]) for k in range(n_calls)]
        start = time.perf_counter()
        for t in times:
            run(rate, t)
        print(f"{name}: {(time.perf_counter() - start) / n_calls * 1e6:.1f} us per call (1 pixel, 1 sample)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--load", choices=sorted(SIZES), default="reference")
    ap.add_argument("--duration", type=float, default=None,
                    help="sensor time for the C++ engine [s] (default 10; imx636: 1)")
    ap.add_argument("--numpy-duration", type=float, default=0.5, help="sensor time for NumPy [s] (reference load)")
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--chunk", type=int, default=250, help="samples per run() call (imx636: 50)")
    ap.add_argument("--period", type=float, default=None,
                    help="seconds of scene rendered and replayed (default 2: one turn; imx636: 0.1)")
    ap.add_argument("--noise-model", choices=["continuous", "sampled"], default="continuous",
                    help="the engine's shot-noise model (the NumPy reference implements 'sampled')")
    ap.add_argument("--call-overhead", type=int, default=0, metavar="N",
                    help="only time N one-pixel, one-sample run() calls (Python's cost per call)")
    args = ap.parse_args()
    if args.call_overhead > 0:
        call_overhead(args.call_overhead)
        return
    imx = args.load == "imx636"
    duration = args.duration if args.duration is not None else (1.0 if imx else 10.0)
    chunk = 50 if imx and args.chunk == 250 else args.chunk
    width, height = SIZES[args.load]
    if imx:
        params = IMX636.pixel_params().replace(noise_model=args.noise_model)
    else:
        params = PixelParams(threshold_sigma=0.03, noise_model=args.noise_model,
                             cutoff_hz=200.0 if args.load == "event-heavy" else 10.0)

    n = int(round(duration * RATE_HZ))
    t_all = np.arange(n) / RATE_HZ
    # One period of the motion is 2 s: render it once and replay it (the sensor sees the same
    # scene as rendering all 10 s, and the benchmark does not wait on the renderer).
    period_s = args.period if args.period is not None else (0.1 if imx else 2.0)
    period = min(n, int(round(period_s * RATE_HZ)))
    frames = np.concatenate([render_chunk(t_all[a : min(a + chunk, period)], width, height)
                             for a in range(0, period, chunk)])
    chunks = [(frames[a % period : a % period + min(chunk, n - a)], t_all[a : a + chunk])
              for a in range(0, n, chunk)]
    updates = n * width * height
    print(f"machine: {platform.processor() or platform.machine()}, {len(__import__('os').sched_getaffinity(0))} cores; "
          f"OpenMP: {has_openmp()}; SIMD: {simd_level()}; load average {__import__('os').getloadavg()[0]:.1f}")
    print(f"load: {args.load}, {width}x{height}, {RATE_HZ:.0f} Hz, {duration:g} s, 5 sources, all noise on, "
          f"cutoff {params.cutoff_hz:g} Hz, noise_model={args.noise_model}")
    results = {}
    for threads in [int(x) for x in args.threads.split(",")]:
        elapsed, cpu, n_ev = bench_engine(params, threads, chunks, width, height)
        results[threads] = updates / elapsed
        print(f"C++ engine, {threads} thread(s): {elapsed:7.2f} s  {updates / elapsed / 1e6:8.1f} M pixel-updates/s  "
              f"{n_ev / elapsed / 1e6:6.2f} M events/s  ({n_ev} events, "
              f"{n_ev / (width * height * duration):.3g} per pixel per s; "
              f"CPU {cpu:.2f} s = {cpu / updates * 1e9:.2f} ns per update, "
              f"{cpu / max(n_ev, 1) * 1e9:.0f} ns per event; "
              f"{elapsed / duration:.3g} s per sensor-second)")
    if args.load != "reference" or args.numpy_duration <= 0:
        return

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
    # The ideal pixel on the engine's own input (the first 2 s, replayed as the engine saw it).
    ideal_frames = frames[: min(period, n)]
    ideal_s, ideal_ev = numpy_ideal(ideal_frames, params.theta_on, params.theta_off)
    ideal_rate = (len(ideal_frames) - 1) * WIDTH * HEIGHT / ideal_s
    print(f"NumPy ideal log-difference model ({(len(ideal_frames) - 1) / RATE_HZ:g} s): {ideal_s:7.2f} s  "
          f"{ideal_rate / 1e6:8.1f} M pixel-updates/s  ({ideal_ev} events)")
    for threads, rate in results.items():
        print(f"engine / NumPy ideal model, {threads} thread(s): {rate / ideal_rate:6.2f}")
    # Like for like: the engine configured as that ideal pixel, on the same frames.
    ideal_chunks = [(ideal_frames[a : a + args.chunk], t_all[a : a + args.chunk])
                    for a in range(0, len(ideal_frames), args.chunk)]
    ideal_updates = len(ideal_frames) * WIDTH * HEIGHT
    for threads in results:
        for name, ideal_params in ideal_pixel_params(params).items():
            elapsed, cpu, n_ev = bench_engine(ideal_params, threads, ideal_chunks)
            print(f"C++ engine as the ideal pixel ({name}), {threads} thread(s): {elapsed:7.2f} s  "
                  f"{ideal_updates / elapsed / 1e6:8.1f} M pixel-updates/s, {ideal_updates / elapsed / ideal_rate:5.2f}x "
                  f"the NumPy ideal model ({n_ev} events; CPU {cpu / ideal_updates * 1e9:.2f} ns per update)")


if __name__ == "__main__":
    main()
