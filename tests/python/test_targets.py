"""Target trajectories, brightness, the random star field, and one run through the engine."""

from __future__ import annotations

import math

import numpy as np
import pytest

from evstwin.optics import Optics
from evstwin.psf import render_frames
from evstwin.targets import (
    CircularTarget,
    LightCurve,
    LinearTarget,
    StaticTarget,
    TabulatedTarget,
    aligned_rotating_targets,
    max_speed_px_s,
    random_star_field,
    sample_targets,
)

T = np.linspace(0.0, 3.0, 301)


def test_static_target() -> None:
    s = StaticTarget(3.5, 7.25, 1e9)
    x, y = s.position_px(T)
    assert x.shape == T.shape and np.all(x == 3.5) and np.all(y == 7.25)
    np.testing.assert_array_equal(s.flux_ph_s(T), 1e9)
    assert s.max_speed_px_s(0.0, 10.0) == 0.0
    x2, _ = s.position_px(np.zeros((2, 3)))
    assert x2.shape == (2, 3)


def test_linear_target() -> None:
    lt = LinearTarget(10.0, 20.0, 3.0, -4.0, 5.0, t0_s=1.0)
    x, y = lt.position_px(np.array([1.0, 3.0]))
    np.testing.assert_allclose(x, [10.0, 16.0])
    np.testing.assert_allclose(y, [20.0, 12.0])
    assert lt.max_speed_px_s(0, 1) == pytest.approx(5.0)
    o = Optics()
    w = 1e-3  # rad/s
    la = LinearTarget.from_angular_velocity(0.0, 0.0, w, 0.0, o, 1.0)
    assert la.vx_px_s == pytest.approx(w / o.plate_scale_rad_per_px)


def test_circular_target_is_analytic() -> None:
    c = CircularTarget.with_period(100.0, 80.0, 50.0, 2.0, 1e9, phase_rad=0.3)
    w = math.pi
    assert c.angular_rate_rad_s == pytest.approx(w)
    assert c.period_s == pytest.approx(2.0)
    x, y = c.position_px(T)
    np.testing.assert_allclose(x, 100.0 + 50.0 * np.cos(w * T + 0.3), rtol=0, atol=1e-12)
    np.testing.assert_allclose(y, 80.0 + 50.0 * np.sin(w * T + 0.3), rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.hypot(x - 100.0, y - 80.0), 50.0, rtol=1e-13)
    vx, vy = c.velocity_px_s(T)
    np.testing.assert_allclose(np.hypot(vx, vy), 50.0 * w, rtol=1e-13)
    assert c.max_speed_px_s(0.0, 1.0) == pytest.approx(50.0 * w)
    # velocity is the derivative of position
    h = 1e-6
    xp, yp = c.position_px(T + h)
    xm, ym = c.position_px(T - h)
    np.testing.assert_allclose((xp - xm) / (2 * h), vx, atol=1e-5)
    np.testing.assert_allclose((yp - ym) / (2 * h), vy, atol=1e-5)
    # a full period comes back; reverse turns the other way
    np.testing.assert_allclose(c.position_px(np.array([0.7, 2.7])), [[x[70]] * 2, [y[70]] * 2], atol=1e-9)
    r = CircularTarget.with_period(0.0, 0.0, 1.0, 4.0, 1.0, reverse=True)
    assert r.position_px(1.0)[1] == pytest.approx(-1.0)


def test_paper_like_sampling_jump() -> None:
    # DESIGN.md point 10: at 250 Hz a source at 100 px radius turning once a second jumps 2.5 px
    c = CircularTarget.with_period(173.0, 130.0, 100.0, 1.0, 1e9)
    assert c.max_speed_px_s(0, 1) / 250.0 == pytest.approx(2.513, rel=1e-3)


def test_aligned_rotating_targets() -> None:
    bar = aligned_rotating_targets(50.0, 40.0, [-20.0, 10.0, 30.0], 1.0, [1.0, 2.0, 3.0])
    assert [t.radius_px for t in bar] == [20.0, 10.0, 30.0]
    x, y = sample_targets(bar, [0.5])[:2]
    # all on one line through the centre
    d = np.stack([x[0] - 50.0, y[0] - 40.0])
    cross = d[0, 0] * d[1, 1:] - d[1, 0] * d[0, 1:]
    np.testing.assert_allclose(cross, 0.0, atol=1e-9)
    assert np.dot(d[:, 0], d[:, 1]) < 0  # the negative radius is on the other side
    with pytest.raises(ValueError, match=r"radii_px\[1\]"):
        aligned_rotating_targets(0.0, 0.0, [1.0, 0.0], 1.0, 1.0)


