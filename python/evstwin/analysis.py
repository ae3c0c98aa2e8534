"""Statistics of an event recording (NumPy only, vectorised): the quantities of the paper's
section 3.3 -- total, ON and OFF counts and their ratio (Table 4), the event rate over time,
and the per-pixel event counts with their histograms (Fig. 7).

Events are arrays of :data:`evstwin.EVENT_DTYPE` (``t`` [us, int64], ``x``, ``y`` [px],
``p`` [1 = ON, 0 = OFF]), sorted by ``t``. Nothing here loops over events in Python.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field

import numpy as np
import numpy.typing as npt

from ._checks import size

KINDS: tuple[str, str, str] = ("total", "on", "off")
"""The three event populations every per-pixel statistic is given for."""


@dataclass(frozen=True)
class RecordingStats:
    """Summary numbers of one recording (the columns of the paper's Table 4, and a few more).

    ``on_off_ratio`` is ON / OFF. When OFF = 0 it is ``inf`` if ON > 0 and ``nan`` if the
    recording has no events at all (``to_dict`` keeps them as floats; JSON writers turn them
    into ``null``).
    ``duration_s`` is the recording length [s]: given by the caller (a file's header) or, by
    default, last minus first event time. ``mean_rate_hz`` = total / duration_s [events/s]
    (``nan`` when the duration is 0).
    """

    total: int
    on: int
    off: int
    on_off_ratio: float
    duration_s: float
    t_start_us: int
    t_end_us: int
    width: int
    height: int
    mean_rate_hz: float

    @property
    def pixel_count(self) -> int:
        return self.width * self.height

    def to_dict(self) -> dict[str, float]:
        return asdict(self)

    @classmethod
    def from_chunks(
        cls, chunks: Iterable[np.ndarray], width: int | None, height: int | None, duration_s: float | None = None
    ) -> RecordingStats:
        """The statistics of a recording given as chunks of events (any number, any sizes:
        the same numbers as from one array), via :class:`CountedRecording`."""
        return CountedRecording.from_chunks(chunks, width, height).stats(duration_s)


def _check_events(events: np.ndarray) -> np.ndarray:
    events = np.asarray(events)
    names = events.dtype.names or ()
    missing = [f for f in ("t", "x", "y", "p") if f not in names]
    if events.ndim != 1 or missing:
        raise ValueError(
            f"events must be a 1-D structured array with fields t, x, y, p; got shape "
            f"{events.shape}, dtype {events.dtype} (missing {missing})"
        )
    return events


def ratio(on: float, off: float) -> float:
    """ON / OFF with the policy of :class:`RecordingStats` (inf if only ON, nan if empty)."""
    if off == 0:
        return math.inf if on > 0 else math.nan
    return float(on) / float(off)


def stats(events: np.ndarray, width: int, height: int, duration_s: float | None = None) -> RecordingStats:
    """Total, ON, OFF, ON/OFF ratio, time span and mean rate of a recording (the one-chunk
    case of :meth:`RecordingStats.from_chunks`).

    duration_s: recording length [s]; default: (last - first event time), 0 for fewer than
        two events.
    """
    return RecordingStats.from_chunks([_check_events(events)], *size(width, height), duration_s)


def event_rate(
    events: np.ndarray, bin_s: float, t_start_us: int | None = None, t_end_us: int | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ON and OFF event rates in consecutive time bins.

    Bins are ``bin_s`` [s] wide, the first starting at ``t_start_us`` (default: the first
    event). Only whole bins are kept: the bins end at or before ``t_end_us`` (default: the
    last event + 1 us), and a tail shorter than one bin is left out, so a partial last bin
    never reads as a drop of the rate. If the recording is shorter than one bin, the single
    bin's rate is its count / the recording's span.

    Returns (t_centres_s, on_rate_hz, off_rate_hz): bin centres [s] relative to the start,
    and rates [events/s]. Empty arrays for an empty recording. :func:`event_rate_chunks`
    gives the same from a stream of chunks.
    """
    events = _check_events(events)
    if events.size == 0:
        if not bin_s > 0:
            raise ValueError(f"bin_s must be > 0; got {bin_s}")
        empty = np.zeros(0)
        return empty, empty.copy(), empty.copy()
    t0 = int(events["t"][0]) if t_start_us is None else int(t_start_us)
    t1 = int(events["t"][-1]) + 1 if t_end_us is None else int(t_end_us)
    return event_rate_chunks([events], bin_s, t0, t1)


def _bin_us(bin_s: float) -> int:
    """A bin width [s] as whole microseconds (event times are integer us), at least 1."""
    if not bin_s > 0:
        raise ValueError(f"bin_s must be > 0; got {bin_s}")
    return max(1, round(bin_s * 1e6))


def event_rate_chunks(
    chunks: Iterable[np.ndarray], bin_s: float, t_start_us: int, t_end_us: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`event_rate` of a recording given as time-ordered chunks, whose first event time
    and last event time + 1 us are ``t_start_us`` and ``t_end_us``; memory is one count per
    bin, whatever the length. Bin widths are whole microseconds (``round(bin_s * 1e6)``)."""
    bin_us = _bin_us(bin_s)
    t0, t1 = int(t_start_us), int(t_end_us)
    if t1 <= t0:
        raise ValueError(f"t_end_us={t1} must be after t_start_us={t0}")
    n = (t1 - t0) // bin_us
    width_us = bin_us
    if n == 0:
        n, width_us = 1, t1 - t0
    on = np.zeros(n, np.int64)
    off = np.zeros(n, np.int64)
    for events in chunks:
        events = _check_events(events)
        if events.size == 0:
            continue
        t = events["t"].astype(np.int64)
        if int(t.min()) < t0:
            raise ValueError(f"t_start_us={t0} is after the first event (t={int(t.min())} us)")
        idx = (t - t0) // width_us
        keep = idx < n
        is_on = events["p"] != 0
        on += np.bincount(idx[keep & is_on], minlength=n)[:n]
        off += np.bincount(idx[keep & ~is_on], minlength=n)[:n]
    return _rate_curve(on, off, width_us)


def _rate_curve(on: np.ndarray, off: np.ndarray, width_us: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    width_s = width_us * 1e-6
    return (np.arange(on.size) + 0.5) * width_s, on / width_s, off / width_s


def nice_bin_s(duration_s: float, target_bins: int = 100) -> float:
    """The event-rate bin width chosen when none is given: the 1-2-5 multiple of a power of
    ten [s] closest above ``duration_s / target_bins`` (about 100 bins over the recording),
    at least 1 us; 1 ms for an empty or instantaneous recording."""
    if not duration_s > 0:
        return 1e-3
    raw = max(duration_s / target_bins, 1e-6)
    exp = math.floor(math.log10(raw))
    for m in (1, 2, 5, 10):
        if m * 10.0**exp >= raw * (1 - 1e-12):
            return float(f"{m * 10.0**exp:.12g}")
    return 10.0 ** (exp + 1)  # pragma: no cover - m = 10 always suffices


class RateBins:
    """ON and OFF event counts in time bins, fed chunk by chunk (:meth:`add`) in one pass.

    With ``bin_us`` given, the bins have that width. Without it the bin width is chosen as
    the recording goes: it starts at 1 us and grows tenfold (10 neighbouring bins merged)
    whenever more than :attr:`MAX_BINS` would be needed, so memory stays below MAX_BINS
    counts however long the recording, and the kept width is a power of ten [us] at most
    1/20,000 of the span. :meth:`curve` then gives any multiple of it, by default
    :func:`nice_bin_s` of the span (about 100 bins, always a multiple). Bins start at the
    first event; events earlier than it (a file not sorted by time) extend them backwards
    by whole bins."""

    MAX_BINS = 200_000

    def __init__(self, bin_us: int | None = None) -> None:
        if bin_us is not None and not (isinstance(bin_us, (int, np.integer)) and bin_us >= 1):
            raise ValueError(f"bin_us must be a positive int [us]; got {bin_us!r}")
        self.fixed = bin_us is not None
        self.bin_us = int(bin_us) if bin_us is not None else 1
        self.origin_us: int | None = None
        self.on = np.zeros(0, np.int64)
        self.off = np.zeros(0, np.int64)

    def add(self, t: np.ndarray, p: np.ndarray) -> None:
        """Count events of times ``t`` [us] and polarities ``p`` (1 ON, 0 OFF)."""
        if t.size == 0:
            return
        t = t.astype(np.int64)
        lo, hi = int(t.min()), int(t.max())
        if self.origin_us is None:
            self.origin_us = lo
        if lo < self.origin_us:
            pad = -(-(self.origin_us - lo) // self.bin_us)
            self.on = np.concatenate([np.zeros(pad, np.int64), self.on])
            self.off = np.concatenate([np.zeros(pad, np.int64), self.off])
            self.origin_us -= pad * self.bin_us
        while not self.fixed and (hi - self.origin_us) // self.bin_us + 1 > self.MAX_BINS:
            self._coarsen()
        n = (hi - self.origin_us) // self.bin_us + 1
        if n > self.on.size:
            grow = max(n, 2 * self.on.size) - self.on.size  # amortised growth
            self.on = np.concatenate([self.on, np.zeros(grow, np.int64)])
            self.off = np.concatenate([self.off, np.zeros(grow, np.int64)])
        idx = (t - self.origin_us) // self.bin_us
        is_on = np.asarray(p) != 0
        self.on[: n] += np.bincount(idx[is_on], minlength=n)[:n]
        self.off[: n] += np.bincount(idx[~is_on], minlength=n)[:n]

    def _coarsen(self) -> None:
        size = -(-self.on.size // 10) * 10
        self.on = np.pad(self.on, (0, size - self.on.size)).reshape(-1, 10).sum(axis=1)
        self.off = np.pad(self.off, (0, size - self.off.size)).reshape(-1, 10).sum(axis=1)
        self.bin_us *= 10

    def curve(self, t_end_us: int, bin_s: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(t_centres_s, on_rate_hz, off_rate_hz) as :func:`event_rate`: whole bins of
        ``bin_s`` (default :func:`nice_bin_s` of the span) from the first event to
        ``t_end_us`` (the last event + 1 us), a single bin of the span when it is shorter."""
        if self.origin_us is None:
            empty = np.zeros(0)
            return empty, empty.copy(), empty.copy()
        span_us = int(t_end_us) - self.origin_us
        if span_us <= 0:
            raise ValueError(f"t_end_us={t_end_us} must be after the first event ({self.origin_us} us)")
        bin_us = _bin_us(bin_s if bin_s is not None else nice_bin_s(span_us * 1e-6))
        if bin_us % self.bin_us:
            raise ValueError(
                f"bin_s={bin_us * 1e-6:g} s is not a multiple of the {self.bin_us} us bins counted; "
                f"count with RateBins(bin_us={bin_us}) for it"
            )
        group = bin_us // self.bin_us
        n = span_us // bin_us
        if n == 0:
            return _rate_curve(np.array([self.on.sum()]), np.array([self.off.sum()]), span_us)
        m = n * group
        on = np.pad(self.on[:m], (0, max(0, m - self.on.size))).reshape(n, group).sum(axis=1)
        off = np.pad(self.off[:m], (0, max(0, m - self.off.size))).reshape(n, group).sum(axis=1)
        return _rate_curve(on, off, bin_us)


@dataclass
class CountedRecording:
    """A recording reduced to its statistics, built chunk by chunk (:meth:`add`, in one
    pass): per-pixel ON and OFF counts (flat, row-major), the first and last event times
    (smallest and largest), and the event rate in time bins (:class:`RateBins`). Memory is two
    integers per pixel plus at most ``RateBins.MAX_BINS`` rate bins, however long the
    recording. ``width``/``height`` None: the size grows to the events' extent (a text file
    without a size header), known once every chunk has been added."""

    width: int
    height: int
    on: np.ndarray
    off: np.ndarray
    t_start_us: int | None = None
    t_end_us: int = 0
    rate: RateBins = field(default_factory=RateBins)
    size_known: bool = True

    @classmethod
    def empty(cls, width: int | None, height: int | None, rate_bin_us: int | None = None) -> CountedRecording:
        """No events yet; ``rate_bin_us``: a fixed event-rate bin [us] (default: chosen as it goes)."""
        known = width is not None and height is not None
        width, height = size(width, height) if known else (0, 0)  # type: ignore[arg-type]
        n = width * height
        return cls(width, height, np.zeros(n, np.int64), np.zeros(n, np.int64),
                   rate=RateBins(rate_bin_us), size_known=known)

    @classmethod
    def from_chunks(cls, chunks: Iterable[np.ndarray], width: int | None, height: int | None,
                    rate_bin_us: int | None = None) -> CountedRecording:
        rec = cls.empty(width, height, rate_bin_us)
        for chunk in chunks:
            rec.add(chunk)
        return rec

    def add(self, events: np.ndarray) -> None:
        """Count one chunk (any order within and between chunks)."""
        events = _check_events(events)
        if events.size == 0:
            return
        if not self.size_known:
            self._grow(int(events["x"].max()) + 1, int(events["y"].max()) + 1)
        counts = pixel_counts(events, self.width, self.height)  # checks the coordinates
        self.on += counts["on"].reshape(-1)
        self.off += counts["off"].reshape(-1)
        t = events["t"]
        lo, hi = int(t.min()), int(t.max())
        first = self.t_start_us is None
        self.t_start_us = lo if self.t_start_us is None else min(self.t_start_us, lo)
        self.t_end_us = hi if first else max(self.t_end_us, hi)
        self.rate.add(t, events["p"])

    def _grow(self, width: int, height: int) -> None:
        width, height = max(width, self.width), max(height, self.height)
        if (width, height) == (self.width, self.height):
            return
        for name in ("on", "off"):
            old = getattr(self, name).reshape(self.height, self.width)
            new = np.zeros((height, width), np.int64)
            new[: self.height, : self.width] = old
            setattr(self, name, new.reshape(-1))
        self.width, self.height = width, height

    @property
    def total(self) -> int:
        return int(self.on.sum() + self.off.sum())

    def pixel_counts(self) -> dict[str, np.ndarray]:
        """As :func:`pixel_counts` of the whole recording."""
        on = self.on.reshape(self.height, self.width)
        off = self.off.reshape(self.height, self.width)
        return {"total": on + off, "on": on, "off": off}

    def event_rate(self, bin_s: float | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """As :func:`event_rate` of the whole recording (``bin_s`` default: :func:`nice_bin_s`
        of the span, about 100 bins)."""
        return self.rate.curve(self.t_end_us + 1, bin_s)

    def stats(self, duration_s: float | None = None) -> RecordingStats:
        """As :func:`stats` of the whole recording."""
        on, off = int(self.on.sum()), int(self.off.sum())
        total = on + off
        t_start = self.t_start_us if self.t_start_us is not None else 0
        t_end = self.t_end_us if total else 0
        if duration_s is None:
            duration_s = (t_end - t_start) * 1e-6
        duration_s = float(duration_s)
        if duration_s < 0:
            raise ValueError(f"duration_s must be >= 0; got {duration_s}")
        return RecordingStats(
            total=total, on=on, off=off, on_off_ratio=ratio(on, off), duration_s=duration_s,
            t_start_us=t_start, t_end_us=t_end, width=self.width, height=self.height,
            mean_rate_hz=total / duration_s if duration_s > 0 else math.nan,
        )


def pixel_counts(events: np.ndarray, width: int, height: int) -> dict[str, np.ndarray]:
    """Number of events of each pixel: {'total', 'on', 'off'} -> (height, width) int64 arrays.

    Raises ValueError if an event lies outside the width x height sensor.
    """
    events = _check_events(events)
    width, height = size(width, height)
    x = events["x"].astype(np.int64)
    y = events["y"].astype(np.int64)
    if events.size and (x.max() >= width or y.max() >= height):
        raise ValueError(
            f"events reach pixel (x={int(x.max())}, y={int(y.max())}) outside the {width}x{height} sensor"
        )
    flat = y * width + x
    is_on = events["p"] != 0
    n = width * height
    on = np.bincount(flat[is_on], minlength=n).reshape(height, width)
    off = np.bincount(flat[~is_on], minlength=n).reshape(height, width)
    return {"total": on + off, "on": on, "off": off}


def histogram_edges(bin_width: float, max_value: float) -> np.ndarray:
    """Bin edges 0, w, 2w, ... with the last bin [k w, (k+1) w) holding ``max_value``."""
    if not bin_width > 0:
        raise ValueError(f"bin_width must be > 0; got {bin_width}")
    if not max_value >= 0:
        raise ValueError(f"max_value must be >= 0; got {max_value}")
    nbins = int(np.floor(max_value / bin_width)) + 1
    return np.arange(nbins + 1) * float(bin_width)


def count_histogram(
    counts: npt.ArrayLike,
    bin_width: float = 2,
    max_count: float | None = None,
    normalise: bool = True,
    per_second: bool = False,
    duration_s: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Distribution over pixels of the per-pixel event count (the paper's Fig. 7).

    counts: per-pixel counts (any shape; every pixel is one sample, pixels with no event
        included -- they fill the first bin).
    bin_width: bin width; bins are [0, w), [w, 2w), ... (the paper uses w = 2 events).
    max_count: value the last bin must hold (default: the largest count); larger values are
        counted in the last bin, so the frequencies always cover every pixel. Give the same
        ``max_count`` to recordings that are to be compared bin by bin.
    normalise: if True the frequencies are fractions of the pixels (they sum to 1, not a
        density: no division by the bin width), so recordings compare by shape and the
        difference of two is directly a share of the sensor's pixel count (Fig. 9). If False
        they are numbers of pixels.
    per_second: if True the counts are first divided by ``duration_s`` (required), i.e. the
        histogram is of per-pixel event rates [events/s] and ``bin_width`` and ``max_count``
        are in events/s too; recordings of different lengths then compare by rate.

    Returns (edges, frequencies): ``len(edges) == len(frequencies) + 1``.
    """
    values = np.asarray(counts, dtype=np.float64).ravel()
    if per_second:
        if duration_s is None or not duration_s > 0:
            raise ValueError(f"per_second=True needs duration_s > 0; got {duration_s}")
        values = values / float(duration_s)
    if values.size and values.min() < 0:
        raise ValueError("counts must be >= 0")
    if max_count is None:
        max_count = float(values.max()) if values.size else 0.0
    edges = histogram_edges(bin_width, float(max_count))
    nbins = edges.size - 1
    idx = np.minimum(np.floor(values / float(bin_width)).astype(np.int64), nbins - 1)
    freq = np.bincount(idx, minlength=nbins).astype(np.float64)
    if normalise and values.size:
        freq /= values.size
    return edges, freq


def wasserstein_1(a: npt.ArrayLike, b: npt.ArrayLike) -> float:
    """1-Wasserstein distance between the distributions of two equal-size samples
    (mean |sorted(a) - sorted(b)|), in the samples' unit: for two per-pixel count maps of the
    same sensor, the mean number of events one pixel has to gain or lose to turn one
    distribution into the other. Unbinned, so smooth in the counts (a tuner's friend)."""
    a = np.sort(np.asarray(a, dtype=np.float64).ravel())
    b = np.sort(np.asarray(b, dtype=np.float64).ravel())
    if a.size != b.size:
        raise ValueError(f"samples must have equal sizes; got {a.size} and {b.size}")
    if a.size == 0:
        return 0.0
    return float(np.mean(np.abs(a - b)))


def accumulate_frame(
    events: np.ndarray, width: int, height: int, t_start_us: int, t_end_us: int
) -> dict[str, np.ndarray]:
    """Per-pixel ON/OFF/total counts of the events with t_start_us <= t < t_end_us
    (an accumulated "frame", the paper's Fig. 5)."""
    events = _check_events(events)
    lo, hi = np.searchsorted(events["t"], [t_start_us, t_end_us], side="left")
    return pixel_counts(events[lo:hi], width, height)


def time_slice(events: np.ndarray, t_start_us: int, t_end_us: int) -> np.ndarray:
    """The events with t_start_us <= t < t_end_us (a view; events are sorted by t)."""
    events = _check_events(events)
    lo, hi = np.searchsorted(events["t"], [t_start_us, t_end_us], side="left")
    return events[lo:hi]


SAME_VALUE_TOLERANCE = 1e-3
"""Fluxes or speeds within this share of each other are one value in the timing summary and
figure: a source's speed in pixels changes in its last digits along a track (geo-stare's
7.8828..7.8830 px/s), and a group or axis tick per digit helps nobody."""


def same_value_groups(values: np.ndarray, tolerance: float = SAME_VALUE_TOLERANCE) -> np.ndarray:
    """A group number per value (0, 1, ... in increasing order of value): sorted values go in
    one group while each is within ``tolerance`` (relative) of the group's smallest."""
    v = np.asarray(values, dtype=np.float64)
    if v.size == 0:
        return np.zeros(0, np.int64)
    order = np.argsort(v, kind="stable")
    s = v[order]
    group = np.zeros(s.size, np.int64)
    start, g = s[0], 0
    for i in range(1, s.size):  # over distinct values in practice: a handful of targets
        if s[i] - start > tolerance * max(abs(start), abs(s[i])):
            g += 1
            start = s[i]
        group[i] = g
    out = np.empty_like(group)
    out[order] = group
    return out
