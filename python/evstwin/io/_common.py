"""What every format shares: the write specification validated from ``meta``, event-array checks,
sizes read from headers, the per-format interface (:class:`FileFormat`) and temporary names."""

from __future__ import annotations

import contextlib
import dataclasses
import numbers
import os
import sys
import uuid
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, Protocol, Union

import numpy as np

from .._extras import require
from ..sensor import EVENT_DTYPE

PathLike = Union[str, "os.PathLike[str]"]
Meta = dict[str, Any]
Truth = dict[str, dict[str, np.ndarray]]
Size = tuple[int, int]

RAW_FORMATS: tuple[str, ...] = ("evt3", "evt2")
"""EVT versions ``write_events`` can write to ``.raw`` (the first is the default)."""

FIELDS: tuple[str, ...] = ("t", "x", "y", "p")
LABEL = "label"
"""The name of the optional label column (why each event fired: codes of ``EVENT_LABELS``) in
every layout that has one: ``/events/label`` (HDF5), ``label`` (NPZ), the fifth text column."""
LABELED_DTYPE = np.dtype([*((name, EVENT_DTYPE[name]) for name in FIELDS), (LABEL, np.uint8)])
"""A decoded packet of a file with a label column: ``EVENT_DTYPE``'s fields, then ``label``
(internal to the readers: callers get the events and the labels as two arrays)."""
COORD_MAX = np.iinfo(np.uint16).max
SIZE_MAX = COORD_MAX  # a width or height read from a header: 1..65535 pixels
EVT_SIZE_MAX = 2048  # EVT 2.0 / 3.0 carry x and y on 11 bits
LAYOUT = "evstwin.events/1"

# Keys of ``meta`` that describe a file that was read rather than content to store: a writer
# ignores them, so that ``write_events(p, *read_events(q))`` works.
DESCRIPTIVE_KEYS = frozenset(
    {
        "format",
        "path",
        "evstwin_version",
        "version",
        "size_inferred",
        "size_source",
        "resorted",
        "raw_header",
        "time_unit_in_file",
        "stream_id",
        "has_labels",
    }
)
# Keys with a meaning of their own in ``meta``.
SPECIAL_KEYS = frozenset({"width", "height", "scenario", "truth", "raw_format"})
# Names used by the HDF5/NPZ layouts for their own bookkeeping.
LAYOUT_KEYS = frozenset({"scenario_encoding", "layout", "events", "ms_to_idx"})


# ---------------------------------------------------------------------------------------------
# the interface of a format module


class ChunkEncoder(Protocol):
    """Writes one format incrementally into a temporary file (opened by the format's factory)."""

    def write(self, events: np.ndarray) -> None:
        """Append validated, sorted ``EVENT_DTYPE`` events (never empty)."""

    def close(self, spec: WriteSpec) -> None:
        """Finish the file: metadata known only at the end (truth, scenario) is written here."""

    def abort(self) -> None:
        """Release what the encoder holds after a failure; the caller removes the files."""


class LabelEncoder(ChunkEncoder, Protocol):
    """The encoder of a format with a label column (``FileFormat.labels``): opened with
    ``spec.labels`` True, it is given the labels of every chunk with its events."""

    def write(self, events: np.ndarray, labels: np.ndarray | None = None) -> None:
        """Append events and, when the file has a label column, their uint8 labels (same length)."""


@dataclasses.dataclass
class EventSource:
    """An opened file: its ``meta`` (``width``/``height`` None when the header has no size;
    ``has_labels`` True when the file has a label column) and an iterator over packets of any
    length, in file order: ``EVENT_DTYPE``, or ``LABELED_DTYPE`` when the file has labels."""

    meta: Meta
    packets: Iterator[np.ndarray]
    size_limit: int = SIZE_MAX


@dataclasses.dataclass(frozen=True)
class FileFormat:
    """One suffix's reader and writer: ``open_source(path, chunk) -> EventSource`` (packets of at
    most about ``chunk`` events where the format lets the reader choose) and
    ``open_encoder(tmp, spec) -> ChunkEncoder`` (None where the format cannot be read/written);
    ``labels``: whether the format has a label column (its encoder is then a
    :class:`LabelEncoder`); ``title``: the format's name in messages."""

    name: str
    open_source: Callable[[Path, int], EventSource] | None
    open_encoder: Callable[[Path, WriteSpec], ChunkEncoder] | None
    labels: bool = False
    title: str = ""


# ---------------------------------------------------------------------------------------------
# the write specification


