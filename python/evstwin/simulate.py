"""End to end: a scenario -> photon rates per pixel, chunk by chunk -> the sensor -> events.

Sampling never skips a track's pixels. The whole array is sampled at the scenario's
``rate_hz``; in each chunk, if some target moves more than ``max_shift_px`` between those
samples, the sample interval is divided by ``n_sub = ceil(speed * dt / max_shift_px)`` for
the pixels within the PSF window of a moving target (``sparse = true``, the default; they
go through ``Sensor.run_pixels``), or for the whole array (``sparse = false``, the plain
dense way). Pixels outside every moving window see only static light, for which the base
rate is exact, so the sparse way gives the dense way's events when noise is off, and its
statistics when noise is on (each pixel's random numbers follow its own sample counter).

With ``labels=True`` every event also carries why it fired (``EVENT_LABELS``: signal, shot
noise, leak, background, hot pixel), taken from ``Sensor.last_labels()`` after each engine call
and put through the same merge and permutation as the events, so label ``i`` is event ``i``'s.

Memory stays flat: only one chunk of photon rates exists at a time. :func:`simulate` keeps
the events and ground-truth tracks in memory (they grow with the recording, not with pixels
x samples); :func:`simulate_to_file` streams both into the output file as each chunk
finishes, so its memory does not grow with the duration.
"""

from __future__ import annotations

import dataclasses
import math
import os
import sys
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._core import __version__
from ._runner import _Chunk, _is_static, _names, _Runner, _tracked
from .scenario import ScenarioError, Scene, build, load, parse_assignment, set_value
from .sensor import EVENT_DTYPE


@dataclass
class SimulationStats:
    """What a simulation produced and what it cost, without the events themselves (what
    :func:`simulate_to_file` returns: its events went to ``path``)."""

    meta: dict[str, Any]
    n_events: int = 0
    n_on: int = 0
    wall_s: float = 0.0
    engine_s: float = 0.0
    scene_s: float = 0.0
    pixel_updates: int = 0
    samples: int = 0
    sub_sampled_chunks: int = 0
    process_id: int = 0
    """The process that simulated it (run_many spreads seeds over processes)."""
    path: Path | None = None

    def summary(self) -> str:
        on, total = self.n_on, self.n_events
        off = total - on
        dur = float(self.meta["duration_s"])
        ratio = on / off if off else float("inf")
        return (
            f"events: {total}  ON: {on}  OFF: {off}  ON/OFF: {ratio:.3f}  "
            f"rate: {total / dur:.4g} ev/s over {dur:g} s of sensor time\n"
            f"{readout_summary(self.meta)}\n"
            f"wall time: {self.wall_s:.2f} s (engine {self.engine_s:.2f} s, scene {self.scene_s:.2f} s), "
            f"{self.pixel_updates / max(self.engine_s, 1e-9) / 1e6:.1f} M pixel-updates/s"
        )


def readout_summary(meta: dict[str, Any]) -> str:
    """One line on what the readout did, from a simulation's meta (``readout_*`` keys)."""
    if not meta.get("readout_enabled"):
        return "readout: off (the engine's timestamps, no rate limit)"
    n_in, dropped = int(meta["readout_n_in"]), int(meta["readout_n_dropped"])
    share = 100.0 * dropped / n_in if n_in else 0.0
    return (
        f"readout: {meta['readout_max_rate_hz'] / 1e6:.4g} Mev/s, FIFO {meta['readout_fifo_depth']}, "
        f"tick {meta['readout_tick_s'] * 1e6:g} us: {dropped} of {n_in} events dropped ({share:.3g} %), "
        f"{meta['readout_n_delayed']} delayed, worst delay {meta['readout_max_delay_s'] * 1e6:.4g} us"
    )


@dataclass
class SimulationResult(SimulationStats):
    """A simulated recording in memory: its events (``EVENT_DTYPE``, sorted by t) and meta
    (size, duration, seed, the resolved scenario, ground truth)."""

    events: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0, EVENT_DTYPE))
    labels: np.ndarray | None = None
    """Why each event fired (uint8 codes of ``EVENT_LABELS``, one per event, in the order of
    ``events``), or None when the simulation was not asked for them (``labels=False``)."""


def resolve_scenario(scenario: str | Path | dict, sets: Sequence[str] = ()) -> dict[str, Any]:
    """The scenario with ``--set key=value`` assignments applied (ScenarioError if bad)."""
    s = load(scenario)
    for text in sets:
        key, value = parse_assignment(text)
        s = set_value(s, key, value)
    return s


