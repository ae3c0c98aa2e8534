"""``fit``: search twin parameters that make a simulation match a real recording.

The pieces, each in its own module: :mod:`.options` (:class:`FitOptions`, what a fit
searches and how), :mod:`.search` (the searches, each saying why it stopped),
:mod:`.intervals` (the calibrated intervals), :mod:`.result` (:class:`FitResult` and its
files); :func:`fit` here runs the trials and puts them together.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, cast

import numpy as np

from .._extras import require
from ..scenario import build, load, set_value
from .bounds import _check_not_shadowed, _current_value
from .counts import CountsObjective
from .execution import JobFailure, _bar, _Context, _Job, announce, make_executor
from .identify import Identifiability, identifiability
from .intervals import INTERVAL_NOISE_SEEDS, _chi2_intervals, _curvature_intervals
from .objectives import MatchObjective
from .options import DISTANCES, LS_STEP, SAMPLERS, FitOptions
from .result import FitResult, TrialRecord
from .search import Stop, _cma_es, _least_squares, _nelder_mead, _Scaler, optuna_search

__all__ = ["DISTANCES", "LS_STEP", "SAMPLERS", "FitOptions", "FitResult", "TrialRecord", "fit"]


def fit(
    real_events: np.ndarray,
    real_meta: Mapping[str, Any],
    scenario: str | Path | dict,
    options: FitOptions | None = None,
    *,
    scheduler: Any = None,
    workers: int | None = None,
    progress: bool = False,
) -> FitResult:
    """Fit twin parameters to a real recording by minimising a distance between it and the
    simulated scenario.

    real_events, real_meta: the recording (``EVENT_DTYPE``; meta with width, height [px] and
        duration_s [s], else last - first event time). The simulated duration is its duration.
    scenario: what to simulate (name, TOML path or dict), of the recording's sensor size.
    options: :class:`FitOptions` (default: ``FitOptions()``): the parameters, bounds, budget,
        seeds, sampler, distance, intervals.
    scheduler, workers: where jobs run (see :func:`make_executor`); they do not change the
        result. progress: a tqdm bar on stderr.

    Intervals. With ``options.intervals`` each parameter gets an interval after the search
    (beyond the budget; the probes are not in the history). Both kinds are taken in the
    [0, 1] coordinates of the bounds (log-scaled where the bound is), so a log parameter's
    interval is wider above.

    With ``distance='chi2'`` (the default 'ls'): the best +- one standard error of the
    least-squares estimate, the square root of the diagonal of
    :func:`evstwin.tune.counts.chi2_covariance`'s sandwich covariance
    ``(1 + 1/K) H^-1 A^T W Sigma W A H^-1`` (A = dm/du, the slopes of the seeds' mean
    statistics over the best +- :data:`evstwin.tune.intervals.CHI2_INTERVAL_STEP` of each
    bound with the fit's seeds, 2 trials a parameter; W the chi-square's weights; Sigma the
    covariance of one seed's statistics, measured at the best from the fit's K seeds and
    :data:`evstwin.tune.intervals.INTERVAL_NOISE_SEEDS` fresh ones, one trial of 8 runs). The
    factor 1 + 1/K counts the recording's noise and the K seeds'; Sigma carries the
    statistics' correlations (they share events); the diagonal of the covariance marginalises
    over the other fitted parameters. Added in quadrature: how far the search stopped from the
    least-squares minimum, estimated by the Gauss-Newton step
    (:func:`evstwin.tune.counts.chi2_gauss_newton_step`) to the fresh seeds' minimum in
    excess of the noise that step carries. Left out: a bias of the estimator and any model
    error. Works with runs_per_trial = 1.

    With ``distance='compare'``: probe each parameter at the best +- 0.05 of its bound width
    with the same seeds (2 trials a parameter) and give it the interval over which a parabola
    through those distances rises by the best trial's standard error over its seeds (the mean
    distance's own noise): "changes the simulator cannot tell from its own noise", a heuristic
    scale rather than a standard error. Needs runs_per_trial >= 2. A flat or concave profile
    gives the whole bound.

    The distance: 'compare' (compare's distance of each seed, averaged over the seeds; the
    default of every sampler but 'ls') or 'chi2' (:mod:`evstwin.tune.counts`: per-pixel count
    histograms of pixel groups set by the scenario's source light, the seeds' statistics
    averaged, a Pearson chi-square; the default, and the only one, of 'ls').
    """
    opts = FitOptions() if options is None else options
    if not isinstance(opts, FitOptions):
        raise ValueError(f"options must be a FitOptions; got {type(opts).__name__}")
    # The optional packages only where used: 'ls' and 'nm' need SciPy alone.
    if opts.sampler == "cmaes":
        require("cmaes")
    elif opts.sampler in ("tpe", "tpe+nm", "random"):
        require("optuna")

    t0 = time.perf_counter()
    objective = MatchObjective(real_events, real_meta, bin_width=opts.bin_width, roi=opts.roi,
                               mask_pixels=opts.mask_pixels, mask_hot=opts.mask_hot)
    base = load(scenario)
    sensor = build(base)
    if (sensor.width, sensor.height) != (objective.sensor_width, objective.sensor_height):
        raise ValueError(
            f"scenario sensor is {sensor.width}x{sensor.height} px but the real recording is "
            f"{objective.sensor_width}x{objective.sensor_height}: set sensor.width / sensor.height"
        )
    counts: CountsObjective | None = None
    if opts.distance == "chi2":  # checked like compare's above; its pixel groups need the scenario
        from .timing import TimingObjective

        kind = TimingObjective if opts.statistics == "timing" else CountsObjective
        counts = kind(real_events, real_meta, base, roi=opts.roi, mask_pixels=opts.mask_pixels,
                      mask_hot=opts.mask_hot)
        objective = counts
    keys, bnds = list(opts.keys), opts.resolved_bounds
    _check_not_shadowed(base, keys, "fitted parameter")
    for k in keys:  # every bound must give a valid scenario (fail now, not in a worker)
        for v in (bnds[k].low, bnds[k].high):
            try:
                build(set_value(base, k, v))
            except ValueError as exc:
                raise ValueError(
                    f"bounds of {k}: {bnds[k].low:g}:{bnds[k].high:g} leave the valid range ({exc})"
                ) from None
    scaler = _Scaler(keys, bnds)
    start_values = _start_values(opts, base)

    sim_seeds = opts.sim_seeds
    ctx = _Context(scenario=base, objective=objective)
    history: list[TrialRecord] = []
    failed: list[JobFailure] = []
    executor = make_executor(scheduler, workers)
    budget, sampler = opts.budget, opts.sampler
    if progress:
        print(announce(f"fit ({sampler}, up to {budget} trials x {opts.runs_per_trial} seed(s))",
                       budget * opts.runs_per_trial,
                       build(objective.prepare(base), duration_s=objective.duration_s), executor), file=sys.stderr)
    bar = _bar(budget, f"fit ({sampler})", progress, unit="trial")
    best = [math.inf]
    residuals: dict[int, np.ndarray] = {}  # trial number -> chi-square residuals ('ls' reads them)
    seed_stats: dict[int, np.ndarray] = {}  # trial number -> its seeds' statistics, (K, S) (the intervals')

    def run_trials(points: list[dict[str, float]], phase: str, seeds: Sequence[int] = sim_seeds
                   ) -> list[TrialRecord]:
        first = len(history)
        jobs = [_Job((first + n, s), p, s) for n, p in enumerate(points) for s in seeds]
        values: dict[tuple[int, int], float] = {}
        stats: dict[tuple[int, int], np.ndarray] = {}
        errors: dict[int, str] = {}
        for job, out in executor.run(ctx, jobs):
            number, s = cast("tuple[int, int]", job.key)
            if isinstance(out, JobFailure):
                failed.append(out)
                errors[number] = out.error
            else:
                values[(number, s)] = out["distance"]
                if counts is not None:
                    stats[(number, s)] = np.asarray(out["stats"])
        records = []
        for n, p in enumerate(points):  # in trial order: deterministic whatever finished first
            number = first + n
            runs = [values[(number, s)] for s in seeds if (number, s) in values]
            mean = float(np.mean(runs)) if len(runs) == len(seeds) else math.nan
            if counts is not None and math.isfinite(mean):
                # The seeds' statistics averaged first: a chi-square of the mean, not a mean
                # of chi-squares (each seed's alone carries its full noise).
                vectors = [stats[(number, s)] for s in seeds]
                residuals[number] = counts.residuals(vectors)
                seed_stats[number] = np.vstack(vectors)
                mean = counts.trial_distance(vectors)
            error = errors.get(number, "")
            if not math.isfinite(mean):
                error, mean = error or "non-finite distance", math.nan
            else:
                best[0] = min(best[0], mean)
            rec = TrialRecord(number, dict(p), mean, runs, error, phase)
            history.append(rec)
            records.append(rec)
            if bar is not None:
                bar.update(1)
                bar.set_postfix(best=f"{best[0]:.4g}")
        return records

    stop = Stop("budget", f"all {budget} trials used", budget)
    try:
        n_optuna = {"nm": 0, "ls": 0, "cmaes": 0, "tpe+nm": max(1, budget // 2)}.get(sampler, budget)
        if n_optuna:
            stop = optuna_search(run_trials, keys, bnds, sampler, opts.seed, n_optuna, opts.batch_size, start_values)
        if len(history) < budget:
            finite = [r for r in history if math.isfinite(r.distance)]
            if finite:
                x0 = scaler.to_unit(min(finite, key=lambda r: (r.distance, r.trial)).params)
            elif start_values is not None:
                x0 = scaler.to_unit(start_values)
            else:
                x0 = np.full(len(keys), 0.5)
            if sampler == "cmaes":
                stop = _cma_es(run_trials, scaler, x0, budget - len(history), opts.seed)
            elif sampler == "ls" and counts is not None:
                stop = _least_squares(run_trials, residuals, counts.real_stats.size, scaler, x0,
                                      budget - len(history), float(opts.ls_step))
            else:
                stop = _nelder_mead(run_trials, scaler, x0, budget - len(history), float(opts.nm_step))
        description = executor.description
    finally:
        if bar is not None:
            bar.close()
        executor.close()
    finite = [r for r in history if math.isfinite(r.distance)]
    if not finite:
        raise RuntimeError(f"every fit trial failed; first error: {history[0].error if history else 'none'}")
    best_rec = min(finite, key=lambda r: (r.distance, r.trial))
    report = _report(stop, scaler, best_rec, 0 if counts is None else counts.real_stats.size)
    found: dict[str, tuple[float, float]] = {} if report is None else _report_intervals(report, scaler, best_rec)
    if opts.intervals:
        # The probes run like trials but stay out of the history (they are not the search's).
        executor, bar, n_searched = make_executor(scheduler, workers), None, len(history)
        try:
            if counts is not None:
                found = _chi2_intervals(run_trials, scaler, best_rec, counts, seed_stats,
                                        [opts.seed + opts.runs_per_trial + k for k in range(INTERVAL_NOISE_SEEDS)])
            else:
                found = _curvature_intervals(run_trials, scaler, best_rec)
        finally:
            executor.close()
            del history[n_searched:]
    best_scenario = base
    for k in keys:
        best_scenario = set_value(best_scenario, k, best_rec.params[k])
    best_scenario = set_value(best_scenario, "duration_s", float(objective.real_meta["duration_s"]))
    best_scenario = set_value(best_scenario, "seed", sim_seeds[0])
    return FitResult(
        best_params=dict(best_rec.params),
        best_distance=best_rec.distance,
        history=history,
        params=keys,
        bounds=bnds,
        scenario=base,
        best_scenario=best_scenario,
        budget=budget,
        runs_per_trial=opts.runs_per_trial,
        seed=opts.seed,
        sim_seeds=sim_seeds,
        sampler=sampler,
        batch_size=opts.batch_size,
        duration_s=float(objective.real_meta["duration_s"]),
        real_events=real_events,
        real_meta=dict(real_meta),
        executor=description,
        elapsed_s=time.perf_counter() - t0,
        failed=failed,
        roi=None if objective.roi is None else objective.roi.as_tuple(),
        mask=objective.mask,
        intervals=found,
        distance=cast(str, opts.distance),
        options=opts,
        stop_reason=stop.reason,
        stop_detail=stop.detail,
        identifiability=report,
        interval_kind="calibrated" if opts.intervals else ("report" if found else ""),
    )


def _report(stop: Stop, scaler: _Scaler, best: TrialRecord, n_stats: int) -> Identifiability | None:
    """The identifiability report from the search's Jacobian (None: the search has none)."""
    if stop.jacobian is None or stop.jacobian_at is None or not np.all(np.isfinite(stop.jacobian)):
        return None
    at_best = np.allclose(stop.jacobian_at, np.clip(scaler.to_unit(best.params), 0.0, 1.0), atol=1e-12)
    where = f"at the best trial {best.trial}" if at_best else f"nearest the best trial {best.trial}"
    return identifiability(stop.jacobian, scaler.keys, f"the least squares' Jacobian {where}; {n_stats} statistics")


