"""Time, the rotating Earth, an observer's site and the Sun: what turns a satellite's orbit
into a direction in an observer's sky, by standard published formulas, offline.

Frames and time (why these formulas and not a library)
-------------------------------------------------------
SGP4 gives positions in TEME, the "true equator, mean equinox" frame of its own epoch of
date. Following Vallado, Crawford, Hujsak & Kelso, "Revisiting Spacetrack Report #3"
(AIAA 2006-6753, sec. "Coordinate systems" and its appendix C), TEME becomes the pseudo
Earth-fixed frame (PEF) by one rotation about z by the Greenwich mean sidereal time of the
IAU 1982 expression (Vallado, *Fundamentals of Astrodynamics and Applications*, 4th ed.,
eq. 3-45/3-47). That is the whole chain here:

* **Earth rotation**: GMST (IAU 1982) from UT1; UT1 = UTC + ``ut1_utc_s`` (a scene takes it
  from the IERS table, :mod:`evstwin.sky.iers`, unless ``site.ut1_utc_s`` is set; leap
  seconds keep it below 0.9 s, but 0.9 s of rotation moves a site by up to 420 m, a few
  arcminutes at a LEO's range, and 0.12 s already 24 arcsec). Polar motion is ignored (PEF
  taken as ITRF: about 0.3 arcsec, 10 m on the ground).
* **The sky frame** is TEME itself: directions of satellites, the pointing and the stars are
  all given in it, so they agree with each other exactly. It is the equator of date with the
  mean equinox of date, which differs from a J2000/ICRS catalogue by precession (0.36 deg
  between 2000 and 2026) and from "true of date" by the equation of the equinoxes (< 1.2 s of
  right ascension). Annual and diurnal aberration and atmospheric refraction are ignored:
  each shifts every object in a small field by nearly the same angle.
* **The Sun** (for the phase angle and the Earth's shadow): the low-precision formula of the
  *Astronomical Almanac* (section C, "Low precision formulas for the Sun"), good to 0.01 deg
  between 1950 and 2050, with UT in place of TT (the 69 s difference moves the Sun by
  0.003 deg).

The accuracy that matters is the elements': a TLE is good to about 1 km at its epoch and
drifts by kilometres per day (Vallado et al. 2006), i.e. arcminutes for a LEO, far more than
any of the approximations above. astropy would do the frames to milliarcseconds, but its
IERS tables go stale for future dates (and then it warns or downloads), it weighs ~40 MB with
pyerfa, and buys nothing against the elements' own error; skyfield needs a downloaded JPL
ephemeris for the Sun. These formulas run offline, vectorised over time, and are tested
against published values (``tests/python/test_sky_orbit.py``).

Units: kilometres for positions (SGP4's), radians inside, degrees at the edges (names say).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone

import numpy as np
import numpy.typing as npt

from .._checks import finite

WGS84_A_KM = 6378.137
"""WGS-84 equatorial radius [km] (NIMA TR8350.2)."""
WGS84_F = 1.0 / 298.257223563
"""WGS-84 flattening."""
EARTH_RADIUS_KM = WGS84_A_KM
"""Radius of the Earth's shadow cylinder [km] (the equatorial radius)."""
EARTH_ROTATION_RAD_S = 7.292115146706979e-5
"""Earth's sidereal rotation rate [rad/s] (Vallado eq. 3-40, 1.00273790935 turns per solar
day): 15.041 arcsec/s, the rate at which stars drift past a camera fixed to the ground."""
AU_KM = 149597870.7
"""Astronomical unit [km] (IAU 2012)."""
JD_J2000 = 2451545.0
"""Julian date of J2000.0 (2000 Jan 1 12h)."""
SECONDS_PER_DAY = 86400.0

_UTC_PATTERN = re.compile(r"^\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}(:\d{2}(\.\d+)?)?(Z|[+-]00:00)?$")


def parse_utc(text: str) -> datetime:
    """An ISO 8601 UTC time ("2014-01-23T11:18:07Z", seconds optional, "Z" or "+00:00" or
    none) as an aware datetime; ValueError naming the text otherwise."""
    if not isinstance(text, str) or not _UTC_PATTERN.match(text.strip()):
        raise ValueError(f"must be a UTC time like '2014-01-23T11:18:07Z'; got {text!r}")
    clean = text.strip().replace(" ", "T").replace("Z", "+00:00")
    if not clean.endswith("+00:00"):
        clean += "+00:00"
    try:
        return datetime.fromisoformat(clean).astimezone(timezone.utc)
    except ValueError as exc:  # 2014-02-30
        raise ValueError(f"is not a valid date and time ({exc}); got {text!r}") from None


