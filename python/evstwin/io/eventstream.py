"""Event Stream (``.es``, DVS events): read and written chunk by chunk with faery (``evstwin[io]``).

ES stores ``y`` from the bottom row (faery flips it both ways) and has no time origin field:
times are written as they are, so a first event later than 60 s is refused (it would be
preceded by megabytes of overflow bytes).
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from .._extras import require
from ._common import (
    EventSource,
    FileFormat,
    Meta,
    WriteSpec,
    check_header_size,
    check_unsigned_times,
    decoded,
    decoding,
    from_packet,
    to_faery,
)
from .prophesee import FaeryEncoder

_ES_T_MAX_US = 60_000_000  # ES has no t0: an origin later than this costs > 0.5 MB of padding


class EsEncoder(FaeryEncoder):
    """faery's ES encoder (DVS events, times as they are)."""

    def __init__(self, tmp: Path, spec: WriteSpec) -> None:
        faery = require("faery")
        self._height = spec.height
        self._started = False
        encoder = faery.es.Encoder(
            path=tmp, event_type="dvs", zero_t0=False, dimensions=(spec.width, spec.height)
        )
        super().__init__(encoder, self._to_es)

    def _to_es(self, events: np.ndarray) -> np.ndarray:
        if not self._started:
            check_unsigned_times(events, ".es")
            first = int(events["t"][0])
            if first > _ES_T_MAX_US:
                raise ValueError(
                    f".es files have no time origin field: a first event at t = {first} us would be "
                    f"padded with overflow bytes (limit {_ES_T_MAX_US} us); subtract events['t'][0] first or "
                    "write .raw/.aedat4/.h5 instead"
                )
            self._started = True
        out = to_faery(events)
        out["y"] = self._height - 1 - out["y"]
        return out


def open_source(path: Path, chunk: int) -> EventSource:
    faery = require("faery")
    with decoding(path, "faery"):
        stream = faery.events_stream_from_file(path, file_type="es")
        width, height = stream.dimensions()
    meta: Meta = {"size_source": "header"}
    meta["width"], meta["height"] = check_header_size(path, width, height)

    def packets() -> Iterator[np.ndarray]:
        for packet in stream:
            yield from_packet(packet, path)

    return EventSource(meta, decoded(path, "faery", packets()))


FORMAT = FileFormat("es", open_source, EsEncoder, title="Event Stream")
