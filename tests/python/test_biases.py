"""Prophesee biases in the vendor's names and units (``[biases] bias_diff_on`` ...): defaults give
the presets' parameters exactly, hand-computed laws, the vendor's direction of each effect, the
vendor's ranges and constraints, refusals, and a tiny simulation."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from evstwin.presets import GEN3_BIASES, IMX636_BIASES, get_preset
from evstwin.scenario import ScenarioError, build, load, parse_assignment, set_value, to_toml
from evstwin.simulate import simulate

FIELDS = ("theta_on", "theta_off", "cutoff_hz", "refractory_s")
# U_T = k_B T / q at 25 degC, from the SI values (exact k_B and q), written out here.
U_T_25C_MV = 1.380649e-23 * 298.15 / 1.602176634e-19 * 1e3


def small(preset: str, **biases: Any) -> dict[str, Any]:
    """A 6 x 6 window of ``preset`` with no target (dark), biases as given."""
    s: dict[str, Any] = {"sensor": {"preset": preset, "roi": [0, 0, 6, 6]}, "duration_s": 0.01}
    if biases:
        s["biases"] = dict(biases)
    return s


def params_with(preset: str, **biases: Any) -> Any:
    return build(small(preset, **biases)).params


# -- the defaults are the presets ------------------------------------------------------------------


@pytest.mark.parametrize("preset", ["prophesee_gen3_vga", "imx636"])
def test_vendor_defaults_give_the_presets_parameters_exactly(preset: str) -> None:
    p = get_preset(preset)
    assert p.vendor_biases is not None
    derived = p.vendor_biases.derive(p.vendor_biases.defaults(), p.pixel)
    assert derived == {f: getattr(p.pixel, f) for f in FIELDS}  # ==, not approx: bit for bit
    # Through a scenario: every default given, at another temperature too, is the preset's pixel.
    explicit = build(small(preset, **p.vendor_biases.defaults())).params
    assert explicit == build(small(preset)).params
    cold = small(preset, **p.vendor_biases.defaults())
    cold["sensor"]["temperature_c"] = 0.0
    plain_cold = small(preset)
    plain_cold["sensor"]["temperature_c"] = 0.0
    assert build(cold).params == build(plain_cold).params


def test_the_vendors_figures_as_the_sources_give_them() -> None:
    # OpenEB 3.0 gen3_ll_biases.cpp (defaults and ranges, mV) and imx636_bias_settings*.h (offsets).
    gen3 = {b.name: (b.default, b.allowed) for b in GEN3_BIASES.biases}
    assert gen3 == {"bias_diff_on": (375, (0, 1800)), "bias_diff_off": (225, (0, 1800)), "bias_diff": (300, (0, 1800)),
                    "bias_fo": (1725, (1650, 1800)), "bias_pr": (1500, (1200, 1800)),
                    "bias_hpf": (1500, (0, 1800)), "bias_refr": (1500, (1300, 1800))}
    imx = {b.name: (b.default, b.allowed, b.recommended) for b in IMX636_BIASES.biases}
    assert imx == {"bias_diff_on": (0, (-150, 200), (-85, 140)), "bias_diff_off": (0, (-150, 200), (-35, 190)),
                   "bias_diff": (0, (-150, 200), (-25, 23)), "bias_fo": (0, (-150, 200), (-35, 55)),
                   "bias_hpf": (0, (0, 255), (0, 120)), "bias_refr": (0, (-50, 255), (-20, 235))}
    # Every law and constant has its sources and assumptions in the preset (the presets reference).
    for model in (GEN3_BIASES, IMX636_BIASES):
        assert len(model.sources) >= 3 and len(model.assumptions) >= 4


def test_a_scenario_with_vendor_biases_round_trips_through_toml(tmp_path) -> None:
    s = load(small("prophesee_gen3_vga", bias_diff_on=414, bias_fo=1700))
    path = tmp_path / "resolved.toml"
    path.write_text(to_toml(s))
    assert build(str(path)).params == build(s).params


# -- hand computations ----------------------------------------------------------------------------


def test_gen3_threshold_is_proportional_to_the_comparator_distance() -> None:
    # bias_diff_on 420 mV: 120 mV above bias_diff 300, against the default 75 mV for ln(1.25).
    assert params_with("prophesee_gen3_vga", bias_diff_on=420).theta_on == pytest.approx(
        math.log(1.25) * 120.0 / 75.0, rel=1e-12)
    # bias_diff_off 195 mV: 105 mV below 300.
    assert params_with("prophesee_gen3_vga", bias_diff_off=195).theta_off == pytest.approx(
        math.log(1.25) * 105.0 / 75.0, rel=1e-12)


def test_gen3_follower_and_refractory_are_exponential_in_the_gate_voltage() -> None:
    p = params_with("prophesee_gen3_vga", bias_fo=1750, bias_refr=1450)
    # 25 mV above the 1725 mV default: 150 Hz x exp(-0.7 x 25 / 25.69) = 75.9 Hz.
    assert p.cutoff_hz == pytest.approx(150.0 * math.exp(-0.7 * 25.0 / U_T_25C_MV), rel=1e-9)
    assert p.cutoff_hz == pytest.approx(75.91, abs=0.01)
    # 50 mV below the 1500 mV default: 1 ms x exp(0.7 x 50 / 25.69) = 3.9 ms.
    assert p.refractory_s == pytest.approx(1e-3 * math.exp(0.7 * 50.0 / U_T_25C_MV), rel=1e-9)


def test_imx636_threshold_moves_with_the_log_of_the_code() -> None:
    # +40 codes on the assumed factory code 115: 0.235 + 0.0659 ln(155 / 115) = 0.2547.
    p = params_with("imx636", bias_diff_on=40, bias_diff_off=-20, bias_fo=37, bias_refr=20)
    assert p.theta_on == pytest.approx(0.235 + 0.0659 * math.log(155.0 / 115.0), rel=1e-12)
    assert p.theta_on == pytest.approx(0.2547, abs=1e-4)
    assert p.theta_off == pytest.approx(0.21 + 0.0659 * math.log(32.0 / 52.0), rel=1e-12)
    assert p.cutoff_hz == pytest.approx(2000.0 * 111.0 / 74.0, rel=1e-12)  # 3 kHz
    assert p.refractory_s == pytest.approx(130e-6 * 20.0 / 40.0, rel=1e-12)  # half


# -- the vendor's direction of each effect --------------------------------------------------------


def test_every_effect_goes_the_vendors_way() -> None:
    g0 = params_with("prophesee_gen3_vga")
    # Gen3: bias_diff_on further above bias_diff, a higher ON threshold, the OFF one untouched.
    up = params_with("prophesee_gen3_vga", bias_diff_on=400)
    assert up.theta_on > g0.theta_on and up.theta_off == g0.theta_off
    # bias_diff_off nearer bias_diff: a lower OFF threshold ("approach bias_diff_off to bias_diff").
    near = params_with("prophesee_gen3_vga", bias_diff_off=250)
    assert near.theta_off < g0.theta_off and near.theta_on == g0.theta_on
    # "Decreasing bias_fo value will increase the bandwidth"; increasing it decreases it.
    assert params_with("prophesee_gen3_vga", bias_fo=1700).cutoff_hz > g0.cutoff_hz
    assert params_with("prophesee_gen3_vga", bias_fo=1760).cutoff_hz < g0.cutoff_hz
    # bias_refr (an nFET, as on Gen3.1): higher, more recharge current, a shorter dead time.
    assert params_with("prophesee_gen3_vga", bias_refr=1550).refractory_s < g0.refractory_s
    assert params_with("prophesee_gen3_vga", bias_refr=1400).refractory_s > g0.refractory_s

    i0 = params_with("imx636")
    assert params_with("imx636", bias_diff_on=30).theta_on > i0.theta_on
    assert params_with("imx636", bias_diff_on=-30).theta_on < i0.theta_on
    assert params_with("imx636", bias_diff_off=30).theta_off > i0.theta_off
    assert params_with("imx636", bias_fo=30).cutoff_hz > i0.cutoff_hz
    assert params_with("imx636", bias_refr=30).refractory_s < i0.refractory_s


def test_colder_sensor_steepens_the_exponential_laws_only() -> None:
    s = small("prophesee_gen3_vga", bias_fo=1700)
    s["sensor"]["temperature_c"] = -20.0
    cold = build(s).params.cutoff_hz
    warm = params_with("prophesee_gen3_vga", bias_fo=1700).cutoff_hz
    u_t_cold_mv = 1.380649e-23 * 253.15 / 1.602176634e-19 * 1e3
    assert cold == pytest.approx(150.0 * math.exp(0.7 * 25.0 / u_t_cold_mv), rel=1e-9)
    assert cold > warm > 150.0


# -- ranges, constraints, refusals, names ---------------------------------------------------------


@pytest.mark.parametrize(("preset", "biases", "message"), [
    ("prophesee_gen3_vga", {"bias_fo": 1600}, r"biases\.bias_fo=1600 is outside .* \[1650, 1800\] mV"),
    ("prophesee_gen3_vga", {"bias_refr": 1900}, r"biases\.bias_refr=1900 is outside .* \[1300, 1800\] mV"),
    ("prophesee_gen3_vga", {"bias_diff_on": 300}, r"biases\.bias_diff_on=300 must be >= bias_diff \+ 1 = 301 mV"),
    ("prophesee_gen3_vga", {"bias_diff_off": 300}, r"biases\.bias_diff_off=300 must be <= bias_diff - 1 = 299 mV"),
    ("prophesee_gen3_vga", {"bias_diff_on": 375.5}, r"biases\.bias_diff_on=375\.5 must be a whole number of mV"),
    ("prophesee_gen3_vga", {"bias_diff": 320}, r"biases\.bias_diff=320: .*not modifiable.*only its default 300 mV"),
    ("prophesee_gen3_vga", {"bias_pr": 1400}, r"biases\.bias_pr=1400: .*photoreceptor.*only its default 1500 mV"),
    ("prophesee_gen3_vga", {"bias_hpf": 1600}, r"biases\.bias_hpf=1600: .*no high-pass filter.*1500 mV"),
    ("imx636", {"bias_diff_on": 201}, r"biases\.bias_diff_on=201 is outside .* \[-150, 200\] DAC codes"),
    ("imx636", {"bias_refr": -20}, r"biases\.bias_refr=-20 puts its register at 0 .*offset in \[-19, 235\]"),
    ("imx636", {"bias_fo": 190}, r"biases\.bias_fo=190 puts its register at 264"),
    ("imx636", {"bias_diff_on": -113}, r"biases \(bias_diff_on=-113, bias_diff=0 .*\) give theta_on = -0\.03\d* <= 0"),
    ("imx636", {"bias_hpf": 10}, r"biases\.bias_hpf=10: .*no high-pass filter.*only its default 0 DAC codes"),
    ("imx636", {"bias_diff": 5}, r"biases\.bias_diff=5: .*only its default 0"),
    ("imx636", {"bias_pr": 0}, r"biases\.bias_pr: the Sony IMX636 .* has no bias_pr; its biases: bias_diff_on"),
    ("davis346", {"bias_diff_on": 20}, r"biases\.bias_diff_on: preset 'davis346' has no Prophesee biases"),
    ("prophesee_gen3_vga", {"bias_diff_on": 400, "i_on_a": 1e-7},
     r"biases\.bias_diff_on \(a Prophesee bias\) cannot be combined with biases\.i_on_a"),
])
def test_bad_biases_get_one_line_naming_key_and_value(preset: str, biases: dict, message: str) -> None:
    with pytest.raises(ScenarioError, match=message) as err:
        build(small(preset, **biases))
    assert "\n" not in str(err.value)


def test_davis_bias_currents_are_refused_on_a_prophesee_preset() -> None:
    # eq. 8-9 and the follower's law are the DAVIS pixel's: on the IMX636 the DAVIS346 set would give
    # theta 0.206 / 0.093, a 10 Hz follower and 1 ms refractory period under the IMX636's name.
    for preset in ("imx636", "prophesee_gen3_vga"):
        for change, named in ((lambda s: s["sensor"].update(bias_set="fast_pr_slow_sf_balanced_th"),
                               r"sensor\.bias_set='fast_pr_slow_sf_balanced_th'"),
                              (lambda s: s.update(biases={"i_on_a": 1e-7}), r"biases\.i_on_a=1e-07"),
                              (lambda s: s["sensor"].update(k=1.0), r"sensor\.k=1\.0")):
            s = small(preset)
            change(s)
            with pytest.raises(ScenarioError, match=named + rf".* do not apply to preset '{preset}'.*"
                                                             r"sensor\.bias_set=\"none\"") as err:
                build(s)
            assert "\n" not in str(err.value)
    # A base scenario's set is dropped with "none": the preset's own pixel, bit for bit.
    own = get_preset("imx636").pixel
    scene = build({"base": "geo-stare", "sensor": {"preset": "imx636", "bias_set": "none"}}, duration_s=0.1)
    assert (scene.params.theta_on, scene.params.theta_off, scene.params.cutoff_hz, scene.params.refractory_s) == \
        (own.theta_on, own.theta_off, own.cutoff_hz, own.refractory_s)
    assert set_value(load("geo-stare"), "sensor.bias_set", "none")["sensor"]["bias_set"] == "none"
    # On the DAVIS346 "none" is its preset's own set; a named set still applies there.
    assert build(dict(small("davis346"), sensor={"preset": "davis346", "roi": [0, 0, 6, 6], "bias_set": "none"})
                 ).params == get_preset("davis346").pixel.replace(pr_pole=True)  # a scenario's pr_pole default
    assert build(dict(small("davis346"), sensor={"preset": "davis346", "roi": [0, 0, 6, 6],
                                                 "bias_set": "paper_run_3"})).params.theta_off == \
        pytest.approx(0.2181, abs=5e-4)  # Table 2 run 3


def test_unknown_bias_name_and_set_syntax() -> None:
    with pytest.raises(ScenarioError, match=r"unknown scenario key 'biases\.bias_fooo'; allowed: .*bias_refr"):
        set_value(load(small("imx636")), "biases.bias_fooo", 3)
    key, value = parse_assignment("biases.bias_diff_on=+20")
    assert (key, value) == ("biases.bias_diff_on", 20)
    s = set_value(load(small("imx636")), key, value)
    assert build(s).params.theta_on == pytest.approx(0.235 + 0.0659 * math.log(135.0 / 115.0))
    # The refused biases take their defaults without complaint.
    assert build(small("prophesee_gen3_vga", bias_pr=1500, bias_hpf=1500, bias_diff=300)).params == \
        build(small("prophesee_gen3_vga")).params


def test_the_vendors_ranges_build_or_say_why() -> None:
    # Gen3: the ends of the driver's range of each mapped bias build into valid pixel parameters.
    for name, b in ((b.name, b) for b in GEN3_BIASES.biases if b.moves):
        lo, hi = b.allowed
        for v in (lo, hi):
            if name == "bias_diff_on" and v < 301 or name == "bias_diff_off" and v > 299:
                continue  # the constraint's side, tested above
            build(small("prophesee_gen3_vga", **{name: v}))
    # The IMX636's recommended range builds, but for bias_refr's -20: with the assumed factory code
    # 20 that is code 0, no current, a dead time without end (refused, saying so).
    for name, b in ((b.name, b) for b in IMX636_BIASES.biases if b.moves):
        assert b.recommended is not None
        lo, hi = b.recommended
        for v in (lo, hi):
            if (name, v) == ("bias_refr", -20):
                with pytest.raises(ScenarioError, match=r"biases\.bias_refr=-20 puts its register at 0"):
                    build(small("imx636", **{name: v}))
            else:
                build(small("imx636", **{name: v}))


# -- a tiny simulation --------------------------------------------------------------------------


def brightening(**biases: Any) -> dict[str, Any]:
    """An 8 x 8 IMX636 window with a blurred source brightening 1000-fold over 0.1 s: a run of ON
    events in each lit pixel, about ln(1000) / theta_on of them."""
    s = small("imx636", **biases)
    s["sensor"]["roi"] = [0, 0, 8, 8]
    s["duration_s"] = 0.12
    s["sampling"] = {"rate_hz": 2000.0}
    s["optics"] = {"extra_blur_sigma_px": 1.0}
    s["targets"] = [{"kind": "static", "x_px": 4.0, "y_px": 4.0,
                     "light_curve": {"t_s": [0.0, 0.1], "flux_ph_s": [1e5, 1e8]}}]
    return s


def test_raising_bias_diff_on_lowers_the_on_events() -> None:
    default = simulate(brightening(), seed=7).events
    explicit = simulate(brightening(bias_diff_on=0, bias_diff_off=0, bias_fo=0, bias_refr=0), seed=7).events
    assert explicit.tobytes() == default.tobytes()  # the defaults: the same events, bit for bit
    raised = simulate(brightening(bias_diff_on=140), seed=7).events
    on_default = int(np.count_nonzero(default["p"] == 1))
    on_raised = int(np.count_nonzero(raised["p"] == 1))
    assert on_default > 300
    # +140 codes: theta_on 0.235 -> 0.235 + 0.0659 ln(255 / 115) = 0.2875; each lit pixel fires
    # about ln(rise) / theta_on ON events, so the count falls by 0.235 / 0.2875 = 0.82.
    theta_raised = 0.235 + 0.0659 * math.log(255.0 / 115.0)
    assert on_raised == pytest.approx(on_default * 0.235 / theta_raised, rel=0.05)
    assert on_raised < on_default
