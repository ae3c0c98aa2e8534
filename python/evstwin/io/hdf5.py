"""HDF5 (``.h5``, ``.hdf5``): the evstwin layout, written and read in chunks with h5py.

Layout: ``/events/{t,x,y,p}`` (resizable, chunked, gzip + shuffle), optionally
``/events/label`` (uint8, one code per event, chunked alike; its ``codes`` attribute names
them: ``EVENT_LABELS``), root attributes (``layout``,
``width``, ``height``, ``evstwin_version``, ``scenario`` + ``scenario_encoding``, extra scalars),
ground truth under ``/truth/<name>/<field>``, and a time index ``/ms_to_idx`` as in the DSEC
files: entry ``m`` is the index of the first event with ``t >= t_origin_us + 1000 * m``, where
``t_origin_us`` (an attribute of the dataset) is 0 when the first event is in [0, 60 s) and the
first event's time floored to the millisecond otherwise (Unix-time recordings). Without the
attribute (DSEC files) the origin is 0. The index has ``floor((t_last - t_origin_us) / 1000) + 1``
entries.

Metavision's HDF5 event files (Prophesee's ``.hdf5``; layout: docs.prophesee.ai, "HDF5 Event
File Format", and openeb's ``hdf5_event_file_writer.cpp``) are read too: ``/CD/events`` is a
compound dataset (``x`` uint16, ``y`` uint16, ``p`` int16, ``t`` int64 [us]) in chunks of 16384
events, ``/CD/indexes`` (``id`` uint64, ``ts`` int64, one every 2 ms, its ``offset``
attribute the first time's negative), ``/EXT_TRIGGER/events`` and ``/EXT_TRIGGER/indexes``
(trigger events, not read), and string attributes on the root (``version`` "1.0", the
camera's ``geometry`` "WxH", ``format``, ``generation``, ``serial_number``, ...). Metavision
compresses ``/CD/events`` with Prophesee's ECF codec (HDF5 filter 0x8ECF), which libhdf5 loads
as a plugin from ``HDF5_PLUGIN_PATH`` where Prophesee's ``hdf5_ecf`` is installed (no package
on PyPI ships it); without it reading stops with one line saying so. Files written with gzip
(h5py, other tools) or no filter need nothing more. No maintained Python writer of the layout
exists (the Metavision SDK writes it from C++ only), so evstwin writes its own layout.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from .. import _core
from ..sensor import EVENT_DTYPE
from ._common import (
    FIELDS,
    LABEL,
    LAYOUT,
    EventSource,
    FileFormat,
    Meta,
    SpooledColumn,
    Truth,
    WriteSpec,
    check_header_size,
    decode_scenario,
    decoded,
    decoding,
    from_columns,
    label_header,
    one_line,
)

H5_CHUNK = 1 << 16  # events per HDF5 chunk (512 KiB of t)
MS_INDEX = "ms_to_idx"
_MS_CHUNK = 1 << 12  # index entries per HDF5 chunk
_MS_BLOCK = 1 << 20  # index entries computed at a time (a long gap stays O(block) in memory)
_ORIGIN_FREE_US = 60_000_000  # below this the index counts milliseconds from t = 0


def index_origin(first_t_us: int) -> int:
    """``t_origin_us`` of the millisecond index for a recording whose first event is at ``first_t_us``."""
    if 0 <= first_t_us < _ORIGIN_FREE_US:
        return 0
    return (first_t_us // 1000) * 1000


class Hdf5Encoder:
    """Appends each chunk to resizable datasets and extends the millisecond index; the scenario,
    extra scalars and ground truth are written at close."""

    def __init__(self, tmp: Path, spec: WriteSpec) -> None:
        import h5py

        self._file = h5py.File(tmp, "w", track_order=True)
        f = self._file
        f.attrs["layout"] = LAYOUT
        f.attrs["width"] = spec.width
        f.attrs["height"] = spec.height
        f.attrs["evstwin_version"] = str(_core.__version__)
        group = f.create_group("events")
        group.attrs["t_unit"] = "us"
        group.attrs["p_convention"] = "1 = ON, 0 = OFF"
        self._columns = [
            group.create_dataset(
                name,
                shape=(0,),
                maxshape=(None,),
                dtype=EVENT_DTYPE[name] if name != LABEL else np.uint8,
                chunks=(H5_CHUNK,),
                compression="gzip",
                compression_opts=4,
                shuffle=True,
            )
            for name in FIELDS + ((LABEL,) if spec.labels else ())
        ]
        if spec.labels:
            self._columns[-1].attrs["codes"] = label_header()
        self._index = f.create_dataset(
            MS_INDEX,
            shape=(0,),
            maxshape=(None,),
            dtype=np.uint64,
            chunks=(_MS_CHUNK,),
            compression="gzip",
            compression_opts=4,
            shuffle=True,
        )
        self._count = 0
        self._origin: int | None = None
        self._next_ms = 0

    def write(self, events: np.ndarray, labels: np.ndarray | None = None) -> None:
        start, end = self._count, self._count + len(events)
        for name, dataset in zip(FIELDS, self._columns):
            dataset.resize((end,))
            dataset[start:end] = events[name]
        if labels is not None:  # the writer gives them exactly when the file has the column
            self._columns[-1].resize((end,))
            self._columns[-1][start:end] = labels
        self._extend_index(events["t"], start)
        self._count = end

    def _extend_index(self, t: np.ndarray, offset: int) -> None:
        if self._origin is None:
            self._origin = index_origin(int(t[0]))
        last_ms = (int(t[-1]) - self._origin) // 1000
        for first in range(self._next_ms, last_ms + 1, _MS_BLOCK):
            ms = np.arange(first, min(last_ms + 1, first + _MS_BLOCK), dtype=np.int64)
            entries = offset + np.searchsorted(t, self._origin + 1000 * ms, side="left")
            size = len(self._index)
            self._index.resize((size + len(ms),))
            self._index[size:] = entries.astype(np.uint64)
        self._next_ms = max(self._next_ms, last_ms + 1)

    def close(self, spec: WriteSpec) -> None:
        f = self._file
        if spec.scenario is not None:
            f.attrs["scenario"] = spec.scenario
            f.attrs["scenario_encoding"] = "toml" if spec.scenario_is_toml else "str"
        for key, value in spec.extras.items():
            f.attrs[key] = value
        self._index.attrs["t_origin_us"] = 0 if self._origin is None else self._origin
        write_truth(f, spec.truth)
        f.close()

    def abort(self) -> None:
        self._file.close()


def write_truth(f: Any, truth: Truth) -> None:
    if not truth:
        return
    root = f.create_group("truth", track_order=True)
    for name, fields in truth.items():
        group = root.create_group(name, track_order=True)
        for field, values in fields.items():
            opts = {"compression": "gzip", "compression_opts": 4, "shuffle": True}
            if isinstance(values, SpooledColumn):  # streamed: copied in blocks
                dataset = group.create_dataset(
                    field, shape=(values.length,), dtype=values.dtype,
                    chunks=(max(1, min(values.length, H5_CHUNK)),), **opts,
                )
                start = 0
                for block in values.blocks():
                    dataset[start : start + len(block)] = block
                    start += len(block)
                continue
            data = np.asarray(values)
            chunks: bool | tuple[int, ...] = (
                (min(data.size, H5_CHUNK),) if data.ndim == 1 and data.size else True
            )
            group.create_dataset(field, data=data, chunks=chunks, **opts)


# ---------------------------------------------------------------------------------------------
# reading


def _attr_value(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.generic):
        return value.item()
    return value


def _event_datasets(f: Any, path: Path) -> list[Any]:
    import h5py

    group = f.get("events")
    if not isinstance(group, h5py.Group):
        raise ValueError(  # noqa: TRY004 - a malformed file, not a wrong argument
            f"{str(path)!r}: no /events group (expected datasets /events/t, x, y, p, or Metavision's "
            f"{METAVISION_EVENTS})"
        )
    missing = [name for name in FIELDS if not isinstance(group.get(name), h5py.Dataset)]
    if missing:
        raise ValueError(f"{str(path)!r}: missing datasets {['/events/' + m for m in missing]}")
    columns = [group[name] for name in FIELDS]
    lengths = {c.shape for c in columns}
    if len(lengths) != 1 or len(columns[0].shape) != 1:
        raise ValueError(f"{str(path)!r}: /events/t, x, y, p have shapes {[c.shape for c in columns]}")
    return columns


def _label_dataset(f: Any, path: Path, n: int) -> Any:
    """``/events/label``, or None when the file has no label column."""
    import h5py

    labels = f["events"].get(LABEL)
    if labels is None:
        return None
    if not isinstance(labels, h5py.Dataset) or labels.shape != (n,) or labels.dtype.kind not in "biu":
        raise ValueError(
            f"{str(path)!r}: /events/label must be a 1-D integer dataset of {n} codes like /events/t; "
            f"got {getattr(labels, 'shape', type(labels).__name__)}"
        )
    return labels


def _read_meta(f: Any) -> Meta:
    import h5py

    meta: Meta = {key: _attr_value(value) for key, value in f.attrs.items()}
    decode_scenario(meta)
    truth = f.get("truth")
    if isinstance(truth, h5py.Group):
        meta["truth"] = {
            name: {field: ds[()] for field, ds in obj.items() if isinstance(ds, h5py.Dataset)}
            for name, obj in truth.items()
            if isinstance(obj, h5py.Group)
        }
    return meta


# ---------------------------------------------------------------------------------------------
# Metavision's layout

METAVISION_EVENTS = "/CD/events"
METAVISION_FIELDS = ("x", "y", "p", "t")
ECF_FILTER = 0x8ECF
"""HDF5 filter id of Prophesee's ECF codec (self-assigned; docs.prophesee.ai)."""
ECF_INSTALL = (
    "install Prophesee's HDF5 ECF plugin (hdf5_ecf: it comes with the Metavision SDK and OpenEB, or "
    "build it from github.com/prophesee-ai/hdf5_ecf) and set HDF5_PLUGIN_PATH to the folder that holds it"
)
_GEOMETRY = re.compile(r"^\s*(\d+)\s*x\s*(\d+)\s*$", re.IGNORECASE)


