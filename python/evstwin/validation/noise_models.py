"""The statistics of a background calibration (:mod:`evstwin.validation.noise`): the
Poisson-log-normal mixture of per-pixel counts (its pmf, tail and maximum-likelihood fit), the
hot-pixel test against it, and the random-telegraph fit of one hot pixel's events."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

ALPHA = 1e-6
"""Default false-alarm probability per pixel of the hot-pixel test (split over the two
polarities)."""
SIGMA_MAX = 3.0
"""The engine's largest ``background_rate_sigma`` and ``hot_pixel_rate_sigma``."""
_Z = np.linspace(-10.0, 10.0, 1001)  # standard-normal grid of the log-normal factor
_LOG_W = -0.5 * _Z**2 - 0.5 * math.log(2 * math.pi) + math.log(_Z[1] - _Z[0])


# --- Poisson-log-normal mixture --------------------------------------------------------------


def _log_lambda(mean: float, sigma: float) -> np.ndarray:
    """ln of the Poisson mean on the grid of the log-normal factor (mean 1)."""
    return math.log(mean) + sigma * _Z - 0.5 * sigma**2


def pln_logpmf(k: np.ndarray, mean: float, sigma: float) -> np.ndarray:
    """ln P(N = k) of a Poisson count whose mean is ``mean`` times a log-normal factor of
    mean 1 and log-sigma ``sigma`` (quadrature on a standard-normal grid)."""
    from scipy.special import gammaln, logsumexp

    k = np.asarray(k, dtype=np.float64)[:, None]
    ll = _log_lambda(mean, sigma)[None, :]
    terms = k * ll - np.exp(ll) - gammaln(k + 1) + _LOG_W[None, :]
    return np.asarray(logsumexp(terms, axis=1))


def pln_logsf(k: np.ndarray, mean: float, sigma: float) -> np.ndarray:
    """ln P(N >= k) of the same mixture (0 for k <= 0)."""
    from scipy.special import gammainc, logsumexp

    k = np.asarray(k, dtype=np.float64)
    out = np.zeros(k.shape)
    pos = k > 0
    if pos.any():
        lam = np.exp(_log_lambda(mean, sigma))[None, :]
        with np.errstate(divide="ignore"):
            p = np.log(gammainc(k[pos][:, None], lam))  # P(Poisson(lam) >= k), regularised
        out[pos] = logsumexp(p + _LOG_W[None, :], axis=1)
    return out


def fit_poisson_lognormal(counts: np.ndarray) -> tuple[float, float | None, float | None]:
    """(sigma, its standard error, the moment estimate) of per-pixel counts: the maximum-likelihood
    fit of the Poisson-log-normal mixture, its mean and sigma jointly (callers report the sample
    mean as the rate: it is the mixture's mean, unbiased); the standard error from the inverse
    Hessian of the log-likelihood, None where it is not positive definite (sigma at 0)."""
    from scipy.optimize import minimize

    counts = np.asarray(counts, dtype=np.int64)
    mean = float(counts.mean())
    var = float(counts.var(ddof=1)) if counts.size > 1 else 0.0
    moment = math.sqrt(math.log1p((var - mean) / mean**2)) if mean > 0 and var > mean else None
    if mean == 0:
        return 0.0, None, moment
    values, hist = np.unique(counts, return_counts=True)

    def nll(theta: np.ndarray) -> float:
        return float(-np.dot(hist, pln_logpmf(values, math.exp(theta[0]), abs(theta[1]))))

    start = np.array([math.log(mean), min(moment if moment is not None else 0.5, SIGMA_MAX)])
    best = minimize(nll, start, method="Nelder-Mead", options={"xatol": 1e-4, "fatol": 1e-6, "maxiter": 2000})
    theta = best.x
    sigma = abs(float(theta[1]))
    se = _hessian_se(nll, np.array([theta[0], sigma]))
    return sigma, se, moment


