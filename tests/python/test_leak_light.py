"""The leak that grows with the photocurrent and its direction (issue 10: leak_photocurrent_hz_per_a,
leak_polarity) against hand computations.

A noise-free static pixel's reference drifts one threshold per leak period, so it fires
exactly at t = n / f with f = (leak_rate_hz + k I_photo) times its spread (1 here), I_photo =
e * electrons_per_photon * photon rate; ON for an ON leak, OFF for an OFF one.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import evstwin
from evstwin import EVENT_DTYPE, PixelParams, Sensor
from evstwin.pixel import LeakPolarity
from evstwin.sensor import EVENT_LABELS

E = evstwin._core.ELEMENTARY_CHARGE_C
LEAK_LABEL = next(code for code, name in EVENT_LABELS.items() if name == "leak")

NOISE_FREE = PixelParams(photon_shot_noise=False, dark_model="none", shot_noise_rate_hz=0.0,
                         leak_random_phase=False, theta_on=0.2, theta_off=0.15)


def static_run(params: PixelParams, rate_ph_s: np.ndarray, duration_s: float, dt_s: float = 0.01,
               seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Events and labels of a static scene (rate_ph_s: (h, w)) sampled every dt_s."""
    h, w = rate_ph_s.shape
    sensor = Sensor(w, h, params, seed=seed)
    n = round(duration_s / dt_s) + 1
    t = np.arange(n) * dt_s
    ev = sensor.run(np.broadcast_to(rate_ph_s, (n, h, w)).copy(), t)
    return ev, sensor.last_labels()


def photo_current_a(params: PixelParams, rate_ph_s: float) -> float:
    return E * params.electrons_per_photon * rate_ph_s


@pytest.mark.parametrize("noise_model", ["continuous", "sampled"])
@pytest.mark.parametrize("polarity", ["on", "off"])
def test_static_pixel_fires_at_the_hand_computed_leak_rate(polarity: LeakPolarity, noise_model: str) -> None:
    rate_ph_s = 2e7
    params = NOISE_FREE.replace(leak_rate_hz=0.7, leak_photocurrent_hz_per_a=1e15, leak_polarity=polarity,
                                noise_model=noise_model)
    f_hz = 0.7 + 1e15 * photo_current_a(params, rate_ph_s)
    assert 2.0 < f_hz < 20.0  # the photocurrent part dominates: a test of it, not of the dark leak
    duration_s = 10.15
    ev, labels = static_run(params, np.full((2, 3), rate_ph_s), duration_s)
    per_pixel = math.floor(f_hz * duration_s)
    assert len(ev) == 6 * per_pixel
    assert np.all(ev["p"] == (1 if polarity == "on" else 0))
    assert np.all(labels == LEAK_LABEL)
    # The n-th event at n / f (the reference starts at the level: leak_random_phase off).
    first = ev[(ev["x"] == 0) & (ev["y"] == 0)]
    np.testing.assert_allclose(first["t"], 1e6 * np.arange(1, per_pixel + 1) / f_hz, atol=1.5)


def test_leak_rate_is_linear_in_the_photocurrent() -> None:
    # No dark leak: two light levels, a factor 3 apart, in one sensor (left and right halves).
    params = NOISE_FREE.replace(leak_rate_hz=0.0, leak_photocurrent_hz_per_a=2e15, leak_polarity="off")
    rate = np.full((2, 4), 1e7)
    rate[:, 2:] = 3e7
    duration_s = 9.93
    ev, _ = static_run(params, rate, duration_s)
    for x, r in ((0, 1e7), (3, 3e7)):
        f_hz = 2e15 * photo_current_a(params, r)
        got = int(np.count_nonzero((ev["x"] == x) & (ev["y"] == 0)))
        assert got == math.floor(f_hz * duration_s)
    left = np.count_nonzero(ev["x"] < 2)
    right = np.count_nonzero(ev["x"] >= 2)
    assert abs(right / left - 3.0) < 0.1  # floor() costs at most one event of ~26 a pixel


