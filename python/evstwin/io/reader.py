"""Reading event files: :func:`iter_events` (chunks, memory O(chunk)), :func:`read_events`
(built on it) and :func:`read_time_window`; the label column of files that have one through
``read_events(path, labels=True)`` and ``iter_events(path).labeled()``."""

from __future__ import annotations

import numbers
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any, Literal, overload

import numpy as np

from ..sensor import EVENT_DTYPE
from . import _isolation, hdf5
from ._common import (
    SIZE_MAX,
    EventSource,
    FileFormat,
    Meta,
    PathLike,
    Size,
    check_header_size,
    decoded,
    decoding,
    rechunk,
    split_labels,
)
from ._registry import format_for


def _existing(path: PathLike) -> tuple[Path, FileFormat]:
    p = Path(os.fspath(path))
    fmt = format_for(p, "read")
    if not p.is_file():
        if p.exists():
            raise IsADirectoryError(f"cannot read events from {str(p)!r}: not a regular file")
        raise FileNotFoundError(f"no such event file: {str(p)!r}")
    return p, fmt


def _check_size_argument(size: Any) -> Size | None:
    if size is None:
        return None
    if (
        not isinstance(size, (tuple, list))
        or len(size) != 2
        or any(
            isinstance(v, bool) or not isinstance(v, numbers.Integral) or not 1 <= int(v) <= SIZE_MAX
            for v in size
        )
    ):
        raise ValueError(f"size must be (width, height), integers in [1, {SIZE_MAX}]; got {size!r}")
    return int(size[0]), int(size[1])


class EventStream:
    """The events of a file in chunks of at most ``chunk`` events, in the file's order.

    ``meta`` is the dict :func:`read_events` returns. Where the file carries no sensor size
    (text without a ``width=`` header, RAW without geometry and of an unknown plugin, HDF5/NPZ
    without ``width``/``height``) and no ``size`` was given, ``meta['width']`` and
    ``meta['height']`` are None until the iteration has reached the end, then max + 1 with
    ``meta['size_source'] = 'events'``. Each iteration reads the file again.

    Iterating gives ``EVENT_DTYPE`` arrays; :meth:`labeled` gives ``(events, labels)`` pairs
    from a file with a label column (``meta['has_labels']``).
    """

    def __init__(self, path: Path, fmt: FileFormat, chunk: int, size: Size | None) -> None:
        assert fmt.open_source is not None
        self.path = path
        self._format = fmt
        self._chunk = chunk
        self._size = size
        self._source: EventSource | None = self._open()
        self.meta: Meta = self._source.meta

    def _open(self) -> EventSource:
        assert self._format.open_source is not None
        library = _isolation.LIBRARIES.get(self._format.name, self._format.name)
        if _isolation.isolated(self._format):
            source = _isolation.open_source(self._format, self.path, self._chunk)
        else:
            with decoding(self.path, library):
                source = self._format.open_source(self.path, self._chunk)
            source.packets = decoded(self.path, library, source.packets)
        meta = source.meta
        meta.update(format=self._format.name, path=str(self.path))
        if self._size is not None:
            meta["width"], meta["height"] = self._size
            meta["size_source"] = "argument"
        elif meta.get("width") is not None and meta.get("height") is not None:
            meta.setdefault("size_source", "header")
        else:
            meta["width"] = meta["height"] = None
            meta["size_source"] = None
        if meta["size_source"] == "header":  # validated again: HDF5, NPZ and text leave it to us
            meta["width"], meta["height"] = check_header_size(
                self.path, meta["width"], meta["height"], source.size_limit
            )
        meta["size_inferred"] = meta["size_source"] is None
        meta["has_labels"] = bool(meta.get("has_labels", False))
        return source

    def __iter__(self) -> Iterator[np.ndarray]:
        for packet in self._packets():
            yield split_labels(packet)[0]

    def labeled(self) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """The events in chunks as :meth:`__iter__` gives them, each with its labels: uint8 codes
        of ``EVENT_LABELS``, one per event, in the same order. ValueError naming the file when
        it has no label column (``meta['has_labels']`` False)."""
        if not self.meta.get("has_labels"):
            raise ValueError(
                f"{str(self.path)!r} has no label column (only .h5/.hdf5, .npz, .txt and .csv files "
                "written with labels have one: simulate(..., labels=True), evstwin simulate --labels)"
            )
        for packet in self._packets():
            events, labels = split_labels(packet)
            assert labels is not None  # the source yields labelled packets when has_labels
            yield events, labels

    def _packets(self) -> Iterator[np.ndarray]:
        source = self._source if self._source is not None else self._open()
        self._source = None
        meta = source.meta
        self.meta = meta
        width, height = meta["width"], meta["height"]
        x_max = y_max = -1
        for chunk in rechunk(source.packets, self._chunk):
            cx, cy = int(chunk["x"].max()), int(chunk["y"].max())
            if width is not None and (cx >= width or cy >= height):
                given = "the size given" if meta["size_source"] == "argument" else "the declared"
                raise ValueError(
                    f"{str(self.path)!r}: events reach x = {cx}, y = {cy}, outside {given} "
                    f"{width}x{height} sensor"
                )
            x_max, y_max = max(x_max, cx), max(y_max, cy)
            yield chunk
        if width is None:
            meta["width"], meta["height"] = x_max + 1, y_max + 1
            meta["size_source"] = "events"


