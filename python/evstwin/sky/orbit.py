"""A satellite from two-line elements, propagated with SGP4, seen from a site.

Propagation is the maintained ``sgp4`` package (Brandon Rhodes' wrapper of Vallado's C++
SGP4, the version of "Revisiting Spacetrack Report #3", AIAA 2006-6753), with WGS-72
constants as the elements are fitted with them. Its positions are TEME [km]; ``evstwin.sky.earth``
turns them into the site's topocentric direction, azimuth/elevation and range.

``observe(elements, site, start, t_s)`` gives, for times t_s [s] after the UTC start, the
satellite's topocentric sky direction (TEME, unit vectors), RA/Dec, az/el [deg], range [km],
solar phase angle [rad], whether it is in the Earth's shadow, and the Sun's distance [AU].
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import datetime

import numpy as np
import numpy.typing as npt

from . import earth

_SGP4_ERRORS = {
    1: "mean eccentricity out of range",
    2: "mean motion below zero",
    3: "perturbed eccentricity out of range",
    4: "semi-latus rectum below zero",
    6: "the orbit has decayed (below the Earth's surface)",
}


@dataclass(frozen=True)
class Elements:
    """Two-line elements, checked (format and checksums) and ready for SGP4."""

    line1: str
    line2: str
    name: str = ""

    def __post_init__(self) -> None:
        from sgp4 import earth_gravity, io

        for key in ("line1", "line2"):
            if not isinstance(getattr(self, key), str):
                raise ValueError(f"{key} must be a string (a TLE line); got {getattr(self, key)!r}")
        l1, l2 = self.line1.rstrip(), self.line2.rstrip()
        object.__setattr__(self, "line1", l1)
        object.__setattr__(self, "line2", l2)
        try:
            io.twoline2rv(l1, l2, earth_gravity.wgs72)
        except ValueError as exc:
            # sgp4's message is a page (the punch-card layout): keep its first line.
            first = str(exc).strip().splitlines()[0]
            raise ValueError(f"line1/line2 are not valid two-line elements ({first}); got line1={l1!r}, "
                             f"line2={l2!r}") from None
        for key, line in (("line1", l1), ("line2", l2)):
            if len(line) >= 69 and line[68].isdigit() and _checksum(line) != int(line[68]):
                raise ValueError(f"{key} fails its checksum (column 69 is {line[68]}, the line sums to "
                                 f"{_checksum(line)}): a mistyped element; got {key}={line!r}")

    def satrec(self) -> object:
        """The sgp4 ``Satrec`` (WGS-72) of these elements."""
        from sgp4.api import WGS72, Satrec

        return Satrec.twoline2rv(self.line1, self.line2, WGS72)

    @property
    def epoch_jd(self) -> float:
        """The elements' epoch as a Julian date (UTC)."""
        sat = self.satrec()
        return float(sat.jdsatepoch + sat.jdsatepochF)  # type: ignore[attr-defined]

    @property
    def norad_id(self) -> int:
        return int(self.satrec().satnum)  # type: ignore[attr-defined]


def _checksum(line: str) -> int:
    """The TLE checksum of a line's first 68 columns: digits summed, each '-' counting 1, mod 10."""
    return sum(int(c) if c.isdigit() else (1 if c == "-" else 0) for c in line[:68]) % 10


