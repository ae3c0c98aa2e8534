"""File-level entry points that read, compute, draw and write: :func:`compare_files`,
:func:`compare_runs` (a Monte Carlo of N runs), :func:`info`, :func:`show` and
:func:`timing_report`. The only validation module that imports :mod:`evstwin.plots`.

Every recording is read once, chunk by chunk (:data:`READ_CHUNK` events at a time), into a
:class:`evstwin.analysis.CountedRecording` (per-pixel counts, first and last times, event
rate) plus the events of the figures' time slice: memory does not grow with its length."""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .. import analysis
from ..analysis import KINDS, nice_bin_s
from ..sensor import EVENT_DTYPE
from .comparison import Comparison, PathLike, _duration, _fmt, _label, _size, compare
from .montecarlo import MonteCarloSummary, aggregate
from .region import HOT_FALSE_ALARMS, Roi, RoiLike, check_mask_leaves_pixels, describe, hot_pixels, mask_array


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
    roi: RoiLike | None = None,
    mask_pixels: Sequence[tuple[int, int]] = (),
    mask_hot: bool = False,
    hot_false_alarms: float = HOT_FALSE_ALARMS,
    mask: np.ndarray | None = None,
) -> Comparison:
    """Read the recordings (any format :func:`evstwin.io.read_events` takes, in chunks),
    compare them, and write ``out_dir/compare.json`` (every number) and the figures:

    frames.png (Fig. 5: ``n_windows`` successive ``window_s`` windows overlaid, from
    ``t_offset_s`` after each recording's first event), xyt.png (Fig. 6, the same time slice),
    histograms.png (Fig. 7), percent_error.png (Fig. 8), bin_error.png (Fig. 9) and
    event_rate.png (bins of ``rate_bin_s`` [s]; default :func:`evstwin.analysis.nice_bin_s`
    of the real recording's span, about 100 bins, over the real recording's span).
    The written paths are in ``Comparison.outputs``. ``size`` (W, H) is the real recording's
    sensor size where its header has none. Every input is read and compared before
    ``out_dir`` is created.

    roi: ``(x0, y0, w, h)`` (or ``'X0,Y0,W,H'``): compare only this rectangle of the real
    sensor, every recording cut to it and shifted to its coordinates (a SIM already of the
    ROI's size, simulated with ``sensor.roi``, is taken as it is). mask_pixels: (x, y) pixels
    of the sensor left out of every statistic; mask_hot: also leave out the real recording's
    hot pixels (:func:`evstwin.validation.region.hot_pixels`, ``hot_false_alarms``); mask: a
    (h, w) bool array of the compared region, True = left out, added to those.
    """
    from .. import plots

    span_s = window_s * n_windows
    rate_bin_us = None if rate_bin_s is None else analysis._bin_us(rate_bin_s)
    real_rec, real_meta, real_slice = scan_recording(
        real_path, size, t_offset_s, span_s, rate_bin_us=rate_bin_us, roi=roi
    )
    the_roi = None if roi is None else Roi.of(roi)
    found = region_mask(real_rec, real_meta, the_roi, mask_pixels, mask_hot, hot_false_alarms)
    if mask is not None:
        mask = np.asarray(mask, dtype=bool) | (False if found is None else found)
        check_mask_leaves_pixels(mask, the_roi)
    else:
        mask = found
    sims = [scan_recording(p, None, t_offset_s, span_s, rate_bin_us=rate_bin_us, roi=the_roi) for p in sim_paths]
    comp = compare(
        real_rec,
        real_meta,
        [(rec, meta) for rec, meta, _ in sims],
        bin_width=bin_width,
        mask=mask,
        region=describe(the_roi, mask),
    )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    w, h = comp.real.width, comp.real.height
    recs = [(comp.real_label + " (real)", real_slice)] + [(s.label, sl) for s, (_, _, sl) in zip(comp.sims, sims)]
    counted = [real_rec] + [rec for rec, _, _ in sims]
    bin_s = rate_bin_s if rate_bin_s is not None else common_rate_bin_s(counted)
    rates = [rec.event_rate(bin_s) for rec in counted]
    outputs = _recording_figures(recs, w, h, out, window_s, n_windows, t_offset_s, bin_s, rates, _span_s(real_rec))
    outputs["histograms"] = plots.plot_comparison_histograms(comp, out / "histograms.png")
    outputs["percent_error"] = plots.plot_comparison_percent_error(comp, out / "percent_error.png")
    outputs["bin_error"] = plots.plot_comparison_bin_error(comp, out / "bin_error.png")
    comp.outputs = {k: str(v) for k, v in outputs.items()}
    comp.outputs["json"] = str(out / "compare.json")
    with open(out / "compare.json", "w", encoding="utf-8") as fh:
        json.dump(comp.to_json_dict(), fh, indent=1, allow_nan=False)
    return comp


