"""PSF shapes beyond the Gaussian (issue 9): Airy of an obstructed pupil with spider vanes,
Moffat, and a PSF image, checked against formulas computed here, not by the renderer."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import j0, j1
from test_simulate import spinning

from evstwin.optics import Optics
from evstwin.psf import (
    CompositePSF,
    GaussianPSF,
    KernelPSF,
    airy_psf,
    from_optics,
    halo_psf,
    image_psf,
    load_psf_image,
    moffat_enclosed_energy,
    moffat_psf,
    render_frames,
    render_points,
    render_window,
    taper_width_px,
)
from evstwin.scenario import ScenarioError, build
from evstwin.simulate import simulate

SQ2 = math.sqrt(2.0)


def airy_ee(r_px: float, lam_n_px: float, eps: float = 0.0) -> float:
    """Encircled energy of an annular pupil (Mahajan 1986, JOSA A 3, 470, eq. 12; eps = 0 is
    the Airy formula 1 - J0(v)^2 - J1(v)^2), v = pi r / (lambda N)."""
    v = math.pi * r_px / lam_n_px
    ee = 1.0 - j0(v) ** 2 - j1(v) ** 2
    if eps == 0.0:
        return float(ee)
    cross = quad(lambda t: j1(t) * j1(eps * t) / t, 0.0, v, limit=400)[0]
    return float((ee + eps**2 * (1.0 - j0(eps * v) ** 2 - j1(eps * v) ** 2) - 4.0 * eps * cross) / (1.0 - eps**2))


def fine_ee(shape: KernelPSF, r_px: float) -> tuple[float, np.ndarray]:
    """Flux of the cells (1 / k px) whose centres lie within r, and every cell's radius."""
    n = shape.fine.shape[0]
    c = (np.arange(n) + 0.5 - n / 2) / shape.subpixel
    r = np.hypot(c[None, :], c[:, None])
    return float(shape.fine[r <= r_px].sum()), r


def gaussian_image(sigma_px: float, oversampling: int, n: int) -> np.ndarray:
    """A Gaussian integrated over the pixels of an n x n image 1 / oversampling px wide."""
    edges = (np.arange(n + 1) - n / 2) / oversampling
    cdf = np.array([0.5 * math.erfc(-e / (SQ2 * sigma_px)) for e in edges])
    p = np.diff(cdf)
    return np.outer(p, p)


SHAPES = {
    "gaussian": lambda: GaussianPSF(1.3),
    "airy": lambda: airy_psf(1.5),
    "airy-obstructed-spider-blur": lambda: airy_psf(1.1, 0.35, 4, 0.02, 30.0, 0.7),
    "moffat": lambda: moffat_psf(3.0, 2.5),
    "image": lambda: image_psf(gaussian_image(1.0, 4, 40), 4),
    "airy+halo": lambda: CompositePSF(airy_psf(1.5), halo_psf(6.0, 1.5, 32), 0.2),
}


@pytest.mark.parametrize("name", SHAPES)
def test_flux_conserved_for_every_shape(name: str) -> None:
    shape = SHAPES[name]()
    rng = np.random.default_rng(3)
    x = 100.0 + rng.uniform(-0.5, 0.5, 6)
    y = 90.0 + rng.uniform(-0.5, 0.5, 6)
    flux = rng.uniform(1e3, 1e6, 6)
    img = render_points(200, 180, x, y, flux, shape)
    assert img.sum() == pytest.approx(flux.sum(), rel=1e-12)
    assert render_window(200, 180, x, y, flux, shape).value.sum() == pytest.approx(flux.sum(), rel=1e-12)
    frames = render_frames(200, 180, x.reshape(2, 3), y.reshape(2, 3), flux.reshape(2, 3), shape)
    np.testing.assert_allclose(frames.sum(axis=(1, 2)), flux.reshape(2, 3).sum(axis=1), rtol=1e-12)
    # Sources are independent: two renders add up to the render of both.
    both = render_points(200, 180, x[:2], y[:2], flux[:2], shape)
    one = render_points(200, 180, x[0], y[0], flux[0], shape) + render_points(200, 180, x[1], y[1], flux[1], shape)
    np.testing.assert_allclose(both, one, rtol=1e-12, atol=1e-12 * flux[:2].sum())


def test_airy_encircled_energy_matches_the_airy_formula() -> None:
    lam = 3.0
    shape = airy_psf(lam, half_width_px=30)
    for r in (0.9, 1.83, 3.66, 6.0, 12.0, 25.0):  # 3.66 px: the first dark ring, 1.22 lambda N
        got, _ = fine_ee(shape, r)
        # Tolerance from the grid: counting whole cells 1/8 px wide, those the circle cuts lie
        # within sqrt(2)/16 px of r, so the count is off by at most the flux in that annulus;
        # plus 2e-4 for the pupil's 256 samples and the cells' centre-point sums.
        d = SQ2 / (2 * shape.subpixel)
        tol = airy_ee(r + d, lam) - airy_ee(r - d, lam) + 2e-4
        assert abs(got - airy_ee(r, lam)) <= tol, (r, got, airy_ee(r, lam), tol)
    # The PSF is cut where the formula says: the taper keeps all within h - w and nothing past h.
    h, w = shape.half_width_px, taper_width_px(shape.half_width_px)
    assert airy_ee(h - w, lam) < shape.captured_fraction < airy_ee(h, lam)


