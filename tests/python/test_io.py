"""Event files: round trips through every format, the real recordings, atomic writes, bad input."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import evstwin
from evstwin import io
from evstwin.io import aedat, hdf5, numpy_files, prophesee, text
from evstwin.io._registry import FORMATS
from evstwin.sensor import EVENT_DTYPE

DATA = Path(__file__).resolve().parents[1] / "data"
SHARED = Path(os.environ.get("EVSTWIN_SHARED_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))

# (suffix, raw_format): every writer/reader pair.
PAIRS = [
    (".h5", None),
    (".hdf5", None),
    (".npz", None),
    (".txt", None),
    (".csv", None),
    (".aedat4", None),
    (".raw", "evt3"),
    (".raw", "evt2"),
    (".dat", None),
    (".es", None),
]
PAIR_IDS = [s.lstrip(".") + (f"-{r}" if r else "") for s, r in PAIRS]


def make_events(
    n: int, width: int = 346, height: int = 260, t0_us: int = 0, span_us: int = 2_000_000, seed: int = 1
) -> np.ndarray:
    """Sorted synthetic events with repeated timestamps and the sensor's corner pixels."""
    rng = np.random.default_rng(seed)
    ev = np.zeros(n, EVENT_DTYPE)
    ev["t"] = t0_us + np.sort(rng.integers(0, span_us, n))
    ev["x"] = rng.integers(0, width, n)
    ev["y"] = rng.integers(0, height, n)
    ev["p"] = rng.integers(0, 2, n)
    if n >= 4:
        ev["t"][1] = ev["t"][0]  # simultaneous events
        ev["x"][2], ev["y"][2] = width - 1, height - 1
        ev["x"][3], ev["y"][3] = 0, 0
    return ev


def roundtrip(
    tmp_path: Path,
    suffix: str,
    events: np.ndarray,
    meta: dict[str, Any] | None = None,
    raw_format: str | None = None,
) -> tuple[np.ndarray, dict[str, Any]]:
    path = tmp_path / f"events{suffix}"
    written = io.write_events(path, events, meta, raw_format=raw_format)
    assert written == path and path.is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name], "temporary files left behind"
    return io.read_events(path)


def shared_file(name: str) -> Path:
    path = SHARED / name
    if not path.is_file():
        pytest.skip(f"real recording {path} absent (set EVSTWIN_SHARED_DATA to the shared/data folder)")
    return path


# --------------------------------------------------------------------------------------------
# round trips


@pytest.mark.parametrize("suffix,raw_format", PAIRS, ids=PAIR_IDS)
def test_roundtrip_every_format(tmp_path: Path, suffix: str, raw_format: str | None) -> None:
    events = make_events(3000, t0_us=1_234)
    back, meta = roundtrip(tmp_path, suffix, events, {"width": 346, "height": 260}, raw_format)
    assert back.dtype == EVENT_DTYPE
    assert np.array_equal(back, events)
    assert (meta["width"], meta["height"]) == (346, 260)
    assert meta["format"] == FORMATS[suffix].name
    assert meta["path"] == str(tmp_path / f"events{suffix}")
    if suffix == ".raw":
        assert meta["raw_format"] == raw_format


@pytest.mark.parametrize(
    "suffix,raw_format",
    [p for p in PAIRS if p[0] != ".es"],
    ids=[i for i, p in zip(PAIR_IDS, PAIRS) if p[0] != ".es"],
)
def test_roundtrip_keeps_absolute_times(tmp_path: Path, suffix: str, raw_format: str | None) -> None:
    # DAVIS cameras stamp events with Unix time in microseconds; nothing may shift it.
    events = make_events(500, width=1280, height=720, t0_us=1_589_163_147_368_868)
    back, _ = roundtrip(tmp_path, suffix, events, None, raw_format)
    assert np.array_equal(back, events)


def test_es_refuses_a_late_time_origin(tmp_path: Path) -> None:
    events = make_events(10, t0_us=1_589_163_147_368_868)
    with pytest.raises(ValueError, match="no time origin"):
        io.write_events(tmp_path / "late.es", events)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("raw_format", io.RAW_FORMATS)
