"""The fit's chi-square distance: grouped per-pixel count histograms, seeds averaged, Pearson terms.

``compare``'s distance (W1 of the per-pixel count distributions, rate and polarity terms) is
the paper's figure of merit, but as a fitting objective it mixes everything into one number a
trial: on a sparse scene most pixels hold 0-1 noise events, the few thousand pixels a source
lights are lost among them, and each seed's distance is taken apart before averaging. The
distance here (``fit(..., distance="chi2")``, and the residuals of ``sampler="ls"``) keeps
the parameters apart:

* pixels are put in **groups by the light the scenario's sources bring them** (the largest
  photon rate any source gives the pixel over the recording, as a share of the brightest
  pixel's; :data:`GROUP_LEVELS`), computed once from the scenario, so the partition depends
  on neither the fitted values nor any recording's noise. The quiet group sees only the
  background (its ON and OFF rates fix the background-activity rates), the lit groups the
  sources (their counts against the light level fix the thresholds and, through the
  contrast ln(1 + I_source / I_dark), the dark rate);
* per polarity and group: the histogram of per-pixel counts on bins that widen
  geometrically (:func:`count_bin_edges`) and the group's event total;
* the K seeds of a trial are **averaged statistic by statistic** (m = mean over seeds) and
  compared with the real value r by a two-sample Pearson term (r - m)^2 / (m + r / K + 1):
  for Poisson counts of mean lambda, var(r - m) = lambda (1 + 1/K) and m + r/K estimates it
  (the +1 keeps rare bins from dominating). The distance is the sum over the S statistics
  divided by S: about 1 or less for a simulation of the same parameters (binomial bins are
  less variable than Poisson ones), and growing with the squared standardised differences.

Measured on the full-size recovery benchmark (``bench/bench_recovery.py --profile``: 346 x
260 px, 0.5 s, S of 60-110 statistics), it is 0.27-0.68 at the hidden values with a seed-to-seed
standard deviation of about 30 % of that (the statistics share events, so it varies more than
a chi-square of S independent terms), and it sees a 10 % change of the weakly constrained threshold (theta_off there)
better than ``compare``'s distance does with the same seeds (2.7-6.3 against 0.2-4.4 times
the change's own standard deviation); both see the strongly constrained one clearly. Its main
use is as residuals: S standardised differences that a Gauss-Newton search
(``sampler='ls'``) reads parameter by parameter; at the best, the same weighted least squares
gives the fit's standard errors (:func:`chi2_covariance`, ``fit(intervals=True)``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..targets import psf_groups
from .objectives import MatchObjective

GROUP_LEVELS: tuple[float, ...] = (1e-3, 1e-2, 0.1, 0.3)
"""Shares of the brightest pixel's source light that bound the pixel groups: group 0 (quiet)
gets less than 1e-3 of it, group 1 1e-3 to 1e-2, ..., the last more than 0.3. Decades reach
the PSF's wings (where I_source ~ I_dark and the count's dependence on the dark rate shows);
the top split keeps the track's core apart from its edge."""

FLUX_MAP_SHIFT_PX = 0.25
"""The source-light map samples each source at steps of at most this many pixels of travel,
so that no pixel a source crosses is missed (the simulation's own max_shift_px default)."""

CHI2_FORMULA = (
    "(1/S) sum_j (r_j - m_j)^2 / (m_j + r_j / K + 1) over S statistics: per polarity and per pixel group "
    "(by source light), the histogram of per-pixel counts (geometric bins) and the group's event total; "
    "r = the real recording's, m = the mean over the trial's K seeds"
)
"""The fit's chi-square distance in one line (written into fit.json)."""


def source_flux_map(scene: Any) -> np.ndarray:
    """(height, width) [photons/s]: per pixel, the largest photon rate any one of the
    scene's targets brings it over [0, duration] (the uniform background excluded). The
    targets are sampled at steps of at most :data:`FLUX_MAP_SHIFT_PX` of travel."""
    return source_light_and_time(scene)[0]


