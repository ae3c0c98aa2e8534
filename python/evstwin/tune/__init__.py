"""Tuning: fit the twin to a real recording, sweep bias configurations, limiting magnitudes.

Three entry points, each a grid or a search of independent simulations ("jobs"):

* :func:`fit` -- search of named twin parameters within documented bounds
  (:data:`FIT_BOUNDS`) minimising a distance between a real recording and the simulated
  scenario: by default SciPy's trust-region least squares (``sampler='ls'``) from the
  scenario's values on the residuals of a low-noise chi-square of grouped per-pixel counts
  (:mod:`.counts`) and of statistics that carry timing (:mod:`.timing`: delays after a
  source's passage, intervals between a pixel's events, ON/OFF alternation), the
  ``runs_per_trial`` seeds averaged, its Jacobian one parallel batch of
  trials; or SciPy's Nelder-Mead and Optuna (seeded TPE, CMA-ES, random; ask/tell, trials
  batched to the workers) on :func:`evstwin.validation.compare`'s distance (mean over the
  seeds) or, with ``distance='chi2'``, on the chi-square; see :data:`SAMPLERS`.
  :class:`FitResult.write` writes the best scenario as a TOML that ``evstwin simulate``
  takes, the history, a convergence figure and the comparison figures of the best fit.
* :func:`sweep` -- every combination of a grid of scenario values (``--set`` keys) times K
  seeds, scored by an objective (:data:`OBJECTIVES`: ``match``, ``detect``, ``noise``; see
  :class:`MatchObjective`, :class:`DetectObjective`, :class:`NoiseObjective`), tabulated in a
  CSV written row by row as jobs finish (an interrupted sweep keeps its finished rows and
  ``resume=True`` skips them), a summary CSV and a figure.
* :func:`limiting_magnitude` -- the faintest magnitude detected against angular rate, for
  one bias configuration: a ``detect`` sweep of a linear mover over (rate, magnitude), for a
  scenario or a real :class:`Setup` (lens, preset and biases, sky, seeing, pointing mode).

Execution. Every job is the top-level function :func:`evaluate` ``(scenario, overrides, seed,
objective)`` returning a dict of numbers. Jobs run in local worker processes
(``concurrent.futures.ProcessPoolExecutor``, one engine thread each) by default, or on a Dask
distributed cluster when ``scheduler`` is an address (``tcp://host:8786``), a
``distributed.Client``, or ``"local"`` (an in-process ``LocalCluster`` on the loopback
interface). A job that raises, or whose worker dies, is resubmitted up to
:data:`JOB_RETRIES` times (Dask: ``retries=`` on submit; local pool: resubmission, with a new
pool when a worker died); a job that still fails is reported (``FitResult.failed``,
``SweepResult.failed``), never dropped silently. Results depend only on the seeds, not on
where or in which order jobs ran.

The package is laid out by the user's verbs and what they share:

* :mod:`.bounds` -- parameter names, documented search bounds, scenario keys.
* :mod:`.objectives` -- what a job measures: ``match``, ``detect``, ``noise``.
* :mod:`.counts` -- the fit's chi-square distance (pixel groups by source light, count
  histograms, Pearson terms of the seeds' mean); :mod:`.timing` -- the statistics that carry
  timing beside the counts; :mod:`.identify` -- what the statistics can and cannot separate
  (the identifiability report every least-squares fit prints).
* :mod:`.execution` -- jobs on local worker processes or a Dask cluster, retries, progress.
* :mod:`.fit`, :mod:`.sweep`, :mod:`.limits` -- the three verbs; each returns data and
  writes its tables. The fit's parts: :mod:`.options` (:class:`FitOptions`), :mod:`.search`
  (the searches and why they stop), :mod:`.intervals`, :mod:`.result` (:class:`FitResult`).
* :mod:`.figures` -- the figures of those results (matplotlib, the ``plot`` extra); no
  compute module imports it.
"""

from __future__ import annotations

from .bounds import DEFAULT_FIT_PARAMS, FIT_BOUNDS, ParamBound, canonical_key, parse_bound
from .counts import (
    CHI2_FORMULA,
    CountsObjective,
    chi2_distance,
    count_statistics,
    pixel_groups,
    source_flux_map,
)
from .execution import JOB_RETRIES, DaskExecutor, JobFailure, LocalExecutor, evaluate, make_executor
from .figures import (
    draw_fit,
    draw_limiting_magnitude,
    draw_sweep,
    plot_convergence,
    plot_limiting_magnitude,
    plot_sweep,
)
from .fit import fit
from .limits import (
    DEFAULT_MAGNITUDES,
    DEFAULT_RATES_ARCSEC_S,
    POINTINGS,
    SIDEREAL_RATE_ARCSEC_S,
    LimitingMagnitudeResult,
    PointingDetectObjective,
    Setup,
    limiting_magnitude,
    limiting_magnitude_scenario,
    parse_float_list,
    static_detect_metrics,
)
from .objectives import (
    OBJECTIVES,
    DetectObjective,
    MatchObjective,
    NoiseObjective,
    Objective,
    detect_metrics,
    make_objective,
)
from .options import DISTANCES, SAMPLERS, STATISTICS, FitOptions
from .result import FitResult, TrialRecord
from .sweep import FitMatchObjective, SweepResult, parse_grid, sweep

__all__ = [
    "CHI2_FORMULA",
    "CountsObjective",
    "DISTANCES",
    "DEFAULT_FIT_PARAMS",
    "DEFAULT_MAGNITUDES",
    "DEFAULT_RATES_ARCSEC_S",
    "FIT_BOUNDS",
    "DaskExecutor",
    "DetectObjective",
    "FitMatchObjective",
    "FitOptions",
    "FitResult",
    "JOB_RETRIES",
    "JobFailure",
    "LimitingMagnitudeResult",
    "POINTINGS",
    "PointingDetectObjective",
    "SIDEREAL_RATE_ARCSEC_S",
    "Setup",
    "static_detect_metrics",
    "LocalExecutor",
    "MatchObjective",
    "NoiseObjective",
    "OBJECTIVES",
    "Objective",
    "ParamBound",
    "SAMPLERS",
    "STATISTICS",
    "SweepResult",
    "TrialRecord",
    "canonical_key",
    "chi2_distance",
    "count_statistics",
    "detect_metrics",
    "draw_fit",
    "draw_limiting_magnitude",
    "draw_sweep",
    "evaluate",
    "fit",
    "limiting_magnitude",
    "limiting_magnitude_scenario",
    "make_executor",
    "make_objective",
    "parse_bound",
    "parse_float_list",
    "parse_grid",
    "pixel_groups",
    "plot_convergence",
    "plot_limiting_magnitude",
    "plot_sweep",
    "source_flux_map",
    "sweep",
]
