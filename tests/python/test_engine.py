"""The pixel engine against analytic results (issue 2's acceptance tests).

Noise-free cases compare event times with closed-form crossing times; noisy cases compare
rates, means and variances with the formulas of the paper's eq. 4 and 12-13 within the
statistical error of the run.
"""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest

import evstwin
from evstwin import EVENT_DTYPE, PixelParams, Sensor

E = evstwin._core.ELEMENTARY_CHARGE_C

IDEAL = PixelParams(
    theta_on=0.2,
    theta_off=0.15,
    refractory_s=0.0,
    cutoff_hz=None,
    leak_rate_hz=0.0,
    shot_noise_rate_hz=0.0,
    dark_model="none",
    photon_shot_noise=False,
)


def constant_run(params: PixelParams, rate: float, n: int, dt: float, shape=(1, 1), seed: int = 0, **kw):
    h, w = shape
    sensor = Sensor(w, h, params, seed=seed, **kw)
    t = np.arange(n) * dt
    return sensor, sensor.run(np.full((n, h, w), rate), t)


def test_event_dtype_is_the_fields_convention() -> None:
    assert EVENT_DTYPE == np.dtype([("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")])
    assert EVENT_DTYPE.itemsize == 13


@pytest.mark.parametrize("ratio", [1.3, 2.0, math.e, 10.0, 1e3, 0.5, 0.01])
def test_step_gives_floor_ln_ratio_over_theta_events(ratio: float) -> None:
    sensor = Sensor(3, 2, IDEAL)
    rate = np.full((2, 2, 3), 1e9)
    rate[1] *= ratio
    ev = sensor.run(rate, [0.0, 1e-3])
    theta = IDEAL.theta_on if ratio > 1 else IDEAL.theta_off
    per_pixel = math.floor(abs(math.log(ratio)) / theta)
    assert len(ev) == 6 * per_pixel
    assert np.all(ev["p"] == (1 if ratio > 1 else 0))
    assert np.all(np.diff(ev["t"]) >= 0)
    # Interpolated times (eq. 16): the n-th level is crossed at n theta / |ln R| of the interval,
    # floored to the microsecond as a sensor's counter reads it (a nanosecond's tolerance).
    first_pixel = ev[(ev["x"] == 0) & (ev["y"] == 0)]
    expect_us = 1e3 * theta * np.arange(1, per_pixel + 1) / abs(math.log(ratio))
    np.testing.assert_array_equal(first_pixel["t"], np.floor(expect_us + 1e-3))


def test_first_sample_sets_steady_state_without_events() -> None:
    rng = np.random.default_rng(1)
    rate = rng.uniform(1e3, 1e12, size=(1, 20, 30))
    params = PixelParams(threshold_sigma=0.2)  # every noise source on
    assert len(Sensor(30, 20, params).run(rate, [0.0])) == 0


def test_exponential_ramp_crossings_at_analytic_times() -> None:
    g = 40.0  # d ln(rate) / dt [1/s]
    t = np.linspace(0.0, 0.25, 97)  # deliberately not aligned with the crossings
    rate = (1e8 * np.exp(g * t))[:, None, None]
    ev = Sensor(1, 1, IDEAL).run(rate, t)
    n = np.arange(1, math.floor(g * 0.25 / IDEAL.theta_on) + 1)
    assert len(ev) == len(n)
    assert np.all(ev["p"] == 1)
    np.testing.assert_allclose(ev["t"], n * IDEAL.theta_on / g * 1e6, atol=0.5)
    # And falling: OFF events at n theta_off / g.
    ev = Sensor(1, 1, IDEAL).run(rate[::-1].copy(), t)
    n = np.arange(1, math.floor(g * 0.25 / IDEAL.theta_off + 1e-9) + 1)
    assert len(ev) == len(n) and np.all(ev["p"] == 0)
    np.testing.assert_allclose(ev["t"], n * IDEAL.theta_off / g * 1e6, atol=0.5)


@pytest.mark.parametrize("refr_over_tc", [0.5, 1.0 - 1e-6, 2.5, 4.0])
def test_refractory_removes_exactly_the_crossings_inside_it(refr_over_tc: float) -> None:
    # Crossings every tc on a ramp. A refractory period shorter than tc removes nothing; a
    # longer one leaves one event at the first crossing and then one every refractory
    # period (the pixel fires as soon as it wakes, merging the levels it missed).
    g, theta = 50.0, IDEAL.theta_on
    tc = theta / g
    refr = refr_over_tc * tc
    t = np.linspace(0.0, 0.2, 801)
    ev = Sensor(1, 1, IDEAL.replace(refractory_s=refr)).run((1e8 * np.exp(g * t))[:, None, None], t)
    if refr < tc:
        expect = tc * np.arange(1, math.floor(0.2 / tc + 1e-9) + 1)
    else:
        expect = tc + refr * np.arange(0, math.floor((0.2 - tc) / refr + 1e-9) + 1)
    assert len(ev) == len(expect)
    np.testing.assert_allclose(ev["t"], expect * 1e6, atol=0.5)


def test_lowpass_delays_a_step_by_the_analytic_time() -> None:
    fc, ratio = 10.0, 8.0
    tau = 1.0 / (2 * math.pi * fc)
    # A step at t = 0 (the input rises over 1 us), then samples every 20 us for 0.2 s.
    t = np.concatenate([[-1e-6], np.arange(0.0, 0.2, 20e-6)])
    rate = np.full(len(t), 1e9 * ratio)
    rate[0] = 1e9
    ev = Sensor(1, 1, IDEAL.replace(cutoff_hz=fc)).run(rate[:, None, None], t)
    delta = math.log(ratio)
    n = np.arange(1, math.floor(delta / IDEAL.theta_on) + 1)
    # y(t) = x1 - delta exp(-t/tau): level n*theta is crossed at -tau ln(1 - n theta / delta).
    expect_us = -tau * np.log(1.0 - n * IDEAL.theta_on / delta) * 1e6
    assert len(ev) == len(n)
    # The input's 1 us ramp acts as a step at its middle, 0.5 us before t = 0; each event is
    # floored to the microsecond its crossing lies in (within the line's 0.05 us between samples).
    t_cross_us = expect_us - 0.5
    assert np.all((ev["t"] <= t_cross_us + 0.05) & (t_cross_us < ev["t"] + 1.05)), (ev["t"], t_cross_us)
    assert ev["t"][0] > 1500  # the filter really delays: 1.6 ms for the first level


