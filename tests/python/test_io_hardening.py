"""Issue 11, files: a corrupted file cannot take the process down (decoders in a child), writes
check free space and leave no temporary file on any failure, orphans of dead writers are
removed, non-native arrays are stored as their values, sizes read from headers are validated."""

from __future__ import annotations

import errno
import gc
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import pytest

from evstwin import io
from evstwin.io import _isolation, writer
from evstwin.sensor import EVENT_DTYPE

META = {"width": 8, "height": 8}


def three_events() -> np.ndarray:
    ev = np.zeros(3, EVENT_DTYPE)
    ev["t"], ev["x"], ev["y"], ev["p"] = [0, 10, 20], [1, 2, 3], [1, 1, 2], [1, 0, 1]
    return ev


def flipped(path: Path, offset: int, mask: int, name: str) -> Path:
    data = bytearray(path.read_bytes())
    data[offset] ^= mask
    out = path.with_name(name)
    out.write_bytes(bytes(data))
    return out


def run_python(code: str, *args: str, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    """``code`` in a fresh interpreter: a regression that kills or hangs the reader fails the
    test instead of taking pytest with it."""
    return subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code), *args], capture_output=True, text=True, timeout=timeout
    )


READ_ONE_LINE = """
    import sys
    from evstwin.io import read_events, _isolation
    _isolation.NO_PROGRESS_TIMEOUT_S = float(sys.argv[1])
    for path in sys.argv[2:]:
        try:
            read_events(path)
        except BaseException as err:
            print(type(err).__name__, "|", err)
        else:
            print("decoded")
"""


# --------------------------------------------------------------------------------------------
# 1. untrusted decoding cannot take the process down


def test_an_aedat4_that_aborts_the_decoder_is_a_one_line_error(tmp_path: Path) -> None:
    pytest.importorskip("aedat")
    bad = flipped(io.write_events(tmp_path / "a.aedat4", three_events(), META), 91, 0x80, "b.aedat4")
    result = run_python(READ_ONE_LINE, "60", str(bad))
    assert result.returncode == 0, result.stderr[-500:]  # the aedat decoder used to SIGABRT here
    line = result.stdout.strip()
    assert line.count("\n") == 0
    assert line.startswith("DecoderCrashError |") and "SIGABRT" in line and str(bad) in line
    assert result.stderr == ""  # the Rust backtrace stays in the child


def test_an_aedat4_that_panics_the_decoder_is_a_value_error(tmp_path: Path) -> None:
    pytest.importorskip("aedat")
    bad = flipped(io.write_events(tmp_path / "a.aedat4", three_events(), META), 14, 0xFF, "b.aedat4")
    with pytest.raises(ValueError, match="PanicException") as info:  # a BaseException before
        io.read_events(bad)
    assert str(bad) in str(info.value) and "\n" not in str(info.value)


def test_a_panic_is_a_value_error_in_the_process_too(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("aedat")
    bad = flipped(io.write_events(tmp_path / "a.aedat4", three_events(), META), 14, 0xFF, "b.aedat4")
    monkeypatch.setattr(_isolation, "ENABLED", False)
    with pytest.raises(ValueError, match=r"b\.aedat4.*PanicException"):
        io.read_events(bad)


# Single-byte mutants (xor 0xff) of the three-event file on which libhdf5 spins forever in the
# object header of the root group: found by decoding every mutant of the file in a forked child
# with an alarm (4 of 18,758 offsets). If the layout moves, search again the same way.
H5_HANGING_OFFSETS = (2072, 2104, 2128, 2152)


def test_an_h5_that_hangs_libhdf5_is_stopped(tmp_path: Path) -> None:
    good = io.write_events(tmp_path / "h.h5", three_events(), META)
    bad = [str(flipped(good, offset, 0xFF, f"b{offset}.h5")) for offset in H5_HANGING_OFFSETS[:2]]
    result = run_python(READ_ONE_LINE, "1", *bad, timeout=60)
    assert result.returncode == 0, result.stderr[-500:]
    outcomes = result.stdout.strip().splitlines()
    assert len(outcomes) == len(bad)
    hangs = [line for line in outcomes if line.startswith("DecoderHangError |")]
    assert hangs, f"no mutant hangs libhdf5 any more (layout moved?): {outcomes}"
    assert all("made no progress" in line and ".h5" in line for line in hangs)


def test_a_script_without_main_guard_is_not_run_again_by_the_decoder(tmp_path: Path) -> None:
    io.write_events(tmp_path / "h.h5", three_events(), META)
    script = tmp_path / "script.py"
    script.write_text(
        "from evstwin.io import read_events\n"
        f"print('body', len(read_events({str(tmp_path / 'h.h5')!r})[0]), flush=True)\n"
    )
    result = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120)
    assert result.stdout.split() == ["body", "3"], result.stderr[-500:]


