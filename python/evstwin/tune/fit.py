"""``fit``: search twin parameters that make a simulation match a real recording."""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import sys
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from .._extras import require
from ..scenario import build, load, set_value
from ._types import PathLike
from .bounds import (
    DEFAULT_FIT_PARAMS,
    FIT_BOUNDS,
    ParamBound,
    _check_not_shadowed,
    _current_value,
    canonical_key,
    parse_bound,
)
from .counts import CountsObjective
from .execution import JobFailure, _bar, _Context, _Job, announce, make_executor
from .objectives import MatchObjective
from .sweep import _atomic_write_text, _fmt_value, _jsonable


@dataclass
class TrialRecord:
    """One trial of a fit: its number, parameter values, mean distance over the runs (nan
    if failed), each run's distance, and the error of a failed trial."""

    trial: int
    params: dict[str, float]
    distance: float
    run_distances: list[float]
    error: str = ""
    phase: str = ""
    """Which search proposed the trial: tpe, random, cmaes, nm or ls."""


@dataclass
class FitResult:
    """Result of :func:`fit`. ``best_scenario`` is the input scenario with the best values
    set (and the real recording's duration, the first fit seed): what ``best.toml`` holds."""

    best_params: dict[str, float]
    best_distance: float
    history: list[TrialRecord]
    params: list[str]
    bounds: dict[str, ParamBound]
    scenario: dict[str, Any]
    best_scenario: dict[str, Any]
    budget: int
    runs_per_trial: int
    seed: int
    sim_seeds: list[int]
    sampler: str
    batch_size: int
    duration_s: float
    real_events: np.ndarray = field(repr=False)
    real_meta: dict[str, Any] = field(repr=False)
    executor: str = ""
    elapsed_s: float = 0.0
    failed: list[JobFailure] = field(default_factory=list)
    roi: tuple[int, int, int, int] | None = None
    """The compared rectangle (x0, y0, w, h) of the sensor; None: the whole sensor."""
    mask: np.ndarray | None = field(default=None, repr=False)
    """The (h, w) pixels of the compared region left out (listed and hot); None: none."""
    distance: str = "compare"
    """The distance minimised: 'compare' (:func:`evstwin.validation.compare`'s, mean over the
    seeds) or 'chi2' (:mod:`evstwin.tune.counts`, from the mean of the seeds' statistics)."""
    intervals: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Each parameter's interval (``intervals=True``; see :func:`fit`): with the chi-square, the
    best +- one standard error of the least-squares estimate; with compare's distance, the
    values that raise the mean distance by its own seed-to-seed standard error. Empty when not
    asked for."""

    @property
    def best_trial(self) -> int:
        finite = [r for r in self.history if math.isfinite(r.distance)]
        return min(finite, key=lambda r: (r.distance, r.trial)).trial if finite else -1

    def to_text(self) -> str:
        """The best parameters and distance as a table, for a terminal."""
        rows = [("parameter", "best", "interval", "low", "high", "scale")]
        for p in self.params:
            b = self.bounds[p]
            iv = self.intervals.get(p)
            rows.append(
                (p, f"{self.best_params[p]:.6g}", f"{iv[0]:.4g}..{iv[1]:.4g}" if iv else "-", f"{b.low:g}",
                 f"{b.high:g}", "log" if b.log else "lin")
            )
        widths = [max(len(r[i]) for r in rows) for i in range(6)]
        lines = [
            "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths)))
            for r in rows
        ]
        lines.insert(1, "-" * len(lines[0]))
        n_ok = sum(math.isfinite(r.distance) for r in self.history)
        lines.append(
            f"best distance {self.best_distance:.6g} ({self.distance}; trial {self.best_trial} of {len(self.history)}, "
            f"{n_ok} finished; {self.runs_per_trial} run(s) per trial, seeds {self.sim_seeds}; "
            f"{self.elapsed_s:.1f} s on {self.executor})"
        )
        return "\n".join(lines)

    def to_json_dict(self) -> dict[str, Any]:
        from ..validation import DISTANCE_FORMULA
        from .counts import CHI2_FORMULA

        return _jsonable(
            {
                "best_params": self.best_params,
                "best_distance": self.best_distance,
                "intervals": {k: list(v) for k, v in self.intervals.items()},
                "best_trial": self.best_trial,
                "params": self.params,
                "bounds": {
                    k: {"low": b.low, "high": b.high, "log": b.log, "why": b.why}
                    for k, b in self.bounds.items()
                },
                "budget": self.budget,
                "trials": len(self.history),
                "runs_per_trial": self.runs_per_trial,
                "seed": self.seed,
                "sim_seeds": self.sim_seeds,
                "sampler": self.sampler,
                "batch_size": self.batch_size,
                "duration_s": self.duration_s,
                "real": str(self.real_meta.get("path", "")),
                "executor": self.executor,
                "elapsed_s": self.elapsed_s,
                "distance": self.distance,
                "distance_formula": CHI2_FORMULA if self.distance == "chi2" else DISTANCE_FORMULA,
                "roi": list(self.roi) if self.roi is not None else None,
                "masked_pixels": (
                    [] if self.mask is None
                    else [[int(x) + (self.roi[0] if self.roi else 0), int(y) + (self.roi[1] if self.roi else 0)]
                          for y, x in np.argwhere(self.mask)]
                ),
                "failed": [dataclasses.asdict(f) for f in self.failed],
            }
        )

    def write(self, out_dir: PathLike) -> dict[str, Path]:
        """Write the data of the fit: ``best.toml`` (runnable by ``evstwin simulate``),
        ``history.csv`` and ``fit.json``. Returns {name: path}. The figures (convergence and
        the comparison of the best fit) are :func:`evstwin.tune.figures.draw_fit`'s."""
        from ..scenario import to_toml

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths: dict[str, Path] = {}
        paths["best_toml"] = out / "best.toml"
        _atomic_write_text(paths["best_toml"], to_toml(self.best_scenario))
        paths["history"] = out / "history.csv"
        with open(paths["history"], "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(
                [
                    "trial",
                    "phase",
                    "distance",
                    *self.params,
                    *[f"distance_seed{s}" for s in self.sim_seeds],
                    "error",
                ]
            )
            for r in self.history:
                run_d = r.run_distances + [math.nan] * (len(self.sim_seeds) - len(r.run_distances))
                w.writerow(
                    [
                        r.trial,
                        r.phase,
                        _fmt_value(r.distance),
                        *[_fmt_value(r.params[p]) for p in self.params],
                        *[_fmt_value(d) for d in run_d],
                        r.error,
                    ]
                )
        report = self.to_json_dict()
        report["outputs"] = {k: str(v) for k, v in paths.items()}
        paths["json"] = out / "fit.json"
        _atomic_write_text(paths["json"], json.dumps(report, indent=1, allow_nan=False))
        return paths



