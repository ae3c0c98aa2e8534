"""File-level entry points that compute, draw and write: compare_files, info, show. The only validation module that imports plots."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .. import analysis
from ..analysis import KINDS
from ..sensor import EVENT_DTYPE
from .comparison import Comparison, PathLike, _duration, _fmt, _label, _size, compare


def _read(path: PathLike, size: tuple[int, int] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
    from ..io import read_events  # lazy: io is optional at import time

    events, meta = read_events(path, size=size)
    meta = dict(meta)
    meta.setdefault("path", str(path))
    return events, meta


def nice_bin_s(duration_s: float, target_bins: int = 100) -> float:
    """A 1-2-5 bin width [s] giving about ``target_bins`` bins over ``duration_s``."""
    if not duration_s > 0:
        return 1e-3
    raw = duration_s / target_bins
    exp = math.floor(math.log10(raw))
    for m in (1, 2, 5, 10):
        if m * 10.0**exp >= raw:
            return m * 10.0**exp
    return 10.0 ** (exp + 1)


def compare_files(
    real_path: PathLike,
    sim_paths: Sequence[PathLike],
    out_dir: PathLike,
    bin_width: float = 2,
    *,
    window_s: float = 0.033,
    n_windows: int = 3,
    t_offset_s: float = 0.0,
    rate_bin_s: float | None = None,
    size: tuple[int, int] | None = None,
) -> Comparison:
    """Read the recordings (any format :func:`evstwin.io.read_events` takes), compare them,
    and write ``out_dir/compare.json`` (every number) and the figures:

    frames.png (Fig. 5: ``n_windows`` successive ``window_s`` windows overlaid, from
    ``t_offset_s`` after each recording's start), xyt.png (Fig. 6, the same time slice),
    histograms.png (Fig. 7), percent_error.png (Fig. 8), bin_error.png (Fig. 9) and
    event_rate.png (bins of ``rate_bin_s``, default about 1/100 of the real duration).
    The written paths are in ``Comparison.outputs``. ``size`` (W, H) is the real recording's
    sensor size where its header has none. Every input is read and compared before
    ``out_dir`` is created.
    """
    from .. import plots

    # Every recording is read once in chunks for its counts and the events of the figures'
    # time slice, and once more for its event rate: memory does not grow with its length.
    span_s = window_s * n_windows
    real_rec, real_meta, real_slice = scan_recording(real_path, size, t_offset_s, span_s)
    sims = [scan_recording(p, None, t_offset_s, span_s) for p in sim_paths]
    comp = compare(real_rec, real_meta, [(rec, meta) for rec, meta, _ in sims], bin_width=bin_width)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    w, h = comp.real.width, comp.real.height
    recs = [(comp.real_label + " (real)", real_slice)] + [(s.label, sl) for s, (_, _, sl) in zip(comp.sims, sims)]
    bin_s = rate_bin_s if rate_bin_s is not None else nice_bin_s(comp.real.duration_s)
    rates = [_rate(p, r, bin_s, sz) for p, r, sz in [(real_path, real_rec, size)]
             + [(p, rec, None) for p, (rec, _, _) in zip(sim_paths, sims)]]
    real_span = (real_rec.t_end_us - real_rec.t_start_us + 1) * 1e-6 if real_rec.t_start_us is not None else None
    outputs = _recording_figures(recs, w, h, out, window_s, n_windows, t_offset_s, bin_s, rates, real_span)
    outputs["histograms"] = plots.plot_comparison_histograms(comp, out / "histograms.png")
    outputs["percent_error"] = plots.plot_comparison_percent_error(comp, out / "percent_error.png")
    outputs["bin_error"] = plots.plot_comparison_bin_error(comp, out / "bin_error.png")
    comp.outputs = {k: str(v) for k, v in outputs.items()}
    comp.outputs["json"] = str(out / "compare.json")
    with open(out / "compare.json", "w", encoding="utf-8") as fh:
        json.dump(comp.to_json_dict(), fh, indent=1, allow_nan=False)
    return comp


READ_CHUNK = 1_000_000
"""Events read at a time by the file-level functions (about 13 MB)."""


def scan_recording(
    path: PathLike, size: tuple[int, int] | None, t_offset_s: float, span_s: float
) -> tuple[analysis.CountedRecording, dict[str, Any], np.ndarray]:
    """One pass over a recording: its per-pixel counts, its meta, and the events of the
    figures' slice [first + t_offset_s, first + t_offset_s + span_s), preceded by the first
    event (the figures measure their offset from a recording's first event)."""
    from ..io import iter_events

    stream = iter_events(path, chunk=READ_CHUNK, size=size)
    meta = dict(stream.meta)
    meta.setdefault("path", str(path))
    if not (meta.get("width") and meta.get("height")):  # a text file without a size header
        events, meta = _read(path, size)
        width, height = _size(meta, str(path))
        return analysis.CountedRecording.from_chunks([events], width, height), meta, events
    width, height = _size(meta, str(path))
    rec = analysis.CountedRecording.empty(width, height)
    parts: list[np.ndarray] = []
    lo = hi = 0
    for ev in stream:
        if len(ev) == 0:
            continue
        if rec.t_start_us is None:
            lo = int(ev["t"][0]) + round(t_offset_s * 1e6)
            hi = lo + round(span_s * 1e6)
            if int(ev["t"][0]) < lo:
                parts.append(ev[:1])
        rec.add(ev)
        parts.append(ev[(ev["t"] >= lo) & (ev["t"] < hi)])
    events = np.concatenate(parts) if parts else np.zeros(0, EVENT_DTYPE)
    return rec, meta, events


def _rate(
    path: PathLike, rec: analysis.CountedRecording, bin_s: float, size: tuple[int, int] | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The event-rate curve of a recording, in a second pass over its chunks."""
    from ..io import iter_events

    if rec.t_start_us is None:
        empty = np.zeros(0)
        return empty, empty.copy(), empty.copy()
    return analysis.event_rate_chunks(iter_events(path, chunk=READ_CHUNK, size=size), bin_s,
                                      rec.t_start_us, rec.t_end_us + 1)


def info(path: PathLike, *, size: tuple[int, int] | None = None, chunk: int = 1_000_000) -> str:
    """A summary of one recording, as text, read ``chunk`` events at a time: memory does not
    grow with the recording (per-pixel counts and running totals are all it keeps). A text
    file without a size header is read whole, its size being known only from its events."""
    from ..io import iter_events

    stream = iter_events(path, chunk=chunk, size=size)
    meta = dict(stream.meta)
    meta.setdefault("path", str(path))
    if not (meta.get("width") and meta.get("height")):
        events, meta = _read(path, size)
        return format_info(events, meta)
    width, height = _size(meta, str(path))
    counts = np.zeros(width * height, np.int64)
    total = on = 0
    t_first: int | None = None
    t_last = 0
    for ev in stream:
        if len(ev) == 0:
            continue
        counts += np.bincount(ev["y"].astype(np.int64) * width + ev["x"], minlength=counts.size)
        total += len(ev)
        on += int(np.count_nonzero(ev["p"]))
        t_first = int(ev["t"][0]) if t_first is None else t_first
        t_last = int(ev["t"][-1])
    duration = meta.get("duration_s")
    if duration is None:
        duration = (t_last - t_first) * 1e-6 if t_first is not None else 0.0
    return _info_text(meta, width, height, total, on, t_first or 0, t_last, float(duration), counts)


def format_info(events: np.ndarray, meta: Mapping[str, Any]) -> str:
    """The text of :func:`info` for events already in memory."""
    width, height = _size(meta, str(meta.get("path", "recording")))
    st = analysis.stats(events, width, height, _duration(events, meta))
    counts = analysis.pixel_counts(events, width, height)["total"].reshape(-1)
    return _info_text(meta, width, height, st.total, st.on, st.t_start_us, st.t_end_us, st.duration_s, counts)


def _info_text(meta: Mapping[str, Any], width: int, height: int, total: int, on: int, t_start_us: int,
               t_end_us: int, duration_s: float, counts: np.ndarray) -> str:
    off = total - on
    pixels = width * height
    rate = total / duration_s if duration_s > 0 else math.nan
    active = int(np.count_nonzero(counts))
    lines = [
        f"file          {meta.get('path', '')}",
        f"sensor        {width} x {height} px ({pixels} pixels)",
        f"events        {total} (ON {on}, OFF {off}), ON/OFF {_fmt(analysis.ratio(on, off), 4)}",
        f"time          {t_start_us} .. {t_end_us} us, duration {duration_s:.6g} s",
        f"mean rate     {_fmt(rate, 1)} events/s, {_fmt(rate / pixels, 4)} events/s per pixel",
        (
            f"per pixel     mean {counts.mean():.4g}, max {int(counts.max()) if counts.size else 0} events; "
            f"{active} pixels ({100 * active / pixels:.2f} %) have events"
        ),
    ]
    return "\n".join(lines)


def show(
    path: PathLike,
    out_dir: PathLike,
    bin_width: float = 2,
    *,
    window_s: float = 0.033,
    n_windows: int = 3,
    t_offset_s: float = 0.0,
    rate_bin_s: float | None = None,
    size: tuple[int, int] | None = None,
) -> dict[str, str]:
    """Draw one recording's figures into ``out_dir``: frames.png, xyt.png, histograms.png and
    event_rate.png (options as in :func:`compare_files`). Returns {figure: path}."""
    from .. import plots

    events, meta = _read(path, size)
    width, height = _size(meta, str(path))
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    st = analysis.stats(events, width, height, _duration(events, meta))
    recs = [(_label(str(meta["path"])), events)]
    counts = analysis.pixel_counts(events, width, height)
    hists = {}
    edges = {}
    for k in KINDS:
        edges[k], hists[k] = analysis.count_histogram(counts[k], bin_width)
    bin_s = rate_bin_s if rate_bin_s is not None else nice_bin_s(st.duration_s)
    outputs = _recording_figures(recs, width, height, out, window_s, n_windows, t_offset_s, bin_s)
    outputs["histograms"] = plots.plot_count_histograms(edges, [(recs[0][0], hists)], out / "histograms.png")
    return {k: str(v) for k, v in outputs.items()}


def _recording_figures(
    recs: Sequence[tuple[str, np.ndarray]],
    width: int,
    height: int,
    out: Path,
    window_s: float,
    n_windows: int,
    t_offset_s: float,
    bin_s: float,
    rates: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None,
    span_s: float | None = None,
) -> dict[str, Path]:
    """The figures drawn of the recordings themselves, for compare_files and show alike:
    frames.png (Fig. 5), xyt.png (Fig. 6) and event_rate.png (from ``rates`` where the
    recordings were read in chunks)."""
    from .. import plots

    return {
        "frames": plots.plot_frames(
            recs, width, height, out / "frames.png", window_s=window_s, n_windows=n_windows, t_offset_s=t_offset_s
        ),
        "xyt": plots.plot_xyt(
            recs, width, height, out / "xyt.png", t_offset_s=t_offset_s, duration_s=window_s * n_windows
        ),
        "event_rate": plots.plot_event_rate(recs, out / "event_rate.png", bin_s=bin_s, curves=rates, span_s=span_s),
    }