def test_airy_pixels_match_the_formula_integrated_over_pixels() -> None:
    lam = 3.0
    shape = airy_psf(lam, half_width_px=12)
    img = render_points(25, 25, 12.0, 12.0, 1.0, shape) * shape.captured_fraction
    sub = (np.arange(24) + 0.5) / 24 - 0.5
    for i, j in ((12, 12), (12, 13), (13, 14), (12, 16), (15, 17)):
        dx = (j - 12) + sub[None, :]
        dy = (i - 12) + sub[:, None]
        v = np.maximum(math.pi * np.hypot(dx, dy) / lam, 1e-12)
        # Unit flux: peak pi/4 per (lambda N)^2 (the pupil area in D^2 over (lambda N)^2).
        expect = float(np.mean((2.0 * j1(v) / v) ** 2)) * math.pi / 4.0 / lam**2
        assert img[i, j] == pytest.approx(expect, rel=2e-3, abs=2e-6), (i, j)


def test_obstruction_moves_energy_from_the_core_to_the_rings() -> None:
    lam, eps = 8.0, 0.5
    clear = airy_psf(lam, 0.0, half_width_px=20)
    obstructed = airy_psf(lam, eps, half_width_px=20)
    # Central intensity for the same total flux scales as (1 - eps^2) (Schroeder, Astronomical
    # Optics, sec. 10.2: I(0) = E A / (lambda f)^2 with A the open area). The centre pixel
    # averages the core over +-0.5 px, v_a = pi 0.5 / lambda N: the obstructed core is
    # narrower, 1 - (1 + eps^2) v^2 / 4 against 1 - v^2 / 4, so the pixel ratio is lower
    # by eps^2 <v^2> / 4 = eps^2 v_a^2 / 6 (0.16 % here).
    k = clear.subpixel // 2  # the phase of a source at a pixel centre
    peak0 = clear.table[k, k].max() * clear.captured_fraction
    peak1 = obstructed.table[k, k].max() * obstructed.captured_fraction
    v_a = math.pi * 0.5 / lam
    assert peak1 / peak0 == pytest.approx((1.0 - eps**2) * (1.0 - eps**2 * v_a**2 / 6.0), rel=2e-4)
    # Inside the first dark ring of the clear pupil the obstructed one holds less, and its
    # encircled energy follows the annular-pupil formula.
    assert fine_ee(obstructed, 1.22 * lam)[0] < fine_ee(clear, 1.22 * lam)[0] - 0.1
    small = airy_psf(3.0, eps, half_width_px=25)
    d = SQ2 / (2 * small.subpixel)
    for r in (2.0, 3.0, 10.0, 20.0):
        tol = airy_ee(r + d, 3.0, eps) - airy_ee(r - d, 3.0, eps) + 3e-4
        assert abs(fine_ee(small, r)[0] - airy_ee(r, 3.0, eps)) <= tol, r


def _wedge_means(img: np.ndarray, centre: float, angles_deg: list[float]) -> np.ndarray:
    yy, xx = np.mgrid[0 : img.shape[0], 0 : img.shape[1]] - centre
    ang = np.degrees(np.arctan2(yy, xx)) % 360.0
    rad = np.hypot(xx, yy)
    ring = (rad > 12) & (rad < 36)
    return np.array([img[ring & (np.abs((ang - a + 180.0) % 360.0 - 180.0) < 3.0)].mean() for a in angles_deg])


def test_spider_vanes_make_spikes_perpendicular_to_them() -> None:
    # Three vanes at 10, 130, 250 deg (from +x towards +y): each spreads light perpendicular to
    # itself, both ways: spikes at 100, 280, 220, 40, 340, 160 deg; the vanes' own directions
    # lie 30 deg from every spike.
    shape = airy_psf(2.0, 0.3, 3, 0.03, 10.0, half_width_px=40)
    img = render_points(81, 81, 40.0, 40.0, 1.0, shape)
    spikes = _wedge_means(img, 40.0, [40.0, 100.0, 160.0, 220.0, 280.0, 340.0])
    between = _wedge_means(img, 40.0, [10.0, 70.0, 130.0, 190.0, 250.0, 310.0])
    assert spikes.min() > 2.0 * between.max()  # 2.6x: the spikes hold ~1e-3 of the flux at 12-36 px
    # Rotating the spider rotates the spikes; no vanes, no spikes (round to 10 %).
    turned = _wedge_means(render_points(81, 81, 40.0, 40.0, 1.0, airy_psf(2.0, 0.3, 3, 0.03, 40.0, half_width_px=40)),
                          40.0, [70.0, 130.0, 190.0])
    assert turned.min() > 2.0 * between.max()
    plain = _wedge_means(render_points(81, 81, 40.0, 40.0, 1.0, airy_psf(2.0, 0.3, half_width_px=40)), 40.0,
                         [40.0, 100.0, 10.0, 70.0])
    assert plain.max() < 1.1 * plain.min()


def test_moffat_fwhm_and_enclosed_energy() -> None:
    fwhm, beta = 10.0, 3.0
    shape = moffat_psf(fwhm, beta)
    alpha = fwhm / (2.0 * math.sqrt(2.0 ** (1.0 / beta) - 1.0))
    n = 2 * shape.half_width_px + 1
    c = float(shape.half_width_px)
    img = render_points(n, n, c, c, 1.0, shape) * shape.captured_fraction
    row = img[shape.half_width_px]
    # Peak = (beta - 1) / (pi alpha^2) per px^2; a 1 px pixel averages it down by the profile's
    # curvature, 1 - beta / (6 alpha^2) to first order (6e-3 here).
    peak = (beta - 1.0) / (math.pi * alpha**2)
    assert row.max() == pytest.approx(peak * (1.0 - beta / (6.0 * alpha**2)), rel=1e-3)
    # FWHM from the row through the centre, by linear interpolation of the half maximum
    # (the pixel averaging above changes it by ~1e-3; interpolation on a 1 px grid by < 0.5 %).
    right = row[shape.half_width_px :]
    i = int(np.argmax(right < 0.5 * right[0]))
    half_right = (i - 1) + (right[i - 1] - 0.5 * right[0]) / (right[i - 1] - right[i])
    assert 2.0 * half_right == pytest.approx(fwhm, rel=5e-3)
    for r in (2.0, 5.0, 10.0, 20.0):
        d = SQ2 / (2 * shape.subpixel)
        e = moffat_enclosed_energy([r - d, r, r + d], fwhm, beta)
        assert abs(fine_ee(shape, r)[0] - e[1]) <= e[2] - e[0] + 1e-4, r
    # The default window's taper starts where 1 - EE = 1 %, in the smallest such window.
    h, w = shape.half_width_px, taper_width_px(shape.half_width_px)
    assert moffat_enclosed_energy(h - w, fwhm, beta) >= 0.99 > moffat_enclosed_energy(h - 1.0 - w, fwhm, beta)
    ee = moffat_enclosed_energy([h - w, h], fwhm, beta)
    assert ee[0] < shape.captured_fraction < ee[1]
    # Heavy wings reach the 128 px cap: captured_fraction says what the window keeps.
    heavy = moffat_psf(3.0, 1.2, subpixel=2)
    assert heavy.half_width_px == 128
    ee = moffat_enclosed_energy([128.0 - 16.0, 128.0], 3.0, 1.2)
    assert ee[0] < heavy.captured_fraction < ee[1] < 0.9  # 0.82 within 128 px: far from 99 %