def _resolve_bounds(
    params: Sequence[str], bounds: Mapping[str, Any] | None
) -> tuple[list[str], dict[str, ParamBound]]:
    keys = [canonical_key(p) for p in params]
    if not keys:
        raise ValueError("params: give at least one parameter to fit")
    if len(set(keys)) != len(keys):
        raise ValueError(f"params: repeated parameter in {list(params)}")
    user: dict[str, ParamBound] = {}
    for name, b in (bounds or {}).items():
        key = canonical_key(name)
        if isinstance(b, ParamBound):
            user[key] = b
        elif isinstance(b, str):
            user[key] = parse_bound(f"{name}={b}")[1]
        else:
            try:
                lo, hi = (float(v) for v in b)
            except (TypeError, ValueError):
                raise ValueError(
                    f"bounds[{name!r}] must be (low, high), 'low:high' or a ParamBound; got {b!r}"
                ) from None
            default = FIT_BOUNDS.get(key)
            log = bool(default.log and lo > 0) if default is not None else False
            try:
                user[key] = ParamBound(lo, hi, log, "user")
            except ValueError as exc:
                raise ValueError(f"bounds[{name!r}]: {exc}") from None
    unused = sorted(set(user) - set(keys))
    if unused:
        raise ValueError(f"bounds given for parameters that are not fitted: {', '.join(unused)}")
    out: dict[str, ParamBound] = {}
    for key in keys:
        if key in user:
            out[key] = user[key]
        elif key in FIT_BOUNDS:
            out[key] = FIT_BOUNDS[key]
        else:
            raise ValueError(f"parameter {key} has no default bounds: give them (--bounds {key}=lo:hi)")
    return keys, out


SAMPLERS = ("ls", "nm", "tpe+nm", "tpe", "cmaes", "random")
DISTANCES = ("compare", "chi2")


"""Search strategies of :func:`fit`:

* ``nm``: SciPy's bounded Nelder-Mead from the starting point, in coordinates
  scaled to [0, 1] over each bound (log-scaled where the bound is), restarted from the best
  point with a fresh simplex whenever SciPy's run converges or stalls (no new best in
  :data:`NM_STALL_TRIALS_PER_PARAM` trials a parameter), until the budget is spent. Local and
  deterministic: the automated form of the paper's sec. 3.3 hand tuning. Trials run one after
  another (the runs of a trial in parallel).
* ``tpe``: Optuna's multivariate TPE (seeded), global, trials batched to the workers with
  ask/tell. ``random``: Optuna's seeded random sampler, the same way.
* ``tpe+nm``: TPE for half the budget, then Nelder-Mead from the best point found.
* ``cmaes``: CMA-ES (the ``cmaes`` package, bounded) from the starting point with a step of
  :data:`CMAES_SIGMA` in the [0, 1] coordinates, seeded; each generation (its default
  population, 4 + 3 ln n) is one batch of trials run in parallel; restarted from the best
  point when it stops with budget left. (Optuna's wrapper, used before, sampled the first
  batch uniformly over the bounds: it learns the search space from finished trials.)
* ``ls`` (default): SciPy's trust-region least squares (``least_squares``, method 'trf', bounded) on
  the chi-square distance's residuals (:mod:`evstwin.tune.counts`; ``distance='chi2'``), in
  the same [0, 1] coordinates. Its Jacobian is a batch of forward differences (one trial a
  parameter, :data:`LS_STEP` of the bound width, run in parallel with the seeds of each);
  restarted from the best point with half the step when SciPy's run converges, until the
  budget cannot hold another step (a point and its n-trial Jacobian: up to n trials of the
  budget may stay unused). Deterministic. The distance is a sum of squared standardised
  differences, so Gauss-Newton steps use its structure where Nelder-Mead and CMA-ES see
  one number a trial.

Why least squares by default: on the full-size recovery benchmark (bench/bench_recovery.py:
five parameters of the DAVIS346 ``mcreynolds`` scene, budget 60) it recovered 9 hidden
settings of 10, CMA-ES on the chi-square none, Nelder-Mead 1 on ``compare``'s distance and 3 on
the chi-square (the fit guide's "Recovery at full size" (docs/guides/fit-twin.md)); it also recovers the small recovery problems of the tests that
Nelder-Mead was chosen on (thresholds and dark rate of a 48 x 36 px scene, with the sampled
and the continuous noise models, 1 or 2 seeds a trial; in trial runs, the tests keep 'nm'
there). Nelder-Mead stays for the paper's
distance (``distance='compare'``), where it beat TPE and CMA-ES: that distance has a long
curved valley between higher thresholds and a lower dark rate.
"""