def test_euler_option_is_eq7() -> None:
    fc, dt = 10.0, 1e-3
    a = 2 * math.pi * fc * dt
    rng = np.random.default_rng(2)
    rate = rng.uniform(1e8, 1e9, size=(50, 1, 1))
    t = np.arange(50) * dt
    _, trace = Sensor(1, 1, IDEAL.replace(cutoff_hz=fc, lowpass="euler")).run_probe(rate, t, [(0, 0)])
    x, y = trace["log_current"][:, 0], trace["filtered"][:, 0]
    np.testing.assert_allclose(x, np.log(E * rate[:, 0, 0] * IDEAL.electrons_per_photon), rtol=1e-12)
    np.testing.assert_allclose(y[1:], a * x[:-1] + (1 - a) * y[:-1], rtol=1e-12)
    with pytest.raises(ValueError, match="euler.*cutoff_hz=10.*dt=0.05"):
        Sensor(1, 1, IDEAL.replace(cutoff_hz=fc, lowpass="euler")).run(np.ones((2, 1, 1)) * 1e9, [0.0, 0.05])


def test_leak_alone_gives_on_events_at_f_leak() -> None:
    f_leak = 4.0
    _, ev = constant_run(IDEAL.replace(leak_rate_hz=f_leak, leak_random_phase=False), 1e9, 3001, 1e-3)
    assert len(ev) == 12 and np.all(ev["p"] == 1)
    # Each on a whole microsecond, which its timestamp bears (floored within a nanosecond).
    np.testing.assert_array_equal(ev["t"], np.arange(1, 13) * round(1e6 / f_leak))


def test_leak_events_keep_their_times_across_sample_intervals_of_hours() -> None:
    # The engine's working records keep an event's microsecond modulo 2^32 and take the rest
    # from its sample's end; an event more than 2^31 us (35.8 min) before that end makes its
    # block keep full times. Leak events every 900 s over intervals of 1000 s and 5000 s (the
    # second holds events up to 4200 s before its end), on run() and on run_pixels() (listed
    # out of order: the comparison sort), on 1 and 2 threads: every time the analytic one.
    f_leak = 1 / 900.0
    params = IDEAL.replace(leak_rate_hz=f_leak, leak_random_phase=False)
    t = np.array([0.0, 1000.0, 6000.0, 6001.0])
    want = np.arange(1, 7) / f_leak * 1e6  # 900 s ... 5400 s
    h, w = 2, 3
    for threads in (1, 2):
        ev = Sensor(w, h, params, seed=1, num_threads=threads).run(np.full((4, h, w), 1e9), t)
        assert len(ev) == len(want) * h * w and np.all(ev["p"] == 1)
        np.testing.assert_allclose(ev["t"][:: h * w], want, atol=0.5)
        assert np.all(ev["t"].reshape(len(want), h * w) == ev["t"][:: h * w, None])
        sensor = Sensor(w, h, params, seed=1, num_threads=threads)
        sub = sensor.run_pixels(np.array([4, 1]), np.full((4, 2), 1e9), t)
        assert len(sub) == 2 * len(want) and np.all(sub["y"] * w + sub["x"] == np.tile([1, 4], len(want)))
        np.testing.assert_allclose(sub["t"][::2], want, atol=0.5)


def test_statistical_shot_noise_rates_follow_eq12() -> None:
    rn, factor = 2.0, 0.25
    params = IDEAL.replace(shot_noise_rate_hz=rn, shot_noise_factor=factor)
    i_ratio = 0.4
    photon_rate = i_ratio * params.shot_noise_i_max_a / E / params.electrons_per_photon
    n_pix, duration, dt = 40 * 50, 5.0, 2e-3
    _, ev = constant_run(params, photon_rate, int(duration / dt) + 1, dt, shape=(40, 50), seed=3)
    r = ((factor - 1) * i_ratio + 1) * rn  # eq. 12, per polarity
    expect = r * n_pix * duration
    for pol in (0, 1):
        count = int(np.sum(ev["p"] == pol))
        assert abs(count - expect) < 4 * math.sqrt(expect), (pol, count, expect)
    # (A noise event resets the reference to the level there, so it has no follow-on
    # events: those would have pushed the counts above the eq. 12 rate.)


def probe_currents(params: PixelParams, rate: float, dt: float, n: int, n_pix: int = 100, seed: int = 5) -> np.ndarray:
    sensor = Sensor(n_pix, 1, params, seed=seed)
    _, trace = sensor.run_probe(np.full((n, 1, n_pix), rate), np.arange(n) * dt, [(i, 0) for i in range(n_pix)])
    return trace["current_a"][1:].ravel()  # sample 0 is the noise-free steady state


@pytest.mark.parametrize("dt", [1e-3, 10e-3])  # mean 18 (table inversion) and 180 (PTRS)
def test_poisson_dark_current_mean_and_variance(dt: float) -> None:
    lam = 18000.0
    params = IDEAL.replace(dark_model="poisson", dark_rate_e_per_s=lam, noise_model="sampled")
    i = probe_currents(params, 0.0, dt, 400)
    mean, var = lam * E, lam * E * E / dt  # N ~ Poisson(lam dt), I = N e / dt
    n = i.size
    assert abs(i.mean() - mean) < 5 * math.sqrt(var / n)
    assert abs(i.var() / var - 1) < 5 * math.sqrt(2 / n)


def test_paper_dark_current_mean_and_variance_do_not_depend_on_dt() -> None:
    lam = 18000.0
    params = IDEAL.replace(dark_model="paper", noise_model="sampled", dark_rate_e_per_s=lam)
    for dt in (1e-4, 1e-2):
        i = probe_currents(params, 0.0, dt, 200)
        mean, var = lam * E, lam * E * E  # eq. 4: I = Poisson(lam) e
        assert abs(i.mean() - mean) < 5 * math.sqrt(var / i.size)
        assert abs(i.var() / var - 1) < 5 * math.sqrt(2 / i.size)


@pytest.mark.parametrize("dt", [4e-3, 1e-3, 1e-4])  # 72, 18 and 1.8 electrons per sample
def test_the_log_sees_n_plus_half_so_the_baseline_does_not_depend_on_dt(dt: float) -> None:
    from scipy.stats import poisson

    lam = 18000.0
    params = IDEAL.replace(dark_model="poisson", dark_rate_e_per_s=lam, noise_model="sampled")
    sensor = Sensor(100, 1, params, seed=5)
    n_samples = 400
    _, trace = sensor.run_probe(np.zeros((n_samples, 1, 100)), np.arange(n_samples) * dt, [(i, 0) for i in range(100)])
    counts = trace["current_a"][1:].ravel() * dt / E
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)  # the current is N e / dt
    np.testing.assert_allclose(trace["log_current"][1:].ravel(), np.log((np.round(counts) + 0.5) * E / dt), rtol=1e-12)
    # E[ln(N + 1/2)] - ln(mu), from the Poisson pmf: small at every dt, unlike E[ln N].
    mu = lam * dt
    k = np.arange(0, int(mu + 20 * math.sqrt(mu) + 30))
    pmf = poisson.pmf(k, mu)
    expected_bias = float(np.sum(pmf * np.log(k + 0.5))) - math.log(mu)
    assert abs(expected_bias) < 0.05
    x = trace["log_current"][1:].ravel() - math.log(lam * E)
    assert abs(x.mean() - expected_bias) < 5 * x.std() / math.sqrt(x.size)


