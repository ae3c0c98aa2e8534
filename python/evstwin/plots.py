"""Figures of the validation (the paper's Figs. 5-9, the event rate and the timing bias), as PNG.

Headless: figures are built on :class:`matplotlib.figure.Figure` (no pyplot, no global state,
Agg canvas), so they can be drawn from worker threads or processes. Each ``fig_*`` function
returns the Figure (to inspect or adjust); each ``plot_*`` function draws it, writes a PNG of
``figsize * dpi`` pixels to ``path`` and returns the path.

Fixed colours in every figure: ON events :data:`ON_COLOUR` (red-orange), OFF events
:data:`OFF_COLOUR` (blue), all events :data:`TOTAL_COLOUR` (dark grey).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from . import analysis
from ._extras import require
from .analysis import KINDS

# matplotlib is the ``plot`` extra: importing this module without it is one line naming it.
if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.colors import to_rgb
    from matplotlib.figure import Figure
else:
    to_rgb = require("matplotlib.colors").to_rgb
    Figure = require("matplotlib.figure").Figure

if TYPE_CHECKING:  # pragma: no cover
    from .validation import Comparison, MonteCarloSummary

PathLike = str | Path
LabelledEvents = tuple[str, np.ndarray]

ON_COLOUR = "#e34a1b"
OFF_COLOUR = "#2066b0"
TOTAL_COLOUR = "#404040"
KIND_COLOURS: dict[str, str] = {"total": TOTAL_COLOUR, "on": ON_COLOUR, "off": OFF_COLOUR}
KIND_LABELS: dict[str, str] = {"total": "all events", "on": "ON events", "off": "OFF events"}

DPI = 120
MAX_SCATTER_POINTS = 20000
"""Cap on the events drawn per recording in a scatter plot (evenly spaced in time order)."""


def save(fig: Figure, path: PathLike, dpi: int = DPI) -> Path:
    """Write ``fig`` as a PNG of exactly figsize * dpi pixels and return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, format="png")
    return path


def subsample(events: np.ndarray, max_points: int = MAX_SCATTER_POINTS) -> np.ndarray:
    """At most ``max_points`` events, evenly spaced in the (time) order, deterministic."""
    if events.size <= max_points:
        return events
    idx = np.linspace(0, events.size - 1, max_points).round().astype(np.int64)
    return events[idx]


def _unit(value_unit: str) -> str:
    return "events" if value_unit == "events" else "events/s"


def _value_label(kind: str, value_unit: str) -> str:
    """x label of a per-pixel histogram: 'ON events per pixel [events]' or, compared by rate,
    'ON event rate per pixel [events/s]'."""
    prefix = {"total": "", "on": "ON ", "off": "OFF "}[kind]
    if value_unit == "events":
        return f"{prefix}events per pixel [events]"
    return f"{prefix}event rate per pixel [events/s]"


# --------------------------------------------------------------------------------------------
# Fig. 5: accumulated frames


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


# --------------------------------------------------------------------------------------------
# Fig. 6: x-y-t scatter


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


# --------------------------------------------------------------------------------------------
# Fig. 7: per-pixel count histograms


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
            e = np.asarray(edges[k])
            f = np.asarray(h[k], dtype=np.float64)
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
    w = float(np.asarray(edges[KINDS[0]])[1] - np.asarray(edges[KINDS[0]])[0])
    what = "count" if value_unit == "events" else "rate"
    fig.suptitle(f"Per-pixel event {what} distribution (bin width {w:.4g} {unit})", fontsize=11)
    return fig


def plot_count_histograms(
    edges: Mapping[str, np.ndarray],
    hists: Sequence[tuple[str, Mapping[str, np.ndarray]]],
    path: PathLike,
    dpi: int = DPI,
    **kw: Any,
) -> Path:
    """Write :func:`fig_count_histograms` to ``path``."""
    return save(fig_count_histograms(edges, hists, **kw), path, dpi)


def plot_comparison_histograms(comp: Comparison, path: PathLike, dpi: int = DPI, **kw: Any) -> Path:
    """Fig. 7 of a :class:`~evstwin.validation.Comparison`: real, then each simulation."""
    hists = [(comp.real_label + " (real)", comp.real_hist)] + [(s.label, s.hist) for s in comp.sims]
    return plot_count_histograms(comp.edges, hists, path, dpi, value_unit=comp.value_unit, **kw)


# --------------------------------------------------------------------------------------------
# Figs. 8 and 9: per-bin errors