def test_raw_survives_long_sparse_recordings(tmp_path: Path, raw_format: str) -> None:
    # 100 s with gaps of up to seconds: crosses the 2**24 us EVT 3.0 time wrap several times.
    rng = np.random.default_rng(5)
    events = np.zeros(300, EVENT_DTYPE)
    events["t"] = 90_000_000 + np.sort(rng.integers(0, 100_000_000, 300))
    events["x"] = rng.integers(0, 1280, 300)
    events["y"] = rng.integers(0, 720, 300)
    events["p"] = rng.integers(0, 2, 300)
    back, meta = roundtrip(tmp_path, ".raw", events, {"width": 1280, "height": 720}, raw_format)
    assert np.array_equal(back, events)
    assert meta["raw_format"] == raw_format


def test_evt3_writes_a_time_high_word_per_period(tmp_path: Path) -> None:
    # As the sensors do: any EVT 3.0 decoder can then follow the 24-bit time wrap.
    events = make_events(40, t0_us=3_000_000, span_us=40_000_000)
    path = io.write_events(tmp_path / "e.raw", events)
    data = path.read_bytes()
    start = 0
    while data[start : start + 1] == b"%":
        start = data.index(b"\n", start) + 1
    words = np.frombuffer(data[start:], "<u2")
    high = (words[words >> 12 == 0x8] & 0xFFF).astype(np.int64)
    assert high[0] == 0 and np.all(np.diff(high) % 4096 == 1)
    assert len(high) == events["t"][-1] // 4096 + 1


@pytest.mark.parametrize(
    "suffix,raw_format",
    [p for p in PAIRS if p[0] != ".dat"],
    ids=[i for i, p in zip(PAIR_IDS, PAIRS) if p[0] != ".dat"],
)
def test_roundtrip_empty(tmp_path: Path, suffix: str, raw_format: str | None) -> None:
    back, meta = roundtrip(
        tmp_path, suffix, np.zeros(0, EVENT_DTYPE), {"width": 64, "height": 48}, raw_format
    )
    assert back.dtype == EVENT_DTYPE and len(back) == 0
    assert (meta["width"], meta["height"]) == (64, 48)


def test_dat_refuses_empty_and_overlong(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="without events"):
        io.write_events(tmp_path / "e.dat", np.zeros(0, EVENT_DTYPE), {"width": 4, "height": 4})
    events = make_events(3, width=4, height=4)
    events["t"] = [0, 1, 5_000_000_000]
    with pytest.raises(ValueError, match="32-bit"):
        io.write_events(tmp_path / "long.dat", events)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("suffix", [".h5", ".npz"])
def test_truth_scenario_and_extras_roundtrip(tmp_path: Path, suffix: str) -> None:
    n = 50
    truth = {
        "target0": {
            "t_s": np.linspace(0.0, 1.0, n),
            "x_px": np.linspace(10, 20, n),
            "y_px": np.linspace(5, 6, n),
            "flux_ph_s": np.full(n, 3.5e4),
        },
        "star1": {"t_s": np.zeros(0), "id": np.arange(3, dtype=np.int32)},
    }
    scenario = {
        "name": "geo pass",
        "sensor": {"preset": "davis346", "bias_on": np.float64(0.25)},
        "seed": np.int64(7),
        "duration_s": 2.0,
        "targets": [{"mag": 9.5}, {"mag": 11.0}],
        "unset": None,
    }
    meta = {
        "width": 346,
        "height": 260,
        "scenario": scenario,
        "truth": truth,
        "seed": 7,
        "exposure_note": "night",
        "gain": np.float32(1.5),
        "flag": True,
    }
    events = make_events(200)
    back, got = roundtrip(tmp_path, suffix, events, meta)
    assert np.array_equal(back, events)
    assert got["scenario"] == {
        "name": "geo pass",
        "sensor": {"preset": "davis346", "bias_on": 0.25},
        "seed": 7,
        "duration_s": 2.0,
        "targets": [{"mag": 9.5}, {"mag": 11.0}],
    }
    assert set(got["truth"]) == set(truth)
    for name, fields in truth.items():
        assert set(got["truth"][name]) == set(fields)
        for field, values in fields.items():
            assert got["truth"][name][field].dtype == values.dtype
            assert np.array_equal(got["truth"][name][field], values)
    assert got["seed"] == 7 and got["exposure_note"] == "night" and got["flag"] is True
    assert got["gain"] == pytest.approx(1.5)
    assert got["evstwin_version"] == evstwin.__version__


@pytest.mark.parametrize("suffix", [".h5", ".npz"])
def test_scenario_string_kept_as_is(tmp_path: Path, suffix: str) -> None:
    text = "# hand written\n[sensor]\npreset = 'davis346'\n"
    _, meta = roundtrip(tmp_path, suffix, make_events(5), {"scenario": text})
    assert meta["scenario"] == text