def test_photon_shot_noise_is_poisson_on_the_signal() -> None:
    params = IDEAL.replace(photon_shot_noise=True, noise_model="sampled")
    dt = 1e-3
    photon_rate = 5e4 / params.electrons_per_photon  # 50 electrons per sample
    i = probe_currents(params, photon_rate, dt, 300)
    mean, var = 5e4 * E, 5e4 * E * E / dt
    assert abs(i.mean() - mean) < 5 * math.sqrt(var / i.size)
    assert abs(i.var() / var - 1) < 5 * math.sqrt(2 / i.size)


def test_threshold_mismatch_is_gaussian_and_fixed_per_seed() -> None:
    params = IDEAL.replace(threshold_sigma=0.1)
    on, off = Sensor(100, 100, params, seed=1).thresholds()
    assert abs(on.mean() / 0.2 - 1) < 4 * 0.1 / 100
    assert abs(on.std() / (0.1 * 0.2) - 1) < 0.05
    assert abs(np.corrcoef(on.ravel(), off.ravel())[0, 1]) < 0.05
    on2, _ = Sensor(100, 100, params, seed=1).thresholds()
    on3, _ = Sensor(100, 100, params, seed=2).thresholds()
    assert np.array_equal(on, on2) and not np.array_equal(on, on3)
    same, _ = Sensor(10, 10, IDEAL, seed=1).thresholds()
    assert np.all(same == 0.2)


def test_photoreceptor_pole_makes_the_pixel_slow_in_the_dark() -> None:
    # Off by default. On, the first event of a 4x step comes later at low light.
    def first_event_us(params: PixelParams, level: float) -> int:
        t = np.concatenate([[-1e-6], np.arange(0.0, 0.05, 5e-6)])
        rate = np.full(len(t), 4 * level)
        rate[0] = level
        return int(Sensor(1, 1, params).run(rate[:, None, None], t)["t"][0])

    pole = IDEAL.replace(pr_pole=True)
    bright, dim = 1e12, 1e8
    assert first_event_us(IDEAL, bright) == first_event_us(IDEAL, dim)
    slow, fast = first_event_us(pole, dim), first_event_us(pole, bright)
    assert slow > fast + 50
    # At the step's end level the pixel's cutoff is f = f_ref I / I_ref; the first level is
    # crossed near -ln(1 - theta / ln 4) / (2 pi f) (the pole tracks the rising current,
    # so the real delay lies between the cutoffs at the start and end currents).
    i_end = 4 * dim * E * IDEAL.electrons_per_photon
    i_start = dim * E * IDEAL.electrons_per_photon
    base = -math.log(1 - 0.2 / math.log(4)) / (2 * math.pi * IDEAL.pr_cutoff_ref_hz / IDEAL.pr_ref_current_a)
    assert base / i_end * 1e6 - 2 <= slow <= base / i_start * 1e6 + 2


def test_a_bright_pixel_with_a_fast_pole_keeps_firing_after_long_samples() -> None:
    # The imx636-pointsource pixel (pole of 1 kHz at 1 pA, 2 kHz source follower, continuous
    # noise), bright, sampled at 20 Hz as its 12 s pre-roll is: once the pole outruns the
    # source follower by (a - b) T > 709 the noise's cross term was 0 x inf = NaN, and every
    # pixel the star's core had crossed in the pre-roll stayed silent all run. Here 2e8
    # photons/s puts (a - b) T well past it; the pixel, after 2 s of such samples, fires a 4x
    # step at 1 kHz like a fresh one: ON events floor(ln 4 / theta_on) or one more (its noise).
    from evstwin.scenario import build

    params = build("imx636-pointsource").params
    level = 2e8
    current_a = (level * params.electrons_per_photon + params.dark_rate_e_per_s) * E
    a = 2 * math.pi * params.pr_cutoff_ref_hz * current_a / params.pr_ref_current_a
    b = 2 * math.pi * params.cutoff_hz
    assert (a - b) * 0.05 > 1000  # far past exp's overflow at 709
    slow = np.arange(-2.0, 0.0 + 1e-9, 0.05)
    fast = np.arange(1, 101) * 1e-3
    t = np.concatenate([slow, fast])
    rate = np.where(t < 0.05, level, 4 * level)
    sensor = Sensor(1, 1, params, seed=3)
    ev, trace = sensor.run_probe(rate[:, None, None], t, [(0, 0)])
    assert np.all(np.isfinite(trace["filtered"])) and np.all(np.isfinite(trace["reference"]))
    after = ev[ev["t"] > 49_000]  # the light ramps linearly from the sample before the step, 49 ms
    on = int(np.sum(after["p"] == 1))
    assert math.floor(math.log(4) / params.theta_on) <= on <= math.floor(math.log(4) / params.theta_on) + 1
    assert np.sum(after["p"] == 0) <= 1


NOISY = PixelParams(threshold_sigma=0.05, leak_rate_hz=2.0, shot_noise_rate_hz=1.0, refractory_s=3e-4)


def moving_spot(n: int, w: int, h: int, dt: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) * dt
    yy, xx = np.mgrid[0:h, 0:w]
    xc = 3 + 200 * t
    rate = 1e7 + 5e9 * np.exp(-((xx[None] - xc[:, None, None]) ** 2 + (yy[None] - h / 2) ** 2) / 2.0)
    return rate, t


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_same_events_whatever_threads_and_chunks(dtype: type) -> None:
    rate, t = moving_spot(120, 37, 23)
    rate = rate.astype(dtype)
    ref = Sensor(37, 23, NOISY, seed=11, num_threads=1).run(rate, t)
    assert len(ref) > 200 and np.all(np.diff(ref["t"]) >= 0)
    two = Sensor(37, 23, NOISY, seed=11, num_threads=2).run(rate, t)
    assert ref.tobytes() == two.tobytes()
    chunked = Sensor(37, 23, NOISY, seed=11, num_threads=2)
    parts = [chunked.run(rate[a:b], t[a:b]) for a, b in [(0, 1), (1, 7), (7, 60), (60, 61), (61, 120)]]
    assert np.concatenate(parts).tobytes() == ref.tobytes()
    other_seed = Sensor(37, 23, NOISY, seed=12).run(rate, t)
    assert other_seed.tobytes() != ref.tobytes()


# The event-heavy regime (bench_engine.py --load event-heavy): a 200 Hz source follower lets the
# dark current's shot noise cross the thresholds on most samples of most pixels.
EVENT_HEAVY = PixelParams(threshold_sigma=0.03, cutoff_hz=200.0)


