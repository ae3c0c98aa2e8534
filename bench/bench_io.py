"""Event files in a stream: write N events chunk by chunk to every format, stream them back
with iter_events, and print wall time and peak traced memory (tracemalloc sees NumPy's
buffers) of each; for .h5, a 10 ms window read through the file's millisecond index.

    python bench/bench_io.py [--events 5000000] [--chunk 100000] [--formats .h5,.npz,...]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path

import numpy as np

from evstwin.io import iter_events, open_event_writer, read_time_window
from evstwin.sensor import EVENT_DTYPE

FORMATS = ".h5,.npz,.csv,.aedat4,.raw,.dat,.es"


def traced(fn: Callable[[], object]) -> tuple[float, float]:
    """(wall seconds without tracing, peak traced MB of a second, traced run)."""
    start = time.perf_counter()
    fn()
    wall = time.perf_counter() - start
    tracemalloc.start()
    try:
        fn()
        return wall, tracemalloc.get_traced_memory()[1] / 1e6
    finally:
        tracemalloc.stop()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--events", type=int, default=5_000_000, help="events written (default 5000000)")
    ap.add_argument("--chunk", type=int, default=100_000, help="events per chunk (default 100000)")
    ap.add_argument("--formats", default=FORMATS, help=f"suffixes (default {FORMATS})")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    block = np.zeros(args.chunk, EVENT_DTYPE)  # 100 ms of a 346 x 260 sensor per chunk
    block["t"] = np.sort(rng.integers(0, 100_000, args.chunk))
    block["x"] = rng.integers(0, 346, args.chunk)
    block["y"] = rng.integers(0, 260, args.chunk)
    block["p"] = rng.integers(0, 2, args.chunk)
    n_chunks = args.events // args.chunk
    print(f"machine: {os.cpu_count()} cores; {n_chunks * args.chunk} events in chunks of {args.chunk} "
          f"({n_chunks * args.chunk * EVENT_DTYPE.itemsize / 1e6:.0f} MB as EVENT_DTYPE, "
          f"{args.chunk * EVENT_DTYPE.itemsize / 1e6:.1f} MB a chunk)")
    print(f"{'format':8s} {'file MB':>8s} {'write s':>8s} {'peak MB':>8s} {'read s':>7s} {'peak MB':>8s}")
    with tempfile.TemporaryDirectory() as tmp:
        for suffix in args.formats.split(","):
            path = Path(tmp) / f"events{suffix}"

            def write(path: Path = path) -> None:
                with open_event_writer(path, {"width": 346, "height": 260}) as w:
                    for k in range(n_chunks):
                        chunk = block.copy()
                        chunk["t"] += k * 100_000
                        w.write(chunk)

            def read(path: Path = path) -> None:
                assert sum(len(c) for c in iter_events(path, chunk=args.chunk)) == n_chunks * args.chunk

            write_s, write_mb = traced(write)
            read_s, read_mb = traced(read)
            line = (f"{suffix:8s} {path.stat().st_size / 1e6:8.1f} {write_s:8.2f} {write_mb:8.1f} "
                    f"{read_s:7.2f} {read_mb:8.1f}")
            if suffix == ".h5":
                start = time.perf_counter()
                window = read_time_window(path, 2_500_000, 2_510_000)
                line += f"   10 ms window: {len(window)} events in {(time.perf_counter() - start) * 1e3:.1f} ms"
            print(line, flush=True)


if __name__ == "__main__":
    main()
