"""Writing event files in chunks: :func:`open_event_writer` and :class:`EventWriter`, and
:func:`write_events` as a one-chunk use of them."""

from __future__ import annotations

import contextlib
import errno
import os
import re
import weakref
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType
from typing import Any, cast

import numpy as np

from ._common import (
    ChunkEncoder,
    FileFormat,
    LabelEncoder,
    PathLike,
    SpooledColumn,
    WriteSpec,
    as_event_array,
    as_labels,
    check_sorted,
    remove_quietly,
    temporary_path,
)
from ._registry import FORMATS, format_for


def _check_labels(path: Path, fmt: FileFormat, labels: bool) -> None:
    """ValueError naming the format when ``labels`` asks for a label column it does not have."""
    if labels and not fmt.labels:
        holders = ", ".join(s for s, f in FORMATS.items() if f.labels)
        raise ValueError(
            f"cannot write labels to {str(path)!r}: {fmt.title or fmt.name} files have no label column; "
            f"write {holders} to keep them, or leave labels out"
        )


def _destination(path: PathLike) -> tuple[Path, FileFormat]:
    p = Path(os.fspath(path))
    fmt = format_for(p, "write")
    if not p.parent.is_dir():
        raise FileNotFoundError(f"cannot write {str(p)!r}: directory {str(p.parent)!r} does not exist")
    return p, fmt


SPACE_MARGIN_BYTES = 512 * 1024
"""Free space [bytes] a writer leaves on the destination's file system beyond what the next
chunk (or the close) may need: a write that would go below it raises OSError(ENOSPC) first."""

# Upper bounds of the bytes an encoder writes per event and per microsecond of recording, and
# of what it holds in memory before writing (HDF5's chunk cache: one 64 Ki-event chunk of each
# column; AEDAT: one pending packet). Text: a 20-digit t, two 5-digit coordinates, p, 4 separators.
_BYTES_PER_EVENT = {"hdf5": 16, "npz": 16, "txt": 36, "csv": 36, "aedat4": 17, "raw": 8, "dat": 8, "es": 8}
_BYTES_PER_LABEL = {"hdf5": 1, "npz": 1, "txt": 4, "csv": 4}  # a label column: a byte, or " 255"
_BYTES_PER_US = {"hdf5": 8 / 1000, "raw": 2 / 4096, "es": 1 / 1000}
_BUFFERED = {"hdf5": 1 << 20, "aedat4": 17 << 16}
_BUFFERED_DEFAULT = 64 * 1024


class _Held:
    """What an open writer must release: its lock, its encoder and its temporary files."""

    def __init__(self, lock: Any) -> None:
        self.lock = lock
        self.encoder: ChunkEncoder | None = None
        self.paths: list[Path] = []

    def release(self) -> None:
        encoder, self.encoder = self.encoder, None
        try:
            if encoder is not None:
                with contextlib.suppress(Exception):
                    encoder.abort()
        finally:
            remove_quietly(*self.paths)
            self.paths.clear()
            lock, self.lock = self.lock, None
            if lock is not None:
                remove_quietly(Path(lock.name))
                lock.close()  # closing the descriptor releases the flock


_TEMPORARY = re.compile(r"^\.\.?(?P<name>.+)\.tmp-(?P<pid>\d+)-[0-9a-f]{8}(?:\.[a-z0-9-]+-\d+-[0-9a-f]{8})?$")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: alive, another user's
        return True
    return True


def remove_orphans(path: Path) -> list[Path]:
    """Remove the temporary files that a dead writer of ``path`` left beside it (the pid in
    their name is no longer running: killed, out of memory, power cut); return them. Called by
    every writer of ``path`` while it holds the lock, so no live writer of ``path`` can own
    them; files of a pid that is alive are left (the pid may have been reused)."""
    removed = []
    with contextlib.suppress(OSError):
        for entry in os.scandir(path.parent):
            match = _TEMPORARY.match(entry.name)
            if match is None or match["name"] != path.name or int(match["pid"]) == os.getpid():
                continue
            if not _pid_alive(int(match["pid"])):
                orphan = path.with_name(entry.name)
                remove_quietly(orphan)
                removed.append(orphan)
    return removed