def _make_sampler(sampler: str, seed: int, n_startup: int) -> Any:
    optuna = require("optuna")

    with warnings.catch_warnings():
        # Older Optuna marks multivariate TPE experimental; the option is what we want.
        warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)
        if sampler in ("tpe", "tpe+nm"):
            return optuna.samplers.TPESampler(seed=seed, multivariate=True, n_startup_trials=n_startup)
        if sampler == "random":
            return optuna.samplers.RandomSampler(seed=seed)
    raise ValueError(f"sampler must be one of {', '.join(SAMPLERS)}; got {sampler!r}")


class _BudgetSpent(Exception):
    """Raised inside the Nelder-Mead objective when the trial budget is used up."""


class _Scaler:
    """Parameter values <-> coordinates in [0, 1] over each bound (log-scaled if log)."""

    def __init__(self, keys: Sequence[str], bounds: Mapping[str, ParamBound]) -> None:
        self.keys = list(keys)
        self.bounds = [bounds[k] for k in keys]

    def to_unit(self, values: Mapping[str, float]) -> np.ndarray:
        out = []
        for k, b in zip(self.keys, self.bounds):
            v = min(max(float(values[k]), b.low), b.high)
            if b.log:
                out.append((math.log(v) - math.log(b.low)) / (math.log(b.high) - math.log(b.low)))
            else:
                out.append((v - b.low) / (b.high - b.low))
        return np.array(out)

    def from_unit(self, u: np.ndarray) -> dict[str, float]:
        out = {}
        for k, b, ui in zip(self.keys, self.bounds, np.clip(u, 0.0, 1.0)):
            if b.log:
                out[k] = float(math.exp(math.log(b.low) + ui * (math.log(b.high) - math.log(b.low))))
            else:
                out[k] = float(b.low + ui * (b.high - b.low))
            out[k] = min(max(out[k], b.low), b.high)
        return out


