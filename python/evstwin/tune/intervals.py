"""The calibrated intervals of :func:`evstwin.tune.fit` (``FitOptions.intervals``): probes
around the best point, beyond the search's budget."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from .counts import CountsObjective
from .result import TrialRecord
from .search import RunTrials, _Scaler

INTERVAL_STEP = 0.05
"""The probe step of fit's intervals with compare's distance, as a share of each parameter's
(log) bound width (the chi-square's slopes use :data:`CHI2_INTERVAL_STEP`)."""


def _curvature_intervals(
    run_trials: RunTrials, scaler: _Scaler, best: TrialRecord
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