class EventWriter:
    """An event file being written chunk by chunk; make one with :func:`open_event_writer`.

    The events go to a hidden temporary file beside ``path``; :meth:`close` finishes it (ground
    truth and scenario are written then) and renames it onto ``path`` atomically. An exception
    inside ``with open_event_writer(...) as w:``, or :meth:`abort`, removes the temporary file:
    nothing appears under ``path`` (an existing file there is left untouched). Memory stays
    O(chunk) for every format. While it is open, a lock file beside ``path`` makes a second
    writer of the same path (in this process or another) fail at once, rather than both
    finishing and the last one silently winning.

    A writer opened with ``labels=True`` writes a label column (``.h5``/``.hdf5``, ``.npz``,
    ``.txt``, ``.csv``): every :meth:`write` then takes the chunk's labels with its events.
    """

    def __init__(self, path: Path, fmt: FileFormat, spec: WriteSpec) -> None:
        assert fmt.open_encoder is not None
        self.path = path
        self.format = fmt.name
        self._spec = spec
        self._count = 0
        self._first_t: int | None = None
        self._last_t: int | None = None
        self._open = True
        self._truth_spool: dict[str, dict[str, SpooledColumn]] = {}
        self._spooled_bytes = 0
        # What a failure, abort() or the garbage collector must undo; the finalizer holds this,
        # not the writer, so an abandoned writer still removes its files (at the latest at exit).
        self._held = _Held(_lock_output(path))
        self._finalizer = weakref.finalize(self, self._held.release)
        try:
            remove_orphans(path)
            self._tmp = temporary_path(path)
            self._held.paths.append(self._tmp)
            self._check_space(_BUFFERED.get(self.format, _BUFFERED_DEFAULT), "opening it")
            self._encoder: ChunkEncoder = fmt.open_encoder(self._tmp, spec)
            self._held.encoder = self._encoder
        except BaseException:
            self._open = False
            self._finalizer()
            raise

    @property
    def labels(self) -> bool:
        """Whether the file gets a label column (every :meth:`write` must give the labels)."""
        return self._spec.labels

    @property
    def count(self) -> int:
        """Events written so far."""
        return self._count

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of the sensor [pixels]."""
        return self._spec.width, self._spec.height

    def write(self, events: np.ndarray, labels: np.ndarray | None = None) -> None:
        """Append ``events`` (``EVENT_DTYPE``, or the same fields in another order or integer
        width) sorted by ``t``, none earlier than the previous chunk's last event, with
        coordinates inside the sensor. A chunk that fails these checks raises ValueError/
        TypeError and writes nothing (the writer stays usable); an error of the encoder aborts
        the writer, as does a chunk the destination has no space for (OSError ENOSPC, checked
        before writing with :data:`SPACE_MARGIN_BYTES` to spare). Big-endian and other
        non-native arrays are converted to their values.

        labels: the events' labels (1-D integer codes in [0, 255], one per event, as
        ``Sensor.last_labels()`` gives them), required when the writer was opened with
        ``labels=True`` and refused otherwise (ValueError, nothing written)."""
        self._check_open()
        ev = as_event_array(events)
        if self._spec.labels and labels is None:
            raise ValueError(
                f"the writer of {str(self.path)!r} was opened with labels=True: give each chunk's labels"
            )
        if not self._spec.labels and labels is not None:
            raise ValueError(
                f"the writer of {str(self.path)!r} has no label column: open it with labels=True to write labels"
            )
        codes = None if labels is None else as_labels(labels, len(ev))
        if len(ev) == 0:
            return
        check_sorted(ev, self._count, self._last_t)
        width, height = self.size
        x_max, y_max = int(ev["x"].max()), int(ev["y"].max())
        if x_max >= width or y_max >= height:
            raise ValueError(
                f"events fall outside the {width}x{height} sensor "
                f"(max x = {x_max}, max y = {y_max}); fix meta['width']/meta['height']"
            )
        try:
            self._check_space(self._chunk_bytes(ev), f"the next {len(ev)} events")
            if codes is None:
                self._encoder.write(ev)
            else:  # in step with the events: the same chunk, the same call
                cast(LabelEncoder, self._encoder).write(ev, codes)
        except BaseException:
            self.abort()
            raise
        if self._first_t is None:
            self._first_t = int(ev["t"][0])
        self._count += len(ev)
        self._last_t = int(ev["t"][-1])

    def _chunk_bytes(self, ev: np.ndarray) -> int:
        """About the most bytes the encoder may write for ``ev`` (an upper bound, not a guess):
        the records, the time-driven words (HDF5's millisecond index, EVT 3.0's TIME_HIGH, ES
        overflow bytes) and what the encoder may hold unwritten."""
        start = self._last_t if self._last_t is not None else int(ev["t"][0])
        span_us = max(0, int(ev["t"][-1]) - start)
        per_us = _BYTES_PER_US.get(self.format, 0.0)
        per_event = _BYTES_PER_EVENT.get(self.format, 40) + (_BYTES_PER_LABEL[self.format] if self.labels else 0)
        return (
            len(ev) * per_event
            + int(span_us * per_us)
            + _BUFFERED.get(self.format, _BUFFERED_DEFAULT)
        )

    def _check_space(self, needed: int, what: str) -> None:
        """OSError(ENOSPC) naming the path unless the destination's file system has ``needed``
        bytes plus :data:`SPACE_MARGIN_BYTES` free (libhdf5 crashes the process in its close
        once a write has hit ENOSPC, so the writer must stop before the disk is full)."""
        try:
            stat = os.statvfs(self.path.parent)
        except (AttributeError, OSError):  # pragma: no cover - no statvfs (Windows) or a vanished dir
            return
        free = stat.f_bavail * stat.f_frsize
        wanted = needed + SPACE_MARGIN_BYTES
        if free < wanted:
            raise OSError(
                errno.ENOSPC,
                f"no space left to write {str(self.path)!r}: {free} bytes free on its file system, "
                f"about {wanted} needed for {what} (margin included); the partial file was removed",
            )

    def append_truth(self, name: str, fields: Mapping[str, Any]) -> None:
        """Append rows to the ground-truth track ``name`` (field -> 1-D numeric array, all of
        one length; the same fields every time), kept in temporary files beside the output and
        written at close by the formats that hold truth (``.h5``, ``.npz``; the others ignore
        it, as they ignore ``meta['truth']``). Memory stays O(chunk). A name given here must
        not also come through ``meta['truth']``."""
        self._check_open()
        if not isinstance(name, str) or not name or "/" in name:
            raise ValueError(f"truth names must be non-empty str without '/'; got {name!r}")
        if not isinstance(fields, Mapping) or not fields:
            raise TypeError(f"truth {name!r}: fields must be a non-empty dict field -> array; got {fields!r}")
        arrays = {}
        for field, values in fields.items():
            if not isinstance(field, str) or not field or "/" in field:
                raise ValueError(f"truth {name!r}: fields must be non-empty str without '/'; got {field!r}")
            arr = np.asarray(values)
            if arr.ndim != 1 or arr.dtype.kind not in "biuf":
                raise TypeError(f"truth {name!r}[{field!r}] must be a 1-D numeric array; got {arr.dtype} {arr.shape}")
            arrays[field] = arr.astype(arr.dtype.newbyteorder("="), copy=False)  # native byte order
        lengths = {len(a) for a in arrays.values()}
        if len(lengths) != 1:
            raise ValueError(f"truth {name!r}: fields must have one length; got {sorted(lengths)}")
        track = self._truth_spool.get(name)
        if track is None:
            track = self._truth_spool[name] = {
                field: SpooledColumn(temporary_path(self._tmp, f"truth{len(self._truth_spool)}-{i}"),
                                     arr.dtype.newbyteorder("="))
                for i, (field, arr) in enumerate(arrays.items())
            }
            self._held.paths.extend(column.path for column in track.values())
        elif set(track) != set(arrays):
            raise ValueError(f"truth {name!r}: fields must be {sorted(track)} every time; got {sorted(arrays)}")
        else:
            lossy = {f: f"{a.dtype} into {track[f].dtype}" for f, a in arrays.items()
                     if not np.can_cast(a.dtype, track[f].dtype, casting="safe")}
            if lossy:
                raise TypeError(f"truth {name!r}: the first rows fixed the fields' dtypes; cannot append {lossy}")
        nbytes = sum(arr.nbytes for arr in arrays.values())
        try:
            self._check_space(nbytes, f"{len(next(iter(arrays.values())))} rows of truth {name!r}")
            for field, arr in arrays.items():
                track[field].append(arr)
        except BaseException:
            self.abort()
            raise
        self._spooled_bytes += nbytes

    def update_meta(self, meta: Mapping[str, Any]) -> None:
        """Replace ``scenario``/``truth`` and add extra scalars before :meth:`close` (for
        ground truth known only at the end); ``width``, ``height`` and ``raw_format`` are fixed
        at open and ignored here."""
        self._check_open()
        if not isinstance(meta, Mapping):
            raise TypeError(f"meta must be a mapping (dict); got {type(meta).__name__}")
        self._spec.update(meta)

    def close(self) -> Path:
        """Finish the file and rename it onto ``path``; return ``path``. Closing twice is a no-op.
        On any failure the temporary files are removed and nothing appears under ``path``."""
        if not self._open:
            return self.path
        self._open = False
        try:
            for name, track in self._truth_spool.items():
                if name in self._spec.truth:
                    raise ValueError(f"truth {name!r} was given both by append_truth and meta['truth']")
                self._spec.truth[name] = dict(track)  # type: ignore[arg-type]  # encoders copy them in blocks
            self._check_space(self._closing_bytes(), "finishing it")
            self._encoder.close(self._spec)
            self._held.encoder = None
            os.replace(self._tmp, self.path)
        finally:
            self._finalizer()  # on success the temporary name is gone already
        return self.path

    def _closing_bytes(self) -> int:
        """About the most bytes :meth:`close` writes: the truth (spooled and given in meta), and
        for NPZ the whole archive (the records are compressed into it at close)."""
        given = sum(
            np.asarray(v).nbytes
            for fields in self._spec.truth.values()
            for v in fields.values()
            if not isinstance(v, SpooledColumn)
        )
        per_event = _BYTES_PER_EVENT["npz"] + (_BYTES_PER_LABEL["npz"] if self.labels else 0)
        archive = self._count * per_event if self.format == "npz" else 0
        scenario = len(self._spec.scenario or "")
        return self._spooled_bytes + given + archive + scenario + _BUFFERED.get(self.format, _BUFFERED_DEFAULT)

    def abort(self) -> None:
        """Drop the file being written: the temporary files are removed, ``path`` is not touched."""
        if not self._open:
            return
        self._open = False
        self._finalizer()

    def _check_open(self) -> None:
        if not self._open:
            raise ValueError(f"the writer of {str(self.path)!r} is closed")

    def __enter__(self) -> EventWriter:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


def _lock_output(path: Path) -> Any:
    """An exclusive advisory lock on ``.<name>.lock`` beside ``path`` (None where the platform
    has no flock); FileExistsError if another writer holds it. The lock file is removed at
    close; a lock taken on a file another writer was removing at that moment is taken again."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        return None
    lock_path = path.with_name(f".{path.name}.lock")
    for _ in range(100):
        fh = open(lock_path, "a+")  # noqa: SIM115 - held open while writing, closed by _Held.release
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            fh.close()
            raise FileExistsError(
                f"another writer is writing {str(path)!r} now; wait for it or choose another path"
            ) from None
        except OSError:  # pragma: no cover - a file system without flock
            fh.close()
            return None
        try:
            same = os.stat(lock_path).st_ino == os.fstat(fh.fileno()).st_ino
        except FileNotFoundError:
            same = False
        if same:
            return fh
        fh.close()  # the previous writer removed this file after we opened it: lock the new one
    raise FileExistsError(f"cannot lock {str(lock_path)!r}: it keeps being replaced")  # pragma: no cover


