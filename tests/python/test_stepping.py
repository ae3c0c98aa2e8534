"""Time steps per pixel: a pixel whose light is constant may take long steps with the
statistics of short ones (issue 33), and the run that gives it long steps keeps the engine's
guarantees (the same events whatever the threads and chunking).

The expectations are independent of the step: the same pixel advanced finely (1 kHz, where
the dense engine has converged: the documentation's noise model page) and coarsely must give
the same counts within their seed-to-seed noise."""

from __future__ import annotations

import math

import numpy as np
import pytest

from evstwin import PixelParams, Sensor, simulate
from evstwin.presets import get_preset
from evstwin.simulate import resolve_scenario


def dark_counts(rate_hz: float, seed: int, side: int = 32, duration_s: float = 2.0) -> tuple[int, int, np.ndarray]:
    """ON, OFF and per-pixel counts of the DAVIS346 preset's pixel (the source follower alone,
    10 Hz: its dark shot noise crosses the thresholds ~2 times a second) in the dark, sampled
    at rate_hz from a first sample at t = 0 (which only sets the steady state)."""
    sensor = Sensor(side, side, get_preset("davis346").pixel_params(), seed=seed, num_threads=1)
    t = np.arange(0, round(duration_s * rate_hz) + 1) / rate_hz
    ev = sensor.run(np.broadcast_to(np.zeros((1, side, side)), (t.size, side, side)), t)
    on = int(np.count_nonzero(ev["p"]))
    per_pixel = np.bincount(ev["y"].astype(np.int64) * side + ev["x"], minlength=side * side)
    return on, len(ev) - on, per_pixel


@pytest.mark.parametrize("coarse_hz", [25.0, 5.0])
def test_a_static_pixel_has_the_same_statistics_at_long_steps(coarse_hz: float) -> None:
    # 25 Hz is 2.5 source-follower time constants a step, 5 Hz 12.6: before the engine refined
    # such intervals, 50 Hz gave +24 % ON and +20 % OFF against 1 kHz (3 seeds of 64 x 64 px).
    fine = [dark_counts(1000.0, s) for s in (1, 2)]
    coarse = [dark_counts(coarse_hz, s) for s in (1, 2)]
    for i, name in ((0, "ON"), (1, "OFF")):
        a, b = sum(r[i] for r in fine), sum(r[i] for r in coarse)
        # Counts of neighbouring intervals are correlated (refractory, the reference's reset):
        # twice the Poisson spread of the difference, four standard deviations of it.
        tolerance = 4 * 2 * math.sqrt(a + b)
        assert abs(a - b) < tolerance, f"{name}: {a} at 1 kHz, {b} at {coarse_hz:g} Hz (tolerance {tolerance:.0f})"
    share_fine = np.mean([np.bincount(np.minimum(r[2], 4), minlength=5) / r[2].size for r in fine], axis=0)
    share_coarse = np.mean([np.bincount(np.minimum(r[2], 4), minlength=5) / r[2].size for r in coarse], axis=0)
    np.testing.assert_allclose(share_coarse, share_fine, atol=0.03)


# geo-stare's IMX636 pixel under its DAVIS346 bias set: the photoreceptor pole at the dark
# current's ~18 /s, slower than the 10 Hz follower, and the noise's standard deviation on the
# level ~1/4.7 of the OFF threshold, so the noise crosses (~0.07 events a pixel in 16 s) and
# a crossing stays plausible over pieces of a long step down to ~1/a (refine_and_compare
# halves only those).
GEO_PIXEL = PixelParams(theta_on=0.206, theta_off=0.093, refractory_s=1e-3, cutoff_hz=10.0, leak_rate_hz=0.0,
                        shot_noise_rate_hz=0.0, shot_noise_factor=1.0, fill_factor=1.0, absorption_per_m=2e5,
                        depletion_width_m=5e-6, pr_pole=True)