def compare_runs(
    real: tuple[analysis.CountedRecording, Mapping[str, Any]],
    runs: Sequence[Sequence[PathLike]],
    labels: Sequence[str],
    out_dir: PathLike,
    bin_width: float = 2,
    roi: RoiLike | None = None,
    mask: np.ndarray | None = None,
) -> MonteCarloSummary:
    """The Monte Carlo of N runs (the paper's 20 seeds): compare the real recording (read by
    :func:`scan_recording`) with each run's simulated files (``runs[i]``: one path per
    simulation, called ``labels[j]``), aggregate, and draw ``out_dir/percent_error_mc.png``
    and ``bin_error_mc.png`` (mean +- 1 std). Returns the summary. ``real`` is already cut to
    ``roi`` (as :func:`scan_recording` with ``roi`` gives it); the runs are cut here, and
    ``mask`` (a (h, w) bool array of the ROI, True = left out) applies to all."""
    from .. import plots

    rec, meta = real
    the_roi = None if roi is None else Roi.of(roi)
    comparisons = []
    for paths in runs:
        sims = []
        for path, label in zip(paths, labels):
            sim_rec, sim_meta, _ = scan_recording(path, None, 0.0, 0.0, roi=the_roi)
            sims.append((sim_rec, dict(sim_meta, path=label)))
        comparisons.append(
            compare(rec, meta, sims, bin_width=bin_width, mask=mask, region=describe(the_roi, mask))
        )
    summary = aggregate(comparisons)
    plots.plot_monte_carlo(summary, Path(out_dir))
    return summary


def common_rate_bin_s(recs: Sequence[analysis.CountedRecording]) -> float:
    """One event-rate bin [s] for recordings drawn together: :func:`evstwin.analysis.nice_bin_s`
    of the first (real) recording's span, or the coarsest bin a longer one kept if that is
    larger (a power of ten [us]; either is a multiple of every kept bin)."""
    coarsest = max(rec.rate.bin_us for rec in recs) * 1e-6
    return max(nice_bin_s(_span_s(recs[0]) or 0.0), coarsest)


def _span_s(rec: analysis.CountedRecording) -> float | None:
    """First to last event + 1 us [s]; None for an empty recording."""
    return None if rec.t_start_us is None else (rec.t_end_us - rec.t_start_us + 1) * 1e-6


def region_mask(
    real: analysis.CountedRecording,
    real_meta: Mapping[str, Any],
    roi: Roi | None,
    mask_pixels: Sequence[tuple[int, int]] = (),
    mask_hot: bool = False,
    hot_false_alarms: float = HOT_FALSE_ALARMS,
    sensor_size: tuple[int, int] | None = None,
) -> np.ndarray | None:
    """The (h, w) mask of the compared region (the ROI, else the sensor): the listed pixels
    (sensor coordinates) and, with ``mask_hot``, the real recording's hot pixels; None when
    nothing is masked. ``sensor_size``: the sensor's (width, height) (default: the recording's
    own, which is the ROI's once cut, so give it whenever ``roi`` is set and pixels are
    listed). ValueError when no pixel is left."""
    if not mask_pixels and not mask_hot:
        return None
    w, h = sensor_size if sensor_size is not None else (int(real_meta["width"]), int(real_meta["height"]))
    if roi is not None and sensor_size is None:
        w, h = _sensor_size(real_meta, roi)
    mask = mask_array(mask_pixels, w, h, roi)
    if mask_hot:
        mask |= hot_pixels(real.pixel_counts()["total"], mask, hot_false_alarms)
    check_mask_leaves_pixels(mask, roi)
    return mask


