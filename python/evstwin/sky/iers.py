"""UT1 - UTC from the IERS Earth-orientation table that ``astropy-iers-data`` ships.

The Earth's rotation angle follows UT1, clocks follow UTC; leap seconds keep the two within
0.9 s. Left out, the difference turns the whole sky about the pole: 0.12 s in January 2014
moves a site 42 m along its parallel, 24 arcsec of azimuth and elevation on a LEO pass.

The table is the IERS ``finals2000A.all`` (daily values at 0 h UTC from 2 January 1973, with
about a year of predictions past its release) as the ``astropy-iers-data`` package ships it:
a data-only package (no code, no download at run time) that the Astropy project releases
weekly. Where the final value (IERS Bulletin B) is given it is used, else the rapid or
predicted one (Bulletin A: 0.1-1 ms, growing to ~10 ms a few months ahead). Between two days
the value is interpolated linearly, with a leap second between them taken out first.

An explicit ``site.ut1_utc_s`` in a scenario wins over the table. A ``start_utc`` outside
the table is an error that names the table's span and the key to set. Polar motion (the
pole's 0.3 arcsec wander, 10 m on the ground) is left out, as in skyfield's default.
"""

from __future__ import annotations

import functools
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

MJD_OFFSET = 2400000.5
"""Modified Julian Date = Julian Date - this [d]."""


@functools.lru_cache(maxsize=1)
def _table() -> tuple[np.ndarray, np.ndarray, str]:
    """(MJD at 0 h UTC, UT1 - UTC [s], where it comes from) of every tabulated day."""
    try:
        import astropy_iers_data
    except ImportError:
        from .._extras import MissingExtraError

        raise MissingExtraError(
            "UT1 - UTC from the IERS tables needs the 'astropy-iers-data' package (pip install "
            "astropy-iers-data), or set site.ut1_utc_s in the scenario"
        ) from None
    path = Path(astropy_iers_data.IERS_A_FILE)
    mjd: list[float] = []
    dut1: list[float] = []
    with open(path, encoding="ascii", errors="replace") as fh:
        for line in fh:
            # columns of ReadMe.finals2000A: MJD 8-15, UT1-UTC Bulletin A 59-68, Bulletin B 155-165
            final = line[154:165].strip()
            value = final or line[58:68].strip()
            if not value:
                continue  # past the predictions: the day is listed without values
            mjd.append(float(line[7:15]))
            dut1.append(float(value))
    if len(mjd) < 2:
        raise ValueError(f"{path}: no UT1 - UTC values found (not an IERS finals2000A table?)")
    version = getattr(astropy_iers_data, "__version__", "?")
    return np.asarray(mjd), np.asarray(dut1), f"IERS finals2000A.all of astropy-iers-data {version}"


def span_utc() -> tuple[datetime, datetime]:
    """First and last UTC day (0 h) with a tabulated UT1 - UTC."""
    mjd, _, _ = _table()
    return _utc_of_mjd(float(mjd[0])), _utc_of_mjd(float(mjd[-1]))


def source() -> str:
    """The table's name and package version, for reports."""
    return _table()[2]


def ut1_utc_s(when: datetime) -> float:
    """UT1 - UTC [s] at the UTC time ``when`` (a timezone-aware datetime, or naive UTC);
    ValueError outside the table, naming its span and ``site.ut1_utc_s``."""
    mjd, dut1, where = _table()
    t = _mjd_of_utc(when)
    if not mjd[0] <= t <= mjd[-1]:
        first, last = span_utc()
        raise ValueError(
            f"start_utc {when.isoformat()} is outside the UT1 - UTC table ({where}: "
            f"{first:%Y-%m-%d} to {last:%Y-%m-%d}); set site.ut1_utc_s [s] for this date "
            "(IERS Bulletin A gives it; 0 leaves the Earth's timing offset out, up to 0.9 s)"
        )
    i = int(np.searchsorted(mjd, t, side="right")) - 1
    i = min(max(i, 0), len(mjd) - 2)
    d0, d1 = float(dut1[i]), float(dut1[i + 1])
    d1 -= round(d1 - d0)  # a leap second at the end of day i: UT1 - UTC jumps by 1 s there
    frac = (t - float(mjd[i])) / (float(mjd[i + 1]) - float(mjd[i]))
    return d0 + frac * (d1 - d0)


def _mjd_of_utc(when: datetime) -> float:
    if when.tzinfo is None:
        when = when.replace(tzinfo=timezone.utc)
    epoch = datetime(1858, 11, 17, tzinfo=timezone.utc)  # MJD 0
    return (when - epoch).total_seconds() / 86400.0


def _utc_of_mjd(mjd: float) -> datetime:
    from datetime import timedelta

    return datetime(1858, 11, 17, tzinfo=timezone.utc) + timedelta(days=mjd)


__all__ = ["source", "span_utc", "ut1_utc_s"]
