"""evstwin.tune: fit recovery, sweeps (local and Dask), resume, detect ranking, retries, CLI."""

from __future__ import annotations

import contextlib
import csv
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from evstwin import tune
from evstwin.scenario import build, load, set_value, to_toml
from evstwin.simulate import simulate

HIDDEN = {"pixel.theta_on": 0.3, "pixel.theta_off": 0.2, "pixel.dark_rate_e_per_s": 2000.0}


def flicker(x: float, y: float) -> dict:
    """A static source stepping between 4e9 and 1.6e10 photons/s every 50 ms: a contrast of
    ln 4 whatever the dark current, which pins the thresholds."""
    return {
        "kind": "static",
        "x_px": x,
        "y_px": y,
        "label": f"flicker{x:g}_{y:g}",
        "light_curve": {
            "t_s": [0.0, 0.049, 0.05, 0.099, 0.1],
            "flux_ph_s": [4e9, 4e9, 1.6e10, 1.6e10, 4e9],
            "periodic": True,
        },
    }


def recovery_scenario(theta_on: float, theta_off: float, dark_rate_e_per_s: float) -> dict:
    """48 x 36 px, 0.4 s: a source on a 10 px circle and four flickering sources (blurred to
    ~2.5 px) over a dim sky (~1000 e-/s per pixel, half the hidden dark rate). The dark pixels'
    noise depends on dark rate / threshold^2, the flickers on the thresholds alone: together
    they separate the three parameters."""
    return {
        "name": "recovery",
        "duration_s": 0.4,
        "background": {"photon_rate_ph_s": 2e6},
        "sensor": {"preset": "davis346_paper", "width": 48, "height": 36},
        # The single-pole pixel with the paper's sampled noise that these recovery problems
        # were designed on (scenarios now default to the photoreceptor pole, which damps the
        # dark pixels' noise, and to the continuous noise model; recovery with those is
        # issue 10's).
        "pixel": {"theta_on": theta_on, "theta_off": theta_off, "dark_rate_e_per_s": dark_rate_e_per_s,
                  "pr_pole": False, "noise_model": "sampled"},
        "optics": {"extra_blur_sigma_px": 2.5},
        "sampling": {"rate_hz": 500.0, "max_shift_px": 0.5, "sparse": True, "chunk_samples": 50},
        "targets": [
            {
                "kind": "circular",
                "centre_x_px": 24.0,
                "centre_y_px": 18.0,
                "radius_px": 10.0,
                "period_s": 0.4,
                "flux_ph_s": 4e9,
                "label": "led",
            },
            flicker(8.0, 8.0),
            flicker(40.0, 8.0),
            flicker(8.0, 28.0),
            flicker(40.0, 28.0),
        ],
    }


def noise_scenario() -> dict:
    """A small dark field for quick sweeps (24 x 16 px, 0.3 s)."""
    return {
        "name": "toy",
        "duration_s": 0.3,
        "background": {"photon_rate_ph_s": 1e6},
        "sensor": {"preset": "davis346_paper", "width": 24, "height": 16},
        "pixel": {"dark_rate_e_per_s": 2000.0, "pr_pole": False},
        "sampling": {"rate_hz": 200.0},
        "targets": [{"kind": "static", "x_px": 5.0, "y_px": 5.0, "flux_ph_s": 1e9}],
    }


def geo_small() -> dict:
    """The limiting-magnitude scenario (geo-stare optics, sky and biases) on 48 x 24 px for
    1 s, the target crossing at 60 arcsec/s (31 px/s)."""
    s = tune.limiting_magnitude_scenario()
    s["sensor"] = dict(s["sensor"], width=48, height=24)
    s["duration_s"] = 1.0
    s["targets"][0].update(x0_px=3.0, y0_px=11.5, wx_arcsec_s=60.0)
    return load(s)


@pytest.fixture(scope="module")
def dask_address():
    """A real two-worker Dask cluster on the loopback interface."""
    distributed = pytest.importorskip("distributed")
    # HTTP endpoints on a free loopback port: no "port 8787 in use" warning.
    cluster = distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address="127.0.0.1:0"
    )
    try:
        yield cluster.scheduler_address
    finally:
        cluster.close()


# -- fit ----------------------------------------------------------------------------------------


