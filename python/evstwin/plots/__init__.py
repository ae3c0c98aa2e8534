"""Figures of the validation (the paper's Figs. 5-9, the event rate and the timing bias), as PNG.

Headless: figures are built on :class:`matplotlib.figure.Figure` (no pyplot, no global state,
Agg canvas), so they can be drawn from worker threads or processes. Each ``fig_*`` function
returns the Figure (to inspect or adjust); each ``plot_*`` function draws it, writes a PNG of
``figsize * dpi`` pixels to ``path`` and returns the path.

Fixed colours in every figure: ON events :data:`ON_COLOUR` (red-orange), OFF events
:data:`OFF_COLOUR` (blue), all events :data:`TOTAL_COLOUR` (dark grey)."""

from __future__ import annotations

from .comparison import (
    fig_bin_error,
    fig_percent_error,
    plot_bin_error,
    plot_comparison_bin_error,
    plot_comparison_histograms,
    plot_comparison_percent_error,
    plot_monte_carlo,
    plot_percent_error,
)
from .recording import (
    fig_count_histograms,
    fig_event_rate,
    fig_frames,
    fig_xyt,
    frame_rgb,
    plot_count_histograms,
    plot_event_rate,
    plot_frames,
    plot_xyt,
)
from .style import (
    DPI,
    KIND_COLOURS,
    KIND_LABELS,
    MAX_SCATTER_POINTS,
    OFF_COLOUR,
    ON_COLOUR,
    TOTAL_COLOUR,
    LabelledEvents,
    PathLike,
    save,
    subsample,
)
from .timing import fig_timing_bias, fig_timing_by_setting, plot_timing_bias, plot_timing_by_setting

__all__ = [
    "DPI",
    "KIND_COLOURS",
    "KIND_LABELS",
    "LabelledEvents",
    "MAX_SCATTER_POINTS",
    "OFF_COLOUR",
    "ON_COLOUR",
    "PathLike",
    "TOTAL_COLOUR",
    "fig_bin_error",
    "fig_count_histograms",
    "fig_event_rate",
    "fig_frames",
    "fig_percent_error",
    "fig_timing_bias",
    "fig_timing_by_setting",
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
    "plot_timing_by_setting",
    "plot_xyt",
    "save",
    "subsample",
]