def fit(
    real_events: np.ndarray,
    real_meta: Mapping[str, Any],
    scenario: str | Path | dict,
    params: Sequence[str] = DEFAULT_FIT_PARAMS,
    budget: int = 40,
    runs_per_trial: int = 1,
    seed: int = 0,
    bounds: Mapping[str, Any] | None = None,
    scheduler: Any = None,
    workers: int | None = None,
    progress: bool = False,
    sampler: str = "ls",
    batch_size: int = 4,
    start: str | Mapping[str, float] | None = "scenario",
    bin_width: float = 2.0,
    nm_step: float = 0.1,
    roi: Any = None,
    mask_pixels: Sequence[tuple[int, int]] = (),
    mask_hot: bool = False,
    intervals: bool = False,
    distance: str | None = None,
    ls_step: float | None = None,
) -> FitResult:
    """Fit twin parameters to a real recording by minimising the comparison distance.

    real_events, real_meta: the recording (``EVENT_DTYPE``; meta with width, height [px] and
        duration_s [s], else last - first event time). The simulated duration is its duration.
    scenario: what to simulate (name, TOML path or dict), of the recording's sensor size.
    params: scenario keys to fit (bare PixelParams fields mean ``pixel.<name>``); default
        :data:`DEFAULT_FIT_PARAMS`.
    bounds: {name: (low, high) | 'low:high' | ParamBound} replacing :data:`FIT_BOUNDS`
        entries (required for keys without default bounds).
    budget: number of trials (each is runs_per_trial simulations). Least squares spends n + 1
        trials an iteration on n parameters and needs a handful of iterations (60 recover
        five parameters in the fit guide's benchmark); Nelder-Mead needs about 20-30 trials per
        fitted parameter. The default 40 suits up to about 4 parameters.
    runs_per_trial: seeds per trial (``seed .. seed + runs_per_trial - 1``, the same for every
        trial: common random numbers); the trial's value is the mean distance.
    sampler: see :data:`SAMPLERS` (default 'ls'). Optuna's samplers (tpe, random) ask ``batch_size`` trials
        per round (ask/tell, constant liar) and run them in parallel; the trials depend on
        seed and batch_size, not on workers or scheduler: the same arguments give the same
        trials and the same best. nm_step: the first Nelder-Mead simplex's edge, as a
        fraction of each bound's (log) width.
    start: 'scenario' (default): the scenario's own values (clipped into the bounds) are the
        starting point (Nelder-Mead's first vertex; Optuna's first trial); a dict of values; or
        None (the middle of the bounds).
    scheduler, workers: where jobs run (see :func:`make_executor`). progress: a tqdm bar on
        stderr.
    intervals: after the search, give each parameter an interval (beyond the budget; the
        probes are not in the history). Both are taken in the [0, 1] coordinates of the
        bounds (log-scaled where the bound is), so a log parameter's interval is wider above.

        With ``distance='chi2'`` (the default 'ls'): the best +- one standard error of the
        least-squares estimate, the square root of the diagonal of
        :func:`evstwin.tune.counts.chi2_covariance`'s sandwich covariance
        ``(1 + 1/K) H^-1 A^T W Sigma W A H^-1`` (A = dm/du, the slopes of the seeds' mean
        statistics over the best +- :data:`CHI2_INTERVAL_STEP` of each bound with the fit's
        seeds, 2 trials a parameter; W the chi-square's weights; Sigma the covariance of one
        seed's statistics, measured at the best from the fit's K seeds and
        :data:`INTERVAL_NOISE_SEEDS` fresh ones, one trial of 8 runs). The factor 1 + 1/K
        counts the recording's noise and the K seeds'; Sigma carries the statistics'
        correlations (they share events); the diagonal of the covariance marginalises over the
        other fitted parameters. Added in quadrature: how far the search stopped from the
        least-squares minimum, estimated by the Gauss-Newton step
        (:func:`evstwin.tune.counts.chi2_gauss_newton_step`) to the fresh seeds' minimum in
        excess of the noise that step carries. Left out: a bias of the estimator and any model
        error. Works with runs_per_trial = 1.

        With ``distance='compare'``: probe each parameter at the best +- 0.05 of its bound
        width with the same seeds (2 trials a parameter) and give it the interval over which
        a parabola through those distances rises by the best trial's standard error over its
        seeds (the mean distance's own noise): "changes the simulator cannot tell from its
        own noise", a heuristic scale rather than a standard error. Needs runs_per_trial >= 2.
        A flat or concave profile gives the whole bound.
    distance: 'compare' (compare's distance of each seed, averaged over the seeds; the
        default of every sampler but 'ls') or 'chi2' (:mod:`evstwin.tune.counts`: per-pixel
        count histograms of pixel groups set by the scenario's source light, the seeds'
        statistics averaged, a Pearson chi-square; the default, and the only one, of 'ls').
        ls_step: the Jacobian's forward-difference step of 'ls', as a share of each bound's
        (log) width (default :data:`LS_STEP`).
    """
    # The optional packages only where used: 'ls' and 'nm' need SciPy alone.
    if sampler == "cmaes":
        require("cmaes")
    elif sampler in ("tpe", "tpe+nm", "random"):
        require("optuna")
    optuna: Any = None

    t0 = time.perf_counter()
    for name, value, low in (
        ("budget", budget, 1),
        ("runs_per_trial", runs_per_trial, 1),
        ("batch_size", batch_size, 1),
        ("seed", seed, 0),
    ):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"{name} must be an integer >= {low}; got {value!r}")
    if sampler not in SAMPLERS:
        raise ValueError(f"sampler must be one of {', '.join(SAMPLERS)}; got {sampler!r}")
    if not (isinstance(nm_step, (int, float)) and 0 < nm_step <= 0.5):
        raise ValueError(f"nm_step must be in (0, 0.5]; got {nm_step!r}")
    step_ls = LS_STEP if ls_step is None else ls_step
    if isinstance(step_ls, bool) or not (isinstance(step_ls, (int, float)) and 0 < step_ls <= 0.25):
        raise ValueError(f"ls_step must be in (0, 0.25]; got {ls_step!r}")
    if distance is None:
        distance = "chi2" if sampler == "ls" else "compare"
    if distance not in DISTANCES:
        raise ValueError(f"distance must be one of {', '.join(DISTANCES)}; got {distance!r}")
    if sampler == "ls" and distance != "chi2":
        raise ValueError("sampler 'ls' fits the chi-square's residuals: it needs distance='chi2'; "
                         f"got distance={distance!r}")
    if intervals and distance == "compare" and runs_per_trial < 2:
        raise ValueError("intervals=True with distance='compare' needs runs_per_trial >= 2 (the distance's noise "
                         f"is measured over the seeds); got runs_per_trial={runs_per_trial}")
    objective = MatchObjective(
        real_events, real_meta, bin_width=bin_width, roi=roi, mask_pixels=mask_pixels, mask_hot=mask_hot
    )
    base = load(scenario)
    sensor = build(base)
    if (sensor.width, sensor.height) != (objective.sensor_width, objective.sensor_height):
        raise ValueError(
            f"scenario sensor is {sensor.width}x{sensor.height} px but the real recording is "
            f"{objective.sensor_width}x{objective.sensor_height}: set sensor.width / sensor.height"
        )
    counts: CountsObjective | None = None
    if distance == "chi2":  # checked like compare's above; its pixel groups need the scenario
        counts = CountsObjective(real_events, real_meta, base, roi=roi, mask_pixels=mask_pixels, mask_hot=mask_hot)
        objective = counts
    keys, bnds = _resolve_bounds(params, bounds)
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

    start_values: dict[str, float] | None = None
    if isinstance(start, str):
        if start != "scenario":
            raise ValueError(f"start must be 'scenario', a dict or None; got {start!r}")
        current = {k: _current_value(base, k) for k in keys}
        if all(v is not None for v in current.values()):
            start_values = {
                k: min(max(float(v), bnds[k].low), bnds[k].high)  # type: ignore[arg-type]
                for k, v in current.items()
            }
    elif start is not None:
        start_values = {canonical_key(k): float(v) for k, v in start.items()}
        bad = [k for k in start_values if k not in bnds or not bnds[k].contains(start_values[k])]
        if bad or set(start_values) != set(keys):
            raise ValueError(
                f"start must give a value inside the bounds for each of {keys}; got {dict(start)}"
            )

    sim_seeds = [seed + k for k in range(runs_per_trial)]
    ctx = _Context(scenario=base, objective=objective)
    history: list[TrialRecord] = []
    failed: list[JobFailure] = []
    executor = make_executor(scheduler, workers)
    if progress:
        print(announce(f"fit ({sampler}, up to {budget} trials x {runs_per_trial} seed(s))", budget * runs_per_trial,
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

    verbosity = None
    try:
        n_optuna = {"nm": 0, "ls": 0, "cmaes": 0, "tpe+nm": max(1, budget // 2)}.get(sampler, budget)
        if n_optuna:
            optuna = require("optuna")
            verbosity = optuna.logging.get_verbosity()
            optuna.logging.set_verbosity(optuna.logging.WARNING)  # Optuna logs every trial otherwise
            study = optuna.create_study(
                direction="minimize",
                sampler=_make_sampler(sampler, seed, max(4, min(10, n_optuna // 4))),
            )
            dists: dict[str, Any] = {
                k: optuna.distributions.FloatDistribution(bnds[k].low, bnds[k].high, log=bnds[k].log)
                for k in keys
            }
            if start_values is not None:
                with warnings.catch_warnings():
                    warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)
                    study.enqueue_trial(start_values)
            while len(history) < n_optuna:
                trials = [study.ask(dists) for _ in range(min(batch_size, n_optuna - len(history)))]
                recs = run_trials(
                    [{k: float(t.params[k]) for k in keys} for t in trials], sampler.split("+")[0]
                )
                for t, rec in zip(trials, recs):
                    if math.isfinite(rec.distance):
                        study.tell(t, rec.distance)
                    else:
                        study.tell(t, state=optuna.trial.TrialState.FAIL)
        if len(history) < budget:
            finite = [r for r in history if math.isfinite(r.distance)]
            if finite:
                x0 = scaler.to_unit(min(finite, key=lambda r: (r.distance, r.trial)).params)
            elif start_values is not None:
                x0 = scaler.to_unit(start_values)
            else:
                x0 = np.full(len(keys), 0.5)
            if sampler == "cmaes":
                _cma_es(run_trials, scaler, x0, budget - len(history), seed)
            elif sampler == "ls" and counts is not None:
                _least_squares(run_trials, residuals, counts.real_stats.size, scaler, x0, budget - len(history),
                               float(step_ls))
            else:
                _nelder_mead(run_trials, scaler, x0, budget - len(history), float(nm_step))
        description = executor.description
    finally:
        if bar is not None:
            bar.close()
        executor.close()
        if optuna is not None and verbosity is not None:
            optuna.logging.set_verbosity(verbosity)
    finite = [r for r in history if math.isfinite(r.distance)]
    if not finite:
        raise RuntimeError(f"every fit trial failed; first error: {history[0].error if history else 'none'}")
    best_rec = min(finite, key=lambda r: (r.distance, r.trial))
    found: dict[str, tuple[float, float]] = {}
    if intervals:
        # The probes run like trials but stay out of the history (they are not the search's).
        executor, bar, n_searched = make_executor(scheduler, workers), None, len(history)
        try:
            if counts is not None:
                found = _chi2_intervals(run_trials, scaler, best_rec, counts, seed_stats,
                                        [seed + runs_per_trial + k for k in range(INTERVAL_NOISE_SEEDS)])
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
        runs_per_trial=runs_per_trial,
        seed=seed,
        sim_seeds=sim_seeds,
        sampler=sampler,
        batch_size=batch_size,
        duration_s=float(objective.real_meta["duration_s"]),
        real_events=real_events,
        real_meta=dict(real_meta),
        executor=description,
        elapsed_s=time.perf_counter() - t0,
        failed=failed,
        roi=None if objective.roi is None else objective.roi.as_tuple(),
        mask=objective.mask,
        intervals=found,
        distance=distance,
    )


INTERVAL_STEP = 0.05
"""The probe step of fit's intervals with compare's distance, as a share of each parameter's
(log) bound width (the chi-square's slopes use :data:`CHI2_INTERVAL_STEP`)."""


def _curvature_intervals(
    run_trials: Callable[[list[dict[str, float]], str], list[TrialRecord]], scaler: _Scaler, best: TrialRecord
) -> dict[str, tuple[float, float]]:
    """fit(intervals=True) with compare's distance: per parameter, d(u) ~ d0 + c (u - u0)^2 / 2
    from the best and two probes (the stencil kept inside [0, 1]); the interval is
    u0 +- sqrt(2 sigma / c) with sigma the standard error of the best's mean distance over its
    seeds (the same quantity whose curvature c is)."""
    sigma = float(np.std(best.run_distances, ddof=1) / math.sqrt(len(best.run_distances)))
    u0 = scaler.to_unit(best.params)
    h = INTERVAL_STEP
    points = []
    centres = []
    for i in range(len(scaler.keys)):
        c = min(max(float(u0[i]), h), 1.0 - h)  # the stencil's centre, inside the bounds
        centres.append(c)
        for du in (-h, h):
            u = u0.copy()
            u[i] = c + du
            points.append(scaler.from_unit(u))
    # The centre itself, where it moved off the best (a best on a bound).
    extra = [i for i, c in enumerate(centres) if c != u0[i]]
    for i in extra:
        u = u0.copy()
        u[i] = centres[i]
        points.append(scaler.from_unit(u))
    recs = run_trials(points, "interval")
    out: dict[str, tuple[float, float]] = {}
    for i, key in enumerate(scaler.keys):
        d_lo, d_hi = recs[2 * i].distance, recs[2 * i + 1].distance
        d_c = recs[2 * len(scaler.keys) + extra.index(i)].distance if i in extra else best.distance
        curvature = (d_lo + d_hi - 2.0 * d_c) / (h * h)
        lo_u, hi_u = 0.0, 1.0
        if math.isfinite(curvature) and curvature > 0.0 and sigma > 0.0:
            half = math.sqrt(2.0 * sigma / curvature)
            lo_u, hi_u = max(0.0, float(u0[i]) - half), min(1.0, float(u0[i]) + half)
        lo = u0.copy()
        lo[i] = lo_u
        hi = u0.copy()
        hi[i] = hi_u
        out[key] = (scaler.from_unit(lo)[key], scaler.from_unit(hi)[key])
    return out


CHI2_INTERVAL_STEP = 0.01
"""The half-span of the secants that give the chi-square intervals' slopes dm/du, as a share of
each parameter's (log) bound width (3.3 % of a threshold with the default bounds): half the
search's :data:`LS_STEP`. Measured with bench/bench_intervals.py (20 refits, 1 seed a trial):
with LS_STEP the statistics' curvature over the wider span left the reported standard errors
1.1 and 1.7 times narrower than the refits' spread; with this step 1.1 and 1.1; with a quarter
of LS_STEP the slopes' own noise made the least-squares estimates scatter 15-17 % more."""

INTERVAL_NOISE_SEEDS = 8
"""fit(intervals=True) with the chi-square: the fresh seeds simulated at the best (beyond the fit's
K) whose statistics measure the noise; with the K, M = K + 8 single-seed vectors, so the
standard errors carry about 1 / sqrt(2 (M - 1)) <= 25 % of relative noise of their own."""


def _chi2_intervals(
    run_trials: Callable[..., list[TrialRecord]],
    scaler: _Scaler,
    best: TrialRecord,
    counts: CountsObjective,
    seed_stats: Mapping[int, np.ndarray],
    noise_seeds: Sequence[int],
) -> dict[str, tuple[float, float]]:
    """fit(intervals=True) with the chi-square: per parameter, u0 +- its standard error in the
    [0, 1] coordinates (log-scaled where the bound is), clipped to the bounds. The standard
    errors are the square roots of :func:`evstwin.tune.counts.chi2_covariance`'s diagonal:
    the slopes dm/du are secants of the mean statistics over u0 +- :data:`CHI2_INTERVAL_STEP`
    (kept inside [0, 1]) with the fit's seeds (2 trials a parameter), the noise the statistics
    of the fit's seeds at the best and of ``noise_seeds`` there (one more trial). Added in
    quadrature: how far the search stopped from the least-squares minimum, estimated from the
    Gauss-Newton step to the fresh seeds' minimum in excess of the noise that step carries. A
    parameter whose probes failed, or that the statistics cannot separate, gets its whole
    bound."""
    from .counts import chi2_covariance, chi2_gauss_newton_step

    keys = scaler.keys
    u0 = scaler.to_unit(best.params)
    h = CHI2_INTERVAL_STEP
    points, spans = [], []
    for i in range(len(keys)):
        lo, hi = u0.copy(), u0.copy()
        lo[i], hi[i] = max(0.0, float(u0[i]) - h), min(1.0, float(u0[i]) + h)
        points += [scaler.from_unit(lo), scaler.from_unit(hi)]
        spans.append(hi[i] - lo[i])
    recs = run_trials(points, "interval")
    noise = run_trials([dict(best.params)], "interval", seeds=noise_seeds)[0]
    mean_best = seed_stats[best.trial].mean(axis=0)
    slopes = np.zeros((mean_best.size, len(keys)))
    for i in range(len(keys)):
        r_lo, r_hi = recs[2 * i], recs[2 * i + 1]
        if r_lo.trial in seed_stats and r_hi.trial in seed_stats:
            slopes[:, i] = (seed_stats[r_hi.trial].mean(axis=0) - seed_stats[r_lo.trial].mean(axis=0)) / spans[i]
    sd = np.full(len(keys), math.inf)
    k = len(best.run_distances)
    if noise.trial in seed_stats:
        fresh = seed_stats[noise.trial]
        cov = chi2_covariance(counts.real_stats, mean_best, slopes, np.vstack([seed_stats[best.trial], fresh]), k)
        per_draw = np.diag(cov) / (1.0 + 1.0 / k)  # one seed's (and the recording's) share
        # The fresh seeds' own least-squares minimum, u0 + step: it differs from the best by
        # their noise and the fit's seeds' (expected variance (1/M + 1/K) per_draw, the
        # recording's cancels) and by how far the search stopped from the minimum; the excess
        # over that noise estimates the latter. (The fit's own seeds cannot: the search ends
        # where their noise happens to fit the recording best.)
        step = chi2_gauss_newton_step(counts.real_stats, fresh.mean(axis=0), slopes, fresh.shape[0])
        search = np.maximum(0.0, step * step - (1.0 / fresh.shape[0] + 1.0 / k) * per_draw)
        sd = np.sqrt(np.diag(cov) + search)
    out: dict[str, tuple[float, float]] = {}
    for i, key in enumerate(keys):
        lo, hi = u0.copy(), u0.copy()
        if math.isfinite(sd[i]):
            lo[i], hi[i] = max(0.0, float(u0[i]) - sd[i]), min(1.0, float(u0[i]) + sd[i])
        else:
            lo[i], hi[i] = 0.0, 1.0
        out[key] = (scaler.from_unit(lo)[key], scaler.from_unit(hi)[key])
    return out


NM_STALL_TRIALS_PER_PARAM = 4
"""fit's Nelder-Mead restarts when this many trials per fitted parameter (at least 10) pass
without a new best: on a noisy distance the simplex otherwise keeps shrinking around a point
of a valley, spending the budget on differences below the seed-to-seed noise."""


class _Stalled(Exception):
    """Raised inside the Nelder-Mead objective when no new best came for a while."""


def _nelder_mead(
    run_trials: Callable[[list[dict[str, float]], str], list[TrialRecord]],
    scaler: _Scaler,
    x0: np.ndarray,
    budget: int,
    step: float,
) -> None:
    """SciPy's bounded Nelder-Mead on [0, 1]^n from x0 (one trial per evaluation), restarted
    from the best point with a fresh simplex until the budget is spent: when SciPy's run
    converges, and when NM_STALL_TRIALS_PER_PARAM x n trials pass without a new best. A restart
    keeps the edge while the previous run improved the best and halves it otherwise (down to
    step / 8, then it starts again from step), and points the simplex the other way each
    time. Deterministic: no random numbers."""
    from scipy.optimize import minimize

    n = x0.size
    stall_after = max(10, NM_STALL_TRIALS_PER_PARAM * n)
    used = [0]
    cache: dict[bytes, float] = {}
    best_u, best_f = np.clip(x0, 0.0, 1.0), [math.inf]
    since_best = [0]

    def f(u: np.ndarray) -> float:
        nonlocal best_u
        u = np.clip(u, 0.0, 1.0)
        key = u.tobytes()
        if key in cache:  # scipy re-evaluates clipped points: no new simulation
            return cache[key]
        if used[0] >= budget:
            raise _BudgetSpent
        if since_best[0] >= stall_after:
            raise _Stalled
        used[0] += 1
        d = run_trials([scaler.from_unit(u)], "nm")[0].distance
        cache[key] = d if math.isfinite(d) else math.inf
        if cache[key] < best_f[0]:
            best_u, best_f[0], since_best[0] = u.copy(), cache[key], 0
        else:
            since_best[0] += 1
        return cache[key]

    edge, restart = step, 0
    while used[0] < budget:
        before = best_f[0]
        since_best[0] = 0
        # The simplex: the best point and one vertex per axis, stepped towards the middle of
        # the box on the first run, then alternately away from it and towards it.
        direction = np.where(best_u < 0.5, 1.0, -1.0) * (-1.0 if restart % 2 else 1.0)
        vertices = [np.clip(best_u + edge * direction[i] * np.eye(n)[i], 0.0, 1.0) for i in range(n)]
        for i, v in enumerate(vertices):  # a vertex clipped onto the best: step the other way
            if np.array_equal(v, best_u):
                vertices[i] = np.clip(best_u - edge * direction[i] * np.eye(n)[i], 0.0, 1.0)
        try:
            minimize(
                f,
                best_u,
                method="Nelder-Mead",
                bounds=[(0.0, 1.0)] * n,
                options={"initial_simplex": np.vstack([best_u, *vertices]), "xatol": 1e-3, "fatol": 1e-4,
                         "maxfev": 10 * budget},
            )
        except _BudgetSpent:
            return
        except _Stalled:
            pass
        restart += 1
        if not best_f[0] < before:
            edge = edge / 2.0 if edge > step / 8.0 * 1.0001 else step


LS_STEP = 0.02
"""The forward-difference step of ``sampler='ls'``'s Jacobian, as a share of each parameter's
(log) bound width: 5.5 % of a threshold, 20 % of a dark or background rate with the default
bounds. Large enough that the trials' common seeds make the difference a change of the
expected counts rather than of which events happen to fire; small enough for the
Gauss-Newton model to hold over the last steps."""

LS_FAILED_RESIDUAL = 1e3
"""The residuals given to 'ls' for a failed trial (every statistic 1000 standard deviations
off): a point the trust region steps back from."""


def _least_squares(
    run_trials: Callable[[list[dict[str, float]], str], list[TrialRecord]],
    residuals: Mapping[int, np.ndarray],
    n_stats: int,
    scaler: _Scaler,
    x0: np.ndarray,
    budget: int,
    step: float,
) -> None:
    """SciPy's bounded trust-region least squares on [0, 1]^n from x0 over the chi-square's
    residuals. Each residual evaluation is one trial; the Jacobian is one batch of n trials
    (forward differences of ``step``, away from the nearer bound), run in parallel. When
    SciPy's run ends (converged) with budget left, it restarts from the best point with half
    the step (back to ``step`` below step / 8), until the budget cannot hold a point and its
    Jacobian (up to n trials may stay unused) or a restart would evaluate nothing new.
    Deterministic: no random numbers."""
    from scipy.optimize import least_squares

    n = x0.size
    used = [0]
    cache: dict[bytes, np.ndarray] = {}
    best: list[Any] = [np.clip(x0, 0.0, 1.0), math.inf]
    failed = np.full(n_stats, LS_FAILED_RESIDUAL)

    def at(points: list[np.ndarray]) -> list[np.ndarray]:
        new: list[np.ndarray] = []
        for u in points:
            if u.tobytes() not in cache and all(u.tobytes() != v.tobytes() for v in new):
                new.append(u)
        if new:
            if used[0] + len(new) > budget:
                raise _BudgetSpent
            used[0] += len(new)
            for u, rec in zip(new, run_trials([scaler.from_unit(u) for u in new], "ls")):
                r = residuals.get(rec.trial) if math.isfinite(rec.distance) else None
                cache[u.tobytes()] = failed if r is None else r
                if math.isfinite(rec.distance) and rec.distance < best[1]:
                    best[0], best[1] = u.copy(), rec.distance
        return [cache[u.tobytes()] for u in points]

    def fun(u: np.ndarray) -> np.ndarray:
        return at([np.clip(u, 0.0, 1.0)])[0]

    def make_jac(h: float) -> Callable[[np.ndarray], np.ndarray]:
        def jac(u: np.ndarray) -> np.ndarray:
            u = np.clip(u, 0.0, 1.0)
            steps = np.where(u + h <= 1.0, h, -h)
            points = [u]
            for i in range(n):
                v = u.copy()
                v[i] += steps[i]
                points.append(v)
            r = at(points)
            return np.column_stack([(r[i + 1] - r[0]) / steps[i] for i in range(n)])

        return jac

    h = step
    while used[0] < budget:
        before = used[0]
        # SciPy's trf wants a start strictly inside the bounds.
        start = np.clip(best[0], 1e-9, 1.0 - 1e-9)
        try:
            least_squares(fun, start, jac=make_jac(h), bounds=(0.0, 1.0), method="trf", x_scale=1.0,
                          xtol=1e-4, ftol=1e-4, gtol=1e-8, max_nfev=10 * budget)
        except _BudgetSpent:
            return
        if used[0] == before and h <= step / 8.0 * 1.0001:
            return  # nothing new to evaluate at any step: the search is done
        h = h / 2.0 if h > step / 8.0 * 1.0001 else step


CMAES_SIGMA = 0.1
"""The initial step of ``sampler='cmaes'`` in the [0, 1] coordinates (a tenth of each bound's
(log) width), like Nelder-Mead's first simplex edge."""


def _cma_es(
    run_trials: Callable[[list[dict[str, float]], str], list[TrialRecord]],
    scaler: _Scaler,
    x0: np.ndarray,
    budget: int,
    seed: int,
) -> None:
    """CMA-ES (``cmaes.CMA``) on [0, 1]^n from x0, one generation a batch of trials; a failed
    trial counts as worse than every finished one. When it stops (``should_stop``) with
    budget left it restarts from the best point; a last generation the budget cannot hold
    is evaluated in part (its trials are kept, not told). Seeded: the same arguments give
    the same trials."""
    from cmaes import CMA

    n = x0.size
    bounds = np.array([[0.0, 1.0]] * n)
    used, restart = 0, 0
    best_u, best_d = np.clip(x0, 0.0, 1.0), math.inf
    while used < budget:
        opt = CMA(mean=np.clip(best_u, 1e-9, 1.0 - 1e-9), sigma=CMAES_SIGMA, bounds=bounds, seed=seed + restart)
        while used < budget and not opt.should_stop():
            asked = [opt.ask() for _ in range(opt.population_size)][: budget - used]
            recs = run_trials([scaler.from_unit(u) for u in asked], "cmaes")
            used += len(recs)
            finite = [r.distance for r in recs if math.isfinite(r.distance)]
            worst = max(finite) if finite else 1.0
            for u, r in zip(asked, recs):
                if math.isfinite(r.distance) and r.distance < best_d:
                    best_u, best_d = u.copy(), r.distance
            if len(asked) == opt.population_size:
                opt.tell([(u, r.distance if math.isfinite(r.distance) else 2.0 * abs(worst) + 1.0)
                          for u, r in zip(asked, recs)])
        restart += 1