def is_time_then_pixel_ordered(events: np.ndarray, width: int) -> bool:
    """Whether events are sorted by (t, row-major pixel), ties allowed."""
    pixel = events["y"].astype(np.int64) * width + events["x"]
    t = events["t"]
    return bool(np.all((t[1:] > t[:-1]) | ((t[1:] == t[:-1]) & (pixel[1:] >= pixel[:-1]))))


def test_event_heavy_sort_is_the_same_on_any_thread_count_and_chunking() -> None:
    # Tens of thousands of events a call over ten blocks: each sample's events of all blocks
    # are counting-sorted by their own thread. A call of one sample is ordered by (t, pixel)
    # alone; the concatenated one-sample calls must equal one call, on 1 and 2 threads.
    w, h, n = 64, 40, 40
    rate = np.full((n, h, w), 2e6, dtype=np.float32)
    t = np.arange(n) * 1e-3
    one = Sensor(w, h, EVENT_HEAVY, seed=3, num_threads=1).run(rate, t)
    assert len(one) > 0.3 * w * h * (n - 1)  # event-heavy indeed
    two = Sensor(w, h, EVENT_HEAVY, seed=3, num_threads=2).run(rate, t)
    assert two.tobytes() == one.tobytes()
    stepped = Sensor(w, h, EVENT_HEAVY, seed=3, num_threads=2)
    parts = [stepped.run(rate[k : k + 1], t[k : k + 1]) for k in range(n)]
    assert all(is_time_then_pixel_ordered(part, w) for part in parts)
    assert np.concatenate(parts).tobytes() == one.tobytes()
    assert np.all(np.diff(one["t"]) >= 0)


def test_event_heavy_run_pixels_sort_in_any_pixel_order_and_thread_count() -> None:
    # run_pixels' list in a shuffled order: each sample's events are sorted by (t, pixel) with
    # a comparison sort, samples in parallel (64 x 40 pixels x 14 samples: above the engine's
    # PARALLEL_MIN_UPDATES, so two threads do share the work). Within one sample call that
    # order is exact.
    w, h, n = 64, 40, 14
    order = np.random.default_rng(5).permutation(w * h)
    rate = np.full((n, w * h), 2e6)
    t = 0.01 + np.arange(n) * 1e-3
    outs = []
    for threads in (1, 2):
        sensor = Sensor(w, h, EVENT_HEAVY, seed=8, num_threads=threads)
        sensor.run(np.full((1, h, w), 2e6), [0.0])
        outs.append(sensor.run_pixels(order, rate, t))
    assert len(outs[0]) > 0.3 * w * h * n
    assert outs[1].tobytes() == outs[0].tobytes()
    sensor = Sensor(w, h, EVENT_HEAVY, seed=8, num_threads=2)
    sensor.run(np.full((1, h, w), 2e6), [0.0])
    parts = [sensor.run_pixels(order, rate[k : k + 1], t[k : k + 1]) for k in range(n)]
    assert all(is_time_then_pixel_ordered(part, w) for part in parts)
    assert np.concatenate(parts).tobytes() == outs[0].tobytes()


def test_events_reach_numpy_without_a_copy() -> None:
    # The buffer the engine wrote the events into (Sensor::run_into) becomes the array's memory
    # (a capsule frees it with the array): NumPy does not own, and so did not copy, the data.
    rate, t = moving_spot(40, 16, 8)
    events = Sensor(16, 8, NOISY, seed=2).run(rate, t)
    assert len(events) > 0 and events.dtype == EVENT_DTYPE
    assert events.flags.owndata is False
    assert type(events.base).__name__ == "PyCapsule"


def test_reset_replays_the_same_events() -> None:
    rate, t = moving_spot(50, 20, 10)
    sensor = Sensor(20, 10, NOISY, seed=4)
    first = sensor.run(rate, t)
    with pytest.raises(ValueError, match="continue after"):
        sensor.run(rate, t)
    sensor.reset()
    assert sensor.samples_seen == 0
    assert sensor.run(rate, t).tobytes() == first.tobytes()


def test_output_owns_its_memory_and_input_is_not_modified() -> None:
    rate, t = moving_spot(30, 16, 8)
    before = rate.copy()
    sensor = Sensor(16, 8, NOISY)
    a = sensor.run(rate[:15], t[:15])
    b = sensor.run(rate[15:], t[15:])
    assert np.array_equal(rate, before)
    assert not np.shares_memory(a, b)
    assert not np.shares_memory(a, rate)
    a["t"] = 0  # writable and independent
    # A Fortran-ordered or strided input is accepted (copied) and gives the same events.
    f = np.asfortranarray(before)
    assert Sensor(16, 8, NOISY).run(f, t).tobytes() == Sensor(16, 8, NOISY).run(before, t).tobytes()


def test_gil_is_released_while_the_engine_runs() -> None:
    rate, t = moving_spot(400, 200, 100)
    ticks: list[float] = []
    stop = threading.Event()

    def tick() -> None:
        while not stop.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.0005)

    sensor = Sensor(200, 100, NOISY, num_threads=1)
    thread = threading.Thread(target=tick)
    thread.start()
    start = time.perf_counter()
    sensor.run(rate, t)
    end = time.perf_counter()
    stop.set()
    thread.join()
    # With the GIL held for the whole run the other thread could not tick in between.
    inside = [x for x in ticks if start + 0.2 * (end - start) < x < end - 0.2 * (end - start)]
    assert len(inside) >= 2


@pytest.mark.parametrize(
    "field,value,message",
    [
        ("theta_on", 0.0, r"theta_on must be in .*got theta_on=0"),
        ("theta_off", -0.1, r"theta_off=-0.1"),
        ("refractory_s", -1e-3, r"refractory_s=-0.001"),
        ("refractory_s", 5.0, r"refractory_s=5"),
        ("cutoff_hz", 0.0, r"cutoff_hz=0"),
        ("cutoff_hz", float("inf"), r"cutoff_hz=inf"),
        ("cutoff_hz", float("nan"), r"cutoff_hz=nan"),
        ("leak_rate_hz", -1.0, r"leak_rate_hz=-1"),
        ("threshold_sigma", 2.0, r"threshold_sigma=2"),
        ("dark_model", "thermal", r"dark_model must be one of 'poisson', 'paper', 'none'; got dark_model='thermal'"),
        ("lowpass", "rk4", r"lowpass must be one of 'exact', 'euler'; got lowpass='rk4'"),
    ],
)
def test_bad_params_raise_value_error_naming_them(field: str, value: object, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        IDEAL.replace(**{field: value})


def test_bad_param_types_and_names() -> None:
    with pytest.raises(TypeError, match="theta_on must be a number"):
        PixelParams(theta_on="0.2")  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="photon_shot_noise must be True or False"):
        PixelParams(photon_shot_noise=1)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="unknown PixelParams field"):
        IDEAL.replace(theta=0.3)


