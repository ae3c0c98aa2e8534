"""evstwin.validation: comparison, Monte Carlo aggregation, file entry points, timing bias."""

from __future__ import annotations

import importlib.util
import json
import math
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from evstwin import validation
from evstwin.sensor import EVENT_DTYPE

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
HAVE_IO = importlib.util.find_spec("evstwin.io") is not None


def block_recording(counts, width, step_us=1000):
    """Pixel i (x = i % width, y = i // width) gets counts[i] events in one block of time,
    polarities ON, ON, OFF, OFF, ... (every count is a multiple of 4)."""
    counts = np.asarray(counts)
    n = int(counts.sum())
    ev = np.zeros(n, dtype=EVENT_DTYPE)
    pix = np.repeat(np.arange(counts.size), counts)
    local = np.arange(n) - np.repeat(np.cumsum(counts) - counts, counts)
    ev["t"] = np.arange(n) * step_us
    ev["x"] = pix % width
    ev["y"] = pix // width
    ev["p"] = (local % 4 < 2).astype(np.uint8)
    return ev


COUNTS = [0, 4, 8, 4, 12, 0, 4, 8]  # a 4 x 2 sensor; 40 events, 20 ON, 20 OFF
REAL = block_recording(COUNTS, 4)
META = {"width": 4, "height": 2, "duration_s": 0.04}


HALF_DISTANCE = 40 / 41 + math.log(81 / 41)
"""The distance of REAL[::2] (every count halved) to REAL: see the test below."""


