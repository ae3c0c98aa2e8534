"""Figures of tuning results (matplotlib, the ``plot`` extra). Compute modules never import this one."""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from .._extras import require
from ._types import PathLike
from .identify import Identifiability, short
from .limits import LimitingMagnitudeResult
from .result import FitResult, TrialRecord
from .sweep import SweepResult, _fmt_value


def plot_convergence(history: Sequence[TrialRecord], path: PathLike) -> Path:
    """Distance of each trial (dots) and the best so far (line) against the trial number."""
    Figure = require("matplotlib.figure").Figure

    from .. import plots

    trial = np.array([r.trial for r in history], dtype=float)
    dist = np.array([r.distance for r in history], dtype=float)
    fig = Figure(figsize=(7, 4))
    ax = fig.add_subplot(1, 1, 1)
    ok = np.isfinite(dist)
    ax.plot(trial[ok], dist[ok], "o", ms=4, color=plots.TOTAL_COLOUR, alpha=0.6, label="trial")
    if ok.any():
        best = np.fmin.accumulate(np.where(ok, dist, np.inf))
        shown = np.isfinite(best)
        ax.step(trial[shown], best[shown], where="post", color=plots.ON_COLOUR, label="best so far")
        if np.all(dist[ok] > 0):
            ax.set_yscale("log")
    if (~ok).any():
        ax.plot(
            trial[~ok],
            np.full((~ok).sum(), np.nanmax(dist) if ok.any() else 1.0),
            "x",
            color="k",
            label="failed",
        )
    ax.set_xlabel("trial")
    ax.set_ylabel("distance to the real recording")
    ax.set_title("fit convergence")
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    return plots.save(fig, Path(path))


def plot_correlation(report: Identifiability, path: PathLike) -> Path:
    """The identifiability report's correlation matrix as a heatmap (-1 blue .. +1 red, the
    values written in), pairs beyond the warning level framed, and the weakest direction."""
    Figure = require("matplotlib.figure").Figure

    from .. import plots
    from .options import CORRELATION_WARN

    names = [short(p) for p in report.params]
    n = len(names)
    fig = Figure(figsize=(2.0 + 0.9 * n, 1.6 + 0.8 * n))
    ax = fig.add_subplot(1, 1, 1)
    corr = np.ma.masked_invalid(report.correlation)
    im = ax.imshow(corr, cmap="RdBu_r", vmin=-1.0, vmax=1.0)
    for i in range(n):
        for j in range(n):
            c = report.correlation[i, j]
            ax.text(j, i, "nan" if not np.isfinite(c) else f"{c:+.2f}", ha="center", va="center", fontsize=8,
                    color="white" if np.isfinite(c) and abs(c) > 0.6 else "black")
            if i != j and np.isfinite(c) and abs(c) > CORRELATION_WARN:
                ax.add_patch(plots_rectangle(j, i))
    ax.set_xticks(range(n), names, rotation=40, ha="right", fontsize=8)
    ax.set_yticks(range(n), names, fontsize=8)
    fig.colorbar(im, ax=ax, label="correlation of the estimates")
    sd, comp = report.weak_directions()[0] if n else (float("nan"), {})
    along = ", ".join(f"{c:+.2f} {short(p)}" for p, c in sorted(comp.items(), key=lambda kv: -abs(kv[1])))
    ax.set_title(textwrap.fill(f"weakest direction: sd {sd:.3g} of the (log) bound widths along {along}", 60),
                 fontsize=8)
    fig.tight_layout()
    return plots.save(fig, Path(path))


def plots_rectangle(x: int, y: int) -> Any:
    """A black frame around cell (x, y) of a heatmap."""
    Rectangle = require("matplotlib.patches").Rectangle
    return Rectangle((x - 0.5, y - 0.5), 1.0, 1.0, fill=False, edgecolor="black", linewidth=2.0)


