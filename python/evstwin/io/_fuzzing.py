"""Byte-mutation fuzzing of the readers (issue 11): shared by ``tests/python/test_fuzz_io.py``
(a few hundred mutants) and ``bench/fuzz_io.py`` (long budgets). Not part of the API.

Every mutant is decoded with :func:`evstwin.io.read_events` with *every* format decoded in a
child process (:func:`evstwin.io._isolation.forced`), so that a crash or a hang is observed
whichever decoder it comes from, and classified:

``ok``       decoded (the mutation hit padding, or a value that is still valid);
``error``    ValueError or OSError, one line, naming the file: what a user must get;
``crash``    the decoder's process died (SIGABRT, SIGSEGV...): contained by the isolation,
             a process crash for a format decoded in the process by default;
``hang``     no progress within the timeout: same;
``bad``      any other outcome (another exception type, several lines, the file not named).
"""

from __future__ import annotations

import dataclasses
import itertools
import random
import time
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from ..sensor import EVENT_DTYPE
from . import _isolation
from ._isolation import DecoderCrashError, DecoderHangError
from .reader import read_events
from .writer import write_events

OUTCOMES = ("ok", "error", "crash", "hang", "bad")
KINDS = ("flip", "truncate", "splice")

REAL_CUTS = {"aedat4 (DAVIS346 cut)": "davis346_road_cut.aedat4", "raw (IMX636 EVT3 cut)": "imx636_cut_evt3.raw"}


def sample_events(n: int = 40, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    events = np.zeros(n, EVENT_DTYPE)
    events["t"] = np.sort(rng.integers(0, 20_000, n))
    events["x"] = rng.integers(0, 16, n)
    events["y"] = rng.integers(0, 12, n)
    events["p"] = rng.integers(0, 2, n)
    return events


def write_samples(directory: Path, data_dir: Path | None = None) -> dict[str, Path]:
    """A small file of every format evstwin writes and reads (label -> path), with a scenario
    and ground truth where the format holds them, plus the real cuts (:data:`REAL_CUTS`) in
    ``data_dir``, the repository's tests/data (given by the caller, who knows where the
    repository is: an installed package does not)."""
    events = sample_events()
    meta = {
        "width": 16,
        "height": 12,
        "scenario": {"name": "fuzz", "sensor": {"width": 16, "height": 12}},
        "truth": {"star": {"t_us": np.arange(5, dtype=np.int64), "x_px": np.linspace(0, 4, 5)}},
    }
    plain = {"width": 16, "height": 12}
    files = {
        "hdf5": write_events(directory / "s.h5", events, meta),
        "npz": write_events(directory / "s.npz", events, meta),
        "txt": write_events(directory / "s.txt", events, plain),
        "csv": write_events(directory / "s.csv", events, plain),
        "aedat4": write_events(directory / "s.aedat4", events, plain),
        "raw evt3": write_events(directory / "s3.raw", events, plain, raw_format="evt3"),
        "raw evt2": write_events(directory / "s2.raw", events, plain, raw_format="evt2"),
        "dat": write_events(directory / "s.dat", events, plain),
        "es": write_events(directory / "s.es", events, plain),
    }
    if data_dir is not None:
        for label, name in REAL_CUTS.items():
            files[label] = Path(data_dir) / name
    return files


def mutate(data: bytes, rng: random.Random) -> tuple[str, bytes]:
    """One mutant of ``data``: a single-byte flip, a truncation or a splice (a span of the file
    copied over another place, or random bytes inserted). Half the offsets fall in the first
    512 bytes, where the headers are."""
    n = len(data)

    def offset() -> int:
        return rng.randrange(min(n, 512)) if rng.random() < 0.5 else rng.randrange(n)

    kind = rng.choice(KINDS)
    out = bytearray(data)
    if kind == "flip":
        out[offset()] ^= rng.randrange(1, 256)
    elif kind == "truncate":
        del out[offset():]
    elif rng.random() < 0.5:
        start, length = rng.randrange(n), rng.randrange(1, 65)
        at = offset()
        out[at : at + length] = data[start : start + length]
    else:
        at = offset()
        out[at:at] = bytes(rng.randrange(256) for _ in range(rng.randrange(1, 17)))
    return kind, bytes(out)


@dataclasses.dataclass
class Result:
    label: str
    kind: str
    outcome: str
    message: str
    seconds: float
    mutant: bytes  # kept for crash, hang and bad only


def decode(path: Path) -> tuple[str, str]:
    """(outcome, message) of reading ``path``."""
    try:
        read_events(path)
    except DecoderCrashError as err:
        return "crash", str(err)
    except DecoderHangError as err:
        return "hang", str(err)
    except (ValueError, OSError) as err:
        message = str(err)
        good = "\n" not in message and str(path) in message
        return ("error" if good else "bad"), f"{type(err).__name__}: {message}"
    except KeyboardInterrupt:
        raise
    except BaseException as err:  # noqa: BLE001 - exactly what the fuzzing looks for
        return "bad", f"{type(err).__module__}.{type(err).__name__}: {err}"
    return "ok", ""


def run(
    files: dict[str, Path], examples: int, workdir: Path, seed: int = 0, timeout_s: float = 5.0,
    workers: int = 2,
) -> Iterator[Result]:
    """``examples`` mutants of each file, decoded ``workers`` at a time (each in a child
    process, stopped after ``timeout_s`` without progress); results in order."""
    def jobs() -> Iterator[tuple[str, str, Path, bytes]]:
        for index, (label, path) in enumerate(files.items()):
            data = path.read_bytes()
            rng = random.Random(f"{seed}:{label}")
            for k in range(examples):
                kind, mutant = mutate(data, rng)
                yield label, kind, workdir / f"m{index}-{k}{path.suffix}", mutant

    def one(job: tuple[str, str, Path, bytes]) -> Result:
        label, kind, target, mutant = job
        target.write_bytes(mutant)
        start = time.perf_counter()
        outcome, message = decode(target)
        seconds = time.perf_counter() - start
        target.unlink()
        kept = mutant if outcome in ("crash", "hang", "bad") else b""  # memory O(findings)
        return Result(label, kind, outcome, message, seconds, kept)

    saved = _isolation.NO_PROGRESS_TIMEOUT_S
    _isolation.NO_PROGRESS_TIMEOUT_S = timeout_s
    try:
        with _isolation.forced(), ThreadPoolExecutor(workers) as pool:
            pending = jobs()
            while batch := list(itertools.islice(pending, 8 * workers)):  # mutants made as needed
                yield from pool.map(one, batch)
    finally:
        _isolation.NO_PROGRESS_TIMEOUT_S = saved
