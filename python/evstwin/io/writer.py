"""Writing event files in chunks: :func:`open_event_writer` and :class:`EventWriter`, and
:func:`write_events` as a one-chunk use of them."""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType
from typing import Any

import numpy as np

from ._common import (
    ChunkEncoder,
    FileFormat,
    PathLike,
    SpooledColumn,
    WriteSpec,
    as_event_array,
    check_sorted,
    remove_quietly,
    temporary_path,
)
from ._registry import format_for


def _destination(path: PathLike) -> tuple[Path, FileFormat]:
    p = Path(os.fspath(path))
    fmt = format_for(p, "write")
    if not p.parent.is_dir():
        raise FileNotFoundError(f"cannot write {str(p)!r}: directory {str(p.parent)!r} does not exist")
    return p, fmt


class EventWriter:
    """An event file being written chunk by chunk; make one with :func:`open_event_writer`.

    The events go to a hidden temporary file beside ``path``; :meth:`close` finishes it (ground
    truth and scenario are written then) and renames it onto ``path`` atomically. An exception
    inside ``with open_event_writer(...) as w:``, or :meth:`abort`, removes the temporary file:
    nothing appears under ``path`` (an existing file there is left untouched). Memory stays
    O(chunk) for every format. While it is open, a lock file beside ``path`` makes a second
    writer of the same path (in this process or another) fail at once, rather than both
    finishing and the last one silently winning.
    """

    def __init__(self, path: Path, fmt: FileFormat, spec: WriteSpec) -> None:
        assert fmt.open_encoder is not None
        self.path = path
        self.format = fmt.name
        self._spec = spec
        self._lock = _lock_output(path)
        self._tmp = temporary_path(path)
        self._count = 0
        self._last_t: int | None = None
        self._open = True
        self._truth_spool: dict[str, dict[str, SpooledColumn]] = {}
        try:
            self._encoder: ChunkEncoder = fmt.open_encoder(self._tmp, spec)
        except BaseException:
            remove_quietly(self._tmp)
            self._unlock()
            raise

    @property
    def count(self) -> int:
        """Events written so far."""
        return self._count

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) of the sensor [pixels]."""
        return self._spec.width, self._spec.height

    def write(self, events: np.ndarray) -> None:
        """Append ``events`` (``EVENT_DTYPE``, or the same fields in another order or integer
        width) sorted by ``t``, none earlier than the previous chunk's last event, with
        coordinates inside the sensor. A chunk that fails these checks raises ValueError/
        TypeError and writes nothing (the writer stays usable); an error of the encoder aborts
        the writer."""
        self._check_open()
        ev = as_event_array(events)
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
            self._encoder.write(ev)
        except BaseException:
            self.abort()
            raise
        self._count += len(ev)
        self._last_t = int(ev["t"][-1])

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
            arrays[field] = arr
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
        elif set(track) != set(arrays):
            raise ValueError(f"truth {name!r}: fields must be {sorted(track)} every time; got {sorted(arrays)}")
        for field, arr in arrays.items():
            track[field].append(arr)

    def update_meta(self, meta: Mapping[str, Any]) -> None:
        """Replace ``scenario``/``truth`` and add extra scalars before :meth:`close` (for
        ground truth known only at the end); ``width``, ``height`` and ``raw_format`` are fixed
        at open and ignored here."""
        self._check_open()
        if not isinstance(meta, Mapping):
            raise TypeError(f"meta must be a mapping (dict); got {type(meta).__name__}")
        self._spec.update(meta)

    def close(self) -> Path:
        """Finish the file and rename it onto ``path``; return ``path``. Closing twice is a no-op."""
        if not self._open:
            return self.path
        try:
            for name, track in self._truth_spool.items():
                if name in self._spec.truth:
                    raise ValueError(f"truth {name!r} was given both by append_truth and meta['truth']")
                self._spec.truth[name] = dict(track)  # type: ignore[arg-type]  # encoders copy them in blocks
            self._encoder.close(self._spec)
            os.replace(self._tmp, self.path)
        except BaseException:
            self._open = False
            remove_quietly(self._tmp)
            raise
        finally:
            self._drop_spool()
            self._unlock()
        self._open = False
        return self.path

    def _unlock(self) -> None:
        if self._lock is not None:
            lock, self._lock = self._lock, None
            remove_quietly(Path(lock.name))
            lock.close()  # closing the descriptor releases the flock

    def _drop_spool(self) -> None:
        remove_quietly(*(c.path for track in self._truth_spool.values() for c in track.values()))

    def abort(self) -> None:
        """Drop the file being written: the temporary file is removed, ``path`` is not touched."""
        if not self._open:
            return
        self._open = False
        try:
            self._encoder.abort()
        finally:
            remove_quietly(self._tmp)
            self._drop_spool()
            self._unlock()

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
    has no flock); FileExistsError if another writer holds it."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        return None
    lock_path = path.with_name(f".{path.name}.lock")
    fh = open(lock_path, "a+")  # noqa: SIM115 - held open while writing, closed by _unlock
    try:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        fh.close()
        raise FileExistsError(f"another writer is writing {str(path)!r} now; wait for it or choose another path") from None
    return fh


def open_event_writer(
    path: PathLike, meta: Mapping[str, Any] | None = None, *, raw_format: str | None = None
) -> EventWriter:
    """Open ``path`` for writing events chunk by chunk (format from the suffix, as
    :func:`write_events`); use as a context manager, or call ``close()`` / ``abort()``.

    meta: as for :func:`write_events`, but ``width`` and ``height`` [pixels] are required (the
        headers of most formats carry them before the events). ``scenario``/``truth`` may also
        be given later with :meth:`EventWriter.update_meta`; they are written at close.
    raw_format: EVT version for ``.raw`` files (``'evt3'``, default, or ``'evt2'``).

    Raises ValueError for an unknown suffix or missing/invalid size, FileNotFoundError for a
    missing directory, TypeError for meta of the wrong type.
    """
    p, fmt = _destination(path)
    if meta is not None and not isinstance(meta, Mapping):
        raise TypeError(f"meta must be a mapping (dict); got {type(meta).__name__}")
    for key in ("width", "height"):
        if meta is None or meta.get(key) is None:
            raise ValueError(f"open_event_writer needs meta[{key!r}] (the sensor size in pixels); got none")
    spec = WriteSpec.from_meta(meta, raw_format, (1, 1))
    return EventWriter(p, fmt, spec)


def write_events(
    path: PathLike,
    events: np.ndarray,
    meta: Mapping[str, Any] | None = None,
    *,
    raw_format: str | None = None,
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

    The events go through :func:`open_event_writer` as one chunk, so the file is the same as
    one written chunk by chunk. Raises TypeError for events of another dtype or meta of the
    wrong type, ValueError for an unknown suffix, unsorted events, coordinates outside the
    sensor, or content the format cannot hold (the message says which formats can).
    """
    p = Path(os.fspath(path))
    format_for(p, "write")
    ev = as_event_array(events)
    check_sorted(ev)
    default = (int(ev["x"].max()) + 1, int(ev["y"].max()) + 1) if len(ev) else (1, 1)
    spec = WriteSpec.from_meta(meta, raw_format, default)
    p, fmt = _destination(p)
    with EventWriter(p, fmt, spec) as writer:
        writer.write(ev)
    return p


def check_writable(path: PathLike) -> Path:
    """Raise now, before a long simulation, if ``write_events(path, ...)`` could not write:
    an unknown suffix (ValueError naming it and the supported ones) or a missing directory
    (FileNotFoundError). Returns the path."""
    return _destination(path)[0]
