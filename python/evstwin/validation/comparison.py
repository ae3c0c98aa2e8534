"""One simulation against a real recording (the paper's section 3): totals, ON/OFF, per-pixel count histograms, their errors, and the summary distance."""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Union

import numpy as np

from .. import analysis
from ..analysis import KINDS, CountedRecording, RecordingStats

PathLike = Union[str, "os.PathLike[str]"]


Recording = tuple[np.ndarray | CountedRecording, Mapping[str, Any]]


DISTANCE_FORMULA = (
    "sum_k W1_k / (m_real + 1/N) + |ln(R_sim / R_real)| + |ln(O_sim / O_real)|; k = total, ON, OFF; "
    "W1_k = mean |sorted(real_k) - sorted(sim_k)| over the N compared pixels of the per-pixel count "
    "(each simulated count scaled to the real duration when the durations differ), m_real = mean per-pixel "
    "total of the real recording; R = events + 1/2, O = (ON + 1/2) / (OFF + 1/2), the simulation's counts "
    "scaled to the real duration when the durations differ"
)
"""The summary distance of :func:`compare`, in one line (written into every report)."""


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
    distance_terms: dict[str, float] = field(default_factory=dict)
    """The three terms of ``distance``: ``w1`` (histogram shape and level), ``rate`` (total
    rate) and ``polarity`` (ON/OFF balance)."""

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
    masked_pixels: int = 0
    """Pixels left out of every statistic (the ``mask`` of :func:`compare`)."""
    region: str = ""
    """The region compared, in words (ROI and mask; empty: the whole sensor)."""

    @property
    def pixel_count(self) -> int:
        """The pixels compared: the recording's, less the masked ones (the Fig. 9 share's base)."""
        return self.real.pixel_count - self.masked_pixels

    @property
    def real_label(self) -> str:
        return _label(self.real_path)

    def to_json_dict(self) -> dict[str, Any]:
        """Every number, JSON-ready (arrays as lists, inf and nan as null)."""
        real = {
            "path": self.real_path,
            **self.real.to_dict(),
            "pixel_count": self.pixel_count,
            "masked_pixels": self.masked_pixels,
            "region": self.region,
        }
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
                    "distance_terms": s.distance_terms,
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
            f"as a share of the {self.pixel_count} pixels compared (Fig. 9)"
        )
        if self.region:
            lines.append(f"pixels: {self.region}")
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


def _duration(events: np.ndarray | CountedRecording, meta: Mapping[str, Any]) -> float:
    d = meta.get("duration_s")
    if d is not None:
        return float(d)
    if isinstance(events, CountedRecording):
        return events.stats().duration_s
    if events.size == 0:
        return 0.0
    return (int(events["t"][-1]) - int(events["t"][0])) * 1e-6


def _stats(events: np.ndarray | CountedRecording, width: int, height: int, duration_s: float) -> RecordingStats:
    if isinstance(events, CountedRecording):
        return events.stats(duration_s)
    return analysis.stats(events, width, height, duration_s)


def _pixel_counts(events: np.ndarray | CountedRecording, width: int, height: int) -> dict[str, np.ndarray]:
    if isinstance(events, CountedRecording):
        return events.pixel_counts()
    return analysis.pixel_counts(events, width, height)


def _size(meta: Mapping[str, Any], what: str) -> tuple[int, int]:
    try:
        return int(meta["width"]), int(meta["height"])
    except KeyError:
        raise ValueError(f"{what}: meta must give 'width' and 'height'; got keys {sorted(meta)}") from None


