"""The fit's options, stop reasons, identifiability report and timing statistics (issue 34)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from evstwin import tune
from evstwin.tune.bounds import ParamBound
from evstwin.tune.identify import identifiability
from evstwin.tune.result import TrialRecord
from evstwin.tune.search import STOP_REASONS, _least_squares, _Scaler
from evstwin.tune.timing import binned, quantile_edges, timing_samples, timing_statistics

# -- FitOptions --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, words",
    [
        ({"budget": 0}, "FitOptions.budget must be an integer >= 1; got 0"),
        ({"budget": 2.5}, "FitOptions.budget must be an integer >= 1; got 2.5"),
        ({"runs_per_trial": True}, "FitOptions.runs_per_trial must be an integer >= 1; got True"),
        ({"seed": -1}, "FitOptions.seed must be an integer >= 0; got -1"),
        ({"sampler": "bfgs"}, "FitOptions.sampler must be one of ls, nm, tpe+nm, tpe, cmaes, random; got 'bfgs'"),
        ({"ls_step": 0.5}, "FitOptions.ls_step must be in (0, 0.25]; got 0.5"),
        ({"nm_step": 0.0}, "FitOptions.nm_step must be in (0, 0.5]; got 0.0"),
        ({"bin_width": float("nan")}, "FitOptions.bin_width must be a finite number > 0; got nan"),
        ({"statistics": "rates"}, "FitOptions.statistics must be one of timing, counts; got 'rates'"),
        ({"distance": "w1"}, "FitOptions.distance must be one of compare, chi2; got 'w1'"),
        ({"intervals": 1}, "FitOptions.intervals must be True or False; got 1"),
        ({"start": "middle"}, "FitOptions.start must be 'scenario', a dict or None; got 'middle'"),
        ({"params": ["theta_on"], "start": {"theta_on": 5.0}}, "FitOptions.start must give a value inside the bounds"),
        ({"params": ["theta_on", "theta_on"]}, "params: repeated parameter"),
    ],
)
def test_fit_options_refuse_bad_values_in_one_line(kwargs: dict, words: str) -> None:
    with pytest.raises(ValueError) as err:
        tune.FitOptions(**kwargs)
    assert words in str(err.value) and "\n" not in str(err.value)


def test_fit_options_resolve_names_distance_and_are_frozen() -> None:
    o = tune.FitOptions(params="theta_on,dark_rate_e_per_s", sampler="nm")
    assert o.keys == ("pixel.theta_on", "pixel.dark_rate_e_per_s") and o.distance == "compare"
    assert o.resolved_bounds["pixel.theta_on"] == tune.FIT_BOUNDS["pixel.theta_on"]
    assert tune.FitOptions().distance == "chi2" and tune.FitOptions(runs_per_trial=3, seed=4).sim_seeds == [4, 5, 6]
    with pytest.raises(AttributeError):
        o.budget = 3  # type: ignore[misc]


# -- the identifiability report ----------------------------------------------------------------


def test_report_of_a_linear_model_by_hand() -> None:
    # Residuals r = J u with J = [[1, 0], [0, 1], [1, 1]]: J^T J = [[2, 1], [1, 2]], its inverse
    # (1/3) [[2, -1], [-1, 2]]: standard errors sqrt(2/3), correlation -1/2; eigenvalues 1
    # (along (1, -1)/sqrt 2) and 3 (along (1, 1)/sqrt 2).
    j = np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    rep = identifiability(j, ["pixel.theta_on", "pixel.dark_rate_e_per_s"], "by hand")
    assert rep.correlation == pytest.approx(np.array([[1.0, -0.5], [-0.5, 1.0]]))
    assert rep.sd_unit == pytest.approx([math.sqrt(2 / 3)] * 2)
    assert rep.eigenvalues == pytest.approx([1.0, 3.0])
    sd, along = rep.weak_directions()[0]
    assert sd == pytest.approx(1.0)  # 1 / sqrt(1)
    assert along["pixel.theta_on"] == pytest.approx(1 / math.sqrt(2))
    assert along["pixel.dark_rate_e_per_s"] == pytest.approx(-1 / math.sqrt(2))
    assert not rep.warnings() and not rep.correlated_pairs
    # Scaling a parameter (another unit) changes its standard error, not the correlation.
    scaled = identifiability(j * np.array([1.0, 10.0]), ["a", "b"])
    assert scaled.correlation[0, 1] == pytest.approx(-0.5) and scaled.sd_unit[1] == pytest.approx(math.sqrt(2 / 3) / 10)


def test_report_flags_the_degenerate_valley_and_an_unconstrained_parameter() -> None:
    rng = np.random.default_rng(3)
    a = rng.normal(size=40)
    c = rng.normal(size=40)
    # theta_on's column is nearly minus twice the dark rate's: a rise of one undone by the other.
    j = np.column_stack([a, -0.5 * a + 0.02 * rng.normal(size=40), c, np.zeros(40)])
    keys = ["pixel.theta_on", "pixel.dark_rate_e_per_s", "pixel.theta_off", "pixel.refractory_s"]
    rep = identifiability(j, keys)
    (first, second, r), = rep.correlated_pairs
    assert {first, second} == {"pixel.theta_on", "pixel.dark_rate_e_per_s"} and r > 0.9
    assert rep.unconstrained == ["pixel.refractory_s"] and math.isinf(rep.sd_unit[3])
    assert np.isnan(rep.correlation[3, 0]) and abs(rep.correlation[2, 0]) < 0.5
    text = rep.to_text()
    assert "warning: theta_on and dark_rate_e_per_s cannot be told apart" in text
    assert "refractory_s is not constrained" in text
    # The weakest direction with information is along the valley.
    sd, along = rep.weak_directions()[0]
    assert math.isinf(sd) and set(along) == {"pixel.refractory_s"}
    sd, along = rep.weak_directions()[1]
    assert set(along) == {"pixel.theta_on", "pixel.dark_rate_e_per_s"} and sd > 1.0
    # Exactly degenerate: the two columns equal up to a factor: r = +-1, both unconstrained.
    exact = identifiability(np.column_stack([a, -0.5 * a]), ["x", "y"])
    assert exact.correlation[0, 1] == pytest.approx(1.0) and exact.unconstrained == ["x", "y"]
    json.dumps(rep.to_json_dict(), allow_nan=False)
    with pytest.raises(ValueError, match=r"jacobian must be \(S, 4\); got \(40, 3\)"):
        identifiability(j[:, :3], keys)


# -- the least squares' stop reason ------------------------------------------------------------


def _linear_search(budget: int):
    a = np.array([[3.0, 1.0], [0.5, 2.0], [1.0, -1.0]])
    target = np.array([0.62, 0.27])
    residuals: dict[int, np.ndarray] = {}
    points: list[np.ndarray] = []

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
    return _least_squares(run_trials, residuals, 3, scaler, np.array([0.1, 0.9]), budget, 0.02), points, a


def test_least_squares_says_why_it_stopped_and_keeps_its_jacobian() -> None:
    stop, points, a = _linear_search(200)
    assert stop.reason == "converged" and stop.trials_used == len(points) < 200
    # Linear residuals: the forward differences are the exact Jacobian.
    assert stop.jacobian == pytest.approx(a) and stop.jacobian_at == pytest.approx([0.62, 0.27], abs=1e-6)
    stop, points, _ = _linear_search(5)
    assert stop.reason == "budget" and len(points) <= 5 and "fewer than the next step" in stop.detail
    assert set(STOP_REASONS) == {"budget", "converged", "stalled"}


# -- the timing statistics ---------------------------------------------------------------------


def _events(rows: list[tuple[int, int, int, int]]) -> np.ndarray:
    from evstwin import EVENT_DTYPE

    ev = np.zeros(len(rows), EVENT_DTYPE)
    for name, column in zip(("t", "x", "y", "p"), zip(*rows)):
        ev[name] = column
    return ev


def test_timing_statistics_of_a_handmade_event_list() -> None:
    # A 3 x 1 sensor: pixel 0 quiet (group 0), pixel 1 lit (group 1, its source passes at
    # t = 10 ms), pixel 2 masked (-1).
    groups = np.array([[0, 1, -1]])
    passage_s = np.array([[np.nan, 0.010, 0.020]])
    ev = _events([
        (1000, 0, 0, 1), (9000, 1, 0, 1), (11000, 1, 0, 1), (12000, 2, 0, 1),
        (14000, 1, 0, 0), (31000, 0, 0, 0), (40000, 1, 0, 0), (50000, 0, 0, 0),
    ])
    s = timing_samples(ev, 3, groups, passage_s, n_groups=2)
    # Pixel 1's delays: 9 - 10 = -1 ms and 11 - 10 = +1 ms (ON); 14 - 10 = 4 ms, 40 - 10 = 30 ms (OFF).
    assert s[("delay", 1, 1, -1)] == pytest.approx([-0.001, 0.001])
    assert s[("delay", 1, 0, -1)] == pytest.approx([0.004, 0.030])
    # Its intervals: ON->ON 2 ms, ON->OFF 3 ms, OFF->OFF 26 ms; pixel 0's: ON->OFF 30 ms,
    # OFF->OFF 19 ms. The masked pixel's event is in none.
    assert s[("interval", 1, 1, 1)] == pytest.approx([0.002])
    assert s[("interval", 1, 1, 0)] == pytest.approx([0.003])
    assert s[("interval", 1, 0, 0)] == pytest.approx([0.026])
    assert s[("interval", 1, 0, 1)].size == 0
    assert s[("interval", 0, 1, 0)] == pytest.approx([0.030])
    assert s[("interval", 0, 0, 0)] == pytest.approx([0.019])
    assert ("delay", 0, 1, -1) not in s  # the quiet group has no passage
    # Counts in bins: an edge's value goes to the bin above it.
    assert binned(np.array([0.5, 1.0, 1.5, 3.0]), np.array([1.0, 2.0])).tolist() == [1.0, 2.0, 1.0]
    edges = {("interval", 1, 0, 0): np.array([0.01]), ("delay", 1, 0, -1): np.array([0.0, 0.02])}
    assert timing_statistics(s, edges).tolist() == [0.0, 1.0, 0.0, 1.0, 1.0]
    # Too few samples for quantiles: one bin; enough: the quantiles, distinct.
    assert quantile_edges(np.arange(5.0), (0.5,)).size == 0
    assert quantile_edges(np.arange(101.0), (0.1, 0.5, 0.5)).tolist() == [10.0, 50.0]


def test_source_passage_time_follows_a_moving_source() -> None:
    from evstwin.scenario import build
    from evstwin.tune.counts import source_light_and_time

    scen = {
        "name": "mover", "duration_s": 0.2, "seed": 0,
        "sensor": {"preset": "davis346", "width": 40, "height": 12},
        "sampling": {"rate_hz": 500.0},
        "targets": [{"kind": "linear", "x0_px": 5.0, "y0_px": 6.0, "vx_px_s": 150.0, "vy_px_s": 0.0,
                     "flux_ph_s": 1e7}],
    }
    flux, when = source_light_and_time(build(scen))
    # The source's centre is over column x at t = (x - 5) / 150 s.
    for x in (8, 15, 30):
        assert when[6, x] == pytest.approx((x - 5) / 150.0, abs=0.25 / 150.0 + 1e-9)
    assert np.isnan(when[flux == 0.0]).all()


# -- fit end to end ----------------------------------------------------------------------------


def small_scene(theta_on: float, dark_rate_e_per_s: float) -> dict:
    """32 x 24 px, 0.2 s: a source on an 8 px circle over a dim sky."""
    return {
        "name": "small", "duration_s": 0.2, "seed": 0,
        "background": {"photon_rate_ph_s": 2e6},
        "sensor": {"preset": "davis346_paper", "width": 32, "height": 24},
        "pixel": {"theta_on": theta_on, "dark_rate_e_per_s": dark_rate_e_per_s},
        "optics": {"extra_blur_sigma_px": 1.5},
        "sampling": {"rate_hz": 500.0, "max_shift_px": 0.5, "sparse": True},
        "targets": [{"kind": "circular", "centre_x_px": 16.0, "centre_y_px": 12.0, "radius_px": 8.0,
                     "period_s": 0.2, "flux_ph_s": 4e9, "label": "led"}],
    }


def test_fit_reports_what_it_can_separate_and_why_it_stopped(tmp_path: Path) -> None:
    from evstwin.simulate import simulate

    real = simulate(small_scene(0.3, 2000.0), seed=5, num_threads=1)
    opts = tune.FitOptions(params=["theta_on", "dark_rate_e_per_s"], budget=7, seed=3)
    result = tune.fit(real.events, real.meta, small_scene(0.4, 4000.0), opts, workers=0)
    assert result.stop_reason in STOP_REASONS and result.stop_detail
    rep = result.identifiability
    assert rep is not None and rep.params == ["pixel.theta_on", "pixel.dark_rate_e_per_s"]
    assert rep.correlation[0, 0] == 1.0 and -1.0 <= rep.correlation[0, 1] <= 1.0
    # Intervals by default, from the report: around the best.
    assert result.interval_kind == "report"
    for k, (lo, hi) in result.intervals.items():
        assert lo <= result.best_params[k] <= hi
    text = result.to_text()
    assert "stopped: " in text and "identifiability (" in text and "correlation" in text
    paths = result.write(tmp_path)
    report = json.loads(paths["json"].read_text())
    assert report["stop"]["reason"] == result.stop_reason
    assert report["identifiability"]["params"] == rep.params and report["statistics"] == opts.statistics
    drawn = tune.draw_fit(result, tmp_path, comparison=False)
    assert drawn["correlation"].is_file()


def test_timing_statistics_separate_the_threshold_from_the_dark_rate() -> None:
    """Issue 34's degenerate case on a small sensor: `mcreynolds` through a 160 x 120 px window
    for 0.5 s, hidden theta_on 0.2, theta_off 0.25, dark rate 8000 e-/s. The identifiability
    report of the standardised residuals' Jacobian at the hidden values (forward differences of
    the least squares' step, two common seeds) names theta_on and the dark rate as correlated
    beyond 0.9 on the counts alone; with the timing statistics the correlation falls below it
    and both standard errors shrink (by about 3.5 here)."""
    from evstwin.scenario import load, set_value
    from evstwin.simulate import simulate
    from evstwin.tune.counts import CountsObjective
    from evstwin.tune.options import CORRELATION_WARN, LS_STEP
    from evstwin.tune.timing import TimingObjective

    roi = (93, 70, 160, 120)
    keys = ["pixel.theta_on", "pixel.dark_rate_e_per_s"]
    truth = {"pixel.theta_on": 0.2, "pixel.theta_off": 0.25, "pixel.dark_rate_e_per_s": 8000.0}
    base = dict(load("mcreynolds"), duration_s=0.5)
    for k, v in truth.items():
        base = set_value(base, k, v)

    def run(values: dict[str, float], seed: int):
        s = set_value(base, "sensor.roi", list(roi))
        for k, v in values.items():
            s = set_value(s, k, v)
        return simulate(s, seed=seed, num_threads=1)

    real = run({}, 100)
    events = real.events.copy()
    events["x"] += roi[0]
    events["y"] += roi[1]
    meta = dict(real.meta, width=346, height=260)
    objectives = {"counts": CountsObjective(events, meta, base, roi=roi),
                  "timing": TimingObjective(events, meta, base, roi=roi)}
    scaler = _Scaler(keys, tune.FIT_BOUNDS)
    u0 = scaler.to_unit(truth)
    points = [u0] + [u0 + LS_STEP * np.eye(2)[i] for i in range(2)]
    sims = [[run(scaler.from_unit(u), seed) for seed in (0, 1)] for u in points]
    reports = {}
    for name, obj in objectives.items():
        res = [obj.residuals([obj.statistics(r.events) for r in runs]) for runs in sims]
        jac = np.column_stack([(res[i + 1] - res[0]) / LS_STEP for i in range(2)])
        reports[name] = identifiability(jac, keys, name)
    counts, timing = reports["counts"], reports["timing"]
    assert counts.correlated_pairs and set(counts.correlated_pairs[0][:2]) == set(keys)
    assert "theta_on and dark_rate_e_per_s cannot be told apart" in counts.to_text()
    assert abs(timing.correlation[0, 1]) < CORRELATION_WARN < abs(counts.correlation[0, 1])
    assert not timing.correlated_pairs
    assert np.all(timing.sd_unit < counts.sd_unit / 2.0)
