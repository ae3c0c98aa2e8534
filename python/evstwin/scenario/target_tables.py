"""``[[targets]]`` tables as :class:`~evstwin.targets.Target` objects (kinds, brightness, own PSFs,
ghosts, steady halos), and the star field's drift and path, and the ROI's cut of the targets."""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any

import numpy as np

from .. import psf
from ..constants import RAD_PER_ARCSEC
from ..optics import Optics
from ..targets import (
    CircularTarget,
    FieldPath,
    LightCurve,
    LinearTarget,
    MirroredTarget,
    StaticTarget,
    SteadyTarget,
    TabulatedTarget,
    Target,
    aligned_rotating_targets,
    drift_px_s_from_arcsec,
    shifted,
    with_psf,
)
from .schema import ScenarioError, _wrap


def _roi(value: Any, width: int, height: int) -> tuple[int, int, int, int] | None:
    """sensor.roi as (x0, y0, w, h), checked against the width x height sensor."""
    if value is None:
        return None
    ok = (isinstance(value, (list, tuple)) and len(value) == 4
          and all(isinstance(v, int) and not isinstance(v, bool) for v in value))
    if not ok:
        raise ScenarioError(f"sensor.roi must be [x0, y0, width, height] in whole pixels; got {value!r}")
    x0, y0, w, h = (int(v) for v in value)
    if w < 1 or h < 1:
        raise ScenarioError(f"sensor.roi={list(value)!r} is empty: width and height must be >= 1 px")
    if x0 < 0 or y0 < 0 or x0 + w > width or y0 + h > height:
        raise ScenarioError(f"sensor.roi={list(value)!r} (columns {x0}..{x0 + w - 1}, rows {y0}..{y0 + h - 1}) "
                            f"is not inside the {width}x{height} sensor")
    return x0, y0, w, h


def _into_roi(targets: list[Target], sources: list[str], field_stars: int, roi: tuple[int, int, int, int],
              half: int, t_end: float) -> tuple[list[Target], list[str], int]:
    """The targets in the ROI's coordinates. A star field's static and linear stars whose PSF
    window never touches the ROI during the run are dropped (they would light none of its
    pixels), so the work follows the ROI, not the sensor; the named targets are all kept (their
    ground truth, in the ROI's coordinates, and the sub-sampling they set stay as on the whole
    sensor)."""
    x0, y0, w, h = roi
    n_named = len(targets) - field_stars
    out = [shifted(t, -x0, -y0) for t in targets[:n_named]]
    src = list(sources[:n_named])
    lo_x, hi_x, lo_y, hi_y = -half - 0.5, w - 0.5 + half, -half - 0.5, h - 0.5 + half
    kept = 0
    for t, source in zip(targets[n_named:], sources[n_named:]):
        t = shifted(t, -x0, -y0)
        if isinstance(t, (StaticTarget, LinearTarget)):
            xs, ys = t.position_px(np.array([0.0, t_end]))
            if max(xs) < lo_x or min(xs) > hi_x or max(ys) < lo_y or min(ys) > hi_y:
                continue  # its straight path's bounding box misses the ROI's reach
        out.append(t)
        src.append(source)
        kept += 1
    return out, src, kept


def _field_drift(s: dict[str, Any], optics: Optics) -> tuple[tuple[float, float], str]:
    """The star field's drift (vx, vy) [px/s] and the key that sets it, for messages."""
    sf = s.get("star_field", {})
    if "drift_px_s" in sf:
        v = sf["drift_px_s"]
        return (float(v[0]), float(v[1])), f"star_field.drift_px_s={v!r}"
    if "drift_arcsec_s" in sf:
        w = sf["drift_arcsec_s"]
        key = f"star_field.drift_arcsec_s={w!r}"
        vx, vy = _wrap(f"{key} through optics={s.get('optics', {})}", drift_px_s_from_arcsec, w[0], w[1], optics)
        return (vx, vy), f"{key} ({vx:.4g}, {vy:.4g} px/s at {optics.plate_scale_arcsec_per_px:.4g} arcsec/px)"
    return (0.0, 0.0), "no drift"


