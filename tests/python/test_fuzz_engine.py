"""Fuzzing the engine API (issue 11): random small sensors, pixel parameters inside and outside
their ranges, rates from 0 to beyond 1e20 (NaN and infinities too) in any dtype, byte order and
layout, odd sample times, random chunkings and 1 or 2 threads.

Whatever comes in, a call either returns events (sorted by t, on the sensor, within the
samples' time span, the same bytes for any chunking and thread count) or raises a one-line
ValueError/TypeError naming its argument. A crash would end the test process.

The default budget is small (the test command); ``EVSTWIN_FUZZ_EXAMPLES=N`` runs N examples
per test, and ``bench/fuzz_engine.py`` runs a long budget in subprocesses, counting crashes and
hangs. Examples are derandomised (the same ones every run) unless the variable is set.
"""

from __future__ import annotations

import faulthandler
import math
import os
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, event, given, settings
from hypothesis import strategies as st

from evstwin import EVENT_DTYPE, PixelParams, Sensor

_ENV = os.environ.get("EVSTWIN_FUZZ_EXAMPLES")
FUZZ = settings(
    max_examples=int(_ENV) if _ENV else 40,
    deadline=None,
    database=None,
    derandomize=_ENV is None,
    phases=[Phase.explicit, Phase.reuse, Phase.generate, Phase.shrink],  # no explain phase: it writes .hypothesis/
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
"""The settings of every fuzz test here (and in test_fuzz_scenario)."""

MAX_EVENTS = 300_000
"""Each fuzzed sensor's cap: a flood (theta 1e-3 and rates 1e-30 <-> 1e20) stops small."""

ARGUMENTS = (
    "photon_rate", "t_s", "sample intervals", "pixels", "width", "height", "num_threads", "seed", "max_events",
    "probe", *PixelParams.field_names(),
)
"""What an error message must name (one of)."""


def tick(area: str) -> None:
    """Count one example of an area for bench/fuzz_engine.py (a line in its progress file), and
    re-arm its hang watchdog: an example still running after EVSTWIN_FUZZ_HANG_S seconds ends
    the process with faulthandler's "Timeout" and the stacks."""
    path = os.environ.get("EVSTWIN_FUZZ_PROGRESS")
    if path:
        with open(path, "a", encoding="ascii") as fh:
            fh.write(area + "\n")
    hang_s = os.environ.get("EVSTWIN_FUZZ_HANG_S")
    if hang_s:
        faulthandler.dump_traceback_later(float(hang_s), exit=True)


def assert_names_an_argument(exc: BaseException, names: tuple[str, ...] = ARGUMENTS) -> None:
    message = str(exc)
    assert isinstance(exc, (ValueError, TypeError)), f"{type(exc).__name__}: {message}"
    assert "\n" not in message, f"a multi-line error: {message!r}"
    assert any(name in message for name in names), f"the error names no argument: {message!r}"


# -- strategies -------------------------------------------------------------------------------

WILD = [0.0, -0.0, -1.0, 5e-324, 1e-300, 1e-30, 1e-6, 0.5, 1.0, 2.0, 1e6, 1e15, 1e20, 1e300,
        math.inf, -math.inf, math.nan]
_RANGES = {  # (lo, hi) of each float field (evstwin::validate); values are drawn inside and out
    "theta_on": (1e-3, 10.0), "theta_off": (1e-3, 10.0), "refractory_s": (0.0, 1.0), "cutoff_hz": (1e-6, 1e9),
    "leak_rate_hz": (0.0, 1e6), "shot_noise_rate_hz": (0.0, 1e6), "shot_noise_factor": (0.0, 1e6),
    "shot_noise_i_max_a": (1e-30, 1.0), "dark_rate_e_per_s": (0.0, 1e15), "threshold_sigma": (0.0, 1.0),
    "fill_factor": (1e-6, 1.0), "internal_qe": (1e-6, 1.0), "transmission": (1e-6, 1.0),
    "absorption_per_m": (1e-6, 1e12), "depletion_width_m": (1e-15, 1.0), "pr_cutoff_ref_hz": (1e-6, 1e12),
    "pr_ref_current_a": (1e-30, 1.0),
}


def _in_range(lo: float, hi: float) -> st.SearchStrategy[float]:
    if lo > 0:  # log-uniform, so 1e-30 .. 1 is not all near 1
        return st.floats(math.log10(lo), math.log10(hi)).map(lambda e: min(max(10.0**e, lo), hi))
    return st.one_of(st.just(lo), st.floats(lo, hi), st.floats(-12, math.log10(hi)).map(lambda e: min(10.0**e, hi)))


_IDEAL = {"photon_shot_noise": False, "dark_model": "none", "leak_rate_hz": 0.0, "shot_noise_rate_hz": 0.0,
          "cutoff_hz": None, "refractory_s": 0.0, "theta_on": 0.05, "theta_off": 0.05}


@st.composite
def pixel_fields(draw: Any) -> dict[str, Any]:
    """PixelParams fields: the defaults or a noiseless pixel, some fields drawn in their range,
    and in one example of five one field far out (NaN, infinities, 1e300, a string...)."""
    fields: dict[str, Any] = dict(_IDEAL) if draw(st.booleans()) else {}
    for name, (lo, hi) in _RANGES.items():
        if draw(st.integers(0, 5)) == 0:
            fields[name] = draw(_in_range(lo, hi))
    if draw(st.booleans()):
        fields["cutoff_hz"] = None
    for name, values in (("dark_model", ["poisson", "paper", "none"]), ("lowpass", ["exact", "euler"]),
                         ("photon_shot_noise", [True, False]), ("pr_pole", [True, False])):
        if draw(st.integers(0, 3)) == 0:
            fields[name] = draw(st.sampled_from(values))
    if draw(st.integers(0, 4)) == 0:
        wild = st.one_of(st.sampled_from(WILD), st.floats(allow_nan=True, allow_infinity=True),
                         st.sampled_from(["abc", 10**400, True, None, [1.0]]))
        fields[draw(st.sampled_from(sorted(_RANGES)))] = draw(wild)
    return fields


_RATES = np.array([0.0, 1e-31, 1e-30, 1e-6, 1.0, 1e3, 1e6, 1e8, 1e9, 1e12, 1e15, 1e19, 1e20,
                   np.nextafter(1e20, 0), np.nextafter(1e20, np.inf), 1e21, -1.0, np.inf, -np.inf, np.nan])
_DTS = np.array([1e-13, 1e-12, 2e-12, 1e-9, 1e-6, 1e-5, 1e-4, 1e-3, 1e-3, 1e-3, 1e-2, 0.1, 1.0, 100.0, 1e5])


@st.composite
def rate_array(draw: Any, n_samples: int, height: int, width: int) -> np.ndarray:
    """(n_samples, height, width) rates: smooth random light, jumps between extremes, or
    specials sprinkled in; float32/float64, little or big endian, C, Fortran or unaligned."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    shape = (n_samples, height, width)
    kind = draw(st.sampled_from(["lognormal", "jumps", "specials", "static"]))
    if kind == "lognormal":
        lo, hi = sorted((draw(st.floats(-30, 20)) + 0.0, draw(st.floats(-30, 20)) + 0.0))  # no -0.0: (0, -0) is "high < low"
        rate = 10.0 ** rng.uniform(lo, hi, shape)
    elif kind == "jumps":
        lo, hi = draw(st.sampled_from([(1e-30, 1e20), (1e6, 1e9), (0.0, 1e12), (1e3, 1e3)]))
        rate = np.where(rng.random(shape) < 0.5, lo, hi)
    elif kind == "specials":
        rate = 10.0 ** rng.uniform(4, 10, shape)
        mask = rng.random(shape) < draw(st.sampled_from([0.0, 0.01, 0.3]))
        rate[mask] = rng.choice(_RATES, int(mask.sum()))
    else:
        rate = np.broadcast_to(10.0 ** rng.uniform(4, 10, shape[1:]), shape)
    dtype = draw(st.sampled_from(["<f8", ">f8", "<f4", ">f4"]))
    with np.errstate(over="ignore"):
        out = rate.astype(dtype) if kind != "static" or dtype != "<f8" else rate
    layout = draw(st.sampled_from(["c", "fortran", "unaligned"]))
    if layout == "fortran":
        out = np.asfortranarray(out)
    elif layout == "unaligned" and out.size:
        raw = np.zeros(out.nbytes + 1, np.uint8)[1:]
        unaligned = raw.view(out.dtype).reshape(out.shape)
        unaligned[...] = out
        out = unaligned
    return out


@st.composite
def sample_times(draw: Any, n_samples: int) -> np.ndarray:
    """n_samples increasing times from odd starts and steps; now and then a bad one."""
    t0 = draw(st.sampled_from([0.0, 0.0, 0.0, -5.0, 1e-3, 1e6, 9.1e12, -9.1e12]))
    if draw(st.integers(0, 2)) == 0:  # irregular steps, tiny to huge
        steps = np.array([draw(st.sampled_from(list(_DTS))) for _ in range(n_samples)])
    else:
        steps = np.full(n_samples, draw(st.sampled_from(list(_DTS[1:]))))
    t = t0 + np.cumsum(steps) - steps[0]
    if draw(st.integers(0, 19)) == 0 and n_samples > 1:
        k = draw(st.integers(0, n_samples - 1))
        t[k] = draw(st.sampled_from([math.nan, math.inf, t[k - 1] if k else -math.inf, 1e13, -1e13]))
    return t


@st.composite
def engine_case(draw: Any) -> dict[str, Any]:
    width = draw(st.integers(1, 64))
    height = draw(st.integers(1, 64 if width * 64 <= 4096 else 4096 // width))
    n_samples = draw(st.integers(1, 16))
    return {
        "width": width, "height": height, "seed": draw(st.integers(0, 2**64 - 1)),
        "fields": draw(pixel_fields()), "rate": draw(rate_array(n_samples, height, width)),
        "t": draw(sample_times(n_samples)),
        "cuts": sorted(set(draw(st.lists(st.integers(1, max(1, n_samples - 1)), max_size=4)))),
    }


# -- properties -------------------------------------------------------------------------------


def check_events(events: np.ndarray, width: int, height: int, t: np.ndarray) -> None:
    assert events.dtype == EVENT_DTYPE
    assert np.all(np.diff(events["t"]) >= 0), "events not sorted by t"
    assert np.all(events["x"] < width) and np.all(events["y"] < height), "an event off the sensor"
    assert np.all((events["p"] == 0) | (events["p"] == 1))
    if len(events):
        assert events["t"][0] >= math.floor(t.min() * 1e6) - 1, "an event before the samples"
        assert events["t"][-1] <= math.ceil(t.max() * 1e6) + 1, "an event after the samples"


def _params(fields: dict[str, Any]) -> PixelParams | None:
    try:
        return PixelParams(**fields)
    except (ValueError, TypeError) as exc:
        assert_names_an_argument(exc)
        event("PixelParams refused")
        return None


def _run_chunks(sensor: Sensor, rate: np.ndarray, t: np.ndarray, cuts: list[int]) -> np.ndarray:
    bounds = [0, *cuts, len(t)]
    parts = [sensor.run(rate[a:b], t[a:b]) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]
    return np.concatenate(parts) if parts else np.zeros(0, EVENT_DTYPE)


@FUZZ
@given(engine_case())
def test_fuzzed_runs_give_sorted_events_or_a_named_error_the_same_for_any_chunking_and_threads(case: dict) -> None:
    tick("engine.run")
    params = _params(case["fields"])
    if params is None:
        return
    w, h, t, rate = case["width"], case["height"], case["t"], case["rate"]
    one = Sensor(w, h, params, seed=case["seed"], num_threads=1, max_events=MAX_EVENTS)
    try:
        events = one.run(rate, t)
    except (ValueError, TypeError) as exc:
        assert_names_an_argument(exc)
        event("run refused: " + next(name for name in ARGUMENTS if name in str(exc)))
        if "max_events" in str(exc):
            return  # chunks may each stay under the cap
        # Bad input is refused before any state changes, and again in whichever chunk holds it.
        assert one.samples_seen == 0
        with pytest.raises((ValueError, TypeError)):
            _run_chunks(Sensor(w, h, params, seed=case["seed"], num_threads=2, max_events=MAX_EVENTS),
                        rate, t, case["cuts"])
        return
    check_events(events, w, h, t)
    event("events: " + ("none" if len(events) == 0 else "some"))
    two = Sensor(w, h, params, seed=case["seed"], num_threads=2, max_events=MAX_EVENTS)
    chunked = _run_chunks(two, rate, t, case["cuts"])
    assert chunked.tobytes() == events.tobytes(), "chunking or threads changed the events"


@FUZZ
@given(engine_case(), st.data())
def test_fuzzed_sub_sampling_of_some_pixels_is_a_named_error_or_events_on_the_sensor(case: dict, data: Any) -> None:
    tick("engine.run_pixels")
    params = _params(case["fields"])
    if params is None:
        return
    w, h, t, rate = case["width"], case["height"], case["t"], case["rate"]
    npix = w * h
    pixels = np.array(data.draw(st.lists(st.one_of(st.integers(0, npix - 1), st.sampled_from([-1, npix, 2**40])),
                                         min_size=1, max_size=8)), np.int64)
    # Fine times around the start of the run (some after it: run skips what they passed).
    t_fine = np.array(sorted(data.draw(st.lists(st.floats(-0.01, 0.01), min_size=1, max_size=6)))) + t[0]
    sub_rate = np.resize(rate.reshape(-1), (len(t_fine), len(pixels)))
    sensor = Sensor(w, h, params, seed=case["seed"], num_threads=data.draw(st.sampled_from([1, 2])),
                    max_events=MAX_EVENTS)
    try:
        events = sensor.run_pixels(pixels, sub_rate, t_fine)
    except (ValueError, TypeError) as exc:
        assert_names_an_argument(exc)
        return
    check_events(events, w, h, t_fine)
    try:
        # A sub-sampled pixel's next interval starts at its own last sample, maybe before t[0].
        check_events(sensor.run(rate, t), w, h, np.concatenate([t_fine[:1], t]))
    except (ValueError, TypeError) as exc:
        assert_names_an_argument(exc)


@FUZZ
@given(
    st.one_of(st.integers(-2, 70_000), st.sampled_from([2**31, 2**63, 10**30]), st.floats(), st.booleans(), st.text()),
    st.one_of(st.none(), st.integers(-2, 5000), st.sampled_from([2**31 - 1, 2**31, 2**64]), st.floats()),
    st.one_of(st.none(), st.integers(-1, 2**33), st.floats()),
)
def test_fuzzed_constructor_arguments_are_accepted_or_a_named_error(width: Any, threads: Any, max_events: Any) -> None:
    tick("engine.Sensor")
    try:
        sensor = Sensor(width, 4, num_threads=threads, max_events=max_events)
    except (ValueError, TypeError) as exc:
        assert_names_an_argument(exc)
        return
    assert sensor.width == width and 1 <= sensor.num_threads <= 1024