def test_block_recording_is_what_the_arithmetic_assumes():
    assert REAL.size == 40 and REAL["p"].sum() == 20
    half = REAL[::2]
    # every second event dropped: each pixel keeps half its events, half of them ON
    per_pixel = np.bincount(half["y"].astype(int) * 4 + half["x"], minlength=8)
    np.testing.assert_array_equal(per_pixel, np.array(COUNTS) // 2)
    assert half["p"].sum() == 10


def test_compare_with_itself_is_zero():
    c = validation.compare(REAL, META, [(REAL.copy(), dict(META, path="same"))])
    s = c.sims[0]
    assert s.distance == 0.0 and s.max_bin_error_share == 0.0
    assert s.total_diff == s.on_diff == s.off_diff == 0
    assert s.total_rel_error == 0.0 and s.on_off_ratio_diff == 0.0 and s.on_off_ratio_rel_error == 0.0
    for k in ("total", "on", "off"):
        assert not np.any(s.error[k]) and not np.any(s.error_pixels[k])
        assert not np.any(s.percent_error[k])
        assert s.wasserstein[k] == 0.0
        np.testing.assert_array_equal(s.hist[k], c.real_hist[k])
    assert c.adjustments == [] and c.value_unit == "events" and c.bin_width == 2


def test_compare_with_every_second_event_dropped():
    c = validation.compare(REAL, META, [(REAL[::2], dict(META, path="half.npz"))])
    s = c.sims[0]
    # Table 4: real 40 / 20 / 20, ratio 1; sim 20 / 10 / 10, ratio 1
    assert (s.stats.total, s.stats.on, s.stats.off) == (20, 10, 10)
    assert (s.total_diff, s.on_diff, s.off_diff) == (-20, -10, -10)
    assert s.total_rel_error == pytest.approx(-0.5)
    assert s.on_off_ratio_diff == 0.0 and s.on_off_ratio_rel_error == 0.0
    # Fig. 7, all events, bins [0,2) .. [12,14) (largest count 12):
    # real counts 0,4,8,4,12,0,4,8 -> 2,0,3,0,2,0,1 pixels; sim 0,2,4,2,6,0,2,4 -> 2,3,2,1,0,0,0
    np.testing.assert_array_equal(c.edges["total"], np.arange(0, 16, 2))
    np.testing.assert_allclose(c.real_hist["total"], np.array([2, 0, 3, 0, 2, 0, 1]) / 8)
    np.testing.assert_allclose(s.hist["total"], np.array([2, 3, 2, 1, 0, 0, 0]) / 8)
    np.testing.assert_allclose(s.error_pixels["total"], [0, 3, -1, 1, -2, 0, -1])
    np.testing.assert_allclose(s.error["total"], np.array([0, 3, -1, 1, -2, 0, -1]) / 8)
    # Fig. 8: 100 (sim - real) / real; nan where real is empty and sim is not, 0 where both are
    np.testing.assert_allclose(s.percent_error["total"], [0, np.nan, -100 / 3, np.nan, -100, 0, -100])
    # ON (OFF alike): real 0,2,4,2,6,0,2,4 -> bins [0,2)..[6,8): 2,3,2,1; sim 0,1,2,1,3,0,1,2 -> 5,3,0,0
    for k in ("on", "off"):
        np.testing.assert_array_equal(c.edges[k], [0, 2, 4, 6, 8])
        np.testing.assert_allclose(c.real_hist[k] * 8, [2, 3, 2, 1])
        np.testing.assert_allclose(s.hist[k] * 8, [5, 3, 0, 0])
        np.testing.assert_allclose(s.percent_error[k], [150, 0, -100, -100])
    # Fig. 9: the largest |error| is 3 pixels of 8
    assert s.max_bin_error_share == pytest.approx(3 / 8)
    # W1 = mean |sorted real - sorted sim|: total (0+0+2+2+2+4+4+6)/8 = 2.5, ON and OFF 1.25;
    # m_real = 40/8 = 5, N = 8: w1 = (2.5 + 1.25 + 1.25)/(5 + 1/8) = 40/41; rate = |ln(20.5/40.5)|;
    # polarity = |ln(10.5/10.5) - ln(20.5/20.5)| = 0
    assert s.wasserstein == pytest.approx({"total": 2.5, "on": 1.25, "off": 1.25})
    assert s.distance_terms == pytest.approx({"w1": 40 / 41, "rate": math.log(81 / 41), "polarity": 0.0})
    assert s.distance == pytest.approx(HALF_DISTANCE)


def test_different_sizes_is_an_error():
    with pytest.raises(ValueError, match=r"real .* is 4x2, simulation big is 5x2"):
        validation.compare(REAL, META, [(REAL, {"width": 5, "height": 2, "path": "big"})])
    with pytest.raises(ValueError, match="width"):
        validation.compare(REAL, {"height": 2}, [(REAL, META)])
    with pytest.raises(ValueError, match="at least one"):
        validation.compare(REAL, META, [])


def test_different_durations_compared_by_rate():
    real = block_recording(COUNTS, 4)
    sim = real[::2]  # half the events in half the time: the same rates
    c = validation.compare(
        real, dict(META, duration_s=10.0), [(sim, dict(META, duration_s=5.0, path="short"))]
    )
    s = c.sims[0]
    assert c.value_unit == "events/s"
    assert c.bin_width == pytest.approx(2 / 10.0)
    assert len(c.adjustments) == 1
    assert "durations differ" in c.adjustments[0] and "by rate" in c.adjustments[0]
    assert "short 5 s" in c.adjustments[0]
    assert s.total_diff == -20  # raw counts are still reported
    assert s.total_rel_error == pytest.approx(0.0, abs=1e-12)
    assert s.distance == pytest.approx(0.0, abs=1e-12)
    assert s.max_bin_error_share == 0.0
    # the real histogram keeps the shape of its count histogram
    np.testing.assert_allclose(c.real_hist["total"], np.array([2, 0, 3, 0, 2, 0, 1]) / 8)


def test_durations_within_tolerance_and_from_events():
    a = block_recording(COUNTS, 4, step_us=1000)  # spans 39 ms
    b = block_recording(COUNTS, 4, step_us=1010)  # spans 39.39 ms: 1 % longer
    m = {"width": 4, "height": 2}
    assert validation.compare(a, m, [(b, m)], duration_rtol=0.02).adjustments == []
    assert validation.compare(a, m, [(b, m)], duration_rtol=0.005).value_unit == "events/s"
    with pytest.raises(ValueError, match="zero duration"):
        validation.compare(a, m, [(a[:1], m)])


def test_json_dict_has_every_number():
    c = validation.compare(REAL, dict(META, path="real.aedat4"), [(REAL[::2], dict(META, path="half.npz"))])
    d = c.to_json_dict()
    text = json.dumps(d, allow_nan=False)  # strict JSON: no NaN / Infinity
    back = json.loads(text)
    assert back["real"]["path"] == "real.aedat4"
    for key in ("total", "on", "off", "on_off_ratio", "duration_s"):
        assert key in back["real"]
    assert back["real"]["total"] == 40 and back["real"]["duration_s"] == 0.04
    sim = back["sims"][0]
    for key in ("path", "total", "on", "off", "on_off_ratio", "distance", "max_bin_error_share"):
        assert key in sim
    assert sim["path"] == "half.npz" and sim["distance"] == pytest.approx(HALF_DISTANCE)
    assert sim["percent_error"]["total"][1] is None  # nan -> null
    assert sim["error_pixels"]["total"] == [0, 3, -1, 1, -2, 0, -1]
    assert back["edges"]["on"] == [0, 2, 4, 6, 8]
    assert back["adjustments"] == [] and "W1" in back["distance_formula"]
    only_on = REAL[REAL["p"] == 1]
    d = validation.compare(only_on, META, [(REAL, META)]).to_json_dict()
    assert d["real"]["on_off_ratio"] is None  # inf -> null
    assert d["sims"][0]["on_off_ratio_rel_error"] is None


def test_to_text_table():
    c = validation.compare(
        REAL, dict(META, path="/x/real.aedat4"), [(REAL[::2], dict(META, path="/y/half.npz"))]
    )
    text = c.to_text()
    assert "real.aedat4 (real)" in text and "half.npz" in text
    assert "-50.00%" in text and f"{HALF_DISTANCE:.4f}" in text and "+37.50%" in text


def test_aggregate_mean_and_std():
    same = validation.compare(REAL, META, [(REAL, dict(META, path="sim"))])
    half = validation.compare(REAL, META, [(REAL[::2], dict(META, path="sim"))])
    mc = validation.aggregate([same, half])
    assert mc.runs == 2
    s_mean, s_std = mc.mean["sims"][0], mc.std["sims"][0]
    assert s_mean["path"] == "sim"
    assert s_mean["distance"] == pytest.approx(HALF_DISTANCE / 2)
    assert s_std["distance"] == pytest.approx(HALF_DISTANCE / math.sqrt(2))  # sample std, ddof = 1
    assert s_mean["total"] == pytest.approx(30) and s_std["total"] == pytest.approx(20 / math.sqrt(2))
    # bin [2,4): percent error 0 (both empty) in one run, undefined in the other -> mean 0, std null
    assert s_mean["percent_error"]["total"][1] == 0.0 and s_std["percent_error"]["total"][1] is None
    assert mc.mean["real"]["total"] == 40 and mc.std["real"]["total"] == 0.0
    json.dumps(mc.to_json_dict(), allow_nan=False)
    assert "distance" in mc.to_text()


def test_aggregate_pads_histograms_of_different_lengths():
    same = validation.compare(REAL, META, [(REAL, dict(META, path="sim"))])  # 7 total bins
    double = validation.compare(REAL, META, [(np.repeat(REAL, 2), dict(META, path="sim"))])  # 13
    mc = validation.aggregate([same, double])
    assert mc.mean["edges"]["total"] == list(np.arange(0, 28, 2))
    np.testing.assert_allclose(mc.mean["real_histogram"]["total"], double.real_hist["total"])
    np.testing.assert_allclose(mc.std["real_histogram"]["total"], 0.0)
    assert len(mc.mean["sims"][0]["error"]["total"]) == 13


def test_aggregate_rejects_mismatched_runs():
    a = validation.compare(REAL, META, [(REAL, META)])
    b = validation.compare(REAL, dict(META, duration_s=4.0), [(REAL, dict(META, duration_s=2.0))])
    with pytest.raises(ValueError, match="bin widths"):
        validation.aggregate([a, b])
    c = validation.compare(REAL, dict(META, duration_s=1.0), [(REAL, dict(META, duration_s=2.0))])
    with pytest.raises(ValueError, match="units"):
        validation.aggregate([a, c])
    with pytest.raises(ValueError, match="numbers of simulations"):
        validation.aggregate([a, validation.compare(REAL, META, [(REAL, META), (REAL, META)])])
    with pytest.raises(ValueError, match="at least one"):
        validation.aggregate([])


# --------------------------------------------------------------------------------------------
# file entry points


def _npz_reader(path):
    with np.load(path) as z:
        return z["events"], {"width": int(z["width"]), "height": int(z["height"])}


@pytest.fixture
def npz_io(monkeypatch):
    """evstwin.io.read_events for .npz files written by these tests: the real one when it
    reads them, else a local stand-in (io.py is written elsewhere and may not exist yet)."""
    if HAVE_IO:
        from evstwin import io

        return io
    fake = types.ModuleType("evstwin.io")
    fake.read_events = _npz_reader  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "evstwin.io", fake)
    return fake


