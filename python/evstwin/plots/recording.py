"""Figures of one or more recordings: frames, x-y-t, per-pixel count histograms, event rate."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import analysis
from .._extras import require
from ..analysis import KINDS

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.colors import to_rgb
    from matplotlib.figure import Figure
    from matplotlib.ticker import MaxNLocator
else:
    to_rgb = require("matplotlib.colors").to_rgb
    Figure = require("matplotlib.figure").Figure
    MaxNLocator = require("matplotlib.ticker").MaxNLocator
from .style import (
    DPI,
    KIND_COLOURS,
    KIND_LABELS,
    MAX_SCATTER_POINTS,
    OFF_COLOUR,
    ON_COLOUR,
    LabelledEvents,
    PathLike,
    _unit,
    _value_label,
    save,
    subsample,
)


def frame_rgb(on: np.ndarray, off: np.ndarray, saturate: float = 2.0) -> np.ndarray:
    """An RGB image of a frame on white: ON pixels tinted ON_COLOUR, OFF pixels OFF_COLOUR,
    full colour at ``saturate`` events (pixels with both are a darker mix)."""
    a_on = np.clip(on / saturate, 0, 1)[..., None]
    a_off = np.clip(off / saturate, 0, 1)[..., None]
    c_on = np.array(to_rgb(ON_COLOUR))
    c_off = np.array(to_rgb(OFF_COLOUR))
    rgb = 1.0 - a_on * (1.0 - c_on) - a_off * (1.0 - c_off)
    return np.clip(rgb, 0.0, 1.0)


def _window(events: np.ndarray, t_offset_s: float, duration_s: float) -> tuple[int, int]:
    t0 = int(events["t"][0]) if events.size else 0
    start = t0 + round(t_offset_s * 1e6)
    return start, start + round(duration_s * 1e6)


def fig_frames(
    recordings: Sequence[LabelledEvents],
    width: int,
    height: int,
    window_s: float = 0.033,
    n_windows: int = 3,
    t_offset_s: float = 0.0,
    figsize: tuple[float, float] | None = None,
) -> Figure:
    """Fig. 5: ``n_windows`` successive ``window_s`` frames overlaid, one panel per recording
    (real first), each from ``t_offset_s`` after the recording's first event."""
    n = len(recordings)
    if figsize is None:
        figsize = (max(4.2 * n + 0.4, 5.6), 4.2 * height / width + 1.4)
    fig = Figure(figsize=figsize, layout="constrained")
    axes = fig.subplots(1, n, squeeze=False)[0]
    for ax, (label, events) in zip(axes, recordings):
        a, b = _window(events, t_offset_s, window_s * n_windows)
        c = analysis.accumulate_frame(events, width, height, a, b)
        ax.imshow(
            frame_rgb(c["on"], c["off"]),
            interpolation="nearest",
            origin="upper",
            extent=(-0.5, width - 0.5, height - 0.5, -0.5),
        )
        ax.set_title(f"{label}\n{c['on'].sum()} ON, {c['off'].sum()} OFF", fontsize=10)
        ax.set_xlabel("x [px]")
        ax.set_ylabel("y [px]")
    # One line per panel width of text: wrap the title on narrow (single-panel) figures.
    joiner = ", " if n > 1 else "\n"
    fig.suptitle(
        f"{n_windows} successive {1e3 * window_s:g} ms frames overlaid{joiner}from t = {t_offset_s:g} s "
        "after the first event (ON red, OFF blue)",
        fontsize=10 if n == 1 else 11,
    )
    return fig


def plot_frames(
    recordings: Sequence[LabelledEvents], width: int, height: int, path: PathLike, dpi: int = DPI, **kw: Any
) -> Path:
    """Write :func:`fig_frames` to ``path``."""
    return save(fig_frames(recordings, width, height, **kw), path, dpi)