def test_halo_is_a_moffat_of_its_share_added_to_the_core() -> None:
    # Optics' scattered-light halo: the core keeps 1 - f of the flux, a Moffat of FWHM 12 px,
    # beta 1.5 holds f; far from the core the halo's pixels follow the Moffat density
    # (beta - 1) / (pi alpha^2) (1 + r^2 / alpha^2)^-beta, divided by what its window keeps.
    f, fwhm, beta = 0.1, 12.0, 1.5
    optics = Optics(psf="airy", halo_fraction=f, halo_fwhm_px=fwhm, halo_beta=beta, halo_half_width_px=128)
    shape = from_optics(optics)
    assert isinstance(shape, CompositePSF) and shape.half_width_px == 128
    core = from_optics(optics.replace(halo_fraction=0.0, halo_fwhm_px=None))
    assert isinstance(core, KernelPSF) and core.kind == "airy"
    x, y, flux = 150.3, 140.6, 1e6
    img = render_points(300, 280, x, y, flux, shape)
    assert img.sum() == pytest.approx(flux, rel=1e-12)
    halo = render_points(300, 280, x, y, flux, halo_psf(fwhm, beta, 128))
    np.testing.assert_allclose(img, render_points(300, 280, x, y, (1.0 - f) * flux, core) + f * halo,
                               rtol=1e-12, atol=1e-12 * flux)
    alpha = fwhm / (2.0 * math.sqrt(2.0 ** (1.0 / beta) - 1.0))
    kept = shape.halo.captured_fraction
    assert 1.0 - (1.0 + 112.0**2 / alpha**2) ** (1.0 - beta) < kept < 1.0 - (1.0 + 128.0**2 / alpha**2) ** (1.0 - beta)
    for dx in (20, 40, 70, 100):
        r2 = (150 + dx - x) ** 2 + (141 - y) ** 2
        density = (beta - 1.0) / (math.pi * alpha**2) * (1.0 + r2 / alpha**2) ** (-beta)
        assert img[141, 150 + dx] == pytest.approx(f * flux * density / kept, rel=2e-3), dx
    # Far out the halo is the light: the core (an Airy pattern of lambda N = 0.07 px) has none.
    assert img[141, 250] > 0.99 * f * halo[141, 250]


def test_seeing_blurs_the_core_and_keeps_the_halo() -> None:
    from evstwin.sky.atmosphere import seeing_psf

    optics = Optics(psf="airy", focal_length_m=2.0, f_number=8.0, halo_fraction=0.05, halo_fwhm_px=10.0,
                    halo_half_width_px=64)
    both = seeing_psf(optics, 3.0)
    plain = seeing_psf(optics.replace(halo_fraction=0.0, halo_fwhm_px=None), 3.0)
    assert isinstance(both, CompositePSF) and both.core is plain and both.halo is halo_psf(10.0, 1.5, 64)
    assert both.halo_fraction == 0.05


def test_image_psf_of_a_gaussian_reproduces_the_gaussian_render(tmp_path: Path) -> None:
    sigma = 1.0
    path = tmp_path / "psf.npy"
    np.save(path, 7.0 * gaussian_image(sigma, 4, 48))  # any scale: the image is normalised
    shape = image_psf(load_psf_image(path), 4)
    # Default window: the taper starts past the image's corners (sqrt 2 x 6 px, 8/7 of it: 10 px).
    assert shape.half_width_px == 10 and shape.captured_fraction == pytest.approx(1.0, abs=1e-12)
    rng = np.random.default_rng(5)
    x = 20.0 + rng.uniform(-0.5, 0.5, 40)
    y = 21.0 + rng.uniform(-0.5, 0.5, 40)
    peak = 0.0
    for xi, yi in zip(x, y, strict=True):
        got = render_points(41, 41, xi, yi, 1.0, shape)
        expect = render_points(41, 41, xi, yi, 1.0, sigma, window_sigmas=6.0)
        peak = max(peak, float(np.abs(got - expect).max()) / float(expect.max()))
    # Two errors, bounded from the Gaussian itself (sigma = 1 px, unit flux, peak pixel
    # m^2 with m = erf(0.5 / sqrt 2) = 0.383, the share of a 1 px row):
    # - the image's pixels (d = 1/4 px) are taken as uniform: where a sensor pixel's edge cuts
    #   one (odd phases at k = 8), each side gets half, misplacing d^2 / 8 |dI/dx| per unit of
    #   edge; a pixel's two edges, integrated over its row, move at most 2 d^2 / 8 m phi'_max,
    #   phi'_max = phi(1) = 0.242; for each axis;
    # - bilinear interpolation between phases 1/8 px apart: (1/8)^2 / 8 |V''|, with |V''| at
    #   most 2 * 0.5 phi(0.5) m in the pixel at the centre.
    m = math.erf(0.5 / SQ2)
    phi = lambda t: math.exp(-0.5 * t * t) / math.sqrt(2.0 * math.pi)  # noqa: E731
    resample = 2.0 * (0.25**2 / 8.0) * m * phi(1.0) / m**2
    interpolation = (1.0 / 8.0) ** 2 / 8.0 * (2.0 * 0.5 * phi(0.5) * m) / m**2
    assert peak < 2.0 * resample + interpolation  # 0.0216; measured 0.013
    # At the tabulated phases the image's own pixel boundaries fall on the cells': exact.
    for fx in (-0.5, -0.25, 0.0, 0.25):
        got = render_points(41, 41, 20.0 + fx, 21.0, 1.0, shape)
        expect = render_points(41, 41, 20.0 + fx, 21.0, 1.0, sigma, window_sigmas=6.0)
        np.testing.assert_allclose(got, expect, atol=1e-9)


