"""evstwin.analysis: every statistic against a hand computation on small constructed recordings."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats as sps

from evstwin import analysis
from evstwin.sensor import EVENT_DTYPE


def make_events(rows):
    """rows: (t_us, x, y, p) tuples, any order -> EVENT_DTYPE array sorted by t."""
    ev = np.array([tuple(r) for r in rows], dtype=EVENT_DTYPE)
    return ev[np.argsort(ev["t"], kind="stable")]


# A 3 x 2 sensor. Pixel (x, y): ON, OFF events
#   (0,0): 2 ON 1 OFF   (1,0): 0          (2,0): 1 ON
#   (0,1): 0            (1,1): 3 OFF      (2,1): 1 ON 1 OFF
SMALL = make_events(
    [
        (100, 0, 0, 1),
        (200, 0, 0, 1),
        (300, 0, 0, 0),
        (400, 2, 0, 1),
        (500, 1, 1, 0),
        (600, 1, 1, 0),
        (700, 1, 1, 0),
        (800, 2, 1, 1),
        (1100, 2, 1, 0),
    ]
)


def test_stats_counts_ratio_duration():
    s = analysis.stats(SMALL, 3, 2)
    assert (s.total, s.on, s.off) == (9, 4, 5)
    assert s.on_off_ratio == pytest.approx(0.8)
    assert (s.t_start_us, s.t_end_us) == (100, 1100)
    assert s.duration_s == pytest.approx(1000e-6)
    assert s.mean_rate_hz == pytest.approx(9 / 1e-3)
    assert (s.width, s.height, s.pixel_count) == (3, 2, 6)
    s2 = analysis.stats(SMALL, 3, 2, duration_s=2.0)
    assert s2.duration_s == 2.0 and s2.mean_rate_hz == pytest.approx(4.5)
    assert s.to_dict()["total"] == 9


def test_stats_ratio_policy_and_empty():
    only_on = make_events([(1, 0, 0, 1), (2, 0, 0, 1)])
    assert analysis.stats(only_on, 1, 1).on_off_ratio == math.inf
    empty = np.zeros(0, dtype=EVENT_DTYPE)
    s = analysis.stats(empty, 2, 2)
    assert (s.total, s.on, s.off, s.duration_s) == (0, 0, 0, 0.0)
    assert math.isnan(s.on_off_ratio) and math.isnan(s.mean_rate_hz)
    only_off = make_events([(1, 0, 0, 0)])
    assert analysis.stats(only_off, 1, 1).on_off_ratio == 0.0


def test_stats_rejects_bad_input():
    with pytest.raises(ValueError, match="structured"):
        analysis.stats(np.zeros(3), 2, 2)
    with pytest.raises(ValueError, match="positive"):
        analysis.stats(SMALL, 0, 2)


def test_pixel_counts_by_hand():
    c = analysis.pixel_counts(SMALL, 3, 2)
    on = np.array([[2, 0, 1], [0, 0, 1]])
    off = np.array([[1, 0, 0], [0, 3, 1]])
    np.testing.assert_array_equal(c["on"], on)
    np.testing.assert_array_equal(c["off"], off)
    np.testing.assert_array_equal(c["total"], on + off)
    assert c["total"].shape == (2, 3) and c["total"].dtype.kind == "i"


def test_pixel_counts_outside_sensor():
    with pytest.raises(ValueError, match="outside the 2x2 sensor"):
        analysis.pixel_counts(SMALL, 2, 2)


def test_event_rate_by_hand():
    # 0.5 ms bins from t = 100 us: [100, 600) [600, 1100); the event at 1100 us lies in the
    # partial tail [1100, 1101) and is left out.
    t, on, off = analysis.event_rate(SMALL, 0.5e-3)
    np.testing.assert_allclose(t, [0.25e-3, 0.75e-3])
    # bin 0: t=100,200 ON, 300 OFF, 400 ON, 500 OFF -> 3 ON 2 OFF; bin 1: 600,700 OFF, 800 ON
    np.testing.assert_allclose(on, [3 / 0.5e-3, 1 / 0.5e-3])
    np.testing.assert_allclose(off, [2 / 0.5e-3, 2 / 0.5e-3])
    # explicit end: the tail bin [1100, 1600) is whole and kept
    t, on, off = analysis.event_rate(SMALL, 0.5e-3, t_end_us=1600)
    np.testing.assert_allclose(off, [2 / 0.5e-3, 2 / 0.5e-3, 1 / 0.5e-3])
    # shorter than one bin: one bin, rate = count / span (1001 us)
    t, on, off = analysis.event_rate(SMALL, 1.0)
    np.testing.assert_allclose(on, [4 / 1001e-6])
    np.testing.assert_allclose(t, [0.5 * 1001e-6])


def test_event_rate_empty_and_errors():
    t, on, off = analysis.event_rate(np.zeros(0, dtype=EVENT_DTYPE), 0.1)
    assert t.size == on.size == off.size == 0
    with pytest.raises(ValueError, match="bin_s"):
        analysis.event_rate(SMALL, 0)
    with pytest.raises(ValueError, match="after the first event"):
        analysis.event_rate(SMALL, 1e-3, t_start_us=500)


def test_count_histogram_by_hand():
    counts = np.array([[0, 1, 2, 3], [4, 5, 0, 9]])
    edges, f = analysis.count_histogram(counts, bin_width=2, normalise=False)
    # bins [0,2) [2,4) [4,6) [6,8) [8,10): 0,1,0 | 2,3 | 4,5 | - | 9
    np.testing.assert_array_equal(edges, [0, 2, 4, 6, 8, 10])
    np.testing.assert_array_equal(f, [3, 2, 2, 0, 1])
    edges, f = analysis.count_histogram(counts, bin_width=2)
    np.testing.assert_allclose(f, np.array([3, 2, 2, 0, 1]) / 8)
    assert f.sum() == pytest.approx(1.0)
    # common max: more (empty) bins; a smaller max puts the overflow into the last bin
    edges, f = analysis.count_histogram(counts, 2, max_count=12, normalise=False)
    np.testing.assert_array_equal(f, [3, 2, 2, 0, 1, 0, 0])
    assert edges[-1] == 14
    edges, f = analysis.count_histogram(counts, 2, max_count=5, normalise=False)
    np.testing.assert_array_equal(f, [3, 2, 3])


def test_count_histogram_per_second():
    counts = np.array([0, 10, 20, 30])
    edges, f = analysis.count_histogram(counts, bin_width=5, per_second=True, duration_s=2.0, normalise=False)
    # rates 0, 5, 10, 15 events/s in bins of 5 events/s
    np.testing.assert_array_equal(edges, [0, 5, 10, 15, 20])
    np.testing.assert_array_equal(f, [1, 1, 1, 1])
    with pytest.raises(ValueError, match="duration_s"):
        analysis.count_histogram(counts, per_second=True)


def test_count_histogram_matches_numpy():
    rng = np.random.default_rng(3)
    counts = rng.poisson(7.0, size=(40, 50))
    edges, f = analysis.count_histogram(counts, bin_width=2, normalise=False)
    ref, _ = np.histogram(counts, bins=edges)
    np.testing.assert_array_equal(f, ref)


def test_wasserstein_matches_scipy():
    rng = np.random.default_rng(4)
    a = rng.poisson(3.0, 500)
    b = rng.poisson(5.0, 500)
    assert analysis.wasserstein_1(a, b) == pytest.approx(sps.wasserstein_distance(a, b))
    assert analysis.wasserstein_1(a, a) == 0.0
    with pytest.raises(ValueError, match="equal sizes"):
        analysis.wasserstein_1(a, b[:10])


def test_frames_and_slices():
    f = analysis.accumulate_frame(SMALL, 3, 2, 200, 700)  # t = 200..600
    np.testing.assert_array_equal(f["on"], [[1, 0, 1], [0, 0, 0]])
    np.testing.assert_array_equal(f["off"], [[1, 0, 0], [0, 2, 0]])
    sl = analysis.time_slice(SMALL, 300, 800)
    np.testing.assert_array_equal(sl["t"], [300, 400, 500, 600, 700])


def test_vectorised_on_a_million_events():
    rng = np.random.default_rng(5)
    n = 1_000_000
    ev = np.zeros(n, dtype=EVENT_DTYPE)
    ev["t"] = np.sort(rng.integers(0, 10_000_000, n))
    ev["x"] = rng.integers(0, 346, n)
    ev["y"] = rng.integers(0, 260, n)
    ev["p"] = rng.integers(0, 2, n)
    c = analysis.pixel_counts(ev, 346, 260)
    assert c["total"].sum() == n
    assert c["on"].sum() == analysis.stats(ev, 346, 260).on
    t, on, off = analysis.event_rate(ev, 0.01)
    whole = np.count_nonzero(ev["t"] < ev["t"][0] + t.size * 10_000)  # events in whole bins
    assert (on.sum() + off.sum()) * 0.01 == pytest.approx(whole)


def _random_recording(n: int, w: int, h: int, seed: int, t_end_us: int = 3_000_000) -> np.ndarray:
    r = np.random.default_rng(seed)
    ev = np.zeros(n, EVENT_DTYPE)
    ev["t"] = np.sort(r.integers(0, t_end_us, n)) + 123_456
    ev["x"], ev["y"], ev["p"] = r.integers(0, w, n), r.integers(0, h, n), r.integers(0, 2, n)
    return ev


def test_statistics_from_one_chunk_equal_statistics_from_seven_uneven_chunks():
    ev = _random_recording(20_000, 17, 11, seed=3)
    cuts = [0, 1, 1, 4000, 4001, 13_000, 19_999, 20_000]  # 7 chunks, two of them empty or single
    chunks = [ev[a:b] for a, b in zip(cuts[:-1], cuts[1:])]
    assert len(chunks) == 7
    one = analysis.CountedRecording.from_chunks([ev], 17, 11)
    seven = analysis.CountedRecording.from_chunks(chunks, 17, 11)
    assert seven.stats() == one.stats() == analysis.stats(ev, 17, 11)
    assert analysis.RecordingStats.from_chunks(chunks, 17, 11, duration_s=3.0) == analysis.stats(ev, 17, 11, 3.0)
    for k in analysis.KINDS:
        np.testing.assert_array_equal(seven.pixel_counts()[k], analysis.pixel_counts(ev, 17, 11)[k])
    # The event rate from the chunks is event_rate of the whole array, at its default bin
    # (nice_bin_s of the ~3 s span: 3 s / 100 = 30 ms, rounded up to 1-2-5: 50 ms) and others.
    assert analysis.nice_bin_s(ev["t"][-1] * 1e-6 - ev["t"][0] * 1e-6) == 0.05
    for bin_s in (None, 0.05, 0.001, 10.0):
        expected = analysis.event_rate(ev, bin_s if bin_s is not None else 0.05)
        for got in (seven.event_rate(bin_s), one.event_rate(bin_s)):
            for a, b in zip(got, expected):
                np.testing.assert_allclose(a, b, rtol=1e-12)


def test_rate_bins_grow_tenfold_and_keep_the_counts(monkeypatch):
    # With at most 50 bins kept, 1 us bins over a 1,000 us span become 100 us bins (10 of them);
    # the counts are the same as binning at 100 us from the start.
    monkeypatch.setattr(analysis.RateBins, "MAX_BINS", 50)
    ev = make_events([(t, 0, 0, t % 3 == 0) for t in range(1000, 2000, 7)])
    bins = analysis.RateBins()
    for part in np.array_split(ev, 5):
        bins.add(part["t"], part["p"])
    assert bins.bin_us == 100 and bins.origin_us == 1000
    on = [sum(1 for t in range(1000 + 100 * i, 1100 + 100 * i) if (t - 1000) % 7 == 0 and t % 3 == 0)
          for i in range(9)]
    t_c, on_hz, _ = bins.curve(int(ev["t"][-1]) + 1, 100e-6)
    np.testing.assert_allclose(on_hz * 100e-6, on)
    np.testing.assert_allclose(t_c, (np.arange(9) + 0.5) * 100e-6)
    with pytest.raises(ValueError, match="not a multiple of the 100 us bins"):
        bins.curve(int(ev["t"][-1]) + 1, 150e-6)


def test_counted_recording_of_unknown_size_grows_to_the_events_extent():
    rec = analysis.CountedRecording.from_chunks([SMALL[:3], SMALL[3:]], None, None)
    assert (rec.width, rec.height) == (3, 2)  # max x + 1, max y + 1
    np.testing.assert_array_equal(rec.pixel_counts()["on"], [[2, 0, 1], [0, 0, 1]])
    np.testing.assert_array_equal(rec.pixel_counts()["off"], [[1, 0, 0], [0, 3, 1]])


def test_nice_bin_s_by_hand():
    assert analysis.nice_bin_s(2.36) == 0.05  # 23.6 ms -> 50 ms
    assert analysis.nice_bin_s(0.049926) == 0.0005  # 0.499 ms -> 0.5 ms
    assert analysis.nice_bin_s(1.0) == 0.01
    assert analysis.nice_bin_s(0.0) == 1e-3
