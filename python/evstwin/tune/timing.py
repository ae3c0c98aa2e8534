"""Statistics that carry timing, beside the fit's per-pixel counts (``FitOptions.statistics='timing'``).

The counts of a short recording cannot tell a lower threshold on a brighter dark current from
the opposite (both give the same number of events: the README's threshold / dark-current
valley); when the events fire can. Beside :mod:`evstwin.tune.counts`' statistics, per pixel
group (the same groups, by the light the scenario's sources bring):

* **delay after the source's passage** (lit groups, per polarity): each event's time minus
  the time its pixel got the most source light (:func:`source_light`, from the scenario's
  truth), counted in the bins between the real recording's own quantiles
  :data:`DELAY_QUANTILES` of that delay. The events of a passage fire while the pixel's log
  intensity rises and falls by ln(1 + I_source / I_dark) through a photoreceptor whose
  bandwidth grows with its current: the dark current sets both where on the rise the first
  event fires and how fast the pixel follows, the threshold only how many fire. Constrains
  the dark rate against the thresholds (and the photoreceptor's bandwidth).
* **intervals between a pixel's successive events**, per transition (ON->ON, ON->OFF,
  OFF->ON, OFF->OFF) and group, counted between the real recording's quantiles
  :data:`INTERVAL_QUANTILES` of each. Within a passage, successive same-polarity events are
  one threshold of log intensity apart: their intervals follow theta / (d ln I / dt), so the
  ratio of theta to the contrast the dark current leaves. The lowest quantile bins (2 %,
  10 %) hold the **refractory period's imprint**: no interval of a pixel is shorter than
  refractory_s, so a longer refractory empties them and a shorter one fills them. In the
  quiet group the intervals are the background's: shot noise is Poisson (exponential
  intervals), the leak a clock (near-regular intervals of theta_on / leak rate): they tell
  the leak from the shot noise where the counts see only their sum.
* **ON/OFF alternation**: the count of each transition is the bins' sum: how often a pixel's
  next event has the other polarity (a passage gives ON runs then OFF runs; the shot noise
  alternates at random; the leak gives ON runs alone).
* **the background's rate and spread** are the quiet group's count histogram and totals,
  already in the counts.

Each statistic is a count (of events or intervals in a bin), standardised as the counts are:
by its analytic Poisson noise, the Pearson term (r - m)^2 / (m + r / K + 1)
(:data:`evstwin.tune.counts.CHI2_FORMULA`). The bins' edges come from the real recording once,
so they depend on no fitted value. Where the recording holds fewer than
:data:`MIN_TIMING_SAMPLES` delays or intervals of a kind, that kind is one bin (its count).
Intervals and delays of one pixel share events, so the statistics are correlated; the
calibrated intervals (``FitOptions.intervals``) measure that correlation from replicate
seeds (:func:`evstwin.tune.counts.chi2_covariance`).

The recording's times are taken on the scenario's clock (t = 0 at the scenario's start), as
its pixel groups already take the scenario's geometry.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .counts import GROUP_LEVELS, CountsObjective, count_statistics

TIMING_FORMULA = (
    "and, the same Pearson terms, the timing statistics: per lit group and polarity the events' delays after "
    "their pixel's source passage, per group and transition (ON->ON, ON->OFF, OFF->ON, OFF->OFF) the intervals "
    "between a pixel's successive events, each counted in the bins between the real recording's quantiles"
)
"""What the timing statistics add to :data:`evstwin.tune.counts.CHI2_FORMULA` (fit.json)."""

DELAY_QUANTILES: tuple[float, ...] = (0.1, 0.25, 0.5, 0.75, 0.9)
"""The real recording's quantiles of each lit group's and polarity's delays that bound the
delay bins (six bins, the outer two open)."""

INTERVAL_QUANTILES: tuple[float, ...] = (0.02, 0.1, 0.25, 0.5, 0.75)
"""The real recording's quantiles of each group's and transition's intervals that bound the
interval bins (six bins, the outer two open): 2 % and 10 % for the refractory imprint."""

MIN_TIMING_SAMPLES = 30
"""A kind of delay or interval with fewer samples in the real recording gets one bin."""

TRANSITIONS: tuple[tuple[int, int], ...] = ((1, 1), (1, 0), (0, 1), (0, 0))
"""(polarity of an event, polarity of the pixel's next one): ON->ON, ON->OFF, OFF->ON, OFF->OFF."""


def quantile_edges(values: np.ndarray, quantiles: Sequence[float]) -> np.ndarray:
    """The inner bin edges at ``quantiles`` of ``values`` (distinct, increasing; empty when
    there are fewer than :data:`MIN_TIMING_SAMPLES` values: one bin)."""
    v = np.asarray(values, np.float64)
    if v.size < MIN_TIMING_SAMPLES:
        return np.zeros(0)
    return np.unique(np.quantile(v, quantiles))


def binned(values: np.ndarray, inner_edges: np.ndarray) -> np.ndarray:
    """Counts of ``values`` in the len(inner_edges) + 1 bins the inner edges bound (a value on
    an edge goes to the bin above it)."""
    idx = np.searchsorted(inner_edges, np.asarray(values, np.float64), side="right")
    return np.bincount(idx, minlength=inner_edges.size + 1).astype(np.float64)


def pixel_sequences(events: np.ndarray, width: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The events ordered by pixel, then time: (pixel index y * width + x, t [us], p)."""
    pixel = events["y"].astype(np.int64) * width + events["x"].astype(np.int64)
    t = events["t"].astype(np.int64)
    order = np.lexsort((t, pixel))
    return pixel[order], t[order], events["p"][order].astype(np.int64)


def timing_samples(events: np.ndarray, width: int, groups: np.ndarray, passage_s: np.ndarray,
                   n_groups: int) -> dict[tuple[str, int, int, int], np.ndarray]:
    """The recording's delays and intervals by kind: ``('delay', group, polarity, -1)`` ->
    event time minus its pixel's passage time [s] (lit groups, groups >= 1);
    ``('interval', group, p_first, p_next)`` -> the time from each event to its pixel's next
    [s]. Masked pixels (group -1) are left out."""
    flat_groups = groups.reshape(-1)
    flat_pass = passage_s.reshape(-1)
    pixel, t_us, p = pixel_sequences(events, width)
    g = flat_groups[pixel] if pixel.size else np.zeros(0, np.int64)
    out: dict[tuple[str, int, int, int], np.ndarray] = {}
    delay = t_us * 1e-6 - flat_pass[pixel] if pixel.size else np.zeros(0)
    same = pixel[1:] == pixel[:-1]
    dt_s = (t_us[1:] - t_us[:-1])[same] * 1e-6
    g_pair, first, nxt = g[:-1][same], p[:-1][same], p[1:][same]
    for group in range(n_groups):
        if group >= 1:
            for polarity in (1, 0):
                out[("delay", group, polarity, -1)] = delay[(g == group) & (p == polarity)]
        for a, b in TRANSITIONS:
            out[("interval", group, a, b)] = dt_s[(g_pair == group) & (first == a) & (nxt == b)]
    return out


def timing_statistics(samples: Mapping[tuple[str, int, int, int], np.ndarray],
                      edges: Mapping[tuple[str, int, int, int], np.ndarray]) -> np.ndarray:
    """The timing statistics vector: for each kind of ``edges`` (in its order), the counts of
    that kind's samples in its bins."""
    return np.concatenate([binned(samples.get(kind, np.zeros(0)), e) for kind, e in edges.items()]
                          or [np.zeros(0)])


def timing_edges(samples: Mapping[tuple[str, int, int, int], np.ndarray]
                 ) -> dict[tuple[str, int, int, int], np.ndarray]:
    """Each kind's inner bin edges from the real recording's samples (:func:`quantile_edges`
    at :data:`DELAY_QUANTILES` or :data:`INTERVAL_QUANTILES`)."""
    return {kind: quantile_edges(v, DELAY_QUANTILES if kind[0] == "delay" else INTERVAL_QUANTILES)
            for kind, v in samples.items()}


def source_light(scene: Any) -> tuple[np.ndarray, np.ndarray]:
    """(flux, passage): per pixel, the largest photon rate any one of the scene's targets
    brings it [photons/s] (:func:`evstwin.tune.counts.source_flux_map`) and the time it does
    [s] (nan where no source light reaches the pixel)."""
    from .counts import source_light_and_time

    return source_light_and_time(scene)


class TimingObjective(CountsObjective):
    """The fit's chi-square on the counts and the timing statistics (:mod:`evstwin.tune.timing`):
    each job returns their concatenated vector (metric ``stats``) and its own chi-square
    (``distance``); as :class:`evstwin.tune.counts.CountsObjective` otherwise. ``n_counts`` of
    the statistics are the counts', the rest the timing ones."""

    name = "timing"

    def __init__(self, real_events: np.ndarray, real_meta: Mapping[str, Any], scenario: Mapping[str, Any],
                 roi: Any = None, mask_pixels: Sequence[tuple[int, int]] = (), mask_hot: bool = False,
                 hot_false_alarms: float | None = None, levels: Sequence[float] = GROUP_LEVELS) -> None:
        super().__init__(real_events, real_meta, scenario, roi=roi, mask_pixels=mask_pixels, mask_hot=mask_hot,
                         hot_false_alarms=hot_false_alarms, levels=levels)
        self.n_counts = int(self.real_stats.size)
        samples = timing_samples(self.real_events, self.width, self.groups, self.passage_s, self.n_groups)
        self.edges_timing = timing_edges(samples)
        self.real_stats = np.concatenate([self.real_stats, timing_statistics(samples, self.edges_timing)])

    def statistics(self, events: np.ndarray) -> np.ndarray:
        counts = count_statistics(events, self.width, self.height, self.groups, self.n_groups, self.edges)
        samples = timing_samples(events, self.width, self.groups, self.passage_s, self.n_groups)
        return np.concatenate([counts, timing_statistics(samples, self.edges_timing)])

    def describe_statistics(self) -> list[str]:
        """One label per statistic (counts', then timing's), for reports."""
        labels = super().describe_statistics()
        for kind, e in self.edges_timing.items():
            what, group, a, b = kind
            name = (f"delay g{group} {'ON' if a else 'OFF'}" if what == "delay"
                    else f"interval g{group} {'ON' if a else 'OFF'}->{'ON' if b else 'OFF'}")
            labels += [f"{name} bin {i}" for i in range(e.size + 1)]
        return labels
