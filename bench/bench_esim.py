"""evstwin against ESIM's C++ core, side by side on the same input (issue 33, "against the
reference peer").

The input: 346 x 260 frames, 500 of them at 250 fps (2 s, one turn), five Gaussian spots
circling on a static dim background (bench_engine.render_chunk, the engine benchmark's scene),
as photon rates [photons/s].

- ESIM (uzh-rpg/rpg_vid2e, esim_py): ``EventSimulator::imageCallback`` fed the natural log of
  those frames (relative to the background, float32), frame by frame from memory (no disk
  I/O), 1 thread, refractory period 0: ESIM's ideal pixel (it has no noise model). Its
  Python binding only reads images or videos from disk, so this script compiles bench/esim_harness.cpp together with ESIM's own
  esim_py/src/esim.cpp (-O3 -DNDEBUG, as ESIM's setup.py builds it) and pipes the log frames
  into it; no ESIM code is in this repository.
- evstwin, on the photon-rate frames through ``Sensor.run`` (one call of 500 samples), 1 and 2
  threads: its ideal pixel (the DAVIS346 preset's thresholds, every noise source, the filter,
  the refractory period and the mismatch off: bench_engine.ideal_pixel_params' "no filter",
  ESIM's model) and its full physics (the DAVIS346 preset's pixel as it is: photon and dark
  current shot noise through the continuous noise model, the leak with its spread across
  pixels, the 10 Hz source follower, 1 ms refractory period; the preset has no threshold
  mismatch and no hot pixels).
- The thresholds are the same: ESIM's Cp / Cn = the preset's theta_on / theta_off
  (0.2060 / 0.0930 ln units).

Each is timed over its simulator calls only (frames are rendered, and for ESIM piped, before
the clock starts), best of --repeats runs, each run from a fresh simulator. evstwin's time
includes taking the log of the photon rates; ESIM is given the logs. Prints seconds per run,
the events (ON / OFF), each one's speed against ESIM's (ESIM's best wall time / its best),
its CPU time (the process's, all threads: steadier than wall time on a shared machine) against
ESIM's, and whether the issue's goal (full physics on 2 threads at least 2x ESIM's ideal
core) is met.

Getting and building ESIM (Debian/Ubuntu; the figures in docs/explanation/performance.md are
from commit ecbb11a):

    git clone https://github.com/uzh-rpg/rpg_vid2e /tmp/rpg_vid2e
    sudo apt-get install -y g++ libopencv-dev libeigen3-dev libboost-filesystem-dev
    python bench/bench_esim.py --esim /tmp/rpg_vid2e/esim_py

--esim (or the ESIM environment variable) is the esim_py directory of that checkout (or the
checkout itself): the harness is compiled into build/bench-esim/ (about a minute; again only
when a source is newer), with $CXX (default g++), OpenCV's and Eigen's include paths from
pkg-config (else /usr/include/opencv4 and /usr/include/eigen3). --esim may also name an
esim_harness binary built by hand (the command is in bench/esim_harness.cpp). Without ESIM
the script says so in one line and exits with status 2; it never prints a figure it did not
measure.

    python bench/bench_esim.py --esim PATH [--repeats 5] [--threads 1,2]
"""

from __future__ import annotations

import argparse
import os
import platform
import shlex
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_engine import ideal_pixel_params, render_chunk  # noqa: E402

from evstwin import PixelParams, Sensor  # noqa: E402
from evstwin.presets import DAVIS346  # noqa: E402
from evstwin.sensor import EVENT_DTYPE, simd_level  # noqa: E402

WIDTH, HEIGHT = 346, 260
N_FRAMES = 500
FRAME_RATE_HZ = 250.0
GOAL_SPEEDUP = 2.0
"""Issue 33: evstwin's full physics on 2 threads at least this many times ESIM's speed."""

BENCH_DIR = Path(__file__).resolve().parent
HARNESS_SOURCE = BENCH_DIR / "esim_harness.cpp"
DEFAULT_BUILD_DIR = BENCH_DIR.parent / "build" / "bench-esim"


class EsimUnavailable(Exception):
    """ESIM could not be found or built: the one line to print."""


@dataclass(frozen=True)
class Timing:
    """Wall times of the simulator calls in each run [s], their process CPU times (all
    threads) [s], and the last run's events."""

    times_s: tuple[float, ...]
    cpu_s: tuple[float, ...]
    events: int
    on: int

    @property
    def best_s(self) -> float:
        return min(self.times_s)

    @property
    def best_cpu_s(self) -> float:
        return min(self.cpu_s)

    @property
    def off(self) -> int:
        return self.events - self.on


def esim_source(path: Path) -> Path | None:
    """The esim_py directory (include/esim.h, src/esim.cpp) at or inside ``path``, or None."""
    for root in (path, path / "esim_py"):
        if (root / "include" / "esim.h").is_file() and (root / "src" / "esim.cpp").is_file():
            return root
    return None


