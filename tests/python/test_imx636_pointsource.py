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
    # the recording's hot pixel, as an explicit map (the preset's draw is replaced)
    assert scene.hot_pixel_rates_hz is not None
    assert scene.hot_pixel_rates_hz[261, 187] == 1170.0 and np.count_nonzero(scene.hot_pixel_rates_hz) == 1
    # the preset's calibrated dark background is kept
    assert scene.params.shot_noise_on_rate_hz == 2.2e-4 and scene.params.shot_noise_off_rate_hz == 1.69e-3
    # overridden thresholds stay a sensible contrast step (20-30 %), OFF below ON
    assert 0.18 < scene.params.theta_off < scene.params.theta_on < 0.27


@pytest.mark.parametrize("t", [0.0, 2.5, 10.0])
def test_star_and_companions_drift_at_the_measured_rate(t: float) -> None:
    scene = build(NAME)
    x, y = scene.targets[0].position_px(np.array([t]))
    assert float(x[0]) == pytest.approx(STAR_T0_PX[0] + DRIFT_PX_S[0] * t, abs=1e-9)
    assert float(y[0]) == pytest.approx(STAR_T0_PX[1] + DRIFT_PX_S[1] * t, abs=1e-9)
    # the companions keep their offsets from the star (they belong to the field)
    for target, (dx, dy) in zip(scene.targets[1:], [(80.54, -52.90), (-91.40, 67.67)]):
        cx, cy = target.position_px(np.array([t]))
        assert float(cx[0] - x[0]) == pytest.approx(dx, abs=0.01)
        assert float(cy[0] - y[0]) == pytest.approx(dy, abs=0.01)


@pytest.mark.parametrize("t", [0.0, 5.0, 10.0])
def test_the_ghost_mirrors_the_star_through_the_measured_centre(t: float) -> None:
    # Measured on the recording (bench/make_imx636_pointsource.py, measure_ghost): its event
    # centroid per second runs from (772, 469) at a velocity of (2.30, -2.91) px/s, which is
    # the star's (-2.954, 3.428) times -0.819; a disc of 88 px with no obstruction shadow.
    scene = build(NAME)
    star, ghost = scene.targets[0], scene.targets[3]
    sx, sy = star.position_px(np.array([t]))
    gx, gy = ghost.position_px(np.array([t]))
    assert float(gx[0]) == pytest.approx(642.08 - 0.819 * (float(sx[0]) - 642.08), abs=1e-9)
    assert float(gy[0]) == pytest.approx(387.03 - 0.819 * (float(sy[0]) - 387.03), abs=1e-9)
    assert float(gx[0]) == pytest.approx(772.3 + 2.298 * t, abs=1.5)  # the measured line itself
    assert float(gy[0]) == pytest.approx(468.9 - 2.912 * t, abs=1.5)
    assert ghost.psf is not None and ghost.psf.params["radius_px"] == 84.0


def test_the_ghost_is_steady_at_its_share_of_the_stars_mean_light() -> None:
    # The real ghost fires ~6,000 events/s all through the run and none of the star's light
    # curve's bursts (bench/imx636_ghost_polarity.py): it keeps 0.3 of the star's mean flux.
    # The star's curve is scaled to a mean of 6e9 photons/s over its 10 ms points (the mean of
    # its table, by the trapezoid rule here, is within 1 % of it).
    scene = build(NAME)
    star, ghost = scene.targets[0], scene.targets[3]
    t = np.linspace(0.0, 10.77, 2155)
    star_flux = star.flux_ph_s(t)
    assert star_flux.max() / star_flux.min() > 100.0  # the star's curve does vary
    np.testing.assert_allclose(ghost.flux_ph_s(t), 0.3 * float(np.trapezoid(star_flux, t) / (t[-1] - t[0])), rtol=1e-3)
    assert float(ghost.flux_ph_s(np.array([5.0]))[0]) == pytest.approx(0.3 * 6e9, rel=0.01)


def test_short_window_simulates_and_its_star_drifts() -> None:
    res = simulate(NAME, duration_s=0.2, sets=[f"sensor.roi={list(ROI)}"])
    ev = res.events
    assert res.meta["width"] == ROI[2] and res.meta["height"] == ROI[3]
    assert len(ev) > 1000  # the scintillating star fires in every frame of its core
    assert 0 < int(res.n_on) < len(ev)
    assert int(ev["x"].max()) < ROI[2] and int(ev["y"].max()) < ROI[3]
    track = res.meta["truth"]["star"]
    t, x, y = track["t_s"], track["x_px"], track["y_px"]
    assert t[0] == 0.0 and t[-1] == pytest.approx(0.2, abs=0.01)
    # in the window's coordinates
    np.testing.assert_allclose(x, STAR_T0_PX[0] - ROI[0] + DRIFT_PX_S[0] * t, atol=1e-6)
    np.testing.assert_allclose(y, STAR_T0_PX[1] - ROI[1] + DRIFT_PX_S[1] * t, atol=1e-6)
    # the events within 15 px of the star's start are centred on it
    sx, sy = STAR_T0_PX[0] - ROI[0], STAR_T0_PX[1] - ROI[1]
    near = np.hypot(ev["x"] - sx, ev["y"] - sy) < 15.0
    assert near.sum() > 1000
    assert abs(float(ev["x"][near].mean()) - sx) < 1.0 and abs(float(ev["y"][near].mean()) - sy) < 1.0