def propagate_teme(elements: Elements, jd: npt.ArrayLike, fr: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Positions and velocities (N, 3) in TEME [km, km/s] at the Julian dates jd + fr (UTC);
    ValueError naming the first time SGP4 fails at and why."""
    sat = elements.satrec()
    jd_a = np.ascontiguousarray(np.atleast_1d(np.asarray(jd, np.float64)))
    fr_a = np.ascontiguousarray(np.broadcast_to(np.asarray(fr, np.float64), jd_a.shape))
    err, r, v = sat.sgp4_array(jd_a, fr_a)  # type: ignore[attr-defined]
    if np.any(err):
        k = int(np.flatnonzero(err)[0])
        code = int(err[k])
        days = float(jd_a[k] + fr_a[k] - elements.epoch_jd)
        raise ValueError(f"SGP4 fails {days:+.2f} days from the elements' epoch: "
                         f"{_SGP4_ERRORS.get(code, f'error {code}')} (elements {elements.line1[:24]!r}...)")
    return np.asarray(r), np.asarray(v)


@dataclass(frozen=True)
class Observation:
    """A satellite seen from a site at times ``t_s`` [s] after ``start`` (arrays over time)."""

    t_s: np.ndarray
    direction: np.ndarray
    """Unit vectors (N, 3) from the site to the satellite in the sky frame (TEME axes)."""
    ra_deg: np.ndarray
    dec_deg: np.ndarray
    """Topocentric right ascension and declination [deg], equator and mean equinox of date."""
    az_deg: np.ndarray
    el_deg: np.ndarray
    """Azimuth (north through east) and geometric elevation [deg] (no refraction)."""
    range_km: np.ndarray
    phase_rad: np.ndarray
    """Sun-satellite-observer angle [rad]: 0 = fully lit as seen from the site."""
    in_shadow: np.ndarray
    """True where the satellite is in the Earth's (cylindrical) shadow."""
    sun_distance_au: np.ndarray


def site_teme_km(site: earth.Site, jd_ut1: npt.ArrayLike) -> np.ndarray:
    """The site's geocentric position (N, 3) in TEME [km] at UT1 Julian dates."""
    jd = np.atleast_1d(np.asarray(jd_ut1, np.float64))
    return earth.pef_to_teme(np.broadcast_to(site.ecef_km, jd.shape + (3,)), jd)


def observe(elements: Elements, site: earth.Site, start: datetime, t_s: npt.ArrayLike,
            ut1_utc_s: float = 0.0) -> Observation:
    """The satellite of ``elements`` seen from ``site`` at t_s [s] after the UTC ``start``."""
    t = np.atleast_1d(np.asarray(t_s, np.float64))
    jd0, fr0 = earth.julian_date(start)
    fr = fr0 + t / earth.SECONDS_PER_DAY
    r_sat, _ = propagate_teme(elements, np.full(t.shape, jd0), fr)
    jd_ut1 = jd0 + fr + ut1_utc_s / earth.SECONDS_PER_DAY
    r_site = site_teme_km(site, jd_ut1)
    rho = r_sat - r_site
    rng = np.linalg.norm(rho, axis=-1)
    direction = rho / rng[:, None]
    ra, dec = earth.ra_dec_from_vector(direction)
    enu = earth.teme_to_pef(direction, jd_ut1) @ site.enu_axes.T
    az, el = earth.az_el_from_enu(enu)
    sun = earth.sun_teme_km(jd0 + fr)
    to_sun = sun - r_sat
    to_obs = -rho
    cos_phase = np.sum(to_sun * to_obs, axis=-1) / (np.linalg.norm(to_sun, axis=-1) * rng)
    phase = np.arccos(np.clip(cos_phase, -1.0, 1.0))
    return Observation(t_s=t, direction=direction, ra_deg=ra, dec_deg=dec, az_deg=az, el_deg=el, range_km=rng,
                       phase_rad=phase, in_shadow=earth.in_earth_shadow(r_sat, sun),
                       sun_distance_au=np.linalg.norm(to_sun, axis=-1) / earth.AU_KM)


def sun_elevation_deg(site: earth.Site, start: datetime, t_s: npt.ArrayLike = 0.0) -> np.ndarray:
    """The Sun's geometric elevation [deg] at the site (below -18: astronomical night)."""
    t = np.atleast_1d(np.asarray(t_s, np.float64))
    jd0, fr0 = earth.julian_date(start)
    jd = jd0 + fr0 + t / earth.SECONDS_PER_DAY
    sun = earth.sun_teme_km(jd) - site_teme_km(site, jd)
    enu = earth.teme_to_pef(sun, jd) @ site.enu_axes.T
    return earth.az_el_from_enu(enu)[1]


def sky_direction_from_az_el(site: earth.Site, start: datetime, t_s: npt.ArrayLike, az_deg: npt.ArrayLike,
                             el_deg: npt.ArrayLike, ut1_utc_s: float = 0.0) -> np.ndarray:
    """Sky-frame (TEME) unit vectors (N, 3) of directions fixed in the site's horizon
    (azimuth, elevation [deg]) at times t_s [s] after start: where a camera fixed to the
    ground looks among the stars."""
    t = np.atleast_1d(np.asarray(t_s, np.float64))
    jd0, fr0 = earth.julian_date(start)
    jd_ut1 = jd0 + fr0 + (t + ut1_utc_s) / earth.SECONDS_PER_DAY
    enu = np.broadcast_to(earth.enu_from_az_el(az_deg, el_deg), t.shape + (3,))
    return earth.pef_to_teme(enu @ site.enu_axes, jd_ut1)


def az_el_from_sky_direction(site: earth.Site, start: datetime, t_s: npt.ArrayLike, direction: np.ndarray,
                             ut1_utc_s: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth and elevation [deg] at the site of sky-frame unit vectors (N, 3) at times t_s."""
    t = np.atleast_1d(np.asarray(t_s, np.float64))
    jd0, fr0 = earth.julian_date(start)
    jd_ut1 = jd0 + fr0 + (t + ut1_utc_s) / earth.SECONDS_PER_DAY
    return earth.az_el_from_enu(earth.teme_to_pef(direction, jd_ut1) @ site.enu_axes.T)


def max_elevation(obs: Observation) -> tuple[float, float]:
    """(highest elevation [deg], its time [s]) over an observation."""
    k = int(np.argmax(obs.el_deg))
    return float(obs.el_deg[k]), float(obs.t_s[k])


def angular_rate_deg_s(obs: Observation) -> np.ndarray:
    """The satellite's angular rate across the sky [deg/s] between successive samples."""
    if obs.t_s.size < 2:
        return np.zeros(0)
    cosang = np.clip(np.sum(obs.direction[1:] * obs.direction[:-1], axis=-1), -1.0, 1.0)
    return np.degrees(np.arccos(cosang)) / np.diff(obs.t_s)


__all__ = ["Elements", "Observation", "observe", "propagate_teme", "sun_elevation_deg", "max_elevation",
           "angular_rate_deg_s", "sky_direction_from_az_el", "az_el_from_sky_direction", "site_teme_km"]
