"""Text: ``.txt`` (space separated) and ``.csv`` (comma separated), one ``t x y p`` line per event.

Written by appending lines (a header ``# evstwin <version> width=W height=H`` and ``# t x y p``
first). With labels, each line has a fifth column, ``label`` (a code of ``EVENT_LABELS``), and
the header says so: ``# t x y p label`` and a line naming the codes. A file is read as labelled
when its first data line has five columns (evstwin's, and the ``t x y p label`` text files of
denoising data sets). Read in blocks of about ``chunk`` lines (whole lines, cut at the last newline): ``#`` lines are comments (the first ``width=``/``height=``
in the comments before the data gives the size), one leading row of names is skipped. ``t`` is
integer microseconds; a file whose first data lines have decimals in ``t`` is read as seconds
(the convention of the UZH/RPG event-camera datasets) and rounded to microseconds. Polarity 0/1
or -1/1 (OFF/ON). Without a size in the header the size is known only after the whole file has
been read (max + 1).
"""

from __future__ import annotations

import io
import itertools
import re
import warnings
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from .. import _core
from ._common import (
    FIELDS,
    LABEL,
    EventSource,
    FileFormat,
    Meta,
    WriteSpec,
    decoded,
    from_columns,
    label_header,
)

_HEADER_SIZE = re.compile(r"\bwidth\s*=\s*(-?\d+).*?\bheight\s*=\s*(-?\d+)")
_HEADER_VERSION = re.compile(r"^#\s*evstwin\s+(\S+)")
_NAMES_ROW = re.compile(r"^[\s,]*[A-Za-z_]")
_TXT_BLOCK = 1 << 20  # events formatted per block when writing text
_BYTES_PER_LINE = 32  # bytes read per event asked for: blocks of about `chunk` lines


class TextEncoder:
    """Appends formatted lines; the header is written at open."""

    def __init__(self, tmp: Path, spec: WriteSpec, sep: str) -> None:
        self._sep = sep
        self._file: BinaryIO = open(tmp, "wb")  # noqa: SIM115 - closed by close/abort
        names = FIELDS + ((LABEL,) if spec.labels else ())
        header = f"# evstwin {_core.__version__} width={spec.width} height={spec.height}\n# {sep.join(names)}\n"
        if spec.labels:
            header += f"# label: {label_header()}\n"
        self._file.write(header.encode("ascii"))

    def write(self, events: np.ndarray, labels: np.ndarray | None = None) -> None:
        for start in range(0, len(events), _TXT_BLOCK):
            block = events[start : start + _TXT_BLOCK]
            columns = [block[name] for name in FIELDS]
            if labels is not None:
                columns.append(labels[start : start + _TXT_BLOCK])
            self._file.write(format_int_rows(columns, self._sep))

    def close(self, spec: WriteSpec) -> None:
        self._file.close()

    def abort(self) -> None:
        self._file.close()


def format_int_rows(columns: Sequence[np.ndarray], sep: str) -> bytes:
    """Rows of decimal integers, ``sep`` between columns and ``\\n`` after each row.

    Vectorised (about 4x faster than ``np.savetxt``): each column becomes a fixed-width block
    of digit characters whose leading zeros are then masked out.
    """
    n = len(columns[0])
    if n == 0:
        return b""
    blocks: list[np.ndarray] = []
    keep: list[np.ndarray] = []
    ten = np.uint64(10)
    for index, column in enumerate(columns):
        values = np.asarray(column)
        if values.dtype.kind == "i":
            signed = values.astype(np.int64)
            negative = signed < 0
            magnitude = signed.view(np.uint64).copy()
            magnitude[negative] = ~magnitude[negative] + np.uint64(1)  # |v| without overflow
            if negative.any():
                blocks.append(np.full((n, 1), ord("-"), np.uint8))
                keep.append(negative[:, None])
        else:
            magnitude = values.astype(np.uint64)
        width = len(str(int(magnitude.max())))
        digits = np.empty((n, width), np.uint8)
        significant = np.empty((n, width), bool)
        rest = magnitude.copy()
        for j in range(width - 1, -1, -1):
            digits[:, j] = rest % ten
            rest //= ten
            significant[:, j] = magnitude >= np.uint64(10 ** (width - 1 - j))
        significant[:, width - 1] = True
        digits += ord("0")
        blocks.append(digits)
        keep.append(significant)
        end = "\n" if index == len(columns) - 1 else sep
        blocks.append(np.full((n, 1), ord(end), np.uint8))
        keep.append(np.ones((n, 1), bool))
    return np.concatenate(blocks, axis=1)[np.concatenate(keep, axis=1)].tobytes()


# ---------------------------------------------------------------------------------------------
# reading


def _read_header(path: Path, delimiter: str | None) -> tuple[Meta, int]:
    """Size and version from the leading comments, the number of lines before the data
    (comments, blank lines and a row of names), and ``has_labels``: whether the first data line
    has five columns."""
    meta: Meta = {"width": None, "height": None, "has_labels": False}
    skip = 0
    first: list[bytes] = []  # the first data line, unless it is a row of names
    with open(path, "rb") as f:
        for index, raw in enumerate(f):
            line = raw.decode("utf-8", "replace").strip()
            if not line:
                continue
            if line.startswith("#"):
                size = _HEADER_SIZE.search(line)
                if size and meta["width"] is None:
                    meta["width"], meta["height"] = int(size.group(1)), int(size.group(2))
                version = _HEADER_VERSION.match(line)
                if version:
                    meta["evstwin_version"] = version.group(1)
                continue
            names = _NAMES_ROW.match(line) is not None
            skip = index + 1 if names else index
            first = [] if names else [raw]
            break
        for raw in itertools.chain(first, f):  # the first line of numbers tells the columns
            line = raw.decode("utf-8", "replace").split("#", 1)[0].strip()
            if line:
                meta["has_labels"] = len(line.split(delimiter)) == len(FIELDS) + 1
                break
    return meta, skip


