"""Validation of a simulation against a real recording: the method of the paper's section 3.

* :func:`compare` -- totals and ON/OFF ratio (Table 4), per-pixel count histograms (Fig. 7),
  their per-bin error and percent error (Fig. 8), the error as a share of the sensor's pixels
  (Fig. 9), and one summary ``distance`` a tuner can minimise.
* :func:`aggregate` -- mean and spread of every number over N Monte Carlo runs (the paper's 20).
* :func:`compare_files`, :func:`info`, :func:`show` -- the file-level entry points the CLI uses;
  they return values or text and print nothing.
* :func:`timing_bias`, :func:`timing_bias_summary` -- delay of each event after the true
  crossing of a source over its pixel, against brightness and speed (the astrometry obstacle
  the paper names).

The summary distance (0 for identical recordings, see :func:`compare`)::

    distance = (W1_total + W1_on + W1_off) / m_real + |rel. total error| + |rel. ON/OFF error|

where W1_k is the 1-Wasserstein distance between the real and simulated distributions over
pixels of the per-pixel count of kind k (mean |sorted(real) - sorted(sim)|, the unbinned
limit of the Fig. 7 histograms) and m_real is the real recording's mean per-pixel total count.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Union

import numpy as np

from . import analysis
from .analysis import KINDS, RecordingStats

PathLike = Union[str, "os.PathLike[str]"]
Recording = tuple[np.ndarray, Mapping[str, Any]]

DISTANCE_FORMULA = (
    "(W1_total + W1_on + W1_off) / m_real + |total_rel_error| + |on_off_ratio_rel_error|; "
    "W1_k = mean |sorted(real_k) - sorted(sim_k)| over pixels of the per-pixel count (or "
    "rate) of kind k, m_real = mean per-pixel total of the real recording"
)


# --------------------------------------------------------------------------------------------
# comparison


@dataclass
class SimComparison:
    """One simulation against the real recording.

    Differences are sim - real. ``*_rel_error`` = (sim - real) / real, on counts, or on rates
    when the comparison is by rate (see ``Comparison.value_unit``); 0 when both are equal
    (also both inf or both nan), +-inf when real is 0 or not finite and sim differs.
    Histogram arrays are per kind ('total', 'on', 'off') on ``Comparison.edges[kind]``:

    * ``hist``: fraction of the sensor's pixels in each bin;
    * ``error``: hist - real hist, which is also the error as a share of the sensor's pixel
      count (Fig. 9, right axis);
    * ``error_pixels``: the same in numbers of pixels (Fig. 9, left axis);
    * ``percent_error``: 100 (sim - real) / real per bin (Fig. 8); 0 where both are 0 and
      nan where real is 0 but sim is not (undefined).

    ``wasserstein[kind]`` is W1 between the per-pixel distributions, in ``value_unit``.
    """

    path: str
    stats: RecordingStats
    total_diff: int
    on_diff: int
    off_diff: int
    total_rel_error: float
    on_off_ratio_diff: float
    on_off_ratio_rel_error: float
    hist: dict[str, np.ndarray]
    error: dict[str, np.ndarray]
    error_pixels: dict[str, np.ndarray]
    percent_error: dict[str, np.ndarray]
    wasserstein: dict[str, float]
    distance: float
    max_bin_error_share: float

    @property
    def label(self) -> str:
        return _label(self.path)


@dataclass
class Comparison:
    """Result of :func:`compare`: the real recording's figures, one :class:`SimComparison`
    per simulation, and the adjustments made to compare them (e.g. by rate)."""

    real_path: str
    real: RecordingStats
    sims: list[SimComparison]
    bin_width: float
    value_unit: str
    edges: dict[str, np.ndarray]
    real_hist: dict[str, np.ndarray]
    adjustments: list[str] = field(default_factory=list)
    outputs: dict[str, str] = field(default_factory=dict)

    @property
    def pixel_count(self) -> int:
        return self.real.pixel_count

    @property
    def real_label(self) -> str:
        return _label(self.real_path)

    def to_json_dict(self) -> dict[str, Any]:
        """Every number, JSON-ready (arrays as lists, inf and nan as null)."""
        real = {"path": self.real_path, **self.real.to_dict(), "pixel_count": self.pixel_count}
        sims = []
        for s in self.sims:
            sims.append(
                {
                    "path": s.path,
                    **s.stats.to_dict(),
                    "total_diff": s.total_diff,
                    "on_diff": s.on_diff,
                    "off_diff": s.off_diff,
                    "total_rel_error": s.total_rel_error,
                    "on_off_ratio_diff": s.on_off_ratio_diff,
                    "on_off_ratio_rel_error": s.on_off_ratio_rel_error,
                    "distance": s.distance,
                    "max_bin_error_share": s.max_bin_error_share,
                    "wasserstein": s.wasserstein,
                    "histogram": s.hist,
                    "error": s.error,
                    "error_share": s.error,
                    "error_pixels": s.error_pixels,
                    "percent_error": s.percent_error,
                }
            )
        out = {
            "real": real,
            "sims": sims,
            "bin_width": self.bin_width,
            "value_unit": self.value_unit,
            "edges": self.edges,
            "real_histogram": self.real_hist,
            "adjustments": list(self.adjustments),
            "distance_formula": DISTANCE_FORMULA,
            "outputs": dict(self.outputs),
        }
        return _jsonable(out)

    def to_text(self) -> str:
        """A table of the headline figures (Table 4 plus the distances), for a terminal."""
        rows = [("recording", "total", "ON", "OFF", "ON/OFF", "dur [s]", "rel.tot", "distance", "max err")]
        r = self.real
        rows.append(
            (
                self.real_label + " (real)",
                str(r.total),
                str(r.on),
                str(r.off),
                _fmt(r.on_off_ratio, 3),
                _fmt(r.duration_s, 3),
                "",
                "",
                "",
            )
        )
        for s in self.sims:
            st = s.stats
            rows.append(
                (
                    s.label,
                    str(st.total),
                    str(st.on),
                    str(st.off),
                    _fmt(st.on_off_ratio, 3),
                    _fmt(st.duration_s, 3),
                    _fmt_pct(s.total_rel_error),
                    _fmt(s.distance, 4),
                    _fmt_pct(s.max_bin_error_share),
                )
            )
        widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]))]
        lines = [
            "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(row, widths)))
            for row in rows
        ]
        lines.insert(1, "-" * len(lines[0]))
        unit = "events" if self.value_unit == "events" else "events/s"
        lines.append(
            f"histogram bin width {self.bin_width:g} {unit}; max err = largest |bin error| "
            f"as a share of the {self.pixel_count} pixels"
        )
        lines.append(f"distance = {DISTANCE_FORMULA}")
        lines.extend(f"note: {a}" for a in self.adjustments)
        return "\n".join(lines)


def _label(path: str) -> str:
    return os.path.basename(str(path)) or str(path)


def _fmt(v: float, digits: int) -> str:
    return "n/a" if v is None or not math.isfinite(v) else f"{v:.{digits}f}"


def _fmt_pct(v: float) -> str:
    return "n/a" if v is None or not math.isfinite(v) else f"{100 * v:+.2f}%"


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [_jsonable(v) for v in obj.tolist()]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if math.isfinite(obj) else None
    return obj


def _rel_error(sim: float, real: float) -> float:
    if sim == real or (math.isnan(sim) and math.isnan(real)):
        return 0.0
    if real == 0 or not math.isfinite(real) or math.isnan(sim):
        return math.inf if math.isnan(sim) or sim > real else -math.inf
    return (sim - real) / real


def _diff(sim: float, real: float) -> float:
    if sim == real or (math.isnan(sim) and math.isnan(real)):
        return 0.0
    return sim - real


def _duration(events: np.ndarray, meta: Mapping[str, Any]) -> float:
    d = meta.get("duration_s")
    if d is not None:
        return float(d)
    if events.size == 0:
        return 0.0
    return (int(events["t"][-1]) - int(events["t"][0])) * 1e-6


def _size(meta: Mapping[str, Any], what: str) -> tuple[int, int]:
    try:
        return int(meta["width"]), int(meta["height"])
    except KeyError:
        raise ValueError(f"{what}: meta must give 'width' and 'height'; got keys {sorted(meta)}") from None


def compare(
    real_events: np.ndarray,
    real_meta: Mapping[str, Any],
    sims: Sequence[Recording],
    bin_width: float = 2,
    duration_rtol: float = 0.01,
) -> Comparison:
    """Compare a real recording with one or more simulations of the same sensor.

    real_meta / each sim's meta: a mapping with 'width' and 'height' [px]; optional
        'duration_s' (recording length; default last - first event time) and 'path' (a
        label; default 'real' and 'sim1', 'sim2', ...).
    bin_width: histogram bin width [events] (the paper: 2).
    duration_rtol: durations further apart than this relative tolerance are compared by rate.

    Different sensor sizes raise ValueError. Different durations: every per-pixel count is
    divided by its recording's duration and histogrammed in events/s with bin width
    ``bin_width / real duration`` (so the real histogram keeps its bins), totals are compared
    as rates, and the adjustment is written to ``adjustments``.

    The histograms of all recordings share one set of bin edges per kind, reaching the
    largest value of any of them. ``distance`` per simulation (0 for identical recordings)::

        distance = (W1_total + W1_on + W1_off) / m_real
                   + |total_rel_error| + |on_off_ratio_rel_error|

    with W1_k the 1-Wasserstein distance between the per-pixel count (or rate) distributions
    of kind k (:func:`evstwin.analysis.wasserstein_1`) and m_real the real mean per-pixel
    total. Each W1 term is dimensionless; a simulation that is the real one with every count
    scaled by k scores 3 |k - 1|. If the real recording has no events, a W1 term is 0 when the
    simulation has none either and inf otherwise. ``max_bin_error_share`` is the largest
    |bin error| over the three histograms, as a share of the sensor's pixels (the paper's
    "less than 2 % of the total number of pixels").
    """
    if len(sims) == 0:
        raise ValueError("compare needs at least one simulation")
    width, height = _size(real_meta, "real recording")
    real_path = str(real_meta.get("path", "real"))
    sim_paths = [str(m.get("path", f"sim{i + 1}")) for i, (_, m) in enumerate(sims)]
    for (_, m), p in zip(sims, sim_paths):
        w, h = _size(m, p)
        if (w, h) != (width, height):
            raise ValueError(
                f"sensor sizes differ: real {real_path} is {width}x{height}, simulation {p} is {w}x{h}; "
                "simulate the real sensor's size"
            )

    real_dur = _duration(real_events, real_meta)
    real_stats = analysis.stats(real_events, width, height, real_dur)
    sim_stats = [analysis.stats(e, width, height, _duration(e, m)) for e, m in sims]
    adjustments: list[str] = []
    differ = [
        (p, s.duration_s)
        for p, s in zip(sim_paths, sim_stats)
        if not math.isclose(s.duration_s, real_dur, rel_tol=duration_rtol)
    ]
    by_rate = bool(differ)
    if by_rate:
        bad = [
            (p, d)
            for p, d in [(real_path, real_dur)] + list(zip(sim_paths, [s.duration_s for s in sim_stats]))
            if not d > 0
        ]
        if bad:
            raise ValueError(f"durations differ and cannot be compared by rate: zero duration for {bad}")
        used_bw = float(bin_width) / real_dur
        listed = ", ".join(f"{p} {d:.6g} s" for p, d in differ)
        adjustments.append(
            f"durations differ (real {real_path} {real_dur:.6g} s; {listed}; tolerance "
            f"{100 * duration_rtol:g} %): per-pixel counts and totals compared by rate "
            f"(events/s), histogram bin width {bin_width:g} events / {real_dur:.6g} s = {used_bw:.6g} events/s"
        )
        value_unit = "events/s"
    else:
        used_bw = float(bin_width)
        value_unit = "events"

    def values(events: np.ndarray, st: RecordingStats) -> dict[str, np.ndarray]:
        # By rate, counts are rescaled to the real duration (count * T_real / T): the rate
        # times T_real. Binning these with the count bin width is binning rates with width
        # bin_width / T_real, and keeps the real recording's integer counts exact (no
        # rounding of count / T onto a bin edge).
        counts = analysis.pixel_counts(events, width, height)
        factor = real_dur / st.duration_s if by_rate else 1.0
        return {k: v * factor for k, v in counts.items()}

    real_vals = values(real_events, real_stats)
    sim_vals = [values(e, st) for (e, _), st in zip(sims, sim_stats)]
    edges: dict[str, np.ndarray] = {}
    real_hist: dict[str, np.ndarray] = {}
    sim_hist: list[dict[str, np.ndarray]] = [{} for _ in sims]
    for k in KINDS:
        top = max(float(v[k].max()) for v in [real_vals] + sim_vals)
        e, real_hist[k] = analysis.count_histogram(real_vals[k], bin_width, max_count=top)
        edges[k] = e / real_dur if by_rate else e
        for i, v in enumerate(sim_vals):
            _, sim_hist[i][k] = analysis.count_histogram(v[k], bin_width, max_count=top)

    npix = width * height
    m_real = float(real_vals["total"].mean())
    results: list[SimComparison] = []
    for i, (path, st) in enumerate(zip(sim_paths, sim_stats)):
        err = {k: sim_hist[i][k] - real_hist[k] for k in KINDS}
        pct: dict[str, np.ndarray] = {}
        for k in KINDS:
            r, s = real_hist[k], sim_hist[i][k]
            pe = np.full(r.shape, np.nan)
            np.divide(100.0 * (s - r), r, out=pe, where=r > 0)
            pe[(r == 0) & (s == 0)] = 0.0
            pct[k] = pe
        w1 = {k: analysis.wasserstein_1(real_vals[k], sim_vals[i][k]) for k in KINDS}
        if m_real > 0:
            w_term = sum(w1.values()) / m_real
        else:
            w_term = 0.0 if sum(w1.values()) == 0 else math.inf
        if by_rate:  # report W1 in events/s like the histograms
            w1 = {k: v / real_dur for k, v in w1.items()}
        if by_rate:
            tot_rel = _rel_error(st.total / st.duration_s, real_stats.total / real_dur)
        else:
            tot_rel = _rel_error(float(st.total), float(real_stats.total))
        ratio_rel = _rel_error(st.on_off_ratio, real_stats.on_off_ratio)
        results.append(
            SimComparison(
                path=path,
                stats=st,
                total_diff=st.total - real_stats.total,
                on_diff=st.on - real_stats.on,
                off_diff=st.off - real_stats.off,
                total_rel_error=tot_rel,
                on_off_ratio_diff=_diff(st.on_off_ratio, real_stats.on_off_ratio),
                on_off_ratio_rel_error=ratio_rel,
                hist=sim_hist[i],
                error=err,
                error_pixels={k: err[k] * npix for k in KINDS},
                percent_error=pct,
                wasserstein=w1,
                distance=float(w_term + abs(tot_rel) + abs(ratio_rel)),
                max_bin_error_share=float(max(np.abs(err[k]).max() for k in KINDS)),
            )
        )
    return Comparison(
        real_path=real_path,
        real=real_stats,
        sims=results,
        bin_width=used_bw,
        value_unit=value_unit,
        edges=edges,
        real_hist=real_hist,
        adjustments=adjustments,
    )


# --------------------------------------------------------------------------------------------
# Monte Carlo


@dataclass
class MonteCarloSummary:
    """Mean and sample standard deviation (ddof = 1; null for a single run) over ``runs``
    comparisons of every number of :meth:`Comparison.to_json_dict`, in the same layout.

    Histogram-shaped lists of different lengths (runs whose largest count differs) are padded
    with the empty bins they imply (0, and longer ``edges``). Undefined values (null, e.g. the
    percent error of a bin the real recording leaves empty) are left out of a mean; a value
    undefined in every run stays null. Strings equal in every run are kept, others listed.
    """

    runs: int
    mean: dict[str, Any]
    std: dict[str, Any]

    def to_json_dict(self) -> dict[str, Any]:
        return {"runs": self.runs, "mean": self.mean, "std": self.std}

    def to_text(self) -> str:
        """Mean +- std of the headline figures per simulation, for a terminal."""
        lines = [f"Monte Carlo over {self.runs} runs (mean +- sample std)"]
        for m, s in zip(self.mean["sims"], self.std["sims"]):
            path = m["path"] if isinstance(m["path"], str) else ",".join(m["path"])
            lines.append(f"{_label(path)}:")
            for key in (
                "total",
                "on",
                "off",
                "on_off_ratio",
                "total_rel_error",
                "distance",
                "max_bin_error_share",
            ):
                mv, sv = m.get(key), s.get(key)
                lines.append(f"  {key:22s} {_num(mv)} +- {_num(sv)}")
        return "\n".join(lines)


def _num(v: Any) -> str:
    return "n/a" if v is None else f"{v:.6g}"


def _is_num(v: Any) -> bool:
    return v is None or (isinstance(v, (int, float)) and not isinstance(v, bool))


def _mean_std(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Column mean and sample std of a (runs, n) float array, ignoring nan, without warnings."""
    ok = ~np.isnan(rows)
    n = ok.sum(axis=0)
    filled = np.where(ok, rows, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(n > 0, filled.sum(axis=0) / np.maximum(n, 1), np.nan)
        dev = np.where(ok, rows - mean, 0.0)
        var = np.where(n > 1, (dev**2).sum(axis=0) / np.maximum(n - 1, 1), np.nan)
    return mean, np.sqrt(var)


def _aggregate(values: list[Any], where: tuple[str, ...] = ()) -> tuple[Any, Any]:
    key = ".".join(where)
    if all(isinstance(v, dict) for v in values):
        keys = list(values[0].keys())
        if any(list(v.keys()) != keys for v in values):
            raise ValueError(f"runs differ in the layout of {key or 'the result'}")
        pairs = {k: _aggregate([v[k] for v in values], where + (str(k),)) for k in keys}
        return {k: p[0] for k, p in pairs.items()}, {k: p[1] for k, p in pairs.items()}
    if all(isinstance(v, list) for v in values):
        if all(all(_is_num(x) for x in v) for v in values):
            n = max(len(v) for v in values)
            if "edges" in where:
                longest = max(values, key=len)
                return longest, [0.0] * n
            rows = np.zeros((len(values), n))
            for i, v in enumerate(values):
                rows[i, : len(v)] = [np.nan if x is None else x for x in v]
            mean, std = _mean_std(rows)
            return _jsonable(mean), _jsonable(std)
        if all(len(v) == len(values[0]) for v in values):
            pairs_l = [_aggregate([v[i] for v in values], where + (str(i),)) for i in range(len(values[0]))]
            return [p[0] for p in pairs_l], [p[1] for p in pairs_l]
        if any(isinstance(x, (dict, list)) for v in values for x in v):
            raise ValueError(f"runs differ in the number of entries of {key!r}")
    if all(_is_num(v) for v in values):
        rows = np.array([[np.nan if v is None else float(v)] for v in values])
        mean, std = _mean_std(rows)
        return _jsonable(mean[0]), _jsonable(std[0])
    if all(v == values[0] for v in values):
        return values[0], None
    return list(values), None  # e.g. differing paths or adjustments: listed per run


def aggregate(comparisons: Sequence[Comparison]) -> MonteCarloSummary:
    """Mean and spread of every figure over N runs (e.g. N seeds of one scenario).

    Every comparison must have the same simulations in the same order (sim i of every run is
    one scenario) and the same histogram bin width. See :class:`MonteCarloSummary`.
    """
    if len(comparisons) == 0:
        raise ValueError("aggregate needs at least one comparison")
    widths = {c.bin_width for c in comparisons}
    if len(widths) != 1:
        raise ValueError(f"runs use different histogram bin widths {sorted(widths)}")
    units = {c.value_unit for c in comparisons}
    if len(units) != 1:
        raise ValueError(f"runs compare in different units {sorted(units)} (some by rate)")
    counts = {len(c.sims) for c in comparisons}
    if len(counts) != 1:
        raise ValueError(f"runs compare different numbers of simulations {sorted(counts)}")
    trees = [c.to_json_dict() for c in comparisons]
    for t in trees:
        t.pop("outputs", None)
    mean, std = _aggregate(trees)
    return MonteCarloSummary(runs=len(comparisons), mean=mean, std=std)


# --------------------------------------------------------------------------------------------
# files (the CLI's entry points)


def _read(path: PathLike) -> tuple[np.ndarray, dict[str, Any]]:
    from .io import read_events  # lazy: io is optional at import time

    events, meta = read_events(path)
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
) -> Comparison:
    """Read the recordings (any format :func:`evstwin.io.read_events` takes), compare them,
    and write ``out_dir/compare.json`` (every number) and the figures:

    frames.png (Fig. 5: ``n_windows`` successive ``window_s`` windows overlaid, from
    ``t_offset_s`` after each recording's start), xyt.png (Fig. 6, the same time slice),
    histograms.png (Fig. 7), percent_error.png (Fig. 8), bin_error.png (Fig. 9) and
    event_rate.png (bins of ``rate_bin_s``, default about 1/100 of the real duration).
    The written paths are in ``Comparison.outputs``.
    """
    from . import plots

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    real_events, real_meta = _read(real_path)
    sims = [_read(p) for p in sim_paths]
    comp = compare(real_events, real_meta, sims, bin_width=bin_width)
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