def _hessian_se(f: Any, x: np.ndarray, h: float = 1e-3) -> float | None:
    """Standard error of x[1] from the inverse numerical Hessian of the negative log-likelihood."""
    n = x.size
    hess = np.zeros((n, n))
    f0 = f(x)
    for i in range(n):
        for j in range(i, n):
            ei, ej = np.eye(n)[i] * h, np.eye(n)[j] * h
            if i == j:
                hess[i, i] = (f(x + ei) - 2 * f0 + f(x - ei)) / h**2
            else:
                hess[i, j] = hess[j, i] = (f(x + ei + ej) - f(x + ei - ej) - f(x - ei + ej) + f(x - ei - ej)) / (4 * h**2)
    try:
        cov = np.linalg.inv(hess)
    except np.linalg.LinAlgError:
        return None
    v = float(cov[1, 1])
    return math.sqrt(v) if v > 0 and np.all(np.linalg.eigvalsh(hess) > 0) else None



def find_hot_pixels(on: np.ndarray, off: np.ndarray, alpha: float = ALPHA, max_rounds: int = 50) -> np.ndarray:
    """Boolean mask of the pixels whose ON or OFF count has a tail probability below
    ``alpha / 2`` under the Poisson-log-normal fitted to the others (refitted until no pixel
    is added)."""
    hot = np.zeros(on.shape, bool)
    for _ in range(max_rounds):
        flag = np.zeros(on.shape, bool)
        for counts in (on, off):
            rest = counts[~hot]
            if rest.size == 0 or rest.sum() == 0:
                continue
            sigma, _, _ = fit_poisson_lognormal(rest)
            values, inverse = np.unique(counts, return_inverse=True)
            logsf = pln_logsf(values, float(rest.mean()), sigma)
            flag |= (logsf < math.log(alpha / 2))[inverse.reshape(-1)]
        new = hot | flag
        if new.sum() == hot.sum():
            break
        hot = new
        if hot.all():
            break
    return hot


# --- telegraph of one hot pixel ----------------------------------------------------------------


def telegraph(t_us: np.ndarray, p: np.ndarray, duration_s: float, dead_s: float) -> dict[str, float]:
    """The random-telegraph fit of one hot pixel's events (times [us], sorted; polarities)."""
    n_events = t_us.size
    alternation = float(np.mean(p[1:] != p[:-1])) if n_events > 1 else 0.0
    if n_events < 3:
        rho = n_events / duration_s
        return {"alternation": alternation, "active_rate_hz": rho, "duty": 1.0, "burst_s": duration_s,
                "gaps": 0, "gap_s": duration_s, "min_interval_s": duration_s}
    dt = np.diff(t_us).astype(np.float64) * 1e-6
    d_min = float(dt.min())
    dead = min(dead_s, d_min)
    # The gap: start from the median (robust to the quiet gaps), then take the mean of the
    # intervals below the gap until it settles (the same for exponential intervals; longer
    # where a real pixel's within-burst intervals have a heavier tail than an exponential).
    log_n = math.log(2 * dt.size)
    gap = dead + max(float(np.median(dt)) - dead, 1e-6) / math.log(2) * log_n
    for _ in range(100):
        new = dead + max(float(dt[dt <= gap].mean()) - dead, 1e-6) * log_n
        if abs(new - gap) <= 1e-9 * gap:
            break
        gap = new
    within = dt[dt <= gap]
    rho = within.size / float(within.sum()) if within.size and within.sum() > 0 else n_events / duration_s
    duty = min(1.0, n_events / (rho * duration_s))
    excess = dt[dt > gap] - gap
    if excess.size == 0 or duty >= 1.0:
        burst = duration_s
        duty = 1.0
    else:
        q = float(excess.mean())
        burst = q * duty / (1 - duty)
    return {"alternation": alternation, "active_rate_hz": rho, "duty": duty, "burst_s": burst,
            "gaps": int(excess.size), "gap_s": gap, "min_interval_s": d_min}


def engine_rate(rho: float, dead_s: float) -> tuple[float, bool]:
    """r with r / (1 + r d) = rho, and whether it had to be capped (rho d >= 1: the dead time
    is longer than the pixel's intervals)."""
    from ..scenario import MAX_HOT_PIXEL_RATE_HZ

    if rho * dead_s >= 1 - rho / MAX_HOT_PIXEL_RATE_HZ:
        return MAX_HOT_PIXEL_RATE_HZ, True
    return min(MAX_HOT_PIXEL_RATE_HZ, rho / (1 - rho * dead_s)), False