def test_tabulated_interpolation_and_speed() -> None:
    t = np.array([0.0, 1.0, 3.0])
    tt = TabulatedTarget(t, np.array([0.0, 10.0, 10.0]), np.array([0.0, 0.0, 40.0]), 2.0)
    x, y = tt.position_px(np.array([0.5, 1.0, 2.0, 3.0]))
    np.testing.assert_allclose(x, [5.0, 10.0, 10.0, 10.0])
    np.testing.assert_allclose(y, [0.0, 0.0, 20.0, 40.0])
    vx, vy = tt.velocity_px_s(np.array([0.5, 1.0, 3.0]))
    np.testing.assert_allclose(vx, [10.0, 0.0, 0.0])
    np.testing.assert_allclose(vy, [0.0, 20.0, 20.0])
    assert tt.max_speed_px_s(0.0, 0.9) == pytest.approx(10.0)
    assert tt.max_speed_px_s(0.2, 2.0) == pytest.approx(20.0)
    with pytest.raises(ValueError, match="outside the table"):
        tt.position_px([3.5])
    with pytest.raises(ValueError, match="outside the table"):
        tt.max_speed_px_s(-1.0, 0.5)
    held = TabulatedTarget(t, np.array([0.0, 10.0, 10.0]), np.array([0.0, 0.0, 40.0]), 2.0, outside="hold")
    x, y = held.position_px(np.array([-1.0, 9.0]))
    np.testing.assert_allclose(x, [0.0, 10.0])
    np.testing.assert_allclose(y, [0.0, 40.0])
    assert held.velocity_px_s(np.array([9.0]))[1][0] == 0.0
    assert held.max_speed_px_s(5.0, 6.0) == 0.0


def test_table_is_copied_and_frozen() -> None:
    t = np.array([0.0, 1.0])
    x = np.array([0.0, 1.0])
    tt = TabulatedTarget(t, x, x.copy(), 1.0)
    x[1] = 99.0
    assert tt.x_px[1] == 1.0
    with pytest.raises(ValueError):
        tt.x_px[0] = 5.0


def test_light_curves() -> None:
    lc = LightCurve(np.array([0.0, 1.0, 2.0]), np.array([1.0, 3.0, 1.0]))
    np.testing.assert_allclose(lc(np.array([-1.0, 0.5, 1.5, 5.0])), [1.0, 2.0, 2.0, 1.0])
    periodic = LightCurve(np.array([0.0, 1.0, 2.0]), np.array([1.0, 3.0, 1.0]), periodic=True)
    np.testing.assert_allclose(periodic(np.array([2.5, 4.5, -1.5])), [2.0, 2.0, 2.0])
    o = Optics()
    mags = LightCurve.from_magnitudes([0.0, 10.0], [8.0, 13.0], o)
    # linear in magnitude: half-way is 10.5 mag
    assert o.magnitude_from_flux(mags(5.0)) == pytest.approx(10.5)
    tumbling = StaticTarget(1.0, 1.0, mags)
    assert tumbling.flux_ph_s(np.array([0.0]))[0] == pytest.approx(o.flux_from_magnitude(8.0))


def test_star_field_is_reproducible() -> None:
    o = Optics()
    a = random_star_field(346, 260, o, n_stars=200, seed=7)
    b = random_star_field(346, 260, o, n_stars=200, seed=7)
    c = random_star_field(346, 260, o, n_stars=200, seed=8)
    key = [(s.x_px, s.y_px, s.brightness) for s in a]
    assert key == [(s.x_px, s.y_px, s.brightness) for s in b]
    assert key != [(s.x_px, s.y_px, s.brightness) for s in c]
    x = np.array([s.x_px for s in a])
    y = np.array([s.y_px for s in a])
    assert x.min() >= -0.5 and x.max() < 345.5 and y.min() >= -0.5 and y.max() < 259.5
    mag = o.magnitude_from_flux(np.array([s.brightness for s in a]))
    assert mag.min() >= 6.0 - 1e-9 and mag.max() <= 12.0 + 1e-9
    # power law: more faint stars than bright ones
    assert np.sum(mag > 9.0) > 2 * np.sum(mag < 9.0)
    assert a[0].label.startswith("star 0 mag=")


def test_star_field_counts_follow_the_power_law() -> None:
    o = Optics()
    stars = random_star_field(100, 100, o, n_stars=20000, mag_min=5.0, mag_max=10.0, counts_slope=0.5, seed=1)
    mag = o.magnitude_from_flux(np.array([s.brightness for s in stars]))
    counts, _ = np.histogram(mag, bins=5, range=(5.0, 10.0))
    ratio = counts[1:] / counts[:-1]
    np.testing.assert_allclose(ratio, 10**0.5, rtol=0.15)


def test_star_field_density() -> None:
    o = Optics()
    px_deg = math.degrees(o.plate_scale_rad_per_px)
    expected = 50.0 * 346 * 260 * px_deg**2
    stars = random_star_field(346, 260, o, density_per_deg2=50.0, seed=2)
    assert abs(len(stars) - expected) < 5 * math.sqrt(expected)