@pytest.mark.parametrize("name", ["airy", "moffat", "image", "airy+halo"])
def test_a_moving_source_moves_the_light_continuously(name: str) -> None:
    # Bilinear interpolation between phases, and a tapered PSF that every phase's window holds
    # whole: the light moves with the source without steps for the pixels to turn into events,
    # also where the window re-centres (x = 50.5). The centroid advances with the source to the
    # midpoint rule's error in the fine cells.
    shape = SHAPES[name]()
    xs = np.linspace(50.0, 51.0, 41)
    frames = render_frames(101, 101, xs[:, None], np.full((41, 1), 50.2), 1.0, shape)
    centroid = (frames.sum(axis=1) * np.arange(101.0)).sum(axis=1)
    np.testing.assert_allclose(np.diff(centroid), np.diff(xs), rtol=1e-3)
    assert abs(centroid - xs).max() < 1e-3
    # Crossing the pixel boundary changes nothing: the two windows give the same pixels.
    np.testing.assert_allclose(render_points(101, 101, 50.5 - 1e-12, 50.2, 1.0, shape),
                               render_points(101, 101, 50.5, 50.2, 1.0, shape), atol=1e-12)
    steps = np.abs(np.diff(frames, axis=0)).max()
    assert steps < 0.05 * frames.max()


def test_scenario_keys_select_the_shape_and_gaussian_stays_the_default(tmp_path: Path) -> None:
    geo = build("geo-stare")
    assert isinstance(geo.psf, GaussianPSF) and geo.psf.sigma_px == geo.psf_sigma_px
    assert render_points(50, 40, 20.3, 19.6, 1e5, geo.psf).tobytes() == render_points(
        50, 40, 20.3, 19.6, 1e5, geo.psf_sigma_px).tobytes()
    airy = build({"base": "geo-stare", "optics": {"psf": "airy", "spider_vanes": 4}})
    lam = airy.optics.mean_wavelength_m * airy.optics.f_number / airy.optics.pixel_pitch_m
    assert isinstance(airy.psf, KernelPSF) and airy.psf.kind == "airy"
    assert airy.psf.params["lambda_n_px"] == pytest.approx(lam) and airy.psf.params["obstruction_ratio"] == 0.3
    seeing = build({"base": "geo-stare", "optics": {"psf": "moffat", "moffat_fwhm_arcsec": 2.0}})
    assert seeing.psf.params["fwhm_px"] == pytest.approx(2.0 / seeing.optics.plate_scale_arcsec_per_px)
    assert seeing.psf.params["beta"] == 4.765
    np.save(tmp_path / "g.npy", gaussian_image(1.0, 2, 16))
    measured = build({"base": "geo-stare", "optics": {"psf": "image", "psf_file": str(tmp_path / "g.npy"),
                                                      "psf_file_oversampling": 2}})
    assert measured.psf.kind == "image" and measured.psf.params["oversampling"] == 2.0
    assert from_optics(Optics(psf="moffat", moffat_fwhm_px=2.0)) is from_optics(Optics(psf="moffat", moffat_fwhm_px=2.0))
    haloed = build({"base": "geo-stare", "optics": {"halo_fraction": 0.02, "halo_fwhm_px": 8.0, "halo_half_width_px": 40}})
    assert isinstance(haloed.psf, CompositePSF) and isinstance(haloed.psf.core, GaussianPSF)
    assert haloed.psf.halo.params["fwhm_px"] == 8.0 and haloed.psf.half_width_px == 40


