"""Targets: where point sources are on the sensor [px] and how bright they are [photons/s].

Every target answers, for an array of times ``t_s`` [s]:

* ``position_px(t_s) -> (x, y)``: arrays shaped like ``t_s``, pixel coordinates (centres at
  integers, x right, y down: see ``optics``);
* ``velocity_px_s(t_s) -> (vx, vy)`` [px/s];
* ``flux_ph_s(t_s)``: photons/s at the focal plane (before fill factor and QE);
* ``max_speed_px_s(t0_s, t1_s)``: the largest speed on [t0, t1] [px/s], to choose the sample
  rate so that no target moves more than a fraction of a pixel between samples
  (docs/development/decisions.md, "Sampling never skips a track's pixels").

Brightness is a constant flux [photons/s] or a ``LightCurve`` (a table of times and fluxes,
or of magnitudes through an ``Optics``: a tumbling satellite). For a constant magnitude use
``optics.flux_from_magnitude(mag)``.

Positions are unbounded: a target may leave the sensor (the renderer then skips it).

A star field that drifts across the sensor (a telescope's tracking error, a staring camera)
moves every star at once: ``random_star_field(..., drift_px_s=(vx, vy), duration_s=D)``
gives LinearTargets, including the stars that drift in during the run, and ``drifting(target,
vx, vy)`` carries any target given in field coordinates along with the field.
"""


from __future__ import annotations

from .base import Brightness, LightCurve, Outside, Target, max_speed_px_s, mean_flux_ph_s, sample_targets
from .kinds import (
    CircularTarget,
    LinearTarget,
    StaticTarget,
    TabulatedTarget,
    aligned_rotating_targets,
    drift_px_s_from_arcsec,
)
from .star_field import MAX_STARS, random_star_field
from .wrappers import (
    DriftingTarget,
    FieldPath,
    MirroredTarget,
    PathTarget,
    SteadyTarget,
    adopt,
    along_path,
    drifting,
    psf_groups,
    shifted,
    with_psf,
)

__all__ = [
    "MAX_STARS",
    "Brightness",
    "CircularTarget",
    "DriftingTarget",
    "FieldPath",
    "LightCurve",
    "LinearTarget",
    "MirroredTarget",
    "Outside",
    "PathTarget",
    "StaticTarget",
    "SteadyTarget",
    "TabulatedTarget",
    "Target",
    "adopt",
    "aligned_rotating_targets",
    "along_path",
    "drift_px_s_from_arcsec",
    "drifting",
    "max_speed_px_s",
    "mean_flux_ph_s",
    "psf_groups",
    "random_star_field",
    "sample_targets",
    "shifted",
    "with_psf",
]
