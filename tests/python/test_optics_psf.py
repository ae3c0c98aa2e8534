"""Optics (photometry, geometry) and the erf PSF of paper eq. 17."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from evstwin.optics import (
    ZERO_POINT_V_PH_S_M2,
    Optics,
    broadband_zero_point_ph_s_m2,
)
from evstwin.psf import (
    PixelValues,
    pixel_fractions,
    render_frames,
    render_points,
    render_window,
    window_half_width_px,
)

SQ2 = math.sqrt(2.0)


def share(lo: float, hi: float, centre: float, sigma: float) -> float:
    """Hand formula: share of a 1-D Gaussian between lo and hi."""
    return 0.5 * (math.erf((hi - centre) / (SQ2 * sigma)) - math.erf((lo - centre) / (SQ2 * sigma)))


def eq17(i: int, j: int, x0: float, y0: float, flux: float, sigma: float) -> float:
    """Paper eq. 17 for pixel (row i, column j), pixel centres at integers."""
    return flux * share(j - 0.5, j + 0.5, x0, sigma) * share(i - 0.5, i + 0.5, y0, sigma)


# ---------------------------------------------------------------------------------------------
# optics


def test_paper_setup_geometry() -> None:
    o = Optics()  # 41 mm f/1.8 on a DAVIS346
    assert o.aperture_diameter_m == pytest.approx(0.041 / 1.8)
    assert o.collecting_area_m2 == pytest.approx(math.pi / 4 * (0.041 / 1.8) ** 2)
    assert o.plate_scale_rad_per_px == pytest.approx(18.5e-6 / 0.041)
    assert o.plate_scale_arcsec_per_px == pytest.approx(18.5e-6 / 0.041 * 206264.80624709636, rel=1e-12)
    # eq. 17: sigma = 0.45 Lambda N, tiny against an 18.5 um pixel (DESIGN.md point 9)
    assert o.diffraction_sigma_px == pytest.approx(0.45 * 0.7e-6 * 1.8 / 18.5e-6)
    assert o.psf_sigma_px == pytest.approx(0.0306, abs=1e-4)
    blurred = o.replace(extra_blur_sigma_px=0.8)
    assert blurred.psf_sigma_px == pytest.approx(math.hypot(o.diffraction_sigma_px, 0.8))
    assert o.principal_point_px == (172.5, 129.5)


def test_replace_rederives_the_aperture_unless_given() -> None:
    o = Optics()
    assert o.replace(f_number=4.0).aperture_diameter_m == pytest.approx(0.041 / 4.0)
    assert Optics(aperture_diameter_m=0.01).replace(f_number=4.0).aperture_diameter_m == 0.01


def test_obstruction_reduces_area() -> None:
    o = Optics(focal_length_m=1.0, f_number=5.0, obstruction_ratio=0.3)
    assert o.collecting_area_m2 == pytest.approx(math.pi / 4 * 0.2**2 * (1 - 0.09))


def test_magnitude_flux_round_trip_and_five_magnitudes_is_100x() -> None:
    o = Optics(transmission=0.8)
    mags = np.array([-1.0, 0.0, 3.3, 8.0, 15.0])
    flux = o.flux_from_magnitude(mags)
    np.testing.assert_allclose(o.magnitude_from_flux(flux), mags, rtol=0, atol=1e-12)
    assert o.flux_from_magnitude(5.0) * 100.0 == pytest.approx(o.flux_from_magnitude(0.0), rel=1e-12)
    assert o.flux_from_magnitude(0.0) == pytest.approx(ZERO_POINT_V_PH_S_M2 * o.collecting_area_m2 * 0.8)
    assert isinstance(o.flux_from_magnitude(1.0), float)


def test_v_band_zero_point() -> None:
    # 3640 Jy x 0.16 / h = 8.79e9 photons/s/m^2 (Bessell 1979, Huchra's table)
    assert ZERO_POINT_V_PH_S_M2 == pytest.approx(8.79e9, rel=1e-3)
    # the broadband integral over the V band (0.55 um +- 8 %) agrees with it
    assert broadband_zero_point_ph_s_m2(0.55e-6 * 0.92, 0.55e-6 * 1.08) == pytest.approx(
        ZERO_POINT_V_PH_S_M2, rel=0.02
    )
    assert 3e10 < broadband_zero_point_ph_s_m2(0.4e-6, 1.0e-6) < 6e10


def test_lab_source_projection_and_flux() -> None:
    o = Optics(focus_distance_m=0.63)
    v = 0.041 * 0.63 / (0.63 - 0.041)
    assert o.image_distance_m == pytest.approx(v)
    x, y = o.project_to_px(0.05, -0.02, 0.63)
    assert x == pytest.approx(172.5 + v / 18.5e-6 * 0.05 / 0.63)
    assert y == pytest.approx(129.5 - v / 18.5e-6 * 0.02 / 0.63)
    xs, _ys = o.project_to_px(np.zeros(3), np.zeros(3), np.array([0.5, 1.0, 2.0]))
    np.testing.assert_allclose(xs, 172.5)
    assert o.length_to_px(0.05, 0.63) == pytest.approx(x - 172.5)
    assert o.defocus_sigma_px(0.63) == pytest.approx(0.0, abs=1e-9)
    assert o.defocus_sigma_px(0.70) > 1.0
    assert o.flux_from_intensity(1e12, 0.63) == pytest.approx(1e12 * o.collecting_area_m2 / 0.63**2)


def test_sky_background() -> None:
    o = Optics()
    expected = (
        ZERO_POINT_V_PH_S_M2 * 10 ** (-0.4 * 21.0) * o.plate_scale_arcsec_per_px**2 * o.collecting_area_m2
    )
    assert o.background_ph_s_per_px(21.0) == pytest.approx(expected)
    assert o.background_ph_s_per_px(16.0) == pytest.approx(100 * o.background_ph_s_per_px(21.0))


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"focal_length_m": -0.04}, "focal_length_m"),
        ({"f_number": 0.0}, "f_number"),
        ({"f_number": float("nan")}, "f_number"),
        ({"pixel_pitch_m": 0.0}, "pixel_pitch_m"),
        ({"transmission": 1.5}, "transmission"),
        ({"extra_blur_sigma_px": -1.0}, "extra_blur_sigma_px"),
        ({"obstruction_ratio": 1.0}, "obstruction_ratio"),
        ({"focus_distance_m": 0.01}, "focus_distance_m"),
        ({"aperture_diameter_m": -1.0}, "aperture_diameter_m"),
        ({"width_px": 0}, "width_px"),
    ],
)
def test_optics_validation(kwargs: dict, name: str) -> None:
    with pytest.raises(ValueError, match=name):
        Optics(**kwargs)


def test_photometry_validation() -> None:
    o = Optics()
    with pytest.raises(ValueError, match="flux_ph_s"):
        o.magnitude_from_flux(0.0)
    with pytest.raises(ValueError, match="mag"):
        o.flux_from_magnitude(float("nan"))
    with pytest.raises(ValueError, match="z_m"):
        o.project_to_px(0.0, 0.0, -1.0)


# ---------------------------------------------------------------------------------------------
# PSF: eq. 17 by hand


@pytest.mark.parametrize("normalize", [False, True])
def test_source_at_pixel_centre_matches_eq17(normalize: bool) -> None:
    sigma, flux = 0.7, 1000.0
    img = render_points(21, 17, 10.0, 8.0, flux, sigma, normalize=normalize)
    rtol = 1e-12 if not normalize else 2e-6
    for i, j in [(8, 10), (8, 11), (7, 10), (9, 12), (6, 7), (8, 14)]:
        assert img[i, j] == pytest.approx(eq17(i, j, 10.0, 8.0, flux, sigma), rel=rtol)
    # the centre pixel by hand: erf(0.5 / (sqrt 2 sigma))^2
    assert img[8, 10] == pytest.approx(flux * math.erf(0.5 / (SQ2 * sigma)) ** 2, rel=rtol)
    # symmetric
    assert img[8, 9] == pytest.approx(img[8, 11], rel=1e-12)
    assert img[7, 10] == pytest.approx(img[9, 10], rel=1e-12)


def test_source_at_pixel_corner_splits_into_four() -> None:
    sigma, flux = 0.5, 400.0
    x0, y0 = 4.5, 3.5  # the corner shared by pixels (3, 4), (3, 5), (4, 4), (4, 5)
    img = render_points(10, 8, x0, y0, flux, sigma, normalize=False)
    quarter = flux * (0.5 * math.erf(1.0 / (SQ2 * sigma))) ** 2
    for i, j in [(3, 4), (3, 5), (4, 4), (4, 5)]:
        assert img[i, j] == pytest.approx(quarter, rel=1e-12)
        assert img[i, j] == pytest.approx(eq17(i, j, x0, y0, flux, sigma), rel=1e-12)
    assert img[2, 4] == pytest.approx(eq17(2, 4, x0, y0, flux, sigma), rel=1e-12)


def test_far_tail_keeps_relative_precision() -> None:
    sigma = 0.6
    img = render_points(30, 30, 15.0, 15.0, 1.0, sigma, normalize=False, window_sigmas=8.0)
    j = 15 + 4  # pixel [3.5, 4.5] px = [5.8, 7.5] sigma from the centre
    expected = (
        0.5
        * (math.erfc(3.5 / (SQ2 * sigma)) - math.erfc(4.5 / (SQ2 * sigma)))
        * math.erf(0.5 / (SQ2 * sigma))
    )
    assert expected < 1e-8
    assert img[15, j] == pytest.approx(expected, rel=1e-10)


def test_flux_conserved_for_a_source_on_the_sensor() -> None:
    img = render_points(40, 30, 17.3, 12.8, 1e9, 1.3)
    assert img.sum() == pytest.approx(1e9, rel=1e-12)
    # without renormalisation the 5-sigma tail is lost: at most 2 erfc(5 / sqrt 2) = 1.15e-6
    raw = render_points(40, 30, 17.3, 12.8, 1e9, 1.3, normalize=False)
    assert 0.0 <= 1e9 - raw.sum() <= 1e9 * 2 * math.erfc(5 / SQ2)


@pytest.mark.parametrize("normalize", [False, True])
def test_source_near_edge_deposits_its_in_sensor_share(normalize: bool) -> None:
    w, h, x0, y0, sigma, flux = 30, 20, 0.2, 18.9, 1.1, 5e6
    img = render_points(w, h, x0, y0, flux, sigma, normalize=normalize)
    on_sensor = flux * share(-0.5, w - 0.5, x0, sigma) * share(-0.5, h - 0.5, y0, sigma)
    assert on_sensor < 0.6 * flux  # a corner: much of the PSF is off the sensor
    assert img.sum() == pytest.approx(on_sensor, rel=3e-6)


def test_window_agrees_with_full_sensor_rendering() -> None:
    rng = np.random.default_rng(3)
    x = rng.uniform(-2, 52, 12)
    y = rng.uniform(-2, 42, 12)
    flux = rng.uniform(1e3, 1e6, 12)
    sigma = 1.7
    windowed = render_points(50, 40, x, y, flux, sigma)
    full = render_points(50, 40, x, y, flux, sigma, window_sigmas=100.0, normalize=False)  # covers the sensor
    np.testing.assert_allclose(windowed, full, rtol=0, atol=2e-6 * flux.max())
    # and every pixel agrees with eq. 17 summed over the sources
    i, j = 20, 25
    by_hand = sum(eq17(i, j, xs, ys, f, sigma) for xs, ys, f in zip(x, y, flux))
    assert full[i, j] == pytest.approx(by_hand, rel=1e-10)


def test_sparse_window_equals_dense() -> None:
    x = np.array([3.2, 3.9, 60.0, -40.0])  # two overlapping, one inside, one far off the sensor
    y = np.array([5.5, 6.1, 30.2, 10.0])
    flux = np.array([1.0, 2.0, 3.0, 4.0])
    dense = render_points(64, 48, x, y, flux, 0.9)
    sparse = render_window(64, 48, x, y, flux, 0.9)
    assert isinstance(sparse, PixelValues)
    assert np.all(np.diff(sparse.flat_index) > 0)
    rebuilt = np.zeros(64 * 48)
    rebuilt[sparse.flat_index] = sparse.value
    np.testing.assert_allclose(rebuilt.reshape(48, 64), dense, rtol=1e-14, atol=0)
    yy, xx = np.divmod(sparse.flat_index, 64)
    assert xx.max() <= 63 and yy.max() <= 47 and xx.min() >= 0


def test_render_cost_does_not_grow_with_sensor_size() -> None:
    sigma = 0.8
    half = window_half_width_px(sigma)
    assert half == 4
    small = render_window(20, 20, 9.3, 10.6, 1.0, sigma)
    huge = render_window(100_000, 100_000, 5000.3, 7000.6, 1.0, sigma)
    assert small.flat_index.size == huge.flat_index.size == (2 * half + 1) ** 2
    np.testing.assert_allclose(small.value, huge.value, rtol=1e-9)
    # the minimum window is +-2 px even for the diffraction-limited 0.03 px PSF
    assert render_window(20, 20, 9.0, 9.0, 1.0, 0.03).flat_index.size == 25


def test_scattered_sources_on_a_large_sensor() -> None:
    # far-apart sources: accumulated pixel by pixel, not through a sensor-sized buffer
    x, y, flux = [10.2, 1990.7, 10.2], [10.0, 1490.4, 10.0], [1.0, 2.0, 3.0]
    for dtype in (np.float64, np.float32):
        out = np.zeros((1500, 2000), dtype)
        render_points(2000, 1500, x, y, flux, 0.8, out=out)
        sparse = render_window(2000, 1500, x, y, flux, 0.8)
        np.testing.assert_allclose(out.reshape(-1)[sparse.flat_index], sparse.value, rtol=1e-6)
        assert float(out.sum(dtype=np.float64)) == pytest.approx(6.0, rel=1e-6)


def test_zero_flux_and_off_sensor_sources_touch_nothing() -> None:
    assert render_window(10, 10, 5.0, 5.0, 0.0, 1.0).flat_index.size == 0
    assert render_window(10, 10, 1e12, -1e12, 1.0, 1.0).flat_index.size == 0
    assert render_points(10, 10, [], [], [], 1.0).sum() == 0.0


def test_render_points_adds_into_out() -> None:
    out = np.full((8, 9), 2.0, np.float32)
    res = render_points(9, 8, 4.0, 4.0, 10.0, 0.5, out=out)
    assert res is out
    assert float(out.sum()) == pytest.approx(2.0 * 72 + 10.0, rel=1e-6)


def test_render_frames_matches_per_frame_rendering() -> None:
    t_count, s_count, w, h = 4, 3, 25, 18
    rng = np.random.default_rng(0)
    x = rng.uniform(0, w, (t_count, s_count))
    y = rng.uniform(0, h, (t_count, s_count))
    flux = np.array([1e3, 2e3, 5e3])  # constant per source: broadcast over T
    bg = rng.uniform(0, 5, (h, w))
    frames = render_frames(w, h, x, y, flux, 0.9, background_ph_s=bg)
    assert frames.shape == (t_count, h, w) and frames.dtype == np.float64
    for t in range(t_count):
        expected = render_points(w, h, x[t], y[t], flux, 0.9) + bg
        np.testing.assert_allclose(frames[t], expected, rtol=1e-13, atol=1e-12)
    f32 = render_frames(w, h, x, y, flux, 0.9, background_ph_s=bg, dtype=np.float32)
    assert f32.dtype == np.float32
    np.testing.assert_allclose(f32, frames, rtol=1e-6)
    per_sample_bg = render_frames(
        w, h, x[:, :0], y[:, :0], 1.0, 1.0, background_ph_s=np.arange(4.0)[:, None, None]
    )
    np.testing.assert_array_equal(per_sample_bg[:, 0, 0], np.arange(4.0))


def test_pixel_fractions_sum_to_one() -> None:
    fr = pixel_fractions([0.0, 0.3], 1.0, -20, 41)
    np.testing.assert_allclose(fr.sum(axis=1), 1.0, rtol=1e-13)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: render_points(10, 10, 1.0, 1.0, -5.0, 1.0), "flux_ph_s"),
        (lambda: render_points(10, 10, float("nan"), 1.0, 5.0, 1.0), "x_px"),
        (lambda: render_points(10, 10, 1.0, np.inf, 5.0, 1.0), "y_px"),
        (lambda: render_points(10, 10, 1.0, 1.0, 5.0, 0.0), "sigma_px"),
        (lambda: render_points(0, 10, 1.0, 1.0, 5.0, 1.0), "width"),
        (lambda: render_points(10, 10, [1.0, 2.0], [1.0, 2.0, 3.0], 5.0, 1.0), "broadcast"),
        (lambda: render_points(10, 10, 1.0, 1.0, 5.0, 1.0, window_sigmas=0.0), "window_sigmas"),
        (lambda: render_points(10, 10, 1.0, 1.0, 5.0, 1.0, out=np.zeros((10, 9))), "shape"),
        (lambda: render_frames(10, 10, np.zeros(3), np.zeros(3), 1.0, 1.0), r"\(T, S\)"),
        (
            lambda: render_frames(10, 10, np.zeros((2, 1)), np.zeros((2, 1)), 1.0, 1.0, -1.0),
            "background_ph_s",
        ),
        (
            lambda: render_frames(10, 10, np.zeros((2, 1)), np.zeros((2, 1)), 1.0, 1.0, np.zeros(3)),
            "background_ph_s",
        ),
    ],
)
def test_psf_validation(call, match: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError, match=match):
        call()


def test_image_coordinates_that_overflow_are_a_value_error() -> None:
    # A distance of 5e-324 m made inf pixels with a RuntimeWarning (found by the scenario fuzz).
    from evstwin.presets import get_preset

    optics = get_preset("davis346").optics(0.041, 1.8)
    with pytest.raises(ValueError, match=r"length_m / distance_m give image coordinates that overflow a 64-bit float"):
        optics.length_to_px(0.01, 5e-324)
    with pytest.raises(ValueError, match=r"x_m, y_m, z_m give image coordinates that overflow"):
        optics.project_to_px(1e300, 0.0, 1e-300)
    assert math.isfinite(float(optics.length_to_px(0.01, 0.63)))


def test_psf_windows_too_wide_for_memory_are_refused() -> None:
    # A sigma of 1000 px rendered a 10001 x 10001 window per source (2.5 GB) before clipping.
    from evstwin.psf import MAX_WINDOW_HALF_PX, render_points, window_half_width_px

    assert window_half_width_px(100.0) == 500 and MAX_WINDOW_HALF_PX == 2048
    with pytest.raises(ValueError, match=r"window_sigmas x sigma_px must be at most 2048 px.*sigma_px=1000.0"):
        window_half_width_px(1000.0)
    with pytest.raises(ValueError, match="sigma_px=10000.0"):
        render_points(8, 8, [1.0], [1.0], [1e6], 1e4)


@pytest.mark.parametrize(("name", "value"), [("focal_length_m", 1e-300), ("f_number", 5e-324), ("pixel_pitch_m", 1e300),
                                             ("mean_wavelength_m", 2.0), ("zero_point_ph_s_m2", 1e300)])
def test_optics_outside_physical_ranges_are_refused(name: str, value: float) -> None:
    # A focal length of 1e-300 m overflowed the plate scale and the sky background (fuzzing).
    with pytest.raises(ValueError, match=rf"{name} must be in \[.*\] \(a physical range.*got {name}={re.escape(repr(value))}"):
        Optics(**{name: value})
