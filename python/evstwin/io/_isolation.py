"""Decoding untrusted files where a crash or a hang of the decoder cannot take the process down.

Some decoders are native code that a corrupted file can make abort (``aedat``, written in
Rust, calls ``abort()`` on a panic inside a destructor and raises ``PanicException``, a
BaseException, otherwise), or spin forever (libhdf5 on a corrupted object header). Files of
those formats (:data:`ISOLATED`) are decoded in a child process:

* the child is forked from a ``multiprocessing`` fork server that has the io modules, h5py and
  the optional decoders imported already, so a decode starts in a few tens of milliseconds;
* the child sends the file's ``meta`` (pickled) and then each decoded chunk of ``EVENT_DTYPE``
  records (``LABELED_DTYPE`` for a file with a label column, tagged so) as raw bytes over a pipe, received straight into the array the caller gets (no extra
  copy); the OS pipe buffer is the only read-ahead, so memory stays O(chunk) on both sides;
* a watchdog stops a child that sends nothing for :data:`NO_PROGRESS_TIMEOUT_S` seconds (the
  time between two chunks, not the whole decode: an hour-long recording still reads);
* a child that dies (SIGABRT, SIGSEGV, killed for memory) becomes :class:`DecoderCrashError`,
  a hang :class:`DecoderHangError`, both ValueError with one line naming the file; any exception
  in the child (PanicException included) comes back as one line: OSError subclasses as
  themselves, everything else as ValueError.

The decoder's own stderr (Rust panic backtraces) is discarded in the child. The child is killed
when the caller drops the stream early. In a daemonic process (a ``multiprocessing.Pool`` or
Dask worker), which may not start children, and with ``EVSTWIN_IO_ISOLATION=0``, decoding runs
in the process itself; errors are still one line, but a decoder that aborts then takes the
process with it.
"""

from __future__ import annotations

import contextlib
import os
import pickle
import signal
import sys
import threading
import types
import weakref
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from .._signals import children_without_sigint
from ..sensor import EVENT_DTYPE
from ._common import LABELED_DTYPE, EventSource, FileFormat, decoded, decoding, one_line

ISOLATED: frozenset[str] = frozenset({"aedat4", "hdf5", "raw", "dat", "es"})
"""Formats (``FileFormat.name``) decoded in a child process by default: those whose decoder is
native code (aedat: Rust; libhdf5: C; faery: Rust). NPZ and text are decoded by Python's
zipfile/zlib and NumPy's parser in the process itself."""

NO_PROGRESS_TIMEOUT_S = float(os.environ.get("EVSTWIN_DECODE_TIMEOUT_S", "60"))
"""Seconds a child may go without sending anything (the meta, or the next chunk of at most
``chunk`` events) before it is stopped as hung. A million events decode in well under a second,
so 60 s is only reached by a decoder that no longer progresses."""

ENABLED = os.environ.get("EVSTWIN_IO_ISOLATION", "1").strip().lower() not in ("0", "false", "no", "off")
"""False with ``EVSTWIN_IO_ISOLATION=0``: decode in the process itself (debugging a decoder)."""

LIBRARIES = {
    "aedat4": "aedat", "hdf5": "libhdf5 (h5py)", "raw": "faery", "dat": "faery", "es": "faery",
    "npz": "zipfile", "txt": "numpy.loadtxt", "csv": "numpy.loadtxt",
}
_EXTRAS = {"aedat4": "aedat", "raw": "faery", "dat": "faery", "es": "faery"}
_PRELOAD = "evstwin.io._isolation_preload"

_META, _EVENTS, _LABELED, _DONE, _ERROR = b"M", b"E", b"L", b"D", b"X"
_DTYPES = {_EVENTS: EVENT_DTYPE, _LABELED: LABELED_DTYPE}


class DecoderCrashError(ValueError):
    """The decoder's child process died (``signal`` names how) while reading a file."""

    def __init__(self, message: str, signal_name: str) -> None:
        super().__init__(message)
        self.signal = signal_name


class DecoderHangError(ValueError):
    """The decoder made no progress for :data:`NO_PROGRESS_TIMEOUT_S` and was stopped."""


@contextlib.contextmanager
def forced(formats: frozenset[str] | None = None) -> Iterator[None]:
    """Decode ``formats`` (default: all) in a child while the block runs, so that a crash or a
    hang of an in-process decoder is observed too (the fuzz harness)."""
    global ISOLATED, ENABLED
    saved = ISOLATED, ENABLED
    ISOLATED = frozenset(LIBRARIES) if formats is None else formats
    ENABLED = True
    try:
        yield
    finally:
        ISOLATED, ENABLED = saved