def geo_counts(rate_hz: float, seed: int, side: int = 128, duration_s: float = 16.0) -> np.ndarray:
    """Per-pixel OFF counts of GEO_PIXEL at a dark sky's 28 photons/s, sampled at rate_hz from
    a first sample at t = 0 (its ON threshold, 2.2 times the OFF one, is out of the noise's
    reach)."""
    sensor = Sensor(side, side, GEO_PIXEL, seed=seed, num_threads=2)
    t = np.arange(0, round(duration_s * rate_hz) + 1) / rate_hz
    ev = sensor.run(np.broadcast_to(np.full((1, side, side), 28.0), (t.size, side, side)), t)
    off = ev[ev["p"] == 0]
    return np.bincount(off["y"].astype(np.int64) * side + off["x"], minlength=side * side)


def test_long_steps_behind_a_slow_pole_keep_the_statistics_of_fine_ones() -> None:
    # One 4 s step (a dt = 72, cut adaptively) and 4 Hz against the scene's 100 Hz (a dt =
    # 0.18; 400 Hz gives the same counts: 6,568 against 6,552 on 256 x 256 px): the OFF
    # counts over three seeds within four standard errors of their difference (from the
    # per-pixel counts' own spread; pixels are independent), and the share of pixels with 0,
    # 1, 2+ events. Refinement stopped at pieces of 1 s counts +17 % at one 4 s step.
    fine = np.concatenate([geo_counts(100.0, s) for s in (1, 2, 3)])
    assert fine.sum() > 2500  # the noise does cross: the test has something to compare
    for coarse_hz in (4.0, 0.25):
        coarse = np.concatenate([geo_counts(coarse_hz, s) for s in (1, 2, 3)])
        se = math.sqrt(fine.size * (fine.var() + coarse.var()))
        assert abs(int(coarse.sum()) - int(fine.sum())) < 4 * se, (
            f"OFF: {fine.sum()} at 100 Hz, {coarse.sum()} at {coarse_hz:g} Hz (standard error {se:.0f})")
        share = [np.bincount(np.minimum(c, 2), minlength=3) / c.size for c in (fine, coarse)]
        np.testing.assert_allclose(share[1], share[0], atol=0.01)


SCENE = ["sensor.roi=[100,60,120,100]"]


def test_long_steps_give_the_statistics_of_the_base_rate() -> None:
    # mcreynolds (five LEDs turning on the DAVIS346 with the paper's pole) with 0.2 s static
    # steps against every pixel at the base rate: totals, ON share and the per-pixel
    # count histogram within the seeds' noise.
    runs = {}
    for step in ("0.2", "0"):
        runs[step] = [simulate(resolve_scenario("mcreynolds", [*SCENE, f"sampling.static_step_s={step}"]),
                               duration_s=0.6, seed=s, num_threads=2) for s in (11, 12)]
    stepped, dense = runs["0.2"], runs["0"]
    n_s, n_d = sum(r.n_events for r in stepped), sum(r.n_events for r in dense)
    assert n_d > 2000
    assert abs(n_s - n_d) < 4 * 2 * math.sqrt(n_s + n_d), (n_s, n_d)
    on_s, on_d = sum(r.n_on for r in stepped) / n_s, sum(r.n_on for r in dense) / n_d
    assert abs(on_s - on_d) < 0.02
    # Fewer pixel updates: the pixels the bar's LEDs leave alone step once per 0.2 s, not at 250 Hz.
    assert sum(r.pixel_updates for r in stepped) < sum(r.pixel_updates for r in dense)

    def histogram(r: object) -> np.ndarray:
        ev = r.events  # type: ignore[attr-defined]
        counts = np.bincount(ev["y"].astype(np.int64) * 120 + ev["x"], minlength=120 * 100)
        return np.bincount(np.minimum(counts, 20), minlength=21) / counts.size

    np.testing.assert_allclose(np.mean([histogram(r) for r in stepped], axis=0),
                               np.mean([histogram(r) for r in dense], axis=0), atol=0.02)