def _bin_axis(edges: np.ndarray) -> np.ndarray:
    return 0.5 * (edges[:-1] + edges[1:])


def _error_panels(
    edges: Mapping[str, np.ndarray],
    sims: Sequence[tuple[str, Mapping[str, np.ndarray]]],
    std: Sequence[Mapping[str, np.ndarray]] | None,
    value_unit: str,
    ylabel: str,
    title: str,
    figsize: tuple[float, float] | None,
    scale: float = 1.0,
    symlog_above: float | None = None,
    symlog_linthresh: float = 10.0,
) -> tuple[Figure, np.ndarray]:
    n = len(sims)
    if figsize is None:
        figsize = (5.2 * n + 0.6, 4.2)
    fig = Figure(figsize=figsize, layout="constrained")
    axes = fig.subplots(1, n, squeeze=False)[0]
    unit = _unit(value_unit)
    for i, (ax, (label, data)) in enumerate(zip(axes, sims)):
        top = 0.0
        for k in KINDS:
            e = np.asarray(edges[k], dtype=np.float64)
            y = np.asarray(data[k], dtype=np.float64) * scale
            x = _bin_axis(e)[: y.size]
            ax.plot(
                x, y, color=KIND_COLOURS[k], marker=".", markersize=4, linewidth=1.2, label=KIND_LABELS[k]
            )
            if np.isfinite(y).any():
                top = max(top, float(np.nanmax(np.abs(y))))
            if std is not None:
                s = np.asarray(std[i][k], dtype=np.float64)[: y.size] * scale
                ax.fill_between(x, y - s, y + s, color=KIND_COLOURS[k], alpha=0.2, linewidth=0)
        ax.axhline(0.0, color="black", linewidth=0.6)
        if symlog_above is not None and top > symlog_above:
            ax.set_yscale("symlog", linthresh=symlog_linthresh)
            ax.set_title(f"{label} (symlog axis, linear within +-{symlog_linthresh:g} %)", fontsize=10)
        else:
            ax.set_title(label, fontsize=10)
        what = "count" if value_unit == "events" else "rate"
        ax.set_xlabel(f"per-pixel event {what}, bin centre [{unit}]")
        ax.set_ylabel(ylabel)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle(title, fontsize=11)
    return fig, axes


def fig_percent_error(
    edges: Mapping[str, np.ndarray],
    sims: Sequence[tuple[str, Mapping[str, np.ndarray]]],
    std: Sequence[Mapping[str, np.ndarray]] | None = None,
    value_unit: str = "events",
    figsize: tuple[float, float] | None = None,
    symlog_above: float | None = 300.0,
) -> Figure:
    """Fig. 8: percent error 100 (sim - real) / real of each histogram bin, one panel per
    simulation, lines all/ON/OFF; bins the real recording leaves empty are gaps. With
    ``std`` (Monte Carlo), a +-1 std band. A panel whose errors exceed ``symlog_above`` %
    (tail bins the real recording hardly fills) gets a symmetric-log axis, linear within
    +-10 %, so the small errors of the well-filled bins stay readable."""
    runs = " (mean of runs, band +-1 std)" if std is not None else ""
    fig, _ = _error_panels(
        edges,
        sims,
        std,
        value_unit,
        "percent error of bin frequency [%]",
        "Percent error of the histogram bins against the real recording" + runs,
        figsize,
        symlog_above=symlog_above,
    )
    return fig


def plot_percent_error(
    edges: Mapping[str, np.ndarray],
    sims: Sequence[tuple[str, Mapping[str, np.ndarray]]],
    path: PathLike,
    dpi: int = DPI,
    **kw: Any,
) -> Path:
    """Write :func:`fig_percent_error` to ``path``."""
    return save(fig_percent_error(edges, sims, **kw), path, dpi)


def fig_bin_error(
    edges: Mapping[str, np.ndarray],
    sims: Sequence[tuple[str, Mapping[str, np.ndarray]]],
    pixel_count: int,
    std: Sequence[Mapping[str, np.ndarray]] | None = None,
    value_unit: str = "events",
    figsize: tuple[float, float] | None = None,
) -> Figure:
    """Fig. 9: error of each bin in pixels (sim - real, left axis) and as a share of the
    sensor's ``pixel_count`` pixels [%] (right axis), one panel per simulation."""
    runs = " (mean of runs, band +-1 std)" if std is not None else ""
    fig, axes = _error_panels(
        edges,
        sims,
        std,
        value_unit,
        "bin error [pixels]",
        f"Histogram bin error and its share of the {pixel_count} pixels" + runs,
        figsize,
    )
    share = 100.0 / pixel_count
    for ax in axes:
        sec = ax.secondary_yaxis("right", functions=(lambda v: v * share, lambda v: v / share))
        sec.set_ylabel("share of sensor pixels [%]")
    return fig