def isolated(fmt: FileFormat) -> bool:
    """Whether ``fmt`` is decoded in a child process here and now."""
    if not ENABLED or fmt.name not in ISOLATED:
        return False
    import multiprocessing

    return not multiprocessing.current_process().daemon


# ---------------------------------------------------------------------------------------------
# the parent's side


_context_lock = threading.Lock()
_start_lock = threading.Lock()
_context: Any = None


def _get_context() -> Any:
    global _context
    with _context_lock:
        if _context is None:
            import multiprocessing

            ctx: Any
            if "forkserver" in multiprocessing.get_all_start_methods():
                ctx = multiprocessing.get_context("forkserver")
                ctx.set_forkserver_preload([_PRELOAD])  # used if the server is not running yet
            else:  # pragma: no cover - Windows, macOS without forkserver
                ctx = multiprocessing.get_context("spawn")
            _context = ctx
        return _context


@contextlib.contextmanager
def _main_module_hidden() -> Iterator[None]:
    """Start a child without naming the caller's ``__main__`` script: multiprocessing would run
    it again in the child (as ``__mp_main__``), re-running a script without an
    ``if __name__ == '__main__'`` guard. The child only needs evstwin's own modules."""
    main = sys.modules.get("__main__")
    sys.modules["__main__"] = types.ModuleType("__main__")
    try:
        yield
    finally:
        if main is not None:
            sys.modules["__main__"] = main


def _stop(process: Any, connection: Any) -> None:
    with contextlib.suppress(Exception):
        connection.close()
    with contextlib.suppress(Exception):
        if process.exitcode is None:
            process.kill()
        process.join(5)


class _Child:
    """One decode running in a child process, and the end of the pipe it writes to."""

    def __init__(self, fmt: FileFormat, path: Path, job: tuple[Any, ...]) -> None:
        ctx = _get_context()
        self.path = path
        self.library = LIBRARIES.get(fmt.name, fmt.name)
        self.format = fmt.name
        reader, writer = ctx.Pipe(duplex=False)
        process = ctx.Process(target=_child_main, args=(writer, fmt.name, str(path), job), daemon=True)
        try:
            # One start at a time (__main__ is swapped); the child (and the forkserver it may
            # start) never sees a terminal's Ctrl-C: the parent stops it.
            with _start_lock, _main_module_hidden(), children_without_sigint():
                process.start()
        finally:
            writer.close()  # the child holds the only writing end: its death is our EOF
        self.process = process
        self.connection = reader
        self._finalizer = weakref.finalize(self, _stop, process, reader)

    def close(self) -> None:
        self._finalizer()

    def _receive(self) -> bytes:
        if not self.connection.poll(NO_PROGRESS_TIMEOUT_S):
            self.close()
            raise DecoderHangError(
                f"{str(self.path)!r}: {self.library} made no progress decoding it for "
                f"{NO_PROGRESS_TIMEOUT_S:g} s and was stopped (a corrupted {self.format} file?)"
            )
        try:
            return bytes(self.connection.recv_bytes())
        except (EOFError, OSError):
            raise self._crashed() from None

    def _crashed(self) -> ValueError:
        self.process.join(5)
        code = self.process.exitcode
        self.close()
        if code is not None and code < 0:
            try:
                name = signal.Signals(-code).name
            except ValueError:
                name = f"signal {-code}"
        else:
            name = f"exit status {code}"
        return DecoderCrashError(
            f"{str(self.path)!r}: the {self.library} decoder crashed ({name}) reading it; "
            f"the file is corrupted or not a valid {self.format} file",
            name,
        )

    def next_message(self) -> tuple[bytes, Any]:
        """(tag, payload): ``_META`` with (meta, size_limit), ``_EVENTS`` with an array, or
        ``_DONE``; an error of the child is raised here."""
        tag = self._receive()
        if tag[:1] in _DTYPES and len(tag) == 9:
            count = int.from_bytes(tag[1:], "little")
            out = np.empty(count, _DTYPES[tag[:1]])
            if not self.connection.poll(NO_PROGRESS_TIMEOUT_S):
                self._receive()  # raises the hang
            try:
                self.connection.recv_bytes_into(out.view(np.uint8))
            except (EOFError, OSError):
                raise self._crashed() from None
            return _EVENTS, out
        if tag == _META:
            return _META, pickle.loads(self._receive())
        if tag == _DONE:
            self.close()
            return _DONE, None
        if tag[:1] == _ERROR:
            self.close()
            kind, message = pickle.loads(tag[1:])
            raise _rebuild(kind, message, self.path)
        self.close()
        raise ValueError(f"{str(self.path)!r}: unexpected message from the decoder process")


