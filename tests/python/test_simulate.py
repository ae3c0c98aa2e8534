"""Scenarios and the end-to-end simulation: adaptive and sparse sampling, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from evstwin.presets import get_preset
from evstwin.scenario import ScenarioError, build, builtin_names, load, parse_assignment, set_value, to_toml
from evstwin.simulate import simulate

NOISE_FREE = {
    "photon_shot_noise": False,
    "dark_model": "none",
    "leak_rate_hz": 0.0,
    "shot_noise_rate_hz": 0.0,
    "refractory_s": 0.0,
    "pr_pole": False,  # the engine's single-pole model, whose sampling behaviour these tests pin
}


def spinning(rate_hz: float, max_shift_px: float = 0.25, sparse: bool = True, noise: bool = False, **pixel):
    """A 64 x 48 window with one bright source on a 15 px circle, two turns per second
    (188 px/s): 250 Hz sampling would move it 0.75 px per sample."""
    pix = {} if noise else dict(NOISE_FREE)
    pix.update(pixel)
    # Noise-free runs have no dark current, so a dim room light keeps the log finite.
    return {
        "background": {"photon_rate_ph_s": 3.5e7},
        "name": "spin",
        "duration_s": 0.5,
        "sensor": {"preset": "davis346", "width": 64, "height": 48},
        "pixel": pix,
        "optics": {"extra_blur_sigma_px": 0.6},
        "sampling": {"rate_hz": rate_hz, "max_shift_px": max_shift_px, "sparse": sparse, "chunk_samples": 20},
        "targets": [{"kind": "circular", "centre_x_px": 32.0, "centre_y_px": 24.0, "radius_px": 15.0,
                     "period_s": 0.5, "flux_ph_s": 1e9, "label": "led"}],
    }


def test_builtin_scenarios_build() -> None:
    names = builtin_names()
    for required in ("mcreynolds", "mcreynolds-run1", "mcreynolds-run2", "mcreynolds-run3", "geo-stare",
                     "imx636-pointsource"):
        assert required in names
    run3 = build("mcreynolds-run3")
    assert (round(run3.params.theta_on, 4), round(run3.params.theta_off, 4)) == (0.2577, 0.218)
    assert run3.params.dark_rate_e_per_s == 290.0 and run3.params.leak_rate_hz == 0.0
    base = build("mcreynolds")
    assert len(base.targets) == 5 and base.width == 346 and base.height == 260
    assert math.isclose(base.params.theta_on, 0.2061, rel_tol=1e-3)
    geo = build("geo-stare")
    assert geo.targets[0].label == "geo" and len(geo.targets) == 41
    # geo-stare's telescope on the IMX636: its own pixel (not geo-stare's DAVIS346 bias set), the
    # satellite at 15.04 arcsec/s = 30 px/s at 4.86 um / 2 m = 0.501 arcsec/px, long steps on.
    imx = build("geo-stare-imx636")
    own = get_preset("imx636").pixel
    assert (imx.width, imx.height, imx.params.theta_on, imx.params.theta_off, imx.params.cutoff_hz) == \
        (1280, 720, own.theta_on, own.theta_off, own.cutoff_hz)
    assert imx.static_step_s == 0.5 and len(imx.targets) == 41 and imx.targets[0].label == "geo"
    assert math.isclose(imx.optics.plate_scale_arcsec_per_px, 4.86e-6 / 2.0 * 206264.8, rel_tol=1e-4)
    assert math.isclose(imx.targets[0].vx_px_s, 15.04 / (4.86e-6 / 2.0 * 206264.8), rel_tol=1e-3)


def test_set_overrides_one_value_and_names_bad_keys() -> None:
    s = load("mcreynolds")
    assert parse_assignment("pixel.theta_on=0.25") == ("pixel.theta_on", 0.25)
    assert parse_assignment("sensor.bias_set=paper_run_3") == ("sensor.bias_set", "paper_run_3")
    s2 = set_value(s, "pixel.dark_rate_e_per_s", 290)
    assert build(s2).params.dark_rate_e_per_s == 290.0
    assert build(set_value(s, "pixel.theta_on", 0.25)).params.theta_on == 0.25
    assert build(set_value(s, "targets.0.flux_ph_s", 5e8)).targets[0].flux_ph_s(0.0) == 5e8
    assert build(set_value(s, "pixel.cutoff_hz", "none")).params.cutoff_hz is None
    with pytest.raises(ScenarioError, match=r"unknown scenario key 'pixel.theta'; allowed: theta_on"):
        set_value(s, "pixel.theta", 0.3)
    with pytest.raises(ScenarioError, match=r"unknown scenario key 'sensr'"):
        set_value(s, "sensr.preset", "x")
    with pytest.raises(ScenarioError, match=r"targets.7: index must be 0..0"):
        set_value(s, "targets.7.flux_ph_s", 1.0)


@pytest.mark.parametrize(
    "change,message",
    [
        ({"pixel": {"theta_on": -0.1}}, r"pixel.theta_on: theta_on must be in \[0.001, 10\].*got theta_on=-0.1"),
        ({"pixel": {"dark_model": "thermal"}}, r"pixel.dark_model: dark_model must be one of 'poisson', 'paper', 'none'"),
        ({"pixel": {"theta": 0.2}}, r"unknown scenario key 'pixel.theta'"),
        ({"targets": [{"kind": "circular", "radius_px": 5, "period_s": 1, "flux_ph_s": -1.0}]},
         r"targets\[0\].flux_ph_s must be >= 0 and <= 1e\+25; got -1.0"),
        ({"targets": [{"kind": "circular", "radius_px": -5, "period_s": 1, "flux_ph_s": 1.0}]},
         r"targets\[0\]: radius_px must be > 0"),
        ({"targets": [{"kind": "comet", "flux_ph_s": 1.0}]}, r"targets\[0\].kind must be one of static, linear"),
        ({"targets": [{"kind": "static", "x_px": 1, "y_px": 1}]}, r"targets\[0\] needs exactly one of flux_ph_s"),
        ({"sampling": {"rate_hz": 0}}, r"sampling.rate_hz must be > 0"),
        ({"sensor": {"preset": "davis240"}}, r"sensor.preset must be one of davis346, davis346_paper, imx636, prophesee_gen3_vga; got 'davis240'"),
        ({"sensor": {"width": 400}}, r"sensor.width must be in \[1, 346\] for preset 'davis346'; got 400"),
        ({"duration_s": -1}, r"duration_s must be > 0"),
        ({"biases": {"i_on_a": 1e-9, "i_off_a": 2e-9, "i_diff_a": 5e-9}}, r"biases"),
    ],
)
def test_bad_scenarios_get_one_clear_line(change: dict, message: str) -> None:
    s = {"name": "bad", "sensor": {"preset": "davis346", "width": 32, "height": 24}}
    for key, value in change.items():
        if isinstance(value, dict) and key in s:
            s[key] = {**s[key], **value}
        else:
            s[key] = value
    with pytest.raises(ScenarioError, match=message) as info:
        build(s)
    assert "\n" not in str(info.value)


def test_scenario_file_and_base_merge(tmp_path) -> None:
    path = tmp_path / "mine.toml"
    path.write_text('base = "mcreynolds"\nname = "mine"\n[pixel]\ntheta_on = 0.3\n[sensor]\nwidth = 100\n')
    scene = build(path)
    assert scene.params.theta_on == 0.3 and scene.width == 100 and scene.height == 260
    assert scene.params.theta_off == pytest.approx(0.093, rel=1e-3)  # from the base's biases
    (tmp_path / "broken.toml").write_text("name = \n")
    with pytest.raises(ScenarioError, match="invalid TOML"):
        build(tmp_path / "broken.toml")
    with pytest.raises(ScenarioError, match="does not exist"):
        build(tmp_path / "missing.toml")


def track_pixels(result) -> set[tuple[int, int]]:
    truth = next(iter(result.meta["truth"].values()))
    # Pixel centres the source centre passes within 0.3 px of.
    pts = set()
    for x, y in zip(truth["x_px"], truth["y_px"]):
        if abs(x - round(x)) < 0.3 and abs(y - round(y)) < 0.3:
            pts.add((int(round(x)), int(round(y))))
    return pts


def test_adaptive_sampling_leaves_no_track_pixel_without_events() -> None:
    coarse = simulate(spinning(50.0, max_shift_px=1e3))  # adaptation off: 3.8 px per sample
    adaptive = simulate(spinning(50.0))
    assert adaptive.sub_sampled_chunks > 0 and coarse.sub_sampled_chunks == 0
    on_track = track_pixels(adaptive)
    assert len(on_track) > 40

    def fired(result) -> set[tuple[int, int]]:
        return set(zip(result.events["x"].tolist(), result.events["y"].tolist()))

    assert on_track <= fired(adaptive)
    assert len(on_track - fired(coarse)) > 5  # the coarse run skips pixels of the track


def test_event_count_converges_as_the_floor_rate_rises() -> None:
    counts = {r: len(simulate(spinning(r, max_shift_px=1e3)).events) for r in (100.0, 400.0, 1600.0, 6400.0)}
    steps = [abs(counts[b] - counts[a]) for a, b in [(100.0, 400.0), (400.0, 1600.0), (1600.0, 6400.0)]]
    assert steps[0] > steps[1] > steps[2]
    assert steps[2] < 0.02 * counts[6400.0]
    # The adaptive run at a low floor lands near the converged count.
    adaptive = len(simulate(spinning(100.0)).events)
    assert abs(adaptive - counts[6400.0]) < 0.05 * counts[6400.0]


def test_sparse_sub_sampling_gives_the_dense_events_without_noise() -> None:
    sparse = simulate(spinning(100.0, sparse=True, cutoff_hz=40.0))
    dense = simulate(spinning(100.0, sparse=False, cutoff_hz=40.0))
    assert sparse.sub_sampled_chunks > 0 and len(dense.events) > 500
    assert sparse.events.tobytes() == dense.events.tobytes()
    assert sparse.pixel_updates < 0.5 * dense.pixel_updates


def test_sparse_sub_sampling_keeps_the_statistics_with_noise() -> None:
    kw = dict(shot_noise_rate_hz=5.0, leak_rate_hz=2.0)
    sparse = [simulate(spinning(100.0, sparse=True, noise=True, **kw), seed=s).events for s in range(3)]
    dense = [simulate(spinning(100.0, sparse=False, noise=True, **kw), seed=s).events for s in range(3)]
    for pol in (0, 1):
        a = sum(int(np.sum(e["p"] == pol)) for e in sparse)
        b = sum(int(np.sum(e["p"] == pol)) for e in dense)
        assert abs(a - b) < 0.05 * (a + b) / 2 + 5 * math.sqrt(a + b), (pol, a, b)


def test_same_seed_same_events_whatever_the_threads() -> None:
    s = spinning(100.0, noise=True, threshold_sigma=0.05)
    one = simulate(s, seed=3, num_threads=1)
    two = simulate(s, seed=3, num_threads=2)
    assert len(one.events) > 0 and one.events.tobytes() == two.events.tobytes()
    assert simulate(s, seed=4).events.tobytes() != one.events.tobytes()
    truth = one.meta["truth"]["led"]
    assert np.all(np.diff(truth["t_s"]) > 0)
    np.testing.assert_allclose(np.hypot(truth["x_px"] - 32, truth["y_px"] - 24), 15.0)


def test_reused_tables_give_the_events_of_fresh_ones(monkeypatch: pytest.MonkeyPatch) -> None:
    # The chunks' frames and the sub-sampled units' fine rates and haloed base frames reuse
    # their memory from one engine call to the next (_Runner._buffer). With units of several
    # sizes (a source that stops, then moves off fast), dense and sub-sampled chunks in turn
    # and a halo, the events must be those of fresh tables, byte for byte.
    import importlib

    runner = importlib.import_module("evstwin.simulate")._Runner
    s = spinning(100.0, noise=True, threshold_sigma=0.05)
    s["optics"] = {"extra_blur_sigma_px": 0.6, "halo_fraction": 0.3, "halo_fwhm_px": 4.0, "halo_half_width_px": 40}
    s["targets"].append({"kind": "tabulated", "t_s": [0.0, 0.1, 0.3, 0.5], "x_px": [10.0, 10.0, 10.0, 50.0],
                         "y_px": [10.0, 10.0, 10.0, 40.0], "flux_ph_s": 1e9})
    s["sampling"]["chunk_samples"] = 7
    reused = simulate(s, seed=5)
    shapes: list[tuple[int, ...]] = []

    def fresh_buffer(self: object, name: str, shape: tuple[int, ...]) -> np.ndarray:
        shapes.append(shape)
        return np.full(shape, np.nan)  # a table the code failed to overwrite would show

    monkeypatch.setattr(runner, "_buffer", fresh_buffer)
    fresh = simulate(s, seed=5)
    assert reused.sub_sampled_chunks > 0 and len(fresh.events) > 500
    assert len(set(shapes)) > 3  # tables of several shapes took turns in the same memory
    assert reused.events.tobytes() == fresh.events.tobytes()


@pytest.mark.parametrize("sparse", [True, False])
def test_same_seed_same_events_whatever_the_chunking(sparse: bool) -> None:
    # The fine-sampling decision is made per fixed unit of base intervals, not per chunk, so
    # chunk_samples (1, 7, 50, 1000) changes nothing, with noise on and with a source whose
    # speed changes (it stops for a while, then moves off fast): before, a pixel's time grid
    # followed the chunk it fell in, and so did its random numbers and crossing times.
    s = spinning(100.0, sparse=sparse, noise=True, threshold_sigma=0.05)
    s["targets"].append({"kind": "tabulated", "t_s": [0.0, 0.1, 0.3, 0.5], "x_px": [10.0, 10.0, 10.0, 50.0],
                         "y_px": [10.0, 10.0, 10.0, 40.0], "flux_ph_s": 1e9})
    runs = []
    for chunk in (1, 7, 50, 1000):
        s["sampling"]["chunk_samples"] = chunk
        runs.append(simulate(s, seed=5, labels=True))
    assert runs[0].sub_sampled_chunks > 0 and len(runs[0].events) > 500
    for r in runs[1:]:
        assert r.events.tobytes() == runs[0].events.tobytes()
        assert r.labels is not None and runs[0].labels is not None
        assert r.labels.tobytes() == runs[0].labels.tobytes()


def test_monte_carlo_runs_are_reproducible_and_run_in_parallel_processes() -> None:
    from evstwin.simulate import run_many

    scenario = spinning(100.0, noise=True, threshold_sigma=0.05)
    scenario["duration_s"] = 2.0  # six jobs, long enough that both workers take some
    seeds = list(range(6))
    runs = run_many(scenario, seeds=seeds, processes=2)
    assert len({r.process_id for r in runs}) == 2
    for seed, r in zip(seeds, runs):
        assert r.events.tobytes() == simulate(scenario, seed=seed).events.tobytes()
    assert runs[0].events.tobytes() != runs[1].events.tobytes()


@pytest.mark.parametrize("text", ["", "name = 'x'\n", "[sensor]\nwidth = 64\n", "[pixel]\ntheta_on = 0.3\n"])
def test_a_scenario_must_name_its_sensor(tmp_path, text: str) -> None:
    path = tmp_path / "s.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError, match=r"must name its sensor: \[sensor\] preset"):
        load(path)


def test_user_scenarios_get_the_builtins_photoreceptor_pole(tmp_path) -> None:
    path = tmp_path / "s.toml"
    path.write_text("[sensor]\npreset = 'davis346'\n")
    assert load(path)["pixel"]["pr_pole"] is True and build(path).params.pr_pole is True
    path.write_text("[sensor]\npreset = 'davis346'\n[pixel]\npr_pole = false\n")
    assert build(path).params.pr_pole is False  # an explicit choice is kept
    # A scenario based on a built-in inherits the built-in's value.
    assert load({"base": "mcreynolds"})["pixel"]["pr_pole"] is True


@pytest.mark.parametrize(
    ("assignment", "message"),
    [
        ("pixel=1", "pixel is a table"),
        ("pixel.theta_on=1" + "0" * 400, "pixel.theta_on: 100000000000...(401 digits) does not fit"),
        ("star_field.counts_slope=1e300", "star_field.counts_slope must be in [-5, 5]"),
        ("optics.mean_wavelength_m=2", "optics: mean_wavelength_m must be in [1e-10, 0.1]"),
        ("optics.mean_wavelength_m=0.01", "PSF sigma of 973 px (> 100)"),
        ("optics.focal_length_m=1e-300", "optics: focal_length_m must be in [1e-05, 10000]"),
        ("optics.extra_blur_sigma_px=150", "optics give a PSF sigma of 150 px (> 100)"),
        ("optics.f_number=5e-324", "optics: f_number must be in [0.01, 100000] (a physical range"),
        ("targets.0.wx_arcsec_s=1e300", "targets[0] moves 5.24e+299 px/s"),
        ("sampling.max_shift_px=1e-300", "sampling.max_shift_px=1e-300"),
        ("sampling.rate_hz=1e-300", "sampling.rate_hz=1e-300"),
        ('sensor.width="abc"', "sensor.width must be an integer; got 'abc'"),
        ("sensor.width=1.5", "sensor.width must be an integer; got 1.5"),
        ("sensor.width=true", "sensor.width must be an integer; got True"),
        ("targets.0.kind={a = 1}", "targets[0].kind must be one of"),
        ("background.sky_mag_per_arcsec2=-30", "a pixel could receive 2.28e+22 photons/s (> 1e+20, the engine's "
                                               "limit): background={'sky_mag_per_arcsec2': -30} gives 2.28e+22"),
        ("targets.0.magnitude=-30", "the brightest targets[0] at 5.36e+21 photons/s"),
        # issue 29: spectra, bands and the sensor's temperature
        ('photometry.band="U"', "photometry.band: band must be V, G or the path of a .csv response; got 'U'"),
        ('photometry.spectrum="led:1200:20"', "photometry.spectrum: LED peak must be in [300, 1100] nm; got 1200 nm"),
        ('photometry.spectrum="bv:5"', "photometry.spectrum: B-V colour must be in [-0.4, 2.0]"),
        ('targets.0.spectrum="plasma"', "targets[0].spectrum: spectrum must be one of sun, night-sky, flat"),
        ('photometry.filter_file="no-such-filter.csv"', "photometry.filter_file: photometry.filter_file file "
                                                        "'no-such-filter.csv' cannot be read"),
        ("sensor.temperature_c=200", "sensor.temperature_c: temperature_c must be in [-30, 70] degC"),
        ("sensor.k=4.0", "biases with sensor.k=4.0 (sensor.bias_set='fast_pr_slow_sf_balanced_th'): theta_on must be"),
        ("optics.zero_point_ph_s_m2=1e30", "optics={'focal_length_m': 2.0, 'f_number': 4.0, 'transmission': 0.8, "),
        ("star_field.n_stars=1000000000", "star_field gives 1e+09 stars (> 1e+06, about 300 GB of targets): lower "
                                          "star_field.n_stars"),
        ("sampling.chunk_samples=100000", "sampling.chunk_samples=100000 frames of 346x260 pixels take 67 GiB"),
        ("sampling.max_shift_px=1e-9", "7.88e+07 sub-samples per base sample; one chunk of 1.58e+08 fine samples"),
        ("name=1", "name must be a string; got 1"),
        ("sampling.max_events=0", "sampling.max_events must be in [1, 4294967295]; got 0"),
        ("sampling.max_events=1.5", "sampling.max_events must be an integer; got 1.5"),
        ("pixel.lowpass=3", "pixel.lowpass: lowpass must be a string; got lowpass=3"),
        ("seed=1e300", "seed must be an integer"),
        # Found by tests/python/test_fuzz_scenario.py: accepted by build, then refused by the engine
        # (naming no key) or a traceback.
        ("pixel.shot_noise_rate_hz=346", "pixel.shot_noise_rate_hz=346 x max(1, pixel.shot_noise_factor=0.25) / "
                                         "sampling.rate_hz=100 = 3.46 must be <= 0.5"),
        ("optics.aperture_diameter_m=1e300", "optics: aperture_diameter_m must be in [1e-07, 10000]"),
        ('pixel.dark_model="0\\n0"', "pixel.dark_model: dark_model must be one of 'poisson', 'paper', 'none'; "
                                      "got dark_model='0\\n0'"),
        ("sensor.k=nan", "sensor.k must be finite; got nan"),
    ],
)
def test_bad_scenario_values_are_one_line_naming_the_key(tmp_path, capsys, assignment: str, message: str) -> None:
    # Each used to end in a traceback (AttributeError, OverflowError, MemoryError after
    # minutes) or in an error that did not name the key (issue 11).
    from evstwin.cli import main

    out = tmp_path / "o.h5"
    assert main(["simulate", "geo-stare", "-o", str(out), "--duration", "0.01", "--no-progress",
                 "--set", assignment]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err
    assert not out.exists()


def test_pixel_params_overflow_is_a_value_error() -> None:
    from evstwin import PixelParams

    with pytest.raises(ValueError, match="theta_on must fit a 64-bit float; got a number of 401 digits"):
        PixelParams(theta_on=10**400)
    # NumPy scalars are numbers like any other; a bool is not.
    assert PixelParams(theta_on=np.int64(1)).theta_on == 1 and PixelParams(theta_on=np.float32(0.5)).theta_on == 0.5
    with pytest.raises(TypeError, match="theta_on must be a number; got theta_on=True"):
        PixelParams(theta_on=True)


def test_star_density_and_implied_samples_are_bounded_up_front() -> None:
    # A density of 65535 stars per square degree on a wide field, or a target so fast that
    # sub-sampling it would take 1e12 samples, used to run out of memory (issue 9).
    wide = {"base": "mcreynolds", "star_field": {"density_per_deg2": 65535.0}}
    with pytest.raises(ScenarioError, match=r"star_field gives .* stars \(> 1e\+06.*lower star_field.density_per_deg2"):
        build(wide)
    fast = {"base": "geo-stare", "duration_s": 1000.0, "targets": [
        {"kind": "linear", "x0_px": 0.0, "y0_px": 0.0, "vx_px_s": 1e9, "flux_ph_s": 1e6}]}
    with pytest.raises(ScenarioError, match=r"targets\[0\] moves 1e\+09 px/s.*samples over duration_s=1000.0"):
        build(fast)
    with pytest.raises(ScenarioError, match=r"duration_s x sampling.rate_hz = 1e\+10 samples \(> 1e\+09\)"):
        build({"base": "geo-stare", "duration_s": 1e7, "sampling": {"rate_hz": 1e3}})


def test_sampling_max_events_is_read_into_the_scene() -> None:
    assert build("geo-stare").max_events is None  # the engine's default
    scene = build(set_value(load("geo-stare"), "sampling.max_events", 5000))
    assert scene.max_events == 5000
    assert "max_events = 5000" in to_toml(scene.scenario)


def test_a_target_distance_that_overflows_names_the_target() -> None:
    with pytest.raises(ScenarioError, match=r"targets\[0\]: length_m / distance_m give image coordinates that overflow"):
        build(set_value(load("mcreynolds"), "targets.0.distance_m", 5e-324))


def test_a_scenario_without_dark_current_needs_a_background() -> None:
    # The engine refuses a zero rate where there is no dark current: pixels away from the
    # targets see only the background (found by the scenario fuzz).
    with pytest.raises(ScenarioError, match=r"with no dark current \(pixel.dark_model='poisson', "
                                            r"pixel.dark_rate_e_per_s=0\) the background must be >= 1e-30"):
        build(set_value(load("mcreynolds"), "pixel.dark_rate_e_per_s", 0))
    scene = build({"base": "mcreynolds", "pixel": {"dark_rate_e_per_s": 0}, "background": {"photon_rate_ph_s": 1.0}})
    assert scene.params.dark_rate_e_per_s == 0
    with pytest.raises(ScenarioError, match=r"pixel.lowpass='euler' \(eq. 7\) is unstable when 2 pi pixel.cutoff_hz / "
                                            r"sampling.rate_hz > 2; got cutoff_hz=100, rate_hz=250"):
        build({"base": "mcreynolds", "pixel": {"lowpass": "euler", "cutoff_hz": 100.0}})


def test_a_key_below_a_value_is_a_scenario_error() -> None:
    # sensor.width=1 then sensor.width.x=0 was a TypeError (found by the scenario fuzz).
    s = set_value(load("geo-stare"), "sensor.width", 1)
    with pytest.raises(ScenarioError, match=r"sensor.width is a value \(1\), not a table: 'sensor.width.x' does not"):
        set_value(s, "sensor.width.x", 0)
    with pytest.raises(ScenarioError, match=r"sensor.width is a value \(1\), not a table: 'sensor.width.x.y'"):
        set_value(s, "sensor.width.x.y", 0)


def test_a_pre_roll_starts_the_recording_where_a_longer_run_would_be() -> None:
    # sampling.pre_roll_s: the sensor watches the scene before t = 0 and its events there are
    # dropped. A noise-free periodic scene is periodic once it has settled, so a run with two
    # periods of pre-roll must record what a run without one records in its third period,
    # shifted back by two periods (the same pixels, counts and times, to the microsecond
    # rounding of times that differ by float rounding of the phase).
    period = 0.5
    plain = spinning(1000.0, max_shift_px=1e3, cutoff_hz=200.0)
    plain["duration_s"] = 3 * period
    rolled = spinning(1000.0, max_shift_px=1e3, cutoff_hz=200.0)
    rolled["duration_s"] = period
    rolled["sampling"]["pre_roll_s"] = 2 * period
    a, b = simulate(plain), simulate(rolled)
    late = a.events[a.events["t"] >= 2 * period * 1e6]
    assert len(b.events) > 500 and b.events["t"].min() >= 0 and len(late) == len(b.events)
    key = lambda e: np.lexsort((e["p"], e["x"], e["y"], e["t"]))  # noqa: E731
    la, lb = late[key(late)], b.events[key(b.events)]
    assert np.array_equal(la[["x", "y", "p"]], lb[["x", "y", "p"]])
    assert np.abs(la["t"] - 2 * period * 1e6 - lb["t"]).max() <= 1
    # Without the pre-roll the first period differs: the pixels start at the light of t = 0.
    first = a.events[a.events["t"] < period * 1e6]
    assert len(first) != len(b.events) or not np.array_equal(first["x"], b.events["x"])
    # The ground truth starts at t = 0, and the file says how long the sensor watched before.
    assert b.meta["truth"]["led"]["t_s"][0] == 0.0 and b.meta["pre_roll_s"] == 2 * period


def test_the_progress_bar_says_where_a_pre_roll_is(capsys: pytest.CaptureFixture[str]) -> None:
    # The bar counts sensor time from t = 0, so during a long pre-roll it sat at 0; it now
    # says how far the pre-roll has got, and stops saying so once the run proper begins.
    rolled = spinning(1000.0, max_shift_px=1e3, cutoff_hz=200.0)
    rolled["duration_s"] = 0.1
    rolled["sampling"].update(pre_roll_s=0.5, chunk_samples=100)
    simulate(rolled, progress=True)
    err = capsys.readouterr().err
    assert "pre-roll 0.4/0.5 s" in err and "pre-roll 0.5/0.5 s" not in err, err[-400:]


def test_pre_roll_must_be_a_non_negative_number() -> None:
    s = spinning(1000.0)
    s["sampling"]["pre_roll_s"] = -1.0
    with pytest.raises(ScenarioError, match=r"sampling.pre_roll_s must be >= 0 and <= 1e\+06; got -1.0"):
        build(s)


def test_a_coarse_pre_roll_leaves_a_slow_scene_where_a_fine_one_does() -> None:
    # sampling.pre_roll_rate_hz: the pre-roll only sets each pixel's state at t = 0. A slow,
    # smooth, noise-free drift crosses the same thresholds whatever the sampling, so a 20 Hz
    # pre-roll gives the events of a 1 kHz one but where a coarse sample missed a crossing at
    # the top of a pixel's light (measured: one event of 262), and both differ from none.
    def drift(pre_roll_rate_hz: float | None) -> dict:
        s = {"name": "drift", "duration_s": 1.0, "sensor": {"preset": "davis346", "width": 64, "height": 48},
             "background": {"photon_rate_ph_s": 3.5e7}, "pixel": dict(NOISE_FREE, cutoff_hz=None),
             "optics": {"extra_blur_sigma_px": 6.0},
             "sampling": {"rate_hz": 1000.0, "chunk_samples": 50},
             "targets": [{"kind": "linear", "x0_px": 20.0, "y0_px": 24.0, "vx_px_s": 8.0, "vy_px_s": 1.0,
                          "flux_ph_s": 3e9, "label": "star"}]}
        if pre_roll_rate_hz is not None:
            s["sampling"].update(pre_roll_s=2.0, pre_roll_rate_hz=pre_roll_rate_hz)
        return s
    fine, coarse, none = simulate(drift(1000.0)), simulate(drift(20.0)), simulate(drift(None))
    assert len(fine.events) > 200 and coarse.meta["pre_roll_rate_hz"] == 20.0

    def counts(e: np.ndarray) -> np.ndarray:
        return np.bincount((e["y"].astype(np.int64) * 64 + e["x"]) * 2 + e["p"], minlength=64 * 48 * 2)

    diff = counts(fine.events) - counts(coarse.events)
    assert np.abs(diff).max() <= 1 and np.count_nonzero(diff) <= 0.01 * len(fine.events)
    assert len(none.events) < len(fine.events)  # without it the first threshold takes longer


def test_what_a_pre_roll_cannot_do_is_refused_by_name() -> None:
    # A table that starts at t = 0 cannot be placed before it; a drifting random star field is
    # drawn for [0, duration_s] only. Both are one error naming sampling.pre_roll_s.
    s = spinning(1000.0)
    s["sampling"]["pre_roll_s"] = 0.5
    s["targets"] = [{"kind": "tabulated", "t_s": [0.0, 0.5], "x_px": [10.0, 20.0], "y_px": [10.0, 12.0],
                     "flux_ph_s": 1e9, "label": "tab"}]
    with pytest.raises(ScenarioError, match=r"sampling.pre_roll_s=0.5: targets\[0\].* cannot be placed before t = 0"):
        build(s)
    geo = {"base": "geo-stare", "sampling": {"pre_roll_s": 1.0}, "star_field": {"drift_px_s": [3.0, 0.0]}}
    with pytest.raises(ScenarioError, match=r"sampling.pre_roll_s=1.0 with a drifting \[star_field\] of random stars"):
        build(geo)
    big = spinning(1000.0)
    big["sampling"].update(pre_roll_s=1e6, pre_roll_rate_hz=1e4)
    with pytest.raises(ScenarioError, match=r"sampling.pre_roll_s=1000000.0 x sampling.pre_roll_rate_hz=10000.0"):
        build(big)


def test_the_lit_pixels_and_the_rendered_blocks_are_those_of_the_windows(monkeypatch: pytest.MonkeyPatch) -> None:
    # The sub-sampled units fix their hot pixels from the windows' rectangles before any
    # window is rendered, then render a block of samples at a time and drop it (the rendered
    # windows of a whole unit were ~3 times its rates table: 0.3 GB of a 200 x 200 ROI). The
    # rectangles must be exactly the rendered windows' pixels, partly off the sensor included,
    # and the blocks together exactly one call's contributions, in its order.
    import importlib

    from evstwin import psf

    sim = importlib.import_module("evstwin.simulate")
    s = spinning(250.0)
    s["optics"] = {"extra_blur_sigma_px": 3.0}  # a 31 px window, off the 64 x 48 sensor at times
    s["targets"].append({"kind": "linear", "x0_px": -10.0, "y0_px": 50.0, "vx_px_s": 80.0, "vy_px_s": -20.0,
                         "flux_ph_s": 1e9})
    scene = build(s)
    runner = sim._Runner(scene, 1, truth_sink=lambda name, rows: None)
    t = np.linspace(0.0, 0.5, 200)
    x, y, f = runner._sources(t, truth=False)
    f[3, 0] = 0.0  # a source without flux lights nothing
    monkeypatch.setattr(psf.render, "_CHUNK_ELEMENTS", 31 * 31 * 5)  # several blocks
    blocks = list(runner._contribution_parts(x, y, f, runner._fine_groups))
    assert len(blocks) > 20 and all(idx.size <= 31 * 31 * 10 for idx, _ in blocks)
    npix = scene.width * scene.height
    whole = [psf.contributions(scene.width, scene.height, x[:, cols].reshape(-1), y[:, cols].reshape(-1),
                               f[:, cols].reshape(-1), shape, offset=np.repeat(np.arange(t.size), cols.size) * npix)
             for shape, cols in runner._fine_groups]
    idx_all = np.concatenate([i for i, _ in blocks])
    np.testing.assert_array_equal(idx_all, np.concatenate([i for g in whole for i, _ in g]))
    np.testing.assert_array_equal(np.concatenate([v for _, v in blocks]), np.concatenate([v for g in whole for _, v in g]))
    lit = np.zeros(npix, bool)
    lit[np.unique(idx_all % npix)] = True
    partial = ~np.all((x > 15) & (x < 48) & (y > 15) & (y < 32))
    assert partial and 0 < lit.sum() < npix
    np.testing.assert_array_equal(runner._lit(x, y, f), lit)


@pytest.mark.parametrize("duration_s", [0.33, 0.77])
def test_the_progress_bar_ends_at_the_duration(duration_s: float, capsys: pytest.CaptureFixture[str]) -> None:
    # One update a chunk: the bar's position is set, not added up from rounded steps, whose
    # sum ended past the total at these durations (TqdmWarning "clamping frac", ETA -00:00).
    import warnings

    s = {"name": "bar", "duration_s": duration_s, "sensor": {"preset": "davis346", "width": 8, "height": 8},
         "background": {"photon_rate_ph_s": 1e6}, "sampling": {"rate_hz": 200.0, "chunk_samples": 1}}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        simulate(s, progress=True, num_threads=1)
    last = capsys.readouterr().err.replace("\r", "\n").strip().splitlines()[-1]
    assert f"{duration_s:.2f}/{duration_s:.2f} s sensor time" in last and "-00:00" not in last
