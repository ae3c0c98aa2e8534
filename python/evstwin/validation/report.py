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

    real_events, real_meta = _read(real_path, size)
    sims = [_read(p) for p in sim_paths]
    comp = compare(real_events, real_meta, sims, bin_width=bin_width)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    w, h = comp.real.width, comp.real.height
    recs = [(comp.real_label + " (real)", real_events)] + [(s.label, e) for s, (e, _) in zip(comp.sims, sims)]
    bin_s = rate_bin_s if rate_bin_s is not None else nice_bin_s(comp.real.duration_s)
    outputs = _recording_figures(recs, w, h, out, window_s, n_windows, t_offset_s, bin_s)
    outputs["histograms"] = plots.plot_comparison_histograms(comp, out / "histograms.png")
    outputs["percent_error"] = plots.plot_comparison_percent_error(comp, out / "percent_error.png")
    outputs["bin_error"] = plots.plot_comparison_bin_error(comp, out / "bin_error.png")
    comp.outputs = {k: str(v) for k, v in outputs.items()}
    comp.outputs["json"] = str(out / "compare.json")
    with open(out / "compare.json", "w", encoding="utf-8") as fh:
        json.dump(comp.to_json_dict(), fh, indent=1, allow_nan=False)
    return comp


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
) -> dict[str, Path]:
    """The figures drawn of the recordings themselves, for compare_files and show alike:
    frames.png (Fig. 5), xyt.png (Fig. 6) and event_rate.png."""
    from .. import plots

    return {
        "frames": plots.plot_frames(
            recs, width, height, out / "frames.png", window_s=window_s, n_windows=n_windows, t_offset_s=t_offset_s
        ),
        "xyt": plots.plot_xyt(
            recs, width, height, out / "xyt.png", t_offset_s=t_offset_s, duration_s=window_s * n_windows
        ),
        "event_rate": plots.plot_event_rate(recs, out / "event_rate.png", bin_s=bin_s),
    }