def iter_events(
    path: PathLike, *, chunk: int = 1_000_000, size: tuple[int, int] | None = None
) -> EventStream:
    """Open an event file for reading in chunks; iterate the result for ``EVENT_DTYPE`` arrays
    of at most ``chunk`` events (memory O(chunk), whatever the file's length).

    path: the file; its suffix picks the format (see :mod:`evstwin.io`).
    chunk: the most events per array (default one million).
    size: (width, height) [pixels]: overrides the file's own size (always wins) and is checked
        against the events (ValueError naming the file when one falls outside).

    Returns an :class:`EventStream`: ``.meta`` as :func:`read_events` gives it (see there),
    iterable (again and again) over the events in the file's order; :func:`read_events` sorts
    a file that is not sorted by time, this does not. ``.labeled()`` iterates ``(events,
    labels)`` pairs instead, for a file with a label column.
    """
    p, fmt = _existing(path)
    if isinstance(chunk, bool) or not isinstance(chunk, numbers.Integral) or chunk < 1:
        raise ValueError(f"chunk must be a positive int (events per array); got {chunk!r}")
    return EventStream(p, fmt, int(chunk), _check_size_argument(size))


@overload
def read_events(
    path: PathLike, *, t0_zero: bool = ..., size: tuple[int, int] | None = ..., labels: Literal[False] = ...
) -> tuple[np.ndarray, Meta]: ...


@overload
def read_events(
    path: PathLike, *, t0_zero: bool = ..., size: tuple[int, int] | None = ..., labels: Literal[True]
) -> tuple[np.ndarray, Meta, np.ndarray]: ...