def test_long_steps_are_the_same_whatever_the_threads_and_chunks() -> None:
    base = simulate(resolve_scenario("mcreynolds", [*SCENE, "sampling.static_step_s=0.2"]), duration_s=0.3, seed=3,
                    num_threads=1)
    assert base.n_events > 0
    for threads, chunk in ((2, 50), (1, 7), (2, 3)):
        other = simulate(resolve_scenario("mcreynolds", [*SCENE, "sampling.static_step_s=0.2",
                                                         f"sampling.chunk_samples={chunk}"]),
                         duration_s=0.3, seed=3, num_threads=threads)
        assert other.events.tobytes() == base.events.tobytes(), (threads, chunk)


def test_static_step_is_checked() -> None:
    from evstwin.scenario import ScenarioError

    with pytest.raises(ScenarioError, match=r"sampling.static_step_s .*-1"):
        simulate(resolve_scenario("mcreynolds", [*SCENE, "sampling.static_step_s=-1"]), duration_s=0.01)


def test_shot_noise_events_inside_long_steps_keep_the_crossings_that_follow_them() -> None:
    # mcreynolds' pixel in the dark (the paper's photodiode, the photoreceptor pole at the
    # 18,000 e-/s dark current, shot noise 0.05 Hz, the leak off): its OFF events are the shot
    # noise's background events and ~0.006 Hz of noise crossings, many of which follow a
    # background event (it resets the reference to the level there). Advanced in long steps
    # (0.1 s) against every pixel at 250 Hz, 192 x 192 px, 10 s, seeds 1-10: when a background
    # event inside a long interval reset the reference to the interval's straight line, not to
    # the noise's path there, the crossings after it went missing: OFF -2.0 % (-12 standard
    # errors over 20 seeds; bench/stepping_statistics.py --set pixel.leak_rate_hz=0 --step 0.1).
    import dataclasses

    from evstwin.scenario import build

    params = dataclasses.replace(build(resolve_scenario("mcreynolds", [])).params, leak_rate_hz=0.0)
    side, rate_hz, per = 192, 250.0, 25
    dark = np.zeros((side, side))
    totals = {"dense": [0, 0], "stepped": [0, 0]}
    for seed in range(1, 11):
        for label in totals:
            sensor = Sensor(side, side, params, seed=seed, num_threads=2)
            parts = [sensor.run(dark[None], np.array([0.0]))]
            for j in range(1, 2501, per):
                t = np.arange(j, j + per) / rate_hz
                if label == "stepped":
                    parts.append(sensor.run_sparse(dark, t, base_every=1, group_base_samples=per))
                else:
                    parts.append(sensor.run(np.broadcast_to(dark, (per, side, side)).copy(), t))
            ev = np.concatenate(parts)
            on = int(np.count_nonzero(ev["p"] == 1))
            totals[label][0] += on
            totals[label][1] += len(ev) - on
    for i, name in ((0, "ON"), (1, "OFF")):
        a, b = totals["dense"][i], totals["stepped"][i]
        assert a > 150_000, (name, a)
        tolerance = 4 * math.sqrt(a + b)  # the counts' spread over seeds is about Poisson's
        assert abs(a - b) < tolerance, f"{name}: {a} at 250 Hz, {b} in 0.1 s steps (tolerance {tolerance:.0f})"