def test_meta_from_a_read_can_be_written_again(tmp_path: Path) -> None:
    events, meta = io.read_events(DATA / "imx636_cut_evt3.raw")
    path = io.write_events(tmp_path / "copy.h5", events, meta)
    again, meta2 = io.read_events(path)
    assert np.array_equal(again, events)
    assert (meta2["width"], meta2["height"]) == (1280, 720)
    assert meta2["format"] == "hdf5"


def test_t0_zero_shifts_and_reports_origin(tmp_path: Path) -> None:
    events = make_events(20, t0_us=5_000_000)
    path = io.write_events(tmp_path / "e.h5", events)
    back, meta = io.read_events(path, t0_zero=True)
    assert back["t"][0] == 0 and meta["t0_us"] == events["t"][0]
    assert np.array_equal(back["t"] + meta["t0_us"], events["t"])
    _, meta_default = io.read_events(path)
    assert "t0_us" not in meta_default


def test_size_defaults_to_max_coordinate_plus_one(tmp_path: Path) -> None:
    events = make_events(100, width=40, height=30)
    _, meta = roundtrip(tmp_path, ".h5", events)
    assert (meta["width"], meta["height"]) == (40, 30)


def test_text_output_is_plain(tmp_path: Path) -> None:
    events = make_events(3, width=10, height=10)
    events["t"] = [-7, 0, 123456789012]
    io.write_events(tmp_path / "e.csv", events, {"width": 10, "height": 10})
    lines = (tmp_path / "e.csv").read_text().splitlines()
    assert lines[0] == f"# evstwin {evstwin.__version__} width=10 height=10"
    assert lines[1] == "# t,x,y,p"
    assert lines[2:] == [",".join(str(int(e[f])) for f in ("t", "x", "y", "p")) for e in events]


# --------------------------------------------------------------------------------------------
# text files from elsewhere


def test_text_without_header_infers_size(tmp_path: Path) -> None:
    path = tmp_path / "plain.txt"
    path.write_text("10 3 4 1\n12 9 2 0\n12\t0 7 1\n")
    events, meta = io.read_events(path)
    assert events.tolist() == [(10, 3, 4, 1), (12, 9, 2, 0), (12, 0, 7, 1)]
    assert (meta["width"], meta["height"], meta["size_inferred"]) == (10, 8, True)


def test_csv_with_names_row_and_signed_polarity(tmp_path: Path) -> None:
    path = tmp_path / "other.csv"
    path.write_text("t,x,y,p\n5,1,2,-1\n6,3,4,1\n")
    events, meta = io.read_events(path)
    assert events.tolist() == [(5, 1, 2, 0), (6, 3, 4, 1)]
    assert meta["size_inferred"] is True


def test_text_in_seconds_is_converted_to_microseconds(tmp_path: Path) -> None:
    # The UZH/RPG event-camera datasets' events.txt: "t[s] x y p".
    path = tmp_path / "events.txt"
    path.write_text("0.003811000 96 133 0\n0.003820001 127 171 1\n1.5 0 0 1\n")
    events, meta = io.read_events(path)
    assert events["t"].tolist() == [3811, 3820, 1_500_000]
    assert meta["time_unit_in_file"] == "s"


def test_unsorted_file_is_sorted_on_read(tmp_path: Path) -> None:
    path = tmp_path / "shuffled.txt"
    path.write_text("# width=8 height=8\n30 1 1 1\n10 2 2 0\n20 3 3 1\n10 4 4 1\n")
    events, meta = io.read_events(path)
    assert events["t"].tolist() == [10, 10, 20, 30]
    assert events["x"].tolist() == [2, 4, 3, 1]  # stable
    assert meta["resorted"] is True and meta["size_inferred"] is False


# --------------------------------------------------------------------------------------------
# real recordings: committed cuts (always) and the full files (when shared/data is present)


def test_davis_cut_reads() -> None:
    events, meta = io.read_events(DATA / "davis346_road_cut.aedat4")
    assert events.dtype == EVENT_DTYPE
    assert len(events) == 2000 and int(events["p"].sum()) == 1042
    assert (meta["width"], meta["height"], meta["format"]) == (346, 260, "aedat4")
    assert events["t"][0] == 1_589_163_147_368_868  # the camera's own clock, not shifted
    assert np.all(np.diff(events["t"]) >= 0)


