"""The readout model (cpp/include/evstwin/readout.hpp): rate limit, FIFO losses, timestamp tick."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from evstwin import EVENT_DTYPE
from evstwin.presets import DAVIS346, IMX636
from evstwin.readout import Readout, ReadoutParams
from evstwin.scenario import ScenarioError, build
from evstwin.simulate import simulate


def events(t_us, p=1) -> np.ndarray:
    t = np.asarray(t_us, np.int64)
    ev = np.zeros(t.size, EVENT_DTYPE)
    ev["t"] = t
    ev["x"] = np.arange(t.size) % 65536  # the input order, to see who was kept
    ev["p"] = p
    return ev


def reference(t_us, rate_hz: float, depth: int, tick_s: float) -> tuple[list[int], list[int], list[Fraction]]:
    """The model in exact rationals, straight from its definition: (kept input indices,
    their output times [us], their delays [s])."""
    service = 1 / Fraction(rate_hz)
    tick = Fraction(repr(tick_s))  # the decimal tick (the engine rounds it to a whole ps)
    departures: list[Fraction] = []  # of the kept events
    prev = None
    kept, out, delays = [], [], []
    for i, t in enumerate(t_us):
        a = Fraction(int(t), 10**6)
        waiting = sum(1 for d in departures if d > a)
        if waiting >= depth:
            continue
        d = a if prev is None else max(a, prev + service)
        prev = d
        departures.append(d)
        kept.append(i)
        q = (d / tick).__floor__() * tick
        out.append((q * 10**6).__floor__())
        delays.append(d - a)
    return kept, out, delays


def bursty(rng: np.random.Generator, n: int, mean_gap_us: float, burst_p: float = 0.2) -> np.ndarray:
    """Sorted times [us] with many equal ones (bursts of up to 40 events at one microsecond)."""
    gaps = rng.exponential(mean_gap_us, n).astype(np.int64)
    gaps[rng.random(n) < burst_p] = 0
    return np.cumsum(gaps)


# -- the model, by hand ---------------------------------------------------------------------------


def test_a_burst_leaves_one_service_time_apart() -> None:
    r = Readout(1e6, fifo_depth=100, tick_s=1e-6)
    out, delay = r.process_with_delays(events([0] * 5))
    assert out["t"].tolist() == [0, 1, 2, 3, 4]
    assert out["x"].tolist() == [0, 1, 2, 3, 4]  # first in, first out
    assert np.allclose(delay, [0.0, 1e-6, 2e-6, 3e-6, 4e-6], rtol=0, atol=1e-18)
    assert (r.n_in, r.n_out, r.n_dropped, r.n_delayed, r.peak_waiting) == (5, 5, 0, 4, 4)
    assert r.max_delay_s == pytest.approx(4e-6, abs=1e-18)


def test_a_later_event_waits_for_the_queue_and_an_idle_readout_passes_at_once() -> None:
    r = Readout(1e6 / 3, fifo_depth=100, tick_s=1e-6)  # 3 us per event
    # 0, 0 -> 0, 3; 4 arrives while 3 is the last departure: 6; 20: idle, at once.
    out = r.process(events([0, 0, 4, 20]))
    assert out["t"].tolist() == [0, 3, 6, 20]


def test_a_full_fifo_drops_exactly_the_excess() -> None:
    r = Readout(1e6, fifo_depth=3, tick_s=1e-6)
    p = np.array([1, 0] * 5, np.uint8)
    out = r.process(events([0] * 10, p=p))
    # Event 0 leaves at once; 1, 2, 3 wait (the FIFO is full); 4..9 are dropped.
    assert out["x"].tolist() == [0, 1, 2, 3]
    assert out["t"].tolist() == [0, 1, 2, 3]
    assert (r.n_dropped, r.n_dropped_on, r.n_out, r.peak_waiting) == (6, 3, 4, 3)
    # At 2 us, events 1 and 2 have left: one waits (3), so two more fit; the third is dropped.
    out = r.process(events([2, 2, 2]))
    assert out["t"].tolist() == [4, 5]
    assert r.n_dropped == 7 and r.n_out == 6
    # Long after, the readout is idle again.
    assert r.process(events([1000]))["t"].tolist() == [1000]


def test_depth_one_holds_one_waiting_event() -> None:
    r = Readout(1e6, fifo_depth=1, tick_s=1e-6)
    out = r.process(events([0, 0, 0, 1, 1]))
    # 0 leaves at 0; 1 waits (leaves 1); 2 dropped; at 1 us event 1 leaves, 3 waits (2); 4 dropped.
    assert out["x"].tolist() == [0, 1, 3] and out["t"].tolist() == [0, 1, 2]
    assert r.n_dropped == 2


def test_the_tick_floors_the_departure_time() -> None:
    r = Readout(1e9, fifo_depth=10, tick_s=10e-6)
    out = r.process(events([0, 9, 10, 19, 25, 1234]))
    assert out["t"].tolist() == [0, 0, 10, 10, 20, 1230]
    # A queue pushes an event across a tick: 19 us + 2 services of 0.6 us = 20.2 us -> 20.
    r = Readout(1e6 / 0.6, fifo_depth=10, tick_s=10e-6)
    assert r.process(events([19, 19, 19]))["t"].tolist() == [10, 10, 20]


def test_below_saturation_only_the_tick_changes_anything() -> None:
    rng = np.random.default_rng(1)
    t = np.cumsum(rng.integers(1, 50, 20000))  # >= 1 us apart, rate 1 MHz: never a queue
    ev = events(t)
    ev["y"] = rng.integers(0, 260, t.size)
    ev["p"] = rng.integers(0, 2, t.size)
    r = Readout(1e6, fifo_depth=1, tick_s=1e-6)
    assert r.process(ev).tobytes() == ev.tobytes()
    assert (r.n_dropped, r.n_delayed, r.max_delay_s) == (0, 0, 0.0)
    coarse = Readout(1e6, fifo_depth=1, tick_s=8e-6).process(ev)
    assert np.array_equal(coarse["t"], t // 8 * 8)
    for f in ("x", "y", "p"):
        assert np.array_equal(coarse[f], ev[f])


@pytest.mark.parametrize(("rate_hz", "depth", "tick_s"), [(1e6, 5, 1e-6), (2.5e5, 40, 1e-6), (4e6, 1, 3e-6),
                                                         (1e5, 1000, 1e-5)])
def test_random_bursty_streams_match_the_exact_reference(rate_hz: float, depth: int, tick_s: float) -> None:
    rng = np.random.default_rng(int(rate_hz) + depth)
    t = bursty(rng, 3000, mean_gap_us=0.8e6 / rate_hz)
    kept, out_t, delays = reference(t, rate_hz, depth, tick_s)
    r = Readout(rate_hz, depth, tick_s)
    out, delay_s = r.process_with_delays(events(t))
    assert out["x"].tolist() == [k % 65536 for k in kept]
    assert out["t"].tolist() == out_t
    assert np.allclose(delay_s, [float(d) for d in delays], rtol=1e-12, atol=1e-18)
    assert r.n_dropped == t.size - len(kept) > 0
    assert r.max_delay_s == pytest.approx(float(max(delays)), rel=1e-12)


# -- streaming ------------------------------------------------------------------------------------


def test_any_chunking_gives_the_same_bytes() -> None:
    rng = np.random.default_rng(7)
    t = bursty(rng, 50000, mean_gap_us=0.05, burst_p=0.5)  # bursts of equal times, saturated
    ev = events(t, p=rng.integers(0, 2, t.size).astype(np.uint8))
    ev["y"] = rng.integers(0, 720, t.size)
    one = Readout(12e6, 64, 1e-6)
    whole, whole_delay = one.process_with_delays(ev)
    assert one.n_dropped > 0 and one.n_delayed > 0
    # Cut inside bursts too: the cut points are random indices, many between equal times.
    for trial in range(5):
        cuts = np.sort(rng.choice(np.arange(1, t.size), size=rng.integers(1, 200), replace=False))
        inside = np.count_nonzero(t[cuts] == t[cuts - 1])
        assert inside > 0 or trial > 0
        r = Readout(12e6, 64, 1e-6)
        parts = [r.process_with_delays(chunk) for chunk in np.split(ev, cuts)]
        assert np.concatenate([p[0] for p in parts]).tobytes() == whole.tobytes()
        assert np.concatenate([p[1] for p in parts]).tobytes() == whole_delay.tobytes()
        assert (r.n_in, r.n_out, r.n_dropped, r.n_dropped_on, r.n_delayed, r.max_delay_s, r.peak_waiting) == (
            one.n_in, one.n_out, one.n_dropped, one.n_dropped_on, one.n_delayed, one.max_delay_s, one.peak_waiting)
    # Empty chunks change nothing.
    r = Readout(12e6, 64, 1e-6)
    out = [r.process(ev[:0]), r.process(ev[:100]), r.process(ev[:0]), r.process(ev[100:])]
    assert np.concatenate(out).tobytes() == whole.tobytes()


def test_output_is_sorted_and_owns_its_memory() -> None:
    rng = np.random.default_rng(3)
    ev = events(bursty(rng, 20000, mean_gap_us=0.01, burst_p=0.7))
    out = Readout(3e6, 500, 1e-6).process(ev)
    assert out.dtype == EVENT_DTYPE and out.flags.owndata is False  # owned through a capsule
    assert np.all(np.diff(out["t"]) >= 0)
    assert not np.shares_memory(out, ev)
    # A strided view is read correctly.
    assert Readout(3e6, 500, 1e-6).process(ev[::2]).tobytes() == Readout(3e6, 500, 1e-6).process(ev[::2].copy()).tobytes()


@pytest.mark.parametrize("rate_hz", [12e6, 1.066e9, 7.3e5])
def test_a_long_saturated_stream_leaves_at_the_maximum_rate(rate_hz: float) -> None:
    # Twice the rate the readout can take, for 100000 services, into a FIFO that never fills:
    # the k-th event leaves k / rate after the first, with no drift (k * service rounded once).
    n = 100_000
    r = Readout(rate_hz, fifo_depth=n, tick_s=1e-11)
    t = np.floor(np.arange(n) * 0.5e6 / rate_hz).astype(np.int64)
    _, delay = r.process_with_delays(events(t))
    departure_s = t * 1e-6 + delay
    assert r.n_dropped == 0
    # Exact to the model's 10 ps: no accumulated rounding over 100000 services.
    assert abs((departure_s[-1] - departure_s[0]) - (n - 1) / rate_hz) <= 0.51e-11
    assert np.all(np.abs(np.diff(departure_s) - 1 / rate_hz) <= 1.01e-11)
    # With a finite FIFO, what is kept of a flood is the rate times its duration plus the FIFO.
    # (The FIFO must hold one microsecond of arrivals: the engine's times are whole
    # microseconds, so each microsecond's events arrive together; see the README.)
    depth = 10_000
    r = Readout(rate_hz, fifo_depth=depth, tick_s=1e-6)
    t = np.floor(np.arange(n) * 0.25e6 / rate_hz).astype(np.int64)  # 4x the rate
    out = r.process(events(t))
    span_s = (t[-1] - t[0]) * 1e-6
    assert abs(r.n_out - (span_s * rate_hz + depth)) <= 2
    assert r.n_dropped == n - r.n_out
    assert r.max_delay_s == pytest.approx(depth / rate_hz, rel=0.05, abs=2e-6)
    assert out["t"][-1] <= t[-1] + depth / rate_hz * 1e6 + 1


# -- bad input ------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"max_rate_hz": 0.0}, ValueError, r"max_rate_hz must be > 0.*got max_rate_hz=0\.0"),
        ({"max_rate_hz": -5.0}, ValueError, r"max_rate_hz=-5\.0"),
        ({"max_rate_hz": float("nan")}, ValueError, r"max_rate_hz.*got max_rate_hz=nan"),
        ({"max_rate_hz": float("inf")}, ValueError, r"max_rate_hz=inf"),
        ({"max_rate_hz": 1e12}, ValueError, r"max_rate_hz must be > 0 and <= 1e\+11 Hz; got max_rate_hz=1000000000000\.0"),
        ({"max_rate_hz": 1e-6}, ValueError, r"fifo_depth / max_rate_hz .* <= 1e\+06 s; got fifo_depth=10, max_rate_hz=1e-06"),
        ({"max_rate_hz": "fast"}, TypeError, r"max_rate_hz must be a real number; got max_rate_hz='fast'"),
        ({"fifo_depth": 0}, ValueError, r"fifo_depth must be an integer >= 1 \(events\); got fifo_depth=0"),
        ({"fifo_depth": -3}, ValueError, r"fifo_depth=-3"),
        ({"fifo_depth": 2.5}, TypeError, r"fifo_depth must be an integer.*got fifo_depth=2\.5"),
        ({"fifo_depth": True}, TypeError, r"fifo_depth=True"),
        ({"fifo_depth": 2**63}, ValueError, r"fifo_depth=9223372036854775808"),
        ({"tick_s": 0.0}, ValueError, r"tick_s must be in \[1e-11, 1\] s \(> 0\); got tick_s=0\.0"),
        ({"tick_s": -1e-6}, ValueError, r"tick_s=-1e-06"),
        ({"tick_s": float("nan")}, ValueError, r"tick_s.*got tick_s=nan"),
        ({"tick_s": 5.0}, ValueError, r"tick_s=5\.0"),
    ],
)
def test_bad_parameters_name_the_argument_and_value(kwargs: dict, error: type, match: str) -> None:
    args = {"max_rate_hz": 1e6, "fifo_depth": 10, "tick_s": 1e-6}
    args.update(kwargs)
    with pytest.raises(error, match=match):
        Readout(**args)
    with pytest.raises(error, match=match):
        ReadoutParams(**args)


def test_the_engine_refuses_bad_parameters_too() -> None:
    from evstwin import _core

    for args, match in [((0.0, 1, 1e-6), "max_rate_hz=0"), ((float("nan"), 1, 1e-6), "max_rate_hz=nan"),
                        ((1e-7, 1, 1e-6), "fifo_depth=1, max_rate_hz=9.99"),
                        ((1e6, 0, 1e-6), "fifo_depth=0"), ((1e6, 1, 0.0), "tick_s=0")]:
        with pytest.raises(ValueError, match=match):
            _core.Readout(*args)


def test_unsorted_or_foreign_events_are_refused_and_change_nothing() -> None:
    r = Readout(1e6, 2, 1e-6)
    first = r.process(events([0, 0, 0, 0]))
    assert r.n_dropped == 1
    with pytest.raises(ValueError, match=r"sorted by t: event 2 has t=3 us, before the event before it at t=5 us"):
        r.process(events([4, 5, 3]))
    with pytest.raises(ValueError, match=r"event 0 has t=-1 us, before the previous call's last event at t=0 us"):
        r.process(events([-1]))
    assert (r.n_in, r.n_dropped) == (4, 1)  # untouched by the refused calls
    with pytest.raises(TypeError, match=r"EVENT_DTYPE.*got dtype int64"):
        r.process(np.zeros(3, np.int64))
    other = np.zeros(2, [("x", "<u2"), ("y", "<u2"), ("p", "u1"), ("t", "<i8")])
    with pytest.raises(TypeError, match="EVENT_DTYPE"):
        r.process(other)
    with pytest.raises(ValueError, match="1-D"):
        r.process(events([1, 2]).reshape(1, 2))
    with pytest.raises(ValueError, match="outside the readout's"):
        r.process(events([10**14]))
    # The stream goes on as if the refused calls had not been made.
    fresh = Readout(1e6, 2, 1e-6)
    assert np.concatenate([first, r.process(events([1, 1]))])["t"].tolist() == fresh.process(
        events([0, 0, 0, 0, 1, 1]))["t"].tolist() == [0, 1, 2, 3]
    assert (r.n_in, r.n_dropped) == (fresh.n_in, fresh.n_dropped) == (6, 2)
    r.reset()
    assert (r.n_in, r.n_out, r.n_dropped, r.max_delay_s) == (0, 0, 0, 0.0)
    assert r.process(events([-5]))["t"].tolist() == [-5]


def test_unsorted_refusal_keeps_the_state_exactly() -> None:
    ev = events([0, 0, 0, 1, 1, 2, 2, 2])
    a, b = Readout(1e6, 2, 1e-6), Readout(1e6, 2, 1e-6)
    out_a = [a.process(ev[:3])]
    with pytest.raises(ValueError):
        a.process(events([1, 0]))
    out_a.append(a.process(ev[3:]))
    assert np.concatenate(out_a).tobytes() == b.process(ev).tobytes()


# -- presets and scenarios -----------------------------------------------------------------------


def test_presets_carry_sourced_readout_figures() -> None:
    assert DAVIS346.readout is not None and IMX636.readout is not None
    assert (DAVIS346.readout.max_rate_hz, DAVIS346.readout.tick_s) == (12e6, 1e-6)
    assert (IMX636.readout.max_rate_hz, IMX636.readout.tick_s) == (1.066e9, 1e-6)
    for p in (DAVIS346.readout, IMX636.readout):
        assert p.sources and any("FIFO" in a for a in p.assumptions)
    assert DAVIS346.readout.max_queue_delay_s == pytest.approx(4096 / 12e6)
    assert DAVIS346.readout_params(fifo_depth=8).fifo_depth == 8
    bare = DAVIS346.__class__(**{**DAVIS346.__dict__, "readout": None})
    assert bare.readout_params() is None
    with pytest.raises(ValueError, match="no readout figures: give fifo_depth"):
        bare.readout_params(max_rate_hz=1e6)


def flash(**readout) -> dict:
    """A 32 x 24 window whose light jumps x1e4 at 50 ms: every pixel fires at once."""
    s = {
        "name": "flash",
        "duration_s": 0.1,
        "sensor": {"preset": "davis346", "width": 32, "height": 24},
        "pixel": {"photon_shot_noise": False, "dark_model": "none", "leak_rate_hz": 0.0, "shot_noise_rate_hz": 0.0,
                  "cutoff_hz": 1000.0, "refractory_s": 1e-5},
        "background": {"photon_rate_ph_s": 1e6},
        "optics": {"extra_blur_sigma_px": 40.0},
        "sampling": {"rate_hz": 20000.0},
        "targets": [{"kind": "static", "x_px": 16.0, "y_px": 12.0,
                     "light_curve": {"t_s": [0.0, 0.05, 0.0501, 1.0], "flux_ph_s": [0.0, 0.0, 1e13, 1e13]}}],
    }
    if readout:
        s["readout"] = readout
    return s


def test_simulate_applies_the_preset_readout_and_reports_it() -> None:
    ideal = simulate(flash(enabled=False))
    assert ideal.meta["readout_enabled"] is False and "readout: off" in ideal.summary()
    assert "readout_n_dropped" not in ideal.meta
    # The preset's 12 Mev/s: a burst of one microsecond's events is spread over it, in the same microsecond.
    default = simulate(flash())
    assert default.meta["readout_enabled"] is True and default.meta["readout_max_rate_hz"] == 12e6
    assert default.meta["readout_n_in"] == len(ideal.events)
    # A slow readout floods: events are lost and the rest are late, and the summary says so.
    slow = simulate(flash(max_rate_hz=2e5, fifo_depth=64))
    m = slow.meta
    assert m["readout_n_dropped"] > 0 and m["readout_n_in"] == len(ideal.events)
    assert len(slow.events) == m["readout_n_out"] == m["readout_n_in"] - m["readout_n_dropped"]
    assert 0 < m["readout_max_delay_s"] <= 64 / 2e5 + 1e-12
    assert np.all(np.diff(slow.events["t"]) >= 0)
    assert f"{m['readout_n_dropped']} of {m['readout_n_in']} events dropped" in slow.summary()
    # The same as the readout applied to the ideal events in one call.
    assert slow.events.tobytes() == Readout(2e5, 64, 1e-6).process(ideal.events).tobytes()


def test_simulate_to_file_streams_the_same_readout(tmp_path) -> None:
    from evstwin import read_events
    from evstwin.simulate import simulate_to_file

    mem = simulate(flash(max_rate_hz=2e5, fifo_depth=64))
    stats = simulate_to_file(flash(max_rate_hz=2e5, fifo_depth=64), tmp_path / "flash.npz")
    assert stats.n_events == len(mem.events) and stats.meta["readout_n_dropped"] == mem.meta["readout_n_dropped"]
    assert read_events(tmp_path / "flash.npz")[0].tobytes() == mem.events.tobytes()


@pytest.mark.parametrize(
    ("readout", "message"),
    [
        ({"max_rate_hz": 0}, r"readout.max_rate_hz must be > 0 and <= 1e\+11; got 0"),
        ({"max_rate_hz": 1e-300}, r"readout=\{'max_rate_hz': 1e-300\}: fifo_depth / max_rate_hz"),
        ({"max_rate_hz": "fast"}, r"readout.max_rate_hz must be a number; got 'fast'"),
        ({"fifo_depth": 0}, r"readout.fifo_depth must be an integer >= 1 \(events\); got 0"),
        ({"fifo_depth": 1.5}, r"readout.fifo_depth must be an integer; got 1.5"),
        ({"tick_s": 0.0}, r"readout.tick_s must be >= 1e-11 and <= 1; got 0.0"),
        ({"enabled": 1}, r"readout.enabled must be true or false; got 1"),
        ({"depth": 3}, r"unknown scenario key 'readout.depth'; allowed: enabled, max_rate_hz, fifo_depth, tick_s"),
    ],
)
def test_bad_readout_keys_are_scenario_errors_naming_the_key(readout: dict, message: str) -> None:
    with pytest.raises(ScenarioError, match=message):
        build(flash(**readout))


def test_readout_keys_override_the_preset() -> None:
    scene = build(flash(max_rate_hz=5e5, tick_s=1e-5))
    assert scene.readout is not None
    assert (scene.readout.max_rate_hz, scene.readout.fifo_depth, scene.readout.tick_s) == (5e5, 4096, 1e-5)
    assert build(flash(enabled=False)).readout is None
    assert build(flash()).readout == DAVIS346.readout