def open_event_writer(
    path: PathLike, meta: Mapping[str, Any] | None = None, *, raw_format: str | None = None, labels: bool = False
) -> EventWriter:
    """Open ``path`` for writing events chunk by chunk (format from the suffix, as
    :func:`write_events`); use as a context manager, or call ``close()`` / ``abort()``.

    meta: as for :func:`write_events`, but ``width`` and ``height`` [pixels] are required (the
        headers of most formats carry them before the events). ``scenario``/``truth`` may also
        be given later with :meth:`EventWriter.update_meta`; they are written at close.
    raw_format: EVT version for ``.raw`` files (``'evt3'``, default, or ``'evt2'``).
    labels: give the file a label column (``.h5``/``.hdf5``: ``/events/label``; ``.npz``:
        ``label``; ``.txt``/``.csv``: a fifth column); each :meth:`EventWriter.write` then takes
        the chunk's labels. Default False: the file has no label column, as before.

    Raises ValueError for an unknown suffix, missing/invalid size, or ``labels=True`` for a
    format without a label column (AEDAT 4.0, Prophesee RAW/DAT, Event Stream: the message names
    it), FileNotFoundError for a missing directory, TypeError for meta of the wrong type.
    """
    p, fmt = _destination(path)
    _check_labels(p, fmt, labels)
    if meta is not None and not isinstance(meta, Mapping):
        raise TypeError(f"meta must be a mapping (dict); got {type(meta).__name__}")
    for key in ("width", "height"):
        if meta is None or meta.get(key) is None:
            raise ValueError(f"open_event_writer needs meta[{key!r}] (the sensor size in pixels); got none")
    spec = WriteSpec.from_meta(meta, raw_format, (1, 1))
    spec.labels = bool(labels)
    return EventWriter(p, fmt, spec)