def write_npz(path, events, width, height):
    np.savez(path, events=events, width=width, height=height)
    return path


def test_compare_files_writes_json_and_figures(tmp_path, npz_io):
    rng = np.random.default_rng(0)
    n = 3000
    ev = np.zeros(n, dtype=EVENT_DTYPE)
    ev["t"] = np.sort(rng.integers(0, 200_000, n))
    ev["x"] = rng.integers(0, 40, n)
    ev["y"] = rng.integers(0, 30, n)
    ev["p"] = rng.integers(0, 2, n)
    real = write_npz(tmp_path / "real.npz", ev, 40, 30)
    sim = write_npz(tmp_path / "sim.npz", ev[::2], 40, 30)
    out = tmp_path / "out"
    comp = validation.compare_files(real, [sim], out, bin_width=2)
    data = json.loads((out / "compare.json").read_text())
    assert data["real"]["total"] == n and data["sims"][0]["total"] == len(ev[::2])
    assert data["sims"][0]["path"] == str(sim)
    assert data["sims"][0]["distance"] == pytest.approx(comp.sims[0].distance)
    for name in ("frames", "xyt", "histograms", "percent_error", "bin_error", "event_rate"):
        p = Path(comp.outputs[name])
        assert p.parent == out and p.stat().st_size > 0
    text = validation.info(real)
    assert "40 x 30" in text and f"{n}" in text and "ON/OFF" in text
    shown = validation.show(sim, tmp_path / "show")
    assert set(shown) == {"frames", "xyt", "histograms", "event_rate"}
    assert all(Path(p).stat().st_size > 0 for p in shown.values())


