"""Fuzz the engine API and the scenario keys for a long budget (issue 11) and print, per area,
the examples tried, crashes, hangs and property failures.

    python bench/fuzz_engine.py                        # EVSTWIN_FUZZ_EXAMPLES or 5000 per area
    python bench/fuzz_engine.py --examples 20000 --hang-s 60 --areas engine.run,scenario.set

Each area is the hypothesis test of tests/python/test_fuzz_engine.py or test_fuzz_scenario.py,
run in a child pytest with ``EVSTWIN_FUZZ_EXAMPLES`` (random, not derandomised, examples). The
child writes a line per example, so a crash (the child killed by a signal) still counts what
it tried; an example running longer than --hang-s ends the child through faulthandler's
watchdog and counts as a hang. After a crash or hang the area goes on in a fresh child until
its budget is spent (at most --rounds children). A property failure (hypothesis's falsifying
example: an unnamed error, unsorted events, chunking or threads changing the events) is printed.
"""

from __future__ import annotations

import argparse
import os
import resource
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
TESTS = ROOT / "tests" / "python"
AREAS = {
    "engine.run": "test_fuzz_engine.py::test_fuzzed_runs_give_sorted_events_or_a_named_error_the_same_for_any_"
                  "chunking_and_threads",
    "engine.run_pixels": "test_fuzz_engine.py::test_fuzzed_sub_sampling_of_some_pixels_is_a_named_error_or_events_"
                         "on_the_sensor",
    "engine.Sensor": "test_fuzz_engine.py::test_fuzzed_constructor_arguments_are_accepted_or_a_named_error",
    "scenario.set": "test_fuzz_scenario.py::test_fuzzed_assignments_build_and_run_or_are_one_line_naming_the_key",
}


def run_area(test: str, examples: int, hang_s: float, rounds: int, memory_gb: float) -> dict[str, object]:
    tried = crashes = hangs = failures = 0
    notes: list[str] = []
    for _ in range(rounds):
        left = examples - tried
        if left <= 0:
            break
        with tempfile.NamedTemporaryFile("r", suffix=".progress") as progress:
            env = dict(os.environ, EVSTWIN_FUZZ_EXAMPLES=str(left), EVSTWIN_FUZZ_PROGRESS=progress.name,
                       EVSTWIN_FUZZ_HANG_S=str(hang_s))
            proc = subprocess.run(
                [sys.executable, "-m", "pytest", "-q", "-s", "-x", "-p", "no:cacheprovider", "-W", "ignore::DeprecationWarning",
                 str(TESTS / test)],
                cwd=ROOT, env=env, capture_output=True, text=True, check=False,
                preexec_fn=lambda: _limit_memory(memory_gb),
            )
            done = sum(1 for _ in progress)
        tried += done
        out = proc.stdout + proc.stderr
        if proc.returncode < 0:
            crashes += 1
            notes.append(f"crash: {signal.Signals(-proc.returncode).name} after {done} examples; {out[-400:]!r}")
        elif "Timeout (" in out:
            hangs += 1
            notes.append(f"hang: an example ran over {hang_s:g} s; {out[out.index('Timeout ('):][:400]!r}")
        elif proc.returncode != 0:
            failures += 1
            falsifying = out[out.find("Falsifying"):][:600] if "Falsifying" in out else out[-600:]
            notes.append(f"failure: {falsifying!r}")
            break  # hypothesis has shrunk it: another round would find the same
        else:
            break  # the budget ran without incident
    return {"tried": tried, "crashes": crashes, "hangs": hangs, "failures": failures, "notes": notes}


def _limit_memory(gb: float) -> None:
    """In the child: an address-space limit, so a runaway allocation is a MemoryError (a
    failure with its example) rather than the machine's OOM killer (a SIGKILL, no example)."""
    limit = int(gb * 2**30)
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--examples", type=int, default=int(os.environ.get("EVSTWIN_FUZZ_EXAMPLES", "5000")),
                        help="examples per area (default: EVSTWIN_FUZZ_EXAMPLES or 5000)")
    parser.add_argument("--hang-s", type=float, default=60.0,
                        help="seconds one example may run before it counts as a hang (default 60)")
    parser.add_argument("--memory-gb", type=float, default=6.0,
                        help="address-space limit of each child [GiB] (default 6): more is a MemoryError")
    parser.add_argument("--rounds", type=int, default=5, help="children per area at most, after crashes (default 5)")
    parser.add_argument("--areas", default=",".join(AREAS), help=f"comma-separated, of {', '.join(AREAS)}")
    args = parser.parse_args()
    areas = [a for a in args.areas.split(",") if a]
    unknown = [a for a in areas if a not in AREAS]
    if unknown:
        parser.error(f"unknown --areas {unknown}; known: {', '.join(AREAS)}")
    if args.examples < 1 or not args.hang_s > 0 or args.rounds < 1:
        parser.error(f"--examples, --hang-s and --rounds must be positive; got {args.examples}, {args.hang_s}, "
                     f"{args.rounds}")
    print(f"{args.examples} examples per area, hang after {args.hang_s:g} s per example, {args.memory_gb:g} GiB "
          "address space per child")
    print(f"{'area':20} {'examples':>9} {'crashes':>8} {'hangs':>6} {'failures':>9} {'seconds':>8}")
    bad = False
    for area in areas:
        t0 = time.perf_counter()
        r = run_area(AREAS[area], args.examples, args.hang_s, args.rounds, args.memory_gb)
        print(f"{area:20} {r['tried']:9d} {r['crashes']:8d} {r['hangs']:6d} {r['failures']:9d} "
              f"{time.perf_counter() - t0:8.0f}", flush=True)
        for note in r["notes"]:  # type: ignore[attr-defined]
            print("  " + str(note)[:700])
        bad |= bool(r["crashes"] or r["hangs"] or r["failures"])
    print("FAIL" if bad else "PASS: no crash, no hang; every error one line naming its argument or key")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