@dataclasses.dataclass
class WriteSpec:
    """What a writer needs besides the events, validated once (scenario and truth may be
    replaced before the writer closes)."""

    width: int
    height: int
    scenario: str | None  # TOML text or the user's string
    scenario_is_toml: bool
    truth: Truth
    extras: dict[str, str | int | float | bool]
    raw_format: str
    labels: bool = False  # the file gets a label column (set by the writer, not by meta)

    @classmethod
    def from_meta(cls, meta: Mapping[str, Any] | None, raw_format: str | None, size: Size) -> WriteSpec:
        """``size`` is the default (width, height) where ``meta`` has none."""
        meta = {} if meta is None else meta
        if not isinstance(meta, Mapping):
            raise TypeError(f"meta must be a mapping (dict); got {type(meta).__name__}")
        width = size_from_meta(meta, "width", size[0])
        height = size_from_meta(meta, "height", size[1])
        spec = cls(width, height, None, False, {}, {}, RAW_FORMATS[0])
        spec.update(meta)
        fmt = raw_format if raw_format is not None else meta.get("raw_format", RAW_FORMATS[0])
        if not isinstance(fmt, str) or fmt.lower() not in RAW_FORMATS:
            raise ValueError(f"raw_format must be one of {RAW_FORMATS}; got {fmt!r}")
        spec.raw_format = fmt.lower()
        return spec

    def update(self, meta: Mapping[str, Any]) -> None:
        """Take ``scenario``, ``truth`` and extra scalars from ``meta`` (size keys are ignored)."""
        if "scenario" in meta:
            scenario = meta["scenario"]
            if scenario is None:
                self.scenario, self.scenario_is_toml = None, False
            elif isinstance(scenario, str):
                self.scenario, self.scenario_is_toml = scenario, False
            elif isinstance(scenario, Mapping):
                self.scenario, self.scenario_is_toml = scenario_to_toml(scenario), True
            else:
                raise TypeError(f"meta['scenario'] must be a dict or a str; got {type(scenario).__name__}")
        if "truth" in meta:
            self.truth = validate_truth(meta["truth"])
        for key, value in meta.items():
            if not isinstance(key, str):
                raise TypeError(f"meta keys must be str; got {key!r}")
            if key in SPECIAL_KEYS or key in DESCRIPTIVE_KEYS or value is None:
                continue
            if key in LAYOUT_KEYS or "/" in key:
                raise ValueError(f"meta[{key!r}]: this name is reserved by the file layouts")
            scalar = python_scalar(value)
            if scalar is None:
                raise TypeError(
                    f"meta[{key!r}] must be a scalar (str, int, float, bool) to be stored; "
                    f"got {type(value).__name__}"
                )
            self.extras[key] = scalar


def size_from_meta(meta: Mapping[str, Any], key: str, default: int) -> int:
    value = meta.get(key)
    if value is None:
        return default
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise TypeError(f"meta[{key!r}] must be an int; got {value!r}")
    value = int(value)
    if not 0 < value <= COORD_MAX + 1:
        raise ValueError(f"meta[{key!r}] must be in [1, {COORD_MAX + 1}]; got {value}")
    return value


def python_scalar(value: Any) -> str | int | float | bool | None:
    """``value`` as a Python str/int/float/bool, or None if it is not a scalar."""
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, (str, bool, int, float)):
        return value
    return None


def _plain(value: Any) -> Any:
    """``value`` with NumPy scalars/arrays and tuples turned into TOML-able Python objects."""
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items() if v is not None}
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, Path):
        return str(value)
    return value


def scenario_to_toml(scenario: Mapping[str, Any]) -> str:
    """The scenario as TOML text. TOML has no null: keys whose value is None are left out."""
    import tomli_w

    try:
        return tomli_w.dumps(_plain(scenario))
    except (TypeError, ValueError) as err:
        raise TypeError(f"meta['scenario'] cannot be written as TOML: {err}") from err


def toml_loads(text: str) -> dict[str, Any]:
    if sys.version_info >= (3, 11):
        import tomllib
    else:  # pragma: no cover - exercised on Python < 3.11 only
        import tomli as tomllib
    return tomllib.loads(text)