def test_bad_sensor_arguments() -> None:
    with pytest.raises(ValueError, match="width must be in .*got width=0"):
        Sensor(0, 5)
    with pytest.raises(ValueError, match="height=70000"):
        Sensor(5, 70000)
    with pytest.raises(ValueError, match="num_threads=0"):
        Sensor(5, 5, num_threads=0)
    with pytest.raises(ValueError, match="seed=-1"):
        Sensor(5, 5, seed=-1)
    with pytest.raises(TypeError, match="width must be an integer"):
        Sensor(5.5, 5)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="params must be an evstwin.PixelParams"):
        Sensor(5, 5, {"theta_on": 0.2})  # type: ignore[arg-type]


def test_bad_inputs_raise_and_leave_the_sensor_untouched() -> None:
    sensor = Sensor(4, 3, IDEAL)
    good = np.full((3, 3, 4), 1e9)
    t = [0.0, 1e-3, 2e-3]
    cases = [
        (np.full((3, 4, 3), 1e9), t, ValueError, r"shape \(T, height, width\) = \(T, 3, 4\); got shape \(3, 4, 3\)"),
        (np.full((3, 12), 1e9), t, ValueError, r"got shape \(3, 12\)"),
        (good.astype(np.int64), t, TypeError, "float32 or float64.*int64"),
        (good, [0.0, 1e-3], ValueError, r"t_s must be 1-D with one time per sample.*\(3\)"),
        (good, [0.0, 1e-3, 1e-3], ValueError, r"strictly increasing; got t_s\[1\]=0.001 and t_s\[2\]=0.001"),
        (good, [0.0, float("nan"), 1.0], ValueError, r"t_s must be finite; got t_s\[1\]=nan"),
        (good, ["a", "b", "c"], TypeError, "t_s must be an array of real times"),
    ]
    for rate, times, exc, message in cases:
        with pytest.raises(exc, match=message):
            sensor.run(rate, times)
    for value, message in [(-1.0, "-1"), (np.nan, "nan"), (np.inf, "inf"), (1e21, "1e\\+21")]:
        bad = good.copy()
        bad[2, 1, 3] = value
        with pytest.raises(ValueError, match=rf"finite, >= 0 and <= 1e20 photons/s; got photon_rate\[2, 1, 3\]={message}"):
            sensor.run(bad, t)
    for tiny in (0.0, 1e-321):
        zero = good.copy()
        zero[1, 0, 0] = tiny
        with pytest.raises(ValueError, match=r"needs a positive current; got photon_rate\[1, 0, 0\]="):
            sensor.run(zero, t)
    assert sensor.samples_seen == 0
    # Zero light is fine where there is dark current.
    assert len(Sensor(4, 3, IDEAL.replace(dark_model="poisson", noise_model="sampled")).run(zero, t)) >= 0
    assert len(sensor.run(good, t)) == 0 and sensor.samples_seen == 3
    with pytest.raises(ValueError, match=r"continue after the previous run's last sample \(0.002 s\); got t_s\[0\]=0.002"):
        sensor.run(good[:1], [2e-3])
    with pytest.raises(ValueError, match="pixels must lie on the 4x3 sensor"):
        sensor.run_probe(good[:1], [1.0], [(4, 0)])
    with pytest.raises(ValueError, match=r"shot_noise_rate_hz \* dt must be <= 0.5"):
        Sensor(1, 1, IDEAL.replace(shot_noise_rate_hz=10.0, noise_model="sampled")).run(np.ones((2, 1, 1)), [0.0, 0.1])
    with pytest.raises(ValueError, match=r"shot_noise_factor=4"):  # F > 1: the top rate is F R_n
        Sensor(1, 1, IDEAL.replace(shot_noise_rate_hz=2.0, shot_noise_factor=4.0, noise_model="sampled")).run(np.ones((2, 1, 1)), [0.0, 0.1])
    with pytest.raises(ValueError, match=r"sample intervals must be >= 1e-12 s; got dt=1e-13"):
        Sensor(1, 1, IDEAL).run(np.ones((2, 1, 1)), [0.0, 1e-13])
    with pytest.raises(ValueError, match=r"within \+-9.2e12 s"):
        Sensor(1, 1, IDEAL).run(np.ones((1, 1, 1)), [-1e13])


def test_sub_sampled_pixels_match_the_dense_fine_run_without_noise() -> None:
    # A spot crossing row 5 fast: sampling the whole array at 10 kHz, or only rows 3-7 at
    # 10 kHz and the rest at 1 kHz, gives the same events (the rest see no change but leak).
    w, h = 40, 11
    params = IDEAL.replace(leak_rate_hz=20.0, cutoff_hz=200.0, refractory_s=1e-4)
    t_fine = np.arange(0, 201) * 1e-4
    rate_fine, _ = moving_spot(1, w, h)  # shape only
    yy, xx = np.mgrid[0:h, 0:w]
    xc = 2 + 1500 * t_fine
    rate_fine = 1e7 + 5e9 * np.exp(-((xx[None] - xc[:, None, None]) ** 2 + (yy[None] - 5) ** 2) / 1.0)
    rate_fine[:, :3] = rate_fine[:, 8:] = 1e7  # rows far from the track see no change at all
    dense = Sensor(w, h, params).run(rate_fine, t_fine)

    sparse = Sensor(w, h, params)
    hot = np.flatnonzero((yy >= 3) & (yy <= 7))
    events = [sparse.run(rate_fine[:1], t_fine[:1])]
    for a in range(0, 200, 10):  # chunks of 1 ms: fine samples for the hot rows, then the rest
        fine = slice(a + 1, a + 11)
        events.append(sparse.run_pixels(hot, rate_fine[fine].reshape(10, -1)[:, hot], t_fine[fine]))
        events.append(sparse.run(rate_fine[a + 10 : a + 11], t_fine[a + 10 : a + 11]))
    merged = np.concatenate(events)
    merged = merged[np.lexsort((merged["y"].astype(np.int64) * w + merged["x"], merged["t"]))]
    assert len(dense) > 100
    assert merged.tobytes() == dense.tobytes()