def _metavision_events(f: Any, path: Path) -> Any:
    """``/CD/events`` of a Metavision file, checked (fields, shape, filters), or None when the
    file has no ``/CD/events``."""
    import h5py

    ds = f.get(METAVISION_EVENTS)
    if ds is None:
        return None
    names = ds.dtype.names or () if isinstance(ds, h5py.Dataset) else ()
    missing = [name for name in METAVISION_FIELDS if name not in names]
    if not isinstance(ds, h5py.Dataset) or missing or len(ds.shape) != 1:
        raise ValueError(
            f"{str(path)!r}: {METAVISION_EVENTS} must be a 1-D compound dataset with fields x, y, p, t "
            f"(Metavision's layout); got {getattr(ds, 'dtype', type(ds).__name__)} of shape {getattr(ds, 'shape', None)}"
        )
    _check_filters(ds, path)
    return ds


def _check_filters(ds: Any, path: Path) -> None:
    """One line naming what to install when a filter of ``ds`` is not available here."""
    import h5py

    plist = ds.id.get_create_plist()
    for i in range(plist.get_nfilters()):
        code, _flags, _values, name = plist.get_filter(i)
        if h5py.h5z.filter_avail(code):
            continue
        from .._extras import MissingExtraError

        if code == ECF_FILTER:
            raise MissingExtraError(
                f"{str(path)!r}: {ds.name} is compressed with Prophesee's ECF codec (HDF5 filter 0x8ECF), "
                f"which this HDF5 library cannot load: {ECF_INSTALL}"
            )
        label = name.decode("utf-8", "replace") if isinstance(name, bytes) else str(name)
        raise MissingExtraError(
            f"{str(path)!r}: {ds.name} is compressed with HDF5 filter {code} ({label or 'unnamed'}), which this "
            "HDF5 library cannot load: pip install hdf5plugin and import it first, or install that filter's "
            "plugin and set HDF5_PLUGIN_PATH"
        )


