"""The built-in imx636-pointsource scenario (the EVK4 point-source recording as a scene).

The figures checked here were measured by hand on ../shared/data/imx636_pointsource_evt3.raw
(bench/make_imx636_pointsource.py); the tests do not read the recording."""

from __future__ import annotations

import numpy as np
import pytest

from evstwin.scenario import build, builtin_names
from evstwin.simulate import simulate

NAME = "imx636-pointsource"
STAR_T0_PX = (483.08, 287.11)
"""The star at t = 0, from its event centroid per 20 ms in the recording."""
DRIFT_PX_S = (-2.954, 3.428)
"""Its drift: the issue's 'about (-3, +3.2) px/s', measured over 0-10.5 s."""
ROI = (433, 257, 80, 80)
"""An 80 x 80 window around the star's first 0.2 s."""


def test_listed_and_built() -> None:
    assert NAME in builtin_names()
    scene = build(NAME)
    assert (scene.width, scene.height, scene.preset.name) == (1280, 720, "imx636")
    assert [t.label for t in scene.targets] == ["star", "companion1", "companion2", "ghost"]
    assert scene.duration_s == pytest.approx(10.77)
    # the recording's hot pixel and its leaky one, as an explicit map (the preset's draw is
    # replaced); the leaky pixel with its own chain (98 % ON, calibrate-noise's figures)
    assert scene.hot_pixel_rates_hz is not None
    assert scene.hot_pixel_rates_hz[261, 187] == 1170.0 and scene.hot_pixel_rates_hz[658, 1224] == 104.5
    assert np.count_nonzero(scene.hot_pixel_rates_hz) == 2
    assert list(scene.hot_pixel_chains) == [(1224, 658)]
    leaky = scene.hot_pixel_chains[(1224, 658)]
    assert leaky.on_share == 0.9823 and leaky.duty == pytest.approx(0.1018)
    # the preset's calibrated dark background is kept
    assert scene.params.shot_noise_on_rate_hz == 2.2e-4 and scene.params.shot_noise_off_rate_hz == 1.69e-3
    # overridden thresholds stay a sensible contrast step (20-30 %), OFF below ON
    assert 0.18 < scene.params.theta_off < scene.params.theta_on < 0.27