_LABELS = {
    "pixel.theta_on": "ON threshold theta_on (log units)",
    "pixel.theta_off": "OFF threshold theta_off (log units)",
    "pixel.dark_rate_e_per_s": "dark current (e-/s)",
    "pixel.leak_rate_hz": "leak rate (Hz)",
    "pixel.shot_noise_rate_hz": "shot-noise rate (Hz per polarity)",
    "pixel.refractory_s": "refractory period (s)",
    "pixel.cutoff_hz": "source-follower cutoff (Hz)",
    "pixel.threshold_sigma": "threshold mismatch (sigma, fraction)",
    "sensor.bias_set": "bias set",
    "excess_fraction": "track pixels that fire,\nbeyond noise (fraction)",
    "fraction": "track pixels that fire (fraction)",
    "snr": "track / noise event rate\n(per pixel, SNR)",
    "latency_median_s": "first-event latency,\nmedian (s)",
    "noise_rate_per_px_hz": "noise rate\n(events/s per pixel)",
    "distance": "comparison distance",
}
_FIELDS = {
    "wx_arcsec_s": "angular rate along x (arcsec/s)",
    "wy_arcsec_s": "angular rate along y (arcsec/s)",
    "vx_px_s": "velocity along x (px/s)",
    "vy_px_s": "velocity along y (px/s)",
    "magnitude": "magnitude (V)",
    "flux_ph_s": "flux (photons/s)",
    "x0_px": "start x (px)",
    "y0_px": "start y (px)",
    "x_px": "x (px)",
    "y_px": "y (px)",
    "radius_px": "circle radius (px)",
    "period_s": "period (s)",
    "focal_length_m": "focal length (m)",
    "f_number": "f-number",
    "extra_blur_sigma_px": "extra blur, sigma (px)",
    "sky_mag_per_arcsec2": "sky brightness (V mag/arcsec^2)",
    "photon_rate_ph_s": "background (photons/s per pixel)",
    "rate_hz": "sampling rate (Hz)",
    "duration_s": "duration (s)",
}
"""Names a user reads for the last part of a scenario key (``targets.0.wx_arcsec_s``)."""
_SECTIONS = {"optics": "optics", "background": "background", "sampling": "sampling", "sensor": "sensor",
             "pixel": "pixel", "star_field": "star field", "biases": "bias"}
_BOUNDS: dict[str, tuple[float, float]] = {
    "track_fraction": (0.0, 1.0), "chance_fraction": (0.0, 1.0), "active_px_fraction": (0.0, 1.0),
    "fraction": (0.0, 1.0), "excess_fraction": (-np.inf, 1.0),
    "snr": (0.0, np.inf), "distance": (0.0, np.inf), "track_px": (0.0, np.inf), "sim_events": (0.0, np.inf),
    "total_rel_error": (-1.0, np.inf), "on_off_ratio_rel_error": (-1.0, np.inf),
}
"""What each metric can be, where less than the real line (error bars are clipped to it):
shares lie in [0, 1], rates and counts are >= 0, relative errors >= -1."""
_UNITS = (("_e_per_s", "e-/s"), ("_arcsec_s", "arcsec/s"), ("_px_s", "px/s"), ("_ph_s", "photons/s"),
          ("_hz", "Hz"), ("_px", "px"), ("_s", "s"), ("_m", "m"))


def readable(key: str) -> str:
    """A figure label for a scenario key or metric name, with its unit (``pixel.theta_on`` ->
    "ON threshold theta_on (log units)"); unknown names get the unit their suffix says."""
    if key in _LABELS:
        return _LABELS[key]
    parts = key.split(".")
    name = parts[-1]
    where = ""
    if len(parts) >= 3 and parts[0] in ("targets", "stars") and parts[1].isdigit():
        where = f"{'target' if parts[0] == 'targets' else 'star'} {parts[1]}: "
    elif len(parts) == 2 and parts[0] in _SECTIONS:
        where = f"{_SECTIONS[parts[0]]}: " if name not in _FIELDS else ""
    if name in _FIELDS:
        return where + _FIELDS[name]
    for suffix, unit in _UNITS:
        if name.endswith(suffix):
            return f"{where}{name[: -len(suffix)].replace('_', ' ')} ({unit})"
    return where + name.replace("_", " ")


def metric_bounds(metric: str) -> tuple[float, float]:
    """The range a metric can take (``_BOUNDS``; rates ``*_hz`` and ``*_per_s`` are >= 0)."""
    if metric in _BOUNDS:
        return _BOUNDS[metric]
    if metric.endswith(("_hz", "_per_s")):
        return 0.0, np.inf
    return -np.inf, np.inf


def clipped_error(mean: np.ndarray, std: np.ndarray, metric: str) -> np.ndarray:
    """Asymmetric error bars (2, n) of mean +- std, cut where the metric cannot go (a share's
    bar stops at 1.0, a rate's at 0): a missing std is no bar."""
    lo, hi = metric_bounds(metric)
    e = np.where(np.isfinite(std), std, 0.0)
    below = np.clip(np.minimum(e, mean - lo), 0.0, None)
    above = np.clip(np.minimum(e, hi - mean), 0.0, None)
    return np.vstack([np.where(np.isfinite(below), below, 0.0), np.where(np.isfinite(above), above, 0.0)])