def test_sub_sampled_pixels_are_the_fine_run_and_the_rest_the_coarse_run_even_with_noise() -> None:
    # Each pixel's random numbers follow its own sample counter, so with every noise source
    # on, the sub-sampled pixels give exactly the events of a run sampled finely everywhere,
    # and the others exactly those of the coarse run.
    params = PixelParams(shot_noise_rate_hz=20.0, leak_rate_hz=3.0, threshold_sigma=0.05)
    w, h, n = 30, 20, 200
    t = np.arange(n + 1) * 1e-3
    t_fine = np.arange(4 * n + 1) * 0.25e-3
    rate_fine, _ = moving_spot(len(t_fine), w, h, dt=0.25e-3)
    rate = rate_fine[::4]
    coarse = Sensor(w, h, params, seed=2).run(rate, t)
    fine = Sensor(w, h, params, seed=2).run(rate_fine, t_fine)
    hot = np.arange(0, w * h, 3)
    sparse = Sensor(w, h, params, seed=2)
    parts = [sparse.run(rate[:1], t[:1])]
    for a in range(0, n, 50):
        sl = slice(4 * a + 1, 4 * (a + 50) + 1)
        parts.append(sparse.run_pixels(hot, rate_fine[sl].reshape(-1, w * h)[:, hot], t_fine[sl]))
        parts.append(sparse.run(rate[a + 1 : a + 51], t[a + 1 : a + 51]))
    got = np.concatenate(parts)

    def pick(ev: np.ndarray, is_hot: bool) -> np.ndarray:
        sel = np.isin(ev["y"].astype(np.int64) * w + ev["x"], hot) == is_hot
        out = ev[sel]
        return out[np.lexsort((out["y"].astype(np.int64) * w + out["x"], out["t"]))]

    assert len(pick(fine, True)) > 100
    assert pick(got, True).tobytes() == pick(fine, True).tobytes()
    assert pick(got, False).tobytes() == pick(coarse, False).tobytes()


def test_run_pixels_bad_input() -> None:
    sensor = Sensor(4, 3, IDEAL)
    sensor.run(np.full((1, 3, 4), 1e9), [0.0])
    ok = np.full((2, 2), 1e9)
    with pytest.raises(ValueError, match="must not repeat; got pixel 1 twice"):
        sensor.run_pixels([1, 1], ok, [1e-3, 2e-3])
    with pytest.raises(ValueError, match=r"pixels\[1\]=12 is outside the 12-pixel sensor"):
        sensor.run_pixels([1, 12], ok, [1e-3, 2e-3])
    with pytest.raises(ValueError, match=r"start after the last sample of every listed pixel"):
        sensor.run_pixels([1, 2], ok, [0.0, 2e-3])
    with pytest.raises(ValueError, match=r"shape \(T, len\(pixels\)\) = \(T, 2\); got shape \(2, 3\)"):
        sensor.run_pixels([1, 2], np.full((2, 3), 1e9), [1e-3, 2e-3])
    with pytest.raises(TypeError, match="pixels must be an integer array"):
        sensor.run_pixels([1.0, 2.0], ok, [1e-3, 2e-3])


@pytest.mark.parametrize(
    "params",
    [
        NOISY,
        NOISY.replace(pr_pole=True),
        NOISY.replace(photon_shot_noise=False, dark_model="none", pr_pole=True),
        NOISY.replace(cutoff_hz=None, noise_model="sampled"),
        NOISY.replace(lowpass="euler", cutoff_hz=20.0),
        NOISY.replace(dark_model="paper", noise_model="sampled"),
    ],
    ids=["default", "pr_pole", "noise-free pr_pole", "no filter", "euler", "paper dark"],
)
def test_block_kernel_and_per_pixel_path_give_the_same_events(params: PixelParams) -> None:
    # run_probe takes the per-pixel path (step()); run takes the block kernel where it applies.
    rate, t = moving_spot(80, 37, 23)
    fast = Sensor(37, 23, params, seed=9).run(rate, t)
    slow, _ = Sensor(37, 23, params, seed=9).run_probe(rate, t, [(0, 0)])
    assert len(fast) > 100
    assert fast.tobytes() == slow.tobytes()


def test_a_broadcast_static_frame_is_read_as_one_frame() -> None:
    frame = np.random.default_rng(3).uniform(1e6, 1e9, size=(23, 37))
    t = np.arange(40) * 1e-3
    view = np.broadcast_to(frame, (40, 23, 37))
    copy = np.ascontiguousarray(view)
    assert Sensor(37, 23, NOISY, seed=2).run(view, t).tobytes() == Sensor(37, 23, NOISY, seed=2).run(copy, t).tobytes()
    bad = frame.copy()
    bad[4, 5] = -1.0
    with pytest.raises(ValueError, match=r"photon_rate\[0, 4, 5\]=-1"):
        Sensor(37, 23, NOISY).run(np.broadcast_to(bad, (3, 23, 37)), t[:3])


def test_levels_closer_than_the_time_resolution_fire_once_instead_of_looping() -> None:
    # No refractory period, a 1000x step over 1 ps at t = 1000 s (where t resolves ~1e-13 s):
    # the crossings cannot be told apart in time; the engine must finish, not hang.
    ev = Sensor(1, 1, IDEAL).run(np.array([[[1e6]], [[1e9]]]), [1000.0, 1000.0 + 1e-12])
    assert 1 <= len(ev) <= math.floor(math.log(1e3) / IDEAL.theta_on)
    assert np.all(ev["p"] == 1)


def test_chunk_boundaries_inside_a_microsecond_keep_the_order_of_one_run() -> None:
    # Many pixels fire within the microsecond around each sample time; concatenated chunks
    # must equal the single run byte for byte, also in the order within that microsecond.
    w, h, n = 200, 100, 60
    rng = np.random.default_rng(7)
    t = np.arange(n) * 1e-3
    rate = np.exp(rng.normal(20.0, 1.0, size=(n, h, w)))
    one = Sensor(w, h, IDEAL, seed=1).run(rate, t)
    for size in (1, 7):
        chunked = Sensor(w, h, IDEAL, seed=1)
        parts = [chunked.run(rate[a : a + size], t[a : a + size]) for a in range(0, n, size)]
        assert np.concatenate(parts).tobytes() == one.tobytes()


@pytest.mark.parametrize("dt", [1e-3, 0.5])
def test_events_come_out_by_time_then_pixel(dt: float) -> None:
    # The output order (by microsecond, then pixel) made by the counting sort over the blocks
    # (1 ms samples) and by the stable sort that takes over where a sample spans far more
    # microseconds than it has events (0.5 s samples): hot pixels fire at random times, in
    # every block, several pixels within one microsecond at 0.5 s. Time never decreases;
    # within a microsecond the pixel index does not either, except in the microsecond of a
    # sample time, where the earlier interval's events come first (as chunked calls give).
    w, h = 40, 30
    params = PixelParams(hot_pixel_fraction=0.3, hot_pixel_rate_hz=400.0, refractory_s=1e-4)
    t = np.arange(1, 7) * dt
    ev = Sensor(w, h, params, seed=3).run(np.full((len(t), h, w), 1e6), t)
    assert len(ev) > 500
    step_t = np.diff(ev["t"].astype(np.int64))
    step_pixel = np.diff(ev["y"].astype(np.int64) * w + ev["x"])
    at_sample_time = np.isin(ev["t"][1:], np.round(t * 1e6).astype(np.int64))
    assert np.all(step_t >= 0)
    assert np.all((step_t > 0) | (step_pixel >= 0) | at_sample_time)
    assert ((step_t == 0) & ~at_sample_time).sum() >= 5  # ties inside intervals: the pixel order was tested