def _pkg_config_cflags(package: str, fallback: str) -> list[str]:
    """pkg-config's compile flags for a package, or -I<fallback> without pkg-config or the .pc."""
    if shutil.which("pkg-config"):
        done = subprocess.run(["pkg-config", "--cflags", package], capture_output=True, text=True)
        if done.returncode == 0 and done.stdout.strip():
            return shlex.split(done.stdout)
    return [f"-I{fallback}"]


def build_harness(source: Path, build_dir: Path) -> Path:
    """Compile bench/esim_harness.cpp with ESIM's esim.cpp into build_dir (unless the binary is
    newer than both sources); written under a temporary name and renamed when complete."""
    out = build_dir / "esim_harness"
    inputs = [HARNESS_SOURCE, source / "src" / "esim.cpp", source / "include" / "esim.h"]
    if out.is_file() and all(out.stat().st_mtime >= p.stat().st_mtime for p in inputs):
        return out
    cxx = os.environ.get("CXX", "g++")
    if shutil.which(cxx) is None:
        raise EsimUnavailable(f"no C++ compiler to build the ESIM harness: CXX={cxx} not found")
    build_dir.mkdir(parents=True, exist_ok=True)
    tmp = build_dir / f"esim_harness.tmp{os.getpid()}"
    cmd = [cxx, "-std=c++17", "-O3", "-DNDEBUG", f"-I{source / 'include'}",
           *_pkg_config_cflags("eigen3", "/usr/include/eigen3"),
           *_pkg_config_cflags("opencv4", "/usr/include/opencv4"),
           str(HARNESS_SOURCE), str(source / "src" / "esim.cpp"),
           "-lopencv_videoio", "-lopencv_imgcodecs", "-lopencv_imgproc", "-lopencv_core", "-lboost_filesystem",
           "-o", str(tmp)]
    print(f"building the ESIM harness: {shlex.join(cmd)}", flush=True)
    done = subprocess.run(cmd, capture_output=True, text=True)
    if done.returncode != 0:
        tmp.unlink(missing_ok=True)
        errors = [line for line in done.stderr.splitlines() if "error" in line] or done.stderr.splitlines()[-1:]
        raise EsimUnavailable(f"could not build the ESIM harness ({cxx} exit {done.returncode}): "
                              f"{errors[0] if errors else 'no message'}")
    tmp.replace(out)
    return out


def find_harness(esim: str | None, build_dir: Path) -> Path:
    """The ESIM harness binary from --esim / $ESIM: a binary as given, or built from a source."""
    if not esim:
        raise EsimUnavailable("ESIM not found: give --esim PATH or set ESIM to the esim_py directory of a "
                              "uzh-rpg/rpg_vid2e checkout (or a built esim_harness); see this script's docstring")
    path = Path(esim).expanduser()
    if path.is_file():
        if not os.access(path, os.X_OK):
            raise EsimUnavailable(f"ESIM not found: --esim={esim} is a file but not an executable esim_harness")
        return path
    source = esim_source(path) if path.is_dir() else None
    if source is None:
        raise EsimUnavailable(f"ESIM not found: --esim={esim} holds neither include/esim.h and src/esim.cpp "
                              "nor esim_py/ with them, and is not an esim_harness binary")
    return build_harness(source, build_dir)


def time_esim(harness: Path, log_frames: np.ndarray, t_s: np.ndarray, c_pos: float, c_neg: float,
              repeats: int) -> Timing:
    """ESIM's imageCallback over the log frames, in the harness (it times itself)."""
    n, height, width = log_frames.shape
    args = [str(harness), str(width), str(height), str(n), repr(c_pos), repr(c_neg), str(repeats)]
    payload = np.ascontiguousarray(t_s, dtype=np.float64).tobytes() + \
        np.ascontiguousarray(log_frames, dtype=np.float32).tobytes()
    done = subprocess.run(args, input=payload, capture_output=True)
    if done.returncode != 0:
        message = done.stderr.decode(errors="replace").strip().splitlines()
        raise EsimUnavailable(f"the ESIM harness {harness} failed (exit {done.returncode}): "
                              f"{message[-1] if message else 'no message'}")
    words = done.stdout.decode().split()
    try:
        fields = {name: words.index(name) for name in ("times_s", "cpu_s", "events", "on", "off")}
        times = tuple(float(w) for w in words[fields["times_s"] + 1 : fields["cpu_s"]])
        cpu = tuple(float(w) for w in words[fields["cpu_s"] + 1 : fields["events"]])
        events, on = int(words[fields["events"] + 1]), int(words[fields["on"] + 1])
    except (ValueError, IndexError):
        raise EsimUnavailable(f"the ESIM harness {harness} printed {done.stdout[:200]!r}, not its timings") from None
    if len(times) != repeats or len(cpu) != repeats:
        raise EsimUnavailable(f"the ESIM harness {harness} timed {len(times)} runs, not {repeats}")
    return Timing(times, cpu, events, on)