def _sensor_size(meta: Mapping[str, Any], roi: Roi) -> tuple[int, int]:
    """The full sensor's size of a recording cut to ``roi`` (its meta keeps the file's size
    under 'sensor_width'/'sensor_height')."""
    return int(meta.get("sensor_width", roi.x0 + roi.width)), int(meta.get("sensor_height", roi.y0 + roi.height))


READ_CHUNK = 1_000_000
"""Events read at a time by the file-level functions (about 13 MB)."""


def scan_recording(
    path: PathLike,
    size: tuple[int, int] | None,
    t_offset_s: float,
    span_s: float | None,
    *,
    chunk: int | None = None,
    rate_bin_us: int | None = None,
    roi: RoiLike | None = None,
    span_events: Callable[[Mapping[str, Any]], int] | None = None,
) -> tuple[analysis.CountedRecording, dict[str, Any], np.ndarray]:
    """One pass over a recording, ``chunk`` events (default :data:`READ_CHUNK`) at a time:
    its :class:`~evstwin.analysis.CountedRecording` (event-rate bins of ``rate_bin_us``,
    default chosen as it goes), its meta (with the size found from the events where the file
    has none), and the events of the figures' slice [first + t_offset_s, first + t_offset_s +
    span_s), preceded by the first event (the figures measure their offset from it).
    ``span_s`` None: the slice is instead the first ``span_events(meta)`` events from
    first + t_offset_s (memory bounded whatever the recording's length).

    roi: cut every chunk to this rectangle of the file's sensor and shift it to the ROI's
    coordinates (the result is a ``w x h`` recording; ``meta['roi']`` says which), after
    checking the ROI lies on the sensor; a file that is already of the ROI's size (simulated
    with ``sensor.roi``) is read as it is. The figures' slice starts at the first event inside
    the ROI."""
    from ..io import iter_events

    stream = iter_events(path, chunk=chunk or READ_CHUNK, size=size)
    meta = dict(stream.meta)
    cut: Roi | None = None
    if roi is not None:
        r = Roi.of(roi)
        if (meta.get("width"), meta.get("height")) != (r.width, r.height):
            if meta.get("width") is not None and meta.get("height") is not None:
                r.check(int(meta["width"]), int(meta["height"]), f"{path}: roi")
            cut = r
        meta["width"], meta["height"] = r.width, r.height
    rec = analysis.CountedRecording.empty(meta.get("width"), meta.get("height"), rate_bin_us)
    wanted = span_events(meta) if span_s is None and span_events is not None else 0
    parts: list[np.ndarray] = []
    lo = hi = 0
    first_us: int | None = None  # the whole recording's span, before the cut
    last_us = 0
    for ev in stream:
        if cut is not None and len(ev):
            t = ev["t"]
            first_us = int(t.min()) if first_us is None else min(first_us, int(t.min()))
            last_us = max(last_us, int(t.max()))
            ev = cut.crop(ev)
        if len(ev) == 0:
            continue
        if rec.t_start_us is None:
            lo = int(ev["t"][0]) + round(t_offset_s * 1e6)
            hi = lo + round((span_s or 0.0) * 1e6)
            if int(ev["t"][0]) < lo:
                parts.append(ev[:1])
        rec.add(ev)
        if span_s is None:
            if wanted > 0:
                take = ev[ev["t"] >= lo][:wanted]
                parts.append(take)
                wanted -= len(take)
        elif span_s > 0:
            parts.append(ev[(ev["t"] >= lo) & (ev["t"] < hi)])
    meta = dict(stream.meta)  # with the size found from the events where the file has none
    meta.setdefault("path", str(path))
    if roi is not None:
        r = Roi.of(roi)
        if cut is not None:  # a file without a size: its events' extent is the sensor's
            r.check(int(meta["width"]), int(meta["height"]), f"{path}: roi")
            meta["sensor_width"], meta["sensor_height"] = int(meta["width"]), int(meta["height"])
            if first_us is not None:  # the ROI's duration is the recording's, not its own events' span
                meta.setdefault("duration_s", (last_us - first_us) * 1e-6)
        meta["width"], meta["height"], meta["roi"] = r.width, r.height, str(r)
    width, height = _size(meta, str(path))
    if width < 1 or height < 1:
        raise ValueError(f"{path}: no events and no sensor size in the file; give the size (--size W,H)")
    if (rec.width, rec.height) != (width, height):  # the size came from the events
        rec._grow(width, height)
    events = np.concatenate(parts) if parts else np.zeros(0, EVENT_DTYPE)
    if len(events) > 1 and bool(np.any(events["t"][1:] < events["t"][:-1])):
        events = events[np.argsort(events["t"], kind="stable")]
    return rec, meta, events


