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