def _field_path(s: dict[str, Any]) -> FieldPath | None:
    """star_field.path: the field's offset against time on top of its drift (a slew), or None."""
    table = s.get("star_field", {}).get("path")
    if table is None:
        return None
    if not isinstance(table, dict):
        raise ScenarioError(f"star_field.path must be a table {{ t_s = [...], dx_px = [...], dy_px = [...] }}; "
                            f"got {table!r}")
    allowed = ("t_s", "dx_px", "dy_px")
    if set(table) != set(allowed):
        raise ScenarioError(f"star_field.path takes exactly {', '.join(allowed)} (arrays of one length); got keys "
                            f"{sorted(table)}")
    return _wrap("star_field.path", lambda: FieldPath(np.asarray(table["t_s"], float), np.asarray(table["dx_px"], float),
                                                      np.asarray(table["dy_px"], float)))


def _steady_halo(i: int, table: dict[str, Any], made: list[Target], shape: psf.PSFShape) -> list[Target]:
    """``targets[i].halo = "steady"``: the target's core follows its light curve and its
    scattered-light halo (optics.halo_fraction) keeps its mean flux: the targets rendered with
    the core, then their steady copies rendered with the halo."""
    value = table["halo"]
    if value != "steady":
        raise ScenarioError(f"targets[{i}].halo must be 'follows' (the default) or 'steady'; got {value!r}")
    if not isinstance(shape, psf.CompositePSF):
        raise ScenarioError(f"targets[{i}].halo='steady' needs a halo: set optics.halo_fraction > 0 and "
                            "optics.halo_fwhm_px")
    if "defocus_radius_px" in table:
        raise ScenarioError(f"targets[{i}].halo='steady' applies to the scene's PSF; targets[{i}] has its own "
                            "(defocus_radius_px)")
    return [with_psf(t, shape.core_part) for t in made] + [with_psf(SteadyTarget(t), shape.halo_part) for t in made]


def _psf_shape(optics: Optics, table: dict[str, Any]) -> psf.PSFShape:
    """The PSF of the scene's optics, built now so that a bad shape is a ScenarioError naming
    the optics keys (a missing psf_file, an image with NaNs, a window too large)."""
    keys = {k: v for k, v in table.items() if k == "psf" or k.startswith(("psf_", "moffat_", "spider_"))}
    return _wrap(f"optics (psf={optics.psf!r}, {keys})", psf.from_optics, optics)  # type: ignore[no-any-return]


def _brightness(table: dict[str, Any], optics: Optics) -> Any:
    if "flux_ph_s" in table:
        return float(table["flux_ph_s"])
    if "magnitude" in table:
        return float(optics.flux_from_magnitude(float(table["magnitude"])))
    lc = table["light_curve"]
    if not isinstance(lc, dict) or "t_s" not in lc or len({"flux_ph_s", "magnitude"} & set(lc)) != 1:
        raise ValueError("light_curve must be a table with t_s and one of flux_ph_s or magnitude")
    extra = {k: v for k, v in lc.items() if k not in ("t_s", "flux_ph_s", "magnitude")}
    if "magnitude" in lc:
        return LightCurve.from_magnitudes(np.asarray(lc["t_s"], float), np.asarray(lc["magnitude"], float), optics, **extra)
    return LightCurve(np.asarray(lc["t_s"], float), np.asarray(lc["flux_ph_s"], float), **extra)


def _length_px(table: dict[str, Any], px_key: str, m_key: str, optics: Optics) -> Any:
    if px_key in table:
        return table[px_key]
    if m_key in table:
        if "distance_m" not in table:
            raise ValueError(f"{m_key} needs distance_m (the object distance) to become pixels")
        return optics.length_to_px(np.asarray(table[m_key], float), float(table["distance_m"]))
    raise ValueError(f"needs {px_key} or {m_key}")


def _rate(table: dict[str, Any]) -> float:
    if "angular_rate_rad_s" in table:
        return float(table["angular_rate_rad_s"])
    if "period_s" in table:
        period = float(table["period_s"])
        if not period > 0 or math.isinf(period):
            raise ValueError(f"period_s must be > 0 and finite; got period_s={table['period_s']!r}")
        return 2 * math.pi / period
    raise ValueError("needs period_s or angular_rate_rad_s")