def read_events(
    path: PathLike, *, t0_zero: bool = False, size: tuple[int, int] | None = None, labels: bool = False
) -> tuple[np.ndarray, Meta] | tuple[np.ndarray, Meta, np.ndarray]:
    """Read an event file into an ``EVENT_DTYPE`` array sorted by ``t``.

    path: the file; its suffix picks the format (see :mod:`evstwin.io`).
    t0_zero: if True, subtract the first event's time so that ``t`` starts at 0 [us]; the
        subtracted origin is returned as ``meta['t0_us']``. Default False: times are the
        recording's own, in microseconds.
    size: (width, height) [pixels] overriding the file's own size (checked against the events).
    labels: if True, also return the file's label column: why each event fired, uint8 codes of
        ``EVENT_LABELS`` (0 signal, 1 shot_noise, 2 leak, 3 background, 4 hot_pixel), one per
        event in the order of the returned events (sorted with them). Only ``.h5``/``.hdf5``,
        ``.npz``, ``.txt`` and ``.csv`` files have one; a file without it raises ValueError
        (``meta['has_labels']`` tells beforehand, from ``iter_events(path).meta``).

    Returns ``(events, meta)``, or ``(events, meta, labels)`` with ``labels=True``. ``meta`` always has ``width`` and ``height`` [pixels],
    ``size_source`` (``'header'``, ``'plugin'`` for a RAW header naming a known Prophesee
    plugin, ``'events'`` when taken as max + 1, ``'argument'``), ``size_inferred`` (True for
    ``'events'``), ``format`` (``'hdf5'``, ``'npz'``, ``'txt'``, ``'csv'``, ``'aedat4'``,
    ``'raw'``, ``'dat'`` or ``'es'``) and ``path`` (str), plus what the file holds:
    ``evstwin_version``, ``scenario`` (a dict when it was written from a dict, else a str),
    ``truth`` (name -> field -> array), ``raw_format`` (``'evt3'``/``'evt2'``), ``has_labels``
    (whether the file has a label column, always present), ``resorted``
    (True when the file was not sorted by time), and any extra scalars written in ``meta``.

    Raises FileNotFoundError if the file does not exist, ValueError for an unknown suffix, a
    file that cannot be decoded, or a size that is invalid or contradicted by the events.
    """
    stream = iter_events(path, size=size)
    codes: np.ndarray | None = None
    if labels:
        pairs = list(stream.labeled())
        chunks = [events for events, _ in pairs]
        codes = np.concatenate([c for _, c in pairs]) if pairs else np.empty(0, np.uint8)
    else:
        chunks = list(stream)
    meta = stream.meta
    events = np.concatenate(chunks) if chunks else np.empty(0, EVENT_DTYPE)
    if meta["width"] is None or meta["height"] is None:  # pragma: no cover - set by the iteration
        raise AssertionError("size unknown after reading")
    t = events["t"]
    if len(t) > 1 and bool(np.any(t[1:] < t[:-1])):
        order = np.argsort(t, kind="stable")
        events = events[order]
        codes = None if codes is None else codes[order]
        meta["resorted"] = True
    if t0_zero and len(events):
        t0 = int(events["t"][0])
        events["t"] -= t0
        meta["t0_us"] = t0
    if codes is not None:
        return events, meta, codes
    return events, meta


def read_time_window(path: PathLike, t_start_us: int, t_end_us: int) -> np.ndarray:
    """The events with ``t_start_us <= t < t_end_us`` [us, the file's own times], sorted by ``t``.

    HDF5 files written by evstwin (and DSEC files) carry ``/ms_to_idx``: the window is found
    from it and read without scanning. HDF5 files without it are bisected on ``/events/t``;
    the other formats are scanned chunk by chunk (memory O(chunk + window)).
    """
    for name, value in (("t_start_us", t_start_us), ("t_end_us", t_end_us)):
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            raise TypeError(f"{name} must be an int [us]; got {value!r}")
    if t_end_us < t_start_us:
        raise ValueError(f"t_end_us = {t_end_us} is before t_start_us = {t_start_us}")
    p, fmt = _existing(path)
    if fmt.name == "hdf5":
        if _isolation.isolated(fmt):
            return _isolation.read_window(fmt, p, int(t_start_us), int(t_end_us))
        return hdf5.read_window(p, int(t_start_us), int(t_end_us))
    parts = [c[(c["t"] >= t_start_us) & (c["t"] < t_end_us)] for c in iter_events(p)]
    events = np.concatenate(parts) if parts else np.empty(0, EVENT_DTYPE)
    t = events["t"]
    if len(t) > 1 and bool(np.any(t[1:] < t[:-1])):
        events = events[np.argsort(t, kind="stable")]
    return events