def info(path: PathLike, *, size: tuple[int, int] | None = None, chunk: int = READ_CHUNK) -> str:
    """A summary of one recording, as text, read ``chunk`` events at a time: memory does not
    grow with the recording (per-pixel counts and running totals are all it keeps), and the
    text is the same whatever ``chunk`` (a text file without a size header included: its
    size is the events' extent, known at the end)."""
    rec, meta, _ = scan_recording(path, size, 0.0, 0.0, chunk=chunk)
    return _info_text(meta, rec, _duration(rec, meta))


def format_info(events: np.ndarray, meta: Mapping[str, Any]) -> str:
    """The text of :func:`info` for events already in memory (the one-chunk case)."""
    width, height = _size(meta, str(meta.get("path", "recording")))
    rec = analysis.CountedRecording.from_chunks([events], width, height)
    return _info_text(meta, rec, _duration(events, meta))


def _info_text(meta: Mapping[str, Any], rec: analysis.CountedRecording, duration_s: float) -> str:
    st = rec.stats(duration_s)
    counts = rec.pixel_counts()["total"].reshape(-1)
    pixels = st.pixel_count
    active = int(np.count_nonzero(counts))
    size_note = {"events": " (from the events' extent)", "argument": " (--size)",
                 "plugin": " (from the camera plugin)"}.get(str(meta.get("size_source")), "")
    lines = [
        f"file          {meta.get('path', '')}",
        f"sensor        {st.width} x {st.height} px ({pixels} pixels){size_note}",
        f"events        {st.total} (ON {st.on}, OFF {st.off}), ON/OFF {_fmt(st.on_off_ratio, 4)}",
        f"time          {st.t_start_us} .. {st.t_end_us} us, duration {st.duration_s:.6g} s",
        f"mean rate     {_fmt(st.mean_rate_hz, 1)} events/s, {_fmt(st.mean_rate_hz / pixels, 4)} events/s per pixel",
        (
            f"per pixel     mean {counts.mean():.4g}, max {int(counts.max()) if counts.size else 0} events; "
            f"{active} pixels ({100 * active / pixels:.2f} %) have events"
        ),
    ]
    return "\n".join(lines)


FRAME_EVENTS_PER_PIXEL = 0.02
""":func:`show`'s default frame length holds about this many events per pixel of the sensor
(at least :data:`FRAME_EVENTS_MIN`): 1,800 on a DAVIS346, where the paper's 33 ms held a
handful of a slow GEO target's events."""
FRAME_EVENTS_MIN = 1000
SMALL_COUNTS = 20
"""Per-pixel counts up to this are drawn one bin per count (centred on it) by :func:`show`;
above, the paper's 2-event bins."""


