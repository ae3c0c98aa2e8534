"""Event files in chunks: the streaming writer, iter_events, the HDF5 millisecond index and time
windows, RAW files without geometry, sizes read from headers, the optional extra."""

from __future__ import annotations

import sys
import tracemalloc
from pathlib import Path
from typing import Any

import h5py
import numpy as np
import pytest
from test_io import DATA, PAIR_IDS, PAIRS, make_events

from evstwin import io
from evstwin._extras import MissingExtraError
from evstwin.io import hdf5
from evstwin.sensor import EVENT_DTYPE

SIZE = {"width": 346, "height": 260}


def write_in_chunks(
    path: Path, events: np.ndarray, sizes: list[int], meta: dict[str, Any], **kw: Any
) -> Path:
    with io.open_event_writer(path, meta, **kw) as writer:
        start = 0
        for size in sizes:
            writer.write(events[start : start + size])
            start += size
        writer.write(events[start:])
        assert writer.count == len(events)
    return path


# --------------------------------------------------------------------------------------------
# streaming writer


@pytest.mark.parametrize("suffix,raw_format", PAIRS, ids=PAIR_IDS)
def test_chunked_write_equals_one_shot(tmp_path: Path, suffix: str, raw_format: str | None) -> None:
    events = make_events(5000, t0_us=777, span_us=20_000_000)
    kw = {"raw_format": raw_format} if raw_format else {}
    one = io.write_events(tmp_path / f"one{suffix}", events, SIZE, **kw)
    many = write_in_chunks(tmp_path / f"many{suffix}", events, [1, 0, 999, 1, 2047, 3], SIZE, **kw)
    assert one.read_bytes() == many.read_bytes()  # every writer is deterministic and chunk-blind
    back, meta = io.read_events(many)
    assert np.array_equal(back, events)
    assert (meta["width"], meta["height"]) == (346, 260)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([one.name, many.name])


def test_exception_inside_the_writer_leaves_nothing(tmp_path: Path) -> None:
    for suffix in (".h5", ".npz", ".txt", ".raw", ".aedat4", ".es"):
        final = tmp_path / f"out{suffix}"
        with pytest.raises(KeyError), io.open_event_writer(final, SIZE) as writer:
            writer.write(make_events(100))
            raise KeyError("simulation failed")
        assert list(tmp_path.iterdir()) == [], suffix
    writer = io.open_event_writer(tmp_path / "aborted.h5", SIZE)
    writer.write(make_events(10))
    writer.abort()
    assert list(tmp_path.iterdir()) == []


def test_exception_keeps_the_previous_file(tmp_path: Path) -> None:
    final = io.write_events(tmp_path / "out.npz", make_events(10), SIZE)
    before = final.read_bytes()
    with pytest.raises(RuntimeError), io.open_event_writer(final, SIZE) as writer:
        writer.write(make_events(50))
        raise RuntimeError("interrupted")
    assert final.read_bytes() == before and [p.name for p in tmp_path.iterdir()] == ["out.npz"]


def test_writer_checks_each_chunk(tmp_path: Path) -> None:
    events = make_events(20)
    with io.open_event_writer(tmp_path / "e.h5", SIZE) as writer:
        writer.write(events[10:])
        with pytest.raises(ValueError, match=r"sorted by t.*t\[10\].*previous chunk"):
            writer.write(events[:10])
        bad = np.zeros(1, EVENT_DTYPE)
        bad["t"], bad["x"] = events["t"][-1], 346
        with pytest.raises(ValueError, match="outside the 346x260 sensor"):
            writer.write(bad)
        writer.write(events[-1:])  # the writer stays usable after a refused chunk
    back, _ = io.read_events(tmp_path / "e.h5")
    assert np.array_equal(back, np.concatenate([events[10:], events[-1:]]))
    with pytest.raises(ValueError, match="closed"):
        writer.write(events)
    with pytest.raises(ValueError, match=r"meta\['width'\]"):
        io.open_event_writer(tmp_path / "f.h5", {"height": 4})


def test_truth_given_at_close(tmp_path: Path) -> None:
    truth = {"target0": {"t_s": np.linspace(0, 1, 5), "x_px": np.arange(5.0)}}
    with io.open_event_writer(tmp_path / "e.h5", SIZE) as writer:
        writer.write(make_events(30))
        writer.update_meta({"truth": truth, "scenario": {"seed": 3}, "seed": 3})
    _, meta = io.read_events(tmp_path / "e.h5")
    assert np.array_equal(meta["truth"]["target0"]["x_px"], np.arange(5.0))
    assert meta["scenario"] == {"seed": 3} and meta["seed"] == 3