def source_light_and_time(scene: Any) -> tuple[np.ndarray, np.ndarray]:
    """(flux, passage), each (height, width): :func:`source_flux_map` and the time [s] of
    that largest rate (the source's passage over the pixel; the earliest sample of a tie, to
    the sampling of :data:`FLUX_MAP_SHIFT_PX` of travel; nan where no source light arrives)."""
    from .. import psf as psf_mod

    w, h = int(scene.width), int(scene.height)
    flat = np.zeros(w * h)
    when = np.full(w * h, math.nan)
    duration_s = float(scene.duration_s)
    targets = list(scene.targets)
    if not targets:
        return flat.reshape(h, w), when.reshape(h, w)
    speed = max(float(t.max_speed_px_s(0.0, duration_s)) for t in targets)
    n = max(2, math.ceil(duration_s * speed / FLUX_MAP_SHIFT_PX) + 1)
    times = np.linspace(0.0, duration_s, n)
    for a in range(0, n, 512):
        t = times[a : a + 512]
        # Each target through the PSF it is rendered with (a defocused ghost through its own).
        for shape, cols in psf_groups(targets, scene.psf):
            if not cols.size:
                continue
            xs, ys, fs = [], [], []
            for target in (targets[j] for j in cols):
                x, y = target.position_px(t)
                xs.append(np.broadcast_to(np.asarray(x, np.float64), t.shape))
                ys.append(np.broadcast_to(np.asarray(y, np.float64), t.shape))
                fs.append(np.broadcast_to(np.asarray(target.flux_ph_s(t), np.float64), t.shape))
            x_all = np.ascontiguousarray(np.concatenate(xs))
            y_all = np.ascontiguousarray(np.concatenate(ys))
            f_all = np.ascontiguousarray(np.concatenate(fs))
            # Each source-time its own block of flat indices: a shape may give one pixel in
            # several chunks (a core and its halo), added up before the largest is taken.
            area = (2 * shape.half_width_px + 1) ** 2
            step = max(1, 4_000_000 // area)
            for s0 in range(0, x_all.size, step):
                sl = slice(s0, s0 + step)
                offset = np.arange(x_all[sl].size, dtype=np.int64) * (w * h)
                parts = psf_mod.contributions(w, h, x_all[sl], y_all[sl], f_all[sl], shape, offset=offset)
                if not parts:
                    continue
                keys, inverse = np.unique(np.concatenate([p[0] for p in parts]), return_inverse=True)
                summed = np.bincount(inverse.reshape(-1), weights=np.concatenate([p[1] for p in parts]))
                pix, sample = keys % (w * h), s0 + keys // (w * h)
                # Each pixel's largest in this block (the earliest sample of a tie), then
                # against the largest so far.
                order = np.lexsort((sample, -summed, pix))
                first = np.r_[True, pix[order][1:] != pix[order][:-1]]
                top = order[first]
                better = summed[top] > flat[pix[top]]
                flat[pix[top][better]] = summed[top][better]
                when[pix[top][better]] = t[sample[top][better] % t.size]
    return flat.reshape(h, w), when.reshape(h, w)


def pixel_groups(flux_map: np.ndarray, mask: np.ndarray | None = None,
                 levels: Sequence[float] = GROUP_LEVELS) -> np.ndarray:
    """(height, width) int: each pixel's group (0 = quiet .. len(levels) = brightest) from
    its source light as a share of the brightest pixel's; -1 for masked pixels. A scene
    without sources puts every pixel in group 0."""
    groups = np.zeros(flux_map.shape, np.int64)
    peak = float(flux_map.max()) if flux_map.size else 0.0
    if peak > 0.0:
        for level in levels:
            groups[flux_map > peak * level] += 1
    if mask is not None:
        groups[mask] = -1
    return groups


def count_bin_edges(max_count: int) -> np.ndarray:
    """Lower edges of the per-pixel count bins: 0, 1, 2, 3, then widening by x1.5
    (4, 6, 9, 13, 19, ...) up to ``max_count``; the last bin is open. Single counts where
    noise lives, coarser bins where a source's pixels spread."""
    edges = [0, 1, 2, 3]
    while edges[-1] < max_count:
        edges.append(max(edges[-1] + 1, math.floor(edges[-1] * 1.5)))
    return np.array(edges, np.int64)


def count_statistics(events: np.ndarray, width: int, height: int, groups: np.ndarray,
                     n_groups: int, edges: np.ndarray) -> np.ndarray:
    """The statistics vector of one recording: for ON then OFF, for each group 0..n_groups-1,
    the number of its pixels in each count bin (``edges``) followed by its event total."""
    pixel = events["y"].astype(np.int64) * width + events["x"].astype(np.int64)
    flat = groups.reshape(-1)
    out = []
    for polarity in (1, 0):
        counts = np.bincount(pixel[events["p"] == polarity], minlength=width * height)
        for g in range(n_groups):
            c = counts[flat == g]
            hist = np.bincount(np.searchsorted(edges, c, side="right") - 1, minlength=edges.size)
            out.append(hist.astype(np.float64))
            out.append(np.array([float(c.sum())]))
    return np.concatenate(out)


def chi2_residuals(real: np.ndarray, sims: Sequence[np.ndarray]) -> np.ndarray:
    """(r - m) / sqrt(m + r/K + 1) per statistic, m the mean of the K simulated vectors: the
    standardised differences whose mean square is the chi-square distance."""
    if len(sims) == 0:
        raise ValueError("chi2_residuals needs at least one simulation")
    m = np.mean(np.vstack(sims), axis=0)
    return (real - m) / np.sqrt(m + real / len(sims) + 1.0)


def chi2_distance(real: np.ndarray, sims: Sequence[np.ndarray]) -> float:
    """:data:`CHI2_FORMULA`: the mean of the squared :func:`chi2_residuals`."""
    r = chi2_residuals(real, sims)
    return float(np.mean(r * r))


class CountsObjective(MatchObjective):
    """The fit's chi-square distance (:mod:`evstwin.tune.counts`): each job returns the
    statistics vector of its simulation (metric ``stats``, an array) and ``distance``, its
    own chi-square against the real recording (K = 1; the trial's distance is computed from
    the mean of its seeds' vectors by :meth:`trial_distance`). ROI and mask as
    :class:`MatchObjective`'s; the pixel groups come from ``scenario`` (prepared for the ROI)
    and are fixed for the whole fit."""

    name = "counts"
    metrics: tuple[str, ...] = ("distance", "stats")
    headline = ("distance",)

    def __init__(self, real_events: np.ndarray, real_meta: Mapping[str, Any], scenario: Mapping[str, Any],
                 roi: Any = None, mask_pixels: Sequence[tuple[int, int]] = (), mask_hot: bool = False,
                 hot_false_alarms: float | None = None, levels: Sequence[float] = GROUP_LEVELS) -> None:
        super().__init__(real_events, real_meta, roi=roi, mask_pixels=mask_pixels, mask_hot=mask_hot,
                         hot_false_alarms=hot_false_alarms)
        from ..scenario import build, set_value

        scene = build(set_value(self.prepare(dict(scenario)), "duration_s", self.duration_s))
        flux, self.passage_s = source_light_and_time(scene)
        self.groups = pixel_groups(flux, self.mask, levels)
        self.n_groups = len(levels) + 1
        real = self.real_events
        top = 0
        if real.size:
            pixel = real["y"].astype(np.int64) * self.width + real["x"].astype(np.int64)
            keep = self.groups.reshape(-1)[pixel] >= 0
            for polarity in (1, 0):
                sel = pixel[keep & (real["p"] == polarity)]
                if sel.size:
                    top = max(top, int(np.bincount(sel).max()))
        self.edges = count_bin_edges(top)
        self.real_stats = count_statistics(real, self.width, self.height, self.groups, self.n_groups, self.edges)

    def statistics(self, events: np.ndarray) -> np.ndarray:
        """The statistics vector of one recording (of the compared region)."""
        return count_statistics(events, self.width, self.height, self.groups, self.n_groups, self.edges)

    def describe_statistics(self) -> list[str]:
        """One label per statistic, for reports: 'counts g<group> ON|OFF bin <lower edge>' or '... total'."""
        labels = []
        for polarity in ("ON", "OFF"):
            for g in range(self.n_groups):
                labels += [f"counts g{g} {polarity} >= {e}" for e in self.edges] + [f"counts g{g} {polarity} total"]
        return labels

    def evaluate(self, result: Any) -> dict[str, Any]:  # type: ignore[override]
        stats = self.statistics(result.events)
        return {"distance": chi2_distance(self.real_stats, [stats]), "stats": stats}

    def residuals(self, sims: Sequence[np.ndarray]) -> np.ndarray:
        """:func:`chi2_residuals` of the real recording against these seeds' vectors."""
        return chi2_residuals(self.real_stats, sims)

    def trial_distance(self, sims: Sequence[np.ndarray]) -> float:
        """The trial's distance: :func:`chi2_distance` against the mean of its seeds' vectors."""
        return chi2_distance(self.real_stats, sims)


def chi2_covariance(real: np.ndarray, mean_best: np.ndarray, slopes: np.ndarray, seed_stats: np.ndarray,
                    runs_per_trial: int) -> np.ndarray:
    """(n, n): the covariance of the chi-square fit's estimate of n parameters, the least-squares
    "sandwich" ``H^-1 B H^-1`` of the weighted fit ``min (r - m(u))^T W (r - m(u))``, linearised
    at the best: H = A^T W A, B = A^T W C W A.

    real: the S statistics r of the recording. mean_best: m, the mean of the fit's K
    (``runs_per_trial``) seeds' statistics at the best; W = diag(1 / (m + r/K + 1)), the
    chi-square's own weights. slopes: A (S, n), dm/du at the best. seed_stats: (M, S), the
    statistics of M >= 2 single seeds at the best (independent draws).

    C, the covariance of r - m at the best, is (1 + 1/K) Sigma: the recording is one draw of
    the statistics (Sigma, if the twin matches it) and the mean of the K seeds is another
    (Sigma / K; with common seeds the whole fit sees it as a fixed offset). Sigma is the
    sample covariance of ``seed_stats``, used only through its projections A^T W (s - s_bar),
    so that M needs to exceed neither S nor n. The statistics share events (ON and OFF
    histograms of the same pixels, a group's histogram and its total), so Sigma is not
    diagonal: the per-statistic Pearson weights alone (H^-1, "a rise of 1 in the sum") do not
    give the estimate's spread.

    A parameter whose column of A is zero (no statistic moves with it), or a set of them that
    H cannot separate, gets an infinite variance."""
    wa, moved, h = _weighted_slopes("chi2_covariance", real, mean_best, slopes, runs_per_trial)
    s = np.asarray(seed_stats, np.float64)
    if s.ndim != 2 or s.shape[1] != wa.shape[0] or s.shape[0] < 2:
        raise ValueError(f"chi2_covariance: seed_stats must be (M >= 2, {wa.shape[0]}); got {s.shape}")
    n = wa.shape[1]
    g = (s - s.mean(axis=0)) @ wa  # (M, n): A^T W (s_k - s_bar)
    b = (1.0 + 1.0 / runs_per_trial) * (g.T @ g) / (s.shape[0] - 1)
    cov = np.full((n, n), math.inf)
    if h is not None:
        h_inv = np.linalg.inv(h)
        cov[np.ix_(moved, moved)] = h_inv @ b[np.ix_(moved, moved)] @ h_inv
    return cov


def chi2_gauss_newton_step(real: np.ndarray, mean_best: np.ndarray, slopes: np.ndarray,
                           runs_per_trial: int) -> np.ndarray:
    """(n,): the Gauss-Newton step du = H^-1 A^T W (r - m) from the best to the minimum of the
    chi-square's linear model there (arguments and H, W as :func:`chi2_covariance`'s): how far
    the point a search ended at lies from the least-squares estimate that the covariance
    describes. Zero for a parameter no statistic moves with; nan where H cannot separate them."""
    wa, moved, h = _weighted_slopes("chi2_gauss_newton_step", real, mean_best, slopes, runs_per_trial)
    step = np.zeros(wa.shape[1])
    if moved.size:
        residual = np.asarray(real, np.float64) - np.asarray(mean_best, np.float64)
        step[moved] = math.nan if h is None else np.linalg.solve(h, wa[:, moved].T @ residual)
    return step


def _weighted_slopes(who: str, real: np.ndarray, mean_best: np.ndarray, slopes: np.ndarray,
                     runs_per_trial: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """Checked arguments of :func:`chi2_covariance` and :func:`chi2_gauss_newton_step` ->
    (W A, the columns some statistic moves with, H = A^T W A over those columns or None where
    H cannot separate them: a condition number of 1e12 or more)."""
    real = np.asarray(real, np.float64)
    mean_best = np.asarray(mean_best, np.float64)
    a = np.asarray(slopes, np.float64)
    if a.ndim != 2 or a.shape[0] != real.size or mean_best.shape != real.shape:
        raise ValueError(f"{who}: slopes must be (S, n) and mean_best (S,) with S = {real.size}; "
                         f"got {a.shape} and {mean_best.shape}")
    if isinstance(runs_per_trial, bool) or not isinstance(runs_per_trial, int) or runs_per_trial < 1:
        raise ValueError(f"{who}: runs_per_trial must be an integer >= 1; got {runs_per_trial!r}")
    wa = a / (mean_best + real / runs_per_trial + 1.0)[:, None]
    moved = np.flatnonzero(np.any(a != 0.0, axis=0))
    h = a[:, moved].T @ wa[:, moved] if moved.size else None
    return wa, moved, h if h is not None and np.linalg.cond(h) < 1e12 else None
