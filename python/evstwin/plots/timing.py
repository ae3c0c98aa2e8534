"""Figures of the event-timing bias."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._extras import require

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.colors import to_rgb
    from matplotlib.figure import Figure
else:
    to_rgb = require("matplotlib.colors").to_rgb
    Figure = require("matplotlib.figure").Figure
if TYPE_CHECKING:  # pragma: no cover
    pass
from ..analysis import SAME_VALUE_TOLERANCE, same_value_groups
from .style import DPI, MAX_SCATTER_POINTS, OFF_COLOUR, ON_COLOUR, PathLike, save, subsample


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
            if same_value_groups(np.array([lo, hi]))[-1] == 0:  # one value, to SAME_VALUE_TOLERANCE
                lo = hi = float(np.median(v))
            if log and lo > 0:
                edges = np.geomspace(lo, hi, n_bins + 1) if hi > lo else np.array([lo / 1.01, hi * 1.01])
            else:
                edges = np.linspace(lo, hi, n_bins + 1) if hi > lo else np.array([lo - 0.5, hi + 0.5])
            # ON and OFF medians apart: in the dark OFF events trail ON ones by an order of
            # magnitude, and one median of both would describe neither.
            for pol, colour, name, shift in ((1, ON_COLOUR, "ON", -1), (0, OFF_COLOUR, "OFF", 1)):
                sel = (np.asarray(table["p"]) != 0) if pol else (np.asarray(table["p"]) == 0)
                if not sel.any():
                    continue
                c, med, q1, q3 = _binned_median(v[sel], delay_ms[sel], edges, log=log and lo > 0)
                ax.errorbar(c, med, yerr=[med - q1, q3 - med], color=colour, marker="o", markersize=5,
                            markeredgecolor="black", capsize=3, linewidth=1.4,
                            label=f"{name} median, 25-75 %")
            if hi == lo:  # one brightness or speed: a plain axis around it, no offset notation
                ax.set_xlim(lo - 0.5 * abs(lo or 1.0), hi + 0.5 * abs(hi or 1.0))
                ax.set_xticks([lo])
                ax.set_xticklabels([f"{lo:.4g}"])
                ax.set_xlabel(f"{xlabel} (one value, to {100 * SAME_VALUE_TOLERANCE:g} %)")
        if log and v.size and lo > 0 and hi > lo:  # one brightness: linear axis
            ax.set_xscale("log")
        elif v.size and hi > lo:
            ax.ticklabel_format(axis="x", useOffset=False)  # 1e-12+7.88 helps nobody
        ax.axhline(0.0, color="grey", linewidth=0.6)
        if not ax.get_xlabel():
            ax.set_xlabel(xlabel)
        ax.grid(True, alpha=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    if handles:  # one legend for both panels, below them
        fig.legend(handles, labels, loc="outside lower center", ncols=4, fontsize=8)
    outside = 0
    if delay_ms.size:
        lo_ms, hi_ms = np.percentile(delay_ms, [1, 99])
        pad = 0.15 * (hi_ms - lo_ms) + 0.05
        y0, y1 = min(lo_ms, 0.0) - pad, max(hi_ms, 0.0) + pad
        axes[0].set_ylim(y0, y1)
        outside = int(np.count_nonzero((delay_ms < y0) | (delay_ms > y1)))
    axes[0].set_ylabel("delay: event time - true crossing [ms]")
    axes[0].set_title("delay vs brightness", fontsize=10)
    axes[1].set_title("delay vs speed", fontsize=10)
    note = "" if shown.size == table.size else f", {shown.size} of {table.size} shown"
    if outside:
        note += f", {outside} beyond the delay axis"
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
