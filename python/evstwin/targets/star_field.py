"""Random star fields: stars uniform over the sensor with power-law or the sky's magnitude
counts (``evstwin.sky.stars``), static or drifting across it."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .._checks import finite, integer, non_negative
from ..optics import Optics
from ..sky import stars
from ..sky.stars import STAR_FIELD_COUNTS_SLOPE, STAR_FIELD_MAG_MAX, STAR_FIELD_MAG_MIN
from .base import _drift
from .kinds import LinearTarget, StaticTarget

MAX_STARS = 1_000_000
"""Most stars of a random star field: each becomes a target (about 300 bytes, 25 us to make)
rendered at every sample; 1e6 already take 0.3 GB and 25 s to build. Refused up front."""
_STAR_BYTES = 300


def random_star_field(
    width: int,
    height: int,
    optics: Optics,
    n_stars: int | None = None,
    density_per_deg2: float | None = None,
    mag_min: float = STAR_FIELD_MAG_MIN,
    mag_max: float = STAR_FIELD_MAG_MAX,
    counts_slope: float = STAR_FIELD_COUNTS_SLOPE,
    seed: int = 0,
    drift_px_s: Sequence[float] = (0.0, 0.0),
    duration_s: float = 0.0,
    distribution: str = "uniform",
    density_scale: float = 1.0,
    margin_px: float = 0.0,
) -> list[StaticTarget] | list[LinearTarget]:
    """Random stars, uniform over the sensor, with power-law or the sky's magnitude counts.

    distribution: ``"uniform"`` (default, as before: the power law below, and n_stars or
    density_per_deg2) or ``"all-sky"``: the sky's star counts (``evstwin.sky.stars``: the
    all-sky average N(< V) of Tycho-2 + UCAC4, V in [0, 16]) between mag_min and mag_max,
    times density_scale (galactic latitude is not modelled: scale it yourself). The number
    of stars then follows from the optics: a Poisson count of that density over the field
    (give neither n_stars nor density_per_deg2; counts_slope does not apply).

    Give exactly one of ``n_stars`` or ``density_per_deg2`` (stars per square degree between
    mag_min and mag_max; the count is then Poisson over the ``width x height`` pixel field at
    ``optics.plate_scale_rad_per_px``). Magnitudes follow dN/dm ~ 10^(counts_slope m) on
    [mag_min, mag_max]: 0.6 is a uniform Euclidean population; all-sky star counts grow by
    roughly 0.4-0.5 dex per magnitude for 6 < V < 15 (an approximation: the slope flattens
    towards faint magnitudes and depends on galactic latitude). Fluxes come from
    ``optics.flux_from_magnitude``; each star's label is ``"star <k> mag=<m>"``.
    Positions cover the whole sensor area, x in [-0.5, width - 0.5), y likewise.
    The same arguments and seed give the same stars (numpy ``default_rng(seed)``, PCG64).

    drift_px_s: (vx, vy) [px/s], the velocity of the whole field across the sensor (a
    telescope's tracking error, a staring camera; ``drift_px_s_from_arcsec`` converts a rate on
    the sky). With a non-zero drift the stars are LinearTargets at (x0 + vx t, y0 + vy t) with
    the positions above at t = 0, and the field also holds the stars that drift onto the
    sensor during ``duration_s`` [s]: the area the drift sweeps past the sensor, at the same
    density (``n_stars / (width height)`` per px^2 with n_stars, a Poisson count). The
    count on the sensor is then the same in distribution at every time in [0, duration_s].
    The stars on the sensor at t = 0 are those of the field without drift (their random
    numbers come first). With no drift (the default) they are StaticTargets, as before.
    ``margin_px`` [px] adds, at the same density, the stars of a frame that wide around that
    area (drawn last, from their own stream, so the others do not change): the ones a field
    path (a slew of up to margin_px) brings in.
    """
    width = integer("width", width, 1)
    height = integer("height", height, 1)
    lo = finite("mag_min", mag_min)
    hi = finite("mag_max", mag_max)
    if not lo <= hi:
        raise ValueError(f"need mag_min <= mag_max; got mag_min={mag_min!r}, mag_max={mag_max!r}")
    alpha = non_negative("counts_slope", counts_slope)
    seed = integer("seed", seed, 0)
    vx, vy = _drift("drift_px_s", drift_px_s)
    duration = non_negative("duration_s", duration_s)
    if distribution not in ("uniform", "all-sky"):
        raise ValueError(f"distribution must be 'uniform' or 'all-sky'; got distribution={distribution!r}")
    if distribution == "all-sky":
        if n_stars is not None or density_per_deg2 is not None:
            raise ValueError("distribution='all-sky' takes its density from the sky's star counts: give neither n_stars "
                             f"nor density_per_deg2; got n_stars={n_stars!r}, density_per_deg2={density_per_deg2!r}")
        density_per_deg2 = stars.density_per_deg2(lo, hi, density_scale)
    elif density_scale != 1.0:
        raise ValueError(f"density_scale applies to distribution='all-sky'; got density_scale={density_scale!r} with "
                         f"distribution={distribution!r}")
    if (n_stars is None) == (density_per_deg2 is None):
        raise ValueError(
            f"give exactly one of n_stars and density_per_deg2; got n_stars={n_stars!r}, density_per_deg2={density_per_deg2!r}"
        )
    rng = np.random.default_rng(seed)
    # Where a star must be at t = 0 to be on the sensor at some time in [0, duration]: the
    # sensor plus two strips swept by its leading edges moving by d = -v duration (disjoint
    # from the sensor and from each other; their union is the sensor's Minkowski sum with
    # the segment [0, d]).
    dx, dy = -vx * duration, -vy * duration
    strip_x = height * abs(dx)  # swept by the edge x = width - 0.5 (dx > 0) or -0.5 [px^2]
    strip_y = width * abs(dy)
    area_px2 = width * height + strip_x + strip_y
    swept = "" if area_px2 == width * height else (
        f" and the area drift_px_s={drift_px_s!r} sweeps past it over duration_s={duration_s!r}")
    if n_stars is not None:
        n = integer("n_stars", n_stars, 0)
        per_px2 = n / (width * height)
        mean = per_px2 * area_px2 if n else 0.0
        if n > MAX_STARS:
            raise ValueError(f"n_stars must be at most {MAX_STARS:,} (each star is a target, ~{_STAR_BYTES} bytes, "
                             f"rendered every sample); got n_stars={n:,}, {n * _STAR_BYTES / 1e9:.3g} GB")
        if not mean <= MAX_STARS:
            raise ValueError(f"n_stars={n:,} on the {width}x{height} sensor{swept} gives {mean:.3g} stars, more than "
                             f"{MAX_STARS:,} ({mean * _STAR_BYTES / 1e9:.3g} GB)")
    else:
        density = non_negative("density_per_deg2", density_per_deg2)
        px_deg = math.degrees(optics.plate_scale_rad_per_px)
        per_px2 = density * px_deg * px_deg
        on_sensor = density * width * height * px_deg * px_deg  # this order: the same draws as before drifts
        mean = on_sensor + per_px2 * (strip_x + strip_y) if per_px2 > 0.0 else 0.0
        if not mean <= MAX_STARS:
            raise ValueError(
                f"density_per_deg2={density_per_deg2!r} gives {mean:.3g} stars on the {width}x{height} field{swept} "
                f"({area_px2 * px_deg * px_deg:.3g} deg2), more than {MAX_STARS:,} ({mean * _STAR_BYTES / 1e9:.3g} GB)"
            )
        n = int(rng.poisson(on_sensor))
    x = rng.uniform(-0.5, width - 0.5, n)
    y = rng.uniform(-0.5, height - 0.5, n)
    u = rng.uniform(0.0, 1.0, n)
    if strip_x + strip_y > 0.0 and per_px2 > 0.0:
        n_x = int(rng.poisson(per_px2 * strip_x))
        along, s = rng.uniform(-0.5, height - 0.5, n_x), rng.uniform(0.0, 1.0, n_x)
        xs = (width - 0.5 if dx > 0 else -0.5) + s * dx
        ys = along + s * dy
        n_y = int(rng.poisson(per_px2 * strip_y))
        along, s = rng.uniform(-0.5, width - 0.5, n_y), rng.uniform(0.0, 1.0, n_y)
        x = np.concatenate([x, xs, along + s * dx])
        y = np.concatenate([y, ys, (height - 0.5 if dy > 0 else -0.5) + s * dy])
        u = np.concatenate([u, rng.uniform(0.0, 1.0, n_x + n_y)])
        n = x.size
    margin = non_negative("margin_px", margin_px)
    if margin > 0.0 and per_px2 > 0.0:
        # The frame: the bounding box of the sensor and its strips, widened by the margin, less
        # the sensor and strips themselves (rejection, at the same density).
        bx0, bx1 = -0.5 + min(dx, 0.0), width - 0.5 + max(dx, 0.0)
        by0, by1 = -0.5 + min(dy, 0.0), height - 0.5 + max(dy, 0.0)
        fx0, fx1, fy0, fy1 = bx0 - margin, bx1 + margin, by0 - margin, by1 + margin
        frame_rng = np.random.default_rng([seed, 1])
        n_f = int(frame_rng.poisson(per_px2 * (fx1 - fx0) * (fy1 - fy0)))
        fx, fy = frame_rng.uniform(fx0, fx1, n_f), frame_rng.uniform(fy0, fy1, n_f)
        fu = frame_rng.uniform(0.0, 1.0, n_f)
        in_sensor = (fx >= -0.5) & (fx < width - 0.5) & (fy >= -0.5) & (fy < height - 0.5)
        keep = ~in_sensor
        with np.errstate(divide="ignore", invalid="ignore"):
            if dx != 0.0:  # the strip swept by the x edge: edge + s d, s in [0, 1), sheared by dy
                sx = (fx - (width - 0.5 if dx > 0 else -0.5)) / dx
                along = fy - sx * dy
                keep &= ~((sx >= 0.0) & (sx < 1.0) & (along >= -0.5) & (along < height - 0.5))
            if dy != 0.0:
                sy = (fy - (height - 0.5 if dy > 0 else -0.5)) / dy
                along = fx - sy * dx
                keep &= ~((sy >= 0.0) & (sy < 1.0) & (along >= -0.5) & (along < width - 0.5))
        if not (n + int(keep.sum())) <= MAX_STARS:
            raise ValueError(f"margin_px={margin_px!r} around the {width}x{height} field gives {n + int(keep.sum())} "
                             f"stars, more than {MAX_STARS:,}")
        x, y, u = np.concatenate([x, fx[keep]]), np.concatenate([y, fy[keep]]), np.concatenate([u, fu[keep]])
        n = x.size
    if distribution == "all-sky":
        mag = stars.draw_magnitudes(u, lo, hi)
    elif alpha == 0.0 or hi == lo:
        mag = lo + (hi - lo) * u
    else:
        # inverse CDF of dN/dm ~ 10^(alpha m) on [lo, hi], relative to lo (no overflow)
        mag = lo + np.log10(1.0 + u * (10.0 ** (alpha * (hi - lo)) - 1.0)) / alpha
    flux = np.asarray(optics.flux_from_magnitude(mag), np.float64).reshape(-1)
    if vx == 0.0 and vy == 0.0:
        return [
            StaticTarget(float(x[k]), float(y[k]), float(flux[k]), label=f"star {k} mag={mag[k]:.3f}")
            for k in range(n)
        ]
    return [
        LinearTarget(float(x[k]), float(y[k]), vx, vy, float(flux[k]), label=f"star {k} mag={mag[k]:.3f}")
        for k in range(n)
    ]