@pytest.mark.skipif(not HAVE_IO, reason="evstwin.io (read_events for AEDAT4) is not in this tree yet")
@pytest.mark.skipif(not (DATA / "davis346_road.aedat4").exists(), reason="../shared/data is absent")
def test_real_davis_recording_against_a_simulation(tmp_path):
    from evstwin import Sensor
    from evstwin.io import read_events

    real, meta = read_events(DATA / "davis346_road.aedat4")
    assert (int(meta["width"]), int(meta["height"])) == (346, 260)
    sensor = Sensor(346, 260, seed=1)
    t = np.arange(0.0, 2.36, 0.02)
    sim = sensor.run(np.full((t.size, 260, 346), 1e4, dtype=np.float32), t)
    c = validation.compare(real, dict(meta), [(sim, {"width": 346, "height": 260, "path": "noise-sim"})])
    assert c.real.total == real.size and c.sims[0].stats.total == sim.size
    assert math.isfinite(c.sims[0].distance) and c.sims[0].distance > 0
    assert 0 < c.sims[0].max_bin_error_share <= 1
    json.dumps(c.to_json_dict(), allow_nan=False)


# --------------------------------------------------------------------------------------------
# event-timing bias


def line_track(t0, t1, p0, p1, n, flux):
    t = np.linspace(t0, t1, n)
    return {
        "t_s": t,
        "x_px": np.linspace(p0[0], p1[0], n),
        "y_px": np.linspace(p0[1], p1[1], n),
        "flux_ph_s": np.linspace(flux[0], flux[1], n),
    }


