"""NumPy zip (``.npz``): ``events`` (an ``EVENT_DTYPE`` array) plus scalar and truth entries, and
optionally ``label`` (uint8, one code of ``EVENT_LABELS`` per event).

Written in a stream: the chunks' records go to a temporary file beside the output; at close the
archive is assembled with zipfile (deflate, ZIP64 allowed), the ``events.npy`` header written
once the count is known and the records copied through the compressor block by block. Every
entry carries the fixed date 1980-01-01, so the same events and meta give the same bytes (NumPy's
``savez_compressed`` stamps the current time). Read in a stream too: each ``.npy`` member is
decompressed through zipfile and its records read ``chunk`` at a time after the header.
"""

from __future__ import annotations

import shutil
import zipfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np

from .. import _core
from ..sensor import EVENT_DTYPE
from ._common import (
    FIELDS,
    LABEL,
    EventSource,
    FileFormat,
    Meta,
    SpooledColumn,
    Truth,
    WriteSpec,
    decode_scenario,
    decoded,
    decoding,
    from_columns,
    remove_quietly,
    temporary_path,
)

_DATE = (1980, 1, 1, 0, 0, 0)  # the earliest date a zip entry can hold
_COPY_BLOCK = 1 << 20  # bytes copied at a time into the archive


def _open_entry(archive: zipfile.ZipFile, name: str) -> IO[bytes]:
    info = zipfile.ZipInfo(f"{name}.npy", date_time=_DATE)
    info.compress_type = zipfile.ZIP_DEFLATED
    return archive.open(info, "w", force_zip64=True)


class NpzEncoder:
    """Appends the records to a side file; assembles the ``.npz`` at close."""

    def __init__(self, tmp: Path, spec: WriteSpec) -> None:
        self._tmp = tmp
        self._records_path = temporary_path(tmp, "records")
        self._records = open(self._records_path, "wb")  # noqa: SIM115 - closed by close/abort
        self._labels_path = temporary_path(tmp, "labels") if spec.labels else None
        self._labels = None if self._labels_path is None else open(self._labels_path, "wb")  # noqa: SIM115
        self._count = 0

    def write(self, events: np.ndarray, labels: np.ndarray | None = None) -> None:
        self._records.write(np.ascontiguousarray(events).tobytes())
        if self._labels is not None and labels is not None:
            self._labels.write(np.ascontiguousarray(labels, dtype=np.uint8).tobytes())
        self._count += len(events)

    def _close_side_files(self) -> None:
        self._records.close()
        if self._labels is not None:
            self._labels.close()

    def _remove_side_files(self) -> None:
        remove_quietly(self._records_path, *([self._labels_path] if self._labels_path is not None else []))

    def close(self, spec: WriteSpec) -> None:
        self._close_side_files()
        scalars: dict[str, np.ndarray] = {
            "width": np.array(spec.width, np.int64),
            "height": np.array(spec.height, np.int64),
            "evstwin_version": np.array(str(_core.__version__)),
        }
        if spec.scenario is not None:
            scalars["scenario"] = np.array(spec.scenario)
            scalars["scenario_encoding"] = np.array("toml" if spec.scenario_is_toml else "str")
        for key, value in spec.extras.items():
            scalars[f"meta/{key}"] = np.array(value)
        spooled: dict[str, SpooledColumn] = {}
        for name, fields in spec.truth.items():
            for field, values in fields.items():
                if isinstance(values, SpooledColumn):
                    spooled[f"truth/{name}/{field}"] = values
                else:
                    scalars[f"truth/{name}/{field}"] = np.asarray(values)
        try:
            with zipfile.ZipFile(self._tmp, "w", zipfile.ZIP_DEFLATED, allowZip64=True) as archive:
                with _open_entry(archive, "events") as entry, open(self._records_path, "rb") as records:
                    header = {
                        "descr": np.lib.format.dtype_to_descr(EVENT_DTYPE),
                        "fortran_order": False,
                        "shape": (self._count,),
                    }
                    np.lib.format.write_array_header_1_0(entry, header)
                    shutil.copyfileobj(records, entry, _COPY_BLOCK)
                if self._labels_path is not None:
                    with _open_entry(archive, LABEL) as entry, open(self._labels_path, "rb") as labels:
                        np.lib.format.write_array_header_1_0(entry, {
                            "descr": np.lib.format.dtype_to_descr(np.dtype(np.uint8)),
                            "fortran_order": False,
                            "shape": (self._count,),
                        })
                        shutil.copyfileobj(labels, entry, _COPY_BLOCK)
                for key, array in scalars.items():
                    with _open_entry(archive, key) as entry:
                        np.lib.format.write_array(entry, array, allow_pickle=False)
                for key, column in spooled.items():  # streamed truth, copied in blocks
                    with _open_entry(archive, key) as entry, open(column.path, "rb") as raw:
                        np.lib.format.write_array_header_1_0(entry, {
                            "descr": np.lib.format.dtype_to_descr(column.dtype),
                            "fortran_order": False,
                            "shape": (column.length,),
                        })
                        shutil.copyfileobj(raw, entry, _COPY_BLOCK)
        finally:
            self._remove_side_files()

    def abort(self) -> None:
        self._close_side_files()
        self._remove_side_files()


# ---------------------------------------------------------------------------------------------
# reading


def _array_header(f: IO[bytes], key: str, path: Path) -> tuple[tuple[int, ...], np.dtype]:
    version = np.lib.format.read_magic(f)
    if version == (1, 0):
        shape, fortran, dtype = np.lib.format.read_array_header_1_0(f)
    else:
        shape, fortran, dtype = np.lib.format.read_array_header_2_0(f)
    if dtype.hasobject:
        raise ValueError(f"{str(path)!r}: entry {key!r} holds Python objects and is never unpickled")
    if fortran and len(shape) > 1:
        raise ValueError(f"{str(path)!r}: entry {key!r} is a Fortran-ordered array")
    return shape, dtype


