"""The searches of :func:`evstwin.tune.fit`: Nelder-Mead, least squares, CMA-ES and Optuna's
samplers over the fitted parameters' [0, 1] coordinates, each saying why it stopped."""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._extras import require
from .bounds import ParamBound
from .options import SAMPLERS
from .result import TrialRecord

RunTrials = Callable[[list[dict[str, float]], str], list[TrialRecord]]
"""Runs a batch of trials (parameter values, the search's phase name) -> their records, in order."""

STOP_REASONS = ("budget", "converged", "stalled")
"""Why a search ended: ``budget`` (the trials are spent, or the rest cannot hold another
step), ``converged`` (the search's own tolerance met and a restart finds nothing new to
evaluate), ``stalled`` (the budget ran out while the last restarts found no better point: the
search was turning in the distance's noise)."""


@dataclass(frozen=True)
class Stop:
    """Why a search ended (one of :data:`STOP_REASONS`) and the trials it used, in words."""

    reason: str
    detail: str
    trials_used: int = 0
    jacobian: np.ndarray | None = field(default=None, compare=False, repr=False)
    """'ls' only: the residuals' Jacobian d r / d u (S, n) at the point nearest the best
    where one was taken (the identifiability report's; :mod:`evstwin.tune.identify`)."""
    jacobian_at: np.ndarray | None = field(default=None, compare=False, repr=False)
    """The [0, 1] coordinates of the point the Jacobian was taken at."""


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


NM_STALL_TRIALS_PER_PARAM = 4
"""fit's Nelder-Mead restarts when this many trials per fitted parameter (at least 10) pass
without a new best: on a noisy distance the simplex otherwise keeps shrinking around a point
of a valley, spending the budget on differences below the seed-to-seed noise."""


class _Stalled(Exception):
    """Raised inside the Nelder-Mead objective when no new best came for a while."""


def _nelder_mead(
    run_trials: RunTrials,
    scaler: _Scaler,
    x0: np.ndarray,
    budget: int,
    step: float,
) -> Stop:
    """SciPy's bounded Nelder-Mead on [0, 1]^n from x0 (one trial per evaluation), restarted
    from the best point with a fresh simplex until the budget is spent: when SciPy's run
    converges, and when NM_STALL_TRIALS_PER_PARAM x n trials pass without a new best. A restart
    keeps the edge while the previous run improved the best and halves it otherwise (down to
    step / 8, then it starts again from step), and points the simplex the other way each
    time. Deterministic: no random numbers. Returns why it stopped: always the budget, as
    'stalled' when the last restart found no better point."""
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
            break
        except _Stalled:
            pass
        restart += 1
        if not best_f[0] < before:
            edge = edge / 2.0 if edge > step / 8.0 * 1.0001 else step
    improved = best_f[0] < before
    if restart and not improved:
        return Stop("stalled", f"budget spent ({used[0]} trials); the last restart found no better point", used[0])
    return Stop("budget", f"budget spent ({used[0]} trials), still improving", used[0])


LS_FAILED_RESIDUAL = 1e3
"""The residuals given to 'ls' for a failed trial (every statistic 1000 standard deviations
off): a point the trust region steps back from."""