def truth_and_events():
    truth = {
        # along y = 5 at 10 px/s, flux ramping 1e4 -> 3e4 photons/s over 2 s
        "slow": line_track(0.0, 2.0, (0, 5), (20, 5), 41, (1e4, 3e4)),
        # along x = 30 at 40 px/s, 1e6 photons/s
        "fast": line_track(0.0, 1.0, (30, 0), (30, 40), 101, (1e6, 1e6)),
        # not moving: no crossing time
        "still": line_track(0.0, 1.0, (60, 60), (60, 60), 11, (5e5, 5e5)),
    }
    rows = []
    for x in range(2, 19):  # slow crosses (x, 5) at t = x / 10 s
        rows.append((x * 100_000 + 3000, x, 5, 1))  # 3 ms late, on the track
        rows.append((x * 100_000 + 5000, x, 6, 0))  # 5 ms late, 1 px off the track
    for y in range(2, 39):  # fast crosses (30, y) at t = y / 40 s
        rows.append((y * 25_000 + 1000, 30, y, 1))  # 1 ms late
    rows += [
        (500_000, 100, 100, 1),  # nowhere near a track
        (1_500_000, 10, 5, 1),  # 0.5 s after slow crossed (10, 5): beyond max_delay_s
        (800_000, 10, 8, 0),  # 3 px from the slow track: beyond radius_px
        (300_000, 60, 60, 1),  # on the stationary source
    ]
    ev = np.array(rows, dtype=EVENT_DTYPE)
    return truth, ev[np.argsort(ev["t"], kind="stable")]


def test_timing_bias_on_constructed_tracks():
    truth, ev = truth_and_events()
    tab, counts = validation.timing_attribution(ev, truth, radius_px=1.0, max_delay_s=0.1)
    # unexplained: the late one; off track: the one far from every track, the one 3 px from the
    # slow one and the one on the still source (no crossing)
    assert counts == {"events": ev.size, "attributed": 71, "unexplained": 1, "off_track": 3}
    assert tab.size == 17 + 17 + 37
    assert np.all(np.diff(tab["t_us"]) >= 0)
    slow_on = tab[(tab["target"] == "slow") & (tab["p"] == 1)]
    slow_off = tab[(tab["target"] == "slow") & (tab["p"] == 0)]
    fast = tab[tab["target"] == "fast"]
    assert (slow_on.size, slow_off.size, fast.size) == (17, 17, 37)
    np.testing.assert_allclose(slow_on["delay_s"], 0.003, atol=1e-9)
    np.testing.assert_allclose(slow_off["delay_s"], 0.005, atol=1e-9)
    np.testing.assert_allclose(fast["delay_s"], 0.001, atol=1e-9)
    np.testing.assert_allclose(slow_on["t_true_s"], slow_on["x"] / 10.0, atol=1e-12)
    np.testing.assert_allclose(slow_on["distance_px"], 0.0, atol=1e-12)
    np.testing.assert_allclose(slow_off["distance_px"], 1.0, atol=1e-12)
    np.testing.assert_allclose(slow_on["speed_px_s"], 10.0)
    np.testing.assert_allclose(fast["speed_px_s"], 40.0)
    np.testing.assert_allclose(slow_on["flux_ph_s"], 1e4 * (1 + slow_on["x"] / 10.0))
    np.testing.assert_allclose(fast["flux_ph_s"], 1e6)
    # A wider radius crosses the pixel 3 px off the track, but 0.2 s after its event: a cause
    # comes first, so that event stays unexplained; no limit on the delay takes the late one.
    wide, wide_counts = validation.timing_attribution(ev, truth, radius_px=3.0, max_delay_s=None)
    assert wide.size == tab.size + 1 and 800_000 not in wide["t_us"]
    assert wide_counts["unexplained"] == 1 and wide_counts["off_track"] == 2
    late = wide[wide["t_us"] == 1_500_000]
    assert late["delay_s"][0] == pytest.approx(0.5)


def test_timing_bias_picks_the_nearest_of_repeated_crossings():
    out_and_back = {
        "t_s": np.array([0.0, 1.0, 2.0]),
        "x_px": np.array([0.0, 10.0, 0.0]),
        "y_px": np.array([20.0, 20.0, 20.0]),
        "flux_ph_s": np.array([1.0, 1.0, 1.0]),
    }
    ev = np.array([(520_000, 5, 20, 1), (1_490_000, 5, 20, 0)], dtype=EVENT_DTYPE)
    tab = validation.timing_bias(ev, {"pendulum": out_and_back})
    np.testing.assert_allclose(tab["t_true_s"], [0.5, 1.5])
    np.testing.assert_allclose(tab["delay_s"], [0.02, -0.01], atol=1e-9)


