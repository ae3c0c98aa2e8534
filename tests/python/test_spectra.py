"""Spectra, bands, QE curves and temperature (issue 29): magnitudes become electrons through the
source's spectrum and the sensor's QE, checked against integrations written out here."""

from __future__ import annotations

import math
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from evstwin import presets, scenario, simulate, spectra

H = 6.62607015e-34
C = 299792458.0
K_B = 1.380649e-23


def _csv(*parts: str) -> np.ndarray:
    path = Path(str(resources.files("evstwin").joinpath("data", *parts)))
    rows = [line.split(",") for line in path.read_text().splitlines() if line and line[0].isdigit()]
    return np.array(rows, dtype=float)


def _hand_electrons(temperature_k: float, v_mag: float, collection_depth_m: float, optical_factor: float) -> float:
    """Electrons/s/m^2 from a black body of V magnitude v_mag onto eq. 2's QE with silicon's
    alpha, by a 0.1 nm rectangle sum (an independent integration of the same definitions)."""
    lam = np.arange(300.0, 1100.0, 0.1) * 1e-9 + 0.05e-9
    photons = lam**-4 / np.expm1(H * C / (lam * K_B * temperature_k))  # Planck, per photon
    v = _csv("bands", "johnson_v.csv")
    v_photon = np.interp(lam, v[:, 0] * 1e-9, v[:, 1] * v[:, 0], left=0, right=0)  # energy -> photon response
    v_photon /= v_photon.max()
    ab = 3631e-26 / (H * lam)  # AB source, photons per wavelength
    m_ab = v_mag + 0.02  # V_AB - V_Vega (Blanton & Roweis 2007)
    scale = np.sum(ab * v_photon) * 10 ** (-0.4 * m_ab) / np.sum(photons * v_photon)
    a = _csv("sensors", "silicon_absorption_green2008.csv")
    alpha = np.exp(np.interp(lam, a[:, 0] * 1e-9, np.log(a[:, 1] * 100)))
    qe = optical_factor * (1 - np.exp(-alpha * collection_depth_m))
    return float(np.sum(scale * photons * qe) * 0.1e-9)


@pytest.mark.parametrize("preset, depth, factor", [("imx636", 5e-6, 0.68), ("davis346", 2e-6, 0.22 * 0.68)])
@pytest.mark.parametrize("temperature_k", [3500.0, 5772.0, 10000.0])
def test_electrons_from_a_v_magnitude_match_a_hand_integration(preset: str, depth: float, factor: float,
                                                               temperature_k: float) -> None:
    p = presets.get_preset(preset)
    assert p.qe is not None
    got = spectra.electrons_per_s_m2(spectra.blackbody(temperature_k), 10.0, spectra.band("V"), p.qe)
    assert got == pytest.approx(_hand_electrons(temperature_k, 10.0, depth, factor), rel=5e-3)


def test_same_v_magnitude_red_and_blue_stars_differ_as_the_qe_curves_say() -> None:
    v = spectra.band("V")
    red, blue = spectra.star(1.5), spectra.star(-0.2)
    ratio = {}
    for name in ("imx636", "davis346"):
        qe = presets.get_preset(name).qe
        assert qe is not None
        ratio[name] = spectra.electrons_per_s_m2(red, 12.0, v, qe) / spectra.electrons_per_s_m2(blue, 12.0, v, qe)
    # Of the same V, a red star sends more photons beyond the V band's red side, a blue one
    # beyond its blue side: the deep back-illuminated IMX636 collects the red that the shallow
    # front-illuminated DAVIS346 photodiode lets through, so the red star gains on it. The hand
    # integrations say how much.
    for name, depth, factor in (("imx636", 5e-6, 0.68), ("davis346", 2e-6, 0.22 * 0.68)):
        hand = (_hand_electrons(spectra.temperature_from_bv(1.5), 12.0, depth, factor)
                / _hand_electrons(spectra.temperature_from_bv(-0.2), 12.0, depth, factor))
        assert ratio[name] == pytest.approx(hand, rel=5e-3)
    assert ratio["imx636"] > 1.3 * ratio["davis346"]


def test_band_magnitudes_round_trip_and_the_sun_has_its_colour() -> None:
    v, g = spectra.band("V"), spectra.band("G")
    sun = spectra.sun()
    n = sun.photon_flux * v.scale_for(sun, -26.76)
    v_again = -2.5 * math.log10(float(np.trapezoid(n * v.response, spectra.GRID_M)) / v.ab_zero_point_ph_s_m2()) - 0.02
    assert v_again == pytest.approx(-26.76, abs=1e-9)
    g_sun = -2.5 * math.log10(float(np.trapezoid(n * g.response, spectra.GRID_M)) / g.ab_zero_point_ph_s_m2()) \
        - g.ab_minus_vega_mag
    # The Sun's G - V is -0.14 (Casagrande & VandenBerg 2018: G = -26.90, V = -26.76); a black body
    # at 5772 K gives it within a few hundredths.
    assert g_sun - (-26.76) == pytest.approx(-0.14, abs=0.04)
    # The Ballesteros formula puts the Sun (B - V 0.65) at 5778 K, as its paper says.
    assert spectra.temperature_from_bv(0.65) == pytest.approx(5778.0, abs=3.0)