def _report_intervals(report: Identifiability, scaler: _Scaler, best: TrialRecord) -> dict[str, tuple[float, float]]:
    """Each parameter's best +- its report's standard error, in the [0, 1] coordinates, clipped
    to the bounds (the whole bound where unconstrained)."""
    u0 = scaler.to_unit(best.params)
    out = {}
    for i, key in enumerate(scaler.keys):
        lo, hi = u0.copy(), u0.copy()
        sd = float(report.sd_unit[i])
        lo[i], hi[i] = (max(0.0, u0[i] - sd), min(1.0, u0[i] + sd)) if math.isfinite(sd) else (0.0, 1.0)
        out[key] = (scaler.from_unit(lo)[key], scaler.from_unit(hi)[key])
    return out


def _start_values(opts: FitOptions, base: dict[str, Any]) -> dict[str, float] | None:
    """The search's starting point (see :attr:`FitOptions.start`): None for the middle of the
    bounds (or a scenario lacking a value of a fitted key)."""
    bnds = opts.resolved_bounds
    if isinstance(opts.start, str):  # 'scenario' (FitOptions refused any other string)
        current = {k: _current_value(base, k) for k in opts.keys}
        if all(v is not None for v in current.values()):
            return {k: min(max(float(cast(float, v)), bnds[k].low), bnds[k].high) for k, v in current.items()}
        return None
    if opts.start is None:
        return None
    from .bounds import canonical_key

    return {canonical_key(k): float(v) for k, v in opts.start.items()}
