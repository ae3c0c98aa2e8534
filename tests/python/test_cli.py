"""The evstwin command end to end: simulate, info, show, timing, compare, and its errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from evstwin import EVENT_DTYPE, read_events
from evstwin.cli import main

DATA = Path(__file__).resolve().parents[1] / "data"


@pytest.fixture(scope="module")
def simulated(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("sim") / "mc.h5"
    assert main(["simulate", "mcreynolds", "-o", str(out), "--duration", "0.5", "--seed", "3",
                 "--no-progress"]) == 0
    return out


def test_simulate_writes_a_file_that_reads_back(simulated: Path, capsys: pytest.CaptureFixture[str]) -> None:
    events, meta = read_events(simulated)
    assert events.dtype == EVENT_DTYPE and len(events) > 1000
    assert (meta["width"], meta["height"]) == (346, 260)
    assert meta["scenario"]["name"] == "mcreynolds" and meta["scenario"]["seed"] == 3
    assert meta["scenario"]["duration_s"] == 0.5
    assert set(meta["truth"]) == {f"led[{i}]" for i in range(5)}
    assert np.all(np.diff(events["t"]) >= 0) and events["t"][-1] <= 500_000
    # The scenario written beside the events reproduces them.
    scenario_file = simulated.parent / "again.toml"
    from evstwin.scenario import to_toml

    scenario_file.write_text(to_toml(meta["scenario"]))
    again = simulated.parent / "again.npz"
    assert main(["simulate", str(scenario_file), "-o", str(again), "--no-progress"]) == 0
    assert read_events(again)[0].tobytes() == events.tobytes()


def test_info_show_and_timing(simulated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", str(simulated)]) == 0
    assert "346 x 260" in capsys.readouterr().out
    assert main(["show", str(simulated), "--out", str(tmp_path / "show")]) == 0
    for name in ("frames", "xyt", "histograms", "event_rate"):
        assert (tmp_path / "show" / f"{name}.png").stat().st_size > 10_000
    assert main(["timing", str(simulated), "--out", str(tmp_path / "timing")]) == 0
    text = capsys.readouterr().out
    assert "led[4]" in text and "attributed to a crossing" in text
    rows = json.loads((tmp_path / "timing" / "timing_bias.json").read_text())
    on, off = (next(r for r in rows["polarity"] if r["group"] == g) for g in ("ON", "OFF"))
    assert 0 < on["p50_s"] < off["p50_s"]  # the slow decay makes OFF events later than ON


def test_compare_a_real_davis_recording_with_a_scenario(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    real = DATA / "davis346_road_cut.aedat4"
    out = tmp_path / "cmp"
    assert main(["compare", str(real), "mcreynolds", "--out", str(out), "--duration", "0.2", "--runs", "2"]) == 0
    report = json.loads((out / "compare.json").read_text())
    real_events, _ = read_events(real)
    assert report["real"]["total"] == len(real_events) == 2000
    assert {"total", "on", "off", "on_off_ratio", "duration_s"} <= set(report["real"])
    sim = report["sims"][0]
    assert {"path", "total", "on", "off", "on_off_ratio", "distance", "max_bin_error_share"} <= set(sim)
    assert sim["distance"] > 0 and report["monte_carlo"]["runs"] == 2
    for name in ("frames", "xyt", "histograms", "percent_error", "bin_error", "event_rate", "percent_error_mc"):
        assert (out / f"{name}.png").stat().st_size > 10_000
    # Comparing a recording with itself gives zero distance.
    assert main(["compare", str(real), str(real), "--out", str(tmp_path / "self")]) == 0
    assert json.loads((tmp_path / "self" / "compare.json").read_text())["sims"][0]["distance"] == 0


@pytest.mark.parametrize(
    "argv,message",
    [
        (["simulate", "nosuch", "-o", "{out}/x.h5"], "scenario must be a built-in name"),
        (["simulate", "mcreynolds", "-o", "{out}/x.h5", "--set", "pixel.theta=0.3"], "unknown scenario key 'pixel.theta'"),
        (["simulate", "mcreynolds", "-o", "{out}/x.h5", "--set", "pixel.theta_on=-1"], "theta_on=-1"),
        (["simulate", "mcreynolds", "-o", "{out}/x.mp4"], ".mp4"),
        (["simulate", "mcreynolds", "-o", "{out}/missing/x.h5"], "does not exist"),
        (["simulate", "mcreynolds", "-o", "{out}/x.h5", "--threads", "0"], "--threads must be >= 1; got 0"),
        (["info", "{out}/none.h5"], "none.h5"),
    ],
)
def test_bad_input_is_one_line_and_writes_nothing(
    argv: list[str], message: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([a.format(out=tmp_path) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("evstwin: error: ") and message in err and "\n" not in err
    assert list(tmp_path.iterdir()) == []


def test_python_dash_m_works() -> None:
    done = subprocess.run([sys.executable, "-m", "evstwin", "--version"], capture_output=True, text=True, check=True)
    assert done.stdout.startswith("evstwin 0.")
    listed = subprocess.run([sys.executable, "-m", "evstwin", "scenarios"], capture_output=True, text=True, check=True)
    assert "mcreynolds-run3" in listed.stdout and "geo-stare" in listed.stdout
    assert "imx636-pointsource" in listed.stdout


def test_timing_compares_bias_settings(simulated: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    high = tmp_path / "high.npz"
    assert main(["simulate", "mcreynolds", "-o", str(high), "--duration", "0.5", "--seed", "3", "--no-progress",
                 "--set", "pixel.theta_on=0.4", "--set", "pixel.theta_off=0.3"]) == 0
    assert main(["timing", str(simulated), str(high), "--out", str(tmp_path / "t")]) == 0
    text = capsys.readouterr().out
    assert "theta 0.206/0.093" in text and "theta 0.4/0.3" in text
    assert (tmp_path / "t" / "timing_by_setting.png").stat().st_size > 10_000
    report = json.loads((tmp_path / "t" / "timing_bias.json").read_text())
    assert len(report) == 2
    medians = [next(r for r in rows["polarity"] if r["group"] == "ON")["p50_s"] for rows in report.values()]
    assert medians[1] > medians[0]  # higher thresholds: the first ON event comes later