def plot_bin_error(
    edges: Mapping[str, np.ndarray],
    sims: Sequence[tuple[str, Mapping[str, np.ndarray]]],
    pixel_count: int,
    path: PathLike,
    dpi: int = DPI,
    **kw: Any,
) -> Path:
    """Write :func:`fig_bin_error` to ``path``."""
    return save(fig_bin_error(edges, sims, pixel_count, **kw), path, dpi)


def _mask_empty(values: Any, real: Any, sim: Any) -> np.ndarray:
    v = np.array(values, dtype=np.float64)
    r, s = np.asarray(real, dtype=np.float64), np.asarray(sim, dtype=np.float64)
    n = min(v.size, r.size, s.size)
    v[:n][(r[:n] == 0) & (s[:n] == 0)] = np.nan
    return v


def plot_comparison_percent_error(comp: Comparison, path: PathLike, dpi: int = DPI, **kw: Any) -> Path:
    """Fig. 8 of a :class:`~evstwin.validation.Comparison`; bins empty in both recordings
    (percent error 0 by definition) are drawn as gaps, not as points on the zero line."""
    sims = [
        (s.label, {k: _mask_empty(s.percent_error[k], comp.real_hist[k], s.hist[k]) for k in KINDS})
        for s in comp.sims
    ]
    return plot_percent_error(comp.edges, sims, path, dpi, value_unit=comp.value_unit, **kw)


def plot_comparison_bin_error(comp: Comparison, path: PathLike, dpi: int = DPI, **kw: Any) -> Path:
    """Fig. 9 of a :class:`~evstwin.validation.Comparison`."""
    sims = [(s.label, s.error_pixels) for s in comp.sims]
    return plot_bin_error(comp.edges, sims, comp.pixel_count, path, dpi, value_unit=comp.value_unit, **kw)


def _nan_list(v: Sequence[float | None]) -> np.ndarray:
    return np.array([np.nan if x is None else x for x in v], dtype=np.float64)


def plot_monte_carlo(summary: MonteCarloSummary, out_dir: PathLike, dpi: int = DPI) -> dict[str, Path]:
    """Figs. 8 and 9 of a Monte Carlo summary (mean over runs, +-1 std band):
    ``out_dir/percent_error_mc.png`` and ``out_dir/bin_error_mc.png``."""
    out = Path(out_dir)
    m, s = summary.mean, summary.std
    edges = {k: np.asarray(m["edges"][k], dtype=np.float64) for k in KINDS}
    labels = [str(x["path"]) if isinstance(x["path"], str) else str(x["path"][0]) for x in m["sims"]]
    labels = [lab.replace("\\", "/").rsplit("/", 1)[-1] + f" ({summary.runs} runs)" for lab in labels]
    unit = m.get("value_unit", "events")
    real_h = {k: _nan_list(m["real_histogram"][k]) for k in KINDS}
    pct = [
        (
            lab,
            {
                k: _mask_empty(_nan_list(x["percent_error"][k]), real_h[k], _nan_list(x["histogram"][k]))
                for k in KINDS
            },
        )
        for lab, x in zip(labels, m["sims"])
    ]
    pct_sd = [{k: _nan_list(x["percent_error"][k]) for k in KINDS} for x in s["sims"]]
    err = [(lab, {k: _nan_list(x["error_pixels"][k]) for k in KINDS}) for lab, x in zip(labels, m["sims"])]
    err_sd = [{k: _nan_list(x["error_pixels"][k]) for k in KINDS} for x in s["sims"]]
    return {
        "percent_error": plot_percent_error(
            edges, pct, out / "percent_error_mc.png", dpi, std=pct_sd, value_unit=unit
        ),
        "bin_error": plot_bin_error(
            edges,
            err,
            int(m["real"]["pixel_count"]),
            out / "bin_error_mc.png",
            dpi,
            std=err_sd,
            value_unit=unit,
        ),
    }


# --------------------------------------------------------------------------------------------
# event rate