def test_sparse_rendering_gives_the_dense_events_for_a_tabulated_shape() -> None:
    optics = {"psf": "moffat", "moffat_fwhm_px": 2.0, "moffat_beta": 3.0}
    sparse = spinning(100.0, sparse=True, cutoff_hz=40.0)
    dense = spinning(100.0, sparse=False, cutoff_hz=40.0)
    for s in (sparse, dense):
        s["optics"] = optics
        s["duration_s"] = 0.2
    a, b = simulate(sparse), simulate(dense)
    assert a.sub_sampled_chunks > 0 and len(b.events) > 100
    assert a.events.tobytes() == b.events.tobytes()


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: airy_psf(2.0, 1.0), r"obstruction_ratio must be in \[0, 1\); got obstruction_ratio=1.0"),
        (lambda: airy_psf(2.0, 0.3, -1), r"spider_vanes must be an integer in \[0, 64\]; got spider_vanes=-1"),
        (lambda: airy_psf(0.001), r"lambda N\) must be in \[0.02, 50\] px.*0.001"),
        (lambda: moffat_psf(3.0, 1.0), r"moffat_beta must be > 1.*got moffat_beta=1.0"),
        (lambda: moffat_psf(3.0, 0.5), r"moffat_beta=0.5"),
        (lambda: image_psf(np.array([[1.0, np.nan]]), 1.0), r"psf image has 1 NaN or infinite values"),
        (lambda: image_psf(np.array([[1.0, -1.0]]), 1.0), r"psf image has negative values \(the least is -1\)"),
        (lambda: image_psf(np.ones(5), 1.0), r"psf image must be a 2-D image; got shape \(5,\)"),
        (lambda: image_psf(np.ones((2, 2, 2)), 1.0), r"must be a 2-D image; got shape \(2, 2, 2\)"),
        (lambda: image_psf(np.zeros((3, 3)), 1.0), r"sums to 0"),
        (lambda: image_psf(np.ones((3, 3)), 0.0), r"psf_file_oversampling must be in .*got psf_file_oversampling=0.0"),
        (lambda: load_psf_image("/nonexistent/psf.npy"), r"psf_file='/nonexistent/psf.npy' does not exist"),
        (lambda: Optics(psf="sinc"), r"psf must be one of gaussian, airy, moffat, image; got psf='sinc'"),
        (lambda: Optics(obstruction_ratio=1.5), r"obstruction_ratio must be in \[0, 1\); got obstruction_ratio=1.5"),
        (lambda: Optics(psf="airy", spider_vanes=-2), r"spider_vanes must be an integer in \[0, 64\]; got spider_vanes=-2"),
        (lambda: Optics(psf="moffat", moffat_fwhm_px=2.0, moffat_beta=1.0), r"moffat_beta=1.0"),
        (lambda: Optics(psf="moffat"), r"psf='moffat' needs one of moffat_fwhm_px or moffat_fwhm_arcsec"),
        (lambda: Optics(moffat_beta=3.0), r"moffat_beta applies to psf='moffat'; got moffat_beta=3.0 with psf='gaussian'"),
        (lambda: Optics(psf="image", psf_file="a.npy"), r"psf='image' needs psf_file and psf_file_oversampling"),
        (lambda: Optics(psf="airy", psf_half_width_px=1000), r"psf_half_width_px must be an integer in \[1, 256\]"),
        (lambda: airy_psf(0.05, half_width_px=256), r"psf_half_width_px=256 at psf_subpixel=8 needs a grid of \d+ samples a side \(> 3072\)"),
        (lambda: airy_psf(0.2, half_width_px=60), r"needs 5.15e\+09 multiply-adds \(> 2e\+09\): lower psf_half_width_px"),
        (lambda: render_points(9, 9, 4.0, 4.0, 1.0, GaussianPSF(1.0), window_sigmas=3.0), r"window_sigmas and normalize"),
        (lambda: Optics(halo_fraction=1.0, halo_fwhm_px=5.0), r"halo_fraction must be in \[0, 1\); got halo_fraction=1.0"),
        (lambda: Optics(halo_fraction=-0.1, halo_fwhm_px=5.0), r"halo_fraction=-0.1"),
        (lambda: Optics(halo_fraction=0.1), r"halo_fraction > 0 and halo_fwhm_px go together.*halo_fwhm_px=None"),
        (lambda: Optics(halo_fwhm_px=5.0), r"go together.*got halo_fraction=0.0, halo_fwhm_px=5.0"),
        (lambda: Optics(halo_fraction=0.1, halo_fwhm_px=1.0), r"halo_fwhm_px must be in \[2, 200\]; got halo_fwhm_px=1.0"),
        (lambda: Optics(halo_fraction=0.1, halo_fwhm_px=5.0, halo_beta=1.0), r"halo_beta must be in \(1, 10\].*halo_beta=1.0"),
        (lambda: Optics(halo_half_width_px=600), r"halo_half_width_px must be an integer in \[8, 512\]; got halo_half_width_px=600"),
        (lambda: halo_psf(6.0, 1.5, 513), r"halo_half_width_px must be an integer in \[8, 512\]; got halo_half_width_px=513"),
        (lambda: CompositePSF(GaussianPSF(1.0), halo_psf(6.0, 1.5, 32), 0.0), r"halo_fraction must be in \(0, 1\)"),
    ],
)
def test_bad_input_is_one_value_error_naming_the_key(call, match: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError, match=match):
        call()


