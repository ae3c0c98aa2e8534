"""Drifting star fields (issue 9): the whole field moving across the sensor, stars drifting in
and out, targets given in field coordinates, and the scenario keys that set them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from evstwin.optics import Optics
from evstwin.presets import get_preset
from evstwin.scenario import ScenarioError, build
from evstwin.scenario.limits import _most_windows_at_once
from evstwin.simulate import simulate, track_names
from evstwin.targets import (
    CircularTarget,
    DriftingTarget,
    LinearTarget,
    StaticTarget,
    TabulatedTarget,
    drift_px_s_from_arcsec,
    drifting,
    random_star_field,
)

ARCSEC_PER_RAD = 180.0 * 3600.0 / math.pi


def davis_optics(focal_length_m: float = 2.0) -> Optics:
    return get_preset("davis346").optics(focal_length_m, 4.0).replace(width_px=346, height_px=260)


def on_sensor(stars: list, t: float, width: int, height: int) -> int:
    x = np.array([float(s.position_px(t)[0]) for s in stars])
    y = np.array([float(s.position_px(t)[1]) for s in stars])
    return int(np.count_nonzero((x >= -0.5) & (x < width - 0.5) & (y >= -0.5) & (y < height - 0.5)))


def test_a_drifting_star_is_at_its_start_plus_v_t() -> None:
    o = davis_optics()
    still = random_star_field(346, 260, o, n_stars=50, seed=3)
    moving = random_star_field(346, 260, o, n_stars=50, seed=3, drift_px_s=(-3.0, 3.2), duration_s=10.0)
    assert all(isinstance(s, LinearTarget) for s in moving) and len(moving) > 50
    for s, s0 in zip(moving, still):  # the stars on the sensor at t = 0 are the still field's
        assert (s.x0_px, s.y0_px, s.brightness, s.label) == (s0.x_px, s0.y_px, s0.brightness, s0.label)
    t = np.array([0.0, 2.5, 10.0])
    for s in moving:
        x, y = s.position_px(t)
        np.testing.assert_allclose(x, s.x0_px - 3.0 * t, rtol=0, atol=1e-12)
        np.testing.assert_allclose(y, s.y0_px + 3.2 * t, rtol=0, atol=1e-12)
        vx, vy = s.velocity_px_s(t)
        assert np.all(vx == -3.0) and np.all(vy == 3.2)
    # a zero drift is the old static field, StaticTargets
    assert all(isinstance(s, StaticTarget) for s in random_star_field(346, 260, o, n_stars=5, drift_px_s=(0, 0),
                                                                        duration_s=10.0))


def test_arcsec_drift_goes_through_the_plate_scale() -> None:
    o = davis_optics(2.0)
    # by hand: 18.5 um / 2 m = 9.25e-6 rad/px = 1.90795 arcsec/px
    scale = 18.5e-6 / 2.0 * ARCSEC_PER_RAD
    assert scale == pytest.approx(1.90795, abs=1e-5)
    vx, vy = drift_px_s_from_arcsec(15.04, -7.5, o)
    assert vx == pytest.approx(15.04 / 1.90795, rel=1e-5) and vx == pytest.approx(7.8828, abs=1e-4)
    assert vy == pytest.approx(-7.5 / 1.90795, rel=1e-5)
    # the same through a scenario: geo-stare has focal_length_m = 2.0 on a DAVIS346
    scene = build({"base": "geo-stare", "star_field": {"drift_arcsec_s": [15.04, -7.5]}}, duration_s=1.0)
    star = scene.targets[-1]
    assert isinstance(star, LinearTarget)
    assert (star.vx_px_s, star.vy_px_s) == pytest.approx((15.04 / scale, -7.5 / scale), rel=1e-12)


def test_the_count_on_the_sensor_stays_poisson_as_stars_drift_in_and_out() -> None:
    o = davis_optics()
    w, h, duration = 200, 150, 10.0
    vx, vy = -30.0, 20.0  # over 10 s the field moves 1.5 widths and 1.3 heights
    px_deg = o.plate_scale_arcsec_per_px / 3600.0
    mu = 400.0  # stars on the sensor at any time, in the mean
    density = mu / (w * h * px_deg**2)
    stars = random_star_field(w, h, o, density_per_deg2=density, seed=11, drift_px_s=(vx, vy), duration_s=duration)
    # every time's count is Poisson(mu): within 4 sigma (sqrt(mu) = 20) at each of 5 times
    counts = [on_sensor(stars, t, w, h) for t in np.linspace(0.0, duration, 5)]
    assert all(abs(n - mu) < 4.0 * math.sqrt(mu) for n in counts), counts
    # the whole field covers the swept area w h + h |vx| D + w |vy| D at the same density
    swept = (w * h + h * abs(vx) * duration + w * abs(vy) * duration) / (w * h) * mu
    assert abs(len(stars) - swept) < 4.0 * math.sqrt(swept), (len(stars), swept)
    # and no star of it misses the sensor for the whole run
    t = np.linspace(0.0, duration, 2001)
    for s in stars:
        x, y = s.position_px(t)
        assert np.any((x >= -0.5 - 0.2) & (x < w - 0.5 + 0.2) & (y >= -0.5 - 0.2) & (y < h - 0.5 + 0.2))
    # n_stars: exactly that many at t = 0, and the same density after
    fixed = random_star_field(w, h, o, n_stars=400, seed=11, drift_px_s=(vx, vy), duration_s=duration)
    assert on_sensor(fixed, 0.0, w, h) == 400
    assert abs(on_sensor(fixed, duration, w, h) - 400) < 4.0 * math.sqrt(400)


def test_field_frame_targets_move_with_their_own_velocity_plus_the_drift() -> None:
    d = (-3.0, 3.2)
    lin = drifting(LinearTarget(10.0, 20.0, 1.0, 2.0, 5.0, t0_s=1.0, label="sat"), *d)
    assert isinstance(lin, LinearTarget) and lin.label == "sat"
    assert (lin.vx_px_s, lin.vy_px_s) == (1.0 - 3.0, 2.0 + 3.2)
    x, y = lin.position_px(np.array([4.0]))
    # own motion from t0 = 1 s plus the drift from t = 0: 10 + 1 * 3 - 3 * 4, 20 + 2 * 3 + 3.2 * 4
    assert (x[0], y[0]) == pytest.approx((1.0, 38.8), abs=1e-12)
    still = drifting(StaticTarget(5.0, 6.0, 1.0), *d)
    assert isinstance(still, LinearTarget) and still.max_speed_px_s(0.0, 1.0) == pytest.approx(math.hypot(*d))
    circle = CircularTarget(50.0, 50.0, 10.0, 2.0, 1.0)
    carried = drifting(circle, *d)
    assert isinstance(carried, DriftingTarget)
    t = np.array([0.0, 0.3, 1.7])
    vx, vy = carried.velocity_px_s(t)
    cvx, cvy = circle.velocity_px_s(t)
    np.testing.assert_allclose(vx, cvx - 3.0, atol=1e-12)
    np.testing.assert_allclose(vy, cvy + 3.2, atol=1e-12)
    x, y = carried.position_px(t)
    cx, cy = circle.position_px(t)
    np.testing.assert_allclose(x, cx - 3.0 * t, atol=1e-12)
    assert carried.max_speed_px_s(0.0, 1.0) == pytest.approx(20.0 + math.hypot(*d))
    # 4 px/s for a second, then held: exact speeds (4 - 3, 3.2), then the drift alone after 1 s
    tab = drifting(TabulatedTarget(np.array([0.0, 1.0]), np.array([0.0, 4.0]), np.zeros(2), 1.0, outside="hold"), *d)
    assert tab.max_speed_px_s(0.0, 0.5) == pytest.approx(math.hypot(1.0, 3.2))
    assert tab.max_speed_px_s(0.5, 3.0) == pytest.approx(math.hypot(-3.0, 3.2))
    assert drifting(circle, 0.0, 0.0) is circle

    # in a scenario: frame = "field" adds the drift, the default sensor frame does not
    scene = build({
        "base": "geo-stare", "star_field": {"drift_px_s": list(d)},
        "targets": [
            {"kind": "linear", "x0_px": 20.0, "y0_px": 130.0, "vx_px_s": 7.0, "vy_px_s": 0.0, "magnitude": 8.0,
             "frame": "field", "label": "in-field"},
            {"kind": "linear", "x0_px": 20.0, "y0_px": 130.0, "vx_px_s": 7.0, "vy_px_s": 0.0, "magnitude": 8.0,
             "label": "on-sensor"},
        ]}, duration_s=1.0)
    field, sensor = scene.targets[:2]
    assert field.velocity_px_s(0.5)[0] == 7.0 - 3.0 and field.velocity_px_s(0.5)[1] == 3.2
    assert sensor.velocity_px_s(0.5)[0] == 7.0 and sensor.velocity_px_s(0.5)[1] == 0.0
    assert track_names(scene) == ["in-field", "on-sensor"]  # field stars carry no tracks


def test_the_same_seed_gives_the_same_drifting_field() -> None:
    s = {"base": "geo-stare", "star_field": {"drift_px_s": [-3.0, 3.2]}}

    def key(scene) -> list:  # type: ignore[no-untyped-def]
        return [(t.x0_px, t.y0_px, t.vx_px_s, t.vy_px_s, t.brightness) for t in scene.targets[1:]]

    a, b = build(s, duration_s=5.0), build(s, duration_s=5.0)
    assert key(a) == key(b) and a.field_stars == len(a.targets) - 1 > 40
    other = build({"base": "geo-stare", "star_field": {"drift_px_s": [-3.0, 3.2], "seed": 8}}, duration_s=5.0)
    assert key(other) != key(a)


def test_a_drift_alone_moves_field_frame_targets_and_makes_no_stars() -> None:
    scene = build({
        "name": "imx-star", "duration_s": 2.0, "sensor": {"preset": "imx636", "width": 64, "height": 64},
        "background": {"photon_rate_ph_s": 1e4}, "star_field": {"drift_px_s": [-3.0, 3.2]},
        "targets": [{"kind": "static", "x_px": 40.0, "y_px": 20.0, "flux_ph_s": 1e6, "frame": "field"}],
    })
    assert scene.field_stars == 0 and len(scene.targets) == 1
    x, y = scene.targets[0].position_px(np.array([2.0]))
    assert (x[0], y[0]) == pytest.approx((40.0 - 6.0, 20.0 + 6.4))


def test_windows_on_the_sensor_at_once() -> None:
    # two stars crossing a 10 px wide sensor one after the other at 10 px/s: one window at a
    # time (each on for 1 s + its window), a third always on (not linear)
    a = LinearTarget(5.0, 5.0, 10.0, 0.0, 1.0)  # leaves at x = 9.5 + 2 -> t = 0.65 s
    b = LinearTarget(-10.0, 5.0, 10.0, 0.0, 1.0)  # enters at x = -2.5 -> t = 0.75 s
    c = CircularTarget(5.0, 5.0, 1.0, 1.0, 1.0)
    assert _most_windows_at_once([a, b], 10, 10, 2, 2.0) == 1
    assert _most_windows_at_once([a, b, c], 10, 10, 2, 2.0) == 2
    assert _most_windows_at_once([a, LinearTarget(-4.0, 5.0, 10.0, 0.0, 1.0)], 10, 10, 2, 2.0) == 2
    assert _most_windows_at_once([LinearTarget(100.0, 5.0, 10.0, 0.0, 1.0)], 10, 10, 2, 2.0) == 0


@pytest.mark.parametrize(
    ("star_field", "match"),
    [
        ({"drift_px_s": [1.0]}, r"star_field.drift_px_s must be two numbers \[vx, vy\] \(px/s\); got \[1.0\]"),
        ({"drift_px_s": [1, 2, 3]}, r"star_field.drift_px_s must be two numbers .*got \[1, 2, 3\]"),
        ({"drift_px_s": "fast"}, r"star_field.drift_px_s must be two numbers .*got 'fast'"),
        ({"drift_px_s": [True, 1.0]}, r"star_field.drift_px_s must be two numbers .*got \[True, 1.0\]"),
        ({"drift_arcsec_s": [1.0, "x"]}, r"star_field.drift_arcsec_s must be two numbers \[vx, vy\] \(arcsec/s\)"),
        ({"drift_px_s": [1.0, 0.0], "drift_arcsec_s": [1.0, 0.0]},
         r"star_field takes one of drift_px_s or drift_arcsec_s, not both; got drift_px_s=\[1.0, 0.0\], "
         r"drift_arcsec_s=\[1.0, 0.0\]"),
        ({"drift_px_s": [math.inf, 0.0]}, r"star_field.drift_px_s\[0\] must be finite; got inf"),
        ({"drift_arcsec_s": [0.0, math.nan]}, r"star_field.drift_arcsec_s\[1\] must be finite; got nan"),
        ({"drift_px_s": [10**400, 0]}, r"star_field.drift_px_s\[0\]: 100000000000\.\.\.\(401 digits\) does not fit"),
        # so many stars drift in that the field would not fit in memory
        ({"drift_px_s": [1e7, 0.0]}, r"star_field gives 1.16e\+07 stars \(> 1e\+06.*lower star_field.drift_px_s="
                                     r"\[10000000.0, 0.0\] \(it sweeps .* times the sensor area over 10 s\), "
                                     r"star_field.n_stars"),
    ],
)
def test_bad_drifts_name_the_key_and_value(star_field: dict, match: str) -> None:
    with pytest.raises(ScenarioError, match=match):
        build({"base": "geo-stare", "star_field": star_field})


def test_a_drift_too_fast_to_sample_is_refused_naming_it() -> None:
    # no random stars (a drift alone), one field-frame target: 1e9 px/s at 100 Hz would take
    # 4e7 sub-samples per sample
    s = {"sensor": {"preset": "davis346"}, "background": {"photon_rate_ph_s": 1e4},
         "sampling": {"rate_hz": 100.0}, "star_field": {"drift_px_s": [1e9, 0.0]},
         "targets": [{"kind": "static", "x_px": 10.0, "y_px": 10.0, "flux_ph_s": 1e6, "frame": "field"}]}
    with pytest.raises(ScenarioError, match=r"targets\[0\] \(frame='field', moved by star_field.drift_px_s="
                                            r"\[1000000000.0, 0.0\]\) moves 1e\+09 px/s.*> 1e\+09\)"):
        build(s)
    # a drifting field whose fine sampling would render too many windows per chunk
    fast = {"base": "geo-stare", "sensor": {"preset": "imx636", "bias_set": "none"},
            "star_field": {"n_stars": 20000, "drift_px_s": [3000.0, 0.0]}}
    with pytest.raises(ScenarioError, match=r"star_field \(moved by star_field.drift_px_s=\[3000.0, 0.0\]\) moves "
                                            r"3e\+03 px/s.*moving PSF windows"):
        build(fast, duration_s=1.0)
    with pytest.raises(ScenarioError, match=r"targets\[0\].frame must be one of 'sensor', 'field'; got 'sky'"):
        build({"base": "geo-stare", "targets": [{"kind": "static", "x_px": 1.0, "y_px": 1.0, "magnitude": 8.0,
                                                  "frame": "sky"}]})


@pytest.mark.parametrize(
    ("drift", "match"),
    [((1.0,), r"drift_px_s must be two numbers \[vx, vy\]; got drift_px_s=\(1.0,\)"),
     ((1.0, math.nan), r"drift_px_s must be finite; got drift_px_s=\(1.0, nan\)"),
     ((math.inf, 1.0), r"drift_px_s must be finite"),
     ("ab", r"drift_px_s must be two numbers"),
     ((True, False), r"drift_px_s must be two numbers")],
)
def test_bad_drifts_in_python(drift: object, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        random_star_field(10, 10, Optics(), n_stars=5, drift_px_s=drift, duration_s=1.0)  # type: ignore[arg-type]


def test_built_in_scenarios_are_unchanged_by_a_zero_drift() -> None:
    # A zero drift keeps the stars' random numbers, so the field and its events are the same.
    from evstwin.simulate import resolve_scenario

    plain = simulate("geo-stare", duration_s=0.3, num_threads=1)
    still = simulate(resolve_scenario("geo-stare", ["star_field.drift_px_s=[0.0, 0.0]"]), duration_s=0.3, num_threads=1)
    assert plain.n_events > 0
    assert plain.events.tobytes() == still.events.tobytes()
    assert list(plain.meta["truth"]) == ["geo"]


def test_a_drifting_field_simulates_with_the_satellites_truth_only() -> None:
    r = simulate({"base": "geo-stare", "star_field": {"drift_px_s": [-3.0, 3.2]}}, duration_s=0.5, num_threads=1)
    assert list(r.meta["truth"]) == ["geo"] and r.n_events > 0


def test_a_fast_drifting_field_sub_samples_sparsely_with_the_dense_events() -> None:
    """150 px/s at 250 Hz moves every star 0.72 px a sample: n_sub = 3 for the pixels near
    the stars only (sparse), or everywhere (dense); without noise both give the same events."""
    noise_free = {"photon_shot_noise": False, "dark_model": "none", "leak_rate_hz": 0.0, "shot_noise_rate_hz": 0.0,
                  "refractory_s": 0.0, "pr_pole": False}

    def run(sparse: bool):  # type: ignore[no-untyped-def]
        return simulate({
            # 128 x 96 with 12 stars: a unit of the fine-sampling decision (150 fine samples, the
            # whole run here) leaves most pixels coarse; on 64 x 48, 30 stars' paths cover it all.
            "name": "drift", "duration_s": 0.2, "sensor": {"preset": "davis346", "width": 128, "height": 96},
            "pixel": noise_free, "background": {"photon_rate_ph_s": 1e5}, "optics": {"extra_blur_sigma_px": 0.6},
            "sampling": {"rate_hz": 250.0, "sparse": sparse, "chunk_samples": 20},
            "star_field": {"n_stars": 12, "mag_min": -2.0, "mag_max": 2.0, "drift_px_s": [150.0, -100.0]},
        }, num_threads=1)

    sparse, dense = run(True), run(False)
    assert sparse.sub_sampled_chunks > 0 and sparse.n_events > 1000
    assert sparse.pixel_updates < 0.8 * dense.pixel_updates
    np.testing.assert_array_equal(sparse.events, dense.events)


# -- a field path (a slew) on top of the drift ---------------------------------------------------


def test_a_field_path_moves_field_targets_and_stars_by_its_offset() -> None:
    from evstwin.targets import FieldPath, PathTarget, StaticTarget, along_path

    path = FieldPath(np.array([1.0, 1.1, 1.2]), np.array([0.0, 0.0, 4.0]), np.array([0.0, -19.0, -20.0]))
    star = along_path(StaticTarget(50.0, 40.0, 1e8, label="s"), path)
    assert isinstance(star, PathTarget) and along_path(star, None) is star
    x, y = star.position_px(np.array([0.5, 1.0, 1.05, 1.15, 2.0]))
    np.testing.assert_allclose(x, [50.0, 50.0, 50.0, 52.0, 54.0])
    np.testing.assert_allclose(y, [40.0, 40.0, 30.5, 20.5, 20.0])
    vx, vy = star.velocity_px_s(np.array([0.5, 1.05, 1.15, 2.0]))
    np.testing.assert_allclose(vx, [0.0, 0.0, 40.0, 0.0])
    np.testing.assert_allclose(vy, [0.0, -190.0, -10.0, 0.0])
    assert star.max_speed_px_s(0.0, 0.9) == 0.0
    assert star.max_speed_px_s(0.0, 1.05) == pytest.approx(190.0)
    with pytest.raises(ValueError, match="path.t_s must be strictly increasing"):
        FieldPath(np.array([0.0, 0.0]), np.zeros(2), np.zeros(2))


def test_a_scenario_field_path_carries_frame_field_targets_and_the_random_stars() -> None:
    s = {"name": "slew", "duration_s": 0.3, "seed": 1, "sensor": {"preset": "davis346", "width": 64, "height": 48},
         "background": {"photon_rate_ph_s": 3.5e7}, "sampling": {"rate_hz": 200.0},
         "star_field": {"n_stars": 5, "mag_min": 6.0, "mag_max": 8.0, "seed": 3, "drift_px_s": [2.0, 0.0],
                        "path": {"t_s": [0.1, 0.15], "dx_px": [0.0, 0.0], "dy_px": [0.0, 10.0]}},
         "targets": [{"kind": "static", "label": "a", "frame": "field", "x_px": 30.0, "y_px": 10.0, "flux_ph_s": 1e9},
                     {"kind": "static", "label": "b", "x_px": 5.0, "y_px": 5.0, "flux_ph_s": 1e9}]}
    scene = build(s)
    a, b = scene.targets[0], scene.targets[1]
    x, y = a.position_px(np.array([0.0, 0.2]))
    np.testing.assert_allclose(x, [30.0, 30.4])
    np.testing.assert_allclose(y, [10.0, 20.0])
    np.testing.assert_allclose(b.position_px(np.array([0.2]))[1], [5.0])  # sensor frame: not moved
    for star in scene.targets[2:]:
        y0, y1 = star.position_px(np.array([0.0, 0.2]))[1]
        assert y1 - y0 == pytest.approx(10.0)
    result = simulate(s)
    assert result.sub_sampled_chunks > 0  # 200 px/s during the move
    s["star_field"]["path"] = {"t_s": [0.1], "dx_px": [0.0], "dy_px": [0.0]}
    with pytest.raises(ScenarioError, match="path.t_s needs at least 2 points"):
        build(s)
    s["star_field"]["path"] = {"t_s": [0.1, 0.2], "dx_px": [0.0, 1.0]}
    with pytest.raises(ScenarioError, match="star_field.path takes exactly t_s, dx_px, dy_px"):
        build(s)


@pytest.mark.parametrize("drift", [(0.0, 0.0), (30.0, -20.0)])
def test_a_field_path_brings_in_the_stars_beyond_the_field(drift: tuple[float, float]) -> None:
    # A slew of 60 px down and 40 px left: the stars on the sensor after it must be as many
    # (in distribution) as before, not the field's stars less the strips the slew emptied
    # (without the frame: -300 static, -190 with the drift). The counts differ by the stars
    # exchanged, ~2 x 0.02 (60 x 200 + 40 x 150) = 720 in variance: 4 sd = 107.
    # With a drift the frame is drawn around the drift-swept area too (sheared strips).
    from evstwin.targets import FieldPath, along_path, random_star_field

    optics = get_preset("davis346").optics(0.041, 1.8)
    w, h, density, duration = 200, 150, 2.0, 1.0  # 2 stars a 100 px^2: 600 on the sensor
    path = FieldPath(np.array([0.4, 0.5]), np.array([0.0, -40.0]), np.array([0.0, 60.0]))
    margin = float(np.hypot(40.0, 60.0))
    stars = random_star_field(w, h, optics, n_stars=int(density * w * h / 100), seed=5, drift_px_s=drift,
                              duration_s=duration, margin_px=margin)
    plain = random_star_field(w, h, optics, n_stars=int(density * w * h / 100), seed=5, drift_px_s=drift,
                              duration_s=duration)
    assert [t.label for t in stars[:len(plain)]] == [t.label for t in plain]  # the frame comes last
    moved = [along_path(t, path) for t in stars]

    def on_sensor(t_s: float) -> int:
        xy = np.array([t.position_px(np.array([t_s])) for t in moved])[:, :, 0]
        return int(np.sum((xy[:, 0] >= -0.5) & (xy[:, 0] < w - 0.5) & (xy[:, 1] >= -0.5) & (xy[:, 1] < h - 0.5)))

    before, after = on_sensor(0.0), on_sensor(0.9)
    assert abs(before - 600) < 5 * math.sqrt(600)
    assert abs(after - before) < 4 * math.sqrt(2 * 0.02 * (60 * 200 + 40 * 150)), (before, after)
    with pytest.raises(ValueError, match="margin_px must be"):
        random_star_field(w, h, optics, n_stars=10, margin_px=-1.0)