def validate_truth(truth: Any) -> Truth:
    if truth is None:
        return {}
    if not isinstance(truth, Mapping):
        raise TypeError(
            f"meta['truth'] must be a dict name -> dict field -> array; got {type(truth).__name__}"
        )
    out: Truth = {}
    for name, fields in truth.items():
        if not isinstance(name, str) or not name or "/" in name:
            raise ValueError(f"meta['truth'] names must be non-empty str without '/'; got {name!r}")
        if not isinstance(fields, Mapping):
            raise TypeError(
                f"meta['truth'][{name!r}] must be a dict field -> array; got {type(fields).__name__}"
            )
        out[name] = {}
        for field, values in fields.items():
            if not isinstance(field, str) or not field or "/" in field:
                raise ValueError(
                    f"meta['truth'][{name!r}] fields must be non-empty str without '/'; got {field!r}"
                )
            arr = np.asarray(values)
            if arr.dtype.kind not in "biuf":
                raise TypeError(
                    f"meta['truth'][{name!r}][{field!r}] must be a numeric array; got dtype {arr.dtype}"
                )
            out[name][field] = arr.astype(arr.dtype.newbyteorder("="), copy=False)  # native byte order
    return out


def decode_scenario(meta: Meta) -> None:
    """Turn a stored TOML scenario back into a dict and drop the layout's bookkeeping keys."""
    encoding = meta.pop("scenario_encoding", None)
    meta.pop("layout", None)
    if "scenario" in meta and encoding == "toml":
        meta["scenario"] = toml_loads(str(meta["scenario"]))


# ---------------------------------------------------------------------------------------------
# event arrays


def as_event_array(events: Any) -> np.ndarray:
    """Return ``events`` as a 1-D ``EVENT_DTYPE`` array (no copy if it already is one)."""
    if not isinstance(events, np.ndarray):
        raise TypeError(
            f"events must be a NumPy structured array of dtype {EVENT_DTYPE}; got {type(events).__name__}"
        )
    dtype = events.dtype
    if dtype != EVENT_DTYPE:
        if dtype.names is None or set(dtype.names) != set(FIELDS):
            raise TypeError(f"events have dtype {dtype}; expected fields {FIELDS} as in {EVENT_DTYPE}")
        for name in FIELDS:
            field = dtype.fields[name][0]
            if field.kind not in "iub" or field.shape != ():
                raise TypeError(
                    f"events have dtype {dtype}: field {name!r} must be a scalar integer (as in {EVENT_DTYPE})"
                )
    if events.ndim != 1:
        raise ValueError(f"events must be 1-D; got shape {events.shape}")
    if dtype == EVENT_DTYPE:
        out = events
    else:
        out = np.empty(len(events), EVENT_DTYPE)
        for name in FIELDS:
            col = events[name]
            if len(col) and col.dtype != EVENT_DTYPE[name]:
                lo, hi = limits(EVENT_DTYPE[name], name)
                if int(col.min()) < lo or int(col.max()) > hi:
                    raise ValueError(f"events[{name!r}] ({col.dtype}) holds values outside [{lo}, {hi}]")
            out[name] = col
    if len(out) and out["p"].max() > 1:
        raise ValueError("events['p'] must be 0 (OFF) or 1 (ON)")
    return out


def limits(dtype: np.dtype, name: str) -> tuple[int, int]:
    if name == "p":
        return 0, 1
    if name == LABEL:
        return 0, 255
    info = np.iinfo(dtype)
    return int(info.min), int(info.max)


def check_sorted(events: np.ndarray, offset: int = 0, previous_t: int | None = None) -> None:
    """Raise unless ``events`` are sorted by ``t`` and start no earlier than ``previous_t`` (the
    last time of the previous chunk); indices in the message count from ``offset``."""
    t = events["t"]
    if previous_t is not None and len(t) and int(t[0]) < previous_t:
        raise ValueError(
            f"events must be sorted by t; t[{offset}] = {int(t[0])} us < t[{offset - 1}] = {previous_t} us "
            "(the previous chunk's last event)"
        )
    if len(t) > 1:
        bad = np.flatnonzero(t[1:] < t[:-1])
        if len(bad):
            i = int(bad[0])
            raise ValueError(
                f"events must be sorted by t; t[{offset + i + 1}] = {int(t[i + 1])} us < "
                f"t[{offset + i}] = {int(t[i])} us "
                "(sort with events[np.argsort(events['t'], kind='stable')])"
            )