def test_bad_psf_files(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    for name, data, match in (("nan.npy", np.array([[0.0, np.nan], [1.0, 1.0]]), "has 1 NaN or infinite values"),
                              ("neg.npy", np.array([[0.0, -2.0], [1.0, 1.0]]), "has negative values"),
                              ("flat.npy", np.ones(4), r"must be a 2-D image; got shape \(4,\)")):
        np.save(tmp_path / name, data)
        with pytest.raises(ValueError, match=rf"psf_file='.*{name}' {match}"):
            load_psf_image(tmp_path / name)
    (tmp_path / "junk.npy").write_text("not numpy")
    with pytest.raises(ValueError, match=r"junk.npy' is not a readable .npy array"):
        load_psf_image(tmp_path / "junk.npy")
    (tmp_path / "psf.png").write_bytes(b"")
    with pytest.raises(ValueError, match=r"psf_file must be a .npy or .fits file"):
        load_psf_image(tmp_path / "psf.png")
    (tmp_path / "psf.fits").write_bytes(b"")
    monkeypatch.setitem(sys.modules, "astropy", None)  # as if astropy were not installed
    with pytest.raises(ValueError, match=r"reading FITS needs astropy: pip install 'evstwin\[fits\]'"):
        load_psf_image(tmp_path / "psf.fits")


@pytest.mark.parametrize(
    ("optics", "match"),
    [
        ({"obstruction_ratio": 1.0}, r"optics: obstruction_ratio must be in \[0, 1\); got obstruction_ratio=1.0"),
        ({"psf": "airy", "spider_vanes": -1}, r"optics: spider_vanes must be an integer .*got spider_vanes=-1"),
        ({"psf": "moffat", "moffat_fwhm_px": 2.0, "moffat_beta": 1.0}, r"optics: moffat_beta must be > 1.*moffat_beta=1.0"),
        ({"psf": "image", "psf_file": "/nonexistent.npy", "psf_file_oversampling": 2},
         r"optics \(psf='image'.*psf_file='/nonexistent.npy' does not exist"),
        ({"psf": "gaussian", "psf_file": "x.npy"}, r"optics: psf_file applies to psf='image'; got psf_file='x.npy'"),
        ({"psf": "moffat", "moffat_fwhm_arcsec": 1e4}, r"optics \(psf='moffat'.*moffat_fwhm_arcsec=10000.0 is 5.24e\+03 px at 1.91 arcsec/px"),
        ({"psf": "airy", "mean_wavelength_m": 1e-9}, r"optics \(psf='airy'.*lambda N\) must be in \[0.02, 50\] px"),
        ({"psf": "moffat", "moffat_fwhm_px": "wide"}, r"optics: moffat_fwhm_px must be a real number; got moffat_fwhm_px='wide'"),
        ({"halo_fraction": 0.2}, r"optics: halo_fraction > 0 and halo_fwhm_px go together"),
    ],
)
def test_scenario_psf_errors_name_the_key(optics: dict, match: str) -> None:
    with pytest.raises(ScenarioError, match=match):
        build({"base": "geo-stare", "optics": optics})


def test_scenario_psf_image_with_nan(tmp_path: Path) -> None:
    np.save(tmp_path / "bad.npy", np.array([[1.0, np.nan], [1.0, 1.0]]))
    with pytest.raises(ScenarioError, match=r"optics \(psf='image'.*psf_file='.*bad.npy' has 1 NaN"):
        build({"base": "geo-stare", "optics": {"psf": "image", "psf_file": str(tmp_path / "bad.npy"),
                                               "psf_file_oversampling": 1}})


def haloed_spin(sparse: bool) -> dict:
    s = spinning(100.0, sparse=sparse, cutoff_hz=40.0)
    s["optics"] = {"extra_blur_sigma_px": 0.6, "halo_fraction": 0.3, "halo_fwhm_px": 4.0, "halo_half_width_px": 40}
    s["duration_s"] = 0.2
    return s


def test_sub_sampled_runs_take_the_halo_at_the_base_rate() -> None:
    # The sparse path samples finely only the pixels near the cores; a halo reaches every
    # pixel and is sampled at the base times, interpolated linearly in time for the finely
    # sampled pixels. Checked against the halo rendered here at those times.
    from evstwin.psf import CompositePSF, render_frames
    from evstwin.simulate import _Runner

    sc = build(haloed_spin(True))
    assert isinstance(sc.psf, CompositePSF)
    run = _Runner(sc, 1, lambda *a: None)
    assert len(run._halo_groups) == 1 and run._fine_groups[0][0].half_width_px == sc.psf.core.half_width_px
    t_base = np.array([0.03, 0.04, 0.05])
    n_sub = 4
    t_fine = ((np.arange(12) + 1) / n_sub) * 0.01 + 0.02
    hot = np.array([5, 700, 1500, 3000])
    rates = np.zeros((12, hot.size))
    base = np.broadcast_to(run.static_map, (3, sc.height, sc.width))
    frames = run._with_halos(base, t_base, t_fine, hot, rates)
    t_all = np.concatenate([[0.02], t_base])
    x = np.empty((4, 1))
    y = np.empty((4, 1))
    for i, t in enumerate(t_all):
        x[i, 0], y[i, 0] = sc.targets[0].position_px(t)
    halo = render_frames(sc.width, sc.height, x, y, 1e9, sc.psf.halo_part)
    np.testing.assert_allclose(frames, run.static_map + halo[1:], rtol=1e-12, atol=1e-9)
    at_hot = halo.reshape(4, -1)[:, hot]
    w = ((np.arange(12) % n_sub + 1) / n_sub)[:, None]
    k = np.arange(12) // n_sub
    np.testing.assert_allclose(rates, (1 - w) * at_hot[k] + w * at_hot[k + 1], rtol=1e-12, atol=1e-9)
    # and close to the halo rendered at the fine times themselves (the source moves 1.9 px a
    # base interval here: measured 0.6 % of the peak off, checked under 2 %)
    xf = np.empty((12, 1))
    yf = np.empty((12, 1))
    for i, t in enumerate(t_fine):
        xf[i, 0], yf[i, 0] = sc.targets[0].position_px(t)
    fine = render_frames(sc.width, sc.height, xf, yf, 1e9, sc.psf.halo_part).reshape(12, -1)[:, hot]
    assert np.abs(rates - fine).max() < 0.02 * fine.max()
    assert not np.allclose(rates, at_hot[k + 1])  # the interpolation is not the next base sample
    # The whole run: the sparse way's events agree with the dense way's (which samples the
    # halo finely everywhere) to a few in a thousand.
    a, b = simulate(haloed_spin(True)), simulate(haloed_spin(False))
    assert a.sub_sampled_chunks > 0 and len(b.events) > 1000
    assert abs(len(a.events) - len(b.events)) <= 0.005 * len(b.events)


def test_a_steady_halo_keeps_the_mean_flux_while_the_core_follows_the_light_curve() -> None:
    # targets[i].halo = "steady": the core (1 - f of the flux) follows the light curve, the halo
    # (f) keeps the curve's time average; rendered, the two add up to the composite's render
    # of a source whose flux is (1 - f) curve(t) + f mean.
    from evstwin.psf import sharp_part, smooth_part
    from evstwin.targets import SteadyTarget

    f, curve = 0.4, {"t_s": [0.0, 1.0, 2.0], "flux_ph_s": [1e6, 5e6, 3e6]}
    mean = (0.5 * (1e6 + 5e6) + 0.5 * (5e6 + 3e6)) / 2.0  # trapezoids: 3.5e6
    table = {"base": "geo-stare", "optics": {"halo_fraction": f, "halo_fwhm_px": 12.0, "halo_half_width_px": 64},
             "targets": [{"kind": "static", "x_px": 100.3, "y_px": 80.6, "label": "s", "light_curve": curve,
                          "halo": "steady"}], "star_field": {}}
    sc = build(table)
    core, halo = sc.targets[0], sc.targets[1]
    assert core.label == "s" and halo.label == "s-halo" and isinstance(halo, SteadyTarget)
    assert core.psf is sc.psf.core_part and halo.psf is sc.psf.halo_part
    assert sharp_part(halo.psf) is None and smooth_part(halo.psf) is halo.psf
    assert sharp_part(core.psf) is core.psf and smooth_part(core.psf) is None
    t = np.array([0.0, 0.5, 1.7])
    np.testing.assert_allclose(halo.flux_ph_s(t), mean)
    np.testing.assert_allclose(core.flux_ph_s(t), [1e6, 3e6, 3.6e6])
    for ti in t:
        got = (render_points(sc.width, sc.height, 100.3, 80.6, float(core.flux_ph_s(ti)), core.psf)
               + render_points(sc.width, sc.height, 100.3, 80.6, mean, halo.psf))
        expect = (render_points(sc.width, sc.height, 100.3, 80.6, (1 - f) * float(core.flux_ph_s(ti)), sc.psf.core)
                  + render_points(sc.width, sc.height, 100.3, 80.6, f * mean, sc.psf.halo))
        np.testing.assert_allclose(got, expect, rtol=1e-12, atol=1e-12 * mean)


def test_a_steady_halo_with_scintillation_is_refused() -> None:
    # Each target's scintillation is its own stream: a core and its steady halo copy would
    # twinkle apart.
    table = {"base": "geo-stare", "optics": {"halo_fraction": 0.2, "halo_fwhm_px": 9.0},
             "atmosphere": {"scintillation": True, "airmass": 1.2},
             "targets": [{"kind": "static", "x_px": 10.0, "y_px": 10.0, "flux_ph_s": 1e6, "halo": "steady"}]}
    with pytest.raises(ScenarioError, match=r"targets\[0\].halo='steady' with \[atmosphere\] scintillation"):
        build(table)
    del table["targets"][0]["halo"]
    assert isinstance(build(table).psf, CompositePSF)  # the halo alone is fine


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        ({}, r"targets\[0\].halo='steady' needs a halo: set optics.halo_fraction > 0"),
        ({"halo_fraction": 0.2, "halo_fwhm_px": 9.0, "value": "always"},
         r"targets\[0\].halo must be 'follows' \(the default\) or 'steady'; got 'always'"),
    ],
)
def test_steady_halo_errors_name_the_key(extra: dict, match: str) -> None:
    value = extra.pop("value", "steady")
    table = {"base": "geo-stare", "optics": extra,
             "targets": [{"kind": "static", "x_px": 10.0, "y_px": 10.0, "flux_ph_s": 1e6, "halo": value}]}
    with pytest.raises(ScenarioError, match=match):
        build(table)