def _rebuild(kind: str, message: str, path: Path) -> BaseException:
    """The parent's exception for the child's (``kind`` is the child's class name)."""
    import builtins

    if str(path) not in message:
        message = f"{str(path)!r}: {message}"
    if kind == "MissingExtraError":
        from .._extras import MissingExtraError

        return MissingExtraError(message)
    cls = getattr(builtins, kind, None)
    if isinstance(cls, type) and issubclass(cls, OSError):
        return cls(message)
    return ValueError(message)


def open_source(fmt: FileFormat, path: Path, chunk: int) -> EventSource:
    """``fmt.open_source(path, chunk)`` run in a child: the same meta and packets."""
    _require_extra(fmt)
    child = _Child(fmt, path, ("source", chunk))
    tag, payload = child.next_message()
    if tag != _META:  # pragma: no cover - the child always sends the meta first
        child.close()
        raise ValueError(f"{str(path)!r}: the decoder process sent no header")
    meta, size_limit = payload

    def packets() -> Iterator[np.ndarray]:
        try:
            while True:
                tag, events = child.next_message()
                if tag == _DONE:
                    return
                yield events
        finally:
            child.close()

    return EventSource(meta, packets(), size_limit)


def read_window(fmt: FileFormat, path: Path, t_start_us: int, t_end_us: int) -> np.ndarray:
    """``hdf5.read_window`` run in a child."""
    child = _Child(fmt, path, ("window", t_start_us, t_end_us))
    try:
        tag, events = child.next_message()
        if tag != _EVENTS:  # pragma: no cover - the child sends one array, then DONE
            raise ValueError(f"{str(path)!r}: the decoder process sent no events")
        child.next_message()
        return events  # type: ignore[no-any-return]
    finally:
        child.close()


def _require_extra(fmt: FileFormat) -> None:
    """Name the missing extra here, in the caller's process, as the in-process path does."""
    extra = _EXTRAS.get(fmt.name)
    if extra is not None:
        from .._extras import require

        require(extra)


# ---------------------------------------------------------------------------------------------
# the child's side


def _send_events(connection: Any, events: np.ndarray) -> None:
    tag = _LABELED if events.dtype == LABELED_DTYPE else _EVENTS
    events = np.ascontiguousarray(events, dtype=_DTYPES[tag])
    connection.send_bytes(tag + len(events).to_bytes(8, "little"))
    connection.send_bytes(events.view(np.uint8))


def _child_main(connection: Any, format_name: str, path_text: str, job: tuple[Any, ...]) -> None:
    """Run one decode and send its results; never returns (``os._exit``)."""
    with contextlib.suppress(OSError):  # the decoder's own panic/backtrace output goes nowhere
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 2)
        os.close(devnull)
    status = 0
    try:
        from ._registry import FORMATS

        fmt = next(f for f in FORMATS.values() if f.name == format_name)
        path = Path(path_text)
        library = LIBRARIES.get(fmt.name, fmt.name)
        if job[0] == "source":
            assert fmt.open_source is not None
            with decoding(path, library):  # the same one-line errors as in the process itself
                source = fmt.open_source(path, int(job[1]))
            connection.send_bytes(_META)
            connection.send_bytes(pickle.dumps((source.meta, source.size_limit)))
            for packet in decoded(path, library, source.packets):
                _send_events(connection, packet)
        else:
            from . import hdf5

            with decoding(path, library):
                window = hdf5.read_window(path, int(job[1]), int(job[2]))
            _send_events(connection, window)
        connection.send_bytes(_DONE)
    except BaseException as err:  # noqa: BLE001 - PanicException included: everything goes back as one line
        with contextlib.suppress(BaseException):
            connection.send_bytes(_ERROR + pickle.dumps((type(err).__name__, one_line(err))))
        status = 1
    finally:
        with contextlib.suppress(BaseException):
            connection.close()
    os._exit(status)