def from_columns(t_x_y_p: Sequence[Any], where: Path, label: Any = None) -> np.ndarray:
    """Pack decoded columns ``(t, x, y, p)`` into ``EVENT_DTYPE``, or with a ``label`` column
    into ``LABELED_DTYPE``, checking that the values fit."""
    names = FIELDS if label is None else (*FIELDS, LABEL)
    columns = [np.asarray(c) for c in (t_x_y_p if label is None else [*t_x_y_p, label])]
    for name, col in zip(names, columns):
        if col.ndim != 1:
            raise ValueError(f"{str(where)!r}: column {name!r} has shape {col.shape}, expected 1-D")
        if col.dtype.kind not in "biu":
            raise ValueError(f"{str(where)!r}: column {name!r} is {col.dtype}, expected integers")
    n = len(columns[0])
    if any(len(c) != n for c in columns):
        raise ValueError(f"{str(where)!r}: columns {', '.join(names)} have different lengths")
    dtype = EVENT_DTYPE if label is None else LABELED_DTYPE
    out = np.empty(n, dtype)
    if n == 0:
        return out
    for name, col in zip(names, columns):
        lo, hi = limits(dtype[name], name)
        c_min, c_max = int(col.min()), int(col.max())
        if c_min < lo or c_max > hi:
            raise ValueError(
                f"{str(where)!r}: column {name!r} holds values in [{c_min}, {c_max}], outside [{lo}, {hi}]"
            )
        out[name] = col
    return out