def _least_squares(
    run_trials: RunTrials,
    residuals: Mapping[int, np.ndarray],
    n_stats: int,
    scaler: _Scaler,
    x0: np.ndarray,
    budget: int,
    step: float,
) -> Stop:
    """SciPy's bounded trust-region least squares on [0, 1]^n from x0 over the chi-square's
    residuals. Each residual evaluation is one trial; the Jacobian is one batch of n trials
    (forward differences of ``step``, away from the nearer bound), run in parallel. When
    SciPy's run ends (converged) with budget left, it restarts from the best point with half
    the step (back to ``step`` below step / 8), until the budget cannot hold a point and its
    Jacobian (up to n trials may stay unused) or a restart would evaluate nothing new.
    Deterministic: no random numbers. Returns why it stopped (:class:`Stop`: 'converged'
    when a restart has nothing new to evaluate, 'stalled' when the budget ran out after a
    restart that found no better point, else 'budget'), with the last Jacobian taken at the
    best point (or the nearest to it)."""
    from scipy.optimize import least_squares

    n = x0.size
    used = [0]
    cache: dict[bytes, np.ndarray] = {}
    best: list[Any] = [np.clip(x0, 0.0, 1.0), math.inf]
    failed = np.full(n_stats, LS_FAILED_RESIDUAL)
    jacobians: dict[bytes, np.ndarray] = {}  # point -> the Jacobian taken there (the report's)

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
            j = np.column_stack([(r[i + 1] - r[0]) / steps[i] for i in range(n)])
            jacobians[u.tobytes()] = j
            return j

        return jac

    def stop(reason: str, detail: str) -> Stop:
        at_best = jacobians.get(np.clip(best[0], 0.0, 1.0).tobytes())
        if at_best is not None:
            where, jac = np.clip(best[0], 0.0, 1.0), at_best
        elif jacobians:  # the Jacobian taken nearest the best point
            key = min(jacobians, key=lambda k: float(np.sum((np.frombuffer(k) - best[0]) ** 2)))
            where, jac = np.frombuffer(key).copy(), jacobians[key]
        else:
            where, jac = None, None
        return Stop(reason, detail, used[0], jac, where)

    h = step
    runs, improved = 0, True
    while used[0] < budget:
        before, best_before = used[0], best[1]
        # SciPy's trf wants a start strictly inside the bounds.
        start = np.clip(best[0], 1e-9, 1.0 - 1e-9)
        try:
            least_squares(fun, start, jac=make_jac(h), bounds=(0.0, 1.0), method="trf", x_scale=1.0,
                          xtol=1e-4, ftol=1e-4, gtol=1e-8, max_nfev=10 * budget)
        except _BudgetSpent:
            left = budget - used[0]
            if runs and not improved and not best[1] < best_before:
                return stop("stalled", f"{used[0]} of {budget} trials; the last restarts found no better point "
                                       f"({left} trials left, fewer than a step's {n + 1})")
            return stop("budget", f"{used[0]} of {budget} trials: {left} left, fewer than the next step and its "
                                  f"Jacobian need (up to {n + 1})" if left else f"all {budget} trials used")
        runs += 1
        improved = best[1] < best_before
        if used[0] == before and h <= step / 8.0 * 1.0001:
            # nothing new to evaluate at any step: the search is done
            return stop("converged", f"{used[0]} of {budget} trials: the least squares converged and its restarts "
                                     "find nothing new to evaluate")
        h = h / 2.0 if h > step / 8.0 * 1.0001 else step
    return stop("budget", f"all {budget} trials used")


CMAES_SIGMA = 0.1
"""The initial step of ``sampler='cmaes'`` in the [0, 1] coordinates (a tenth of each bound's
(log) width), like Nelder-Mead's first simplex edge."""


def _cma_es(
    run_trials: RunTrials,
    scaler: _Scaler,
    x0: np.ndarray,
    budget: int,
    seed: int,
) -> Stop:
    """CMA-ES (``cmaes.CMA``) on [0, 1]^n from x0, one generation a batch of trials; a failed
    trial counts as worse than every finished one. When it stops (``should_stop``) with
    budget left it restarts from the best point; a last generation the budget cannot hold
    is evaluated in part (its trials are kept, not told). Seeded: the same arguments give
    the same trials. Returns why it stopped: the budget (CMA-ES restarts until it is spent)."""
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
    return Stop("budget", f"all {budget} trials used", used)


def optuna_search(
    run_trials: RunTrials,
    keys: Sequence[str],
    bounds: Mapping[str, ParamBound],
    sampler: str,
    seed: int,
    n_trials: int,
    batch_size: int,
    start_values: Mapping[str, float] | None,
) -> Stop:
    """Optuna's seeded sampler (``tpe`` / ``tpe+nm``: multivariate TPE; ``random``) for
    n_trials trials, asked ``batch_size`` at a time (ask/tell) and run in parallel; the first
    trial is ``start_values`` when given. Its log output is quieted while it runs."""
    optuna = require("optuna")
    verbosity = optuna.logging.get_verbosity()
    optuna.logging.set_verbosity(optuna.logging.WARNING)  # Optuna logs every trial otherwise
    try:
        study = optuna.create_study(
            direction="minimize", sampler=_make_sampler(sampler, seed, max(4, min(10, n_trials // 4)))
        )
        dists: dict[str, Any] = {
            k: optuna.distributions.FloatDistribution(bounds[k].low, bounds[k].high, log=bounds[k].log) for k in keys
        }
        if start_values is not None:
            with warnings.catch_warnings():
                warnings.filterwarnings("ignore", category=optuna.exceptions.ExperimentalWarning)
                study.enqueue_trial(dict(start_values))
        used = 0
        while used < n_trials:
            trials = [study.ask(dists) for _ in range(min(batch_size, n_trials - used))]
            recs = run_trials([{k: float(t.params[k]) for k in keys} for t in trials], sampler.split("+")[0])
            used += len(recs)
            for t, rec in zip(trials, recs):
                if math.isfinite(rec.distance):
                    study.tell(t, rec.distance)
                else:
                    study.tell(t, state=optuna.trial.TrialState.FAIL)
    finally:
        optuna.logging.set_verbosity(verbosity)
    return Stop("budget", f"all {n_trials} trials used", used)