def info(path: PathLike) -> str:
    """A summary of one recording, as text."""
    events, meta = _read(path)
    return format_info(events, meta)


def format_info(events: np.ndarray, meta: Mapping[str, Any]) -> str:
    """The text of :func:`info` for events already in memory."""
    width, height = _size(meta, str(meta.get("path", "recording")))
    st = analysis.stats(events, width, height, _duration(events, meta))
    counts = analysis.pixel_counts(events, width, height)["total"]
    active = int(np.count_nonzero(counts))
    lines = [
        f"file          {meta.get('path', '')}",
        f"sensor        {width} x {height} px ({st.pixel_count} pixels)",
        f"events        {st.total} (ON {st.on}, OFF {st.off}), ON/OFF {_fmt(st.on_off_ratio, 4)}",
        f"time          {st.t_start_us} .. {st.t_end_us} us, duration {st.duration_s:.6g} s",
        (
            f"mean rate     {_fmt(st.mean_rate_hz, 1)} events/s, "
            f"{_fmt(st.mean_rate_hz / st.pixel_count, 4)} events/s per pixel"
        ),
        (
            f"per pixel     mean {counts.mean():.4g}, max {int(counts.max()) if counts.size else 0} events; "
            f"{active} pixels ({100 * active / st.pixel_count:.2f} %) have events"
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
) -> dict[str, str]:
    """Draw one recording's figures into ``out_dir``: frames.png, xyt.png, histograms.png and
    event_rate.png (options as in :func:`compare_files`). Returns {figure: path}."""
    from . import plots

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    events, meta = _read(path)
    width, height = _size(meta, str(path))
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
    from . import plots

    return {
        "frames": plots.plot_frames(
            recs, width, height, out / "frames.png", window_s=window_s, n_windows=n_windows, t_offset_s=t_offset_s
        ),
        "xyt": plots.plot_xyt(
            recs, width, height, out / "xyt.png", t_offset_s=t_offset_s, duration_s=window_s * n_windows
        ),
        "event_rate": plots.plot_event_rate(recs, out / "event_rate.png", bin_s=bin_s),
    }


# --------------------------------------------------------------------------------------------
# event-timing bias

TruthTrack = Mapping[str, np.ndarray]


def _crossings(
    name_index: int, track: TruthTrack, radius_px: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Closest approaches of one sampled track to every pixel centre within radius_px.

    The track is linear between samples. A pixel's closest approach on a segment is the foot
    of the perpendicular from its centre; it counts when it falls inside the segment
    (0 <= u < 1) and lies within radius_px. Stationary segments have no crossing.
    Returns (x, y, t_s, distance_px, flux_ph_s, speed_px_s, target index) arrays.
    """
    t = np.asarray(track["t_s"], dtype=np.float64)
    xs = np.asarray(track["x_px"], dtype=np.float64)
    ys = np.asarray(track["y_px"], dtype=np.float64)
    flux = np.broadcast_to(np.asarray(track["flux_ph_s"], dtype=np.float64), t.shape)
    if not (t.shape == xs.shape == ys.shape) or t.ndim != 1:
        raise ValueError(
            f"truth arrays t_s, x_px, y_px must be 1-D of one length; got {t.shape}, {xs.shape}, {ys.shape}"
        )
    if t.size >= 2 and np.any(np.diff(t) < 0):
        raise ValueError("truth t_s must be increasing")
    x0, x1, y0, y1 = xs[:-1], xs[1:], ys[:-1], ys[1:]
    dt = np.diff(t)
    dx, dy = x1 - x0, y1 - y0
    len2 = dx * dx + dy * dy
    seg = np.nonzero((len2 > 0) & (dt > 0))[0]
    empty = np.zeros(0)
    if seg.size == 0:
        return (empty.astype(np.int64),) * 2 + (empty,) * 4 + (empty.astype(np.int64),)  # type: ignore[return-value]
    xmin = np.floor(np.minimum(x0, x1)[seg] - radius_px).astype(np.int64)
    xmax = np.ceil(np.maximum(x0, x1)[seg] + radius_px).astype(np.int64)
    ymin = np.floor(np.minimum(y0, y1)[seg] - radius_px).astype(np.int64)
    ymax = np.ceil(np.maximum(y0, y1)[seg] + radius_px).astype(np.int64)
    nx, ny = xmax - xmin + 1, ymax - ymin + 1
    n = nx * ny
    owner = np.repeat(np.arange(seg.size), n)
    local = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
    px = xmin[owner] + local % nx[owner]
    py = ymin[owner] + local // nx[owner]
    s = seg[owner]
    u = ((px - x0[s]) * dx[s] + (py - y0[s]) * dy[s]) / len2[s]
    cx, cy = x0[s] + u * dx[s], y0[s] + u * dy[s]
    dist = np.hypot(px - cx, py - cy)
    keep = (u >= 0) & (u < 1) & (dist <= radius_px) & (px >= 0) & (py >= 0)
    s, u, px, py, dist = s[keep], u[keep], px[keep], py[keep], dist[keep]
    tc = t[s] + u * dt[s]
    fc = flux[s] + u * (flux[s + 1] - flux[s])
    speed = np.sqrt(len2[s]) / dt[s]
    return px, py, tc, dist, fc, speed, np.full(px.size, name_index, dtype=np.int64)


def timing_bias(
    events: np.ndarray,
    truth: Mapping[str, TruthTrack],
    radius_px: float = 1.0,
    max_abs_delay_s: float | None = 0.1,
) -> np.ndarray:
    """Delay of each event after the true crossing of a source over its pixel.

    truth: target name -> {'t_s', 'x_px', 'y_px', 'flux_ph_s'}: the sampled track [s, px] of
        the source centre (pixel (x, y) covers [x - 0.5, x + 0.5] x [y - 0.5, y + 0.5], its
        centre at integer coordinates) and its photon flux [photons/s] (scalar or per
        sample). The track is linear between samples.
    radius_px: an event is attributed to a crossing of its pixel when the track's closest
        approach to the pixel centre is within this distance [px] (default 1 px).
    max_abs_delay_s: ... and when |delay| <= this [s] (default 0.1 s; None: no limit). Keep it
        below the time between two passes of a source over one pixel.

    The true crossing time is when the interpolated track passes closest to the pixel centre;
    each event takes the crossing of its pixel nearest in time (any target), and its delay is
    event time - crossing time [s] (negative: the event came first). Events with no crossing
    are left out; so are crossings by a stationary source (no crossing time).

    Returns a structured array, one row per attributed event, sorted by event time: target
    (name), t_us, x, y, p (the event), t_true_s, delay_s, distance_px (closest approach),
    flux_ph_s and speed_px_s (of the source at the crossing).
    """
    events = analysis._check_events(events)
    names = list(truth.keys())
    parts = [_crossings(i, truth[n], float(radius_px)) for i, n in enumerate(names)]
    name_len = max([len(str(n)) for n in names] + [1])
    dtype = np.dtype(
        [
            ("target", f"U{name_len}"),
            ("t_us", "<i8"),
            ("x", "<u2"),
            ("y", "<u2"),
            ("p", "u1"),
            ("t_true_s", "<f8"),
            ("delay_s", "<f8"),
            ("distance_px", "<f8"),
            ("flux_ph_s", "<f8"),
            ("speed_px_s", "<f8"),
        ]
    )
    if not parts or events.size == 0:
        return np.zeros(0, dtype=dtype)
    cx, cy, ct, cd, cf, cs, ci = (np.concatenate([p[j] for p in parts]) for j in range(7))
    if ct.size == 0:
        return np.zeros(0, dtype=dtype)
    ex = events["x"].astype(np.int64)
    ey = events["y"].astype(np.int64)
    et_s = events["t"].astype(np.int64) * 1e-6
    width = int(max(cx.max(), ex.max())) + 1
    ckey = cy * width + cx
    ekey = ey * width + ex
    # One sorted int64 key per (pixel, time [us]), so that searchsorted finds, for each
    # event, the crossings of its pixel just before and after it.
    t0 = min(float(ct.min()), float(et_s.min()))
    ct_us = np.floor((ct - t0) * 1e6).astype(np.int64)
    et_us = np.floor((et_s - t0) * 1e6).astype(np.int64)
    span = int(max(ct_us.max(), et_us.max())) + 2
    if int(max(ckey.max(), ekey.max())) + 1 > (2**62) // span:
        raise ValueError("time span x sensor size too large for the crossing index")
    ccomp = ckey * span + ct_us
    order = np.argsort(ccomp, kind="stable")
    ccomp, ckey, ct = ccomp[order], ckey[order], ct[order]
    ecomp = ekey * span + et_us
    hi = np.searchsorted(ccomp, ecomp, side="right")
    lo = hi - 1
    nc = ccomp.size
    lo_ok = (lo >= 0) & (ckey[np.clip(lo, 0, nc - 1)] == ekey)
    hi_ok = (hi < nc) & (ckey[np.clip(hi, 0, nc - 1)] == ekey)
    d_lo = np.where(lo_ok, np.abs(et_s - ct[np.clip(lo, 0, nc - 1)]), np.inf)
    d_hi = np.where(hi_ok, np.abs(et_s - ct[np.clip(hi, 0, nc - 1)]), np.inf)
    pick = np.where(d_hi < d_lo, hi, lo)
    best = np.minimum(d_lo, d_hi)
    ok = np.isfinite(best)
    if max_abs_delay_s is not None:
        ok &= best <= max_abs_delay_s
    ev = np.nonzero(ok)[0]
    c = order[pick[ev]]
    out = np.zeros(ev.size, dtype=dtype)
    out["target"] = np.asarray(names, dtype=object)[ci[c]].astype(str) if ev.size else []
    out["t_us"] = events["t"][ev]
    out["x"] = events["x"][ev]
    out["y"] = events["y"][ev]
    out["p"] = events["p"][ev]
    t_true = np.concatenate([p[2] for p in parts])[c]
    out["t_true_s"] = t_true
    out["delay_s"] = et_s[ev] - t_true
    out["distance_px"] = cd[c]
    out["flux_ph_s"] = cf[c]
    out["speed_px_s"] = cs[c]
    return out


def _bin_edges(values: np.ndarray, bins: int | Sequence[float] | np.ndarray, log: bool) -> np.ndarray:
    if np.ndim(bins) == 1:
        return np.asarray(bins, dtype=np.float64)
    n = int(bins)  # type: ignore[arg-type]
    lo, hi = float(values.min()), float(values.max())
    if log and lo > 0:
        if hi == lo:
            return np.array([lo / 1.001, hi * 1.001])
        return np.geomspace(lo, hi, n + 1)
    if hi == lo:
        return np.array([lo - 0.5, hi + 0.5])
    return np.linspace(lo, hi, n + 1)


def timing_bias_summary(
    table: np.ndarray,
    by: str = "target",
    bins: int | Sequence[float] | np.ndarray = 5,
    percentiles: Sequence[float] = (5, 25, 50, 75, 95),
) -> list[dict[str, Any]]:
    """Delay statistics per group of a :func:`timing_bias` table.

    by: 'target' (one group per name), 'polarity' (ON, OFF), 'flux' (``bins`` log-spaced
        flux bins [photons/s] between the smallest and largest, or explicit edges) or 'speed'
        (``bins`` linear speed bins [px/s], or edges). Bins are [lo, hi), the last [lo, hi].
    Returns one dict per non-empty group: group (name or [lo, hi]), n, mean_s, std_s and
    p<q>_s for each percentile q (delays in seconds; the median is p50_s).
    """
    if by not in ("target", "polarity", "flux", "speed"):
        raise ValueError(f"by must be 'target', 'polarity', 'flux' or 'speed'; got {by!r}")
    delay = np.asarray(table["delay_s"], dtype=np.float64)
    groups: list[tuple[Any, np.ndarray]] = []
    if delay.size == 0:
        return []
    if by == "target":
        names, inv = np.unique(table["target"], return_inverse=True)
        groups = [(str(n), inv == i) for i, n in enumerate(names)]
    elif by == "polarity":
        groups = [("ON", table["p"] != 0), ("OFF", table["p"] == 0)]
    else:
        col = "flux_ph_s" if by == "flux" else "speed_px_s"
        vals = np.asarray(table[col], dtype=np.float64)
        edges = _bin_edges(vals, bins, log=(by == "flux"))
        idx = np.searchsorted(edges, vals, side="right") - 1
        idx[vals == edges[-1]] = edges.size - 2
        groups = [([float(edges[i]), float(edges[i + 1])], idx == i) for i in range(edges.size - 1)]
    out = []
    for label, mask in groups:
        d = delay[mask]
        if d.size == 0:
            continue
        row: dict[str, Any] = {
            "group": label,
            "n": int(d.size),
            "mean_s": float(d.mean()),
            "std_s": float(d.std(ddof=1)) if d.size > 1 else None,
        }
        for q, v in zip(percentiles, np.percentile(d, list(percentiles))):
            row[f"p{q:g}_s"] = float(v)
        out.append(row)
    return out


def format_timing_bias_summary(rows: Sequence[Mapping[str, Any]], by: str = "target") -> str:
    """A text table of :func:`timing_bias_summary` rows (delays in ms)."""
    if not rows:
        return "no event attributed to a crossing"
    pkeys = [k for k in rows[0] if k.startswith("p") and k.endswith("_s")]
    head = [by, "n", "mean [ms]"] + [k[:-2] + " [ms]" for k in pkeys]
    body = []
    for r in rows:
        g = r["group"]
        gtxt = f"{g[0]:.4g}..{g[1]:.4g}" if isinstance(g, list) else str(g)
        body.append([gtxt, str(r["n"]), f"{1e3 * r['mean_s']:.3f}"] + [f"{1e3 * r[k]:.3f}" for k in pkeys])
    widths = [max(len(x) for x in col) for col in zip(head, *body)]
    lines = ["  ".join(c.rjust(w) for c, w in zip(row, widths)) for row in [head] + body]
    return "\n".join(lines)
