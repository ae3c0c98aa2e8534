"""evstwin.sky.atmosphere: seeing PSF width and flux, image motion statistics, scintillation
against Young/Osborn, the sky background by hand, the [atmosphere] table and its errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from evstwin import psf
from evstwin.optics import Optics
from evstwin.scenario import ScenarioError, build, load
from evstwin.sky import atmosphere as atm

ARCSEC_PER_RAD = 180.0 * 3600.0 / math.pi


def _fwhm_along_row(row: np.ndarray) -> float:
    """Full width at half maximum [px] of a peaked 1-D profile, half-max crossings found by
    linear interpolation between pixel values."""
    k = int(np.argmax(row))
    half = row[k] / 2.0
    left = k
    while row[left - 1] > half:
        left -= 1
    right = k
    while row[right + 1] > half:
        right += 1
    x_left = left - 1 + (half - row[left - 1]) / (row[left] - row[left - 1])
    x_right = right + (row[right] - half) / (row[right] - row[right + 1])
    return x_right - x_left


@pytest.mark.parametrize("seeing_arcsec", [3.0, 6.0])
def test_seeing_psf_fwhm_is_seeing_over_plate_scale_and_flux_is_kept(seeing_arcsec: float) -> None:
    # 8 m focal length, 18.5 um pixels: 18.5e-6 / 8 rad = 0.477 arcsec/px by hand, so the seeing
    # spans 6-13 px and its rendered width can be measured.
    optics = Optics(focal_length_m=8.0, f_number=10.0, pixel_pitch_m=18.5e-6, width_px=81, height_px=81)
    plate = 18.5e-6 / 8.0 * ARCSEC_PER_RAD
    assert optics.plate_scale_arcsec_per_px == pytest.approx(plate, rel=1e-12)
    expected_px = seeing_arcsec / plate
    assert atm.seeing_fwhm_px(seeing_arcsec, optics) == pytest.approx(expected_px, rel=1e-12)
    shape = atm.seeing_psf(optics, seeing_arcsec)
    img = psf.render_points(81, 81, 40.0, 40.0, 1e6, shape)
    assert img.sum() == pytest.approx(1e6, rel=1e-9)  # flux conserved
    # The rendered profile: the Moffat of that FWHM, convolved with the optics' Gaussian (sigma
    # 0.17 px here: the FWHM grows by < 0.3 %) and integrated over pixels (a 1 px box adds 1/12 px^2
    # to the variance: < 1 % of a FWHM >= 6 px); half-max crossings interpolated linearly. 2 %.
    measured = _fwhm_along_row(img[40])
    assert measured == pytest.approx(expected_px, rel=0.02)
    assert _fwhm_along_row(img[:, 40]) == pytest.approx(measured, rel=1e-9)  # round
    # Off a pixel centre the flux is still all there.
    img2 = psf.render_points(81, 81, 40.3, 39.8, 1e6, shape)
    assert img2.sum() == pytest.approx(1e6, rel=1e-9)


def test_seeing_convolves_an_airy_optics_psf_and_refuses_a_second_moffat() -> None:
    optics = Optics(focal_length_m=2.8, f_number=14.0, pixel_pitch_m=4.86e-6, psf="airy", obstruction_ratio=0.3,
                    width_px=160, height_px=160)
    seeing = 3.0
    shape = atm.seeing_psf(optics, seeing)
    assert 2 * shape.half_width_px + 1 < 150  # the whole window on the sensor
    img = psf.render_points(160, 160, 79.25, 80.6, 5e5, shape)
    assert img.sum() == pytest.approx(5e5, rel=1e-9)
    ys, xs = np.mgrid[0:160, 0:160]
    assert (img * xs).sum() / img.sum() == pytest.approx(79.25, abs=0.02)  # centred on the source
    assert (img * ys).sum() / img.sum() == pytest.approx(80.6, abs=0.02)
    # Wider than the seeing alone: the Airy core (lambda N = 2 px here) adds to it.
    img0 = psf.render_points(160, 160, 79.0, 80.0, 5e5, shape)
    seeing_px = seeing / optics.plate_scale_arcsec_per_px
    assert seeing_px * 1.02 < _fwhm_along_row(img0[80]) < seeing_px * 1.2
    with pytest.raises(ValueError, match="already a seeing PSF"):
        atm.seeing_psf(optics.replace(psf="moffat", moffat_fwhm_px=2.0, obstruction_ratio=0.0), seeing)


def test_seeing_convolved_with_a_point_like_image_psf_is_the_moffat(tmp_path) -> None:
    # A PSF image of one pixel 1/8 px wide: the convolution must give back the Moffat alone (the
    # same FWHM as the Gaussian path with a negligible optics sigma), and keep the flux.
    np.save(tmp_path / "delta.npy", np.ones((1, 1)))
    optics = Optics(focal_length_m=8.0, f_number=1.0, pixel_pitch_m=18.5e-6, psf="image",
                    psf_file=str(tmp_path / "delta.npy"), psf_file_oversampling=8.0, width_px=81, height_px=81)
    seeing = 3.0
    img = psf.render_points(81, 81, 40.0, 40.0, 1.0, atm.seeing_psf(optics, seeing))
    assert img.sum() == pytest.approx(1.0, rel=1e-9)
    plain = optics.replace(psf="gaussian", psf_file=None, psf_file_oversampling=None)  # sigma 0.017 px
    ref = psf.render_points(81, 81, 40.0, 40.0, 1.0, atm.seeing_psf(plain, seeing))
    assert _fwhm_along_row(img[40]) == pytest.approx(_fwhm_along_row(ref[40]), rel=0.01)
    assert _fwhm_along_row(img[40]) == pytest.approx(seeing / plain.plate_scale_arcsec_per_px, rel=0.02)


def test_image_motion_rms_and_correlation_time_match_their_parameters() -> None:
    rms_arcsec, tau_s, duration_s = 0.4, 0.01, 200.0
    optics = Optics(focal_length_m=1.0, f_number=5.0, pixel_pitch_m=10e-6)
    plate = 10e-6 / 1.0 * ARCSEC_PER_RAD  # 2.063 arcsec/px
    path = atm.ImageMotion(rms_arcsec, tau_s).path(optics, duration_s, seed=11)
    step = tau_s / atm.JITTER_STEPS_PER_TAU
    assert np.allclose(np.diff(path.t_s), step) and path.t_s[-1] >= duration_s
    n = path.t_s.size
    for series in (path.dx_px, path.dy_px):
        x = series * plate  # arcsec
        # Sample variance of a Gaussian process: relative std sqrt(2 tau / T) (the integral of rho^2
        # over all lags is tau for rho = exp(-|lag| / tau)): 1 % here; 5 sigma.
        rel = math.sqrt(2.0 * tau_s / duration_s)
        assert np.var(x) == pytest.approx(rms_arcsec**2, rel=5 * rel)
        # Autocorrelation at a lag of tau: exp(-1). Bartlett's variance for an AR(1) of
        # coefficient phi at lag k over n samples.
        k = atm.JITTER_STEPS_PER_TAU
        phi = math.exp(-1.0 / k)
        var_r = ((1 + phi**2) * (1 - phi ** (2 * k)) / (1 - phi**2) - 2 * k * phi ** (2 * k)) / n
        xc = x - x.mean()
        r_k = float(np.dot(xc[:-k], xc[k:]) / np.dot(xc, xc))
        assert r_k == pytest.approx(math.exp(-1.0), abs=5 * math.sqrt(var_r))
    # x and y independent: their correlation within 5 / sqrt(n_eff).
    corr = np.corrcoef(path.dx_px, path.dy_px)[0, 1]
    assert abs(corr) < 5 * math.sqrt(tau_s / duration_s)
    again = atm.ImageMotion(rms_arcsec, tau_s).path(optics, duration_s, seed=11)
    assert np.array_equal(again.dx_px, path.dx_px) and np.array_equal(again.dy_px, path.dy_px)
    other = atm.ImageMotion(rms_arcsec, tau_s).path(optics, duration_s, seed=12)
    assert not np.array_equal(other.dx_px, path.dx_px)


def test_image_motion_moves_the_whole_field_together() -> None:
    s = load({
        "sensor": {"preset": "davis346", "width": 64, "height": 32}, "duration_s": 0.5, "seed": 4,
        "sampling": {"rate_hz": 200.0},
        "background": {"sky_mag_per_arcsec2": 20.0},
        "optics": {"focal_length_m": 1.0, "f_number": 5.0},
        "atmosphere": {"jitter_rms_arcsec": 1.0, "jitter_tau_s": 0.02},
        "targets": [{"kind": "static", "x_px": 10.0, "y_px": 10.0, "magnitude": 8.0},
                    {"kind": "linear", "x0_px": 40.0, "y0_px": 20.0, "vx_px_s": 3.0, "vy_px_s": 0.0,
                     "magnitude": 8.0}],
    })
    scene = build(s)
    t = np.linspace(0.0, 0.5, 501)
    (x0, y0), (x1, y1) = (tgt.position_px(t) for tgt in scene.targets)
    assert np.std(x0) > 0.1  # it jitters (1 arcsec = 0.54 px rms)
    assert np.allclose(x1 - x0, 30.0 + 3.0 * t) and np.allclose(y1 - y0, 10.0)  # by the same offset
    again = build(s)
    assert np.array_equal(again.targets[0].position_px(t)[0], x0)  # same seed, same jitter


def _series_g(x: float) -> float:
    """sum_k x^k / (k k!), summed directly (independent of the code's Ei)."""
    return sum(x**k / (k * math.factorial(k)) for k in range(1, 60))


def test_scintillation_exposure_variance_matches_young_osborn() -> None:
    d_m, altitude_m, airmass, c_y = 0.2, 2000.0, 1.5, 1.5
    scint = atm.Scintillation(altitude_m=altitude_m, airmass=airmass, c_y=c_y, wind_speed_m_s=20.0)
    tau = d_m / 20.0  # D > r_F = 7.4 cm: tau = D / v = 10 ms
    assert scint.correlation_time_s(d_m) == pytest.approx(tau)
    # Osborn et al. 2015 eq. 7 by hand, for a 1 s exposure.
    sigma2_1s = 1e-5 * c_y**2 * d_m ** (-4 / 3) * airmass**3 * math.exp(-2 * altitude_m / 8000.0)
    assert scint.exposure_variance(d_m, 1.0) == pytest.approx(sigma2_1s, rel=1e-12)
    s2 = scint.log_variance(d_m)
    assert _series_g(s2) == pytest.approx(sigma2_1s / (2 * tau), rel=1e-9)
    # Simulated: 50 sources x 100 s, exposures of T = 1 s (100 tau): 5000 exposure means.
    t, m = scint.multipliers(d_m, 100.0, 50, seed=3)
    step = t[1] - t[0]
    per = round(1.0 / step)
    n_win = (t.size - 1) // per
    # The mean of the linearly interpolated multiplier over each exposure: trapezoids.
    cells = 0.5 * (m[:, :-1] + m[:, 1:])
    means = cells[:, : n_win * per].reshape(50, n_win, per).mean(axis=2).ravel()
    assert abs(m.mean() - 1.0) < 5 * math.sqrt(math.expm1(s2) * 2 * tau / (100.0 * 50))  # mean 1
    measured = float(np.var(means, ddof=1))
    # Statistical: a variance of (near-Gaussian) means over N exposures: relative std sqrt(2 / N).
    # Model: for T = 100 tau the finite exposure lowers the variance by ~tau / T (1 %).
    tol = 5 * math.sqrt(2.0 / means.size) + 1.5 * tau / 1.0
    assert measured == pytest.approx(sigma2_1s / 1.0, rel=tol)
    # The instantaneous index exp(s^2) - 1.
    assert float(np.var(m)) == pytest.approx(math.expm1(s2), rel=0.05)
    again = scint.multipliers(d_m, 100.0, 50, seed=3)[1]
    assert np.array_equal(again, m)


def test_scintillation_small_aperture_uses_the_fresnel_scale() -> None:
    scint = atm.Scintillation()
    assert scint.correlation_time_s(0.02) == pytest.approx(atm.FRESNEL_SCALE_M / 20.0)
    assert scint.exposure_variance(0.02, 1.0) == pytest.approx(scint.exposure_variance(atm.FRESNEL_SCALE_M, 1.0))
    assert atm.FRESNEL_SCALE_M == pytest.approx(math.sqrt(0.55e-6 * 1e4))


def test_sky_background_photons_per_pixel_by_hand() -> None:
    # 0.2 m f/4 with a 30 % obstruction, 0.8 transmission, 4.86 um pixels; sky 21 mag/arcsec^2.
    optics = Optics(focal_length_m=0.8, f_number=4.0, pixel_pitch_m=4.86e-6, obstruction_ratio=0.3, transmission=0.8)
    h = 6.62607015e-34
    zero_point = 3640.0 * 1e-26 / h * 0.16  # V = 0: f_nu / h x d(lambda)/lambda [photons/s/m^2]
    pixel_arcsec = 4.86e-6 / 0.8 * 180.0 * 3600.0 / math.pi
    area = math.pi * 0.2**2 / 4.0 * (1.0 - 0.3**2)
    expected = zero_point * 10 ** (-0.4 * 21.0) * pixel_arcsec**2 * area * 0.8
    assert zero_point == pytest.approx(8.79e9, rel=1e-3)
    assert optics.background_ph_s_per_px(21.0) == pytest.approx(expected, rel=1e-12)
    assert expected == pytest.approx(1.257, rel=1e-3)  # 1.26 photons/s on a 1.25 arcsec pixel


def _base() -> dict:
    return {"sensor": {"preset": "davis346", "width": 32, "height": 16}, "duration_s": 0.2,
            "optics": {"focal_length_m": 2.0, "f_number": 4.0}, "background": {"sky_mag_per_arcsec2": 20.0},
            "targets": [{"kind": "static", "x_px": 10.0, "y_px": 8.0, "magnitude": 9.0}]}


def test_atmosphere_table_in_a_scenario() -> None:
    s = _base()
    s["atmosphere"] = {"seeing_fwhm_arcsec": 4.0, "scintillation": True, "site_altitude_m": 2400.0,
                       "elevation_deg": 30.0}
    s["sampling"] = {"rate_hz": 1000.0}
    scene = build(s)
    assert scene.psf.kind == "seeing"
    assert scene.psf.params["fwhm_px"] == pytest.approx(4.0 / (18.5e-6 / 2.0 * ARCSEC_PER_RAD))
    # Kasten & Young (1989) at z = 60 deg, by hand: 1 / (cos 60 + 0.50572 (96.07995 - 60)^-1.6364)
    assert scene.atmosphere.scintillation.airmass == pytest.approx(1.99429285, rel=1e-7)
    flux = scene.targets[0].flux_ph_s(np.linspace(0, 0.2, 50))
    assert np.std(flux) > 0  # it twinkles


@pytest.mark.parametrize("table, rate, words", [
    ({"seeing_fwhm_arcsec": -1.0}, 100.0, ["seeing_fwhm_arcsec", "-1"]),
    ({"seeing_fwhm_arcsec": "2"}, 100.0, ["atmosphere.seeing_fwhm_arcsec", "'2'"]),
    ({"moffat_beta": 0.5}, 100.0, ["moffat_beta", "0.5"]),
    ({"jitter_rms_arcsec": 0.5}, 100.0, ["jitter_tau_s"]),
    ({"jitter_rms_arcsec": 0.5, "jitter_tau_s": 0.0}, 100.0, ["jitter_tau_s", "0"]),
    ({"scintillation": True, "airmass": 0.5}, 1000.0, ["airmass", "0.5"]),
    ({"scintillation": True, "airmass": 1.2, "elevation_deg": 40.0}, 1000.0, ["airmass", "elevation_deg"]),
    ({"scintillation": True, "elevation_deg": -5.0}, 1000.0, ["elevation_deg", "-5"]),
    ({"scintillation": True, "site_altitude_m": 20000.0}, 1000.0, ["site_altitude_m", "20000"]),
    ({"site_altitude_m": 2000.0}, 1000.0, ["site_altitude_m", "scintillation = true"]),
    ({"scintillation": "yes"}, 1000.0, ["atmosphere.scintillation", "'yes'"]),
    ({"scintillation": True}, 20.0, ["sampling.rate_hz=20", "at least"]),
    ({"foo": 1}, 100.0, ["atmosphere.foo"]),
])
def test_bad_atmosphere_values_get_one_line(table: dict, rate: float, words: list[str]) -> None:
    s = _base()
    s["atmosphere"] = table
    s["sampling"] = {"rate_hz": rate}
    with pytest.raises(ScenarioError) as err:
        build(s)
    text = str(err.value)
    assert "\n" not in text
    for w in words:
        assert w in text


def test_same_seed_same_events_with_the_atmosphere_whatever_the_threads_and_chunks() -> None:
    from evstwin.simulate import simulate

    scene = {
        "sensor": {"preset": "davis346", "width": 40, "height": 24}, "duration_s": 0.3, "seed": 9,
        "sampling": {"rate_hz": 400.0, "chunk_samples": 50},
        "background": {"sky_mag_per_arcsec2": 19.0},
        "optics": {"focal_length_m": 0.5, "f_number": 2.0},
        "pixel": {"absorption_per_m": 2e5, "depletion_width_m": 2e-6},
        "atmosphere": {"seeing_fwhm_arcsec": 8.0, "scintillation": True, "scintillation_tau_s": 0.005},
        "targets": [{"kind": "static", "x_px": 12.0, "y_px": 12.0, "magnitude": 3.0}],
    }
    s = load(scene)
    a = simulate(s, num_threads=1)
    near = (np.abs(a.events["x"].astype(int) - 12) <= 2) & (np.abs(a.events["y"].astype(int) - 12) <= 2)
    assert near.sum() > 10  # the scintillation makes the static star fire
    b = simulate(s, num_threads=2, sets=["sampling.chunk_samples=7"])
    assert np.array_equal(a.events, b.events)
    assert not np.array_equal(a.events, simulate(s, num_threads=1, seed=10).events)
    # Image motion and a fast mover: sub-sampled, the same events on 1 and 2 threads. (Which
    # pixels a sub-sampled chunk samples finely depends on sampling.chunk_samples, so with
    # noise the events of any sub-sampled scene do too: simulate's sparse path, not the
    # atmosphere's.)
    scene["atmosphere"].update(jitter_rms_arcsec=3.0, jitter_tau_s=0.02)
    scene["targets"].append({"kind": "linear", "x0_px": 2.0, "y0_px": 6.0, "vx_px_s": 60.0, "vy_px_s": 0.0,
                             "magnitude": 3.0})
    s = load(scene)
    a = simulate(s, num_threads=1)
    assert a.sub_sampled_chunks > 0 and np.array_equal(a.events, simulate(s, num_threads=2).events)


def test_scintillation_multiplies_a_light_curve_without_smoothing_its_steps() -> None:
    # A satellite entering the Earth's shadow: its flux drops 100x within 0.1 ms. Through the
    # scintillation it must still drop there (the product at that time, not a curve resampled
    # on the scintillation's grid, which smeared the step over ~25 ms).
    from evstwin.targets import LightCurve, StaticTarget

    optics = Optics(focal_length_m=0.2, f_number=2.0, pixel_pitch_m=18.5e-6, width_px=64, height_px=64)
    step = LightCurve(np.array([0.0, 0.1, 0.1001, 1.0]), np.array([1e9, 1e9, 1e7, 1e7]))
    target = StaticTarget(10.0, 10.0, step)
    seen = atm.Atmosphere(scintillation=atm.Scintillation(altitude_m=2000.0, airmass=1.5)).apply(
        [target], optics, 1.0, seed=3)[0]
    t = np.array([0.0999, 0.1002, 0.102, 0.5])
    ratio = seen.flux_ph_s(t) / target.flux_ph_s(t)
    assert np.all((ratio > 0.2) & (ratio < 5.0))  # a scintillation factor of mean 1 at each time
    assert seen.flux_ph_s(np.array([0.102]))[0] < 0.1 * seen.flux_ph_s(np.array([0.0999]))[0]
