"""Metavision's HDF5 event files (issue 31, item 12): ``/CD/events`` read through h5py.

The files are made here with h5py in the layout the Metavision SDK writes (Prophesee's "HDF5
Event File Format" page, docs.prophesee.ai; openeb's sdk/modules/stream/cpp/src/
hdf5_event_file_writer.cpp): ``/CD/events`` a compound of x (uint16, offset 0), y (uint16, 2),
p (int16, 4), t (int64, 8), 16 bytes an event, in chunks of 16384; ``/CD/indexes`` (id uint64,
ts int64; one every 2 ms; attribute ``offset`` = minus the first time, as a string);
``/EXT_TRIGGER/events`` (p int16, t int64, id int16; 24 bytes) and ``/EXT_TRIGGER/indexes``;
variable-length string attributes on the root. Metavision compresses ``/CD/events`` with its
ECF codec; the gzip variant (what h5py and other tools write) needs no plugin.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from evstwin.cli import main
from evstwin.io import read_events, read_time_window

CD_DTYPE = np.dtype({"names": ["x", "y", "p", "t"], "formats": ["<u2", "<u2", "<i2", "<i8"],
                     "offsets": [0, 2, 4, 8], "itemsize": 16})
INDEX_DTYPE = np.dtype({"names": ["id", "ts"], "formats": ["<u8", "<i8"], "offsets": [0, 8], "itemsize": 16})
TRIGGER_DTYPE = np.dtype({"names": ["p", "t", "id"], "formats": ["<i2", "<i8", "<i2"], "offsets": [0, 8, 16],
                          "itemsize": 24})
CHUNK = 16384
ROOT = {"version": "1.0", "geometry": "1280x720", "format": "EVT3", "generation": "4.2",
        "camera_integrator_name": "Prophesee", "plugin_integrator_name": "Prophesee", "sensor_name": "IMX636",
        "serial_number": "00ca0009", "system_ID": "49"}


def cd_events(n: int = 20_000, seed: int = 3, width: int = 1280, height: int = 720) -> np.ndarray:
    rng = np.random.default_rng(seed)
    ev = np.zeros(n, CD_DTYPE)
    ev["x"] = rng.integers(0, width, n)
    ev["y"] = rng.integers(0, height, n)
    ev["p"] = rng.integers(0, 2, n)
    ev["t"] = 1_000_000 + np.sort(rng.integers(0, 80_000, n))  # 80 ms, starting at 1 s
    return ev


def write_metavision(path: Path, events: np.ndarray, *, compression: str | None = "gzip",
                     root: dict[str, str] = ROOT) -> None:
    """A Metavision-layout file with ``events`` as its CD events."""
    string = h5py.string_dtype()
    with h5py.File(path, "w") as f:
        for key, value in root.items():
            f.attrs.create(key, value, dtype=string)
        cd = f.create_group("CD")
        cd.create_dataset("events", data=events, maxshape=(None,), chunks=(CHUNK,), compression=compression)
        t0 = int(events["t"][0])
        ts = np.arange(0, int(events["t"][-1]) - t0 + 2000, 2000)
        index = np.zeros(len(ts), INDEX_DTYPE)
        index["ts"] = ts
        index["id"] = np.searchsorted(events["t"] - t0, ts)
        cd.create_dataset("indexes", data=index, maxshape=(None,), chunks=(CHUNK,))
        cd["indexes"].attrs.create("offset", str(-t0), dtype=string)
        trigger = f.create_group("EXT_TRIGGER")
        trigger.create_dataset("events", shape=(0,), dtype=TRIGGER_DTYPE, maxshape=(None,), chunks=(CHUNK,))
        trigger.create_dataset("indexes", shape=(0,), dtype=INDEX_DTYPE, maxshape=(None,), chunks=(CHUNK,))


def test_a_gzip_metavision_file_reads_as_its_cd_events(tmp_path: Path) -> None:
    path = tmp_path / "rec.hdf5"
    truth = cd_events()
    write_metavision(path, truth)
    events, meta = read_events(path)
    assert len(events) == len(truth)
    for name in ("t", "x", "y", "p"):
        np.testing.assert_array_equal(events[name], truth[name])
    assert (meta["width"], meta["height"], meta["size_source"]) == (1280, 720, "header")
    assert meta["format"] == "hdf5" and meta["metavision_format"] == "EVT3" and meta["sensor_name"] == "IMX636"
    # a time window: bisection on /CD/events' t
    window = read_time_window(path, 1_010_000, 1_020_000)
    expect = truth[(truth["t"] >= 1_010_000) & (truth["t"] < 1_020_000)]
    assert len(window) == len(expect) > 0
    np.testing.assert_array_equal(window["x"], expect["x"])


def test_info_and_show_accept_a_metavision_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "rec.hdf5"
    truth = cd_events(5000, width=64, height=48)
    write_metavision(path, truth, root={k: v for k, v in ROOT.items() if k != "geometry"})  # size from the events
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    on = int(np.count_nonzero(truth["p"]))
    assert f"events        5000 (ON {on}, OFF {5000 - on})" in out
    assert "sensor        64 x 48 px (3072 pixels) (from the events' extent)" in out
    assert main(["show", str(path), "--out", str(tmp_path / "s")]) == 0
    assert {p.name for p in (tmp_path / "s").iterdir()} == {"event_rate.png", "frames.png", "histograms.png", "xyt.png"}


def test_an_ecf_compressed_file_without_the_codec_names_what_to_install(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    if h5py.h5z.filter_avail(0x8ECF):
        pytest.skip("Prophesee's ECF plugin is installed here")
    path = tmp_path / "ecf.hdf5"
    # As the Metavision SDK writes it: the ECF filter in the dataset's pipeline and chunks
    # written already encoded (H5Dwrite_chunk, filter mask 0).
    with h5py.File(path, "w") as f:
        for key, value in ROOT.items():
            f.attrs.create(key, value, dtype=h5py.string_dtype())
        dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
        dcpl.set_chunk((CHUNK,))
        dcpl.set_filter(0x8ECF, h5py.h5z.FLAG_OPTIONAL, ())
        space = h5py.h5s.create_simple((0,), (h5py.h5s.UNLIMITED,))
        events = h5py.Dataset(h5py.h5d.create(f.create_group("CD").id, b"events", h5py.h5t.py_create(CD_DTYPE),
                                              space, dcpl=dcpl))
        events.resize((100,))
        events.id.write_direct_chunk((0,), b"\x00ECF-encoded bytes", filter_mask=0)
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err
    assert err.startswith(f"evstwin: error: '{path}': /CD/events is compressed with Prophesee's ECF codec "
                          "(HDF5 filter 0x8ECF), which this HDF5 library cannot load: install Prophesee's HDF5 ECF "
                          "plugin (hdf5_ecf")
    assert "HDF5_PLUGIN_PATH" in err


def test_a_malformed_metavision_file_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "bad.hdf5"
    with h5py.File(path, "w") as f:
        f.create_group("CD").create_dataset("events", data=np.zeros(4, [("x", "<u2"), ("t", "<i8")]))
    assert main(["info", str(path)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert "/CD/events must be a 1-D compound dataset with fields x, y, p, t" in err
    bad_geometry = tmp_path / "geometry.hdf5"
    write_metavision(bad_geometry, cd_events(10), root=dict(ROOT, geometry="wide"))
    assert main(["info", str(bad_geometry)]) == 2
    assert "the root attribute geometry = 'wide' is not 'WIDTHxHEIGHT'" in capsys.readouterr().err