def _axis_values(values: Sequence[Any]) -> tuple[np.ndarray, bool, list[str]]:
    numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
    if numeric:
        return np.array(values, dtype=float), True, []
    return np.arange(len(values), dtype=float), False, [str(v) for v in values]


def plot_sweep(result: SweepResult, path: PathLike) -> Path:
    """Headline metrics (mean, error bar = sample std, cut at what the metric can be) against
    the first grid parameter, one line per value of the other parameters (the second's, in a
    2-D grid)."""
    Figure = require("matplotlib.figure").Figure

    from .. import plots

    keys = list(result.grid)
    first = keys[0]
    rest = keys[1:]
    xs_all, numeric, labels = _axis_values(result.grid[first])
    metrics = list(result.headline) or list(result.metrics[:1])
    # constrained layout keeps the legend, outside the axes on the right, inside the figure.
    fig = Figure(figsize=(8.0, 2.8 * len(metrics) + 0.6), constrained_layout=True)
    groups: dict[tuple[Any, ...], list[Mapping[str, Any]]] = {}
    for row in result.summary:
        groups.setdefault(tuple(_fmt_value(row[k]) for k in rest), []).append(row)
    first_pos = {_fmt_value(v): j for j, v in enumerate(result.grid[first])}
    for n, m in enumerate(metrics):
        ax = fig.add_subplot(len(metrics), 1, n + 1)
        for gkey, rs in groups.items():
            xi = np.array([first_pos[_fmt_value(r[first])] for r in rs])
            order = np.argsort(xi)
            x = xs_all[xi[order]]
            y = np.array([r[f"mean_{m}"] for r in rs], dtype=float)[order]
            e = np.array([r[f"std_{m}"] for r in rs], dtype=float)[order]
            label = ", ".join(f"{readable(k)} = {v}" for k, v in zip(rest, gkey)) or None
            ax.errorbar(x, y, yerr=clipped_error(y, e, m), marker="o", ms=4, capsize=3, label=label)
        if numeric and np.all(xs_all > 0) and xs_all.max() / xs_all.min() > 50:
            ax.set_xscale("log")
        if not numeric:
            ax.set_xticks(xs_all, labels)
        ax.set_ylabel(readable(m), fontsize="small")
        ax.grid(True, alpha=0.3)
        if rest and n == 0:
            ax.legend(fontsize="small", loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
        if n == len(metrics) - 1:
            ax.set_xlabel(readable(first))
    fig.suptitle(f"sweep, objective {result.objective} (mean and std over {result.runs} seed(s) per point)")
    return plots.save(fig, Path(path))


def plot_limiting_magnitude(result: LimitingMagnitudeResult, path: PathLike) -> Path:
    """Limiting magnitude against angular rate (log axis), over a map of the criterion
    metric on the (rate, magnitude) grid."""
    Figure = require("matplotlib.figure").Figure

    from .. import plots

    metric, threshold = result.criterion
    rates = np.array([r["rate_arcsec_s"] for r in result.table])
    limit = np.array([r["limiting_magnitude"] for r in result.table])
    mags = np.array(sorted({float(r["targets.0.magnitude"]) for r in result.sweep.summary}))
    grid = np.full((mags.size, rates.size), np.nan)
    for r in result.sweep.summary:
        i = int(np.searchsorted(mags, float(r["targets.0.magnitude"])))
        j = int(np.flatnonzero(rates == float(r["targets.0.wx_arcsec_s"]))[0])
        grid[i, j] = r[f"mean_{metric}"]
    fig = Figure(figsize=(7.5, 5.0))
    ax = fig.add_subplot(1, 1, 1)
    order = np.argsort(rates)
    if rates.size > 1:
        lr = np.log10(rates[order])
        edges_x = 10 ** np.concatenate(
            [[lr[0] - (lr[1] - lr[0]) / 2], (lr[1:] + lr[:-1]) / 2, [lr[-1] + (lr[-1] - lr[-2]) / 2]]
        )
    else:
        edges_x = np.array([rates[0] / 1.5, rates[0] * 1.5])
    if mags.size > 1:
        edges_y = np.concatenate(
            [
                [mags[0] - (mags[1] - mags[0]) / 2],
                (mags[1:] + mags[:-1]) / 2,
                [mags[-1] + (mags[-1] - mags[-2]) / 2],
            ]
        )
    else:
        edges_y = np.array([mags[0] - 0.5, mags[0] + 0.5])
    mesh = ax.pcolormesh(edges_x, edges_y, grid[:, order], cmap="Greys", vmin=0.0, vmax=1.0, shading="flat")
    fig.colorbar(mesh, ax=ax, label=f"mean {metric}")
    ok = np.isfinite(limit[order])
    ax.plot(
        rates[order][ok],
        limit[order][ok],
        "o-",
        color=plots.ON_COLOUR,
        lw=2,
        label=f"limiting magnitude ({metric} >= {threshold:g})",
    )
    undetermined = np.array([r.get("status") == "undetermined" for r in result.table])[order]
    for rate in rates[order][undetermined]:
        ax.axvspan(rate / 1.12, rate * 1.12, color=plots.OFF_COLOUR, alpha=0.25, lw=0)
        ax.text(rate, float(np.mean(edges_y[[0, -1]])), "undetermined:\nnoise fires most pixels", rotation=90,
                ha="center", va="center", fontsize="x-small", color=plots.OFF_COLOUR)
    ax.set_xscale("log")
    ax.set_xlabel(f"angular rate relative to the stars [arcsec/s] ({result.pointing} pointing)")
    ax.set_ylabel("magnitude (fainter up)")
    title = "limiting magnitude against angular rate"
    if result.setup:
        title += "\n" + textwrap.fill(result.setup, 90)
    ax.set_title(title, fontsize="small")
    ax.legend(loc="lower left", fontsize="small")
    fig.text(0.01, 0.005, textwrap.fill(result.criterion_text(), 130), fontsize=6, va="bottom")
    fig.tight_layout(rect=(0.0, 0.06, 1.0, 1.0))
    return plots.save(fig, Path(path))


# ---------------------------------------------------------------------------------------------
# what the commands draw after computing


def draw_fit(result: FitResult, out_dir: PathLike, comparison: bool = True) -> dict[str, Path]:
    """``convergence.png``, ``correlation.png`` (the identifiability report's, where the fit has
    one) and, with ``comparison``, the comparison of the best fit (simulated
    with the first fit seed) in ``compare/`` (figures and compare.json of
    :func:`evstwin.validation.compare_files`). Returns {name: path}."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"convergence": plot_convergence(result.history, out / "convergence.png")}
    if result.identifiability is not None:
        paths["correlation"] = plot_correlation(result.identifiability, out / "correlation.png")
    if comparison:
        paths.update(_fit_comparison(result, out / "compare"))
    return paths


def _fit_comparison(result: FitResult, out: Path) -> dict[str, Path]:
    from ..io import write_events
    from ..simulate import simulate
    from ..validation import compare_files

    out.mkdir(parents=True, exist_ok=True)
    real_path = Path(str(result.real_meta.get("path", "")))
    if not (str(result.real_meta.get("path", "")) and real_path.is_file()):
        real_path = out / "real.h5"
        write_events(
            real_path,
            result.real_events,
            {k: v for k, v in result.real_meta.items() if k in ("width", "height", "duration_s")},
        )
    scenario = result.best_scenario
    if result.roi is not None:  # the compared rectangle alone, as the fit simulated it
        from ..scenario import set_value

        scenario = set_value(scenario, "sensor.roi", list(result.roi))
    best = simulate(scenario, num_threads=1)
    sim_path = out / "best_fit.h5"
    write_events(sim_path, best.events, best.meta)
    comp = compare_files(real_path, [sim_path], out, roi=result.roi, mask=result.mask)
    paths = {f"compare_{k}": Path(v) for k, v in comp.outputs.items()}
    paths["best_fit_events"] = sim_path
    return paths


def draw_sweep(result: SweepResult) -> Path:
    """``sweep.png`` beside the sweep's CSV; sets ``result.figure_path``."""
    if result.csv_path is None:
        raise ValueError("the sweep was run without out_dir: nothing to draw beside")
    result.figure_path = plot_sweep(result, result.csv_path.parent / "sweep.png")
    return result.figure_path


def draw_limiting_magnitude(result: LimitingMagnitudeResult, out_dir: PathLike) -> Path:
    """``limiting_magnitude.png`` in ``out_dir``; sets ``result.figure_path``."""
    result.figure_path = plot_limiting_magnitude(result, Path(out_dir) / "limiting_magnitude.png")
    return result.figure_path