def _metavision_meta(f: Any, path: Path) -> Meta:
    """The root's string attributes, the sensor size from ``geometry`` (None without one)."""
    meta: Meta = {key: _attr_value(value) for key, value in f.attrs.items()}
    if "format" in meta:  # the camera's encoding (EVT3, ...): meta["format"] is the file's
        meta["metavision_format"] = meta.pop("format")
    meta["hdf5_layout"] = "metavision"
    meta["width"], meta["height"], meta["size_source"] = None, None, None
    geometry = meta.get("geometry")
    if geometry is not None:
        match = _GEOMETRY.match(str(geometry))
        if match is None:
            raise ValueError(f"{str(path)!r}: the root attribute geometry = {one_line(repr(geometry), 80)} "
                             "is not 'WIDTHxHEIGHT'")
        meta["width"], meta["height"] = check_header_size(path, int(match[1]), int(match[2]))
        meta["size_source"] = "header"
    return meta


def _metavision_columns(ds: Any, start: int, stop: int, path: Path) -> np.ndarray:
    block = ds[start:stop]
    return from_columns([block["t"], block["x"], block["y"], block["p"]], where=path)


def open_source(path: Path, chunk: int) -> EventSource:
    import h5py

    with decoding(path, "h5py"), h5py.File(path, "r") as f:
        if "events" not in f and _metavision_events(f, path) is not None:
            return _open_metavision(path, chunk, _metavision_meta(f, path))
        columns = _event_datasets(f, path)
        has_labels = _label_dataset(f, path, columns[0].shape[0]) is not None
        meta = _read_meta(f)
    meta.setdefault("width", None)
    meta.setdefault("height", None)
    meta["has_labels"] = has_labels

    def packets() -> Iterator[np.ndarray]:
        with h5py.File(path, "r") as f:
            columns = _event_datasets(f, path)
            n = columns[0].shape[0]
            labels = _label_dataset(f, path, n)
            for start in range(0, n, chunk):
                label = None if labels is None else labels[start : start + chunk]
                yield from_columns([c[start : start + chunk] for c in columns], where=path, label=label)

    return EventSource(meta, decoded(path, "h5py", packets()))