@pytest.mark.parametrize(("x", "y"), [(60.3, 50.77), (3.2, 97.5), (-20.0, 40.0), (119.5, 0.25), (500.0, 50.0)])
def test_a_dense_add_gives_the_rendered_values(x: float, y: float) -> None:
    # KernelPSF.add_dense, the halos' path in simulate, writes what contributions gives (the
    # same bilinear mix of phases), inside the image, clipped at its edges, or nothing.
    shape = halo_psf(6.0, 1.5, 40)
    img = np.full((100, 120), 7.0)
    shape.add_dense(img, x, y, 1e6)
    np.testing.assert_allclose(img - 7.0, render_points(120, 100, x, y, 1e6, shape), rtol=1e-12, atol=1e-9)


def test_the_fit_groups_see_a_core_and_its_halo_together() -> None:
    # tune.counts.source_flux_map takes, per pixel, the largest light one source brings it:
    # for a composite PSF, the core and the halo added, not the larger of the two.
    from evstwin.tune.counts import source_flux_map

    table = haloed_spin(True)
    table["targets"] = [{"kind": "static", "x_px": 30.3, "y_px": 20.6, "flux_ph_s": 1e6}]
    sc = build(table)
    flux = source_flux_map(sc)
    expect = render_points(sc.width, sc.height, 30.3, 20.6, 1e6, sc.psf)
    np.testing.assert_allclose(flux, expect, rtol=1e-12, atol=1e-9)


# -- the C++ loops of KernelPSF (evstwin/stamp.hpp) against the NumPy code they replaced --------


def _numpy_phase_mix(table: np.ndarray, q: np.ndarray, p: np.ndarray, a: np.ndarray, b: np.ndarray,
                     flux: np.ndarray) -> np.ndarray:
    """KernelPSF.contributions' weights as NumPy computed them before the C++ loop."""
    a3, b3 = a[:, None, None], b[:, None, None]
    w = ((1.0 - b3) * ((1.0 - a3) * table[q, p] + a3 * table[q, p + 1])
         + b3 * ((1.0 - a3) * table[q + 1, p] + a3 * table[q + 1, p + 1]))
    w *= flux[:, None, None]
    return w


def _numpy_add_dense(shape: KernelPSF, image: np.ndarray, x: float, y: float, flux: float) -> None:
    """KernelPSF.add_dense as NumPy summed it before the C++ loop: its terms, one at a time."""
    window = shape.dense_terms(image.shape, x, y, flux)
    if window is None:
        return
    rows, cols, terms, coef = window
    out = image[rows, cols]
    for term, c in zip(terms, coef):
        out += c * term