def test_photopic_curve_gives_black_body_luminous_efficacies() -> None:
    # The luminous efficacy of a black body over all wavelengths: 54 lm/W at 4000 K, 95 lm/W at
    # 7000 K (published reference values), from the CIE V(lambda) table shipped.
    lam = np.linspace(1e-8, 1e-4, 2_000_001)
    v = np.interp(lam, spectra.GRID_M, spectra.photopic(), left=0.0, right=0.0)
    for t, expected in ((4000.0, 54.0), (7000.0, 95.0)):
        p = lam**-5 / np.expm1(H * C / (lam * K_B * t))
        assert 683.0 * np.sum(p * v) / np.sum(p) == pytest.approx(expected, rel=0.02)


def test_a_scenario_target_takes_its_own_spectrum() -> None:
    base = scenario.load("geo-stare")
    red = scenario.build(scenario.set_value(base, "targets.0.spectrum", "bv:1.5"), duration_s=0.1)
    blue = scenario.build(scenario.set_value(base, "targets.0.spectrum", "bv:-0.2"), duration_s=0.1)
    p = presets.get_preset("davis346")
    assert p.qe is not None
    v = spectra.band("V")
    expected = (spectra.electrons_per_s_m2(spectra.star(1.5), 0.0, v, p.qe)
                / spectra.electrons_per_s_m2(spectra.star(-0.2), 0.0, v, p.qe))
    assert red.targets[0].brightness / blue.targets[0].brightness == pytest.approx(expected, rel=1e-12)
    # The star field keeps the default spectrum (the Sun's): same stars, same fluxes.
    assert [t.brightness for t in red.targets[1:]] == [t.brightness for t in blue.targets[1:]]


def test_spectrum_outside_the_qe_range_and_bad_tables_are_refused(tmp_path: Path) -> None:
    table = tmp_path / "narrow.csv"
    table.write_text("wavelength_nm,flux\n450,1\n700,1\n")
    narrow = spectra.from_table(table)
    qe = presets.get_preset("imx636").qe
    assert qe is not None
    with pytest.raises(spectra.SpectrumError, match=r"covers 450-700 nm but the sensor responds over 300-1"):
        spectra.electrons_per_s_m2(narrow, 10.0, spectra.band("V"), qe)
    with pytest.raises(spectra.SpectrumError, match="band 'G' spans"):
        spectra.band("G").scale_for(narrow, 10.0)
    bad = tmp_path / "bad.csv"
    bad.write_text("wavelength_nm,flux\n500,1\n400,2\n")
    with pytest.raises(spectra.SpectrumError, match="wavelengths must increase"):
        spectra.from_table(bad)
    with pytest.raises(spectra.SpectrumError, match=r"LED FWHM must be in \[2, 500\] nm; got 1 nm"):
        spectra.spectrum_from_name("led:630:1")


def test_presets_without_a_qe_curve_refuse_spectra() -> None:
    s = scenario.load("mcreynolds")
    with pytest.raises(scenario.ScenarioError, match=r"\[photometry\] .* preset 'davis346_paper' has no QE curve"):
        scenario.build(scenario.set_value(s, "photometry.band", "G"))


def _dark_events(temperature_c: float, preset: str) -> int:
    s = {"name": "dark", "duration_s": 4.0, "seed": 5,
         "sensor": {"preset": preset, "width": 346, "height": 260, "temperature_c": temperature_c},
         "sampling": {"rate_hz": 100.0}}
    return int(simulate(s, num_threads=2).events.size)


@pytest.mark.parametrize("preset", ["imx636", "davis346"])
def test_ten_degrees_colder_lowers_the_dark_background_by_the_published_law(preset: str) -> None:
    warm, cold = _dark_events(25.0, preset), _dark_events(15.0, preset)
    # The dark-current law: doubling every 5-8 degC (Theuwissen), i.e. x 0.25-0.42 for 10 degC;
    # the model's 6.5 degC gives 0.344. Poisson noise of ~600 events: +-0.05 at 3 sigma.
    assert warm > 300
    assert 0.25 - 0.05 < cold / warm < 0.42 + 0.05
    assert presets.get_preset(preset).at_temperature(presets.get_preset(preset).pixel, 15.0).dark_rate_e_per_s == \
        pytest.approx(presets.get_preset(preset).pixel.dark_rate_e_per_s * 2 ** (-10 / 6.5))
