"""Prophesee files: RAW (``.raw``, EVT 3.0 and EVT 2.0) and DAT 2.0 (``.dat``, CD events).

Reading streams through faery's decoders (``evstwin[io]``), packet by packet. Writing streams
too: EVT 3.0 with the encoder below (it carries the time-high period, last time and last row
across chunks), EVT 2.0 and DAT with faery's encoders fed chunk by chunk.

A RAW file whose header has no geometry (Gen3 ``hal_plugin_gen3_fx3`` recordings carry only
``% plugin_name`` and the like) takes its size from the plugin name where it is known
(:data:`PLUGIN_SIZES`), else from the events (max + 1, known after the whole file was read).
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any, BinaryIO

import numpy as np

from .. import _core
from .._extras import require
from ._common import (
    EVT_SIZE_MAX,
    RAW_FORMATS,
    EventSource,
    FileFormat,
    Meta,
    WriteSpec,
    check_header_size,
    check_unsigned_times,
    decoded,
    decoding,
    from_columns,
    from_packet,
    to_faery,
)

_EVT3_T0_FREE_US = 60_000_000  # below this, EVT 3.0 keeps absolute times (t0 = 0 in the header)
_DAT_SPAN_MAX_US = (1 << 32) - 1  # DAT 2.0 carries t - t0 on 32 bits (faery does not unwrap)

# Sensor size (width, height) and EVT version of the Prophesee HAL plugins, for RAW headers
# without geometry. Source: openeb (github.com/prophesee-ai/openeb),
# hal_psee_plugins .../raw_constants.h, ``plugins_map`` (sensor_width_, sensor_height_,
# encodings_): Gen3.0/Gen3.1 = 640x480 VGA, Gen4.0/Gen4.1 = 1280x720 HD. IMX636 (EVK3/EVK4 HD):
# 1280x720 per Sony's IMX636 specification (and the geometry line of tests/data/imx636_cut_evt3.raw).
PLUGIN_SIZES: dict[str, tuple[int, int]] = {
    "hal_plugin_gen3_fx3": (640, 480),
    "hal_plugin_gen31_fx3": (640, 480),
    "hal_plugin_gen31_evk2": (640, 480),
    "hal_plugin_gen31_evk3": (640, 480),
    "hal_plugin_gen4_fx3": (1280, 720),
    "hal_plugin_gen4_evk2": (1280, 720),
    "hal_plugin_gen41_evk2": (1280, 720),
    "hal_plugin_gen41_evk3": (1280, 720),
    "hal_plugin_imx636_evk3": (1280, 720),
    "hal_plugin_imx636_evk4": (1280, 720),
}
# Plugins that only ever produced EVT 2.0 (openeb's plugins_map: encodings_ = {ENCODING_EVT2}).
_EVT2_ONLY_PLUGINS = frozenset({"hal_plugin_gen3_fx3", "hal_plugin_gen31_fx3", "hal_plugin_gen31_evk2"})
_GEOMETRY = re.compile(r"^geometry\s+(-?\d+)\s*x\s*(-?\d+)", re.IGNORECASE)
_FORMAT_SIZE = re.compile(r"(width|height)\s*=\s*(-?\d+)", re.IGNORECASE)
_KEY_SIZE = re.compile(r"^(width|height)\s+(-?\d+)\s*$", re.IGNORECASE)


# ---------------------------------------------------------------------------------------------
# headers


def prophesee_header(path: Path) -> str:
    """The ``% key value`` header lines of a Prophesee file, without the ``%``."""
    lines: list[str] = []
    with open(path, "rb") as f:
        while True:
            position = f.tell()
            if f.read(1) != b"%":
                break
            f.seek(position)
            lines.append(f.readline().decode("utf-8", "replace")[1:].strip())
    return "\n".join(line for line in lines if line)


def header_size(header: str) -> tuple[Any, Any] | None:
    """(width, height) declared by a RAW header (``geometry WxH``, ``format ...;width=..``,
    ``width``/``height`` lines), as found (not yet validated), or None."""
    found: dict[str, int] = {}
    for line in header.splitlines():
        geometry = _GEOMETRY.match(line)
        if geometry:
            return int(geometry.group(1)), int(geometry.group(2))
        if line.lower().startswith("format"):
            found.update((k.lower(), int(v)) for k, v in _FORMAT_SIZE.findall(line))
        key = _KEY_SIZE.match(line)
        if key:
            found[key.group(1).lower()] = int(key.group(2))
    if "width" in found and "height" in found:
        return found["width"], found["height"]
    return None


def header_value(header: str, key: str) -> str | None:
    for line in header.splitlines():
        name, _, value = line.partition(" ")
        if name == key:
            return value.strip()
    return None


# ---------------------------------------------------------------------------------------------
# EVT 3.0 encoder


class Evt3State:
    """What an EVT 3.0 stream remembers between chunks: the last TIME_HIGH period written, the
    last TIME_LOW time and the last EVT_ADDR_Y row (None: nothing written yet)."""

    def __init__(self) -> None:
        self.period = -1
        self.t: int | None = None
        self.y: int | None = None


def encode_evt3_words(
    t: np.ndarray, x: np.ndarray, y: np.ndarray, p: np.ndarray, state: Evt3State
) -> np.ndarray:
    """EVT 3.0 16-bit words for sorted events: TIME_HIGH for every 4096 us period up to each
    event, then TIME_LOW (when t changes), EVT_ADDR_Y (when y changes) and EVT_ADDR_X. ``state``
    continues the previous chunk's stream and is updated.

    t: times [us] from the file's t0, >= 0, sorted, at least one event. Returns uint16 words.
    """
    n = len(t)
    period = t >> 12
    previous = np.empty(n, np.int64)
    previous[0] = state.period
    previous[1:] = period[:-1]
    n_high = period - previous
    new_t = np.ones(n, bool)
    new_t[0] = state.t is None or int(t[0]) != state.t
    new_t[1:] = t[1:] != t[:-1]
    new_y = np.ones(n, bool)
    new_y[0] = state.y is None or int(y[0]) != state.y
    new_y[1:] = y[1:] != y[:-1]
    per_event = n_high + new_t + new_y + 1
    end = np.cumsum(per_event)
    start = end - per_event
    words = np.empty(int(end[-1]), np.uint16)
    owner = np.repeat(np.arange(n), n_high)
    step = np.arange(len(owner)) - np.repeat(np.cumsum(n_high) - n_high, n_high)
    words[start[owner] + step] = 0x8000 | ((previous[owner] + 1 + step) & 0xFFF)
    at = start + n_high
    words[at[new_t]] = 0x6000 | (t[new_t] & 0xFFF)
    at = at + new_t
    words[at[new_y]] = y[new_y].astype(np.int64) & 0x7FF
    at = at + new_y
    words[at] = 0x2000 | (p.astype(np.int64) << 11) | (x.astype(np.int64) & 0x7FF)
    state.period, state.t, state.y = int(period[-1]), int(t[-1]), int(y[-1])
    return words


class Evt3Encoder:
    """Prophesee EVT 3.0, encoded here rather than by faery.

    faery 0.7's EVT 3.0 encoder writes a TIME_HIGH word only when an event needs one, while its
    decoder (like the cameras' firmware convention) counts a 24-bit time wrap only between
    consecutive TIME_HIGH words; a recording longer than 2**24 us = 16.8 s with any 4.096 ms
    period without events came back with wrong times. This encoder writes one TIME_HIGH word per
    4.096 ms period, as the sensors do, so the times survive any span. The header (written with
    the first chunk) carries the sensor size and, when the first event is later than 60 s, a
    ``t0`` [us] that faery adds back.
    """

    def __init__(self, tmp: Path, spec: WriteSpec) -> None:
        self._spec = spec
        self._file: BinaryIO = open(tmp, "wb")  # noqa: SIM115 - closed by close/abort
        self._t0: int | None = None
        self._state = Evt3State()

    def _header(self, t0: int) -> bytes:
        spec = self._spec
        lines = [
            "% evt 3.0",
            f"% format EVT3;height={spec.height};width={spec.width}",
            f"% geometry {spec.width}x{spec.height}",
            f"% generator evstwin {_core.__version__}",
        ]
        if t0:
            lines.append(f"% t0 {t0}")
        lines.append("% end")
        return ("\n".join(lines) + "\n").encode("ascii")

    def write(self, events: np.ndarray) -> None:
        if self._t0 is None:
            check_unsigned_times(events, ".raw")
            first = int(events["t"][0])
            self._t0 = first if first > _EVT3_T0_FREE_US else 0
            self._file.write(self._header(self._t0))
        t = events["t"].astype(np.int64) - self._t0
        words = encode_evt3_words(t, events["x"], events["y"], events["p"], self._state)
        self._file.write(words.astype("<u2", copy=False).tobytes())

    def close(self, spec: WriteSpec) -> None:
        if self._t0 is None:  # no events: the header and a lone TIME_HIGH 0
            self._file.write(self._header(0))
            self._file.write(np.array([0x8000], "<u2").tobytes())
        self._file.close()

    def abort(self) -> None:
        self._file.close()


def _check_evt_size(spec: WriteSpec) -> None:
    if spec.width > EVT_SIZE_MAX or spec.height > EVT_SIZE_MAX:
        raise ValueError(
            f"EVT 2.0/3.0 .raw files hold sensors up to {EVT_SIZE_MAX}x{EVT_SIZE_MAX}; "
            f"got {spec.width}x{spec.height} (write .h5, .npz, .aedat4, .dat or .es instead)"
        )


class FaeryEncoder:
    """One of faery's encoders (EVT 2.0, DAT 2.0, ES) opened on the temporary file and fed
    chunk by chunk; ``convert`` turns ``EVENT_DTYPE`` events into what its ``write`` takes."""

    def __init__(self, encoder: Any, convert: Any) -> None:
        self._encoder = encoder
        self._convert = convert
        encoder.__enter__()

    def write(self, events: np.ndarray) -> None:
        self._encoder.write(self._convert(events))

    def close(self, spec: WriteSpec) -> None:
        self._encoder.__exit__(None, None, None)

    def abort(self) -> None:
        self._encoder.__exit__(None, None, None)


def open_raw_encoder(tmp: Path, spec: WriteSpec) -> Evt3Encoder | FaeryEncoder:
    _check_evt_size(spec)
    if spec.raw_format == "evt3":
        return Evt3Encoder(tmp, spec)
    faery = require("faery")
    encoder = faery.evt.Encoder(
        path=tmp, version="evt2", zero_t0=True, dimensions=(spec.width, spec.height), enforce_monotonic=True
    )
    first = [True]

    def convert(events: np.ndarray) -> dict[str, np.ndarray]:
        if first[0]:
            check_unsigned_times(events, ".raw")
            first[0] = False
        return {"events": to_faery(events)}

    return FaeryEncoder(encoder, convert)


class DatEncoder(FaeryEncoder):
    """faery's DAT 2.0 encoder; refuses a span over 2**32 us and a file without events."""

    def __init__(self, tmp: Path, spec: WriteSpec) -> None:
        faery = require("faery")
        self._first_t: int | None = None
        encoder = faery.dat.Encoder(tmp, "dat2", "cd", True, (spec.width, spec.height))
        super().__init__(encoder, self._to_dat)

    def _to_dat(self, events: np.ndarray) -> np.ndarray:
        if self._first_t is None:
            check_unsigned_times(events, ".dat")
            self._first_t = int(events["t"][0])
        span = int(events["t"][-1]) - self._first_t
        if span > _DAT_SPAN_MAX_US:
            raise ValueError(
                f".dat files hold 32-bit times: the recording spans {span} us > {_DAT_SPAN_MAX_US} us "
                "(write .raw with raw_format='evt2', .aedat4 or .h5 instead)"
            )
        faery_events = to_faery(events)
        out = np.empty(len(events), [("t", "=u8"), ("x", "=u2"), ("y", "=u2"), ("payload", "u1")])
        for name in ("t", "x", "y"):
            out[name] = faery_events[name]
        out["payload"] = faery_events["on"]
        return out

    def close(self, spec: WriteSpec) -> None:
        super().close(spec)
        if self._first_t is None:
            raise ValueError("faery cannot read back a .dat file without events; write .h5 or .raw instead")


# ---------------------------------------------------------------------------------------------
# reading


def open_raw_source(path: Path, chunk: int) -> EventSource:
    faery = require("faery")
    header = prophesee_header(path)
    declared = header_size(header)
    plugin = header_value(header, "plugin_name")
    meta: Meta = {}
    if declared is not None:
        width, height = check_header_size(path, *declared, limit=EVT_SIZE_MAX)
        fallback, meta["size_source"] = (width, height), "header"
    elif plugin in PLUGIN_SIZES:
        fallback, meta["size_source"] = PLUGIN_SIZES[plugin], "plugin"
    else:
        fallback, meta["size_source"] = (EVT_SIZE_MAX, EVT_SIZE_MAX), None  # any 11-bit address
    version_fallback = "evt2" if plugin in _EVT2_ONLY_PLUGINS else None
    with decoding(path, "faery"), faery.evt.Decoder(path, fallback, version_fallback) as decoder:
        version = str(decoder.version)
    if version not in RAW_FORMATS:
        raise ValueError(f"{str(path)!r}: {version} is not supported (faery decodes {RAW_FORMATS})")
    if meta["size_source"] is None:
        meta["width"], meta["height"] = None, None
    else:
        meta["width"], meta["height"] = fallback
    meta["raw_format"] = version
    if header:
        meta["raw_header"] = header

    def packets() -> Iterator[np.ndarray]:
        with faery.evt.Decoder(path, fallback, version_fallback) as decoder:
            for packet in decoder:
                if "events" in packet:
                    yield from_packet(packet["events"], path)

    return EventSource(meta, decoded(path, "faery", packets()), size_limit=EVT_SIZE_MAX)


def open_dat_source(path: Path, chunk: int) -> EventSource:
    faery = require("faery")
    declared = header_size(prophesee_header(path))
    if declared is not None:  # faery drops a size it cannot use: name it here instead
        check_header_size(path, *declared)
    with decoding(path, "faery"), faery.dat.Decoder(path, None, "dat2") as decoder:
        dimensions = decoder.dimensions
        event_type = decoder.event_type
    if event_type != "cd":
        raise ValueError(f"{str(path)!r}: DAT events of type {event_type!r}; only CD events are read")
    meta: Meta = {"width": None, "height": None, "size_source": None}
    if dimensions is not None:
        meta["width"], meta["height"] = check_header_size(path, *dimensions)
        meta["size_source"] = "header"

    def packets() -> Iterator[np.ndarray]:
        with faery.dat.Decoder(path, None, "dat2") as decoder:
            for events in decoder:
                yield from_columns([events["t"], events["x"], events["y"], events["payload"] > 0], path)

    return EventSource(meta, decoded(path, "faery", packets()))


RAW_FORMAT = FileFormat("raw", open_raw_source, open_raw_encoder, title="Prophesee RAW (EVT)")
DAT_FORMAT = FileFormat("dat", open_dat_source, DatEncoder, title="Prophesee DAT")