def write_events(
    path: PathLike,
    events: np.ndarray,
    meta: Mapping[str, Any] | None = None,
    *,
    raw_format: str | None = None,
    labels: np.ndarray | None = None,
) -> Path:
    """Write events to ``path`` in the format given by its suffix; return the path written.

    events: 1-D structured array with fields ``t`` [us, int], ``x``, ``y`` [pixels],
        ``p`` [1 = ON, 0 = OFF], sorted by ``t``. ``EVENT_DTYPE`` is taken as is; other field
        orders and integer widths are converted (values must fit).
    meta: optional. ``width``, ``height`` [pixels] (default: max coordinate + 1);
        ``scenario`` (dict, stored as TOML, or str, stored as is); ``truth``
        (name -> field -> numeric array); ``raw_format`` (``'evt3'`` or ``'evt2'``); any other
        entry must be a scalar (str, int, float, bool) and is kept by ``.h5``/``.npz``.
        Descriptive keys returned by ``read_events`` (``format``, ``path``, ...) are ignored.
    raw_format: EVT version for ``.raw`` files, overrides ``meta['raw_format']``;
        default ``'evt3'``.
    labels: optional label column, one integer code in [0, 255] per event (why it fired:
        ``EVENT_LABELS``, as ``SimulationResult.labels`` or ``read_events(..., labels=True)``
        give them). Written by ``.h5``/``.hdf5``, ``.npz``, ``.txt`` and ``.csv``; other formats
        refuse it with ValueError naming the format (they have no label column). Default None:
        no label column.

    The events go through :func:`open_event_writer` as one chunk, so the file is the same as
    one written chunk by chunk. Raises TypeError for events of another dtype or meta of the
    wrong type, ValueError for an unknown suffix, unsorted events, coordinates outside the
    sensor, or content the format cannot hold (the message says which formats can).
    """
    p = Path(os.fspath(path))
    _check_labels(p, format_for(p, "write"), labels is not None)
    ev = as_event_array(events)
    check_sorted(ev)
    codes = None if labels is None else as_labels(labels, len(ev))
    default = (int(ev["x"].max()) + 1, int(ev["y"].max()) + 1) if len(ev) else (1, 1)
    spec = WriteSpec.from_meta(meta, raw_format, default)
    spec.labels = codes is not None
    p, fmt = _destination(p)
    with EventWriter(p, fmt, spec) as writer:
        writer.write(ev, codes)
    return p


def check_writable(path: PathLike) -> Path:
    """Raise now, before a long simulation, if ``write_events(path, ...)`` could not write:
    an unknown suffix (ValueError naming it and the supported ones) or a missing directory
    (FileNotFoundError). Returns the path."""
    return _destination(path)[0]
