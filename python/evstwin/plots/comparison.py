"""Figures of a comparison with a real recording (the paper's Figs. 7-9) and of its Monte Carlo."""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from .._extras import require
from ..analysis import KINDS

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.colors import to_rgb
    from matplotlib.figure import Figure
else:
    to_rgb = require("matplotlib.colors").to_rgb
    Figure = require("matplotlib.figure").Figure
from .recording import plot_count_histograms
from .style import DPI, KIND_COLOURS, KIND_LABELS, PathLike, _unit, save


# What these plots read of evstwin.validation's results, as protocols: plotting does not import
# the validation package (whose report imports plotting), it takes anything of this shape.
class SimComparisonLike(Protocol):
    """What the plots read of a :class:`~evstwin.validation.SimComparison`."""

    @property
    def label(self) -> str: ...
    @property
    def hist(self) -> Mapping[str, np.ndarray]: ...
    @property
    def percent_error(self) -> Mapping[str, np.ndarray]: ...
    @property
    def error_pixels(self) -> Mapping[str, np.ndarray]: ...
    @property
    def max_bin_error_share(self) -> float: ...


class ComparisonLike(Protocol):
    """What the plots read of a :class:`~evstwin.validation.Comparison`."""

    @property
    def real_label(self) -> str: ...
    @property
    def real_hist(self) -> Mapping[str, np.ndarray]: ...
    @property
    def sims(self) -> Sequence[SimComparisonLike]: ...
    @property
    def edges(self) -> Mapping[str, np.ndarray]: ...
    @property
    def value_unit(self) -> str: ...
    @property
    def pixel_count(self) -> int: ...


class MonteCarloLike(Protocol):
    """What the plots read of a :class:`~evstwin.validation.MonteCarloSummary`."""

    @property
    def runs(self) -> int: ...
    @property
    def mean(self) -> Mapping[str, Any]: ...
    @property
    def std(self) -> Mapping[str, Any]: ...


def plot_comparison_histograms(comp: ComparisonLike, path: PathLike, dpi: int = DPI, **kw: Any) -> Path:
    """Fig. 7 of a :class:`~evstwin.validation.Comparison`: real, then each simulation."""
    hists = [(comp.real_label + " (real)", comp.real_hist)] + [(s.label, s.hist) for s in comp.sims]
    return plot_count_histograms(comp.edges, hists, path, dpi, value_unit=comp.value_unit, **kw)


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
    # Wrapped to the figure's width (about 11 characters an inch at this size): a one-panel
    # figure would otherwise clip a long title at both ends.
    fig.suptitle(textwrap.fill(title, width=max(30, int(10.5 * figsize[0]))), fontsize=11)
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
    worst: Sequence[float] | None = None,
) -> Figure:
    """Fig. 9: error of each bin in pixels (sim - real, left axis) and as a share of the
    ``pixel_count`` pixels compared [%] (right axis), one panel per simulation. ``worst``:
    each panel's largest |bin error| as a share of the pixels (the paper's headline figure,
    "less than 2 %"), written in its corner."""
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
        sec.set_ylabel("share of compared pixels [%]")
    for ax, w in zip(axes, worst or ()):
        ax.text(0.02, 0.03, f"worst bin: {100 * w:.2f} % of {pixel_count} px", transform=ax.transAxes,
                fontsize=8, ha="left", va="bottom", bbox={"facecolor": "white", "alpha": 0.8, "linewidth": 0})
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


def plot_comparison_percent_error(comp: ComparisonLike, path: PathLike, dpi: int = DPI, **kw: Any) -> Path:
    """Fig. 8 of a :class:`~evstwin.validation.Comparison`; bins empty in both recordings
    (percent error 0 by definition) are drawn as gaps, not as points on the zero line."""
    sims = [
        (s.label, {k: _mask_empty(s.percent_error[k], comp.real_hist[k], s.hist[k]) for k in KINDS})
        for s in comp.sims
    ]
    return plot_percent_error(comp.edges, sims, path, dpi, value_unit=comp.value_unit, **kw)


def plot_comparison_bin_error(comp: ComparisonLike, path: PathLike, dpi: int = DPI, **kw: Any) -> Path:
    """Fig. 9 of a :class:`~evstwin.validation.Comparison`."""
    sims = [(s.label, s.error_pixels) for s in comp.sims]
    kw.setdefault("worst", [s.max_bin_error_share for s in comp.sims])
    return plot_bin_error(comp.edges, sims, comp.pixel_count, path, dpi, value_unit=comp.value_unit, **kw)


def _nan_list(v: Sequence[float | None]) -> np.ndarray:
    return np.array([np.nan if x is None else x for x in v], dtype=np.float64)


def plot_monte_carlo(summary: MonteCarloLike, out_dir: PathLike, dpi: int = DPI) -> dict[str, Path]:
    """Figs. 8 and 9 of a Monte Carlo summary (mean over runs, +-1 std band):
    ``out_dir/percent_error_mc.png`` and ``out_dir/bin_error_mc.png``."""
    out = Path(out_dir)
    m, s = summary.mean, summary.std
    edges = {k: np.asarray(m["edges"][k], dtype=np.float64) for k in KINDS}
    labels = [str(x["path"]) if isinstance(x["path"], str) else str(x["path"][0]) for x in m["sims"]]
    labels = [lab.replace("\\", "/").rsplit("/", 1)[-1] for lab in labels]
    labels = [lab if "seeds)" in lab else f"{lab} ({summary.runs} runs)" for lab in labels]
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
