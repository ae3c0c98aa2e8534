"""Where `evstwin simulate` spends its CPU: the engine calls by kind and the scene layer's steps.

    python bench/profile_simulate.py [--scenario imx636-pointsource] [--duration 0.3] [--threads 1]

Wraps ``Sensor.run`` (split into the pre-roll's calls and the run's own), ``Sensor.run_pixels``
and the sub-sampled path's steps of ``simulate``'s runner, and prints for each the process CPU
time (all threads), the pixel-updates and CPU per update of the engine calls, and the minor
page faults and system time (fresh memory the kernel zeroes) of each step, its wall time, and
with --threads > 1 the engine calls' CPU on the calling thread against the others' (their
difference: the calls' serial work and imbalance between the threads). Steps nest:
``_sparse`` holds ``_with_halos``, ``Sensor.run_pixels`` and a ``Sensor.run``. CPU time, not
wall time: on a shared machine it is the steadier figure.
"""

from __future__ import annotations

import argparse
import collections
import importlib
import resource
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from evstwin.sensor import Sensor

simulate_module = importlib.import_module("evstwin.simulate")  # the package exports simulate() under that name

cpu_s: dict[str, float] = collections.defaultdict(float)
calls: collections.Counter[str] = collections.Counter()
updates: collections.Counter[str] = collections.Counter()
faults: collections.Counter[str] = collections.Counter()
sys_s: dict[str, float] = collections.defaultdict(float)
wall_s: dict[str, float] = collections.defaultdict(float)
main_s: dict[str, float] = collections.defaultdict(float)


def timed(owner: Any, name: str, kind: Callable[..., tuple[str, int]] | None = None) -> None:
    """Replace owner.name by a wrapper that books its CPU, faults and system time under a key
    (``kind(*args)`` gives the key and the call's pixel-updates; else the name, 0)."""
    original = getattr(owner, name)

    def wrapper(*args: Any, **kwargs: Any) -> Any:
        key, n = kind(*args) if kind else (name, 0)
        w0, m0, c0 = time.perf_counter(), time.thread_time(), time.process_time()
        r0 = resource.getrusage(resource.RUSAGE_SELF)
        out = original(*args, **kwargs)
        r1 = resource.getrusage(resource.RUSAGE_SELF)
        cpu_s[key] += time.process_time() - c0
        main_s[key] += time.thread_time() - m0
        wall_s[key] += time.perf_counter() - w0
        sys_s[key] += r1.ru_stime - r0.ru_stime
        faults[key] += r1.ru_minflt - r0.ru_minflt
        calls[key] += 1
        updates[key] += n
        return out

    setattr(owner, name, wrapper)


def run_kind(_sensor: Sensor, photon_rate: Any, t_s: Any, **_: Any) -> tuple[str, int]:
    t = np.asarray(t_s)
    pre_roll = t.size > 0 and t[0] < 0.0
    return ("Sensor.run (pre-roll)" if pre_roll else "Sensor.run"), int(np.asarray(photon_rate).size)


def run_pixels_kind(_sensor: Sensor, _pixels: Any, photon_rate: Any, _t_s: Any, **_: Any) -> tuple[str, int]:
    return "Sensor.run_pixels", int(np.asarray(photon_rate).size)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default="imx636-pointsource")
    ap.add_argument("--duration", type=float, default=0.3)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    timed(Sensor, "run", run_kind)
    timed(Sensor, "run_pixels", run_pixels_kind)
    runner = simulate_module._Runner
    for step in ("_dense", "_sparse", "frames", "_with_halos", "_contribution_parts"):
        if hasattr(runner, step):
            timed(runner, step)
    c0, w0 = time.process_time(), time.perf_counter()
    result = simulate_module.simulate(args.scenario, duration_s=args.duration, num_threads=args.threads)
    total = time.process_time() - c0
    print(f"{args.scenario}, {args.duration:g} s, {args.threads} thread(s): {total:.2f} s CPU, "
          f"{time.perf_counter() - w0:.2f} s wall, {len(result.events)} events, "
          f"{result.pixel_updates:.3g} pixel-updates")
    engine = sum(v for k, v in cpu_s.items() if k.startswith("Sensor."))
    print(f"  {'all but the engine calls':24s} {total - engine:8.2f} s CPU ({100 * (total - engine) / total:4.1f} %): "
          "the scene layer, the runner's steps, the readout")
    for key in sorted(cpu_s, key=lambda k: -cpu_s[k]):
        per = f", {updates[key]:.3g} updates, {cpu_s[key] / updates[key] * 1e9:.1f} ns CPU an update" if updates[key] else ""
        print(f"  {key:24s} {cpu_s[key]:8.2f} s CPU ({100 * cpu_s[key] / total:4.1f} %), {wall_s[key]:.2f} s wall, "
              f"{calls[key]} calls{per}; {faults[key]} minor faults, {sys_s[key]:.2f} s system")
        if args.threads > 1 and updates[key]:
            # The calling thread does the call's serial parts (checks, set-up, the layout of the
            # output) and its share of the blocks; the others only their share. So its CPU less
            # theirs is the serial work plus the blocks' imbalance: what keeps the call from
            # halving on two free cores. CPU, so the neighbours' load does not enter it.
            others = cpu_s[key] - main_s[key]
            print(f"  {'':24s} calling thread {main_s[key]:.2f} s CPU, the other threads {others:.2f} s: "
                  f"serial work and imbalance ~{main_s[key] - others / (args.threads - 1):.2f} s")


if __name__ == "__main__":
    main()