def test_evk4_cut_reads() -> None:
    events, meta = io.read_events(DATA / "imx636_cut_evt3.raw")
    assert events.dtype == EVENT_DTYPE
    assert len(events) == 5000 and int(events["p"].sum()) == 2597
    assert (meta["width"], meta["height"], meta["raw_format"]) == (1280, 720, "evt3")
    assert events["t"][0] == 11_200_224
    assert "serial_number 00050567" in meta["raw_header"]


def test_full_davis_recording() -> None:
    events, meta = io.read_events(shared_file("davis346_road.aedat4"))
    assert len(events) == 78_830
    assert int(events["p"].sum()) == 41_257 and int((events["p"] == 0).sum()) == 37_573
    assert (meta["width"], meta["height"]) == (346, 260)
    cut, _ = io.read_events(DATA / "davis346_road_cut.aedat4")
    assert np.array_equal(cut, events[: len(cut)])


def test_full_evk4_recording(tmp_path: Path) -> None:
    events, meta = io.read_events(shared_file("imx636_pointsource_evt3.raw"))
    assert len(events) == 1_218_618
    assert int(events["p"].sum()) == 553_295 and int((events["p"] == 0).sum()) == 665_323
    assert (meta["width"], meta["height"], meta["raw_format"]) == (1280, 720, "evt3")
    cut, _ = io.read_events(DATA / "imx636_cut_evt3.raw")
    assert np.array_equal(cut, events[: len(cut)])
    back, _ = roundtrip(tmp_path, ".raw", events, meta)  # our EVT 3.0 encoder, faery's decoder
    assert np.array_equal(back, events)


# --------------------------------------------------------------------------------------------
# atomic writes


def _boom(*args: Any, **kwargs: Any) -> None:
    raise RuntimeError("disk unplugged mid-write")


def _partial_copy(source: Any, target: Any, length: int = 0) -> None:
    target.write(source.read(100))
    raise RuntimeError("disk unplugged mid-write")


def _overflowing_faery_events(events: np.ndarray) -> np.ndarray:
    import faery

    out = np.zeros(len(events), faery.EVENTS_DTYPE)
    out["t"] = events["t"]
    out["x"] = 60_000  # faery stops with "x overflow" once its file is open
    return out


@pytest.mark.parametrize(
    "suffix,owner,target,replacement",
    [
        (".txt", text, "format_int_rows", _boom),
        (".h5", hdf5, "write_truth", _boom),
        (".npz", numpy_files.shutil, "copyfileobj", _partial_copy),
        (".raw", prophesee, "encode_evt3_words", _boom),
        (".dat", prophesee, "to_faery", _overflowing_faery_events),
        (".aedat4", aedat, "to_faery", _overflowing_faery_events),
    ],
)
def test_failed_write_leaves_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, suffix: str, owner: Any, target: str, replacement: Any
) -> None:
    final = tmp_path / f"out{suffix}"
    monkeypatch.setattr(owner, target, replacement)
    with pytest.raises(RuntimeError):
        io.write_events(final, make_events(100), {"truth": {"a": {"t_s": np.zeros(3)}}})
    assert not final.exists()
    assert list(tmp_path.iterdir()) == [], "temporary file left behind"


def test_failed_write_keeps_the_previous_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    final = tmp_path / "out.txt"
    io.write_events(final, make_events(10))
    before = final.read_bytes()
    monkeypatch.setattr(text, "format_int_rows", _boom)
    with pytest.raises(RuntimeError):
        io.write_events(final, make_events(20))
    assert final.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


# --------------------------------------------------------------------------------------------
# bad input


def test_unknown_suffix(tmp_path: Path) -> None:
    path = tmp_path / "events.mp4"
    with pytest.raises(ValueError, match=r"events\.mp4.*supported: \.h5, \.hdf5, \.npz"):
        io.write_events(path, make_events(3))
    path.write_bytes(b"x")
    with pytest.raises(ValueError, match=r"events\.mp4.*\.aedat4, \.raw, \.dat, \.es"):
        io.read_events(path)


def test_missing_file(tmp_path: Path) -> None:
    path = tmp_path / "nowhere.h5"
    with pytest.raises(FileNotFoundError, match="nowhere.h5"):
        io.read_events(path)
    with pytest.raises(FileNotFoundError, match="no_dir"):
        io.write_events(tmp_path / "no_dir" / "x.h5", make_events(3))