def julian_date(when: datetime) -> tuple[float, float]:
    """(whole, fraction) Julian date of an aware UTC datetime, split to keep microseconds
    (Vallado algorithm 14 via the proleptic Gregorian ordinal)."""
    if when.tzinfo is None:
        raise ValueError(f"needs a time zone (UTC); got naive {when!r}")
    w = when.astimezone(timezone.utc)
    midnight = datetime(w.year, w.month, w.day, tzinfo=timezone.utc)
    # JD of 0001-01-01 00:00 (ordinal 1) is 1721425.5.
    jd0 = midnight.toordinal() + 1721424.5
    fr = (w - midnight) / timedelta(days=1)
    return jd0, fr


def gmst_rad(jd_ut1: npt.ArrayLike) -> np.ndarray:
    """Greenwich mean sidereal time [rad] of the IAU 1982 model (Vallado eq. 3-47):
    ``67310.54841 s + (876600 h + 8640184.812866 s) T + 0.093104 s T^2 - 6.2e-6 s T^3``, T in
    Julian centuries of UT1 from J2000.0. ``jd_ut1`` is the full Julian date (UT1)."""
    t = (np.asarray(jd_ut1, np.float64) - JD_J2000) / 36525.0
    seconds = 67310.54841 + (876600.0 * 3600.0 + 8640184.812866) * t + 0.093104 * t * t - 6.2e-6 * t**3
    return np.mod(seconds, SECONDS_PER_DAY) / SECONDS_PER_DAY * 2.0 * math.pi


def rotate_z(angle_rad: npt.ArrayLike, vectors: np.ndarray) -> np.ndarray:
    """Coordinates of ``vectors`` (..., 3) in a frame turned by ``angle_rad`` about z
    (the ROT3 of Vallado): x' = cos a x + sin a y, y' = -sin a x + cos a y."""
    a = np.asarray(angle_rad, np.float64)[..., None]
    c, s = np.cos(a[..., 0]), np.sin(a[..., 0])
    x, y, z = vectors[..., 0], vectors[..., 1], vectors[..., 2]
    return np.stack([c * x + s * y, -s * x + c * y, np.broadcast_to(z, np.broadcast(x, c).shape)], axis=-1)


@dataclass(frozen=True)
class Site:
    """An observer on the WGS-84 ellipsoid.

    lat_deg: geodetic latitude [deg], in [-90, 90]; lon_deg: longitude east [deg], in
    [-180, 360); alt_m: height above the ellipsoid [m], in [-500, 1e5].
    """

    lat_deg: float
    lon_deg: float
    alt_m: float = 0.0

    def __post_init__(self) -> None:
        for name, lo, hi in (("lat_deg", -90.0, 90.0), ("lon_deg", -180.0, 360.0), ("alt_m", -500.0, 1e5)):
            raw = getattr(self, name)
            v = finite(name, raw)
            if not lo <= v <= hi or (name == "lon_deg" and v == 360.0):
                bracket = ")" if name == "lon_deg" else "]"
                raise ValueError(f"{name} must be in [{lo:g}, {hi:g}{bracket}; got {name}={raw!r}")

    @property
    def ecef_km(self) -> np.ndarray:
        """Earth-fixed position [km] (Vallado algorithm 51, geodetic to ECEF)."""
        phi, lam = math.radians(self.lat_deg), math.radians(self.lon_deg)
        e2 = WGS84_F * (2.0 - WGS84_F)
        n = WGS84_A_KM / math.sqrt(1.0 - e2 * math.sin(phi) ** 2)
        h = self.alt_m / 1000.0
        return np.array([(n + h) * math.cos(phi) * math.cos(lam), (n + h) * math.cos(phi) * math.sin(lam),
                         (n * (1.0 - e2) + h) * math.sin(phi)])

    @property
    def enu_axes(self) -> np.ndarray:
        """Unit vectors east, north, up (rows) of the local horizon, in Earth-fixed axes."""
        phi, lam = math.radians(self.lat_deg), math.radians(self.lon_deg)
        east = [-math.sin(lam), math.cos(lam), 0.0]
        north = [-math.sin(phi) * math.cos(lam), -math.sin(phi) * math.sin(lam), math.cos(phi)]
        up = [math.cos(phi) * math.cos(lam), math.cos(phi) * math.sin(lam), math.sin(phi)]
        return np.array([east, north, up])