def default_num_threads() -> int:
    """Engine threads when the caller gives none: the cores this process may use, less those
    other processes keep busy right now.

    On a 2-core machine with one core busy elsewhere, two engine threads ran 1.1-2.5x slower
    than one (each of the many short parallel regions waits at its join for the thread that
    shares a core with the other process). Linux reports the tasks runnable at this instant in
    /proc/loadavg's fourth field; the least of five readings 2 ms apart, less this process's
    own thread, is the busy cores. Elsewhere, every core. Results never depend on it (same
    events for any thread count); only speed does.
    """
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1
    try:
        runnable = []
        for i in range(5):
            if i:
                time.sleep(0.002)
            with open("/proc/loadavg", encoding="ascii") as fh:
                runnable.append(int(fh.read().split()[3].split("/")[0]))
    except (OSError, ValueError, IndexError):
        return cores
    busy_elsewhere = max(0, min(runnable) - 1)
    return max(1, cores - busy_elsewhere)


def simulate(
    scenario: str | Path | dict,
    duration_s: float | None = None,
    seed: int | None = None,
    num_threads: int | None = None,
    sets: Sequence[str] = (),
    progress: bool = False,
    labels: bool = False,
) -> SimulationResult:
    """Simulate a scenario (built-in name, TOML path or dict) and return its events.

    duration_s, seed: override the scenario's; sets: ``key=value`` overrides as on the CLI;
    num_threads: engine threads (default: :func:`default_num_threads`, the cores not busy
    elsewhere); progress: a tqdm bar on stderr over sensor time; labels: also return why each
    event fired as ``result.labels`` (uint8 codes of ``EVENT_LABELS``; default False: None).
    """
    wall0 = time.perf_counter()
    scene = build(resolve_scenario(scenario, sets), duration_s=duration_s, seed=seed)
    tracks: dict[str, list[dict[str, np.ndarray]]] = {}
    threads = default_num_threads() if num_threads is None else num_threads
    runner = _Runner(scene, threads, truth_sink=lambda name, rows: tracks.setdefault(name, []).append(rows),
                     labels=labels)
    parts = list(_with_bar(runner, scene, progress))
    events = np.concatenate([e for e, _ in parts]) if parts else np.zeros(0, EVENT_DTYPE)
    codes = None
    if labels:
        codes = np.concatenate([c for _, c in parts if c is not None]) if parts else np.zeros(0, np.uint8)
    truth = {name: {k: np.concatenate([r[k] for r in rows]) for k in rows[0]} for name, rows in tracks.items()}
    return SimulationResult(events=events, labels=codes,
                            **_stats(runner, dict(_meta(runner, scene), truth=truth), wall0,
                                     len(events), int(np.count_nonzero(events["p"] == 1))))


def simulate_to_file(
    scenario: str | Path | dict,
    out_path: str | Path,
    duration_s: float | None = None,
    seed: int | None = None,
    num_threads: int | None = None,
    sets: Sequence[str] = (),
    progress: bool = False,
    labels: bool = False,
) -> SimulationStats:
    """simulate() streamed into ``out_path`` (format from the extension): the events and the
    ground truth go to the file as each chunk finishes, so memory does not grow with the
    duration; the file appears under its name only when complete (an error or Ctrl-C leaves
    nothing). The result carries the counts, not the events.

    labels: also write why each event fired as the file's label column (``.h5``/``.hdf5``,
    ``.npz``, ``.txt``, ``.csv``; any other format is refused with ValueError before the
    simulation starts). Default False: the file is as without labels."""
    from .io import open_event_writer

    wall0 = time.perf_counter()
    scene = build(resolve_scenario(scenario, sets), duration_s=duration_s, seed=seed)
    size = {"width": scene.width, "height": scene.height}
    with open_event_writer(out_path, size, labels=labels) as writer:
        threads = default_num_threads() if num_threads is None else num_threads
        runner = _Runner(scene, threads, truth_sink=writer.append_truth, labels=labels)
        n_on = 0
        for part, codes in _with_bar(runner, scene, progress):
            writer.write(part, labels=codes)
            n_on += int(np.count_nonzero(part["p"] == 1))
        meta = _meta(runner, scene)
        writer.update_meta(meta)
        n_events = writer.count
    return SimulationStats(path=writer.path, **_stats(runner, meta, wall0, n_events, n_on))


def _with_bar(runner: _Runner, scene: Scene, progress: bool) -> Iterator[_Chunk]:
    """The runner's (events, labels) chunks, with a tqdm bar over sensor time on stderr if asked."""
    if not progress:
        yield from runner.chunks()
        return
    from tqdm import tqdm

    bar = tqdm(total=round(scene.duration_s, 6), unit="s", desc=f"simulating {scene.scenario['name']}",
               file=sys.stderr, bar_format="{l_bar}{bar}| {n:.2f}/{total:.2f} s sensor time [{elapsed}<{remaining}{postfix}]")
    try:
        yield from runner.chunks(bar)
    finally:
        bar.close()