# -- hardening (issue 11) ------------------------------------------------------------------------


@pytest.mark.parametrize("n", [1025, 5000, 100_000, 2**31 - 1, 2**31, 2**64, 0, -1])
def test_thread_counts_beyond_the_bound_are_refused_not_crashed(n: int) -> None:
    with pytest.raises(ValueError, match=r"num_threads must be in \[1, 1024\].*num_threads=" + str(n)):
        Sensor(8, 8, PixelParams(), num_threads=n)
    assert Sensor(8, 8, PixelParams(), num_threads=1024).num_threads == evstwin.sensor.MAX_THREADS == 1024


def test_non_native_and_unaligned_rates_give_the_native_events() -> None:
    t = np.arange(1, 51) * 1e-3
    r = np.random.default_rng(0).uniform(1e6, 1e9, (50, 8, 8))
    native = Sensor(8, 8, PixelParams(), seed=1).run(r, t)
    assert len(native) > 100
    assert np.array_equal(Sensor(8, 8, PixelParams(), seed=1).run(r.astype(">f8"), t), native)
    assert np.array_equal(Sensor(8, 8, PixelParams(), seed=1).run(r.astype(">f4"), t),
                          Sensor(8, 8, PixelParams(), seed=1).run(r.astype("<f4"), t))
    unaligned = np.zeros(r.nbytes + 1, np.uint8)[1:].view(np.float64).reshape(r.shape)
    unaligned[:] = r
    assert not unaligned.flags.aligned
    assert np.array_equal(Sensor(8, 8, PixelParams(), seed=1).run(unaligned, t), native)
    static = np.broadcast_to(r[0], r.shape)
    assert np.array_equal(Sensor(8, 8, PixelParams(), seed=1).run(np.broadcast_to(r[0].astype(">f8"), r.shape), t),
                          Sensor(8, 8, PixelParams(), seed=1).run(static, t))
    px = np.array([3, 9])
    rates = r.reshape(50, 64)[:, px]
    assert np.array_equal(Sensor(8, 8, PixelParams(), seed=1).run_pixels(px, rates.astype(">f8"), t),
                          Sensor(8, 8, PixelParams(), seed=1).run_pixels(px, rates, t))
    # Times and pixel indices too: big-endian or unaligned, they are read as their values
    # (the bindings ask NumPy for an aligned native copy; a misaligned load is undefined).
    t_odd = np.zeros(t.nbytes + 1, np.uint8)[1:].view(np.float64)
    t_odd[:] = t
    px_odd = np.zeros(px.nbytes + 1, np.uint8)[1:].view(np.int64)
    px_odd[:] = px
    assert not t_odd.flags.aligned and not px_odd.flags.aligned
    assert np.array_equal(Sensor(8, 8, PixelParams(), seed=1).run(r, t_odd), native)
    assert np.array_equal(Sensor(8, 8, PixelParams(), seed=1).run(r, t.astype(">f8")), native)
    assert np.array_equal(Sensor(8, 8, PixelParams(), seed=1).run_pixels(px_odd, rates, t_odd),
                          Sensor(8, 8, PixelParams(), seed=1).run_pixels(px.astype(">i8"), rates, t))


def test_float32_rates_meet_the_same_limit_as_float64() -> None:
    t = np.array([1e-3, 2e-3])
    top = np.float32(1e20)  # rounds up to 1.00000002e20, above the limit
    for dtype in (np.float32, np.float64):
        with pytest.raises(ValueError, match="<= 1e20 photons/s"):
            Sensor(4, 4, PixelParams()).run(np.full((2, 4, 4), top, dtype), t)
    Sensor(4, 4, PixelParams()).run(np.full((2, 4, 4), np.nextafter(top, np.float32(0))), t)  # the largest below


def test_run_pixels_refuses_times_beyond_int64_microseconds() -> None:
    with pytest.raises(ValueError, match=r"t_s must lie within \+-9.2e12 s"):
        Sensor(4, 4, PixelParams()).run_pixels(np.array([0]), np.full((1, 1), 1e6), np.array([1e13]))


def test_an_event_flood_stops_at_max_events_before_memory_runs_out() -> None:
    # Issue 11's flood: theta 1e-3, no refractory, rates alternating 1e-30 / 1e20 on 64 x 64
    # pixels make ~4.7e8 events from 4 samples; the guard stops the call while producing them.
    p = PixelParams(theta_on=1e-3, theta_off=1e-3, refractory_s=0.0, dark_model="none", photon_shot_noise=False,
                    shot_noise_rate_hz=0.0, leak_rate_hz=0.0, cutoff_hz=None)
    rates = np.empty((4, 64, 64))
    rates[0::2], rates[1::2] = 1e-30, 1e20
    t4 = np.arange(1, 5) * 1e-3
    for threads in (1, 2):
        sensor = Sensor(64, 64, p, num_threads=threads, max_events=200_000)
        with pytest.raises(ValueError, match=r"more than max_events=200000 events \(about 30 bytes each.*use shorter "
                                             r"chunks, or raise max_events"):
            sensor.run(rates, t4)
        # Its pixels are half advanced: refused until reset, then as new.
        with pytest.raises(RuntimeError, match=r"stopped part-way.*reset\(\)"):
            sensor.run(rates[:1], [1.0])
        sensor.reset()
        assert len(sensor.run(rates[:1], [1.0])) == 0
    # The default, its bounds, and a cap for one call only.
    assert Sensor(4, 4, PixelParams()).max_events == evstwin.sensor.DEFAULT_MAX_EVENTS == 100_000_000
    for bad in (0, -1, 2**32, 2**70):
        with pytest.raises(ValueError, match=rf"max_events must be in \[1, 4294967295\]; got max_events={bad}"):
            Sensor(4, 4, PixelParams(), max_events=bad)
    with pytest.raises(TypeError, match="max_events must be an integer; got max_events=1.5"):
        Sensor(4, 4, PixelParams(), max_events=1.5)  # type: ignore[arg-type]
    sensor = Sensor(64, 64, p, num_threads=2)
    with pytest.raises(ValueError, match="max_events=1000 events"):
        sensor.run_pixels(np.arange(64), rates.reshape(4, -1)[:, :64], t4, max_events=1000)
    assert sensor.max_events == 100_000_000  # restored after the call
    # Below the cap nothing changes: the same events with and without a (generous) guard.
    coarse = p.replace(theta_on=0.05, theta_off=0.05)
    few = np.full((3, 64, 64), 1e8)
    few[1] = 3e8  # ln 3 / 0.05: 21 events a pixel each way, 180 k in all
    t = np.arange(1, 4) * 1e-3
    guarded = Sensor(64, 64, coarse, max_events=200_000).run(few, t)
    assert 150_000 < len(guarded) < 200_000
    assert np.array_equal(guarded, Sensor(64, 64, coarse).run(few, t))
    assert np.array_equal(guarded, Sensor(64, 64, coarse, num_threads=2).run(few, t, max_events=len(guarded)))
    with pytest.raises(ValueError, match=f"max_events={len(guarded) - 1} "):
        Sensor(64, 64, coarse, num_threads=2).run(few, t, max_events=len(guarded) - 1)