def test_the_phase_mix_is_the_numpy_expression_bit_for_bit() -> None:
    # Values over 30 decades and weights at 0, just below 1 and between, so that any other
    # order of the products and sums (or a fused multiply-add) would round differently.
    from evstwin import _core

    rng = np.random.default_rng(4)
    table = np.ascontiguousarray(10.0 ** rng.uniform(-30, 0, (5, 5, 9, 9)))
    n = 400
    q, p = rng.integers(0, 4, n).astype(np.intp), rng.integers(0, 4, n).astype(np.intp)
    a, b = rng.uniform(0, 1, n), rng.uniform(0, 1, n)
    a[:20], b[20:40], a[40:60] = 0.0, 0.0, np.nextafter(1.0, 0.0)
    flux = 10.0 ** rng.uniform(0, 12, n)
    got = _core.bilinear_phase_mix(table, q, p, a, b, flux)
    want = _numpy_phase_mix(table, q, p, a, b, flux)
    assert got.shape == (n, 9, 9) and got.tobytes() == want.tobytes()
    # Off by one ulp somewhere would show: the test can fail.
    assert not np.array_equal(got, _numpy_phase_mix(table, q, p, a, b, flux * (1 + 2**-52)))


@pytest.mark.parametrize(("x", "y"), [(60.3, 50.77), (3.2, 97.5), (-20.0, 40.0), (119.5, 0.25), (60.0, 50.0),
                                      (59.5, 49.5), (500.0, 50.0)])
def test_add_dense_is_the_term_by_term_sum_bit_for_bit(x: float, y: float) -> None:
    # Inside, clipped at the edges, on a phase (a or b exactly 0: fewer terms), and off the image.
    rng = np.random.default_rng(5)
    for shape in (halo_psf(6.0, 1.5, 40), moffat_psf(3.0, 2.5, 0.0, 8, 12)):
        base = rng.uniform(0.0, 50.0, (100, 120))
        got, want = base.copy(), base.copy()
        shape.add_dense(got, x, y, 3.7e6)
        _numpy_add_dense(shape, want, x, y, 3.7e6)
        assert got.tobytes() == want.tobytes()
    # A float32 image (no C++ loop) and a view with a row stride take the same sums.
    shape = halo_psf(6.0, 1.5, 40)
    wide = rng.uniform(0.0, 5.0, (100, 300))
    got, want = wide.copy(), wide.copy()
    shape.add_dense(got[:, 50:170], x, y, 3.7e6)
    _numpy_add_dense(shape, want[:, 50:170], x, y, 3.7e6)
    assert got.tobytes() == want.tobytes()
    got32, want32 = wide[:, :120].astype(np.float32), wide[:, :120].astype(np.float32)
    shape.add_dense(got32, x, y, 3.7e6)
    _numpy_add_dense(shape, want32, x, y, 3.7e6)
    assert got32.tobytes() == want32.tobytes()
    # Rows 164 bytes apart (unaligned doubles on every other row): the NumPy path, same sums.
    buf = np.zeros(100 * 164 + 8, np.uint8)
    odd = np.ndarray((100, 20), np.float64, buffer=buf, strides=(164, 8))
    odd[:] = wide[:, :20]
    want_odd = wide[:, :20].copy()
    shape.add_dense(odd, x, y, 3.7e6)
    _numpy_add_dense(shape, want_odd, x, y, 3.7e6)
    assert np.array_equal(odd, want_odd)


def test_add_scaled_terms_takes_views_with_negative_row_strides() -> None:
    from evstwin import _core

    rng = np.random.default_rng(11)
    table = rng.uniform(-1.0, 1.0, (6, 7))
    image = rng.uniform(0.0, 1.0, (12, 7))
    want = image.copy()
    want[::-2] += 0.5 * table[::-1]
    _core.add_scaled_terms(image[::-2], [table[::-1]], [0.5])
    assert image.tobytes() == want.tobytes()


def test_the_psf_loops_refuse_bad_input() -> None:
    from evstwin import _core

    table = np.zeros((3, 3, 5, 5))
    one = np.zeros(1)
    with pytest.raises(ValueError, match=r"q and p must lie in \[0, 1\]; got q\[0\]=2"):
        _core.bilinear_phase_mix(table, np.array([2], np.intp), np.array([0], np.intp), one, one, one)
    with pytest.raises(ValueError, match="one length"):
        _core.bilinear_phase_mix(table, np.array([0, 0], np.intp), np.array([0], np.intp), one, one, one)
    with pytest.raises(ValueError, match="phases, phases, side, side"):
        _core.bilinear_phase_mix(np.zeros((3, 2, 5, 5)), np.array([0], np.intp), np.array([0], np.intp), one, one, one)
    image = np.zeros((4, 6))
    with pytest.raises(ValueError, match=r"terms\[0\] must have the image's shape \(4, 6\); got \(4, 5\)"):
        _core.add_scaled_terms(image, [np.zeros((4, 5))], [1.0])
    with pytest.raises(ValueError, match="at most 4"):
        _core.add_scaled_terms(image, [image] * 5, [1.0] * 5)
    with pytest.raises(ValueError, match="contiguous rows"):
        _core.add_scaled_terms(image[:, ::2], [np.zeros((4, 3))], [1.0])
    with pytest.raises(ValueError, match=r"terms\[1\] must have contiguous rows"):
        _core.add_scaled_terms(image[:, :3], [np.zeros((4, 3)), np.zeros((4, 6))[:, ::2]], [1.0, 1.0])
    with pytest.raises(ValueError, match=r"got shape \(3, 2, 5, 5\)"):
        _core.bilinear_phase_mix(np.zeros((3, 2, 5, 5)), np.array([0], np.intp), np.array([0], np.intp), one, one, one)
    image.flags.writeable = False
    with pytest.raises(ValueError, match="writeable"):
        _core.add_scaled_terms(image, [np.zeros((4, 6))], [1.0])