def compare(
    real_events: np.ndarray | CountedRecording,
    real_meta: Mapping[str, Any],
    sims: Sequence[Recording],
    bin_width: float = 2,
    duration_rtol: float = 0.01,
    mask: np.ndarray | None = None,
    region: str = "",
) -> Comparison:
    """Compare a real recording with one or more simulations of the same sensor.

    real_events / each sim's events: an event array, or a :class:`evstwin.analysis.CountedRecording`
        built chunk by chunk (a recording larger than memory; the result is the same).
    real_meta / each sim's meta: a mapping with 'width' and 'height' [px]; optional
        'duration_s' (recording length; default last - first event time) and 'path' (a
        label; default 'real' and 'sim1', 'sim2', ...).
    bin_width: histogram bin width [events] (the paper: 2).
    duration_rtol: durations further apart than this relative tolerance are compared by rate.
    mask: (height, width) bool, True = a pixel left out of every statistic of every recording
        (its events are not counted in the totals, the ON/OFF balance or the histograms,
        whose shares are of the N pixels left). Recordings cut to a region of interest are
        compared as recordings of that region's size (:mod:`evstwin.validation.region`).
    region: the region compared, in words, for the report.

    Different sensor sizes raise ValueError. Different durations: every per-pixel count is
    divided by its recording's duration and histogrammed in events/s with bin width
    ``bin_width / real duration`` (so the real histogram keeps its bins), totals are compared
    as rates, and the adjustment is written to ``adjustments``.

    The histograms of all recordings share one set of bin edges per kind, reaching the
    largest value of any of them. ``distance`` per simulation, finite for any two recordings
    (one with no OFF events, one with no events at all) and 0 for identical ones::

        distance = (W1_total + W1_on + W1_off) / (m_real + 1/N)      "w1"
                   + |ln(R_sim / R_real)|                              "rate"
                   + |ln(O_sim / O_real)|                              "polarity"

    * W1_k: the 1-Wasserstein distance between the per-pixel count distributions of kind k
      over the N compared pixels (:func:`evstwin.analysis.wasserstein_1`), each simulated
      count scaled by T_real / T_sim when compared by rate; m_real the real mean per-pixel
      total. The ``1/N`` (one event shared by the pixels) keeps the term finite for an empty
      real recording and changes it by a factor 1 / (1 + 1/total) otherwise.
    * R = events + 1/2: the total, the simulation's scaled by T_real / T_sim when compared by
      rate (so it is the rate times T_real, and half an event per real duration is added).
    * O = (ON + 1/2) / (OFF + 1/2), counts scaled likewise: the ON/OFF ratio with the
      Haldane-Anscombe 1/2, finite when either polarity is missing.

    The logarithms make the terms symmetric (k times too many events costs what k times too
    few does) and, for small errors, equal to the relative errors (``total_rel_error``,
    ``on_off_ratio_rel_error``, still reported). A simulation that is the real one with every
    count scaled by k scores about 3 |k - 1| + |ln k|. ``max_bin_error_share`` is the largest
    |bin error| over the three histograms, as a share of the N pixels (the paper's Fig. 9,
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
    keep = np.ones((height, width), dtype=bool)
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != (height, width):
            raise ValueError(f"mask must be a (height, width) = ({height}, {width}) array; got shape {mask.shape}")
        keep = ~mask
    n_kept = int(np.count_nonzero(keep))
    if n_kept == 0:
        raise ValueError(f"the mask leaves no pixel of the {width}x{height} recording to compare")

    def counted(events: np.ndarray | CountedRecording) -> dict[str, np.ndarray]:
        counts = _pixel_counts(events, width, height)
        return {k: np.asarray(v)[keep] for k, v in counts.items()}

    real_dur = _duration(real_events, real_meta)
    real_counts = counted(real_events)
    real_stats = _masked_stats(_stats(real_events, width, height, real_dur), real_counts, mask)
    sim_counts = [counted(e) for e, _ in sims]
    sim_stats = [
        _masked_stats(_stats(e, width, height, _duration(e, m)), c, mask) for (e, m), c in zip(sims, sim_counts)
    ]
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

    def values(counts: dict[str, np.ndarray], st: RecordingStats) -> dict[str, np.ndarray]:
        # By rate, counts are rescaled to the real duration (count * T_real / T): the rate
        # times T_real. Binning these with the count bin width is binning rates with width
        # bin_width / T_real, and keeps the real recording's integer counts exact (no
        # rounding of count / T onto a bin edge).
        factor = real_dur / st.duration_s if by_rate else 1.0
        return {k: v * factor for k, v in counts.items()}

    real_vals = values(real_counts, real_stats)
    sim_vals = [values(c, st) for c, st in zip(sim_counts, sim_stats)]
    edges: dict[str, np.ndarray] = {}
    real_hist: dict[str, np.ndarray] = {}
    sim_hist: list[dict[str, np.ndarray]] = [{} for _ in sims]
    for k in KINDS:
        top = max(float(v[k].max()) for v in [real_vals] + sim_vals)
        e, real_hist[k] = analysis.count_histogram(real_vals[k], bin_width, max_count=top)
        edges[k] = e / real_dur if by_rate else e
        for i, v in enumerate(sim_vals):
            _, sim_hist[i][k] = analysis.count_histogram(v[k], bin_width, max_count=top)

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
        terms = _distance_terms(w1, m_real, n_kept, real_stats, st, by_rate)
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
                error_pixels={k: err[k] * n_kept for k in KINDS},
                percent_error=pct,
                wasserstein=w1,
                distance=float(sum(terms.values())),
                max_bin_error_share=float(max(np.abs(err[k]).max() for k in KINDS)),
                distance_terms=terms,
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
        masked_pixels=width * height - n_kept,
        region=region,
    )


def _masked_stats(st: RecordingStats, counts: Mapping[str, np.ndarray], mask: np.ndarray | None) -> RecordingStats:
    """The recording's stats with the masked pixels' events taken out of the totals."""
    if mask is None or not mask.any():
        return st
    on, off = int(counts["on"].sum()), int(counts["off"].sum())
    total = on + off
    return dataclasses.replace(
        st,
        total=total,
        on=on,
        off=off,
        on_off_ratio=analysis.ratio(on, off),
        mean_rate_hz=total / st.duration_s if st.duration_s > 0 else math.nan,
    )


def _distance_terms(
    w1: Mapping[str, float], m_real: float, n_pixels: int, real: RecordingStats, sim: RecordingStats, by_rate: bool
) -> dict[str, float]:
    """The three terms of the distance (see :func:`compare`); finite for any counts."""
    w_term = sum(w1.values()) / (m_real + 1.0 / n_pixels)
    # Counts with half an event added, the simulation's scaled to the real duration when the
    # durations differ (rates times T_real: equal rates give equal values), so an empty
    # recording or a missing polarity stays finite, and a zero-length pair of equal
    # durations compares by count.
    f = real.duration_s / sim.duration_s if by_rate else 1.0
    rate = abs(math.log((f * sim.total + 0.5) / (real.total + 0.5)))
    polarity = abs(
        math.log((f * sim.on + 0.5) / (f * sim.off + 0.5)) - math.log((real.on + 0.5) / (real.off + 0.5))
    )
    return {"w1": float(w_term), "rate": float(rate), "polarity": float(polarity)}
