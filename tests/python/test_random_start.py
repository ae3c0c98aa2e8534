"""A reference that starts at a random offset within the thresholds (issue 10:
``random_reference_start``), against what a uniform offset implies by hand.

A noise-free pixel whose ln I rises at a constant rate g from t = 0 fires its first ON event
when y - ref reaches theta_on: at (theta_on - d0) / g with d0 = y - ref at t = 0. With d0
uniform on (-theta_off, theta_on) the first events are uniform on (0, (theta_on + theta_off)
/ g); with the paper's start (d0 = 0) every pixel fires at theta_on / g.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from evstwin import PixelParams, Sensor

NOISE_FREE = PixelParams(photon_shot_noise=False, dark_model="none", shot_noise_rate_hz=0.0, leak_rate_hz=0.0, cutoff_hz=None,
                         refractory_s=0.0, theta_on=0.2, theta_off=0.15)
RATE_PER_S = 0.5
"""Rise of ln I [1/s]: the light grows as exp(0.5 t)."""


def ramp_run(params: PixelParams, w: int = 64, h: int = 32, duration_s: float = 1.5, seed: int = 3) -> np.ndarray:
    n = round(duration_s / 1e-3) + 1
    t = np.arange(n) * 1e-3
    frames = np.broadcast_to((1e9 * np.exp(RATE_PER_S * t))[:, None, None], (n, h, w)).copy()
    return Sensor(w, h, params, seed=seed).run(frames, t)


def first_on_s(ev: np.ndarray, w: int = 64, h: int = 32) -> np.ndarray:
    pix = ev["y"].astype(np.int64) * w + ev["x"]
    first = np.full(w * h, np.inf)
    np.minimum.at(first, pix[ev["p"] == 1], ev["t"][ev["p"] == 1] / 1e6)
    return first


def test_paper_start_fires_every_pixel_after_one_whole_threshold() -> None:
    first = first_on_s(ramp_run(NOISE_FREE))
    np.testing.assert_allclose(first, 0.2 / RATE_PER_S, atol=2e-6)


def test_random_start_spreads_the_first_events_uniformly_over_one_threshold_span() -> None:
    ev = ramp_run(NOISE_FREE.replace(random_reference_start=True))
    assert np.all(ev["p"] == 1) and ev["t"].min() > 0  # nothing fires at t = 0, no OFF on a rise
    first = first_on_s(ev)
    span_s = (0.2 + 0.15) / RATE_PER_S  # 0.7 s
    assert np.isfinite(first).all() and first.max() < span_s
    assert stats.kstest(first / span_s, "uniform").pvalue > 1e-3
    # Every later event one threshold later: the offset moves the phase, not the rate.
    pix = ev["y"].astype(np.int64) * 64 + ev["x"]
    order = np.lexsort((ev["t"], pix))
    gaps = np.diff(ev["t"][order] / 1e6)[np.diff(pix[order]) == 0]
    np.testing.assert_allclose(gaps, 0.2 / RATE_PER_S, atol=2e-6)
    # Per seed and pixel: the same seed gives the same offsets, another seed others.
    again = first_on_s(ramp_run(NOISE_FREE.replace(random_reference_start=True)))
    other = first_on_s(ramp_run(NOISE_FREE.replace(random_reference_start=True), seed=4))
    assert np.array_equal(first, again) and not np.allclose(first, other)


def test_a_static_scene_stays_silent_and_a_leak_keeps_its_own_phase() -> None:
    static = Sensor(16, 8, NOISE_FREE.replace(random_reference_start=True), seed=1)
    t = np.arange(101) * 1e-2
    assert len(static.run(np.full((101, 8, 16), 1e9), t)) == 0
    # With a leak the leak's random phase sets the reference: the same events as without the
    # switch (the leak's first event uniform over its period either way).
    leak = NOISE_FREE.replace(leak_rate_hz=3.0, leak_random_phase=True)
    a = Sensor(16, 8, leak, seed=1).run(np.full((101, 8, 16), 1e9), t)
    b = Sensor(16, 8, leak.replace(random_reference_start=True), seed=1).run(np.full((101, 8, 16), 1e9), t)
    assert len(a) > 100 and a.tobytes() == b.tobytes()


def test_the_switch_must_be_a_bool() -> None:
    with pytest.raises(TypeError, match="random_reference_start must be True or False; got random_reference_start=1"):
        PixelParams(random_reference_start=1)  # type: ignore[arg-type]