def test_hdf5_memory_stays_flat(tmp_path: Path) -> None:
    n, chunk = 5_000_000, 100_000
    base = make_events(chunk, span_us=100_000)
    tracemalloc.start()
    try:
        with io.open_event_writer(tmp_path / "long.h5", SIZE) as writer:
            for k in range(n // chunk):
                block = base.copy()
                block["t"] += k * 100_000
                writer.write(block)
        _, write_peak = tracemalloc.get_traced_memory()
        tracemalloc.reset_peak()
        count = 0
        for part in io.iter_events(tmp_path / "long.h5", chunk=chunk):
            count += len(part)
        _, read_peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    total = n * EVENT_DTYPE.itemsize  # 80 MB
    assert count == n
    assert write_peak < total / 10, write_peak
    assert read_peak < total / 10, read_peak


# --------------------------------------------------------------------------------------------
# iter_events


READABLE = [
    *[(f"events{s}", r) for s, r in PAIRS],
    (str(DATA / "davis346_road_cut.aedat4"), None),
    (str(DATA / "imx636_cut_evt3.raw"), None),
]


@pytest.mark.parametrize("name,raw_format", READABLE, ids=[*PAIR_IDS, "davis-cut", "evk4-cut"])
def test_iter_events_concatenated_equals_read_events(
    tmp_path: Path, name: str, raw_format: str | None
) -> None:
    path = Path(name)
    if not path.is_absolute():
        path = io.write_events(tmp_path / name, make_events(3000), SIZE, raw_format=raw_format)
    whole, meta = io.read_events(path)
    stream = io.iter_events(path, chunk=333)
    chunks = list(stream)
    assert all(0 < len(c) <= 333 for c in chunks) and all(c.dtype == EVENT_DTYPE for c in chunks)
    assert np.array_equal(np.concatenate(chunks), whole)
    assert {k: v for k, v in stream.meta.items() if k != "truth"} == {
        k: v for k, v in meta.items() if k != "truth"
    }
    assert np.array_equal(np.concatenate(list(stream)), whole)  # iterable again


def test_npz_with_separate_columns_streams(tmp_path: Path) -> None:
    events = make_events(1000)
    path = tmp_path / "columns.npz"
    np.savez(path, **{name: events[name] for name in ("t", "x", "y", "p")})
    chunks = list(io.iter_events(path, chunk=300))
    assert [len(c) for c in chunks] == [300, 300, 300, 100]
    assert np.array_equal(np.concatenate(chunks), events)


def test_text_size_known_after_the_scan(tmp_path: Path) -> None:
    path = tmp_path / "plain.txt"
    path.write_text("10 3 4 1\n12 9 2 0\n12 0 7 1\n")
    stream = io.iter_events(path, chunk=2)
    assert stream.meta["width"] is None and stream.meta["size_source"] is None
    assert [len(c) for c in stream] == [2, 1]
    assert (stream.meta["width"], stream.meta["height"], stream.meta["size_source"]) == (10, 8, "events")


def test_bad_chunk_and_size_arguments(tmp_path: Path) -> None:
    path = io.write_events(tmp_path / "e.h5", make_events(10), SIZE)
    for chunk in (0, -5, 2.5, True):
        with pytest.raises(ValueError, match="chunk"):
            io.iter_events(path, chunk=chunk)  # type: ignore[arg-type]
    for size in ((0, 10), (10,), (70_000, 10), "640x480"):
        with pytest.raises(ValueError, match="size"):
            io.read_events(path, size=size)  # type: ignore[arg-type]


# --------------------------------------------------------------------------------------------
# HDF5 millisecond index and time windows


def test_ms_index_by_hand(tmp_path: Path) -> None:
    events = np.zeros(7, EVENT_DTYPE)
    events["t"] = [0, 10, 999, 1000, 1000, 2500, 7000]
    path = write_in_chunks(tmp_path / "e.h5", events, [2, 2], {"width": 4, "height": 4})
    with h5py.File(path, "r") as f:
        index = f["ms_to_idx"][()]
        assert f["ms_to_idx"].attrs["t_origin_us"] == 0
    # entry m: the first event with t >= 1000 m
    assert index.tolist() == [0, 3, 5, 6, 6, 6, 6, 6]
    assert index.dtype == np.uint64


def test_ms_index_origin_for_unix_times(tmp_path: Path) -> None:
    events = make_events(200, t0_us=1_589_163_147_368_868, span_us=50_000)
    path = io.write_events(tmp_path / "e.h5", events, SIZE)
    with h5py.File(path, "r") as f:
        index = f["ms_to_idx"][()]
        origin = int(f["ms_to_idx"].attrs["t_origin_us"])
    assert origin == int(events["t"][0]) // 1000 * 1000  # the first event, floored to the ms
    expected = np.searchsorted(events["t"], origin + 1000 * np.arange(len(index)), side="left")
    assert np.array_equal(index, expected)
    assert len(index) == (int(events["t"][-1]) - origin) // 1000 + 1


def _windows(events: np.ndarray) -> list[tuple[int, int]]:
    t0, t1 = int(events["t"][0]), int(events["t"][-1])
    rng = np.random.default_rng(3)
    windows = [(t0 - 5000, t0), (t0 - 5000, t0 + 1), (t1, t1 + 1), (t1 + 1, t1 + 9000), (t0, t1 + 1)]
    windows += [(3000, 5000), (2999, 3001), (int(events["t"][100]), int(events["t"][100]))]
    for _ in range(20):
        a, b = np.sort(rng.integers(t0 - 2000, t1 + 2000, 2))
        windows.append((int(a), int(b)))
    return windows


@pytest.mark.parametrize("kind", ["indexed", "no-index", "npz", "unix-time"])
def test_read_time_window_matches_a_mask(tmp_path: Path, kind: str) -> None:
    t0 = 1_589_163_147_368_868 if kind == "unix-time" else 500
    events = make_events(4000, t0_us=t0, span_us=300_000)
    suffix = ".npz" if kind == "npz" else ".h5"
    path = io.write_events(tmp_path / f"e{suffix}", events, SIZE)
    if kind == "no-index":
        with h5py.File(path, "a") as f:
            del f["ms_to_idx"]
    for a, b in _windows(events):
        got = io.read_time_window(path, a, b)
        assert np.array_equal(got, events[(events["t"] >= a) & (events["t"] < b)]), (a, b)
    with pytest.raises(ValueError, match="before"):
        io.read_time_window(path, 10, 5)


def test_index_window_reads_little(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    events = make_events(20_000, span_us=2_000_000)
    path = io.write_events(tmp_path / "e.h5", events, SIZE)
    called: list[int] = []
    real = hdf5._bisect
    monkeypatch.setattr(hdf5, "_bisect", lambda *a: called.append(1) or real(*a))
    got = io.read_time_window(path, 1_000_000, 1_010_000)
    assert not called  # the index, not a bisection
    assert np.array_equal(got, events[(events["t"] >= 1_000_000) & (events["t"] < 1_010_000)])


# --------------------------------------------------------------------------------------------
# Prophesee EVT 2.0 without geometry


def encode_evt2(events: np.ndarray) -> bytes:
    """EVT 2.0 words (32-bit little endian): TIME_HIGH (type 0x8, t >> 6) whenever t >> 6
    changes, then CD_OFF/CD_ON (type 0x0/0x1) with t & 63 on bits 22-27, x on 11-21, y on 0-10."""
    words: list[int] = []
    high = -1
    for t, x, y, p in zip(
        events["t"].tolist(), events["x"].tolist(), events["y"].tolist(), events["p"].tolist()
    ):
        if t >> 6 != high:
            high = t >> 6
            words.append((0x8 << 28) | high)
        words.append((p << 28) | ((t & 63) << 22) | (x << 11) | y)
    return np.array(words, "<u4").tobytes()


def gen3_file(path: Path, events: np.ndarray, plugin: str, evt_line: bool) -> Path:
    lines = ["% Date 2020-09-14 09:03:25", "% integrator_name Prophesee", f"% plugin_name {plugin}"]
    lines += ["% serial_number 00001234", "% system_ID 21"]
    if evt_line:
        lines.append("% evt 2.0")
    path.write_bytes(("\n".join(lines) + "\n").encode() + encode_evt2(events))
    return path


def test_evt2_gen3_without_geometry_takes_the_plugin_size(tmp_path: Path) -> None:
    events = make_events(2000, width=640, height=480, span_us=300_000)
    path = gen3_file(tmp_path / "gen3.raw", events, "hal_plugin_gen3_fx3", evt_line=False)
    assert path.stat().st_size < 1 << 20
    back, meta = io.read_events(path)
    assert np.array_equal(back, events)
    assert (meta["width"], meta["height"], meta["size_source"]) == (640, 480, "plugin")
    assert meta["raw_format"] == "evt2" and "plugin_name hal_plugin_gen3_fx3" in meta["raw_header"]
    assert np.array_equal(np.concatenate(list(io.iter_events(path, chunk=500))), events)


def test_evt2_unknown_plugin_takes_the_size_from_the_events(tmp_path: Path) -> None:
    events = make_events(500, width=300, height=200)
    path = gen3_file(tmp_path / "other.raw", events, "hal_plugin_someone_else", evt_line=True)
    stream = io.iter_events(path)
    assert stream.meta["width"] is None
    back = np.concatenate(list(stream))
    assert np.array_equal(back, events)
    assert (stream.meta["width"], stream.meta["height"], stream.meta["size_source"]) == (300, 200, "events")
    _, meta = io.read_events(path)
    assert (meta["width"], meta["height"], meta["size_inferred"]) == (300, 200, True)


def test_evt2_size_argument_wins_and_is_checked(tmp_path: Path) -> None:
    events = make_events(500, width=640, height=480)
    path = gen3_file(tmp_path / "gen3.raw", events, "hal_plugin_gen31_fx3", evt_line=True)
    _, meta = io.read_events(path, size=(800, 600))
    assert (meta["width"], meta["height"], meta["size_source"]) == (800, 600, "argument")
    with pytest.raises(ValueError, match=r"gen3\.raw.*outside the size given 100x100"):
        io.read_events(path, size=(100, 100))


# --------------------------------------------------------------------------------------------
# sizes read from headers


def test_header_sizes_are_validated(tmp_path: Path) -> None:
    text = tmp_path / "big.txt"
    text.write_text("# width=99999999999 height=5\n1 2 3 1\n")
    with pytest.raises(ValueError, match=r"big\.txt.*width = 99999999999"):
        io.read_events(text)
    npz = tmp_path / "neg.npz"
    np.savez(npz, events=make_events(5), width=np.array(-3), height=np.array(10))
    with pytest.raises(ValueError, match=r"neg\.npz.*width = -3"):
        io.read_events(npz)
    h5 = io.write_events(tmp_path / "zero.h5", make_events(5), SIZE)
    with h5py.File(h5, "a") as f:
        f.attrs["height"] = 0
    with pytest.raises(ValueError, match=r"zero\.h5.*height = 0"):
        io.read_events(h5)
    raw = tmp_path / "huge.raw"
    raw.write_bytes(b"% evt 2.0\n% geometry 4096x4096\n% end\n" + encode_evt2(make_events(5)))
    with pytest.raises(ValueError, match=r"huge\.raw.*width = 4096.*2048"):
        io.read_events(raw)
    small = io.write_events(tmp_path / "small.h5", make_events(50), SIZE)
    with h5py.File(small, "a") as f:
        f.attrs["width"] = 10
    with pytest.raises(ValueError, match=r"small\.h5.*outside the declared 10x260"):
        io.read_events(small)


# --------------------------------------------------------------------------------------------
# the optional extra


@pytest.mark.parametrize("module,suffix", [("faery", ".raw"), ("faery", ".es"), ("aedat", ".aedat4")])
def test_missing_extra_names_it(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, module: str, suffix: str
) -> None:
    path = io.write_events(tmp_path / f"e{suffix}", make_events(10), SIZE)
    monkeypatch.setitem(sys.modules, module, None)
    with pytest.raises(MissingExtraError, match=r"evstwin\[io\]"):
        io.read_events(path)
    if module == "faery":
        with pytest.raises(MissingExtraError, match=r"evstwin\[io\]"):
            io.write_events(tmp_path / f"f{suffix}", make_events(10), SIZE, raw_format="evt2")
    assert io.read_events(io.write_events(tmp_path / "core.h5", make_events(10)))[0].size == 10


def test_a_second_writer_of_the_same_path_is_refused(tmp_path):
    # Two runs writing one output used to both succeed, the last silently winning (issue 11).
    import subprocess
    import sys

    from evstwin.io import open_event_writer

    out = tmp_path / "o.h5"
    meta = {"width": 8, "height": 8}
    with open_event_writer(out, meta) as first:
        with pytest.raises(FileExistsError, match="another writer is writing"):
            open_event_writer(out, meta)
        code = (
            "import sys\nfrom evstwin.io import open_event_writer\n"
            "try:\n    open_event_writer(sys.argv[1], {'width': 8, 'height': 8})\n"
            "except FileExistsError as e:\n    print('refused')\n"
        )
        other = subprocess.run([sys.executable, "-c", code, str(out)], capture_output=True, text=True, timeout=60)
        assert other.stdout.strip() == "refused"
        assert first.count == 0
    assert out.is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.h5"]  # lock file gone
    with open_event_writer(out, meta):  # free again once the first closed
        pass


@pytest.mark.parametrize("suffix", [".h5", ".npz", ".txt", ".raw"])
def test_big_endian_events_are_written_as_their_values(tmp_path, suffix):
    big = np.zeros(3, [("t", ">i8"), ("x", ">u2"), ("y", ">u2"), ("p", "u1")])
    big["t"], big["x"], big["y"], big["p"] = [0, 10, 20], [1, 2, 3], [1, 1, 2], [1, 0, 1]
    from evstwin.io import read_events, write_events

    write_events(tmp_path / f"e{suffix}", big, {"width": 8, "height": 8})
    got, _ = read_events(tmp_path / f"e{suffix}")
    assert got["t"].tolist() == [0, 10, 20] and got["x"].tolist() == [1, 2, 3] and got["p"].tolist() == [1, 0, 1]