def split_labels(packet: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """A decoded packet as ``EVENT_DTYPE`` events and their uint8 labels (None without a label
    column); copies only a ``LABELED_DTYPE`` packet."""
    if packet.dtype == EVENT_DTYPE:
        return packet, None
    events = np.empty(len(packet), EVENT_DTYPE)
    for name in FIELDS:
        events[name] = packet[name]
    return events, np.ascontiguousarray(packet[LABEL])


def as_labels(labels: Any, n: int) -> np.ndarray:
    """``labels`` for ``n`` events as a 1-D uint8 array (no copy if it already is one), or
    TypeError/ValueError saying what is wrong (nothing is written then)."""
    if not isinstance(labels, np.ndarray):
        raise TypeError(f"labels must be a 1-D NumPy integer array (uint8 codes); got {type(labels).__name__}")
    if labels.ndim != 1 or labels.dtype.kind not in "iub":
        raise TypeError(f"labels must be a 1-D integer array (uint8 codes); got {labels.dtype} of shape {labels.shape}")
    if len(labels) != n:
        raise ValueError(f"labels must have one code per event: {len(labels)} labels for {n} events")
    if labels.dtype == np.uint8:
        return labels
    if n and (int(labels.min()) < 0 or int(labels.max()) > 255):
        raise ValueError(f"labels must be codes in [0, 255]; got values in [{int(labels.min())}, {int(labels.max())}]")
    return labels.astype(np.uint8)


def label_header() -> str:
    """The label codes in one line, as the files that have a label column describe them."""
    from .. import _core

    return ", ".join(f"{code} = {name}" for code, name in sorted(_core.EVENT_LABELS.items()))


def from_packet(packet: np.ndarray, where: Path) -> np.ndarray:
    """A decoder's packet (``t`` uint64, ``x``, ``y``, ``on``/``p`` bool) as ``EVENT_DTYPE``."""
    p_name = "on" if "on" in (packet.dtype.names or ()) else "p"
    return from_columns([packet["t"], packet["x"], packet["y"], packet[p_name].astype(np.uint8)], where)


def rechunk(packets: Iterable[np.ndarray], chunk: int) -> Iterator[np.ndarray]:
    """Regroup packets of any length into chunks of ``chunk`` events (the last may be shorter);
    memory O(chunk + largest packet)."""
    pending: list[np.ndarray] = []
    count = 0
    for packet in packets:
        if len(packet) == 0:
            continue
        pending.append(packet)
        count += len(packet)
        if count < chunk:
            continue
        joined = pending[0] if len(pending) == 1 else np.concatenate(pending)
        full = (len(joined) // chunk) * chunk
        for start in range(0, full, chunk):
            yield joined[start : start + chunk]
        rest = joined[full:]
        pending, count = ([rest], len(rest)) if len(rest) else ([], 0)
    if count:
        yield pending[0] if len(pending) == 1 else np.concatenate(pending)


def check_header_size(where: Path, width: Any, height: Any, limit: int = SIZE_MAX) -> Size:
    """A sensor size read from a file's header, as ints in [1, ``limit``], or ValueError."""
    out = []
    for name, value in (("width", width), ("height", height)):
        if isinstance(value, np.generic):
            value = value.item()
        if isinstance(value, bool) or not isinstance(value, numbers.Integral) or not 1 <= int(value) <= limit:
            raise ValueError(
                f"{str(where)!r}: the header's {name} = {one_line(repr(value), 80)} is not an integer "
                f"in [1, {limit}]"
            )
        out.append(int(value))
    return out[0], out[1]


def to_faery(events: np.ndarray) -> np.ndarray:
    """``EVENT_DTYPE`` events as faery's ``EVENTS_DTYPE`` (``t``, ``x``, ``y``, ``on``)."""
    faery = require("faery")
    out = np.empty(len(events), faery.EVENTS_DTYPE)
    out["t"] = events["t"]
    out["x"] = events["x"]
    out["y"] = events["y"]
    out["on"] = events["p"] != 0
    return out


def check_unsigned_times(events: np.ndarray, suffix: str) -> None:
    if len(events) and int(events["t"][0]) < 0:
        raise ValueError(
            f"{suffix} files store unsigned times; the first event is at t = {int(events['t'][0])} us "
            "(shift the times, or write .h5/.npz/.txt/.csv, which accept negative times)"
        )


# ---------------------------------------------------------------------------------------------
# files


def temporary_path(path: Path, tag: str = "tmp") -> Path:
    """A hidden name beside ``path`` for a file that is not complete yet."""
    return path.with_name(f".{path.name}.{tag}-{os.getpid()}-{uuid.uuid4().hex[:8]}")


def remove_quietly(*paths: Path) -> None:
    for path in paths:
        with contextlib.suppress(OSError):
            path.unlink()


def one_line(err: BaseException | str, limit: int = 400) -> str:
    """An error's message on one line (whitespace runs collapsed), at most ``limit`` characters."""
    text = " ".join(str(err).split()) if not isinstance(err, BaseException) or str(err) else type(err).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


@contextlib.contextmanager
def decoding(path: Path, library: str) -> Iterator[None]:
    """Turn whatever a decoding library raises into one-line ValueError naming the file.

    evstwin's own one-line ValueErrors naming the file, and the OSErrors of a missing or
    unreadable file, pass as they are; anything else (RuntimeError, EOFError, MemoryError for
    a size read from a corrupted header, zlib.error, and BaseExceptions such as pyo3's
    ``PanicException``) becomes ValueError. KeyboardInterrupt, SystemExit and GeneratorExit pass through.
    """
    try:
        yield
    except (KeyboardInterrupt, SystemExit, GeneratorExit):
        raise
    except (FileNotFoundError, PermissionError, IsADirectoryError) as err:  # access, not content
        if "\n" in str(err):
            raise type(err)(err.errno, one_line(err)) from err
        raise
    except ValueError as err:  # evstwin's own checks name the file; a library's may not
        if type(err) is ValueError and "\n" not in str(err) and str(path) in str(err):
            raise
        raise ValueError(f"{str(path)!r}: {library} could not decode the file: {one_line(err)}") from err
    except BaseException as err:  # noqa: BLE001 - the libraries raise RuntimeError, EOFError, PanicException...
        if type(err).__name__ == "MissingExtraError":
            raise
        raise ValueError(
            f"{str(path)!r}: {library} could not decode the file: {type(err).__name__}: {one_line(err)}"
        ) from err


def decoded(path: Path, library: str, packets: Iterator[np.ndarray]) -> Iterator[np.ndarray]:
    """``packets`` with the library's decoding errors turned into ValueError naming the file."""
    with decoding(path, library):
        yield from packets


# ---------------------------------------------------------------------------------------------
# ground truth streamed with the events


SPOOL_BLOCK_ROWS = 1 << 18  # rows of a spooled column copied into the file at a time


@dataclasses.dataclass
class SpooledColumn:
    """One ground-truth column appended chunk by chunk to a raw temporary file (native byte
    order) while the events stream, and copied into the output in blocks at close, so a long
    recording's truth never sits in memory."""

    path: Path
    dtype: np.dtype
    length: int = 0

    def append(self, values: np.ndarray) -> None:
        with open(self.path, "ab") as fh:
            fh.write(np.ascontiguousarray(values, dtype=self.dtype).tobytes())
        self.length += len(values)

    def blocks(self, rows: int = SPOOL_BLOCK_ROWS) -> Iterator[np.ndarray]:
        """The column in order, ``rows`` values at a time."""
        if self.length == 0:
            return
        with open(self.path, "rb") as fh:
            while True:
                block = np.fromfile(fh, dtype=self.dtype, count=rows)
                if block.size == 0:
                    return
                yield block
