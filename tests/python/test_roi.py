"""Region of interest, pixel mask, hot-pixel rule and the distance that stays finite (issue 10).

Every recording here is made by hand or simulated (a few hundred pixels, well under a
second of sensor time): nothing needs ../shared/data."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest

from evstwin import tune, validation
from evstwin.analysis import pixel_counts
from evstwin.cli import main
from evstwin.sensor import EVENT_DTYPE
from evstwin.simulate import simulate
from evstwin.validation.region import Roi, hot_pixels, mask_array, parse_pixel_list, read_pixel_file


def events_at(rows: list[tuple[int, int, int, int]]) -> np.ndarray:
    """Events from (t_us, x, y, p) rows."""
    ev = np.zeros(len(rows), dtype=EVENT_DTYPE)
    for i, (t, x, y, p) in enumerate(rows):
        ev["t"][i], ev["x"][i], ev["y"][i], ev["p"][i] = t, x, y, p
    return ev


def noiseless_scene() -> dict:
    """64 x 48 px, 0.3 s, two moving sources, no noise of any kind and no readout: every event
    is the signal's, the same whatever the pixels' random keys."""
    return {
        "name": "noiseless",
        "duration_s": 0.3,
        "seed": 3,
        "sensor": {"preset": "davis346", "width": 64, "height": 48},
        "background": {"photon_rate_ph_s": 2e6},
        "pixel": {"threshold_sigma": 0.0, "shot_noise_rate_hz": 0.0, "leak_rate_hz": 0.0, "dark_model": "none",
                  "hot_pixel_fraction": 0.0, "photon_shot_noise": False},
        "readout": {"enabled": False},
        "targets": [
            {"kind": "linear", "x0_px": 5, "y0_px": 30, "vx_px_s": 150, "vy_px_s": -30, "flux_ph_s": 1e9},
            {"kind": "circular", "radius_px": 8, "period_s": 0.2, "flux_ph_s": 5e8},
        ],
    }


def noise_scene(width: int = 40, height: int = 30, duration_s: float = 1.0) -> dict:
    """A dark field whose pixels all fire as the same Poisson processes (no mismatch, no spread
    of the background rates, no hot pixels): about 2 events per pixel a second."""
    return {
        "name": "noise",
        "duration_s": duration_s,
        "seed": 7,
        "sensor": {"preset": "davis346", "width": width, "height": height},
        "background": {"photon_rate_ph_s": 2e6},
        "pixel": {"threshold_sigma": 0.0, "background_rate_sigma": 0.0, "leak_rate_sigma": 0.0,
                  "hot_pixel_fraction": 0.0, "leak_rate_hz": 0.5, "shot_noise_rate_hz": 1.0},
        "sampling": {"rate_hz": 200.0},
        "readout": {"enabled": False},
    }


# -- the ROI ------------------------------------------------------------------------------------


def test_roi_cuts_and_shifts_events_by_hand() -> None:
    ev = events_at([(0, 0, 0, 1), (1, 2, 1, 0), (2, 4, 2, 1), (3, 5, 2, 1), (4, 2, 3, 0), (5, 3, 0, 1)])
    roi = Roi(2, 1, 3, 2)  # columns 2..4, rows 1..2
    out = roi.crop(ev)
    assert out.dtype == EVENT_DTYPE
    assert [tuple(int(v) for v in e) for e in out[["t", "x", "y", "p"]]] == [(1, 0, 0, 0), (2, 2, 1, 1)]
    assert ev["x"][1] == 2  # the input is not changed
    assert roi.crop(ev[:0]).size == 0


def test_roi_text_and_its_errors_name_the_value() -> None:
    assert Roi.of("980,520,300,200") == Roi(980, 520, 300, 200) == Roi.of((980, 520, 300, 200))
    for bad in ("1,2,3", "a,b,c,d", "1.5,0,2,2"):
        with pytest.raises(ValueError, match="X0,Y0,W,H"):
            Roi.of(bad)
    with pytest.raises(ValueError, match=r"980,520,300,200 .* not inside the 346x260 sensor"):
        Roi(980, 520, 300, 200).check(346, 260)
    with pytest.raises(ValueError, match=r"0,0,0,5 is empty"):
        Roi(0, 0, 0, 5).check(346, 260)
    with pytest.raises(ValueError, match="not inside"):
        Roi(-1, 0, 5, 5).check(346, 260)
    assert Roi(0, 0, 346, 260).check(346, 260) == Roi(0, 0, 346, 260)


def test_windowed_simulation_is_the_full_run_cropped_byte_for_byte_without_noise() -> None:
    scene = noiseless_scene()
    full = simulate(scene)
    roi = Roi(10, 12, 30, 25)
    windowed = copy.deepcopy(scene)
    windowed["sensor"]["roi"] = list(roi.as_tuple())
    win = simulate(windowed)
    assert (win.meta["width"], win.meta["height"]) == (30, 25)
    assert (win.meta["roi_x0_px"], win.meta["roi_y0_px"]) == (10, 12)
    cropped = roi.crop(full.events)
    assert cropped.size > 100  # the sources cross the ROI
    np.testing.assert_array_equal(win.events, cropped)
    # The ground truth is in the ROI's coordinates too.
    name = next(iter(full.meta["truth"]))
    np.testing.assert_allclose(win.meta["truth"][name]["x_px"], full.meta["truth"][name]["x_px"] - 10)


def test_windowed_noise_has_the_full_runs_statistics() -> None:
    """Noise draws are keyed by the simulated array's pixel index, so a window's noise is
    another draw of the same processes: its statistics are the full run's, cut, within the
    Poisson spread of the counts."""
    scene = noise_scene(32, 24, 4.0)
    full = simulate(scene)
    roi = Roi(8, 4, 16, 16)
    windowed = copy.deepcopy(scene)
    windowed["sensor"]["roi"] = list(roi.as_tuple())
    win = simulate(windowed)
    cropped = roi.crop(full.events)
    meta = {"width": roi.width, "height": roi.height, "duration_s": 4.0}
    s = validation.compare(cropped, meta, [(win.events, dict(meta, path="window"))]).sims[0]
    on = [int(np.count_nonzero(e["p"] == 1)) for e in (cropped, win.events)]
    off = [int(np.count_nonzero(e["p"] == 0)) for e in (cropped, win.events)]
    assert min(on + off) > 500
    # |ln| of two Poisson counts' ratio: sigma sqrt(1/a + 1/b); four sigmas
    assert s.distance_terms["rate"] < 4 * math.sqrt(1 / cropped.size + 1 / win.events.size)
    assert s.distance_terms["polarity"] < 4 * math.sqrt(sum(1 / v for v in on + off))
    # the per-pixel distributions: as close as two seeds of the full run are
    other = roi.crop(simulate(scene, seed=8).events)
    ref = validation.compare(cropped, meta, [(other, meta)]).sims[0]
    assert s.distance_terms["w1"] < 2 * ref.distance_terms["w1"] + 0.05
    assert s.max_bin_error_share < 2 * ref.max_bin_error_share + 0.03


def test_roi_outside_the_sensor_in_a_scenario_is_one_error_naming_it() -> None:
    scene = noiseless_scene()
    scene["sensor"]["roi"] = [60, 0, 10, 10]
    with pytest.raises(ValueError, match=r"sensor.roi=\[60, 0, 10, 10\] .* not inside the 64x48 sensor"):
        simulate(scene)
    scene["sensor"]["roi"] = [0, 0, 0, 10]
    with pytest.raises(ValueError, match="empty"):
        simulate(scene)


# -- the mask and the hot-pixel rule -----------------------------------------------------------


def test_mask_removes_exactly_the_listed_pixels() -> None:
    rng = np.random.default_rng(1)
    n = 4000
    ev = np.zeros(n, dtype=EVENT_DTYPE)
    ev["t"] = np.sort(rng.integers(0, 1_000_000, n))
    ev["x"] = rng.integers(0, 8, n)
    ev["y"] = rng.integers(0, 6, n)
    ev["p"] = rng.integers(0, 2, n)
    listed = parse_pixel_list("1,2; 7,5;3,0")
    assert listed == [(1, 2), (7, 5), (3, 0)]
    mask = mask_array(listed, 8, 6)
    assert np.count_nonzero(mask) == 3 and mask[2, 1] and mask[5, 7] and mask[0, 3]
    meta = {"width": 8, "height": 6, "duration_s": 1.0}
    sim = ev[::2]
    comp = validation.compare(ev, meta, [(sim, meta)], mask=mask)
    keep = ~mask[ev["y"], ev["x"]]
    assert comp.real.total == int(np.count_nonzero(keep))
    assert comp.real.on == int(np.count_nonzero(keep & (ev["p"] == 1)))
    keep_s = ~mask[sim["y"], sim["x"]]
    assert comp.sims[0].stats.total == int(np.count_nonzero(keep_s))
    assert comp.pixel_count == 45 and comp.masked_pixels == 3
    assert sum(comp.real_hist["total"]) == pytest.approx(1.0)  # shares of the 45 pixels left
    # the same as comparing recordings that never had those pixels' events
    bare = validation.compare(ev[keep], meta, [(sim[keep_s], meta)], mask=mask)
    assert bare.sims[0].distance == pytest.approx(comp.sims[0].distance)
    # In an ROI: pixels outside it are not in it; a pixel off the sensor is an error.
    in_roi = mask_array(listed, 8, 6, Roi(0, 1, 4, 3))
    assert in_roi.shape == (3, 4) and np.argwhere(in_roi).tolist() == [[1, 1]]
    with pytest.raises(ValueError, match=r"\(9, 0\) is not on the 8x6 sensor"):
        mask_array([(9, 0)], 8, 6)


def test_mask_file_and_bad_lists(tmp_path: Path) -> None:
    f = tmp_path / "hot.txt"
    f.write_text("# hot pixels\n187,261\n5 9  # a comment\n\n")
    assert read_pixel_file(f) == [(187, 261), (5, 9)]
    f.write_text("1,2,3\n")
    with pytest.raises(ValueError, match=r"hot.txt:1: .*x,y"):
        read_pixel_file(f)
    with pytest.raises(ValueError, match="x,y"):
        parse_pixel_list("1;2")


def test_hot_pixel_rule_finds_a_planted_hot_pixel_and_no_false_ones() -> None:
    clean = simulate(noise_scene())
    counts = pixel_counts(clean.events, 40, 30)["total"]
    assert counts.mean() > 1.0  # a real test of the rule, not of an empty recording
    assert not hot_pixels(counts).any()
    planted = noise_scene()
    planted["hot_pixels"] = {"pixels": [[17, 9, 40.0]]}
    hot_run = simulate(planted)
    found = hot_pixels(pixel_counts(hot_run.events, 40, 30)["total"])
    assert np.argwhere(found).tolist() == [[9, 17]]
    # a masked pixel is neither tested nor part of the fit
    already = np.zeros((30, 40), dtype=bool)
    already[9, 17] = True
    assert not hot_pixels(pixel_counts(hot_run.events, 40, 30)["total"], already).any()
    with pytest.raises(ValueError, match="false_alarms"):
        hot_pixels(counts, false_alarms=0.0)


# -- the distance --------------------------------------------------------------------------------


def _dark() -> tuple[np.ndarray, dict]:
    run = simulate(noise_scene(20, 15, 0.5))
    return run.events, {"width": 20, "height": 15, "duration_s": 0.5}


def test_distance_is_zero_for_identical_recordings_and_finite_for_any_pair() -> None:
    ev, meta = _dark()
    on_only = ev[ev["p"] == 1]
    off_only = ev[ev["p"] == 0]
    empty = ev[:0]
    assert validation.compare(ev, meta, [(ev.copy(), meta)]).sims[0].distance == 0.0
    assert validation.compare(on_only, meta, [(on_only, meta)]).sims[0].distance == 0.0
    assert validation.compare(empty, meta, [(empty, meta)]).sims[0].distance == 0.0
    for real in (on_only, off_only, empty, ev):
        for sim in (on_only, off_only, empty, ev):
            for sim_meta in (meta, dict(meta, duration_s=1.7)):  # also by rate
                s = validation.compare(real, meta, [(sim, sim_meta)]).sims[0]
                assert math.isfinite(s.distance), (real.size, sim.size, sim_meta)
                assert set(s.distance_terms) == {"w1", "rate", "polarity"}
                assert s.distance == pytest.approx(sum(s.distance_terms.values()))
    # ON only against both: the polarity term says how far, not infinity
    s = validation.compare(on_only, meta, [(ev, meta)]).sims[0]
    off = int(np.count_nonzero(ev["p"] == 0))
    assert s.distance_terms["polarity"] == pytest.approx(math.log((off + 0.5) / 0.5))
    # The same rates over another duration: zero
    half = ev[ev["t"] < 250_000]
    s = validation.compare(half, dict(meta, duration_s=0.25), [(half, dict(meta, duration_s=0.25))]).sims[0]
    assert s.distance == 0.0


def test_match_objective_and_fit_survive_a_recording_without_off_events() -> None:
    """The issue's failure: no OFF events made every trial's distance infinite and fit ended in
    'every fit trial failed'."""
    scene = noise_scene(20, 15, 0.4)
    run = simulate(scene)
    real = run.events[run.events["p"] == 1]
    meta = {"width": 20, "height": 15, "duration_s": 0.4}
    obj = tune.MatchObjective(real, meta, roi=(2, 3, 12, 8))
    assert (obj.width, obj.height, obj.sensor_width, obj.sensor_height) == (12, 8, 20, 15)
    assert obj.prepare(scene)["sensor"]["roi"] == [2, 3, 12, 8]
    result = tune.fit(real, meta, scene,
                      tune.FitOptions(params=["leak_rate_hz"], budget=2, roi=(2, 3, 12, 8), mask_pixels=[(5, 5)]))
    assert all(math.isfinite(r.distance) for r in result.history)
    assert result.roi == (2, 3, 12, 8) and result.mask is not None and result.mask[2, 3]
    report = result.to_json_dict()
    assert report["roi"] == [2, 3, 12, 8] and report["masked_pixels"] == [[5, 5]]
    assert "roi" not in result.best_scenario["sensor"]  # best.toml is the whole sensor's


def test_bad_regions_fail_before_anything_runs() -> None:
    ev, meta = _dark()
    with pytest.raises(ValueError, match=r"roi 15,0,10,10 .* not inside the 20x15 sensor"):
        tune.MatchObjective(ev, meta, roi=(15, 0, 10, 10))
    with pytest.raises(ValueError, match=r"roi 0,0,5,0 is empty"):
        tune.fit(ev, meta, noise_scene(20, 15, 0.5), tune.FitOptions(params=["leak_rate_hz"], budget=1, roi=(0, 0, 5, 0)))
    with pytest.raises(ValueError, match=r"leaves no pixel of the roi 0,0,2,1"):
        tune.MatchObjective(ev, meta, roi=(0, 0, 2, 1), mask_pixels=[(0, 0), (1, 0)])
    with pytest.raises(ValueError, match="for objective 'match'"):
        tune.make_objective("noise", roi=(0, 0, 2, 2))
    with pytest.raises(ValueError, match="no pixel"):
        validation.compare(ev, meta, [(ev, meta)], mask=np.ones((15, 20), dtype=bool))


# -- the commands --------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def recordings(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A real.h5 with no OFF events and a sim.h5 of the same 20 x 15 dark field."""
    from evstwin.io import write_events

    tmp_path = tmp_path_factory.mktemp("recordings")
    scene = noise_scene(20, 15, 0.5)
    a = simulate(scene)
    b = simulate(scene, seed=11)
    real, sim = tmp_path / "real.h5", tmp_path / "sim.h5"
    write_events(real, a.events[a.events["p"] == 1], a.meta)  # no OFF events
    write_events(sim, b.events, b.meta)
    return real, sim