def star_line(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return STAR_T0_PX[0] + DRIFT_PX_S[0] * t, STAR_T0_PX[1] + DRIFT_PX_S[1] * t


def test_star_and_companions_drift_at_the_measured_rate_and_move_with_its_image() -> None:
    # The star follows the measured line plus its image motion (star_field.path, the event
    # centroid per 10 ms less the line, its mean over 0-10.4 s taken out): a few px about
    # the line, on it on average, then the slew (12 px of the real ~20 px: the centroid within
    # 25 px of the line loses part of it).
    scene = build(NAME)
    t = np.arange(0.0, 10.4, 0.005)
    x, y = scene.targets[0].position_px(t)
    lx, ly = star_line(t)
    assert np.abs(x - lx).max() < 15.0 and np.abs(y - ly).max() < 15.0
    assert 0.5 < np.std(y - ly) < 5.0  # it does move
    assert abs(float(np.mean(x - lx))) < 0.3 and abs(float(np.mean(y - ly))) < 0.3
    end = np.array([10.77])
    assert float(scene.targets[0].position_px(end)[1][0] - star_line(end)[1][0]) < -10.0  # the slew
    # the companions keep their offsets from the star (they belong to the field)
    for target, (dx, dy) in zip(scene.targets[1:3], [(80.54, -52.90), (-91.40, 67.67)]):
        cx, cy = target.position_px(t)
        np.testing.assert_allclose(cx - x, dx, atol=0.01)
        np.testing.assert_allclose(cy - y, dy, atol=0.01)


def test_the_ghost_mirrors_the_star_through_the_measured_centre() -> None:
    # Measured on the recording (bench/make_imx636_pointsource.py, measure_ghost): its event
    # centroid per second runs from (772, 469) at a velocity of (2.30, -2.91) px/s, which is
    # the star's (-2.954, 3.428) times -0.819; a disc of 88 px with no obstruction shadow.
    scene = build(NAME)
    star, ghost = scene.targets[0], scene.targets[-1]
    t = np.arange(0.0, 10.4, 0.01)
    sx, sy = star.position_px(t)
    gx, gy = ghost.position_px(t)
    np.testing.assert_allclose(gx, 642.08 - 0.819 * (sx - 642.08), atol=1e-9)
    np.testing.assert_allclose(gy, 387.03 - 0.819 * (sy - 387.03), atol=1e-9)
    # the measured line itself, on average (the image motion moves it about it)
    assert float(np.mean(gx - (772.3 + 2.298 * t))) == pytest.approx(0.0, abs=1.5)
    assert float(np.mean(gy - (468.9 - 2.912 * t))) == pytest.approx(0.0, abs=1.5)
    assert ghost.psf is not None and ghost.psf.params["radius_px"] == 84.0


def test_steady_star_with_a_halo_ghost_at_its_old_light_and_a_pre_roll() -> None:
    # The star is steady (its events come from its image motion and drift) at 3.6e10
    # photons/s; the optics' halo holds 0.417 of it (README, "A real point-source recording");
    # the ghost keeps 1.8e9 photons/s (0.05 of it), what it had as 0.3 of the old 6e9; and
    # the sensor watched the sky 12 s before t = 0.
    from evstwin.psf import CompositePSF

    scene = build(NAME)
    star, ghost = scene.targets[0], scene.targets[-1]
    t = np.linspace(0.0, 10.77, 50)
    np.testing.assert_allclose(star.flux_ph_s(t), 3.6e10)
    np.testing.assert_allclose(ghost.flux_ph_s(t), 1.8e9, rtol=1e-3)
    assert isinstance(scene.psf, CompositePSF) and scene.psf.halo_fraction == pytest.approx(0.417)
    assert scene.psf.halo.half_width_px == 512 and scene.psf.core.kind == "moffat"
    assert scene.pre_roll_s == 12.0 and scene.pre_roll_rate_hz == 20.0


def test_short_window_simulates_and_its_star_moves() -> None:
    # A 1 s pre-roll in place of the scenario's 12 s (the test above checks that value): the
    # window still starts after a pre-roll whose events are dropped, and the run takes ~2 s of
    # engine time in place of ~22 s (the 12 s at 20 Hz were nine tenths of it).
    res = simulate(NAME, duration_s=0.2, sets=[f"sensor.roi={list(ROI)}", "sampling.pre_roll_s=1"])
    ev = res.events
    assert res.meta["width"] == ROI[2] and res.meta["height"] == ROI[3]
    assert res.meta["pre_roll_s"] == pytest.approx(1.0)
    assert len(ev) > 1000  # the moving core fires in every frame
    assert 0 < int(res.n_on) < len(ev) and ev["t"].min() >= 0  # the pre-roll's events are dropped
    assert int(ev["x"].max()) < ROI[2] and int(ev["y"].max()) < ROI[3]
    track = res.meta["truth"]["star"]
    t, x, y = track["t_s"], track["x_px"], track["y_px"]
    assert t[0] == 0.0 and t[-1] == pytest.approx(0.2, abs=0.01)
    # in the window's coordinates: the scene's star shifted by the window's corner
    sx, sy = build(NAME).targets[0].position_px(t)
    np.testing.assert_allclose(x, sx - ROI[0], atol=1e-6)
    np.testing.assert_allclose(y, sy - ROI[1], atol=1e-6)
    # the events within 15 px of the star's mean position are centred near it
    mx, my = float(np.mean(x)), float(np.mean(y))
    near = np.hypot(ev["x"] - mx, ev["y"] - my) < 15.0
    assert near.sum() > 1000
    assert abs(float(ev["x"][near].mean()) - mx) < 2.0 and abs(float(ev["y"][near].mean()) - my) < 2.0
