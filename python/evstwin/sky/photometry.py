"""The brightness of real objects: a satellite as a diffuse sphere lit by the Sun, and the
atmosphere's extinction by airmass (for satellites and stars alike).

Magnitudes are Johnson V, the band of ``evstwin.optics``' default zero point; they become
photons/s through ``Optics.flux_from_magnitude``.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

SUN_V_MAG = -26.76
"""Apparent V magnitude of the Sun at 1 AU (Willmer 2018, ApJS 236, 47, Table 3: -26.76;
-26.74 in older compilations such as Allen's Astrophysical Quantities)."""


def lambert_phase_function(phase_rad: npt.ArrayLike) -> np.ndarray:
    """Phase law of a diffusely (Lambert) reflecting sphere, 1 at zero phase:
    ``[sin p + (pi - p) cos p] / pi`` (Russell 1916, ApJ 43, 173; the law used for spherical
    satellites by e.g. McCue, Williams & Morford 1971, Planet. Space Sci. 19, 851, and Hejduk
    2011, AMOS "Specular and diffuse components in spherical satellite photometric
    modeling"). p in [0, pi]."""
    p = np.clip(np.asarray(phase_rad, np.float64), 0.0, math.pi)
    return (np.sin(p) + (math.pi - p) * np.cos(p)) / math.pi


def diffuse_sphere_magnitude(
    diameter_m: npt.ArrayLike,
    albedo: npt.ArrayLike,
    range_km: npt.ArrayLike,
    phase_rad: npt.ArrayLike,
    sun_distance_au: npt.ArrayLike = 1.0,
) -> np.ndarray:
    """V magnitude of a Lambertian sphere lit by the Sun.

    The sphere (radius a = diameter / 2, Lambert reflectance = Bond albedo A) has geometric
    albedo p = 2 A / 3, so the flux it sends to an observer at range R and phase angle phase
    is ``F / F_sun = (2 A / 3) (a / R)^2 * lambert_phase_function(phase)``, i.e.

        m = SUN_V_MAG - 2.5 log10( 2 A a^2 / (3 pi R^2) [sin p + (pi - p) cos p] )
            + 5 log10(sun distance / 1 AU).

    (Hejduk 2011, eq. 3; McCue et al. 1971.) At zero phase (p = 0) the sun is behind the
    observer; at p = pi the sphere shows its dark side (no light; rounding leaves > 40 mag).
    """
    a_m = 0.5 * np.asarray(diameter_m, np.float64)
    rho = np.asarray(albedo, np.float64)
    r_m = 1000.0 * np.asarray(range_km, np.float64)
    ratio = (2.0 / 3.0) * rho * (a_m / r_m) ** 2 * lambert_phase_function(phase_rad)
    with np.errstate(divide="ignore"):
        return SUN_V_MAG - 2.5 * np.log10(ratio) + 5.0 * np.log10(np.asarray(sun_distance_au, np.float64))


def airmass_kasten_young(elevation_deg: npt.ArrayLike) -> np.ndarray:
    """Relative optical airmass at an (apparent) elevation [deg] by Kasten & Young (1989),
    Applied Optics 28, 4735, eq. 3:

        X = 1 / [cos z + 0.50572 (96.07995 deg - z)^-1.6364],  z = 90 deg - elevation

    (z in degrees inside the bracket). 1 at the zenith, 37.9 at the horizon, within 0.1 % of
    the refraction-integrated airmass above 5 deg elevation; defined for elevation >= 0 only
    (ValueError below the horizon)."""
    el = np.asarray(elevation_deg, np.float64)
    if np.any(el < 0.0) or not np.all(np.isfinite(el)):
        bad = el[~(el >= 0.0)].ravel()[0]
        raise ValueError(f"airmass needs an elevation in [0, 90] deg; got {bad!r}")
    z = 90.0 - np.minimum(el, 90.0)
    return 1.0 / (np.cos(np.radians(z)) + 0.50572 * (96.07995 - z) ** -1.6364)


def extinction_mag(elevation_deg: npt.ArrayLike, k_mag_per_airmass: float) -> np.ndarray:
    """Atmospheric extinction [mag] at an elevation: ``k X`` with X the Kasten & Young
    airmass (Bouguer's law). Typical V-band k: 0.12-0.2 at a good mountain site (e.g. 0.11-0.13
    at La Palma, King 1985 RGO/La Palma tech. note 31), 0.25-0.3 near sea level."""
    return float(k_mag_per_airmass) * airmass_kasten_young(elevation_deg)
