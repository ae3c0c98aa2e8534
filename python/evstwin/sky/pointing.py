"""Where the camera looks: pointing modes, the camera's attitude over time, and the gnomonic
projection of sky directions onto the sensor.

Modes (``[pointing] mode``):

* ``staring``: fixed in azimuth/elevation (a camera on a fixed mount). The sky turns past it
  at the Earth's rate, so a star at declination dec drifts at 15.04 arcsec/s x cos(dec).
* ``sidereal``: fixed in right ascension/declination (a mount tracking the stars). Stars
  stay put; satellites streak.
* ``target``: the boresight follows a satellite's predicted direction (a mount driven from
  its elements). The satellite stays at the centre; stars streak.
* ``table``: the boresight from a table of times and (az, el) or (RA, Dec), interpolated
  along the great circle between rows (linear in the unit vector, renormalised).

Field rotation is modelled, not ignored: the camera's "up" (the -y direction of the image)
is the projection on the image plane of a reference direction, ``up = "zenith"`` (an
alt-azimuth mount: the image rotates against the stars as the parallactic angle changes) or
``up = "north"`` (the celestial pole: an equatorial mount, no field rotation). Defaults:
``north`` for sidereal tracking (what an equatorial mount does), ``zenith`` otherwise (a fixed
camera, and the alt-az mounts that slew fast enough to follow a LEO). ``roll_deg`` turns the
sensor about the boresight from there (positive turns the image's +x axis towards +y).

Projection: a sky direction d (unit vector, sky frame of ``evstwin.sky.earth``) lands at
``x = cx + (d.e_x)/(d.b) / k``, ``y = cy + (d.e_y)/(d.b) / k`` [px] with b the boresight, e_x
and e_y the image axes on the sky, (cx, cy) the sensor centre and k the plate scale
``Optics.plate_scale_rad_per_px`` (pitch / focal length): the gnomonic (tangent-plane)
projection, which is what a distortion-free lens does (``Optics.project_to_px`` is the same
pinhole). The image is as seen on the sky from behind the camera (north up, east left when
looking south with up = zenith), not mirrored.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
import numpy.typing as npt

Up = Literal["zenith", "north"]
MODES = ("staring", "sidereal", "target", "table")
UPS = ("zenith", "north")
MIN_UP_SINE = 1e-3
"""The reference "up" must make at least this sine (0.06 deg) with the boresight, or the
image's orientation is undefined (pointing at the zenith with up = "zenith", at the pole
with up = "north")."""
FRONT_COS = math.cos(math.radians(80.0))
"""Directions more than 80 deg from the boresight are not projected (tan 80 = 5.7 focal
lengths off-axis, far outside any sensor): they are reported as behind the camera."""


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


@dataclass(frozen=True)
class Attitude:
    """The camera's axes in the sky frame at times ``t_s`` [s]: boresight ``b``, image +x
    ``e_x`` and image +y ``e_y`` (each (N, 3), orthonormal, e_x x e_y = b)."""

    t_s: np.ndarray
    b: np.ndarray
    e_x: np.ndarray
    e_y: np.ndarray

    @classmethod
    def from_boresight(cls, t_s: npt.ArrayLike, boresight: np.ndarray, up_reference: np.ndarray,
                       roll_deg: float = 0.0, what: str = "the pointing") -> Attitude:
        """From boresight unit vectors (N, 3) and reference "up" vectors (N, 3) (zenith or
        pole), with the sensor turned by roll_deg about the boresight."""
        t = np.atleast_1d(np.asarray(t_s, np.float64))
        b = _unit(np.broadcast_to(np.asarray(boresight, np.float64), t.shape + (3,)))
        ref = np.broadcast_to(np.asarray(up_reference, np.float64), b.shape)
        up = ref - np.sum(ref * b, axis=-1, keepdims=True) * b
        norm = np.linalg.norm(up, axis=-1)
        if np.any(norm < MIN_UP_SINE * np.linalg.norm(ref, axis=-1)):
            k = int(np.argmin(norm))
            raise ValueError(f"{what} points along its 'up' reference at t={t[k]:g} s (the zenith with "
                             "up='zenith', or the celestial pole with up='north'): the image's orientation is "
                             "undefined; use the other pointing.up")
        up = up / norm[:, None]
        e_y = -up
        e_x = np.cross(b, up)
        if roll_deg:
            c, s = math.cos(math.radians(roll_deg)), math.sin(math.radians(roll_deg))
            e_x, e_y = c * e_x + s * e_y, -s * e_x + c * e_y
        return cls(t, b, e_x, e_y)


def project(attitude: Attitude, directions: np.ndarray, plate_scale_rad_per_px: float,
            centre_px: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gnomonic projection of sky directions onto the sensor.

    directions: (N, 3) (one object, one direction per attitude time), (N, S, 3) (S objects
    moving) or (S, 3) fixed directions (stars), N the attitude's times. Returns x, y [px] and
    ``front`` (True where the direction is within 80 deg of the boresight), each (N,) or
    (N, S); x and y are NaN where not in front."""
    d = np.asarray(directions, np.float64)
    n = attitude.t_s.size
    if d.ndim == 2 and d.shape[0] == n and n != 1 and d.shape != (n, 3):
        raise ValueError(f"directions of shape {d.shape} do not match {n} attitude times")
    b, ex, ey = attitude.b, attitude.e_x, attitude.e_y
    if d.ndim == 2 and d.shape[0] != n:  # fixed directions (S, 3): (N, S) dot products
        db, dx, dy = b @ d.T, ex @ d.T, ey @ d.T
    elif d.ndim == 2:  # one object, (N, 3)
        db, dx, dy = (np.sum(d * v, axis=-1) for v in (b, ex, ey))
    else:  # (N, S, 3)
        db, dx, dy = (np.einsum("nsk,nk->ns", d, v) for v in (b, ex, ey))
    front = db > FRONT_COS
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.where(front, centre_px[0] + dx / db / plate_scale_rad_per_px, np.nan)
        y = np.where(front, centre_px[1] + dy / db / plate_scale_rad_per_px, np.nan)
    return x, y, front


def unproject(attitude: Attitude, x_px: npt.ArrayLike, y_px: npt.ArrayLike, plate_scale_rad_per_px: float,
              centre_px: tuple[float, float], index: int = 0) -> np.ndarray:
    """Sky directions (..., 3) of pixel positions at the attitude's time ``index``: the
    inverse of :func:`project`."""
    x = (np.asarray(x_px, np.float64) - centre_px[0]) * plate_scale_rad_per_px
    y = (np.asarray(y_px, np.float64) - centre_px[1]) * plate_scale_rad_per_px
    b, ex, ey = attitude.b[index], attitude.e_x[index], attitude.e_y[index]
    return _unit(b + x[..., None] * ex + y[..., None] * ey)


def field_rotation_rate_rad_s(lat_deg: float, az_deg: npt.ArrayLike, el_deg: npt.ArrayLike) -> np.ndarray:
    """The rate at which the sky turns about the boresight of an alt-azimuth camera [rad/s]:
    ``omega_E cos(lat) cos(az) / cos(el)`` (the derivative of the parallactic angle; e.g.
    Keicher, "Field rotation in alt-az mounts"; Meeus, *Astronomical Algorithms*, ch. 14, by
    differentiation). Used by the tests as an independent check of the modelled rotation."""
    from .earth import EARTH_ROTATION_RAD_S

    az, el = np.radians(np.asarray(az_deg, np.float64)), np.radians(np.asarray(el_deg, np.float64))
    return EARTH_ROTATION_RAD_S * math.cos(math.radians(lat_deg)) * np.cos(az) / np.cos(el)