def test_dark_current_does_not_drive_the_photocurrent_leak() -> None:
    # No light, 1e7 e-/s of dark current (1.6 pA: with k = 1e18 Hz/A it would leak at 1.6 MHz
    # were it counted): only leak_rate_hz leaks, 0.5 Hz. The dark current's shot noise (sd
    # ~2e-3 of a 0.15 threshold) moves a crossing by a few ms, so a pixel fires floor(0.5 T) = 2
    # events in T = 5.4 s (the third is due at 6 s).
    params = NOISE_FREE.replace(dark_model="poisson", dark_rate_e_per_s=1e7, leak_rate_hz=0.5,
                                leak_photocurrent_hz_per_a=1e18)
    ev, labels = static_run(params, np.zeros((2, 3)), 5.4)
    assert len(ev) == 6 * 2
    assert np.all(ev["p"] == 1) and np.all(labels == LEAK_LABEL)


def test_unset_fields_change_nothing() -> None:
    # A noisy configuration (shot noise, background, leak spread, random phase) with the new
    # fields left unset and set to their defaults by hand: the same events and labels.
    base = dict(leak_rate_hz=3.0, leak_rate_sigma=0.5, shot_noise_rate_hz=1.0, threshold_sigma=0.05)
    rng = np.random.default_rng(1)
    rate = rng.uniform(1e4, 1e8, (5, 7))
    a = static_run(PixelParams(**base), rate, 2.0, dt_s=0.003, seed=4)  # type: ignore[arg-type]
    explicit = PixelParams(**base).replace(leak_photocurrent_hz_per_a=0.0, leak_polarity="on")  # type: ignore[arg-type]
    b = static_run(explicit, rate, 2.0, dt_s=0.003, seed=4)
    assert len(a[0]) > 100
    assert a[0].tobytes() == b[0].tobytes() and a[1].tobytes() == b[1].tobytes()


@pytest.mark.parametrize("polarity", ["on", "off"])
def test_noisy_leak_is_stationary_from_the_start(polarity: LeakPolarity) -> None:
    # Shot noise on, the leak's phase drawn at random (mirrored for an OFF leak): the leak's
    # events come at its rate from t = 0 (a phase drawn on the wrong side would hold the
    # first 1 / f back), and the leak's polarity dominates.
    rate_ph_s = 1e8
    params = PixelParams(leak_rate_hz=0.0, leak_photocurrent_hz_per_a=2e15, leak_polarity=polarity,
                         shot_noise_rate_hz=0.0, theta_on=0.3, theta_off=0.3)
    f_hz = 2e15 * photo_current_a(params, rate_ph_s)
    assert 5.0 < f_hz < 50.0
    h, w = 20, 30
    ev, _ = static_run(params, np.full((h, w), rate_ph_s), 1.0, dt_s=0.002, seed=3)
    leak_pol = 1 if polarity == "on" else 0
    assert np.count_nonzero(ev["p"] == leak_pol) > 0.95 * len(ev)
    # In the first 0.1 s (1.7 leak periods) a stationary start fires f * 0.1 a pixel; a phase
    # on the wrong side (d a uniform share of the other threshold away) would fire ~40 % of it.
    first = np.count_nonzero(ev["t"] < 0.1e6)
    expect = h * w * f_hz * 0.1
    assert abs(first - expect) < 4 * math.sqrt(expect), (first, expect)
    assert abs(len(ev) - 10 * expect) < 4 * math.sqrt(10 * expect), (len(ev), 10 * expect)


def test_bad_leak_arguments_are_one_clear_error() -> None:
    with pytest.raises(ValueError, match=r"leak_polarity must be one of 'on', 'off'; got leak_polarity='up'"):
        PixelParams(leak_polarity="up")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"leak_photocurrent_hz_per_a must be in \[0, .*got leak_photocurrent_hz_per_a=-1"):
        PixelParams(leak_photocurrent_hz_per_a=-1.0)
    with pytest.raises(ValueError, match=r"leak_photocurrent_hz_per_a.*got leak_photocurrent_hz_per_a=nan"):
        PixelParams(leak_photocurrent_hz_per_a=float("nan"))


def test_scenario_keys_reach_the_engine() -> None:
    from evstwin import scenario

    sc = scenario.build({"name": "t", "duration_s": 0.1, "sensor": {"preset": "davis346", "roi": [0, 0, 8, 8]},
                         "pixel": {"leak_polarity": "off", "leak_photocurrent_hz_per_a": 1e14}})
    assert sc.params.leak_polarity == "off" and sc.params.leak_photocurrent_hz_per_a == 1e14
    assert EVENT_DTYPE.itemsize == 13