def test_timing_delays_come_from_the_crossing_that_caused_them_whatever_the_window():
    # A source circling at 1 turn/s (radius 20 px, 126 px/s) crosses 16 pixels once a turn.
    # Each crossing causes an ON event 10 ms after it and OFF events 0.2, 0.4, 0.6 and 0.7 s
    # after it: the last two nearer in time to the next pass than to their own.
    t = np.arange(0.0, 5.0005, 0.001)
    track = {"t_s": t, "x_px": 50 + 20 * np.cos(2 * np.pi * t), "y_px": 50 + 20 * np.sin(2 * np.pi * t),
             "flux_ph_s": np.full(t.size, 1e6)}
    rows, expected = [], []
    for j in range(16):
        px = round(50 + 20 * np.cos(2 * np.pi * j / 16))
        py = round(50 + 20 * np.sin(2 * np.pi * j / 16))
        t_c = (np.arctan2(py - 50, px - 50) / (2 * np.pi)) % 1.0  # closest approach: radial
        for k in range(4):
            for delay, p in [(-0.003, 1), (0.01, 1), (0.2, 0), (0.4, 0), (0.6, 0), (0.7, 0)]:
                rows.append((round((t_c + k + delay) * 1e6), px, py, p))
                expected.append(round((t_c + k + delay) * 1e6) * 1e-6 - (t_c + k))
        rows.append((round((t_c + 4.2) * 1e6), px, py, 0))  # 0.2 s after a pass the track ends before
        expected.append(0.2)
        if t_c > 0.3:
            rows.append((round((t_c - 0.3) * 1e6), px, py, 0))  # before the first pass: no cause
    ev = np.array(rows, dtype=EVENT_DTYPE)
    ev = ev[np.argsort(ev["t"], kind="stable")]
    tables = {}
    for window in (0.8, 1.5, 3.0, None):
        tab, counts = validation.timing_attribution(ev, {"disc": track}, radius_px=1.0, max_delay_s=window)
        tables[window] = tab
        assert counts["unexplained"] == ev.size - len(expected) and counts["attributed"] == len(expected)
    for window in (1.5, 3.0, None):  # the same table once the window covers the slowest delay
        assert np.array_equal(tables[window], tables[0.8])
    np.testing.assert_allclose(np.sort(tables[0.8]["delay_s"]), np.sort(expected), atol=1e-5)  # the polygon vs the circle: 5 us
    off = {r["group"]: r for r in validation.timing_bias_summary(tables[0.8], by="polarity")}
    # per pixel: 0.2 s five times, 0.4, 0.6 and 0.7 s four times each: median 0.4 s (the
    # nearest-in-time rule gave the 0.6 and 0.7 s ones to the next pass, at -0.4 and -0.3 s)
    assert off["OFF"]["p50_s"] == pytest.approx(0.4, abs=1e-5)
    assert off["ON"]["p50_s"] == pytest.approx((0.01 - 0.003) / 2, abs=1e-5)
    # A window shorter than the slowest delay leaves the rest unexplained, never given to the next pass.
    short, counts = validation.timing_attribution(ev, {"disc": track}, radius_px=1.0, max_delay_s=0.5)
    assert short["delay_s"].min() >= -0.0031 and short["delay_s"].max() <= 0.5
    assert counts["unexplained"] == ev.size - len(expected) + 16 * 4 * 2