def _load(data: bytes, delimiter: str | None, dtype: Any) -> np.ndarray:
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*[Ee]mpty input file.*")
        warnings.filterwarnings("ignore", message=".*input contained no data.*")
        return np.loadtxt(
            io.StringIO(data.decode("utf-8", "replace")),
            dtype=dtype,
            comments="#",
            delimiter=delimiter,
            ndmin=2,
        )


def _parse(
    lines: bytes, delimiter: str | None, unit: str | None, first_line: int, path: Path
) -> tuple[np.ndarray, str]:
    """The lines' table as int64 [t in us] and the unit of ``t`` (decided on the first block)."""
    where = f"{str(path)!r} (from line {first_line + 1})"
    if unit != "s":
        try:
            table = _load(lines, delimiter, np.int64)
        except ValueError as int_error:
            if unit == "us":
                raise ValueError(f"{where}: not a table of integer t x y p numbers: {int_error}") from None
            try:
                table = _load(lines, delimiter, np.float64)
            except ValueError:
                raise ValueError(f"{where}: not a table of t x y p numbers: {int_error}") from None
            return _seconds_to_us(table, where), "s"
        return table, "us"
    try:
        table = _load(lines, delimiter, np.float64)
    except ValueError as err:
        raise ValueError(f"{where}: not a table of t x y p numbers: {err}") from None
    return _seconds_to_us(table, where), "s"


def _seconds_to_us(table: np.ndarray, where: str) -> np.ndarray:
    if table.size == 0:
        return table.astype(np.int64)
    if table.shape[1] not in (4, 5):
        raise ValueError(f"{where}: expected 4 columns (t x y p) or 5 (t x y p label); found {table.shape[1]}")
    if not np.all(np.isfinite(table)):
        raise ValueError(f"{where}: not a table of finite t x y p numbers")
    if np.any(table[:, 1:] != np.round(table[:, 1:])):
        raise ValueError(f"{where}: x, y, p (and label) must be integers")
    if np.abs(table[:, 0]).max(initial=0.0) * 1e6 >= 2.0**62:
        raise ValueError(f"{where}: times (read as seconds) are out of range")
    out = np.empty(table.shape, np.int64)
    out[:, 0] = np.rint(table[:, 0] * 1e6).astype(np.int64)
    out[:, 1:] = table[:, 1:].astype(np.int64)
    return out


def open_source(path: Path, chunk: int, delimiter: str | None) -> EventSource:
    meta, skip = _read_header(path, delimiter)
    columns = len(FIELDS) + 1 if meta["has_labels"] else len(FIELDS)
    names = " ".join(FIELDS + ((LABEL,) if meta["has_labels"] else ()))
    meta["size_source"] = "header" if meta["width"] is not None else None

    block_bytes = max(1 << 16, min(chunk * _BYTES_PER_LINE, 1 << 26))

    def blocks() -> Iterator[tuple[bytes, int]]:
        """Whole lines, about ``block_bytes`` at a time, and the line number of the first."""
        with open(path, "rb") as f:
            for _ in itertools.islice(f, skip):
                pass
            line, rest = skip, b""
            while True:
                data = f.read(block_bytes)
                if not data:
                    break
                data = rest + data
                cut = data.rfind(b"\n") + 1
                if cut == 0:
                    rest = data
                    continue
                yield data[:cut], line
                line += data.count(b"\n", 0, cut)
                rest = data[cut:]
            if rest.strip():
                yield rest, line

    def packets() -> Iterator[np.ndarray]:
        unit: str | None = None
        for data, first_line in blocks():
            table, unit = _parse(data, delimiter, unit, first_line, path)
            meta["time_unit_in_file"] = unit
            if table.size == 0:
                continue
            if table.shape[1] != columns:
                raise ValueError(
                    f"{str(path)!r}: expected {columns} columns ({names}) as on the first line; "
                    f"found {table.shape[1]}"
                )
            p = table[:, 3]
            if not np.isin(p, (-1, 0, 1)).all():
                raise ValueError(f"{str(path)!r}: polarity column holds values other than 0/1 (or -1/1)")
            label = table[:, 4] if meta["has_labels"] else None
            yield from_columns([table[:, 0], table[:, 1], table[:, 2], (p > 0).astype(np.uint8)], path, label)
        meta.setdefault("time_unit_in_file", "us")

    return EventSource(meta, decoded(path, "numpy", packets()))


def _txt_source(path: Path, chunk: int) -> EventSource:
    return open_source(path, chunk, None)


def _csv_source(path: Path, chunk: int) -> EventSource:
    return open_source(path, chunk, ",")


def _txt_encoder(tmp: Path, spec: WriteSpec) -> TextEncoder:
    return TextEncoder(tmp, spec, " ")


def _csv_encoder(tmp: Path, spec: WriteSpec) -> TextEncoder:
    return TextEncoder(tmp, spec, ",")


TXT_FORMAT = FileFormat("txt", _txt_source, _txt_encoder, labels=True, title="text")
CSV_FORMAT = FileFormat("csv", _csv_source, _csv_encoder, labels=True, title="CSV")