def fig_xyt(
    recordings: Sequence[LabelledEvents],
    width: int,
    height: int,
    t_offset_s: float = 0.0,
    duration_s: float = 0.1,
    max_points: int = MAX_SCATTER_POINTS,
    figsize: tuple[float, float] | None = None,
) -> Figure:
    """Fig. 6: events of a ``duration_s`` slice (from ``t_offset_s`` after the first event) in
    x-y-t, one 3-D panel per recording; at most ``max_points`` events drawn per recording
    (evenly spaced in time order; the title says how many)."""
    import mpl_toolkits.mplot3d  # noqa: F401  (registers the 3-D projection)

    n = len(recordings)
    if figsize is None:
        figsize = (5.0 * n, 5.0)
    fig = Figure(figsize=figsize)
    for i, (label, events) in enumerate(recordings):
        ax = fig.add_subplot(1, n, i + 1, projection="3d")
        a, b = _window(events, t_offset_s, duration_s)
        sl = analysis.time_slice(events, a, b)
        shown = subsample(sl, max_points)
        t_ms = (shown["t"].astype(np.int64) - a) * 1e-3
        for pol, colour, name in ((1, ON_COLOUR, "ON"), (0, OFF_COLOUR, "OFF")):
            m = shown["p"] == pol if pol else shown["p"] == 0
            ax.scatter(
                shown["x"][m],
                t_ms[m],
                shown["y"][m],
                s=1.5,
                c=colour,
                label=name,
                depthshade=False,
                linewidths=0,
            )
        ax.set_xlim(0, width)
        ax.set_ylim(0, 1e3 * duration_s)
        ax.set_zlim(height, 0)
        ax.set_xlabel("x [px]")
        ax.set_ylabel("t [ms]")
        ax.set_zlabel("y [px]")
        note = f"{sl.size} events" if shown.size == sl.size else f"{shown.size} of {sl.size} events shown"
        ax.set_title(f"{label}\n{note}", fontsize=10)
        ax.legend(loc="upper left", markerscale=6, fontsize=8)
    fig.suptitle(
        f"x-y-t of {1e3 * duration_s:g} ms from t = {t_offset_s:g} s after the first event", fontsize=11
    )
    fig.subplots_adjust(left=0.02, right=0.95, bottom=0.04, top=0.86, wspace=0.12)
    return fig


def plot_xyt(
    recordings: Sequence[LabelledEvents], width: int, height: int, path: PathLike, dpi: int = DPI, **kw: Any
) -> Path:
    """Write :func:`fig_xyt` to ``path``."""
    return save(fig_xyt(recordings, width, height, **kw), path, dpi)


def fig_count_histograms(
    edges: Mapping[str, np.ndarray],
    hists: Sequence[tuple[str, Mapping[str, np.ndarray]]],
    value_unit: str = "events",
    log_y: bool = True,
    figsize: tuple[float, float] | None = None,
) -> Figure:
    """Fig. 7: distribution over pixels of the per-pixel count; rows all/ON/OFF, one column
    per recording (real first). Frequencies are fractions of the sensor's pixels; the y-axis
    is logarithmic by default so the tail shows (empty bins are then not drawn)."""
    n = len(hists)
    if figsize is None:
        figsize = (3.6 * n + 0.6, 7.5)
    fig = Figure(figsize=figsize, layout="constrained")
    axes = fig.subplots(len(KINDS), n, squeeze=False, sharey="row")
    unit = _unit(value_unit)
    for r, k in enumerate(KINDS):
        for c, (label, h) in enumerate(hists):
            ax = axes[r, c]
            e = np.asarray(edges[k], dtype=np.float64)
            f = np.asarray(h[k], dtype=np.float64)
            per_count = value_unit == "events" and _one_per_count(e)
            if per_count:  # one bin per count: centred on it, integer ticks
                e = e - 0.5
                ax.xaxis.set_major_locator(MaxNLocator(integer=True))
            ax.stairs(f, e, fill=True, color=KIND_COLOURS[k], alpha=0.85)
            if log_y:
                positive = f[f > 0]
                ax.set_yscale("log")
                if positive.size:
                    ax.set_ylim(positive.min() / 2, 1.5)
            ax.set_xlim(e[0], e[-1])
            ax.set_title(f"{label}: {KIND_LABELS[k]}", fontsize=10)
            ax.set_xlabel(_value_label(k, value_unit))
            if c == 0:
                ax.set_ylabel("fraction of pixels")
            ax.grid(True, alpha=0.3)
    e0 = np.asarray(edges[KINDS[0]], dtype=np.float64)
    w = float(e0[1] - e0[0])
    what = "count" if value_unit == "events" else "rate"
    binning = "one bin per count" if value_unit == "events" and _one_per_count(e0) else f"bin width {w:.4g} {unit}"
    fig.suptitle(f"Per-pixel event {what} distribution ({binning})", fontsize=11)
    return fig