def test_fit_recovers_hidden_thresholds_and_dark_rate(tmp_path: Path) -> None:
    real = simulate(recovery_scenario(0.3, 0.2, 2000.0), seed=123, num_threads=1)
    # The starting point: thresholds +40 % / -30 %, dark rate x3.
    start = recovery_scenario(0.42, 0.14, 6000.0)
    result = tune.fit(real.events, real.meta, start,
                      tune.FitOptions(params=["theta_on", "theta_off", "dark_rate_e_per_s"], budget=80, seed=0,
                                      sampler="nm"), workers=2)
    best = result.best_params
    assert best["pixel.theta_on"] == pytest.approx(0.3, rel=0.1)
    assert best["pixel.theta_off"] == pytest.approx(0.2, rel=0.1)
    assert 2000.0 / 1.5 < best["pixel.dark_rate_e_per_s"] < 2000.0 * 1.5
    assert len(result.history) <= 80 and result.history[0].params["pixel.theta_on"] == pytest.approx(0.42)
    assert result.best_distance < 0.1 < result.history[0].distance
    assert not result.failed

    paths = result.write(tmp_path / "fit")
    assert set(paths) == {"best_toml", "history", "json"}  # data only: drawing is figures'
    paths.update(tune.draw_fit(result, tmp_path / "fit"))
    for name in ("best_toml", "history", "json", "convergence", "compare_histograms", "compare_json"):
        assert paths[name].is_file(), name
    again = build(str(paths["best_toml"]))  # what `evstwin simulate best.toml` builds
    assert again.params.theta_on == pytest.approx(best["pixel.theta_on"])
    assert again.duration_s == pytest.approx(real.meta["duration_s"])
    with open(paths["history"], newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(result.history) and rows[0]["phase"] == "nm"


def test_fit_recovers_hidden_values_with_the_continuous_noise_model_and_the_pole() -> None:
    def scenario(theta_on: float, theta_off: float, dark_rate_e_per_s: float) -> dict:
        s = recovery_scenario(theta_on, theta_off, dark_rate_e_per_s)
        # The engine's defaults: continuous shot noise, photoreceptor pole.
        s["pixel"] = {"theta_on": theta_on, "theta_off": theta_off, "dark_rate_e_per_s": dark_rate_e_per_s}
        return s

    real = simulate(scenario(0.3, 0.2, 2000.0), seed=123, num_threads=1)
    assert build(scenario(0.3, 0.2, 2000.0)).params.noise_model == "continuous"
    result = tune.fit(real.events, real.meta, scenario(0.42, 0.14, 6000.0),
                      tune.FitOptions(params=["theta_on", "theta_off", "dark_rate_e_per_s"], budget=60, seed=0,
                                      sampler="nm"), workers=2)
    best = result.best_params
    assert best["pixel.theta_on"] == pytest.approx(0.3, rel=0.1)
    assert best["pixel.theta_off"] == pytest.approx(0.2, rel=0.1)
    assert 2000.0 / 1.5 < best["pixel.dark_rate_e_per_s"] < 2000.0 * 1.5
    assert len(result.history) == 60  # the restarts spend the whole budget
    assert result.best_distance < 0.1 < result.history[0].distance


def test_nelder_mead_restarts_when_it_stalls_and_is_deterministic() -> None:
    from evstwin.tune.bounds import ParamBound
    from evstwin.tune.result import TrialRecord
    from evstwin.tune.search import _nelder_mead, _Scaler

    def runs() -> list[np.ndarray]:
        # A noisy bowl: common seeds make it a fixed rough function, whose small-scale
        # minima trap a shrinking simplex.
        points: list[np.ndarray] = []

        def run_trials(ps: list[dict[str, float]], phase: str) -> list[TrialRecord]:
            out = []
            for p in ps:
                u = np.array([p["a"], p["b"]])
                points.append(u)
                d = float(np.sum((u - 0.7) ** 2) + 0.002 * np.sin(400 * u).sum())
                out.append(TrialRecord(len(points) - 1, p, d, [d], phase=phase))
            return out

        scaler = _Scaler(["a", "b"], {"a": ParamBound(0.0, 1.0), "b": ParamBound(0.0, 1.0)})
        _nelder_mead(run_trials, scaler, np.array([0.1, 0.2]), 80, 0.1)
        return points

    first, again = runs(), runs()
    assert len(first) == 80  # restarts spend the whole budget
    assert all(np.array_equal(a, b) for a, b in zip(first, again))
    best = min(first, key=lambda u: float(np.sum((u - 0.7) ** 2) + 0.002 * np.sin(400 * u).sum()))
    assert np.allclose(best, 0.7, atol=0.03)


def test_fit_tpe_is_reproducible_and_independent_of_workers() -> None:
    real = simulate(recovery_scenario(0.3, 0.2, 2000.0), duration_s=0.2, seed=5, num_threads=1)
    start = recovery_scenario(0.4, 0.15, 4000.0)
    kw = {
        "params": ["theta_on", "dark_rate_e_per_s"],
        "budget": 6,
        "seed": 3,
        "sampler": "tpe",
        "batch_size": 3,
    }
    a = tune.fit(real.events, real.meta, start, tune.FitOptions(**kw), workers=0)
    b = tune.fit(real.events, real.meta, start, tune.FitOptions(**kw), workers=2)
    assert [(r.params, r.distance) for r in a.history] == [(r.params, r.distance) for r in b.history]
    assert a.best_params == b.best_params and a.history[0].params["pixel.theta_on"] == 0.4
    assert {r.phase for r in a.history} == {"tpe"}


def test_fit_rejects_bad_input() -> None:
    real = simulate(recovery_scenario(0.3, 0.2, 2000.0), duration_s=0.1, seed=1, num_threads=1)
    start = recovery_scenario(0.3, 0.2, 2000.0)
    with pytest.raises(ValueError, match=r"unknown parameter 'theta'"):
        tune.fit(real.events, real.meta, start, tune.FitOptions(params=["theta"]))
    with pytest.raises(ValueError, match=r"pixel.cutoff_hz has no default bounds"):
        tune.fit(real.events, real.meta, start, tune.FitOptions(params=["cutoff_hz"]))
    with pytest.raises(ValueError, match=r"bound low must be < high; got 0.5:0.1"):
        tune.fit(real.events, real.meta, start, tune.FitOptions(params=["theta_on"], bounds={"theta_on": "0.5:0.1"}))
    with pytest.raises(ValueError, match=r"scenario sensor is 64x36 px but the real recording is 48x36"):
        tune.fit(real.events, real.meta, dict(start, sensor={"preset": "davis346", "width": 64, "height": 36}))
    with pytest.raises(ValueError, match=r"budget must be an integer >= 1; got 0"):
        tune.fit(real.events, real.meta, start, tune.FitOptions(budget=0))
    assert tune.parse_bound("dark_rate_e_per_s=100:1e4") == (
        "pixel.dark_rate_e_per_s",
        tune.ParamBound(100.0, 1e4, True, "user"),
    )


# -- sweep -------------------------------------------------------------------------------------

GRID = {"theta_on": [0.15, 0.3], "pixel.dark_rate_e_per_s": [1000.0, 4000.0]}


def test_sweep_every_point_and_run_identical_on_dask(tmp_path: Path, dask_address: str) -> None:
    local = tune.sweep(
        noise_scenario(), GRID, objective="noise", runs=2, out_dir=tmp_path / "local", workers=2
    )
    assert len(local.rows) == 8 and local.complete
    assert [(r["point"], r["seed"]) for r in local.rows] == [(p, s) for p in range(4) for s in (0, 1)]
    with open(local.csv_path, newline="") as fh:
        table = list(csv.DictReader(fh))
    assert len(table) == 8 and set(table[0]) == {
        "point",
        "pixel.theta_on",
        "pixel.dark_rate_e_per_s",
        "seed",
        *tune.NoiseObjective.metrics,
    }
    assert [r["runs"] for r in local.summary] == [2, 2, 2, 2]
    assert local.summary_path.is_file() and local.figure_path is None
    assert tune.draw_sweep(local).is_file() and local.figure_path == tmp_path / "local" / "sweep.png"
    # Lower thresholds, more noise; more dark current, less (relative) shot noise.
    rate = {
        (r["pixel.theta_on"], r["pixel.dark_rate_e_per_s"]): r["mean_noise_rate_per_px_hz"]
        for r in local.summary
    }
    assert rate[(0.15, 1000.0)] > rate[(0.3, 1000.0)] and rate[(0.15, 1000.0)] > rate[(0.15, 4000.0)]

    on_dask = tune.sweep(
        noise_scenario(), GRID, objective="noise", runs=2, out_dir=tmp_path / "dask", scheduler=dask_address
    )
    assert on_dask.rows == local.rows
    assert on_dask.csv_path.read_text() == local.csv_path.read_text()
    assert "Dask cluster" in on_dask.executor


def test_sweep_resume_skips_finished_rows(tmp_path: Path) -> None:
    out = tmp_path / "sweep"
    # "Interrupted": only half the grid finished, and the last row was cut by the kill.
    first = tune.sweep(
        noise_scenario(),
        {"theta_on": [0.15], "pixel.dark_rate_e_per_s": [1000.0, 4000.0]},
        objective="noise",
        runs=2,
        out_dir=out,
        workers=2,
    )
    assert len(first.rows) == 4
    with open(out / "sweep.csv", "a") as fh:
        fh.write("9,0.3,1000.0,0,0.5")
    with pytest.raises(FileExistsError, match=r"sweep.csv exists: pass --resume"):
        tune.sweep(noise_scenario(), GRID, objective="noise", runs=2, out_dir=out)
    resumed = tune.sweep(
        noise_scenario(), GRID, objective="noise", runs=2, out_dir=out, resume=True, workers=2
    )
    assert resumed.resumed == 4 and len(resumed.rows) == 8 and resumed.complete
    fresh = tune.sweep(noise_scenario(), GRID, objective="noise", runs=2, workers=0)
    assert resumed.rows == fresh.rows
    with open(out / "sweep.csv", newline="") as fh:
        assert len(list(csv.DictReader(fh))) == 8
    # Nothing left to run: a second resume only rewrites the tables.
    again = tune.sweep(noise_scenario(), GRID, objective="noise", runs=2, out_dir=out, resume=True)
    assert again.resumed == 8 and again.rows == fresh.rows and again.executor == "nothing to run"
    with pytest.raises(ValueError, match=r"--resume: .* a different grid or objective"):
        tune.sweep(noise_scenario(), {"theta_off": [0.2]}, objective="noise", out_dir=out, resume=True)


def test_sweep_rejects_bad_grids() -> None:
    with pytest.raises(ValueError, match=r"unknown parameter 'thta_on'"):
        tune.sweep(noise_scenario(), {"thta_on": [0.1]}, objective="noise")
    with pytest.raises(ValueError, match=r"theta_on must be in \[0.001, 10\]"):
        tune.sweep(noise_scenario(), {"theta_on": [0.1, -1.0]}, objective="noise")
    with pytest.raises(ValueError, match=r"objective must be one of match, detect, noise; got 'snr'"):
        tune.sweep(noise_scenario(), {"theta_on": [0.1]}, objective="snr")
    with pytest.raises(ValueError, match=r"objective 'match' needs a real recording"):
        tune.sweep(noise_scenario(), {"theta_on": [0.1]}, objective="match")
    with pytest.raises(ValueError, match=r"biases.i_on_a has no effect: the scenario sets pixel.theta_on"):
        tune.sweep(dict(noise_scenario(), pixel={"theta_on": 0.2}), {"i_on_a": [1e-7]}, objective="noise")
    assert tune.parse_grid(["theta_on=0.1,0.2", "sensor.bias_set=paper_run_3"]) == {
        "pixel.theta_on": [0.1, 0.2],
        "sensor.bias_set": ["paper_run_3"],
    }


def test_sweep_match_scores_the_truth_best() -> None:
    real = simulate(noise_scenario(), seed=50, num_threads=1)
    result = tune.sweep(
        noise_scenario(),
        {"theta_on": [0.1, 0.2061, 0.4]},
        objective="match",
        real=(real.events, real.meta),
        workers=0,
    )
    d = [r["mean_distance"] for r in result.summary]
    assert d[1] < d[0] and d[1] < d[2]
    # 'distance' is the fit's (counts and timing); compare's ranks the same way beside it.
    assert result.metrics[:2] == ("distance", "compare_distance")
    c = [r["mean_compare_distance"] for r in result.summary]
    assert c[1] < c[0] and c[1] < c[2]


# -- detect -------------------------------------------------------------------------------------


def test_detect_ranks_bright_above_faint_and_low_threshold_above_high() -> None:
    # fast_pr_slow_sf_balanced_th: I_diff 8.2 nA; I_ON 30 nA / 187 nA give theta_on 0.085 / 0.206.
    result = tune.sweep(
        geo_small(),
        {"targets.0.magnitude": [9.0, 11.0, 14.0], "biases.i_on_a": [3e-8, 1.869e-7]},
        objective="detect",
        runs=2,
        workers=2,
    )
    m = {(r["targets.0.magnitude"], r["biases.i_on_a"]): r for r in result.summary}
    for bias in (3e-8, 1.869e-7):  # bright above faint
        assert m[(9.0, bias)]["mean_excess_fraction"] > 0.9 > m[(14.0, bias)]["mean_excess_fraction"] + 0.5
        assert m[(9.0, bias)]["mean_snr"] > m[(14.0, bias)]["mean_snr"]
        assert m[(9.0, bias)]["mean_track_events_per_s"] > m[(14.0, bias)]["mean_track_events_per_s"]
    # Low threshold above high, same target (magnitude 11).
    low, high = m[(11.0, 3e-8)], m[(11.0, 1.869e-7)]
    assert low["mean_excess_fraction"] > high["mean_excess_fraction"] + 0.3
    assert low["mean_track_events_per_s"] > high["mean_track_events_per_s"]
    bright = m[(9.0, 3e-8)]
    # The track fraction noise alone would give: with theta_on 0.085 about 4 sigma of the
    # filtered dark shot noise above the level, ~10 % in the continuous noise model.
    assert 0.0 <= bright["mean_chance_fraction"] < 0.2 and bright["mean_track_px"] >= 25
    assert abs(bright["mean_latency_median_s"]) < 0.05 and bright["mean_noise_rate_per_px_hz"] > 0


def test_detect_metrics_on_a_handmade_track() -> None:
    # Target along y = 2 from x = 0 to 9 in 1 s on a 20 x 8 sensor; one event in each of the
    # pixels x = 2..5 at the centre's entry + 10 ms, two noise events far away.
    t = np.linspace(0.0, 1.0, 101)
    track = {"t_s": t, "x_px": 9.0 * t, "y_px": np.full_like(t, 2.0)}
    ev = np.zeros(6, dtype=[("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")])
    for i, x in enumerate(range(2, 6)):
        ev[i] = (round(((x - 0.5) / 9.0 + 0.01) * 1e6), x, 2, 1)
    ev[4] = (500_000, 15, 7, 0)
    ev[5] = (600_000, 19, 0, 1)
    out = tune.detect_metrics(ev, 20, 8, 1.0, track, exclude_px=3.0, tail_s=0.1)
    assert out["track_px"] == 9  # x = 1..9 (x = 0 is where the track starts)
    assert out["track_fraction"] == pytest.approx(4 / 9)
    # From the window's opening (the centre within radius_px = 1 of the pixel's square: 1 px, 1/9 s,
    # before it enters) to the event 10 ms after the entry; resolved to 1/50 px of travel.
    assert out["latency_median_s"] == pytest.approx(1.0 / 9.0 + 0.01, abs=0.02 / 9.0)
    # Elsewhere: farther than 3 px from x = 1..9, y = 2: columns 13..19 (56 px) and rows 6, 7 of
    # columns 0..12 (26 px).
    assert out["noise_rate_per_px_hz"] == pytest.approx(2 / 82)
    assert out["track_events_per_s"] == 4
    assert 0 < out["chance_fraction"] < out["track_fraction"]
    assert out["excess_fraction"] == pytest.approx(
        (out["track_fraction"] - out["chance_fraction"]) / (1 - out["chance_fraction"])
    )


def test_limiting_magnitude_table_and_figure(tmp_path: Path) -> None:
    result = tune.limiting_magnitude(
        geo_small(),
        rates_arcsec_s=[30.0, 120.0],
        magnitudes=[7.0, 9.0, 12.0],
        runs=1,
        out_dir=tmp_path,
        workers=2,
    )
    assert [r["rate_arcsec_s"] for r in result.table] == [30.0, 120.0]
    for row in result.table:
        assert row["limiting_magnitude"] in (7.0, 9.0) and row["metric_at_limit"] >= 0.5
        assert row["rate_px_s"] == pytest.approx(row["rate_arcsec_s"] / 1.908, rel=1e-3)
    assert result.figure_path is None and result.table_path.is_file()
    assert tune.draw_limiting_magnitude(result, tmp_path).is_file() and result.figure_path is not None
    assert (tmp_path / "sweep.csv").is_file()
    assert "limiting mag" in result.to_text()


# -- retries ----------------------------------------------------------------------------------


class FlakyNoise(tune.NoiseObjective):
    """Raises the first time any process evaluates it (a marker file remembers)."""

    def __init__(self, marker: Path, always: bool = False) -> None:
        self.marker = marker
        self.always = always

    def evaluate(self, result):  # type: ignore[no-untyped-def]
        if self.always or not self.marker.exists():
            self.marker.touch()
            raise RuntimeError("transient failure")
        return super().evaluate(result)


@pytest.mark.parametrize("workers", [0, 1])
def test_a_job_that_raises_once_is_retried(tmp_path: Path, workers: int) -> None:
    marker = tmp_path / "failed-once"
    result = tune.sweep(
        noise_scenario(),
        {"theta_on": [0.2]},
        objective=FlakyNoise(marker),
        runs=1,
        out_dir=tmp_path / "out",
        workers=workers,
    )
    assert marker.exists() and not result.failed and len(result.rows) == 1


class KillerNoise(tune.NoiseObjective):
    """Kills its worker process (SIGKILL) the first time it is evaluated."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def evaluate(self, result):  # type: ignore[no-untyped-def]
        if not self.marker.exists():
            self.marker.touch()
            os.kill(os.getpid(), signal.SIGKILL)
        return super().evaluate(result)


def test_a_killed_worker_job_is_rerun_on_a_new_pool(tmp_path: Path) -> None:
    marker = tmp_path / "killed-once"
    result = tune.sweep(
        noise_scenario(), {"theta_on": [0.2, 0.3]}, objective=KillerNoise(marker), runs=2, workers=2
    )
    fresh = tune.sweep(noise_scenario(), {"theta_on": [0.2, 0.3]}, objective="noise", runs=2, workers=0)
    assert marker.exists() and not result.failed and result.rows == fresh.rows


def test_a_job_that_always_fails_is_reported_not_lost(tmp_path: Path) -> None:
    result = tune.sweep(
        noise_scenario(),
        {"theta_on": [0.2, 0.3]},
        objective=FlakyNoise(tmp_path / "m", True),
        runs=1,
        out_dir=tmp_path / "out",
        workers=1,
    )
    assert len(result.failed) == 2 and result.rows == [] and not result.complete
    assert {f.attempts for f in result.failed} == {tune.JOB_RETRIES + 1}
    assert "RuntimeError: transient failure" in result.failed[0].error
    assert "FAILED point" in result.to_text()


def test_a_job_retried_on_an_in_process_dask_cluster(tmp_path: Path) -> None:
    pytest.importorskip("distributed")
    marker = tmp_path / "failed-once-dask"
    result = tune.sweep(
        noise_scenario(),
        {"theta_on": [0.2]},
        objective=FlakyNoise(marker),
        runs=1,
        scheduler="local",
        workers=2,
    )
    assert marker.exists() and not result.failed and len(result.rows) == 1
    assert "Dask cluster at tcp://127.0.0.1" in result.executor


# -- command line -------------------------------------------------------------------------------


def test_cli_sweep_fit_and_errors(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from evstwin import cli
    from evstwin.io import write_events

    scen = tmp_path / "toy.toml"
    scen.write_text(to_toml(load(noise_scenario())))
    out = tmp_path / "sw"
    code = cli.main(
        [
            "sweep",
            "--scenario",
            str(scen),
            "--grid",
            "theta_on=0.15,0.3",
            "--objective",
            "noise",
            "--runs",
            "2",
            "--out",
            str(out),
            "--workers",
            "1",
            "--no-progress",
        ]
    )
    assert code == 0
    text = capsys.readouterr().out
    assert "noise_rate_per_px_hz" in text and "4 rows (0 resumed) over 2 points x 2 seed(s)" in text
    assert (out / "sweep.csv").is_file() and (out / "sweep.png").is_file()

    real = simulate(noise_scenario(), seed=9, num_threads=1)
    real_path = tmp_path / "real.h5"
    write_events(real_path, real.events, real.meta)
    code = cli.main(
        [
            "fit",
            str(real_path),
            "--scenario",
            str(scen),
            "--params",
            "theta_on",
            "--budget",
            "3",
            "--bounds",
            "theta_on=0.1:0.4",
            "--out",
            str(tmp_path / "fit"),
            "--workers",
            "1",
            "--no-progress",
        ]
    )
    assert code == 0
    text = capsys.readouterr().out
    assert "pixel.theta_on" in text and "best distance" in text
    assert (tmp_path / "fit" / "best.toml").is_file() and (
        tmp_path / "fit" / "compare" / "histograms.png"
    ).is_file()

    code = cli.main(
        [
            "sweep",
            "--scenario",
            str(scen),
            "--grid",
            "theta_on",
            "--objective",
            "noise",
            "--out",
            str(tmp_path / "bad"),
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--grid takes name=v1,v2" in err
    assert not (tmp_path / "bad").exists()
    code = cli.main(["limiting-magnitude", "--magnitudes", "7,x", "--out", str(tmp_path / "lm")])
    assert code == 2 and "--magnitudes takes numbers" in capsys.readouterr().err
    code = cli.main(
        [
            "fit",
            str(real_path),
            "--scenario",
            str(scen),
            "--bounds",
            "theta_on=1",
            "--out",
            str(tmp_path / "f2"),
        ]
    )
    assert code == 2 and "--bounds takes name=lo:hi" in capsys.readouterr().err


def test_fit_bounds_are_documented() -> None:
    for key in tune.DEFAULT_FIT_PARAMS:
        b = tune.FIT_BOUNDS[key]
        assert b.why and b.low < b.high
        value = getattr(build(load("mcreynolds")).params, key.split(".", 1)[1])
        assert b.contains(value), key  # the paper's own values are inside
    assert math.isclose(tune.FIT_BOUNDS["pixel.dark_rate_e_per_s"].low, 10.0)


# -- defects a new user hit ---------------------------------------------------------------------


def test_sweep_with_an_unknown_target_fails_at_once_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from evstwin import cli

    scen = tmp_path / "geo.toml"
    scen.write_text(to_toml(geo_small()))
    out = tmp_path / "sw"
    argv = ["sweep", "--scenario", str(scen), "--grid", "pixel.theta_on=0.2,0.3", "--target", "nosuch",
            "--out", str(out), "--no-progress"]
    assert cli.main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "'nosuch' is not a moving target" in err and "known: target" in err
    assert not out.exists()


class _AlwaysWrong(tune.NoiseObjective):
    """A job error that every try would repeat (a deterministic bug in the job)."""

    name = "wrong"

    def evaluate(self, result):  # type: ignore[no-untyped-def]
        raise ValueError("this job is wrong every time")


@pytest.mark.parametrize("workers", [0, 1])
def test_deterministic_job_errors_are_not_retried(workers: int) -> None:
    from evstwin.tune.execution import LocalExecutor, _Context, _Job

    ctx = _Context(scenario=load(noise_scenario()), objective=_AlwaysWrong())
    executor = LocalExecutor(workers)
    try:
        (job, res), = list(executor.run(ctx, [_Job(0, {}, 0)]))
    finally:
        executor.close()
    assert isinstance(res, tune.JobFailure) and res.attempts == 1 and "wrong every time" in res.error


def _descendants(pid: int) -> set[int]:
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as fh:
                    ppid = int(fh.read().rsplit(")", 1)[1].split()[1])
            except OSError:
                continue
            children.setdefault(ppid, []).append(int(entry))
    out, todo = set(), [pid]
    while todo:
        for c in children.get(todo.pop(), []):
            out.add(c)
            todo.append(c)
    return out


@pytest.mark.skipif(not os.path.isdir("/proc"), reason="needs /proc to find the worker processes")
def test_sigint_to_the_main_process_alone_stops_the_sweep_and_its_workers(tmp_path: Path) -> None:
    scen = load(noise_scenario())
    scen["sensor"] = dict(scen["sensor"], width=96, height=64)
    scen["duration_s"] = 600.0  # each job takes over a minute: the interrupt lands mid-job
    (tmp_path / "s.toml").write_text(to_toml(scen))
    out = tmp_path / "sw"
    proc = subprocess.Popen(
        [sys.executable, "-m", "evstwin", "sweep", "--scenario", str(tmp_path / "s.toml"), "--grid",
         "pixel.theta_on=0.15,0.2,0.25,0.3", "--objective", "noise", "--workers", "2", "--out", str(out)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        # Ctrl-C as a terminal delivers it: a test run started in the background by a
        # non-interactive shell (`bash .ci/run &`) ignores SIGINT, and its children inherit
        # that, so the sweep would rightly never see the signal.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    try:
        deadline = time.monotonic() + 60
        while len(_descendants(proc.pid)) < 3 and time.monotonic() < deadline:  # forkserver + 2 workers
            time.sleep(0.2)
        time.sleep(1.0)
        workers = _descendants(proc.pid)
        assert len(workers) >= 3
        start = time.monotonic()
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=20)
        stopped_s = time.monotonic() - start
    finally:
        if proc.poll() is None:  # failed: leave no process behind in any case
            for pid in _descendants(proc.pid) | {proc.pid}:
                with contextlib.suppress(OSError):
                    os.kill(pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130 and stopped_s < 10
    time.sleep(1.0)
    assert not [p for p in workers if _running(p)]


def _running(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"  # a zombie has ended
    except OSError:
        return False


def test_sweep_says_what_it_will_run_and_labels_its_figure(tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    from evstwin.tune.figures import readable

    result = tune.sweep(noise_scenario(), {"pixel.theta_on": [0.2, 0.3]}, objective="noise", out_dir=tmp_path,
                        workers=0, progress=True)
    err = capsys.readouterr().err
    assert "sweep (noise): 2 job(s) of 24x16 px for 0.3 s of sensor time at 200 Hz" in err
    assert "estimate ~" in err and "in all" in err
    assert readable("pixel.theta_on") == "ON threshold theta_on (log units)"
    assert readable("targets.0.wx_arcsec_s") == "target 0: angular rate along x (arcsec/s)"
    assert readable("sampling.max_shift_px") == "sampling: max shift (px)"  # others: the unit of the suffix
    assert tune.draw_sweep(result).is_file()


def test_sweep_error_bars_stop_where_the_metric_does(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from evstwin.tune import figures
    from evstwin.tune.sweep import SweepResult

    # A share of 0.99 +- 0.013 (the bar reached 1.003), a rate of 0.5 +- 2, a latency
    # of -0.01 +- 0.02 s (a PSF wing can fire a pixel early: not clipped).
    err = figures.clipped_error(np.array([0.99, 0.2]), np.array([0.013, np.nan]), "excess_fraction")
    np.testing.assert_allclose(err, [[0.013, 0.0], [0.01, 0.0]])
    np.testing.assert_allclose(figures.clipped_error(np.array([0.5]), np.array([2.0]), "noise_rate_per_px_hz"),
                               [[0.5], [2.0]])
    np.testing.assert_allclose(figures.clipped_error(np.array([-0.01]), np.array([0.02]), "latency_median_s"),
                               [[0.02], [0.02]])
    drawn = []
    real_errorbar = figures.require("matplotlib.axes").Axes.errorbar

    def spy(self, x, y, yerr=None, **kw):  # type: ignore[no-untyped-def]
        drawn.append(np.asarray(y) + np.asarray(yerr)[1])
        return real_errorbar(self, x, y, yerr=yerr, **kw)

    monkeypatch.setattr(figures.require("matplotlib.axes").Axes, "errorbar", spy)
    summary = [{"point": i, "pixel.theta_on": v, "runs": 3, "mean_excess_fraction": m, "std_excess_fraction": 0.05}
               for i, (v, m) in enumerate([(0.2, 0.99), (0.3, 0.5)])]
    result = SweepResult(grid={"pixel.theta_on": [0.2, 0.3]}, objective="detect", metrics=("excess_fraction",),
                         headline=("excess_fraction",), runs=3, seeds=[0, 1, 2], rows=[], summary=summary)
    figures.plot_sweep(result, tmp_path / "s.png")
    assert drawn and max(float(d.max()) for d in drawn) == pytest.approx(1.0)


@pytest.mark.parametrize("sampler, runs_per_trial", [("nm", 2), ("ls", 2), ("ls", 1)])
def test_fit_intervals_bracket_the_best_and_the_hidden_values(sampler: str, runs_per_trial: int) -> None:
    real = simulate(recovery_scenario(0.3, 0.2, 2000.0), seed=123, num_threads=1)
    if sampler == "nm":  # compare's distance: its noise is measured over the trial's own seeds
        with pytest.raises(ValueError, match=r"intervals=True with distance='compare' needs runs_per_trial >= 2"
                                             r".*runs_per_trial=1"):
            tune.fit(real.events, real.meta, recovery_scenario(0.3, 0.2, 2000.0),
                     tune.FitOptions(params=["theta_on"], budget=2, intervals=True, sampler="nm"))
    result = tune.fit(real.events, real.meta, recovery_scenario(0.33, 0.2, 2000.0),
                      tune.FitOptions(params=["theta_on", "theta_off"], budget=16, runs_per_trial=runs_per_trial,
                                      seed=0, intervals=True, sampler=sampler), workers=2)
    assert len(result.history) <= 16  # the probes are not search trials
    for key in ("pixel.theta_on", "pixel.theta_off"):
        lo, hi = result.intervals[key]
        b = result.bounds[key]
        assert b.low <= lo <= result.best_params[key] <= hi <= b.high
        assert hi > lo
    # theta_on is well constrained by the flickering sources: its interval is far narrower
    # than its bound.
    lo, hi = result.intervals["pixel.theta_on"]
    b = result.bounds["pixel.theta_on"]
    assert (hi - lo) < 0.5 * (b.high - b.low)
    assert "interval" in result.to_text() and result.to_json_dict()["intervals"]
    if sampler == "ls":
        # One standard error each side: the hidden values lie within three of them (the
        # calibration of the standard errors is test_chi2_intervals_match_the_spread_*'s).
        for key, hidden in (("pixel.theta_on", 0.3), ("pixel.theta_off", 0.2)):
            lo, hi = result.intervals[key]
            print(key, result.best_params[key], lo, hi, abs(result.best_params[key] - hidden) / ((hi - lo) / 2))
            assert abs(result.best_params[key] - hidden) <= 3.0 * (hi - lo) / 2.0


# -- limiting magnitude for a real setup ------------------------------------------------------



def test_pointing_modes_move_the_target_and_the_stars_as_they_say() -> None:
    from evstwin.tune.limits import SIDEREAL_RATE_ARCSEC_S, PointingDetectObjective

    assert SIDEREAL_RATE_ARCSEC_S == pytest.approx(15.041, abs=1e-3)  # 1296000 arcsec / 86164.09 s
    assert PointingDetectObjective("sidereal").motion(60.0) == (60.0, 0.0)
    staring = PointingDetectObjective("staring", declination_deg=60.0)
    target, field = staring.motion(60.0)
    assert field == pytest.approx(-SIDEREAL_RATE_ARCSEC_S * 0.5) and target == pytest.approx(60.0 + field)
    assert PointingDetectObjective("staring").motion(SIDEREAL_RATE_ARCSEC_S)[0] == pytest.approx(0.0)  # GEO
    assert PointingDetectObjective("target").motion(60.0) == (0.0, -60.0)
    setup = tune.Setup(preset="imx636", focal_length_m=0.2, f_number=2.8, width_px=64, height_px=32)
    s = setup.scenario()
    assert s["star_field"]["distribution"] == "all-sky" and s["atmosphere"]["seeing_fwhm_arcsec"] == 2.0
    s = set_rate(s, 5.0)
    prepared = staring.prepare(s)  # 5 - 7.52 arcsec/s: the target moves left, starting on the right
    assert prepared["targets"][0]["wx_arcsec_s"] == pytest.approx(5.0 - SIDEREAL_RATE_ARCSEC_S * 0.5)
    assert prepared["targets"][0]["x0_px"] == pytest.approx(64 - 1 - 4.0)
    assert prepared["star_field"]["drift_arcsec_s"] == pytest.approx([-SIDEREAL_RATE_ARCSEC_S * 0.5, 0.0])
    tracked = PointingDetectObjective("target").prepare(s)
    assert tracked["targets"][0]["wx_arcsec_s"] == 0.0 and tracked["targets"][0]["x0_px"] == pytest.approx(31.5)
    assert tracked["star_field"]["drift_arcsec_s"] == [-5.0, 0.0]
    assert "drift_arcsec_s" not in PointingDetectObjective("sidereal").prepare(s)["star_field"]


def set_rate(s: dict, rate: float) -> dict:
    from evstwin.scenario import set_value

    return set_value(s, "targets.0.wx_arcsec_s", rate)


def test_static_detect_metrics_by_hand() -> None:
    from evstwin.tune.limits import static_detect_metrics

    # A source at (10, 5) on 30 x 12: core = columns 9..11 x rows 4..6 (9 px); 3 of them fire.
    # Elsewhere: farther than 1 + 3 px: columns <= 5 or >= 15, or rows <= 0 or >= 10 .
    ev = np.zeros(5, dtype=[("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")])
    ev[0], ev[1], ev[2] = (100, 9, 4, 1), (200, 10, 5, 0), (300, 11, 6, 1)
    ev[3], ev[4] = (400, 25, 2, 1), (500, 0, 11, 0)
    out = static_detect_metrics(ev, 30, 12, 2.0, 10.0, 5.0)
    far_cols = 6 + 15  # x <= 5: 0..5, x >= 15: 15..29
    n_noise_px = far_cols * 12 + (30 - far_cols) * 3  # plus rows 0, 10, 11 of columns 6..14
    assert out["track_px"] == 9 and out["track_fraction"] == pytest.approx(3 / 9)
    assert out["noise_rate_per_px_hz"] == pytest.approx(2 / (n_noise_px * 2.0))
    chance = 2 / n_noise_px  # two noise pixels fired, once each
    assert out["chance_fraction"] == pytest.approx(chance)
    # A hot pixel's thousand events raise the noise rate a thousandfold but the chance share by
    # one pixel: chance is the share of noise pixels that fired, not a Poisson guess from the rate.
    hot = np.zeros(1000, dtype=ev.dtype)
    hot["t"], hot["x"], hot["y"] = np.arange(1000) + 600, 0, 0
    out_hot = static_detect_metrics(np.concatenate([ev, hot]), 30, 12, 2.0, 10.0, 5.0)
    assert out_hot["chance_fraction"] == pytest.approx(3 / n_noise_px)
    assert out["excess_fraction"] == pytest.approx((3 / 9 - chance) / (1 - chance))
    assert out["signal_rate_per_px_hz"] == pytest.approx(3 / (9 * 2.0))


def test_limiting_magnitude_for_a_real_setup(tmp_path: Path) -> None:
    setup = tune.Setup(preset="imx636", focal_length_m=0.2, f_number=2.8, width_px=48, height_px=24, duration_s=1.0,
                       pointing="sidereal", stars_mag_max=12.0)
    result = tune.limiting_magnitude(setup=setup, rates_arcsec_s=[30.0, 150.0], magnitudes=[4.0, 8.0, 12.0],
                                     out_dir=tmp_path, workers=0)
    plate = 4.86e-6 / 0.2 * 180 * 3600 / math.pi
    assert [r["rate_px_s"] for r in result.table] == pytest.approx([30.0 / plate, 150.0 / plate])
    assert [r["stars_px_s"] for r in result.table] == [0.0, 0.0]
    # Mag 4 is bright (4e7 photons/s through a 71 mm pupil), mag 12 far below the sky's noise.
    for row in result.table:
        assert row["limiting_magnitude"] in (4.0, 8.0) and row["metric_at_limit"] >= 0.5
    assert "imx636" in result.setup and "200 mm f/2.8" in result.setup and "sidereal" in result.setup
    text = result.to_text()
    assert "criterion: detected: mean excess_fraction >= 0.5" in text and result.setup in text
    assert tune.draw_limiting_magnitude(result, tmp_path).is_file()
    header = (tmp_path / "limiting_magnitude.csv").read_text().splitlines()[0]
    assert header == ("rate_arcsec_s,rate_px_s,target_px_s,stars_px_s,limiting_magnitude,metric_at_limit,"
                      "chance_fraction,status")


def test_target_tracking_measures_the_target_at_rest(tmp_path: Path) -> None:
    # Tracked, the target does not move on the sensor: no seeing motion, no scintillation, no
    # events beyond noise: nothing is detected at any magnitude, and the metric says why
    # (the static criterion on its core: the source sits on the corner of four pixels at
    # (23.5, 11.5), the centre of 48 x 24, so its core within 1 px is 4 x 4 pixels).
    setup = tune.Setup(preset="imx636", focal_length_m=0.2, f_number=2.8, width_px=48, height_px=24, duration_s=0.5,
                       pointing="target", stars=False)
    result = tune.limiting_magnitude(setup=setup, rates_arcsec_s=[60.0], magnitudes=[4.0], workers=0)
    row = result.sweep.summary[0]
    assert row["mean_track_px"] == 16 and row["mean_track_fraction"] == 0.0
    assert math.isnan(result.table[0]["limiting_magnitude"])
    assert result.table[0]["target_px_s"] == 0.0 and result.table[0]["stars_px_s"] < 0


@pytest.mark.parametrize("argv, words", [
    (["--preset", "imx636", "--focal-length-mm", "-5", "--f-number", "2"], ["--focal-length-mm", "-5"]),
    (["--preset", "nosuch", "--focal-length-mm", "50", "--f-number", "2"], ["--preset", "nosuch"]),
    (["--preset", "imx636", "--focal-length-mm", "50"], ["--f-number or --aperture-mm"]),
    (["--preset", "imx636"], ["--focal-length-mm"]),
    (["--f-number", "2"], ["--f-number", "--preset"]),
    (["--preset", "imx636", "--focal-length-mm", "50", "--f-number", "2", "--sky-mag", "45"], ["--sky-mag", "45"]),
    (["--preset", "imx636", "--focal-length-mm", "50", "--aperture-mm", "0"], ["--aperture-mm", "0"]),
    (["--preset", "imx636", "--focal-length-mm", "50", "--f-number", "2", "--window", "10x5"], ["--window", "10x5"]),
    (["--preset", "davis346", "--focal-length-mm", "50", "--f-number", "2", "--window", "400x64"],
     ["--window 400x64", "346x260"]),
    (["--preset", "davis346", "--focal-length-mm", "50", "--f-number", "2", "--bias-set", "fast"], ["--bias-set", "fast"]),
    (["--preset", "imx636", "--focal-length-mm", "50", "--f-number", "2", "--bias-set", "paper_run_3"],
     ["--bias-set paper_run_3", "--preset imx636", "Prophesee"]),
    (["--preset", "imx636", "--focal-length-mm", "50", "--f-number", "2", "--airmass", "0.5"], ["--airmass", "0.5"]),
    (["--preset", "imx636", "--focal-length-mm", "50", "--f-number", "2", "--declination-deg", "95"],
     ["--declination-deg", "95"]),
    (["--scenario", "geo-stare", "--preset", "imx636", "--focal-length-mm", "50", "--f-number", "2"],
     ["--scenario", "not both"]),
    (["--preset", "imx636", "--focal-length-mm", "50", "--f-number", "2", "--rates-arcsec-s", "0,5"],
     ["rates-arcsec-s", "0.0"]),
    (["--preset", "imx636", "--focal-length-mm", "200", "--f-number", "2.8", "--scintillation"],
     ["--rate-hz 100", "--rate-hz 540 or more"]),  # tau = D_eff / 20 m/s = 74 mm / 20 m/s = 3.7 ms
])
def test_limiting_magnitude_setup_bad_input_one_line(tmp_path: Path, capsys, argv: list[str], words: list[str]) -> None:
    from evstwin import cli

    out = tmp_path / "lm"
    code = cli.main(["limiting-magnitude", *argv, "--out", str(out), "--workers", "0", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1, err
    for w in words:
        assert w in err
    assert not out.exists()


def test_announce_uses_a_timed_job_when_given() -> None:
    from types import SimpleNamespace

    from evstwin.tune.execution import LocalExecutor, announce

    scene = SimpleNamespace(width=128, height=64, rate_hz=100.0, duration_s=4.0)
    text = announce("sweep (detect)", 5, scene, LocalExecutor(2), job_seconds=3.0)
    assert "~3.0 s a job, ~9 s in all" in text and "one job timed here" in text  # ceil(5 / 2) rounds of 3 s
    rough = announce("sweep (detect)", 5, scene, LocalExecutor(2))
    assert "~0.2 s a job" in rough and "pixel-updates/s" in rough  # 128 x 64 x 100 x 4 / 15e6



# -- the fit's chi-square distance and least squares (issue 10's recovery goal) -----------------


def test_count_bins_and_statistics_by_hand() -> None:
    from evstwin.tune.counts import count_bin_edges

    # 0, 1, 2, 3, then x1.5 (floored): 4, 6, 9, 13 (the first edge at or past 10).
    assert count_bin_edges(10).tolist() == [0, 1, 2, 3, 4, 6, 9, 13]
    assert count_bin_edges(0).tolist() == [0, 1, 2, 3]
    # 2 x 2 px: (0,0) in group 0; (1,0) and (0,1) in group 1; (1,1) masked.
    groups = np.array([[0, 1], [1, -1]])
    ev = np.zeros(9, dtype=[("t", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1")])
    rows = [(0, 0, 1), (0, 0, 1), (1, 0, 1), (1, 0, 0)] + [(1, 1, 1)] * 5  # (x, y, p)
    for i, (x, y, p) in enumerate(rows):
        ev[i] = (i, x, y, p)
    edges = np.array([0, 1, 2, 3])
    got = tune.count_statistics(ev, 2, 2, groups, 2, edges)
    want = [
        0, 0, 1, 0, 2,  # ON, group 0: one pixel with 2 events; total 2
        1, 1, 0, 0, 1,  # ON, group 1: counts 1 and 0; total 1 (the masked pixel's 5 left out)
        1, 0, 0, 0, 0,  # OFF, group 0: one pixel with 0
        1, 1, 0, 0, 1,  # OFF, group 1: counts 1 and 0
    ]
    assert got.tolist() == want


def test_chi2_distance_compares_the_mean_of_the_seeds() -> None:
    real = np.array([4.0, 0.0])
    # (4 - 2)^2 / (2 + 4/2 + 1) = 0.8 for the first statistic, 0 for the second; mean 0.4.
    assert tune.chi2_distance(real, [np.array([2.0, 0.0]), np.array([2.0, 0.0])]) == pytest.approx(0.4)
    # Seeds 1 and 3 average to 2: the same distance (a chi-square of the mean, not a mean of
    # chi-squares, which would be (9/4 + 1/6) / 2 for the first statistic).
    assert tune.chi2_distance(real, [np.array([1.0, 0.0]), np.array([3.0, 0.0])]) == pytest.approx(0.4)
    assert tune.chi2_distance(real, [real.copy()]) == 0.0


def test_source_flux_map_and_pixel_groups() -> None:
    # One static 1e9 ph/s source at (12, 8) on 24 x 16 px, blurred over a few pixels (its
    # 5-sigma window inside the sensor).
    s = dict(noise_scenario(), optics={"extra_blur_sigma_px": 1.0},
             targets=[{"kind": "static", "x_px": 12.0, "y_px": 8.0, "flux_ph_s": 1e9}])
    scene = build(s)
    fmap = tune.source_flux_map(scene)
    assert fmap.shape == (16, 24)
    # A static source inside the sensor: its (normalised) PSF window holds its whole flux,
    # the uniform sky is left out, and the brightest pixel is the source's.
    assert fmap.sum() == pytest.approx(1e9, rel=1e-9)
    assert np.unravel_index(np.argmax(fmap), fmap.shape) == (8, 12)
    mask = np.zeros(fmap.shape, bool)
    mask[8, 13] = True
    groups = tune.pixel_groups(fmap, mask)
    assert groups[8, 12] == len(tune.counts.GROUP_LEVELS) and groups[15, 23] == 0 and groups[8, 13] == -1
    # Groups follow the source light: never brighter in a group below.
    present = [g for g in range(groups.max() + 1) if (groups == g).any()]
    assert len(present) >= 3
    for g, h in zip(present, present[1:]):
        assert fmap[groups == g].max() <= fmap[groups == h].min()
    assert (tune.pixel_groups(np.zeros((3, 4))) == 0).all()  # no source: all quiet


def test_least_squares_search_on_a_linear_model_is_exact_deterministic_and_budgeted() -> None:
    from evstwin.tune.bounds import ParamBound
    from evstwin.tune.result import TrialRecord
    from evstwin.tune.search import _least_squares, _Scaler

    a = np.array([[3.0, 1.0], [0.5, 2.0], [1.0, -1.0]])
    target = np.array([0.62, 0.27])

    def runs(budget: int) -> tuple[list[np.ndarray], dict[int, np.ndarray]]:
        points: list[np.ndarray] = []
        residuals: dict[int, np.ndarray] = {}

        def run_trials(ps: list[dict[str, float]], phase: str) -> list[TrialRecord]:
            out = []
            for p in ps:
                u = np.array([p["a"], p["b"]])
                points.append(u)
                residuals[len(points) - 1] = a @ (u - target)
                d = float(np.mean(residuals[len(points) - 1] ** 2))
                out.append(TrialRecord(len(points) - 1, p, d, [d], phase=phase))
            return out

        scaler = _Scaler(["a", "b"], {"a": ParamBound(0.0, 1.0), "b": ParamBound(0.0, 1.0)})
        _least_squares(run_trials, residuals, 3, scaler, np.array([0.1, 0.9]), budget, 0.02)
        return points, residuals

    first, res = runs(30)
    again, _ = runs(30)
    assert 3 <= len(first) <= 30 and all(np.array_equal(p, q) for p, q in zip(first, again))
    best = min(range(len(first)), key=lambda i: float(np.sum(res[i] ** 2)))
    # Residuals linear in the parameters: Gauss-Newton lands on the minimum.
    assert np.allclose(first[best], target, atol=1e-6)
    assert len(runs(4)[0]) <= 4  # the start and one Jacobian batch (3 trials) fit; no more


def test_fit_least_squares_is_reproducible_and_independent_of_workers() -> None:
    real = simulate(recovery_scenario(0.3, 0.2, 2000.0), duration_s=0.2, seed=5, num_threads=1)
    start = recovery_scenario(0.4, 0.15, 4000.0)
    kw = {"params": ["theta_on", "dark_rate_e_per_s"], "budget": 7, "seed": 3, "runs_per_trial": 2}
    a = tune.fit(real.events, real.meta, start, tune.FitOptions(**kw), workers=0)
    b = tune.fit(real.events, real.meta, start, tune.FitOptions(**kw), workers=2)
    assert a.sampler == "ls" and a.distance == "chi2"  # the defaults
    assert [(r.params, r.distance, r.run_distances) for r in a.history] == [
        (r.params, r.distance, r.run_distances) for r in b.history
    ]
    # The start, then a Jacobian batch (one trial a parameter), then the first step.
    assert len(a.history) == 7 and a.history[0].params["pixel.theta_on"] == pytest.approx(0.4)
    assert a.best_distance < a.history[0].distance


def test_fit_cmaes_runs_generations_in_batches_reproducibly() -> None:
    real = simulate(recovery_scenario(0.3, 0.2, 2000.0), duration_s=0.2, seed=5, num_threads=1)
    start = recovery_scenario(0.4, 0.15, 4000.0)
    kw = {"params": ["theta_on", "dark_rate_e_per_s"], "budget": 14, "seed": 3, "sampler": "cmaes",
          "distance": "chi2"}
    a = tune.fit(real.events, real.meta, start, tune.FitOptions(**kw), workers=0)
    b = tune.fit(real.events, real.meta, start, tune.FitOptions(**kw), workers=2)
    assert [(r.params, r.distance) for r in a.history] == [(r.params, r.distance) for r in b.history]
    assert len(a.history) == 14 and {r.phase for r in a.history} == {"cmaes"}
    # The first generation (4 + 3 ln 2 -> 6 trials) is drawn around the start (step 0.1 of
    # the log bound widths), not uniformly over the bounds.
    for r in a.history[:6]:
        assert 0.4 / 2 < r.params["pixel.theta_on"] < 0.4 * 2
    assert a.best_distance < a.history[0].distance


def test_fit_distance_and_least_squares_reject_bad_input() -> None:
    real = simulate(recovery_scenario(0.3, 0.2, 2000.0), duration_s=0.1, seed=1, num_threads=1)
    start = recovery_scenario(0.3, 0.2, 2000.0)
    with pytest.raises(ValueError, match=r"distance must be one of compare, chi2; got 'w1'"):
        tune.fit(real.events, real.meta, start, tune.FitOptions(params=["theta_on"], distance="w1"))
    with pytest.raises(ValueError, match=r"sampler 'ls' .* needs distance='chi2'; got distance='compare'"):
        tune.fit(real.events, real.meta, start, tune.FitOptions(params=["theta_on"], sampler="ls", distance="compare"))
    with pytest.raises(ValueError, match=r"ls_step must be in \(0, 0.25\]; got 0.5"):
        tune.fit(real.events, real.meta, start, tune.FitOptions(params=["theta_on"], sampler="ls", ls_step=0.5))


def _linear_chi2_problem(seed: int, runs_per_trial: int):
    """A chi-square fit whose truth is known: S = 12 statistics linear in two parameters u in
    [0, 1]^2, m(u) = c + A u, and each seed's statistics m(u) + e_seed with e_seed ~ N(0, Sigma)
    the same at every u (common random numbers, as the fit's seeds). Sigma is Poisson-like
    (diag m) plus a common mode over the first six statistics (as ON and OFF histograms of the
    same pixels share events). Returns the fit's pieces: run_trials, seed_stats, the real
    statistics, the exact least-squares estimate with the fit's seeds and Sigma."""
    from evstwin.tune.result import TrialRecord

    rng = np.random.default_rng(seed)
    c = np.linspace(2000.0, 4000.0, 12)
    a = np.column_stack([np.linspace(800.0, 1600.0, 12), np.r_[np.full(6, 1500.0), np.linspace(-900.0, 900.0, 6)]])
    load = np.r_[np.full(6, 60.0), np.zeros(6)]
    sigma = np.diag(c) + np.outer(load, load)
    chol = np.linalg.cholesky(sigma)
    u_true = np.array([0.4, 0.6])
    real = c + a @ u_true + chol @ rng.standard_normal(12)
    noise = {s: chol @ rng.standard_normal(12) for s in range(runs_per_trial + 8)}  # one draw a seed
    fit_seeds = list(range(runs_per_trial))
    seed_stats: dict[int, np.ndarray] = {}
    trials: list[TrialRecord] = []

    def run_trials(points: list[dict[str, float]], phase: str, seeds=fit_seeds) -> list[TrialRecord]:
        out = []
        for p in points:
            m = c + a @ np.array([p["a"], p["b"]])
            vectors = [m + noise[s] for s in seeds]
            number = len(trials)
            seed_stats[number] = np.vstack(vectors)
            runs = [tune.chi2_distance(real, [v]) for v in vectors]
            trials.append(TrialRecord(number, dict(p), tune.chi2_distance(real, vectors), runs, phase=phase))
            out.append(trials[-1])
        return out

    # The exact minimum of the chi-square with the fit's seeds (weights fixed at the start,
    # then refreshed: a few Gauss-Newton steps converge on a linear model).
    offset = np.mean([noise[s] for s in fit_seeds], axis=0)
    u = u_true.copy()
    for _ in range(5):
        m = c + a @ u + offset
        w = 1.0 / (m + real / runs_per_trial + 1.0)
        u = u + np.linalg.solve(a.T @ (a * w[:, None]), a.T @ (w * (real - m)))
    return run_trials, seed_stats, real, u, a, sigma


@pytest.mark.parametrize("runs_per_trial, stopped_off", [(1, (0.0, 0.0)), (4, (0.0, 0.0)), (2, (0.06, -0.1))])
def test_chi2_intervals_match_the_spread_of_the_fitted_values(runs_per_trial: int,
                                                              stopped_off: tuple[float, float]) -> None:
    """fit(intervals=True)'s chi-square intervals on a problem with known noise: over 300
    recordings (each with its own seeds), the reported half-widths match the root mean square
    error of the reported values, where the search ends on the least-squares minimum (the
    spread of the exact estimates, also checked against the sandwich formula) and where it
    stops ``stopped_off`` from it (the step to the fresh seeds' minimum widens them). The
    Pearson weights alone (a rise of 1 in the chi-square sum) would be far too narrow here.
    (The curvature rule used before, a rise of the distance by its seeds' standard error,
    reported 0.024 and 0.024 for K = 4 where the spread is 0.019 and 0.040.)"""
    from types import SimpleNamespace

    from evstwin.tune.bounds import ParamBound
    from evstwin.tune.intervals import _chi2_intervals
    from evstwin.tune.search import _Scaler

    scaler = _Scaler(["a", "b"], {"a": ParamBound(0.0, 1.0), "b": ParamBound(0.0, 1.0)})
    estimates, halves = [], []
    for j in range(300):
        run_trials, seed_stats, real, u_hat, a, sigma = _linear_chi2_problem(j, runs_per_trial)
        best = run_trials([scaler.from_unit(u_hat + stopped_off)], "ls")[0]
        found = _chi2_intervals(run_trials, scaler, best, SimpleNamespace(real_stats=real), seed_stats,
                                range(runs_per_trial, runs_per_trial + 8))
        estimates.append(u_hat)
        halves.append([(found[k][1] - found[k][0]) / 2.0 for k in "ab"])
    errors = np.array(estimates) - [0.4, 0.6]
    spread = np.sqrt(np.mean(errors**2, axis=0))  # the least-squares estimates around the truth
    reported = np.sqrt(np.mean(np.array(halves) ** 2, axis=0))
    # The analytic covariance of the estimate: (1 + 1/K) H^-1 A^T W Sigma W A H^-1, W at the
    # expected statistics.
    w = 1.0 / ((1.0 + 1.0 / runs_per_trial) * (np.linspace(2000.0, 4000.0, 12) + a @ [0.4, 0.6]) + 1.0)
    h_inv = np.linalg.inv(a.T @ (a * w[:, None]))
    analytic = np.sqrt((1.0 + 1.0 / runs_per_trial)
                       * np.diag(h_inv @ (a * w[:, None]).T @ sigma @ (a * w[:, None]) @ h_inv))
    assert spread == pytest.approx(analytic, rel=0.1)  # the harness: 300 draws, ~4 % noise
    assert reported == pytest.approx(np.sqrt(np.mean((errors + stopped_off) ** 2, axis=0)), rel=0.15)
    pearson = np.sqrt(np.diag(h_inv))
    assert pearson[1] < 0.6 * spread[1]  # the correlations matter here: the check has power
    if any(stopped_off):
        assert np.all(reported > 1.5 * spread)  # and so does the search's stop


def test_chi2_covariance_and_step_by_hand() -> None:
    from evstwin.tune.bounds import ParamBound
    from evstwin.tune.counts import chi2_covariance, chi2_gauss_newton_step
    from evstwin.tune.search import _Scaler

    scaler = _Scaler(["a", "b"], {"a": ParamBound(0.0, 1.0), "b": ParamBound(0.0, 1.0)})
    run_trials, seed_stats, real, u_hat, a, _ = _linear_chi2_problem(7, 2)
    # A search that ended 0.03 and -0.05 off the minimum: the step back is exact on a linear
    # model (with the fit's own seeds, whose minimum u_hat is).
    far = run_trials([scaler.from_unit(u_hat + [0.03, -0.05])], "ls")[0]
    assert chi2_gauss_newton_step(real, seed_stats[far.trial].mean(axis=0), a, 2) == pytest.approx(
        [-0.03, 0.05], rel=0.05)
    # One statistic, one parameter, unit weight (m + r/K + 1 = 1 at r = m = 0), K = 1: H = A^2 = 4;
    # draws -1, 1, 0 have variance 2 / (3 - 1) = 1, so B = (1 + 1/K) A^2 1 = 8 and the
    # variance is B / H^2 = 0.5.
    cov = chi2_covariance(np.zeros(1), np.zeros(1), np.array([[2.0]]), np.array([[-1.0], [1.0], [0.0]]), 1)
    assert cov[0, 0] == pytest.approx(0.5)
    # A parameter no statistic moves with: infinite variance, no step.
    flat = np.column_stack([a[:, 0], np.zeros(12)])
    cov = chi2_covariance(real, real, flat, np.vstack([real, real + 1.0, real - 2.0]), 1)
    assert math.isfinite(cov[0, 0]) and cov[1, 1] == math.inf
    assert chi2_gauss_newton_step(real, real + 10.0, flat, 1)[1] == 0.0
    with pytest.raises(ValueError, match=r"seed_stats must be \(M >= 2, 12\); got \(1, 12\)"):
        chi2_covariance(real, real, a, real[None, :], 1)


RECOVERY_PARAMS = ("pixel.theta_on", "pixel.theta_off", "pixel.dark_rate_e_per_s",
                   "pixel.shot_noise_on_rate_hz", "pixel.shot_noise_off_rate_hz")


# One hidden setting here (the suite's time); bench/bench_recovery.py recovers ten drawn
# settings of the same five parameters at full size.
@pytest.mark.parametrize("hidden", [(0.35, 0.18, 12000.0, 0.10, 0.40)], ids=["low-off"])
def test_least_squares_recovers_thresholds_dark_and_background_rates_on_a_davis346_window(
    hidden: tuple[float, ...]
) -> None:
    """Issue 10's recovery goal on a small sensor: the full-size DAVIS346 `mcreynolds` scene
    (continuous noise, photoreceptor pole, the five LEDs) seen through a 96 x 72 px window
    around the rotation centre for 0.5 s; five parameters hidden, the fit started with the
    thresholds 25-30 % off and the three rates x or / 2.5, budget 60 trials x 2 seeds. The
    goal's tolerances: thresholds within 10 %, rates within x1.5. (The window holds 1/13 of
    the sensor's pixels: a high dark rate with high thresholds, where the LEDs barely fire,
    is left to bench/bench_recovery.py at full size.)"""
    roi = (125, 94, 96, 72)
    truth = dict(zip(RECOVERY_PARAMS, hidden))
    base = dict(load("mcreynolds"), duration_s=0.5)
    s = dict(base, sensor=dict(base["sensor"], roi=list(roi)), pixel=dict(base["pixel"], **{
        k.split(".")[1]: v for k, v in truth.items()}))
    real = simulate(s, seed=100, num_threads=1)
    # The window's events in sensor coordinates, as a real recording of the whole sensor.
    events = real.events.copy()
    events["x"] += roi[0]
    events["y"] += roi[1]
    meta = dict(real.meta, width=346, height=260)
    factor = {"pixel.theta_on": 1.3, "pixel.theta_off": 0.75, "pixel.dark_rate_e_per_s": 2.5,
              "pixel.shot_noise_on_rate_hz": 0.4, "pixel.shot_noise_off_rate_hz": 2.5}
    start = {k: v * factor[k] for k, v in truth.items()}
    result = tune.fit(events, meta, base, tune.FitOptions(params=RECOVERY_PARAMS, budget=60, runs_per_trial=2, seed=0,
                                                          sampler="ls", start=start, roi=roi), workers=2)
    assert result.distance == "chi2" and len(result.history) <= 60 and {r.phase for r in result.history} == {"ls"}
    found = result.best_params
    for k, v in truth.items():
        if "theta" in k:
            assert found[k] == pytest.approx(v, rel=0.10), k
        else:
            assert v / 1.5 <= found[k] <= v * 1.5, k
    # The distance is low at the end and was not at the start (a chi-square about 1 or below
    # for a simulation of the same parameters).
    assert result.best_distance < 1.0 < result.history[0].distance
    assert result.to_json_dict()["distance_formula"].startswith(tune.CHI2_FORMULA)


def test_limiting_magnitude_is_undetermined_where_noise_fires_most_pixels(tmp_path: Path) -> None:
    # 20 Hz of background per pixel: noise alone fires nearly every pixel while a 15 px/s target
    # crosses it, so "half the track fired" says nothing: no limit, and the table says why.
    noisy = set_value(set_value(geo_small(), "pixel.shot_noise_rate_hz", 20.0), "sampling.rate_hz", 200.0)
    result = tune.limiting_magnitude(noisy, rates_arcsec_s=[30.0], magnitudes=[9.0, 12.0], runs=1, out_dir=tmp_path,
                                     workers=0)
    row = result.table[0]
    assert row["status"] == "undetermined" and math.isnan(row["limiting_magnitude"]) and row["chance_fraction"] > 0.9
    assert "undetermined" in result.to_text()
    with open(result.table_path, newline="") as fh:
        assert next(csv.DictReader(fh))["status"] == "undetermined"
    # Latencies count from when the target's light reaches a pixel: never negative, even where
    # noise fires a pixel before the target's centre enters it.
    assert all(r["mean_latency_median_s"] >= 0.0 for r in result.sweep.summary)
    assert tune.draw_limiting_magnitude(result, tmp_path).is_file()


def test_fit_announces_and_writes_the_recordings_duration(tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    # The real recording spans 2,359,945 us (the DAVIS recording) and has no
    # duration_s: the fit simulates that span, so its estimate speaks of it, not of the
    # scenario's 0.3 s, and best.toml says 2.359945, not 2.3599449999999997.
    real = simulate(noise_scenario(), seed=5, num_threads=1, duration_s=0.05)
    events = real.events.copy()
    events["t"][-1] = events["t"][0] + 2_359_945
    meta = {"width": 24, "height": 16}
    scen = noise_scenario()
    scen["sensor"] = dict(scen["sensor"], width=24, height=16)
    result = tune.fit(events, meta, scen, tune.FitOptions(params=["theta_on"], budget=1, sampler="random"), workers=0,
                      progress=True)
    err = capsys.readouterr().err
    assert "for 2.35995 s of sensor time" in err and "for 0.3 s" not in err
    assert result.duration_s == 2.359945
    text = (result.write(tmp_path)["best_toml"]).read_text()
    assert "duration_s = 2.359945\n" in text