def _read_records(f: IO[bytes], dtype: np.dtype, count: int, key: str, path: Path) -> np.ndarray:
    data = f.read(count * dtype.itemsize)
    if len(data) != count * dtype.itemsize:
        raise ValueError(f"{str(path)!r}: entry {key!r} is truncated")
    return np.frombuffer(data, dtype=dtype, count=count)


def _members(archive: zipfile.ZipFile) -> dict[str, str]:
    return {name.removesuffix(".npy"): name for name in archive.namelist()}


def _read_small(archive: zipfile.ZipFile, member: str, key: str, path: Path) -> np.ndarray:
    with archive.open(member) as f:
        try:
            return np.lib.format.read_array(f, allow_pickle=False)  # type: ignore[no-any-return]
        except ValueError as err:  # object arrays: never unpickled
            raise ValueError(f"{str(path)!r}: entry {key!r} cannot be read safely: {err}") from err


def _check_archive(path: Path) -> None:
    with open(path, "rb") as f:
        start = f.read(6)
    if start == b"\x93NUMPY":
        raise ValueError(f"{str(path)!r}: holds a single .npy array, not an .npz archive")
    if not zipfile.is_zipfile(path):
        raise ValueError(f"{str(path)!r}: not a readable .npz file (not a zip archive)")


def _read_meta(archive: zipfile.ZipFile, path: Path) -> Meta:
    meta: Meta = {}
    truth: Truth = {}
    for key, member in _members(archive).items():
        if key in FIELDS or key in ("events", LABEL):
            continue
        value = _read_small(archive, member, key, path)
        if key.startswith("truth/"):
            parts = key.split("/")
            if len(parts) != 3:
                raise ValueError(f"{str(path)!r}: malformed truth key {key!r}")
            truth.setdefault(parts[1], {})[parts[2]] = value
        elif value.ndim == 0:
            meta[key.removeprefix("meta/")] = value.item()
    decode_scenario(meta)
    if truth:
        meta["truth"] = truth
    return meta


def open_source(path: Path, chunk: int) -> EventSource:
    _check_archive(path)
    with decoding(path, "zipfile"), zipfile.ZipFile(path) as archive:
        members = _members(archive)
        if "events" not in members and not set(FIELDS) <= set(members):
            raise ValueError(f"{str(path)!r}: no 'events' array (nor 't', 'x', 'y', 'p' arrays)")
        meta = _read_meta(archive, path)
        meta["has_labels"] = LABEL in members
    meta.setdefault("width", None)
    meta.setdefault("height", None)
    return EventSource(meta, decoded(path, "zipfile", _packets(path, chunk)))


class _LabelColumn:
    """The ``label`` member read alongside the events, ``count`` codes at a time (or nothing
    when the archive has none)."""

    def __init__(self, archive: zipfile.ZipFile, members: dict[str, str], path: Path) -> None:
        self._path = path
        self._file = archive.open(members[LABEL]) if LABEL in members else None
        if self._file is not None:
            self.shape, self._dtype = _array_header(self._file, LABEL, path)
            if len(self.shape) != 1 or self._dtype.kind not in "biu":
                self._file.close()
                raise ValueError(
                    f"{str(path)!r}: 'label' has dtype {self._dtype} and shape {self.shape}, "
                    "expected a 1-D integer array (one code per event)"
                )

    def check(self, n: int) -> None:
        if self._file is not None and self.shape != (n,):
            raise ValueError(f"{str(self._path)!r}: 'label' has {self.shape[0]} codes for {n} events")

    def read(self, count: int) -> np.ndarray | None:
        if self._file is None:
            return None
        return _read_records(self._file, self._dtype, count, LABEL, self._path)

    def close(self) -> None:
        if self._file is not None:
            self._file.close()


def _packets(path: Path, chunk: int) -> Iterator[np.ndarray]:
    with zipfile.ZipFile(path) as archive:
        members = _members(archive)
        labels = _LabelColumn(archive, members, path)
        try:
            if "events" in members:
                with archive.open(members["events"]) as f:
                    shape, dtype = _array_header(f, "events", path)
                    if dtype.names is None or set(dtype.names) != set(FIELDS) or len(shape) != 1:
                        raise ValueError(
                            f"{str(path)!r}: 'events' has dtype {dtype} and shape {shape}, "
                            f"expected a 1-D array with fields {FIELDS}"
                        )
                    labels.check(shape[0])
                    for start in range(0, shape[0], chunk):
                        count = min(chunk, shape[0] - start)
                        raw = _read_records(f, dtype, count, "events", path)
                        yield from_columns([raw[name] for name in FIELDS], where=path, label=labels.read(count))
                return
            files = [archive.open(members[name]) for name in FIELDS]
            try:
                headers = [_array_header(f, name, path) for f, name in zip(files, FIELDS)]
                n = headers[0][0][0] if len(headers[0][0]) == 1 else -1
                if any(shape != (n,) for shape, _ in headers):
                    raise ValueError(f"{str(path)!r}: 't', 'x', 'y', 'p' have shapes {[h[0] for h in headers]}")
                labels.check(n)
                for start in range(0, n, chunk):
                    count = min(chunk, n - start)
                    columns: list[Any] = [
                        _read_records(f, dtype, count, name, path)
                        for f, (_, dtype), name in zip(files, headers, FIELDS)
                    ]
                    yield from_columns(columns, where=path, label=labels.read(count))
            finally:
                for f in files:
                    f.close()
        finally:
            labels.close()


FORMAT = FileFormat("npz", open_source, NpzEncoder, labels=True, title="NPZ")