def test_sample_targets_and_max_speed() -> None:
    targets = [StaticTarget(1.0, 2.0, 3.0), CircularTarget(0.0, 0.0, 10.0, 2.0, 4.0)]
    x, y, f = sample_targets(targets, T)
    assert x.shape == y.shape == f.shape == (T.size, 2)
    np.testing.assert_array_equal(f[:, 1], 4.0)
    assert max_speed_px_s(targets, 0.0, 1.0) == pytest.approx(20.0)
    assert max_speed_px_s([], 0.0, 1.0) == 0.0


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: StaticTarget(1.0, 1.0, -1.0), "brightness"),
        (lambda: StaticTarget(float("nan"), 1.0, 1.0), "x_px"),
        (lambda: LinearTarget(0.0, 0.0, math.inf, 0.0, 1.0), "vx_px_s"),
        (lambda: CircularTarget(0.0, 0.0, 0.0, 1.0, 1.0), "radius_px"),
        (lambda: CircularTarget(0.0, 0.0, -2.0, 1.0, 1.0), "radius_px"),
        (lambda: CircularTarget.with_period(0.0, 0.0, 1.0, 0.0, 1.0), "period_s"),
        (
            lambda: TabulatedTarget(np.array([0.0, 1.0, 1.0]), np.zeros(3), np.zeros(3), 1.0),
            "strictly increasing",
        ),
        (lambda: TabulatedTarget(np.array([0.0, 1.0]), np.zeros(3), np.zeros(2), 1.0), "x_px"),
        (lambda: TabulatedTarget(np.array([0.0, np.nan]), np.zeros(2), np.zeros(2), 1.0), "t_s"),
        (
            lambda: TabulatedTarget(np.array([0.0, 1.0]), np.zeros(2), np.zeros(2), 1.0, outside="wrap"),
            "outside",
        ),  # type: ignore[arg-type]
        (lambda: LightCurve(np.array([1.0, 0.0]), np.ones(2)), "strictly increasing"),
        (lambda: LightCurve(np.array([0.0, 1.0]), np.array([1.0, -1.0])), "flux_ph_s"),
        (lambda: LightCurve(np.array([0.0, 1.0]), np.array([1.0, 0.0]), log_interp=True), "flux_ph_s"),
        (lambda: StaticTarget(0.0, 0.0, 1.0).max_speed_px_s(2.0, 1.0), "t0_s"),
        (lambda: random_star_field(10, 10, Optics()), "exactly one"),
        (lambda: random_star_field(10, 10, Optics(), n_stars=5, density_per_deg2=1.0), "exactly one"),
        (lambda: random_star_field(10, 10, Optics(), n_stars=-1), "n_stars"),
        (lambda: random_star_field(10, 10, Optics(), n_stars=5, mag_min=9.0, mag_max=8.0), "mag_min"),
        (lambda: random_star_field(0, 10, Optics(), n_stars=5), "width"),
    ],
)
def test_validation(call, match: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError, match=match):
        call()


def test_rotating_source_through_the_engine_fires_only_on_its_track() -> None:
    """End to end: a circular target, rendered at a sample rate that keeps steps < 0.5 px,
    drives the engine; events appear on the circle and nowhere else (noise off)."""
    from evstwin import PixelParams, Sensor

    w = h = 48
    target = CircularTarget.with_period(24.0, 24.0, 12.0, 0.5, 1e9)
    speed = target.max_speed_px_s(0.0, 0.5)
    rate_hz = speed / 0.25  # steps of 0.25 px
    t = np.arange(0.0, 0.5, 1.0 / rate_hz)
    x, y, f = sample_targets([target], t)
    frames = render_frames(w, h, x, y, f, 1.0, background_ph_s=1e5)
    params = PixelParams(shot_noise_rate_hz=0.0, leak_rate_hz=0.0, dark_model="none", photon_shot_noise=False)
    events = Sensor(w, h, params, seed=1).run(frames, t)
    assert events.size > 100
    r = np.hypot(events["x"].astype(float) - 24.0, events["y"].astype(float) - 24.0)
    assert np.all(np.abs(r - 12.0) < 6.0)
    assert np.any(events["p"] == 1) and np.any(events["p"] == 0)


def test_star_fields_beyond_a_million_stars_are_refused_up_front() -> None:
    # Issue 9: 1e9 stars (or a density giving millions) ran out of memory after minutes.
    from evstwin.presets import get_preset
    from evstwin.targets import MAX_STARS, random_star_field

    optics = get_preset("davis346").optics(0.041, 1.8).replace(width_px=346, height_px=260)
    with pytest.raises(ValueError, match=r"n_stars must be at most 1,000,000 .*got n_stars=1,000,000,000, 300 GB"):
        random_star_field(346, 260, optics, n_stars=10**9)
    with pytest.raises(ValueError, match=r"density_per_deg2=65535 gives 3.94e\+06 stars on the 346x260 field"):
        random_star_field(346, 260, optics, density_per_deg2=65535)
    with pytest.raises(ValueError, match=r"density_per_deg2=1e\+300 gives"):
        random_star_field(346, 260, optics, density_per_deg2=1e300)
    assert MAX_STARS == 1_000_000
    assert len(random_star_field(346, 260, optics, density_per_deg2=100.0, seed=1)) > 0
