"""The sky as a scene: satellites from elements and stars on the celestial sphere, seen from a
site through a pointing, as evstwin Targets on the sensor.

The scenario keys (``evstwin.scenario`` reads them and calls :func:`build_sky`):

``start_utc``  the UTC time of t = 0 ("2014-01-23T11:18:07Z").
``[site]``     ``lat_deg``, ``lon_deg``, ``alt_m`` (WGS-84), ``ut1_utc_s`` (default: the IERS
               table at ``start_utc``, :mod:`evstwin.sky.iers`; an error outside it),
               ``extinction_mag_per_airmass`` (V-band k, default ``DEFAULT_EXTINCTION``).
``[pointing]`` ``mode`` = staring | sidereal | target | table (``evstwin.sky.pointing``; right
               ascensions and declinations are of date, TEME's equator and mean equinox, not
               J2000: 0.36 deg of precession apart in 2026), with:
               staring: ``az_deg``/``el_deg``, or ``target`` (an index into targets; default
               the first ``tle`` one) and ``at_s`` (aim where it is at that time; default 0);
               sidereal: ``ra_deg``/``dec_deg``, or ``az_deg``/``el_deg`` (at t = 0), or
               ``target``/``at_s``; target: ``target``; table: ``t_s`` and ``az_deg``/
               ``el_deg`` or ``ra_deg``/``dec_deg`` arrays. All: ``up`` (zenith | north),
               ``roll_deg``, ``step_s`` (the first time step of the position tables; it is
               halved until linear interpolation is within ``TABLE_TOLERANCE_PX``).
``[[targets]]`` ``kind = "tle"``: ``line1``, ``line2``, and its brightness: ``diameter_m`` with
               ``albedo`` (a diffuse sphere, ``evstwin.sky.photometry``), or ``magnitude`` /
               ``light_curve`` (V magnitudes above the atmosphere). Extinction, the Earth's
               shadow and the horizon are applied to all three.
``[star_field]`` with a pointing: stars drawn uniformly on the sky around the area the
               sensor sweeps, ``density_per_deg2`` or ``n_stars`` (the mean count on the
               sensor), magnitudes ``mag_min``..``mag_max`` with ``counts_slope`` (the law of
               ``evstwin.targets.random_star_field``), ``seed``; extinction applied.

Satellites become ``TabulatedTarget``s with a ``LightCurve`` (flux 0 while in shadow, below
the horizon or far off the sensor); stars become ``StaticTarget``/``LinearTarget`` where a
straight line holds their track within ``LINEAR_TOLERANCE_PX`` over the run (sidereal
tracking, a staring camera over a short run), else ``TabulatedTarget``s cut to the time they
are near the sensor. Positions farther than the PSF window outside the sensor are clamped to
that border (they light nothing there; the ground truth written for a satellite is its
clamped track while it is off the sensor).

Hook for a star catalogue (``evstwin.sky.stars``, another module): :func:`stars_to_targets`
takes any star directions and magnitudes; :func:`draw_sky_stars` is the random field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime
from typing import Any

import numpy as np

from ..constants import DEG_PER_RAD
from ..optics import Optics
from ..targets import LightCurve, LinearTarget, StaticTarget, TabulatedTarget, Target
from . import earth, iers, orbit, photometry
from .pointing import MODES, UPS, Attitude, project, unproject
from .stars import STAR_FIELD_COUNTS_SLOPE, STAR_FIELD_MAG_MAX, STAR_FIELD_MAG_MIN

DEFAULT_EXTINCTION = 0.2
"""Default V-band extinction [mag/airmass]: between a good mountain site (0.11-0.15) and sea
level (0.25-0.3) (e.g. King 1985, RGO/La Palma technical note 31; Burki et al. 1995, A&AS
112, 383 for La Silla, 0.11-0.2 in V)."""
TABLE_TOLERANCE_PX = 0.02
"""Largest error [px] of linear interpolation between the tabulated positions (checked at
the midpoints of every table step, for every object near the sensor)."""
LINEAR_TOLERANCE_PX = 0.05
"""A star whose tabulated track stays within this distance [px] of a straight line (or a
point) over the whole run becomes a LinearTarget (StaticTarget)."""
MAX_TABLE_POINTS = 200_001
"""Most rows of a position table (the halving of the step stops there)."""
MAX_SKY_STARS = 200_000
"""Most stars drawn on the sky for one run."""
_ERROR_PROBE_STARS = 256
"""Stars checked for the interpolation error (a random subset: the motion field is smooth)."""

SITE_KEYS = ("lat_deg", "lon_deg", "alt_m", "ut1_utc_s", "extinction_mag_per_airmass")
POINTING_KEYS = ("mode", "az_deg", "el_deg", "ra_deg", "dec_deg", "target", "at_s", "up", "roll_deg", "t_s",
                 "step_s")
TLE_KEYS = ("line1", "line2", "diameter_m", "albedo")


def uses_sky(s: dict[str, Any]) -> bool:
    """Whether a scenario places objects on the sky (a pointing, a site or a tle target)."""
    return any(k in s for k in ("pointing", "site", "start_utc")) or any(
        t.get("kind") == "tle" for t in s.get("targets", []))


def _placed_by(s: dict[str, Any]) -> str:
    """What in a scenario puts objects on the sky, for the messages about what that needs."""
    parts = [f"{k}={s[k]!r}" for k in ("start_utc", "site", "pointing") if k in s]
    parts += [f"targets[{i}] (kind 'tle')" for i, t in enumerate(s.get("targets", [])) if t.get("kind") == "tle"]
    return ", ".join(parts)


@dataclass
class SkyTargets:
    """What :func:`build_sky` makes: the tle targets (in the order of their tables), the
    stars, and a few figures to report."""

    satellites: list[Target]
    stars: list[Target]
    info: dict[str, Any]


class _Context:
    """The parsed site, time, optics and sensor box of one scenario."""

    def __init__(self, s: dict[str, Any], optics: Optics, width: int, height: int, t_end: float, margin_px: float):
        self.site_table = dict(s.get("site", {}))
        for key in ("lat_deg", "lon_deg"):
            if key not in self.site_table:
                raise ValueError(f"{_placed_by(s)} place objects on the sky, which needs site.lat_deg and "
                                 f"site.lon_deg (the observer); got site={self.site_table}")
        try:
            self.site = earth.Site(float(self.site_table["lat_deg"]), float(self.site_table["lon_deg"]),
                                   float(self.site_table.get("alt_m", 0.0)))
        except (TypeError, ValueError) as exc:
            raise ValueError(f"site.{exc}") from None
        explicit_ut1 = "ut1_utc_s" in self.site_table
        if explicit_ut1:
            try:
                self.ut1_utc_s = float(self.site_table["ut1_utc_s"])
            except (TypeError, ValueError):
                self.ut1_utc_s = math.nan
            if not abs(self.ut1_utc_s) <= 1.0:
                raise ValueError(f"site.ut1_utc_s must be in [-1, 1] s (leap seconds keep |UT1 - UTC| < 0.9 s); "
                                 f"got {self.site_table['ut1_utc_s']!r}")
        self.k_ext = float(self.site_table.get("extinction_mag_per_airmass", DEFAULT_EXTINCTION))
        if not 0.0 <= self.k_ext <= 5.0:
            raise ValueError(f"site.extinction_mag_per_airmass must be in [0, 5]; got {self.k_ext!r}")
        if "start_utc" not in s:
            raise ValueError(f"{_placed_by(s)} place objects on the sky, which needs start_utc (the UTC time of "
                             "t = 0, e.g. '2014-01-23T11:18:07Z')")
        try:
            self.start: datetime = earth.parse_utc(s["start_utc"])
        except ValueError as exc:
            raise ValueError(f"start_utc {exc}") from None
        if not explicit_ut1:  # the IERS table's value at the start (it changes < 3 ms a day)
            self.ut1_utc_s = iers.ut1_utc_s(self.start)
        self.ut1_utc_from = "site.ut1_utc_s" if explicit_ut1 else iers.source()
        self.optics = optics
        self.k = optics.plate_scale_rad_per_px
        self.width, self.height = width, height
        self.centre = ((width - 1) / 2.0, (height - 1) / 2.0)
        self.t_end = t_end
        self.box = (-0.5 - margin_px, width - 0.5 + margin_px, -0.5 - margin_px, height - 0.5 + margin_px)

    def in_box(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Where positions [px] are within the sensor plus its margin (NaN: not)."""
        lo_x, hi_x, lo_y, hi_y = self.box
        with np.errstate(invalid="ignore"):
            return (x >= lo_x) & (x <= hi_x) & (y >= lo_y) & (y <= hi_y)

    def clamp(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions clamped to the box (NaN, behind the camera, to the centre of its left edge)."""
        lo_x, hi_x, lo_y, hi_y = self.box
        bad = ~(np.isfinite(x) & np.isfinite(y))
        x = np.where(bad, lo_x, np.clip(np.nan_to_num(x), lo_x, hi_x))
        y = np.where(bad, 0.5 * (lo_y + hi_y), np.clip(np.nan_to_num(y), lo_y, hi_y))
        return x, y

    def elevation_deg(self, t_s: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Elevation [deg] of fixed sky directions (S, 3) at times (N,): (N, S)."""
        n, s_ = t_s.size, directions.shape[0]
        d = np.broadcast_to(directions[None, :, :], (n, s_, 3)).reshape(-1, 3)
        t = np.repeat(t_s, s_)
        return orbit.az_el_from_sky_direction(self.site, self.start, t, d, self.ut1_utc_s)[1].reshape(n, s_)


# -- satellites -------------------------------------------------------------------------------


@dataclass
class _Satellite:
    index: int
    label: str
    elements: orbit.Elements
    table: dict[str, Any]


def _satellites(s: dict[str, Any]) -> list[_Satellite]:
    out = []
    for i, table in enumerate(s.get("targets", [])):
        if table.get("kind") != "tle":
            continue
        for key in ("line1", "line2"):
            if key not in table:
                raise ValueError(f"targets[{i}] (kind 'tle') needs {key}")
        try:
            elements = orbit.Elements(table["line1"], table["line2"], str(table.get("label", "")))
        except ValueError as exc:
            raise ValueError(f"targets[{i}]: {exc}") from None
        brightness = [k for k in ("diameter_m", "magnitude", "light_curve") if k in table]
        if len(brightness) != 1:
            raise ValueError(f"targets[{i}] (kind 'tle') needs exactly one of diameter_m (with albedo), magnitude, "
                             f"light_curve; got {', '.join(brightness) or 'none'}")
        if ("albedo" in table) != ("diameter_m" in table):
            raise ValueError(f"targets[{i}]: diameter_m and albedo go together (a diffuse sphere); got "
                             f"{'albedo' if 'albedo' in table else 'diameter_m'} alone")
        if "diameter_m" in table:
            d, a = table["diameter_m"], table["albedo"]
            if not (isinstance(d, (int, float)) and 0.0 < d <= 1e4):
                raise ValueError(f"targets[{i}].diameter_m must be in (0, 1e4] m; got {d!r}")
            if not (isinstance(a, (int, float)) and 0.0 < a <= 1.0):
                raise ValueError(f"targets[{i}].albedo must be in (0, 1]; got {a!r}")
        label = str(table.get("label", f"NORAD {elements.norad_id}"))
        out.append(_Satellite(i, label, elements, table))
    return out


def _magnitude_above_atmosphere(sat: _Satellite, obs: orbit.Observation) -> np.ndarray:
    """The satellite's V magnitude before extinction at the observation times."""
    table = sat.table
    if "diameter_m" in table:
        return photometry.diffuse_sphere_magnitude(float(table["diameter_m"]), float(table["albedo"]), obs.range_km,
                                                   obs.phase_rad, obs.sun_distance_au)
    if "magnitude" in table:
        return np.full(obs.t_s.shape, float(table["magnitude"]))
    lc = table["light_curve"]
    if not isinstance(lc, dict) or "t_s" not in lc or "magnitude" not in lc or set(lc) - {"t_s", "magnitude"}:
        raise ValueError(f"targets[{sat.index}].light_curve of a tle target must be {{t_s = [...], magnitude = [...]}} "
                         "(V magnitudes above the atmosphere)")
    t, m = np.asarray(lc["t_s"], np.float64), np.asarray(lc["magnitude"], np.float64)
    if t.ndim != 1 or t.shape != m.shape or t.size < 1 or np.any(np.diff(t) <= 0) or not np.all(np.isfinite(m)):
        raise ValueError(f"targets[{sat.index}].light_curve needs strictly increasing t_s and finite magnitudes "
                         "of the same length")
    return np.interp(obs.t_s, t, m)


# -- pointing ---------------------------------------------------------------------------------


def _pointing_target(p: dict[str, Any], sats: list[_Satellite]) -> _Satellite:
    if "target" in p:
        idx = p["target"]
        match = [sat for sat in sats if sat.index == idx]
        if not match:
            raise ValueError(f"pointing.target must be the index of a tle target ({[x.index for x in sats]}); got "
                             f"{idx!r}")
        return match[0]
    if not sats:
        raise ValueError(f"pointing.mode={p.get('mode')!r} aims at a satellite, but there is no tle target: give "
                         "its direction (az_deg/el_deg or ra_deg/dec_deg) instead")
    return sats[0]


def _attitude(ctx: _Context, p: dict[str, Any], sats: list[_Satellite], t: np.ndarray) -> Attitude:
    mode = p.get("mode")
    if mode not in MODES:
        raise ValueError(f"pointing.mode must be one of {', '.join(MODES)}; got {mode!r}")
    up = p.get("up", "north" if mode == "sidereal" else "zenith")
    if up not in UPS:
        raise ValueError(f"pointing.up must be one of {', '.join(UPS)}; got {up!r}")
    roll = float(p.get("roll_deg", 0.0))
    t0 = np.zeros(1)

    def zenith(times: np.ndarray) -> np.ndarray:
        return orbit.sky_direction_from_az_el(ctx.site, ctx.start, times, 0.0, 90.0, ctx.ut1_utc_s)

    def aimed(times: np.ndarray) -> np.ndarray:
        sat = _pointing_target(p, sats)
        at = float(p.get("at_s", 0.0))
        if mode != "target" and not 0.0 <= at <= ctx.t_end:
            raise ValueError(f"pointing.at_s must be in [0, {ctx.t_end:g}] s (the run); got {at!r}: aim within the "
                             f"run (--set pointing.at_s=SECONDS) or simulate past it (--duration over {at:g})")
        return orbit.observe(sat.elements, ctx.site, ctx.start, times if mode == "target" else [at],
                             ctx.ut1_utc_s).direction

    def given(names: tuple[str, str]) -> bool:
        have = [n for n in names if n in p]
        if len(have) == 1:
            raise ValueError(f"pointing.{names[0]} and pointing.{names[1]} go together; got only pointing.{have[0]}")
        return len(have) == 2

    if mode == "table":
        return _table_attitude(ctx, p, t, up, roll)
    extra = [k for k in ("t_s",) if k in p]
    if extra:
        raise ValueError(f"pointing.t_s applies to mode='table'; got it with mode={mode!r}")
    if mode == "staring":
        if given(("az_deg", "el_deg")):
            az, el = float(p["az_deg"]), float(p["el_deg"])
            if not 0.0 < el <= 90.0:
                raise ValueError(f"pointing.el_deg must be in (0, 90] (above the horizon); got {p['el_deg']!r}")
            if not 0.0 <= az < 360.0:
                raise ValueError(f"pointing.az_deg must be in [0, 360); got {p['az_deg']!r}")
        else:
            d = aimed(t0)
            az_a, el_a = orbit.az_el_from_sky_direction(ctx.site, ctx.start, [float(p.get("at_s", 0.0))], d,
                                                         ctx.ut1_utc_s)
            az, el = float(az_a[0]), float(el_a[0])
            if el <= 0.0:
                raise ValueError(f"pointing aims at targets[{_pointing_target(p, sats).index}] at pointing.at_s="
                                 f"{p.get('at_s', 0.0)!r} s, when it is below the horizon (elevation {el:.2f} deg)")
        b = orbit.sky_direction_from_az_el(ctx.site, ctx.start, t, az, el, ctx.ut1_utc_s)
    elif mode == "sidereal":
        if given(("ra_deg", "dec_deg")):
            ra, dec = float(p["ra_deg"]), float(p["dec_deg"])
            if not -90.0 <= dec <= 90.0:
                raise ValueError(f"pointing.dec_deg must be in [-90, 90]; got {p['dec_deg']!r}")
            d = earth.vector_from_ra_dec(ra, dec)
        elif given(("az_deg", "el_deg")):
            d = orbit.sky_direction_from_az_el(ctx.site, ctx.start, t0, float(p["az_deg"]), float(p["el_deg"]),
                                               ctx.ut1_utc_s)[0]
        else:
            d = aimed(t0)[0]
        b = np.broadcast_to(d, t.shape + (3,))
    else:  # target
        for key in ("az_deg", "el_deg", "ra_deg", "dec_deg", "at_s"):
            if key in p:
                raise ValueError(f"pointing.{key} does not apply to mode='target' (the boresight follows "
                                 "pointing.target)")
        b = aimed(t)
    ref = zenith(t) if up == "zenith" else np.array([0.0, 0.0, 1.0])
    return Attitude.from_boresight(t, b, ref, roll, what=f"pointing (mode={mode!r}, up={up!r})")


def _table_attitude(ctx: _Context, p: dict[str, Any], t: np.ndarray, up: str, roll: float) -> Attitude:
    if "t_s" not in p:
        raise ValueError("pointing.mode='table' needs t_s and az_deg/el_deg or ra_deg/dec_deg arrays")
    tt = np.asarray(p["t_s"], np.float64)
    pairs = [pair for pair in (("az_deg", "el_deg"), ("ra_deg", "dec_deg")) if pair[0] in p or pair[1] in p]
    if len(pairs) != 1 or not all(k in p for k in pairs[0]):
        raise ValueError("pointing.mode='table' needs t_s with either az_deg and el_deg or ra_deg and dec_deg; got "
                         f"{sorted(k for k in p if k not in ('mode', 'up', 'roll_deg', 'step_s'))}")
    a, c = (np.asarray(p[k], np.float64) for k in pairs[0])
    if tt.ndim != 1 or tt.size < 1 or a.shape != tt.shape or c.shape != tt.shape:
        raise ValueError(f"pointing.t_s, {pairs[0][0]} and {pairs[0][1]} must be 1-D arrays of one length; got "
                         f"lengths {tt.size}, {a.size}, {c.size}")
    if np.any(np.diff(tt) <= 0):
        raise ValueError(f"pointing.t_s must be strictly increasing; got {p['t_s']!r}")
    if tt[0] > 0.0 or tt[-1] < ctx.t_end:
        raise ValueError(f"pointing.t_s must cover the run [0, {ctx.t_end:g}] s; got [{tt[0]:g}, {tt[-1]:g}]")
    if pairs[0][0] == "az_deg":
        if np.any(c <= 0.0) or np.any(c > 90.0):
            raise ValueError("pointing.el_deg must all be in (0, 90] (above the horizon)")
        rows = orbit.sky_direction_from_az_el(ctx.site, ctx.start, tt, a, c, ctx.ut1_utc_s)
    else:
        if np.any(np.abs(c) > 90.0):
            raise ValueError("pointing.dec_deg must all be in [-90, 90]")
        rows = earth.vector_from_ra_dec(a, c)
    b = np.stack([np.interp(t, tt, rows[:, i]) for i in range(3)], axis=-1)
    ref = (orbit.sky_direction_from_az_el(ctx.site, ctx.start, t, 0.0, 90.0, ctx.ut1_utc_s) if up == "zenith"
           else np.array([0.0, 0.0, 1.0]))
    return Attitude.from_boresight(t, b, ref, roll, what="pointing (mode='table')")


# -- stars ------------------------------------------------------------------------------------


def draw_sky_stars(ctx: _Context, attitude: Attitude, density_per_deg2: float, mag_min: float, mag_max: float,
                   counts_slope: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Random stars (directions (S, 3), V magnitudes (S,)) uniform on the sky over every
    direction the sensor (plus its PSF margin) sees during the run.

    The sky is cut into fixed cells (declination bands ``cell`` wide, each band cut into
    segments of right ascension about ``cell`` wide; ``cell`` is half the footprint's half
    diagonal, a property of the sensor and optics alone). Each cell's stars come from its own
    random stream, keyed by (seed, band, segment): a Poisson number uniform over its area.
    The cells within reach of the run's boresights (``attitude``) are drawn and their stars
    within reach kept, so a star's place does not depend on the run's duration or on how its
    attitude was sampled: a longer run adds cells, it does not redraw them. Magnitudes follow
    dN/dm ~ 10^(counts_slope m) on [mag_min, mag_max] (``evstwin.targets.random_star_field``'s law)."""
    lo_x, hi_x, lo_y, hi_y = ctx.box
    half_diag = math.atan(ctx.k * math.hypot(max(hi_x - ctx.centre[0], ctx.centre[0] - lo_x),
                                             max(hi_y - ctx.centre[1], ctx.centre[1] - lo_y)))
    b = attitude.b
    steps = np.arccos(np.clip(np.sum(b[1:] * b[:-1], axis=-1), -1, 1)) if b.shape[0] > 1 else np.zeros(1)
    # Everything the footprint covers between two sampled boresights lies within this of one.
    reach = min(half_diag + 0.5 * float(np.max(steps)) + 1e-6, math.radians(80.0))
    cell = max(0.5 * half_diag, 1e-4)
    per_sr = density_per_deg2 * DEG_PER_RAD ** 2
    dec_b = np.arcsin(np.clip(b[:, 2], -1.0, 1.0))
    n_bands = max(1, int(math.ceil(math.pi / cell)))
    band_h = math.pi / n_bands
    first = max(0, int(math.floor((float(dec_b.min()) - reach + 0.5 * math.pi) / band_h)))
    last = min(n_bands - 1, int(math.floor((float(dec_b.max()) + reach + 0.5 * math.pi) / band_h)))
    cells: list[tuple[int, int, int, float, float, float, float]] = []  # (band, seg, n_seg, d0, d1, ra0, ra1)
    cos_reach = math.cos(min(math.pi, reach + 2.0 * cell))
    for band in range(first, last + 1):
        d0, d1 = -0.5 * math.pi + band * band_h, -0.5 * math.pi + (band + 1) * band_h
        n_seg = max(1, int(math.floor(2.0 * math.pi * math.cos(0.5 * (d0 + d1)) / cell)))
        ra_c = (np.arange(n_seg) + 0.5) * (2.0 * math.pi / n_seg)
        dm = 0.5 * (d0 + d1)
        centres = np.stack([math.cos(dm) * np.cos(ra_c), math.cos(dm) * np.sin(ra_c), np.full(n_seg, math.sin(dm))], 1)
        near = np.max(centres @ b.T, axis=1) >= cos_reach  # a cell's centre within reach + its size
        for k_seg in np.flatnonzero(near).tolist():
            cells.append((band, k_seg, n_seg, d0, d1, k_seg * 2.0 * math.pi / n_seg, (k_seg + 1) * 2.0 * math.pi / n_seg))
    areas = [(math.sin(d1) - math.sin(d0)) * (ra1 - ra0) for _, _, _, d0, d1, ra0, ra1 in cells]
    expected = per_sr * float(np.sum(areas)) if cells else 0.0
    if expected > 50 * MAX_SKY_STARS:
        raise ValueError(f"star_field: {density_per_deg2:g} stars/deg2 over the {math.degrees(reach):.3g} deg "
                         f"reach of the sensor draws ~{expected:.3g} stars (> {50 * MAX_SKY_STARS:g}): lower "
                         "star_field.density_per_deg2 or mag_max")
    cos_keep = math.cos(reach)
    dirs, mags = [], []
    for (band, seg, n_seg, d0, d1, ra0, ra1), area in zip(cells, areas):
        rng = np.random.default_rng([int(seed), int(band), int(seg), int(n_seg)])
        n = int(rng.poisson(per_sr * area))
        if n == 0:
            continue
        sin_d = rng.uniform(math.sin(d0), math.sin(d1), n)
        ra = rng.uniform(ra0, ra1, n)
        u = rng.uniform(0.0, 1.0, n)
        cos_d = np.sqrt(1.0 - sin_d**2)
        d = np.stack([cos_d * np.cos(ra), cos_d * np.sin(ra), sin_d], 1)
        keep = np.max(d @ b.T, axis=1) >= cos_keep
        dirs.append(d[keep])
        mags.append(u[keep])
    d_all = np.concatenate(dirs) if dirs else np.zeros((0, 3))
    u_all = np.concatenate(mags) if mags else np.zeros(0)
    if d_all.shape[0] > MAX_SKY_STARS:
        raise ValueError(f"star_field gives {d_all.shape[0]} stars over the sky the sensor sweeps (> {MAX_SKY_STARS}): "
                         "lower star_field.density_per_deg2 or mag_max")
    lo, hi, alpha = float(mag_min), float(mag_max), float(counts_slope)
    if alpha == 0.0 or hi == lo:
        mag = lo + (hi - lo) * u_all
    else:
        mag = lo + np.log10(1.0 + u_all * (10.0 ** (alpha * (hi - lo)) - 1.0)) / alpha
    return d_all, mag


def stars_to_targets(ctx: _Context, grid: np.ndarray, attitude: Attitude, directions: np.ndarray,
                     mag_v: np.ndarray) -> list[Target]:
    """Stars at fixed sky directions (S, 3) with V magnitudes above the atmosphere as
    targets on the sensor over the position table ``grid`` (with ``attitude`` on it)."""
    if directions.shape[0] == 0:
        return []
    x, y, front = project(attitude, directions, ctx.k, ctx.centre)
    xc, yc = ctx.clamp(x, y)
    inside = ctx.in_box(x, y)
    seen = np.any(inside, axis=0)
    el = ctx.elevation_deg(grid, directions[seen])
    out: list[Target] = []
    t_mid = grid.size // 2
    tt = grid - grid[0]
    seen_j = np.flatnonzero(seen)
    # a straight line through each track in front of the sensor throughout (elsewhere its
    # positions are NaN), all of them in one least-squares solve
    vxs, vys = np.zeros(seen_j.size), np.zeros(seen_j.size)
    x0s, y0s = x[0, seen_j].copy(), y[0, seen_j].copy()
    whole = np.all(front[:, seen_j], axis=0)
    if grid.size > 1 and np.any(whole):
        fit = seen_j[whole]
        (vxs[whole], x0s[whole]), (vys[whole], y0s[whole]) = np.polyfit(tt, x[:, fit], 1), np.polyfit(tt, y[:, fit], 1)
    # each star's flux at the middle of the run (where it stands above the horizon there), in
    # one call: the extinction and the optics' conversion for every star at once
    el_mid = el[t_mid] if seen_j.size else np.zeros(0)
    up = el_mid > 0.0
    flux_mid = np.zeros(seen_j.size)
    if np.any(up):
        flux_mid[up] = np.asarray(ctx.optics.flux_from_magnitude(
            mag_v[seen_j[up]] + photometry.extinction_mag(el_mid[up], ctx.k_ext)), np.float64)
    for col, j in enumerate(seen_j):
        label = f"star {j} mag={mag_v[j]:.3f}"  # j: its place among the drawn stars, whatever is kept
        xs, ys, on = xc[:, j], yc[:, j], inside[:, j]
        el_j = el[:, col]
        if np.all(front[:, j]) and el_j[t_mid] > 0.0:
            # a straight line (or a point) through the track, if one holds it
            vx, x0, vy, y0 = vxs[col], x0s[col], vys[col], y0s[col]
            resid = np.max(np.hypot(x0 + vx * tt - x[:, j], y0 + vy * tt - y[:, j]))
            if resid <= LINEAR_TOLERANCE_PX:
                flux = float(flux_mid[col])
                if math.hypot(vx, vy) * (grid[-1] - grid[0]) <= LINEAR_TOLERANCE_PX:
                    out.append(StaticTarget(float(np.mean(x[:, j])), float(np.mean(y[:, j])), flux, label=label))
                else:
                    out.append(LinearTarget(float(x0), float(y0), float(vx), float(vy), flux, float(grid[0]), label))
                continue
        # Tabulated: the rows from one before it first comes near the sensor to one after it last leaves.
        k = np.flatnonzero(on)
        lo, hi = max(int(k[0]) - 1, 0), min(int(k[-1]) + 2, grid.size)
        visible = on[lo:hi] & (el_j[lo:hi] > 0.0)
        mag = np.where(visible, mag_v[j] + photometry.extinction_mag(np.maximum(el_j[lo:hi], 0.0), ctx.k_ext), 0.0)
        fluxes = np.where(visible, np.asarray(ctx.optics.flux_from_magnitude(mag), np.float64), 0.0)
        if not np.any(fluxes > 0.0):
            continue
        out.append(TabulatedTarget(grid[lo:hi], xs[lo:hi], ys[lo:hi], LightCurve(grid[lo:hi], fluxes),
                                   outside="hold", label=label))
    return out


# -- the whole sky ----------------------------------------------------------------------------


def _grid(t_end: float, n: int) -> np.ndarray:
    return np.linspace(0.0, t_end, n + 1)


def _interp_error(grid_vals: np.ndarray, mid_vals: np.ndarray, mask: np.ndarray) -> float:
    """Largest |midpoint - mean of its two table neighbours| where mask (N-1, S) is set."""
    est = 0.5 * (grid_vals[1:] + grid_vals[:-1])
    err = np.abs(est - mid_vals)
    err = np.where(mask & np.isfinite(err), err, 0.0)
    return float(err.max(initial=0.0))


def build_sky(s: dict[str, Any], optics: Optics, width: int, height: int, t_end: float,
              margin_px: float) -> SkyTargets:
    """The satellites and stars of a resolved scenario ``s`` (see the module doc) on a
    width x height sensor over [0, t_end] s; positions more than margin_px outside the sensor
    are clamped. ValueError naming the key on bad input."""
    if "pointing" not in s:
        raise ValueError(f"{_placed_by(s)} place objects on the sky, which needs [pointing] (mode = staring | "
                         "sidereal | target | table)")
    ctx = _Context(s, optics, width, height, t_end, margin_px)
    sats = _satellites(s)
    p = dict(s["pointing"])
    step0 = float(p.get("step_s", min(1.0, t_end / 16.0) if t_end > 0 else 1.0))
    if not step0 > 0.0:
        raise ValueError(f"pointing.step_s must be > 0; got {p.get('step_s')!r}")

    # Every satellite must rise at some point of the run (checked on a coarse grid first).
    coarse = _grid(t_end, 64)
    for sat in sats:
        obs = orbit.observe(sat.elements, ctx.site, ctx.start, coarse, ctx.ut1_utc_s)
        if np.all(obs.el_deg < 0.0):
            el, when = orbit.max_elevation(obs)
            raise ValueError(
                f"targets[{sat.index}] ({sat.label}) is below the horizon for the whole run: highest elevation "
                f"{el:.2f} deg at t={when:g} s from start_utc={s['start_utc']!r} at site lat_deg="
                f"{ctx.site.lat_deg:g}, lon_deg={ctx.site.lon_deg:g}")
    coarse_att = _attitude(ctx, p, sats, coarse)

    sf = dict(s.get("star_field", {}))
    for key in ("distribution", "density_scale", "path"):
        if key in sf:  # not drawn on the sky yet: refuse rather than ignore
            raise ValueError(f"star_field.{key} does not apply with a [pointing] (its stars are drawn on the sky from "
                             f"n_stars or density_per_deg2, mag_min, mag_max, counts_slope and seed); got "
                             f"star_field.{key}={sf[key]!r}")
    directions, mag_v = np.zeros((0, 3)), np.zeros(0)
    if "n_stars" in sf or "density_per_deg2" in sf:
        for key in ("drift_px_s", "drift_arcsec_s"):
            if key in sf:
                raise ValueError(f"star_field.{key} does not apply with a [pointing]: the pointing moves the stars")
        if "density_per_deg2" in sf:
            density = float(sf["density_per_deg2"])
        else:
            sensor_deg2 = width * height * math.degrees(ctx.k) ** 2
            density = float(sf["n_stars"]) / sensor_deg2
        if not density >= 0.0:
            raise ValueError(f"star_field density must be >= 0; got {density!r}")
        lo, hi = float(sf.get("mag_min", STAR_FIELD_MAG_MIN)), float(sf.get("mag_max", STAR_FIELD_MAG_MAX))
        if not lo <= hi:
            raise ValueError(f"need star_field.mag_min <= mag_max; got {lo!r}, {hi!r}")
        directions, mag_v = draw_sky_stars(ctx, coarse_att, density, lo, hi,
                                           float(sf.get("counts_slope", STAR_FIELD_COUNTS_SLOPE)),
                                           int(sf.get("seed", 0)))
    probe = directions
    if probe.shape[0] > _ERROR_PROBE_STARS:
        probe = probe[np.random.default_rng(0).choice(probe.shape[0], _ERROR_PROBE_STARS, replace=False)]

    # The position table: halve the step until linear interpolation holds every object near
    # the sensor within TABLE_TOLERANCE_PX at the midpoints.
    n = max(1, math.ceil(t_end / step0 - 1e-9))
    while True:
        grid = _grid(t_end, n)
        both = np.sort(np.concatenate([grid, 0.5 * (grid[1:] + grid[:-1])]))
        att = _attitude(ctx, p, sats, both)
        observations = [orbit.observe(sat.elements, ctx.site, ctx.start, both, ctx.ut1_utc_s) for sat in sats]
        xs = [project(att, obs.direction, ctx.k, ctx.centre)[:2] for obs in observations]
        sx, sy, _ = project(att, probe, ctx.k, ctx.centre)
        error = 0.0
        for x, y in [(a[:, None], b[:, None]) for a, b in xs] + [(sx, sy)]:
            g, m = slice(0, None, 2), slice(1, None, 2)
            near = ctx.in_box(x[g][1:], y[g][1:]) | ctx.in_box(x[g][:-1], y[g][:-1])
            error = max(error, _interp_error(x[g], x[m], near), _interp_error(y[g], y[m], near))
        if error <= TABLE_TOLERANCE_PX:
            break
        if 2 * n + 1 > MAX_TABLE_POINTS:
            raise ValueError(f"the sky's position tables would need more than {MAX_TABLE_POINTS} points to follow "
                             f"the motion within {TABLE_TOLERANCE_PX} px over duration_s={t_end:g} (still "
                             f"{error:.3g} px off at {n} points): shorten the run or slow the pointing")
        n *= 2
    g = slice(0, None, 2)
    att_grid = Attitude(grid, att.b[g], att.e_x[g], att.e_y[g])

    satellites: list[Target] = []
    info: dict[str, Any] = {"table_step_s": float(grid[1] - grid[0]) if grid.size > 1 else 0.0,
                            "table_error_px": error, "satellites": []}
    for sat, obs_both, (x_both, y_both) in zip(sats, observations, xs):
        obs = orbit.observe(sat.elements, ctx.site, ctx.start, grid, ctx.ut1_utc_s)
        x, y = x_both[g], y_both[g]
        xc, yc = ctx.clamp(x, y)
        near = ctx.in_box(x, y)
        mag_top = _magnitude_above_atmosphere(sat, obs)
        lit = (~obs.in_shadow) & (obs.el_deg > 0.0) & np.isfinite(mag_top)
        mag = np.where(lit, mag_top + photometry.extinction_mag(np.maximum(obs.el_deg, 0.0), ctx.k_ext), 99.0)
        flux = np.where(lit & near, np.asarray(optics.flux_from_magnitude(np.where(lit, mag, 99.0)), np.float64), 0.0)
        satellites.append(TabulatedTarget(grid, xc, yc, LightCurve(grid, flux), label=sat.label))
        rate = orbit.angular_rate_deg_s(obs)
        info["satellites"].append({
            "label": sat.label, "max_el_deg": float(obs.el_deg.max()), "min_range_km": float(obs.range_km.min()),
            "mag_min": float(mag[lit].min()) if lit.any() else math.inf,
            "mag_max": float(mag[lit].max()) if lit.any() else math.inf,
            "sunlit_fraction": float(np.mean(~obs.in_shadow)), "on_sensor_fraction": float(np.mean(near)),
            "max_rate_deg_s": float(rate.max()) if rate.size else 0.0})
    stars = stars_to_targets(ctx, grid, att_grid, directions, mag_v)
    info["stars_drawn"] = int(directions.shape[0])
    info["stars_kept"] = len(stars)
    info["sun_el_deg"] = float(orbit.sun_elevation_deg(ctx.site, ctx.start, 0.0)[0])
    info["ut1_utc_s"] = ctx.ut1_utc_s
    info["ut1_utc_from"] = ctx.ut1_utc_from
    return SkyTargets(satellites, stars, info)


__all__ = ["build_sky", "uses_sky", "SkyTargets", "draw_sky_stars", "stars_to_targets", "unproject",
           "DEFAULT_EXTINCTION", "SITE_KEYS", "POINTING_KEYS", "TLE_KEYS"]