def _target(table: dict[str, Any], optics: Optics, width: int, height: int) -> list[Target]:
    kind = table["kind"]
    b = _brightness(table, optics)
    label = str(table.get("label", kind))
    cx = float(table.get("centre_x_px", (width - 1) / 2))
    cy = float(table.get("centre_y_px", (height - 1) / 2))
    if kind == "static":
        return [StaticTarget(float(table["x_px"]), float(table["y_px"]), b, label=label)]
    if kind == "linear":
        if "wx_arcsec_s" in table or "wy_arcsec_s" in table:
            return [LinearTarget.from_angular_velocity(
                float(table["x0_px"]), float(table["y0_px"]), float(table.get("wx_arcsec_s", 0.0)) * RAD_PER_ARCSEC,
                float(table.get("wy_arcsec_s", 0.0)) * RAD_PER_ARCSEC, optics, b, float(table.get("t0_s", 0.0)), label)]
        return [LinearTarget(float(table["x0_px"]), float(table["y0_px"]), float(table.get("vx_px_s", 0.0)),
                             float(table.get("vy_px_s", 0.0)), b, float(table.get("t0_s", 0.0)), label)]
    if kind == "circular":
        radius = float(_length_px(table, "radius_px", "radius_m", optics))
        return [CircularTarget(cx, cy, radius, _rate(table), b, float(table.get("phase_rad", 0.0)), label)]
    if kind == "rotating_bar":
        radii = [float(r) for r in np.atleast_1d(_length_px(table, "radii_px", "radii_m", optics))]
        bar = aligned_rotating_targets(cx, cy, radii, _rate(table), b, float(table.get("phase_rad", 0.0)))
        return [dataclasses.replace(t, label=f"{label}[{j}]") for j, t in enumerate(bar)]
    return [TabulatedTarget(np.asarray(table["t_s"], float), np.asarray(table["x_px"], float),
                            np.asarray(table["y_px"], float), b, outside=table.get("outside", "raise"), label=label)]


def _ghost(table: dict[str, Any], earlier: list[Target], width: int, height: int) -> Target:
    of = table["of"]
    match = [t for t in earlier if t.label == of]
    if len(match) != 1:
        labels = sorted({t.label for t in earlier})
        raise ValueError(f"of={of!r} must name exactly one earlier target; "
                         f"{'found ' + str(len(match)) if match else 'none has that label'} (labels: {labels})")
    return MirroredTarget(match[0], float(table.get("centre_x_px", (width - 1) / 2)),
                          float(table.get("centre_y_px", (height - 1) / 2)), float(table.get("magnification", 1.0)),
                          float(table["flux_fraction"]), label=str(table.get("label", "ghost")),
                          steady=table.get("steady", False))


def _defocus(table: dict[str, Any], optics: Optics) -> psf.PSFShape:
    blur = table.get("defocus_blur_sigma_px", optics.extra_blur_sigma_px)
    obstruction = table.get("defocus_obstruction_ratio", optics.obstruction_ratio)
    vanes = table.get("defocus_spider_vanes", optics.spider_vanes)
    if isinstance(vanes, bool) or not isinstance(vanes, int):
        raise ValueError(f"defocus_spider_vanes must be an integer in [0, 16]; got defocus_spider_vanes={vanes!r}")
    return _defocus_shape(float(table["defocus_radius_px"]), float(obstruction), vanes,
                          float(optics.spider_width_ratio), float(optics.spider_angle_deg), float(blur))


@functools.lru_cache(maxsize=8)
def _defocus_shape(radius: float, obstruction: float, vanes: int, vane_width: float, vane_angle: float,
                   blur: float) -> psf.PSFShape:
    """``psf.defocus_psf`` cached (1-2 s to tabulate a 70 px ring; a fit builds the scene per trial)."""
    return psf.defocus_psf(radius, obstruction, vanes, vane_width, vane_angle, blur)
