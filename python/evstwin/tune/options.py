"""The options of :func:`evstwin.tune.fit`: one frozen :class:`FitOptions`, checked when made."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from .bounds import DEFAULT_FIT_PARAMS, FIT_BOUNDS, ParamBound, canonical_key, parse_bound

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


STATISTICS = ("timing", "counts")
"""The statistics of the chi-square distance (``FitOptions.statistics``): ``timing`` (default),
the per-pixel counts of :mod:`evstwin.tune.counts` and the timing statistics of
:mod:`evstwin.tune.timing` beside them; ``counts``, the counts alone (the distance before
issue 34). The default because it recovers what the counts cannot: on issue 34's default
command (``mcreynolds``, 1 s, hidden theta_on 0.2, theta_off 0.25, dark rate 8000 e-/s, the
then seven default parameters, budget 60) the counts alone end at theta_on -14 % and the dark rate
x1.36 with r(theta_on, dark rate) = -0.98; with the timing statistics at -1.2 % and x1.02,
r = -0.85 (the fit guide's "Statistics that carry timing")."""

LS_STEP = 0.02
"""The forward-difference step of ``sampler='ls'``'s Jacobian, as a share of each parameter's
(log) bound width: 5.5 % of a threshold, 20 % of a dark or background rate with the default
bounds. Large enough that the trials' common seeds make the difference a change of the
expected counts rather than of which events happen to fire; small enough for the
Gauss-Newton model to hold over the last steps."""

CORRELATION_WARN = 0.9
"""The identifiability report warns of two parameters whose estimates correlate beyond this
(|r| > 0.9): the data barely tell them apart (:mod:`evstwin.tune.identify`)."""


def _fail(name: str, must: str, value: Any) -> ValueError:
    return ValueError(f"FitOptions.{name} must be {must}; got {value!r}")


@dataclass(frozen=True)
class FitOptions:
    """What a fit searches and how: everything that decides its trials and result (where the
    trials run -- ``scheduler``, ``workers``, ``progress`` -- is :func:`fit`'s own
    arguments, which do not change the result). Checked when made: a bad value raises
    ValueError in one line naming the field and the value.

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
    seed: the samplers' seed and the first simulation seed.
    sampler: see :data:`SAMPLERS` (default 'ls'). Optuna's samplers (tpe, random) ask
        ``batch_size`` trials per round (ask/tell, constant liar) and run them in parallel;
        the trials depend on seed and batch_size, not on workers or scheduler. nm_step: the
        first Nelder-Mead simplex's edge, as a fraction of each bound's (log) width.
    start: 'scenario' (default): the scenario's own values (clipped into the bounds) are the
        starting point (Nelder-Mead's first vertex; Optuna's first trial); a dict of values; or
        None (the middle of the bounds).
    bin_width: compare's count-histogram bin width (``distance='compare'``).
    roi, mask_pixels, mask_hot: the region compared (see
        :class:`evstwin.tune.MatchObjective`).
    intervals: after the search, the calibrated intervals of :mod:`evstwin.tune.intervals`
        (beyond the budget: 2 trials a parameter and 8 more runs with the chi-square). Without
        it, the least squares still gives each parameter the interval of its identifiability
        report (:mod:`evstwin.tune.identify`, from the search's own Jacobian, at no cost).
    distance: 'compare' or 'chi2' (None: 'chi2' for 'ls', the only one it takes, else
        'compare'); see :data:`DISTANCES`.
    statistics: the chi-square's statistics, :data:`STATISTICS` (default 'timing': counts and
        timing; 'counts': the counts alone).
    ls_step: the Jacobian's forward-difference step of 'ls', as a share of each bound's (log)
        width (default :data:`LS_STEP`).
    """

    params: Sequence[str] = DEFAULT_FIT_PARAMS
    budget: int = 40
    runs_per_trial: int = 1
    seed: int = 0
    bounds: Mapping[str, Any] | None = None
    sampler: str = "ls"
    batch_size: int = 4
    start: str | Mapping[str, float] | None = "scenario"
    bin_width: float = 2.0
    nm_step: float = 0.1
    roi: Any = None
    mask_pixels: Sequence[tuple[int, int]] = ()
    mask_hot: bool = False
    intervals: bool = False
    distance: str | None = None
    statistics: str = "timing"
    ls_step: float = LS_STEP
    keys: tuple[str, ...] = field(init=False, repr=False, compare=False)
    """The canonical scenario keys of ``params``, in order."""
    resolved_bounds: dict[str, ParamBound] = field(init=False, repr=False, compare=False)
    """Each fitted key's bound (the user's, else :data:`FIT_BOUNDS`')."""

    def __post_init__(self) -> None:
        if isinstance(self.params, str):
            object.__setattr__(self, "params", tuple(p for p in self.params.split(",") if p.strip()))
        else:
            object.__setattr__(self, "params", tuple(self.params))
        for name, low in (("budget", 1), ("runs_per_trial", 1), ("batch_size", 1), ("seed", 0)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise _fail(name, f"an integer >= {low}", value)
        if self.sampler not in SAMPLERS:
            raise _fail("sampler", f"one of {', '.join(SAMPLERS)}", self.sampler)
        for name, top in (("nm_step", 0.5), ("ls_step", 0.25)):
            value = getattr(self, name)
            if isinstance(value, bool) or not (isinstance(value, (int, float)) and 0 < value <= top):
                raise _fail(name, f"in (0, {top:g}]", value)
        bw = self.bin_width
        if isinstance(bw, bool) or not (isinstance(bw, (int, float)) and math.isfinite(bw) and bw > 0):
            raise _fail("bin_width", "a finite number > 0", bw)
        for name in ("mask_hot", "intervals"):
            if not isinstance(getattr(self, name), bool):
                raise _fail(name, "True or False", getattr(self, name))
        if self.statistics not in STATISTICS:
            raise _fail("statistics", f"one of {', '.join(STATISTICS)}", self.statistics)
        distance = self.distance
        if distance is None:
            distance = "chi2" if self.sampler == "ls" else "compare"
            object.__setattr__(self, "distance", distance)
        if distance not in DISTANCES:
            raise _fail("distance", f"one of {', '.join(DISTANCES)}", distance)
        if self.sampler == "ls" and distance != "chi2":
            raise ValueError("FitOptions.sampler 'ls' fits the chi-square's residuals: it needs distance='chi2'; "
                             f"got distance={distance!r}")
        if self.intervals and distance == "compare" and self.runs_per_trial < 2:
            raise ValueError("FitOptions.intervals=True with distance='compare' needs runs_per_trial >= 2 (the "
                             f"distance's noise is measured over the seeds); got runs_per_trial={self.runs_per_trial}")
        if isinstance(self.start, str) and self.start != "scenario":
            raise _fail("start", "'scenario', a dict or None", self.start)
        keys, bounds = resolve_bounds(self.params, self.bounds)
        object.__setattr__(self, "keys", tuple(keys))
        object.__setattr__(self, "resolved_bounds", bounds)
        if self.start is not None and not isinstance(self.start, str):
            try:
                values = {canonical_key(k): float(v) for k, v in self.start.items()}
            except (TypeError, ValueError, AttributeError):
                raise _fail("start", "'scenario', a dict of numbers or None", self.start) from None
            bad = [k for k in values if k not in bounds or not bounds[k].contains(values[k])]
            if bad or set(values) != set(keys):
                raise ValueError(f"FitOptions.start must give a value inside the bounds for each of {list(keys)}; "
                                 f"got {dict(self.start)}")

    @property
    def sim_seeds(self) -> list[int]:
        """The simulation seeds of every trial: seed .. seed + runs_per_trial - 1."""
        return [self.seed + k for k in range(self.runs_per_trial)]


def resolve_bounds(
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