def test_sizes_and_arguments_out_of_range_are_value_errors() -> None:
    # Issue 9: a 30000 x 30000 sensor ended in MemoryError after minutes; huge integers were
    # pybind11's multi-line "incompatible function arguments" TypeError.
    # 176 bytes of state a pixel (sizeof(PixelState)); the figure is the engine's own: its C++
    # check, reached directly, names the same size (rounded to whole gigabytes).
    assert evstwin.sensor.STATE_BYTES_PER_PIXEL == 176
    with pytest.raises(ValueError, match=r"width \* height must be at most 67108864 pixels.*width=30000, "
                                         r"height=30000: 900000000 pixels, 158 GB"):
        Sensor(30000, 30000)
    with pytest.raises(ValueError, match=r"height=30000: 900000000 pixels, 158 GB of pixel state"):
        evstwin._core.Sensor(30000, 30000, PixelParams().to_core(), 0, 1)
    for name, value in (("width", 2**40), ("height", 0), ("width", 65536)):
        with pytest.raises(ValueError, match=rf"{name} must be in \[1, 65535\]; got {name}={value}"):
            Sensor(**{"width": 4, "height": 4, name: value})  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="width must be an integer; got width=True"):
        Sensor(True, 4)  # type: ignore[arg-type]
    sensor = Sensor(4, 4)
    rate = np.full((1, 4, 4), 1e6)
    with pytest.raises(ValueError, match="probe pixels must not repeat; got pixel 1 twice"):
        sensor.run_probe(rate, [1.0], [(1, 0), (1, 0)])
    with pytest.raises(TypeError, match=r"pixels must be \(x, y\) pairs of integers; got pixels\[0\]=\(1.5, 0\)"):
        sensor.run_probe(rate, [1.0], [(1.5, 0)])  # type: ignore[list-item]
    assert sensor.samples_seen == 0


@pytest.mark.parametrize("threads", [1, 2])
def test_rate_check_in_parts_names_the_first_bad_rate_and_moves_nothing(threads: int) -> None:
    # The rates are checked in parts of 65,536 values spread over the call's threads (the
    # engine's RateCheck): 256 x 256 pixels and 5 samples make 5 parts and a call worth a
    # parallel region. Whichever part a thread checks first, the message names the first bad
    # value in C order, and no pixel moves.
    w = h = 256
    t = [0.0, 1e-3, 2e-3, 3e-3, 4e-3]
    good = np.full((5, h, w), 1e9)
    sensor = Sensor(w, h, NOISY, seed=4, num_threads=threads)
    bad = good.copy()
    bad[4, 0, 0] = np.nan         # part 4
    bad[3, 10, 7] = -2.0          # part 3: the first
    with pytest.raises(ValueError, match=r"got photon_rate\[3, 10, 7\]=-2"):
        sensor.run(bad, t)
    bad[1, 255, 255] = np.inf     # the last value of part 1: now the first
    with pytest.raises(ValueError, match=r"got photon_rate\[1, 255, 255\]=inf"):
        sensor.run(bad, t)
    assert sensor.samples_seen == 0
    events = sensor.run(good, t)
    assert events.tobytes() == Sensor(w, h, NOISY, seed=4, num_threads=threads).run(good, t).tobytes()

    # run_pixels: 40,000 listed pixels (in no order: 3 is odd, so 3 j mod 2^16 never repeats)
    # x 5 samples, 4 parts (the last one short).
    pixels = np.arange(40_000) * 3 % (w * h)
    fine_t = [5e-3, 6e-3, 7e-3, 8e-3, 9e-3]
    fine = np.full((5, pixels.size), 2e9)
    fine_bad = fine.copy()
    fine_bad[4, 39_999] = 1e21    # part 3, the last value of all
    fine_bad[2, 30_000] = np.nan  # part 2: the first
    with pytest.raises(ValueError, match=r"got photon_rate\[2, 30000\]=nan"):
        sensor.run_pixels(pixels, fine_bad, fine_t)
    again = Sensor(w, h, NOISY, seed=4, num_threads=threads)
    again.run(good, t)
    assert sensor.run_pixels(pixels, fine, fine_t).tobytes() == again.run_pixels(pixels, fine, fine_t).tobytes()


@pytest.mark.parametrize("threads", [1, 2])
def test_run_pixels_bad_rate_beats_a_flood_in_another_block(threads: int) -> None:
    # run_pixels checks each block's rates as the block starts, and the pixels' new states wait
    # until every block has passed. A first block whose events pass max_events before a later
    # block finds a bad rate: the bad rate is still the error, and no pixel has moved (the
    # sensor is usable, and gives what a fresh one gives).
    w, h = 32, 32
    t0 = [0.0]
    dark = np.full((1, h, w), 1e6)
    pixels = np.arange(w * h)  # 4 blocks of 256
    fine_t = [1e-3, 2e-3, 3e-3, 4e-3]
    fine = np.full((4, pixels.size), 1e6)
    fine[1::2, :256] = 1e10  # the first block flashes: thousands of events
    flood_bad = fine.copy()
    flood_bad[3, 1000] = np.nan
    sensor = Sensor(w, h, IDEAL, seed=2, num_threads=threads)
    sensor.run(dark, t0)
    with pytest.raises(ValueError, match=r"max_events=10 "):
        Sensor(w, h, IDEAL, seed=2, num_threads=threads).run_pixels(pixels, fine, fine_t, max_events=10)
    with pytest.raises(ValueError, match=r"got photon_rate\[3, 1000\]=nan"):
        sensor.run_pixels(pixels, flood_bad, fine_t, max_events=10)
    fresh = Sensor(w, h, IDEAL, seed=2, num_threads=threads)
    fresh.run(dark, t0)
    expected = fresh.run_pixels(pixels, fine, fine_t)
    assert len(expected) > 1000
    assert sensor.run_pixels(pixels, fine, fine_t).tobytes() == expected.tobytes()