def fig_event_rate(
    recordings: Sequence[LabelledEvents], bin_s: float = 0.01, figsize: tuple[float, float] | None = None
) -> Figure:
    """ON and OFF event rate over time in ``bin_s`` bins, one row per recording (shared time
    axis, from each recording's first event; whole bins only, see
    :func:`evstwin.analysis.event_rate`)."""
    n = len(recordings)
    if figsize is None:
        figsize = (9.0, 2.4 * n + 0.8)
    fig = Figure(figsize=figsize, layout="constrained")
    axes = fig.subplots(n, 1, squeeze=False, sharex=True)[:, 0]
    for ax, (label, events) in zip(axes, recordings):
        t, on, off = analysis.event_rate(events, bin_s)
        ax.step(t, on, where="mid", color=ON_COLOUR, linewidth=1.2, label="ON")
        ax.step(t, off, where="mid", color=OFF_COLOUR, linewidth=1.2, label="OFF")
        ax.set_title(label, fontsize=10)
        ax.set_ylabel("event rate [events/s]")
        peak = float(max(on.max(), off.max())) if t.size else 1.0
        ax.set_ylim(0, 1.3 * peak if peak > 0 else 1.0)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8, loc="upper right", ncol=2)
    axes[-1].set_xlabel("time since first event [s]")
    fig.suptitle(f"Event rate ({1e3 * bin_s:g} ms bins)", fontsize=11)
    return fig


def plot_event_rate(recordings: Sequence[LabelledEvents], path: PathLike, dpi: int = DPI, **kw: Any) -> Path:
    """Write :func:`fig_event_rate` to ``path``."""
    return save(fig_event_rate(recordings, **kw), path, dpi)


# --------------------------------------------------------------------------------------------
# timing bias


def _binned_median(
    x: np.ndarray, y: np.ndarray, edges: np.ndarray, log: bool = False
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, edges.size - 2)
    order = np.argsort(idx, kind="stable")
    bounds = np.searchsorted(idx[order], np.arange(edges.size))
    med, lo, hi, centre = [], [], [], []
    for i in range(edges.size - 1):  # loop over bins, not events
        yi = y[order[bounds[i] : bounds[i + 1]]]
        if yi.size:
            q = np.percentile(yi, [25, 50, 75])
            lo.append(q[0])
            med.append(q[1])
            hi.append(q[2])
            xi = x[order[bounds[i] : bounds[i + 1]]]
            centre.append(float(np.exp(np.median(np.log(xi)))) if log else float(np.median(xi)))
    return np.array(centre), np.array(med), np.array(lo), np.array(hi)


def fig_timing_bias(
    table: np.ndarray,
    n_bins: int = 8,
    max_points: int = MAX_SCATTER_POINTS,
    figsize: tuple[float, float] | None = (11.0, 4.4),
) -> Figure:
    """Event delay after the true crossing (a :func:`evstwin.validation.timing_bias` table)
    against source flux (log axis) and speed: ON and OFF events as points (at most
    ``max_points`` drawn), with the median and interquartile range of the delay in ``n_bins`` bins (drawn at the
    bin's median flux or speed). The
    delay axis spans the 1st-99th percentile (stray noise events attributed to a crossing
    would otherwise flatten it)."""
    fig = Figure(figsize=figsize, layout="constrained")
    axes = fig.subplots(1, 2, sharey=True)
    shown = subsample(table, max_points)
    delay_ms = np.asarray(table["delay_s"], dtype=np.float64) * 1e3
    for ax, col, xlabel, log in (
        (axes[0], "flux_ph_s", "source flux [photons/s]", True),
        (axes[1], "speed_px_s", "source speed [px/s]", False),
    ):
        v = np.asarray(table[col], dtype=np.float64)
        for pol, colour, name in ((1, ON_COLOUR, "ON"), (0, OFF_COLOUR, "OFF")):
            m = (shown["p"] != 0) if pol else (shown["p"] == 0)
            ax.scatter(
                shown[col][m],
                shown["delay_s"][m] * 1e3,
                s=4,
                c=colour,
                alpha=0.35,
                linewidths=0,
                label=f"{name} events",
            )
        if v.size:
            lo, hi = float(v.min()), float(v.max())
            if log and lo > 0:
                edges = np.geomspace(lo, hi, n_bins + 1) if hi > lo else np.array([lo / 1.01, hi * 1.01])
            else:
                edges = np.linspace(lo, hi, n_bins + 1) if hi > lo else np.array([lo - 0.5, hi + 0.5])
            c, med, q1, q3 = _binned_median(v, delay_ms, edges, log=log and lo > 0)
            ax.errorbar(
                c,
                med,
                yerr=[med - q1, q3 - med],
                color="black",
                marker="o",
                markersize=4,
                capsize=3,
                linewidth=1.2,
                label="median, 25-75 %",
            )
        if log and v.size and v.min() > 0 and v.max() > v.min():  # one brightness: linear axis
            ax.set_xscale("log")
        ax.axhline(0.0, color="grey", linewidth=0.6)
        ax.set_xlabel(xlabel)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    if delay_ms.size:
        lo_ms, hi_ms = np.percentile(delay_ms, [1, 99])
        pad = 0.15 * (hi_ms - lo_ms) + 0.05
        axes[0].set_ylim(min(lo_ms, 0.0) - pad, max(hi_ms, 0.0) + pad)
    axes[0].set_ylabel("delay: event time - true crossing [ms]")
    axes[0].set_title("delay vs brightness", fontsize=10)
    axes[1].set_title("delay vs speed", fontsize=10)
    note = "" if shown.size == table.size else f", {shown.size} of {table.size} shown"
    fig.suptitle(f"Event-timing bias ({table.size} events attributed to a crossing{note})", fontsize=11)
    return fig


