"""Regenerate the small cuts of the real recordings in this folder (run once, by hand).

    python tests/data/make_cuts.py [SHARED_DATA_DIR]

davis346_road_cut.aedat4: the first 2000 events of davis346_road.aedat4, with the first
    APS frame and the IMU samples and triggers of the same time span, re-encoded packet by
    packet with faery's AEDAT 4.0 encoder (LZ4) under the original stream description.
imx636_cut_evt3.raw: the original EVT 3.0 header and the words of imx636_pointsource_evt3.raw
    up to the one that completes event 5000: the camera's own encoding, cut at a word
    boundary, not re-encoded.
"""

from __future__ import annotations

import sys
from pathlib import Path

import faery
import numpy as np

HERE = Path(__file__).resolve().parent
AEDAT_EVENTS = 2000
RAW_EVENTS = 5000


def cut_aedat(source: Path, target: Path) -> None:
    kept = 0
    frames = 0
    t_end = None
    with faery.aedat.Decoder(source) as decoder:
        description = decoder.description()
        packets = []
        for track, packet in decoder:
            if track.data_type == "events":
                if kept >= AEDAT_EVENTS:
                    break
                packet = packet[: AEDAT_EVENTS - kept]
                kept += len(packet)
                t_end = int(packet["t"][-1])
            elif isinstance(packet, faery.aedat.Frame):
                frames += 1
                if frames > 1:  # one frame is enough to exercise the readers; keeps < 200 KB
                    continue
            elif t_end is not None and kept >= AEDAT_EVENTS and int(packet["t"][0]) > t_end:
                continue
            packets.append((track.id, packet))
    with faery.aedat.Encoder(target, description, faery.aedat.LZ4_HIGHEST) as encoder:
        for track_id, packet in packets:
            encoder.write(track_id, packet)


def cut_raw(source: Path, target: Path) -> None:
    data = source.read_bytes()
    header_end = 0
    while data[header_end : header_end + 1] == b"%":
        header_end = data.index(b"\n", header_end) + 1
    words = np.frombuffer(data[header_end:], "<u2")
    kind = words >> 12
    counts = np.zeros(len(words), np.int64)
    counts[kind == 0x2] = 1  # EVT_ADDR_X
    bits12 = np.unpackbits((words & 0xFFF).astype(">u2").view(np.uint8)).reshape(-1, 16).sum(axis=1)
    bits8 = np.unpackbits((words & 0xFF).astype(">u2").view(np.uint8)).reshape(-1, 16).sum(axis=1)
    counts[kind == 0x4] = bits12[kind == 0x4]  # VECT_12
    counts[kind == 0x5] = bits8[kind == 0x5]  # VECT_8
    last = int(np.searchsorted(np.cumsum(counts), RAW_EVENTS))
    target.write_bytes(data[:header_end] + words[: last + 1].tobytes())


def main() -> None:
    shared = Path(sys.argv[1]) if len(sys.argv) > 1 else HERE.parents[2] / "shared" / "data"
    cut_aedat(shared / "davis346_road.aedat4", HERE / "davis346_road_cut.aedat4")
    cut_raw(shared / "imx636_pointsource_evt3.raw", HERE / "imx636_cut_evt3.raw")


if __name__ == "__main__":
    main()