def test_isolated_and_in_process_reads_agree(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(1)
    ev = np.zeros(5000, EVENT_DTYPE)
    ev["t"] = np.sort(rng.integers(0, 3_000_000, 5000))
    ev["x"], ev["y"], ev["p"] = rng.integers(0, 8, 5000), rng.integers(0, 8, 5000), rng.integers(0, 2, 5000)
    path = io.write_events(tmp_path / "e.h5", ev, {**META, "truth": {"s": {"t": np.arange(4)}}, "k": 2})
    chunks = [c.copy() for c in io.iter_events(path, chunk=777)]
    window = io.read_time_window(path, 1_000_000, 2_000_000)
    got, meta = io.read_events(path)
    monkeypatch.setattr(_isolation, "ENABLED", False)
    want, want_meta = io.read_events(path)
    assert np.array_equal(got, want) and np.array_equal(got, ev)
    assert [len(c) for c in chunks] == [777] * 6 + [5000 - 6 * 777]
    assert np.array_equal(np.concatenate(chunks), ev)
    assert np.array_equal(window, io.read_time_window(path, 1_000_000, 2_000_000))
    assert meta["k"] == want_meta["k"] == 2 and meta["truth"]["s"]["t"].tolist() == [0, 1, 2, 3]
    got["t"][0] = -1  # the chunks received from the child are the caller's own, writable arrays


def test_a_missing_file_is_still_file_not_found(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError):
        io.read_events(tmp_path / "none.h5")


# --------------------------------------------------------------------------------------------
# 2. writes: free space, temporary files, orphans


def fake_free(monkeypatch: pytest.MonkeyPatch, free: dict[str, int]) -> None:
    real = os.statvfs

    def statvfs(path: str | os.PathLike[str]) -> object:
        real(path)  # the directory must exist
        return SimpleNamespace(f_bavail=free["bytes"] // 4096, f_frsize=4096)

    monkeypatch.setattr(os, "statvfs", statvfs)


def events(n: int, t0: int = 0) -> np.ndarray:
    ev = np.zeros(n, EVENT_DTYPE)
    ev["t"] = t0 + np.arange(n)
    ev["x"], ev["y"] = np.arange(n) % 8, (np.arange(n) // 8) % 8
    return ev


@pytest.mark.parametrize("suffix", [".h5", ".npz", ".txt", ".raw", ".aedat4"])
def test_a_full_disk_is_enospc_before_the_write_and_leaves_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, suffix: str
) -> None:
    out = tmp_path / f"o{suffix}"
    out.write_bytes(b"previous")
    free = {"bytes": 1 << 40}
    fake_free(monkeypatch, free)
    w = io.open_event_writer(out, META)
    w.write(events(1000))
    w.append_truth("s", {"t": np.arange(10)})
    free["bytes"] = writer.SPACE_MARGIN_BYTES + 50_000  # less than the next chunk needs
    with pytest.raises(OSError, match=r"no space left to write .*o\.") as info:
        w.write(events(100_000, 1000))
    assert info.value.errno == errno.ENOSPC and "\n" not in str(info.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == [out.name]  # temp, spool and lock gone
    assert out.read_bytes() == b"previous"
    with pytest.raises(ValueError, match="closed"):
        w.write(events(1, 200_000))


def test_enospc_at_open_truth_and_close(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    free = {"bytes": 1000}
    fake_free(monkeypatch, free)
    with pytest.raises(OSError, match="opening it") as info:
        io.write_events(tmp_path / "a.h5", events(10), META)
    assert info.value.errno == errno.ENOSPC
    free["bytes"] = writer.SPACE_MARGIN_BYTES + (1 << 20)
    w = io.open_event_writer(tmp_path / "b.npz", META)
    w.write(events(100))
    with pytest.raises(OSError, match="rows of truth 'big'"):
        w.append_truth("big", {"v": np.zeros(1 << 20)})
    assert list(tmp_path.iterdir()) == []
    w = io.open_event_writer(tmp_path / "c.npz", META)
    w.write(events(20_000))  # fits as records; the archive at close would not
    free["bytes"] = writer.SPACE_MARGIN_BYTES + 100_000
    with pytest.raises(OSError, match="finishing it"):
        w.close()
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("suffix", [".h5", ".npz"])
def test_every_failure_removes_the_truth_spool(tmp_path: Path, suffix: str) -> None:
    out = tmp_path / f"o{suffix}"
    w = io.open_event_writer(out, META)
    w.write(events(10))
    w.append_truth("s", {"t": np.arange(5), "x": np.ones(5)})
    assert len(list(tmp_path.iterdir())) > 3  # temporary file, spool files, lock
    w.update_meta({"truth": {"s": {"t": np.arange(2)}}})
    with pytest.raises(ValueError, match="both by append_truth"):
        w.close()
    assert list(tmp_path.iterdir()) == []
    w = io.open_event_writer(out, META)  # abandoned: the garbage collector cleans up
    w.append_truth("s", {"t": np.arange(5)})
    del w
    gc.collect()
    assert list(tmp_path.iterdir()) == []


ORPHAN_WRITER = """
    import os, signal, sys
    import numpy as np
    from evstwin.io import open_event_writer
    from evstwin.sensor import EVENT_DTYPE
    w = open_event_writer(sys.argv[1], {"width": 8, "height": 8})
    w.write(np.zeros(10, EVENT_DTYPE))
    w.append_truth("s", {"t": np.arange(3)})
    print(os.getpid(), flush=True)
    os.kill(os.getpid(), signal.SIGKILL)  # as the OOM killer or a power cut would
"""


def test_the_next_writer_removes_the_orphans_of_a_killed_one(tmp_path: Path) -> None:
    out = tmp_path / "o.h5"
    killed = run_python(ORPHAN_WRITER, str(out))
    assert killed.returncode == -9
    pid = int(killed.stdout)
    left = sorted(p.name for p in tmp_path.iterdir())
    assert any(f"tmp-{pid}-" in name for name in left) and ".o.h5.lock" in left
    alive = tmp_path / f".o.h5.tmp-{os.getppid()}-0123abcd"  # a live pid: maybe another writer
    alive.write_bytes(b"")
    other = tmp_path / f".other.h5.tmp-{pid}-0123abcd"  # another output's: not ours to judge
    other.write_bytes(b"")
    io.write_events(out, three_events(), META)  # the lock died with the writer
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([alive.name, other.name, "o.h5"])
    assert io.read_events(out)[0].size == 3


# --------------------------------------------------------------------------------------------
# 3. non-native arrays and sizes read from headers


@pytest.mark.parametrize("suffix", [".aedat4", ".dat", ".es", ".csv", ".h5"])
def test_big_endian_chunks_are_written_as_their_values(tmp_path: Path, suffix: str) -> None:
    big = three_events().astype([("t", ">i8"), ("x", ">u2"), ("y", ">u2"), ("p", "u1")])
    swapped = np.zeros(3, EVENT_DTYPE.newbyteorder(">"))
    swapped[:] = three_events()
    with io.open_event_writer(tmp_path / f"e{suffix}", META, raw_format="evt2") as w:
        w.write(big[:2])
        w.write(swapped[2:])
    got, _ = io.read_events(tmp_path / f"e{suffix}")
    assert np.array_equal(got, three_events())


@pytest.mark.parametrize("suffix", [".h5", ".npz"])
def test_big_endian_truth_is_stored_as_its_values(tmp_path: Path, suffix: str) -> None:
    values = np.array([1.5, -2.25, 1e10], ">f8")
    ids = np.array([1, 2, 70000], ">i4")
    path = tmp_path / f"e{suffix}"
    with io.open_event_writer(path, {**META, "truth": {"given": {"v": values}}}) as w:
        w.write(three_events())
        w.append_truth("streamed", {"id": ids[:2]})
        w.append_truth("streamed", {"id": ids[2:]})
    truth = io.read_events(path)[1]["truth"]
    for got in (truth["given"]["v"], truth["streamed"]["id"]):
        assert got.dtype.isnative
    assert truth["given"]["v"].tolist() == [1.5, -2.25, 1e10]
    assert truth["streamed"]["id"].tolist() == [1, 2, 70000]


def test_truth_rows_cannot_change_to_a_lossy_dtype(tmp_path: Path) -> None:
    with io.open_event_writer(tmp_path / "e.h5", META) as w:
        w.append_truth("s", {"id": np.arange(3, dtype=np.int32)})
        w.append_truth("s", {"id": np.arange(3, dtype=np.int16)})  # widened: fine
        with pytest.raises(TypeError, match="float64 into int32"):
            w.append_truth("s", {"id": np.array([0.5])})


def test_impossible_sizes_in_headers_name_the_file_and_value(tmp_path: Path) -> None:
    txt = tmp_path / "w.txt"
    txt.write_text("# width=99999999999 height=5\n0 1 1 1\n")
    cases: list[tuple[Path, str]] = [(txt, "99999999999")]
    for name, value, shown in (("a.h5", 2**40, "1099511627776"), ("b.h5", 1e300, "1e+300")):
        path = io.write_events(tmp_path / name, three_events(), META)
        with h5py.File(path, "a") as f:
            f.attrs["width"] = value
        cases.append((path, shown))
    npz = io.write_events(tmp_path / "c.npz", three_events(), META)
    entries = dict(np.load(npz))
    entries["width"] = np.array(-3)
    np.savez(tmp_path / "d.npz", **entries)
    cases.append((tmp_path / "d.npz", "-3"))
    if sys.modules.get("faery") is not None or _has("faery"):
        dat = io.write_events(tmp_path / "e.dat", three_events(), META)
        (tmp_path / "f.dat").write_bytes(dat.read_bytes().replace(b"% Width 8", b"% Width 99999999"))
        cases.append((tmp_path / "f.dat", "99999999"))
    for path, shown in cases:
        with pytest.raises(ValueError, match=rf"{path.name}.*width = {re.escape(shown)} is not an integer in \[1, 65535\]"):
            io.read_events(path)


def _has(module: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(module) is not None