def fig_timing_by_setting(
    tables: Sequence[tuple[str, np.ndarray]], figsize: tuple[float, float] | None = None
) -> Figure:
    """Event delay after the true crossing for several recordings side by side (one per bias
    setting, say): a box per recording and polarity (median, quartiles, 5-95 % whiskers)."""
    n = len(tables)
    fig = Figure(figsize=figsize or (max(6.0, 1.6 * n + 2.5), 4.6), layout="constrained")
    ax = fig.subplots()
    for pol, colour, name, shift in ((1, ON_COLOUR, "ON", -0.18), (0, OFF_COLOUR, "OFF", 0.18)):
        data, where = [], []
        for i, (_, table) in enumerate(tables):
            sel = (table["p"] != 0) if pol else (table["p"] == 0)
            if np.any(sel):
                data.append(np.asarray(table["delay_s"][sel], dtype=np.float64) * 1e3)
                where.append(i + shift)
        if data:
            box = ax.boxplot(data, positions=where, widths=0.3, whis=(5, 95), showfliers=False, patch_artist=True)
            for patch in box["boxes"]:
                patch.set_facecolor(colour)
                patch.set_alpha(0.6)
            for median in box["medians"]:
                median.set_color("black")
            ax.plot([], [], color=colour, linewidth=6, alpha=0.6, label=f"{name} events")
    ax.set_xticks(range(n), [label for label, _ in tables], fontsize=8)
    ax.axhline(0.0, color="grey", linewidth=0.6)
    ax.set_ylabel("delay: event time - true crossing [ms]")
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=8)
    fig.suptitle("Event-timing bias by recording (boxes: quartiles, whiskers: 5-95 %)", fontsize=11)
    return fig


def plot_timing_by_setting(tables: Sequence[tuple[str, np.ndarray]], path: PathLike, dpi: int = DPI) -> Path:
    """Write :func:`fig_timing_by_setting` to ``path``."""
    return save(fig_timing_by_setting(tables), path, dpi)


def plot_timing_bias(table: np.ndarray, path: PathLike, dpi: int = DPI, **kw: Any) -> Path:
    """Write :func:`fig_timing_bias` to ``path``."""
    return save(fig_timing_bias(table, **kw), path, dpi)


__all__: list[str] = [
    "DPI",
    "fig_timing_by_setting",
    "plot_timing_by_setting",
    "KIND_COLOURS",
    "MAX_SCATTER_POINTS",
    "OFF_COLOUR",
    "ON_COLOUR",
    "TOTAL_COLOUR",
    "fig_bin_error",
    "fig_count_histograms",
    "fig_event_rate",
    "fig_frames",
    "fig_percent_error",
    "fig_timing_bias",
    "fig_xyt",
    "frame_rgb",
    "plot_bin_error",
    "plot_comparison_bin_error",
    "plot_comparison_histograms",
    "plot_comparison_percent_error",
    "plot_count_histograms",
    "plot_event_rate",
    "plot_frames",
    "plot_monte_carlo",
    "plot_percent_error",
    "plot_timing_bias",
    "plot_xyt",
    "save",
    "subsample",
]