def show(
    path: PathLike,
    out_dir: PathLike,
    bin_width: float | None = None,
    *,
    window_s: float | None = None,
    n_windows: int = 3,
    t_offset_s: float = 0.0,
    rate_bin_s: float | None = None,
    size: tuple[int, int] | None = None,
    notes: list[str] | None = None,
) -> dict[str, str]:
    """Draw one recording's figures into ``out_dir``: frames.png, xyt.png, histograms.png and
    event_rate.png (options as in :func:`compare_files`). Returns {figure: path}.

    window_s: each frame's length [s]; None: from the recording, so that a frame holds about
        :data:`FRAME_EVENTS_PER_PIXEL` events per pixel where it starts (a rounded length,
        the frames together at most what is left of the recording after ``t_offset_s``).
    bin_width: the count histograms' bin width [events]; None: one bin per count up to
        :data:`SMALL_COUNTS`, else the paper's 2.
    t_offset_s: must start before the recording's last event (ValueError otherwise).
    notes: where given, the choices made for the defaults are appended, as sentences."""
    from .. import plots

    def frame_events(meta: Mapping[str, Any]) -> int:
        pixels = int(meta.get("width") or 0) * int(meta.get("height") or 0)
        return n_windows * max(FRAME_EVENTS_MIN, round(FRAME_EVENTS_PER_PIXEL * pixels))

    rec, meta, events = scan_recording(path, size, t_offset_s, None if window_s is None else window_s * n_windows,
                                       rate_bin_us=None if rate_bin_s is None else analysis._bin_us(rate_bin_s),
                                       span_events=frame_events)
    span = _span_s(rec) or 0.0
    last_us = 0 if rec.t_start_us is None else rec.t_end_us - rec.t_start_us
    if t_offset_s > 0 and round(t_offset_s * 1e6) > last_us:
        raise ValueError(f"--t0 {t_offset_s:g} s is past the end of {path}: its events span {last_us / 1e6:.6g} s "
                         f"from the first; give --t0 below that")
    if window_s is None and rec.t_start_us is None:  # no events: nothing to choose from
        window_s = 0.033
    if window_s is None:
        assert rec.t_start_us is not None
        lo = rec.t_start_us + round(t_offset_s * 1e6)
        after = events[events["t"] >= lo]
        left_s = max(span - t_offset_s, 1e-6)
        n = after.size  # the span that holds them at their rate: n events over n - 1 gaps
        reach_s = (int(after["t"][-1]) - lo) * 1e-6 * n / (n - 1) if n >= frame_events(meta) else left_s
        window_s = _round_down_nice(max(min(reach_s, left_s) / n_windows, 1e-6))
        events = events[events["t"] < lo + round(window_s * n_windows * 1e6)]
        if notes is not None:
            notes.append(f"frames: {n_windows} of {window_s:g} s from --t0 (about {FRAME_EVENTS_PER_PIXEL:g} events "
                         f"per pixel each, at most the recording's span; --window to change)")
    width, height = rec.width, rec.height
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    recs = [(_label(str(meta["path"])), events)]
    counts = rec.pixel_counts()
    if bin_width is None:
        bin_width = 1 if int(counts["total"].max(initial=0)) <= SMALL_COUNTS else 2
    hists = {}
    edges = {}
    for k in KINDS:
        edges[k], hists[k] = analysis.count_histogram(counts[k], bin_width)
    bin_s = rate_bin_s if rate_bin_s is not None else common_rate_bin_s([rec])
    outputs = _recording_figures(recs, width, height, out, window_s, n_windows, t_offset_s, bin_s,
                                 [rec.event_rate(bin_s)], _span_s(rec))
    outputs["histograms"] = plots.plot_count_histograms(edges, [(recs[0][0], hists)], out / "histograms.png")
    return {k: str(v) for k, v in outputs.items()}