def _open_metavision(path: Path, chunk: int, meta: Meta) -> EventSource:
    import h5py

    meta["has_labels"] = False

    def packets() -> Iterator[np.ndarray]:
        with h5py.File(path, "r") as f:
            ds = _metavision_events(f, path)
            n = ds.shape[0]
            for start in range(0, n, chunk):
                yield _metavision_columns(ds, start, start + chunk, path)

    return EventSource(meta, decoded(path, "h5py", packets()))


def read_window(path: Path, t_start_us: int, t_end_us: int) -> np.ndarray:
    """Events with ``t_start_us <= t < t_end_us``: bounds from ``/ms_to_idx`` (then at most one
    millisecond of ``t`` read to refine each), or a bisection on ``/events/t`` without it."""
    import h5py

    with decoding(path, "h5py"), h5py.File(path, "r") as f:
        if "events" not in f:
            ds = _metavision_events(f, path)
            if ds is not None:  # bisection on t, one event read at a time
                t_of = ds.fields("t")
                lo, hi = _bisect(t_of, ds.shape[0], t_start_us), _bisect(t_of, ds.shape[0], t_end_us)
                return _metavision_columns(ds, lo, max(lo, hi), path)
        columns = _event_datasets(f, path)
        t = columns[0]
        n = t.shape[0]
        index = f.get(MS_INDEX)
        if isinstance(index, h5py.Dataset) and len(index.shape) == 1:
            origin = int(index.attrs.get("t_origin_us", 0))
            lo = _first_at_or_after(t, index, origin, n, t_start_us)
            hi = _first_at_or_after(t, index, origin, n, t_end_us)
        else:
            lo, hi = _bisect(t, n, t_start_us), _bisect(t, n, t_end_us)
        hi = max(lo, hi)
        return from_columns([c[lo:hi] for c in columns], where=path)


def _first_at_or_after(t: Any, index: Any, origin: int, n: int, t_us: int) -> int:
    m = (t_us - origin) // 1000
    if m < 0:
        return 0
    if m >= index.shape[0]:
        return n
    lo = int(index[m])
    hi = int(index[m + 1]) if m + 1 < index.shape[0] else n
    return lo + int(np.searchsorted(t[lo:hi], t_us, side="left"))


def _bisect(t: Any, n: int, t_us: int) -> int:
    """Index of the first event with ``t >= t_us`` by bisection (O(log n) single reads)."""
    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) // 2
        if int(t[mid]) < t_us:
            lo = mid + 1
        else:
            hi = mid
    return lo


FORMAT = FileFormat("hdf5", open_source, Hdf5Encoder, labels=True, title="HDF5")