@pytest.mark.parametrize("rate_hz", [1000.0, 2.0])
def test_background_clocks_keep_every_event_at_long_steps(rate_hz: float) -> None:
    # Eq. 12's background alone (no shot noise, no leak, no refractory period): each pixel's ON
    # and OFF events are Poisson processes of 20 Hz, so 32 x 32 px over 2 s hold 2 x 20 x 2 x
    # 1024 = 81,920 events on average, whatever the step. At 2 Hz a step holds ~10 of each
    # clock's events; when an interval kept one at most, it gave ~8,000.
    from evstwin import PixelParams

    params = PixelParams(theta_on=0.2, theta_off=0.15, refractory_s=0.0, cutoff_hz=100.0, leak_rate_hz=0.0,
                         shot_noise_rate_hz=20.0, dark_model="none", photon_shot_noise=False)
    t = np.arange(0, round(2.0 * rate_hz) + 1) / rate_hz
    runs = []
    for kernel in ("auto", "per_pixel"):
        sensor = Sensor(32, 32, params, seed=4, num_threads=1)
        sensor.kernel = kernel
        runs.append(sensor.run(np.broadcast_to(np.full((1, 32, 32), 1e3), (t.size, 32, 32)), t))
    assert runs[0].tobytes() == runs[1].tobytes()
    on = int(np.count_nonzero(runs[0]["p"]))
    off = len(runs[0]) - on
    for n in (on, off):
        assert abs(n - 40_960) < 4 * math.sqrt(40_960), (on, off)
    # Each in time order within its pixel, inside the run.
    assert runs[0]["t"].min() >= 0 and runs[0]["t"].max() <= 2_000_000


def spot_counts(seed: int, sparse: bool) -> tuple[int, int, np.ndarray, int]:
    """ON, OFF, per-pixel counts and pixel-updates of a Gaussian spot crossing 64 x 24 px of
    the IMX636 preset's pixel (continuous noise, photoreceptor pole) at 70 px/s for 1 s, sampled
    at 2 kHz: densely (a frame at every sample) or as four 0.25 s sparse steps (the spot's
    windows as light entries, 500 Hz base samples, groups of 25)."""
    from evstwin import psf

    w, h, fine_hz = 64, 24, 2000.0
    sensor = Sensor(w, h, get_preset("imx636").pixel_params(), seed=seed, num_threads=2)
    background = np.full((h, w), 2e3)
    sensor.run(background[None], np.array([0.0]))
    t = np.arange(1, round(fine_hz) + 1) / fine_hz
    x, y, f = -4.0 + 70.0 * t[:, None], np.full((t.size, 1), 11.7), np.full((t.size, 1), 4e7)
    if not sparse:
        ev = sensor.run(psf.render_frames(w, h, x, y, f, 1.2, background_ph_s=2e3), t)
        updates = w * h * t.size
    else:
        parts, updates = [], 0
        for k0 in range(0, t.size, 500):
            k = slice(k0, k0 + 500)
            sample = np.arange(x[k].shape[0])  # one source: its window at every sample of the step
            flat, rate = zip(*psf.contributions(w, h, x[k, 0], y[k, 0], f[k, 0], 1.2, offset=sample * (w * h)))
            idx = np.concatenate(flat)
            parts.append(sensor.run_sparse(background, t[k], base_every=4, group_base_samples=25,
                                           light_sample=idx // (w * h), light_pixel=idx % (w * h),
                                           light_rate=np.concatenate(rate)))
            updates += sensor.last_pixel_updates
        ev = np.concatenate(parts)
    on = int(np.count_nonzero(ev["p"]))
    per_pixel = np.bincount(ev["y"].astype(np.int64) * w + ev["x"], minlength=w * h)
    return on, len(ev) - on, per_pixel, updates