def _round_down_nice(x: float) -> float:
    """``x`` (> 0) rounded down to two significant digits (0.0166 -> 0.016, 3.33 -> 3.3)."""
    step = 10.0 ** (math.floor(math.log10(x)) - 1)
    return float(f"{math.floor(x / step * (1 + 1e-12)) * step:.12g}")


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


def timing_report(
    files: Sequence[PathLike],
    out_dir: PathLike,
    *,
    radius_px: float = 1.0,
    max_delay_s: float = 0.3,
    labels: Sequence[str] | None = None,
) -> tuple[dict[str, Any], str, Path]:
    """Event-timing bias of simulated files with ground truth (``.h5``/``.npz``): the
    :func:`timing_attribution` table of each file, summarised per target, polarity, flux and
    speed with ON and OFF apart, with the events no crossing explains (count and share, key
    'events'), written to ``out_dir/timing_bias.json`` and drawn as
    ``timing_bias.png`` (one file) or ``timing_by_setting.png`` (one row per file, called
    ``labels[i]``, default the file's name and the thresholds its scenario sets). Every file is read and checked before ``out_dir``
    is created. Returns (report, text, figure path)."""
    from .. import plots
    from ..io import read_events
    from .timing import (
        format_timing_bias_summary,
        format_unexplained,
        timing_attribution,
        timing_bias_summary,
    )

    if not radius_px > 0:
        raise ValueError(f"radius_px must be > 0 px; got {radius_px}")
    if not max_delay_s > 0:
        raise ValueError(f"max_delay_s must be > 0 s; got {max_delay_s}")
    tables: list[tuple[str, np.ndarray]] = []
    all_counts: list[dict[str, int]] = []
    for i, path in enumerate(files):
        events, meta = read_events(path)
        truth = meta.get("truth") or {}
        if not truth:
            raise ValueError(f"{path} holds no ground truth (/truth): simulate to .h5 or .npz first")
        label = labels[i] if labels is not None else _setting_label(path, meta)
        table, counts = timing_attribution(events, truth, radius_px=radius_px, max_delay_s=max_delay_s)
        tables.append((label, table))
        all_counts.append(counts)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report: dict[str, Any] = {}
    text: list[str] = []
    for (label, table), counts in zip(tables, all_counts):
        rows: dict[str, Any] = {by: timing_bias_summary(table, by=by, split_polarity=True)
                                for by in ("target", "polarity", "flux", "speed")}
        on_track = counts["attributed"] + counts["unexplained"]
        rows["events"] = dict(counts, unexplained_share=counts["unexplained"] / on_track if on_track else 0.0,
                              radius_px=radius_px, max_delay_s=max_delay_s)
        report[label] = rows
        text.append(f"== {label}: {format_unexplained(counts, max_delay_s)}")
        text.extend(format_timing_bias_summary(r, by=by) + "\n" for by, r in rows.items() if by != "events")
    if len(tables) == 1:
        png = plots.plot_timing_bias(tables[0][1], out / "timing_bias.png")
        report = report[tables[0][0]]
    else:
        png = plots.plot_timing_by_setting(tables, out / "timing_by_setting.png")
    with open(out / "timing_bias.json", "w", encoding="utf-8") as fh:
        json.dump(report, fh, indent=1, default=float)
    return report, "\n".join(text), png


def _setting_label(path: PathLike, meta: Mapping[str, Any]) -> str:
    """A file's name and the thresholds it was simulated with, when its scenario says."""
    scenario = meta.get("scenario")
    name = Path(path).name
    if isinstance(scenario, dict):
        try:
            from ..scenario import build

            p = build(scenario).params
            return f"{name}\ntheta {p.theta_on:.3g}/{p.theta_off:.3g}"
        except ValueError:
            return name
    return name