def _one_per_count(edges: np.ndarray) -> bool:
    """Edges 0, 1, 2, ...: bins of one count each."""
    return edges.size >= 2 and bool(np.all(np.diff(edges) == 1.0)) and bool(np.all(edges == np.round(edges)))


def plot_count_histograms(
    edges: Mapping[str, np.ndarray],
    hists: Sequence[tuple[str, Mapping[str, np.ndarray]]],
    path: PathLike,
    dpi: int = DPI,
    **kw: Any,
) -> Path:
    """Write :func:`fig_count_histograms` to ``path``."""
    return save(fig_count_histograms(edges, hists, **kw), path, dpi)


def fig_event_rate(
    recordings: Sequence[LabelledEvents],
    bin_s: float = 0.01,
    figsize: tuple[float, float] | None = None,
    curves: Sequence[tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None,
    span_s: float | None = None,
) -> Figure:
    """ON and OFF event rate over time in ``bin_s`` bins, one row per recording (shared time
    axis, from each recording's first event; whole bins only, see
    :func:`evstwin.analysis.event_rate`). ``curves``: the rates already binned (from
    :func:`evstwin.analysis.event_rate_chunks`, for recordings read in chunks), one per
    recording, whose events are then not used; ``span_s``: the time axis's extent (default:
    the first recording's span)."""
    n = len(recordings)
    if figsize is None:
        figsize = (9.0, 2.4 * n + 0.8)
    fig = Figure(figsize=figsize, layout="constrained")
    # One y scale for every row, so rates compare by eye; the time axis spans the first
    # recording (the real one in a comparison), not the longest.
    axes = fig.subplots(n, 1, squeeze=False, sharex=True, sharey=True)[:, 0]
    if curves is None:
        curves = [analysis.event_rate(events, bin_s) for _, events in recordings]
    peak = max((float(max(on.max(), off.max())) for t, on, off in curves if t.size), default=0.0)
    for ax, (label, events), (t, on, off) in zip(axes, recordings, curves):
        ax.step(t, on, where="mid", color=ON_COLOUR, linewidth=1.2, label="ON")
        ax.step(t, off, where="mid", color=OFF_COLOUR, linewidth=1.2, label="OFF")
        ax.set_title(label, fontsize=10)
        ax.set_ylabel("event rate [events/s]")
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc="upper right", ncol=2)
    axes[0].set_ylim(0, 1.3 * peak if peak > 0 else 1.0)
    first = recordings[0][1] if n else None
    if span_s is None and first is not None and first.size > 1:
        span_s = (int(first["t"][-1]) - int(first["t"][0]) + 1) * 1e-6
    if span_s is not None:
        axes[0].set_xlim(0, max(span_s, bin_s))
    axes[-1].set_xlabel("time since first event [s]")
    fig.suptitle(f"Event rate ({1e3 * bin_s:g} ms bins)", fontsize=11)
    return fig


def plot_event_rate(recordings: Sequence[LabelledEvents], path: PathLike, dpi: int = DPI, **kw: Any) -> Path:
    """Write :func:`fig_event_rate` to ``path``."""
    return save(fig_event_rate(recordings, **kw), path, dpi)