def teme_to_pef(vectors_teme: np.ndarray, jd_ut1: npt.ArrayLike) -> np.ndarray:
    """TEME coordinates (..., 3) to the pseudo Earth-fixed frame at each UT1 Julian date:
    one rotation by GMST (Vallado et al. 2006, appendix C)."""
    return rotate_z(gmst_rad(jd_ut1), vectors_teme)


def pef_to_teme(vectors_pef: np.ndarray, jd_ut1: npt.ArrayLike) -> np.ndarray:
    """The inverse of :func:`teme_to_pef`."""
    return rotate_z(-gmst_rad(jd_ut1), vectors_pef)


def az_el_from_enu(enu: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth (from north through east) and elevation [deg] of east/north/up vectors (..., 3)."""
    e, n, u = enu[..., 0], enu[..., 1], enu[..., 2]
    az = np.degrees(np.arctan2(e, n)) % 360.0
    el = np.degrees(np.arctan2(u, np.hypot(e, n)))
    return az, el


def enu_from_az_el(az_deg: npt.ArrayLike, el_deg: npt.ArrayLike) -> np.ndarray:
    """Unit east/north/up vectors (..., 3) of azimuths and elevations [deg]."""
    az, el = np.radians(np.asarray(az_deg, np.float64)), np.radians(np.asarray(el_deg, np.float64))
    return np.stack(np.broadcast_arrays(np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)), axis=-1)


def ra_dec_from_vector(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Right ascension in [0, 360) and declination [deg] of vectors (..., 3) in the sky frame."""
    ra = np.degrees(np.arctan2(v[..., 1], v[..., 0])) % 360.0
    dec = np.degrees(np.arctan2(v[..., 2], np.hypot(v[..., 0], v[..., 1])))
    return ra, dec


def vector_from_ra_dec(ra_deg: npt.ArrayLike, dec_deg: npt.ArrayLike) -> np.ndarray:
    """Unit vectors (..., 3) in the sky frame of right ascensions and declinations [deg]."""
    ra, dec = np.radians(np.asarray(ra_deg, np.float64)), np.radians(np.asarray(dec_deg, np.float64))
    return np.stack(np.broadcast_arrays(np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)), axis=-1)


def sun_teme_km(jd_ut: npt.ArrayLike) -> np.ndarray:
    """The Sun's geocentric position (..., 3) [km], equator and equinox of date.

    *Astronomical Almanac*, section C, "Low precision formulas for the Sun" (also Vallado
    algorithm 29): mean longitude L = 280.460 + 0.9856474 n, mean anomaly g = 357.528 +
    0.9856003 n, ecliptic longitude L + 1.915 sin g + 0.020 sin 2g, obliquity 23.439 -
    0.0000004 n, distance 1.00014 - 0.01671 cos g - 0.00014 cos 2g AU, n = JD - 2451545.0.
    Accurate to 0.01 deg in 1950-2050; its equinox is that of date (the mean equinox to
    this accuracy, i.e. TEME's)."""
    n = np.asarray(jd_ut, np.float64) - JD_J2000
    mean_lon = np.radians(np.mod(280.460 + 0.9856474 * n, 360.0))
    g = np.radians(np.mod(357.528 + 0.9856003 * n, 360.0))
    lam = mean_lon + np.radians(1.915) * np.sin(g) + np.radians(0.020) * np.sin(2.0 * g)
    eps = np.radians(23.439 - 0.0000004 * n)
    r_km = (1.00014 - 0.01671 * np.cos(g) - 0.00014 * np.cos(2.0 * g)) * AU_KM
    return np.stack([r_km * np.cos(lam), r_km * np.cos(eps) * np.sin(lam), r_km * np.sin(eps) * np.sin(lam)], axis=-1)


def in_earth_shadow(r_teme_km: np.ndarray, sun_teme_km_: np.ndarray) -> np.ndarray:
    """True where a satellite at r (..., 3) [km] is in the Earth's shadow: the cylindrical
    model (Vallado algorithm 34 without the penumbra cone: a satellite on the night side
    whose distance from the Earth-Sun line is under one Earth radius). The penumbra, ~10 s of
    a LEO's eclipse entry, is a sharp step here."""
    s_hat = sun_teme_km_ / np.linalg.norm(sun_teme_km_, axis=-1, keepdims=True)
    along = np.sum(r_teme_km * s_hat, axis=-1)
    perp = np.linalg.norm(r_teme_km - along[..., None] * s_hat, axis=-1)
    return (along < 0.0) & (perp < EARTH_RADIUS_KM)