def test_sparse_steps_give_the_statistics_of_the_dense_run() -> None:
    # The convergence check of time steps per pixel: the same spot, the same fine rate, every
    # pixel sampled at it (dense) or only where and while the spot's light changes (sparse).
    dense = [spot_counts(s, sparse=False) for s in (1, 2, 3)]
    sparse = [spot_counts(s, sparse=True) for s in (1, 2, 3)]
    for i, name in ((0, "ON"), (1, "OFF")):
        a, b = sum(r[i] for r in dense), sum(r[i] for r in sparse)
        assert a > 300, (name, a)
        tolerance = 4 * 2 * math.sqrt(a + b)
        assert abs(a - b) < tolerance, f"{name}: {a} dense, {b} sparse (tolerance {tolerance:.0f})"
    # Where the events are: the spot's row band, pixel by pixel, summed over the seeds.
    band_dense = sum(r[2] for r in dense).reshape(24, 64)[8:16].sum(axis=0)
    band_sparse = sum(r[2] for r in sparse).reshape(24, 64)[8:16].sum(axis=0)
    assert np.abs(band_dense - band_sparse).max() < 4 * 2 * math.sqrt(band_dense.max() + 1)
    # And the cost follows the spot: a pixel is updated finely only near it.
    assert all(s[3] * 5 < d[3] for s, d in zip(sparse, dense))


def test_run_sparse_names_a_bad_argument() -> None:
    sensor = Sensor(8, 4, get_preset("imx636").pixel_params(), seed=1, num_threads=1)
    sensor.run(np.full((1, 4, 8), 1e3), np.array([0.0]))
    t = np.array([0.001, 0.002])
    with pytest.raises(ValueError, match=r"static_rate must have shape \(height, width\) = \(4, 8\)"):
        sensor.run_sparse(np.full((8, 4), 1e3), t)
    with pytest.raises(ValueError, match=r"light_pixel\[0\]=32 is outside the 32-pixel sensor"):
        sensor.run_sparse(np.full((4, 8), 1e3), t, light_sample=[0], light_pixel=[32], light_rate=[1.0])
    with pytest.raises(ValueError, match=r"base_every must be >= 1 and divide n_samples.*base_every=3"):
        sensor.run_sparse(np.full((4, 8), 1e3), t, base_every=3)
    with pytest.raises(ValueError, match=r"static_rate\[2, 5\]=nan"):
        bad = np.full((4, 8), 1e3)
        bad[2, 5] = np.nan
        sensor.run_sparse(bad, t)
    # Nothing moved: the sensor still takes the step.
    assert sensor.run_sparse(np.full((4, 8), 1e3), t).dtype.names is not None
    assert sensor.last_pixel_updates == 32


def test_long_steps_keep_the_timing_bias_of_the_dense_run() -> None:
    # The timing-bias statistics of issue 33's "same physics": mcreynolds' LEDs cross their
    # pixels once in 1 s; the delay of each event after its pixel's crossing (the ground
    # truth's closest approach) must have the same law whether every pixel takes the base
    # rate or the pixels with constant light take 0.5 s steps (OFF events come ~110 ms after a
    # crossing, while the pixel settles: a settling pixel stepped too long would shift them).
    from scipy.stats import ks_2samp

    from evstwin.validation import timing_bias

    delays: dict[str, list[np.ndarray]] = {"dense": [], "stepped": []}
    for seed in (1, 2, 3):
        for path, step in (("dense", 0.0), ("stepped", 0.5)):
            r = simulate("mcreynolds", seed=seed, num_threads=2,
                         sets=["duration_s=1", f"sampling.static_step_s={step}"])
            table = timing_bias(r.events, r.meta["truth"])
            delays[path].append(np.column_stack([table["delay_s"], table["p"]]))
    dense, stepped = np.concatenate(delays["dense"]), np.concatenate(delays["stepped"])
    for pol, name in ((1, "ON"), (0, "OFF")):
        a, b = dense[dense[:, 1] == pol, 0], stepped[stepped[:, 1] == pol, 0]
        assert a.size > 2000 and b.size > 2000, (name, a.size, b.size)
        assert abs(a.size - b.size) < 4 * math.sqrt(a.size + b.size), (name, a.size, b.size)
        p = ks_2samp(a, b).pvalue
        assert p > 1e-3, f"{name} delays differ (KS p = {p:.2g}): medians {np.median(a):.4f} s, {np.median(b):.4f} s"