def test_cli_compare_with_roi_and_mask(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], recordings: tuple[Path, Path]
) -> None:
    real, sim = recordings
    out = tmp_path / "cmp"
    argv = ["compare", str(real), str(sim), "--out", str(out), "--roi", "2,3,12,8", "--mask-pixels", "5,5;0,0"]
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "roi 2,3,12,8" in text and "1 pixel(s) masked" in text and "95 pixels compared" in text
    report = json.loads((out / "compare.json").read_text())
    assert report["real"]["off"] == 0 and report["real"]["pixel_count"] == 95
    assert report["sims"][0]["distance"] is not None and report["sims"][0]["distance"] > 0
    assert (out / "bin_error.png").is_file()
    # A scenario SIM simulates the ROI alone.
    out2 = tmp_path / "cmp2"
    toml = tmp_path / "noise.toml"
    from evstwin.scenario import to_toml

    toml.write_text(to_toml(noise_scene(20, 15, 0.5)))
    assert main(["compare", str(real), str(toml), "--out", str(out2), "--roi", "2,3,12,8", "--mask-hot"]) == 0
    from evstwin.io import read_events

    _, meta = read_events(out2 / "noise_seed0.h5")
    assert (meta["width"], meta["height"]) == (12, 8)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--roi", "15,0,10,10"], "15,0,10,10"),
        (["--roi", "0,0,0,4"], "empty"),
        (["--roi", "0,0,1,1", "--mask-pixels", "0,0"], "leaves no pixel"),
        (["--mask-pixels", "30,1"], "not on the 20x15 sensor"),
        (["--mask-pixels", "3"], "--mask-pixels"),
    ],
)
def test_cli_bad_regions_are_one_line_and_write_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], message: str,
    recordings: tuple[Path, Path],
) -> None:
    real, sim = recordings
    for cmd in (["compare", str(real), str(sim), "--out", str(tmp_path / "o")],
                ["fit", str(real), "--scenario", "mcreynolds", "--out", str(tmp_path / "o")],
                ["sweep", "--scenario", "mcreynolds", "--grid", "theta_on=0.2", "--objective", "match",
                 "--real", str(real), "--out", str(tmp_path / "o")]):
        capsys.readouterr()
        assert main(cmd + extra) == 2
        err = capsys.readouterr().err
        assert err.startswith("evstwin: error: ") and err.count("\n") == 1 or "usage:" in err, err
        assert message in err, (cmd, err)
        assert not (tmp_path / "o").exists()


def test_cli_roi_that_is_not_four_numbers_is_a_usage_error(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["compare", "real.h5", "sim.h5", "--out", "o", "--roi", "1,2,3"])
    assert exit_info.value.code == 2
    assert "--roi takes X0,Y0,W,H in whole pixels (e.g. 980,520,300,200); got '1,2,3'" in capsys.readouterr().err