def time_evstwin(params: PixelParams, threads: int, frames: np.ndarray, t_s: np.ndarray, repeats: int) -> Timing:
    """evstwin's Sensor.run over the photon-rate frames, one call, from a fresh sensor each run."""
    times: list[float] = []
    cpu: list[float] = []
    events = np.empty(0, dtype=EVENT_DTYPE)
    for _ in range(repeats):
        sensor = Sensor(frames.shape[2], frames.shape[1], params, seed=1, num_threads=threads)
        start, start_cpu = time.perf_counter(), time.process_time()
        events = sensor.run(frames, t_s)
        times.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return Timing(tuple(times), tuple(cpu), len(events), int(np.count_nonzero(events["p"] == 1)))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--esim", default=os.environ.get("ESIM"),
                    help="ESIM's esim_py directory (or the rpg_vid2e checkout), or a built esim_harness "
                         "(default: $ESIM)")
    ap.add_argument("--repeats", type=int, default=5, help="runs of each simulator; the best is reported")
    ap.add_argument("--threads", default="1,2", help="evstwin thread counts, comma-separated")
    ap.add_argument("--build-dir", type=Path, default=DEFAULT_BUILD_DIR, help="where the harness is built")
    args = ap.parse_args()
    if args.repeats < 1:
        ap.error(f"--repeats must be at least 1; got --repeats={args.repeats}")
    try:
        threads = [int(x) for x in args.threads.split(",")]
    except ValueError:
        ap.error(f"--threads must be comma-separated integers; got --threads={args.threads}")
    if any(n < 1 for n in threads):
        ap.error(f"--threads must be at least 1 each; got --threads={args.threads}")

    try:
        harness = find_harness(args.esim, args.build_dir)
    except EsimUnavailable as exc:
        print(f"bench_esim: {exc}", file=sys.stderr)
        return 2

    t_s = np.arange(N_FRAMES) / FRAME_RATE_HZ
    frames = render_chunk(t_s, WIDTH, HEIGHT)  # (500, 260, 346) float32 photons/s
    # ESIM's levels are single precision: the log relative to the background (0 to 6.2, as
    # small as ESIM's own log(image / 255 + eps)) keeps them finer than ln(photons/s) ~ 14.5.
    log_frames = np.log(frames / frames.min())
    full = DAVIS346.pixel
    ideal = ideal_pixel_params(full)["no filter"]

    print(f"machine: {platform.processor() or platform.machine()}, {len(os.sched_getaffinity(0))} cores, "
          f"load average {os.getloadavg()[0]:.1f}; evstwin SIMD: {simd_level()}")
    print(f"input: {WIDTH}x{HEIGHT}, {N_FRAMES} frames at {FRAME_RATE_HZ:g} fps, 5 spots circling; "
          f"Cp = theta_on = {full.theta_on:.4f}, Cn = theta_off = {full.theta_off:.4f}; best of {args.repeats}")
    try:
        esim = time_esim(harness, log_frames, t_s, full.theta_on, full.theta_off, args.repeats)
    except EsimUnavailable as exc:
        print(f"bench_esim: {exc}", file=sys.stderr)
        return 2
    rows: list[tuple[str, int, Timing]] = [("ESIM ideal (imageCallback)", 1, esim)]
    for name, params in (("evstwin ideal pixel", ideal), ("evstwin full physics (DAVIS346)", full)):
        for n in threads:
            rows.append((name, n, time_evstwin(params, n, frames, t_s, args.repeats)))

    print(f"{'simulator':32s} {'threads':>7s} {'wall s':>7s} {'CPU s':>7s} {'events':>8s} {'ON':>7s} "
          f"{'OFF':>7s} {'speed / ESIM':>12s} {'CPU / ESIM':>10s}  all runs, wall [s]")
    for name, n, timing in rows:
        runs = " ".join(f"{t:.3f}" for t in timing.times_s)
        print(f"{name:32s} {n:7d} {timing.best_s:7.3f} {timing.best_cpu_s:7.3f} {timing.events:8d} {timing.on:7d} "
              f"{timing.off:7d} {esim.best_s / timing.best_s:11.2f}x {timing.best_cpu_s / esim.best_cpu_s:9.2f}x  "
              f"{runs}")
    goal = [t for name, n, t in rows if name.startswith("evstwin full") and n == 2]
    if goal:
        ratio = esim.best_s / goal[0].best_s
        print(f"issue 33's goal, full physics on 2 threads >= {GOAL_SPEEDUP:g}x ESIM's ideal core: {ratio:.2f}x, "
              f"{'met' if ratio >= GOAL_SPEEDUP else 'not met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
