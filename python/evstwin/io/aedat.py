"""AEDAT 4.0 (``.aedat4``, iniVation DV and DAVIS cameras): read packet by packet with the
``aedat`` package, written packet by packet with faery's AEDAT encoder (both in ``evstwin[io]``).

The writer emits packets of exactly ``PACKET`` events (the last one shorter), whatever the
chunks it is given, so the bytes do not depend on how the events were split into chunks.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from .. import _core
from .._extras import require
from ._common import (
    EventSource,
    FileFormat,
    WriteSpec,
    check_header_size,
    check_unsigned_times,
    decoded,
    decoding,
    from_packet,
    to_faery,
)

PACKET = 1 << 16  # events per AEDAT packet (DV writes a few thousand; readers stream per packet)


def _description(faery: Any, spec: WriteSpec) -> list[Any]:
    attribute = faery.aedat.DescriptionAttribute
    info = faery.aedat.DescriptionNode(
        name="info",
        path="/mainloop/Recorder/outInfo/0/info/",
        attributes={
            "sizeX": attribute(attribute_type="int", value=spec.width),
            "sizeY": attribute(attribute_type="int", value=spec.height),
            "source": attribute(attribute_type="string", value=f"evstwin {_core.__version__}"),
        },
        nodes=[],
    )
    stream = faery.aedat.DescriptionNode(
        name="0",
        path="/mainloop/Recorder/outInfo/0/",
        attributes={
            "compression": attribute(attribute_type="string", value="LZ4"),
            "originalOutputName": attribute(attribute_type="string", value="events"),
            "typeIdentifier": attribute(attribute_type="string", value="EVTS"),
        },
        nodes=[info],
    )
    return [
        faery.aedat.DescriptionNode(
            name="outInfo", path="/mainloop/Recorder/outInfo/", attributes={}, nodes=[stream]
        )
    ]


class Aedat4Encoder:
    """faery's AEDAT 4.0 encoder fed with packets of ``PACKET`` events."""

    def __init__(self, tmp: Path, spec: WriteSpec) -> None:
        faery = require("faery")
        self._encoder = faery.aedat.Encoder(
            path=tmp, description=_description(faery, spec), compression=faery.aedat.LZ4_DEFAULT
        )
        self._encoder.__enter__()
        self._pending: list[np.ndarray] = []
        self._pending_count = 0
        self._started = False

    def write(self, events: np.ndarray) -> None:
        if not self._started:
            check_unsigned_times(events, ".aedat4")
            self._started = True
        packets = to_faery(events)
        if self._pending_count:
            packets = np.concatenate([*self._pending, packets])
            self._pending, self._pending_count = [], 0
        full = (len(packets) // PACKET) * PACKET
        for start in range(0, full, PACKET):
            self._encoder.write(0, packets[start : start + PACKET])
        if full < len(packets):
            self._pending, self._pending_count = [packets[full:].copy()], len(packets) - full

    def close(self, spec: WriteSpec) -> None:
        if self._pending_count:
            self._encoder.write(0, np.concatenate(self._pending))
            self._pending, self._pending_count = [], 0
        self._encoder.__exit__(None, None, None)

    def abort(self) -> None:
        self._pending = []
        self._encoder.__exit__(None, None, None)


def open_source(path: Path, chunk: int) -> EventSource:
    aedat = require("aedat")
    with decoding(path, "aedat"):
        decoder = aedat.Decoder(path)
        streams = decoder.id_to_stream()
    event_ids = sorted(i for i, s in streams.items() if s.get("type") == "events")
    if not event_ids:
        raise ValueError(
            f"{str(path)!r}: no event stream (streams: {sorted({str(s.get('type')) for s in streams.values()})})"
        )
    stream_id = event_ids[0]
    stream = streams[stream_id]
    width, height = check_header_size(path, stream.get("width"), stream.get("height"))
    meta = {"width": width, "height": height, "stream_id": stream_id, "size_source": "header"}

    def packets() -> Iterator[np.ndarray]:
        for packet in decoder:
            if packet.get("stream_id") == stream_id and "events" in packet:
                yield from_packet(packet["events"], path)

    return EventSource(meta, decoded(path, "aedat", packets()))


FORMAT = FileFormat("aedat4", open_source, Aedat4Encoder, title="AEDAT 4.0")