def test_timing_bias_summary():
    truth, ev = truth_and_events()
    tab = validation.timing_bias(ev, truth)
    by_target = {r["group"]: r for r in validation.timing_bias_summary(tab, by="target")}
    assert set(by_target) == {"fast", "slow"}
    assert by_target["fast"]["n"] == 37 and by_target["fast"]["p50_s"] == pytest.approx(0.001)
    # 17 delays of 3 ms and 17 of 5 ms: median halfway, mean 4 ms
    assert by_target["slow"]["p50_s"] == pytest.approx(0.004)
    assert by_target["slow"]["mean_s"] == pytest.approx(0.004)
    assert by_target["slow"]["p5_s"] == pytest.approx(0.003)
    assert by_target["slow"]["p95_s"] == pytest.approx(0.005)
    by_pol = {r["group"]: r for r in validation.timing_bias_summary(tab, by="polarity")}
    assert by_pol["OFF"]["n"] == 17 and by_pol["OFF"]["p50_s"] == pytest.approx(0.005)
    assert by_pol["ON"]["n"] == 17 + 37
    by_speed = validation.timing_bias_summary(tab, by="speed", bins=[0.0, 20.0, 50.0])
    assert [r["group"] for r in by_speed] == [[0.0, 20.0], [20.0, 50.0]]
    assert [r["n"] for r in by_speed] == [34, 37]
    by_flux = validation.timing_bias_summary(tab, by="flux", bins=4)
    assert sum(r["n"] for r in by_flux) == tab.size
    assert by_flux[-1]["group"][1] == pytest.approx(1e6) and by_flux[-1]["n"] == 37
    text = validation.format_timing_bias_summary(list(by_target.values()))
    assert "p50 [ms]" in text and "slow" in text and "4.000" in text
    with pytest.raises(ValueError, match="by must be"):
        validation.timing_bias_summary(tab, by="colour")


def test_timing_bias_empty_cases():
    truth, ev = truth_and_events()
    assert validation.timing_bias(ev[:0], truth).size == 0
    still = {"still": truth["still"]}
    assert validation.timing_bias(ev, still).size == 0
    assert validation.timing_bias_summary(validation.timing_bias(ev, still)) == []


def test_timing_bias_summary_single_values_and_polarities():
    truth, ev = truth_and_events()
    tab = validation.timing_bias(ev, truth)
    fast = tab[tab["target"] == "fast"]  # one speed and one flux
    rows = validation.timing_bias_summary(fast, by="speed")
    assert len(rows) == 1 and isinstance(rows[0]["group"], float)  # a value, not a 7.883..7.883 bin
    text = validation.format_timing_bias_summary(rows, by="speed")
    assert ".." not in text.splitlines()[1]
    split = validation.timing_bias_summary(tab, by="target", split_polarity=True)
    slow = {r["polarity"]: r for r in split if r["group"] == "slow"}
    # The slow target's 17 ON delays of 3 ms and 17 OFF delays of 5 ms, no longer one 4 ms median.
    assert slow["ON"]["p50_s"] == pytest.approx(0.003) and slow["OFF"]["p50_s"] == pytest.approx(0.005)
    assert "polarity" in validation.format_timing_bias_summary(split)


def test_compare_from_chunks_equals_compare_in_memory(tmp_path, monkeypatch):
    # A recording larger than memory is compared from per-pixel counts built chunk by chunk.
    from evstwin.analysis import CountedRecording
    from evstwin.io import write_events
    from evstwin.validation import report

    W, H = 40, 30

    def rec(n, seed):
        r = np.random.default_rng(seed)
        ev = np.zeros(n, EVENT_DTYPE)
        ev["t"] = np.sort(r.integers(0, 2_000_000, n))
        ev["x"], ev["y"], ev["p"] = r.integers(0, W, n), r.integers(0, H, n), r.integers(0, 2, n)
        return ev

    real, sim = rec(5000, 1), rec(7000, 2)
    meta = {"width": W, "height": H}
    whole = validation.compare(real, dict(meta, path="real"), [(sim, dict(meta, path="sim"))])
    chunks = [real[a:b] for a, b in [(0, 1), (1, 700), (700, 701), (701, 5000)]]
    counted = CountedRecording.from_chunks(chunks, W, H)
    parts = validation.compare(counted, dict(meta, path="real"), [(sim, dict(meta, path="sim"))])
    assert parts.to_json_dict() == whole.to_json_dict()
    # The files: chunks of 333 events give the numbers of one-chunk reads.
    write_events(tmp_path / "real.h5", real, meta)
    write_events(tmp_path / "sim.npz", sim, meta)
    big = validation.compare_files(tmp_path / "real.h5", [tmp_path / "sim.npz"], tmp_path / "a")
    monkeypatch.setattr(report, "READ_CHUNK", 333)
    small = validation.compare_files(tmp_path / "real.h5", [tmp_path / "sim.npz"], tmp_path / "b")
    a, b = big.to_json_dict(), small.to_json_dict()
    a.pop("outputs", None), b.pop("outputs", None)
    assert a == b