@pytest.mark.parametrize(
    "bad",
    [
        np.zeros(3, [("t", "f8"), ("x", "u2"), ("y", "u2"), ("p", "u1")]),
        np.zeros(3, [("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("on", "?")]),
        np.zeros((3, 4), np.int64),
    ],
)
def test_wrong_dtype(tmp_path: Path, bad: np.ndarray) -> None:
    with pytest.raises(TypeError, match=r"dtype"):
        io.write_events(tmp_path / "e.h5", bad)
    with pytest.raises(TypeError, match="structured array"):
        io.write_events(tmp_path / "e.h5", bad.tolist())  # type: ignore[arg-type]


def test_other_field_order_and_byte_layout_are_converted(tmp_path: Path) -> None:
    events = make_events(100)
    other = np.zeros(100, [("p", "?"), ("y", ">i4"), ("x", "<i8"), ("t", ">i8")])
    for name in ("t", "x", "y", "p"):
        other[name] = events[name]
    back, _ = roundtrip(tmp_path, ".npz", other)
    assert np.array_equal(back, events)


def test_out_of_range_fields(tmp_path: Path) -> None:
    other = np.zeros(2, [("t", "<i8"), ("x", "<i4"), ("y", "<u2"), ("p", "u1")])
    other["x"] = [1, 70_000]
    with pytest.raises(ValueError, match=r"events\['x'\]"):
        io.write_events(tmp_path / "e.h5", other)
    events = make_events(3)
    events["p"][1] = 2
    with pytest.raises(ValueError, match="ON"):
        io.write_events(tmp_path / "e.h5", events)


def test_unsorted_events(tmp_path: Path) -> None:
    events = make_events(10)
    events["t"][5] = events["t"][4] - 1
    with pytest.raises(ValueError, match=r"sorted by t.*t\[5\]"):
        io.write_events(tmp_path / "e.h5", events)
    assert list(tmp_path.iterdir()) == []


def test_events_outside_the_sensor(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="outside the 100x100 sensor"):
        io.write_events(tmp_path / "e.h5", make_events(50, width=346), {"width": 100, "height": 100})


def test_bad_meta(tmp_path: Path) -> None:
    events = make_events(5)
    with pytest.raises(TypeError, match="meta\\['notes'\\]"):
        io.write_events(tmp_path / "e.h5", events, {"notes": ["a", "b"]})
    with pytest.raises(TypeError, match="meta\\['width'\\]"):
        io.write_events(tmp_path / "e.h5", events, {"width": 346.0})
    with pytest.raises(TypeError, match="scenario"):
        io.write_events(tmp_path / "e.h5", events, {"scenario": 3})
    with pytest.raises(TypeError, match="truth"):
        io.write_events(tmp_path / "e.h5", events, {"truth": {"a": {"t_s": np.array(["x"])}}})
    with pytest.raises(ValueError, match="raw_format"):
        io.write_events(tmp_path / "e.raw", events, raw_format="evt4")


def test_format_limits(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="2048x2048"):
        io.write_events(tmp_path / "big.raw", make_events(5), {"width": 4096, "height": 3000})
    negative = make_events(5)
    negative["t"] -= 10_000_000
    with pytest.raises(ValueError, match="unsigned"):
        io.write_events(tmp_path / "neg.aedat4", negative)
    back, _ = roundtrip(tmp_path, ".h5", negative)  # signed times are fine in HDF5
    assert np.array_equal(back, negative)


@pytest.mark.parametrize("suffix", [".h5", ".npz", ".aedat4", ".raw", ".dat", ".es"])
def test_corrupt_binary_files(tmp_path: Path, suffix: str) -> None:
    path = tmp_path / f"junk{suffix}"
    path.write_bytes(bytes(range(256)) * 8)
    with pytest.raises(ValueError, match="junk"):
        io.read_events(path)


def test_corrupt_text(tmp_path: Path) -> None:
    path = tmp_path / "junk.txt"
    path.write_text("1 2 3 1\n2 3 banana 0\n")
    with pytest.raises(ValueError, match="junk.txt"):
        io.read_events(path)
    path.write_text("1 2 3\n")
    with pytest.raises(ValueError, match="4 columns"):
        io.read_events(path)
    path.write_text("1 2 3 7\n")
    with pytest.raises(ValueError, match="polarity"):
        io.read_events(path)