def _meta(runner: _Runner, scene: Scene) -> dict[str, Any]:
    meta: dict[str, Any] = {
        "width": scene.width,
        "height": scene.height,
        "duration_s": runner.t_end,
        "seed": scene.seed,
        "scenario": scene.scenario,
        "evstwin_version": __version__,
        "readout_enabled": runner.readout is not None,
    }
    if runner.n_pre:
        meta["pre_roll_s"] = runner.n_pre * runner.dt_pre
        meta["pre_roll_rate_hz"] = 1.0 / runner.dt_pre
    if scene.roi is not None:  # sensor.roi: where this width x height recording lies on the sensor
        meta["roi_x0_px"], meta["roi_y0_px"] = scene.roi[0], scene.roi[1]
    # Flat scalars: every event-file format stores scalar meta (io.writer), none a nested table.
    if runner.readout is not None:
        meta.update({f"readout_{k}": v for k, v in runner.readout.stats().items()})
    return meta


def _stats(runner: _Runner, meta: dict[str, Any], wall0: float, n_events: int, n_on: int) -> dict[str, Any]:
    return {
        "meta": meta, "n_events": n_events, "n_on": n_on, "wall_s": time.perf_counter() - wall0,
        "engine_s": runner.engine_s, "scene_s": runner.scene_s, "pixel_updates": runner.pixel_updates,
        "samples": runner.n_base, "sub_sampled_chunks": runner.sub_sampled_chunks, "process_id": os.getpid(),
    }


def track_names(scene: Scene) -> list[str]:
    """The names under which a scene's moving targets' ground truth is written (their labels,
    ``target<j>`` for unlabelled ones, ``#<j>`` appended to a repeated label). The stars of a
    drifting star field have none (``Scene.field_stars``)."""
    t_end = max(1, math.ceil(scene.duration_s * scene.rate_hz - 1e-9)) / scene.rate_hz
    return _names([t for t in _tracked(scene) if not _is_static(t, t_end)])



def run_many(
    scenario: str | Path | dict,
    seeds: Iterable[int],
    duration_s: float | None = None,
    sets: Sequence[str] = (),
    processes: int | None = None,
    progress: bool = False,
    labels: bool = False,
) -> list[SimulationResult]:
    """The same scenario with several seeds, in parallel processes (one thread each), in the
    order of ``seeds``; ``progress``: a tqdm bar on stderr counting finished runs; ``labels``:
    as for :func:`simulate`."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    from ._signals import children_without_sigint, ignore_sigint

    resolved = resolve_scenario(scenario, sets)
    seeds = list(seeds)
    # forkserver: never fork a process that has run OpenMP or BLAS threads.
    context = multiprocessing.get_context("forkserver")
    before = set(multiprocessing.active_children())
    with children_without_sigint():
        pool = ProcessPoolExecutor(max_workers=processes, mp_context=context, initializer=ignore_sigint)
    done = False
    try:
        with children_without_sigint():
            futures = [pool.submit(simulate, resolved, duration_s, seed, 1, labels=labels) for seed in seeds]
        if progress:
            from tqdm import tqdm

            with tqdm(total=len(futures), unit="run", desc=f"simulating {resolved['name']}",
                      file=sys.stderr) as bar:
                for _ in as_completed(futures):
                    bar.update(1)
        results = [f.result() for f in futures]
        done = True
        return results
    finally:
        if done:
            pool.shutdown(wait=True)
        else:  # Ctrl-C or a failed run: stop the other runs now rather than wait for them
            stop_workers(pool, before)


def stop_workers(pool: Any, children_before: set[Any]) -> None:
    """Terminate a ``ProcessPoolExecutor``'s workers now (their jobs are lost) and drop the
    pool: any child process started since ``children_before`` was taken, as a worker still
    being spawned is not in the pool's table yet, and the interpreter joins every child at exit."""
    import multiprocessing

    processes = list((getattr(pool, "_processes", None) or {}).values())
    processes += [p for p in multiprocessing.active_children() if p not in processes and p not in children_before]
    for proc in processes:
        if proc.is_alive():
            proc.terminate()
    for proc in processes:
        proc.join(timeout=5)
        if proc.is_alive():
            proc.kill()
    pool.shutdown(wait=False, cancel_futures=False)


__all__ = ["SimulationResult", "SimulationStats", "default_num_threads", "ScenarioError", "resolve_scenario", "run_many", "simulate", "simulate_to_file"]