TEST_DATA = Path(__file__).resolve().parents[1] / "data"


@pytest.mark.parametrize("name", ["davis346_road_cut.aedat4", "imx636_cut_evt3.raw"])
def test_info_is_the_same_whatever_the_chunk(name):
    path = TEST_DATA / name
    text = validation.info(path, chunk=1000)
    assert text == validation.info(path, chunk=10**6)
    from evstwin.io import read_events

    events, meta = read_events(path)
    assert text == validation.format_info(events, meta)  # the in-memory path: one chunk
    assert f"events        {len(events)} " in text


def test_info_of_a_text_file_without_size_reads_in_chunks(tmp_path):
    # No width= header: the size is the events' extent, known only after the last chunk.
    ev = np.zeros(5, EVENT_DTYPE)
    ev["t"], ev["x"], ev["y"], ev["p"] = [10, 20, 30, 40, 1_000_010], [0, 6, 2, 1, 3], [0, 1, 4, 2, 0], [1, 0, 1, 1, 0]
    path = tmp_path / "e.txt"
    path.write_text("".join(f"{t} {x} {y} {p}\n" for t, x, y, p in ev))
    text = validation.info(path, chunk=2)
    assert text == validation.info(path, chunk=10**6)
    assert "sensor        7 x 5 px (35 pixels) (from the events' extent)" in text
    assert "events        5 (ON 3, OFF 2)" in text and "duration 1 s" in text
    assert "5 pixels (14.29 %) have events" in text


def test_statistics_modules_import_without_matplotlib():
    code = (
        "import sys; sys.modules['matplotlib'] = None\n"
        "import evstwin.analysis, evstwin.validation\n"
        "from evstwin.validation import comparison, montecarlo, timing, report\n"
        "assert 'evstwin.plots' not in sys.modules, 'validation imported plots'\n"
        "try:\n"
        "    import evstwin.plots\n"
        "except ImportError as exc:\n"
        "    assert 'evstwin[plot]' in str(exc), exc\n"
        "else:\n"
        "    raise AssertionError('plots imported without matplotlib')\n"
    )
    import subprocess

    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr


def test_statistics_modules_never_import_plotting():
    # Compute returns data, drawing is separate: only report.py (orchestration) imports plots.
    import ast

    root = Path(validation.__file__).parent
    for module in [root.parent / "analysis.py", *root.glob("*.py")]:
        tree = ast.parse(module.read_text())
        names = {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
        names |= {a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) for a in n.names}
        names |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        draws = {n for n in names if "plots" in n or "matplotlib" in n}
        assert not draws or module.name == "report.py", (module.name, draws)


def test_timing_bias_summary_groups_a_few_values_by_value():
    # Five LEDs at five speeds, binned into 5 bins, are five rows named by their speed, not
    # ranges like 141.8..274.2 between two of them.
    tab = np.zeros(10, dtype=[("delay_s", "f8"), ("p", "u1"), ("flux_ph_s", "f8"), ("speed_px_s", "f8"),
                              ("target", "U8")])
    speeds = np.array([141.8, 307.3, 472.8, 638.3, 803.8])
    tab["speed_px_s"] = np.repeat(speeds, 2) * (1 + np.tile([0, 1e-12], 5))  # the same value, computed twice
    tab["delay_s"] = np.arange(10) * 1e-3
    tab["flux_ph_s"] = 1e9
    rows = validation.timing_bias_summary(tab, by="speed")
    assert [r["group"] for r in rows] == pytest.approx(list(speeds))
    assert [r["p50_s"] for r in rows] == pytest.approx([0.5e-3, 2.5e-3, 4.5e-3, 6.5e-3, 8.5e-3])
    # Six values for 5 bins: binned as before.
    tab["speed_px_s"][0] = 100.0
    assert isinstance(validation.timing_bias_summary(tab, by="speed")[0]["group"], list)
