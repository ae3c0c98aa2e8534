"""Physical constants and unit conversions: each defined once, here, and imported by name.

SI 2019 exact values where they exist. Names carry their units (``_J_S`` joule seconds,
``_M_S`` metres per second); a conversion factor is named ``<UNIT>_PER_<UNIT>``: multiply a
value in the second unit by it to get the first (``angle_arcsec = angle_rad * ARCSEC_PER_RAD``).
The elementary charge is the engine's (``evstwin._core``), so the C++ and Python halves use one
value.
"""

from __future__ import annotations

import math

from ._core import ELEMENTARY_CHARGE_C

PLANCK_J_S = 6.62607015e-34
"""Planck constant h [J s] (exact, SI 2019)."""
SPEED_OF_LIGHT_M_S = 299792458.0
"""Speed of light c [m/s] (exact)."""
BOLTZMANN_J_K = 1.380649e-23
"""Boltzmann constant k_B [J/K] (exact, SI 2019)."""
JANSKY_W_M2_HZ = 1e-26
"""1 Jy in W m^-2 Hz^-1."""

ARCSEC_PER_DEG = 3600.0
"""Arcseconds per degree."""
DEG_PER_RAD = 180.0 / math.pi
"""Degrees per radian (57.2957...)."""
ARCSEC_PER_RAD = 180.0 * 3600.0 / math.pi
"""Arcseconds per radian (206264.806...)."""
RAD_PER_ARCSEC = math.pi / (180.0 * 3600.0)
"""Radians per arcsecond (4.848e-6): ``1 / ARCSEC_PER_RAD``."""

__all__ = [
    "ARCSEC_PER_DEG",
    "ARCSEC_PER_RAD",
    "BOLTZMANN_J_K",
    "DEG_PER_RAD",
    "ELEMENTARY_CHARGE_C",
    "JANSKY_W_M2_HZ",
    "PLANCK_J_S",
    "RAD_PER_ARCSEC",
    "SPEED_OF_LIGHT_M_S",
]
