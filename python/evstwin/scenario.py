"""Scenarios: a scene, a sensor with its biases, and how to sample it, as TOML.

The tables mirror the Python objects:

``[sensor]``      ``preset`` (``davis346`` | ``imx636``; required, directly or through
                  ``base``), optional ``width``/``height`` (a
                  smaller window of the sensor, at its origin: the targets' coordinates
                  are the window's), ``roi = [x0, y0, w, h]`` (simulate only this
                  rectangle of the width x height sensor: targets, star field and hot-pixel
                  map stay in the sensor's coordinates and are cut and shifted to the ROI's,
                  and the events come out as a w x h recording in the ROI's coordinates,
                  x - x0 and y - y0), ``bias_set`` (a name from
                  ``evstwin.presets.BIAS_SETS``), ``k`` (eq. 8-9 factor),
                  ``temperature_c`` (the sensor's temperature [degC], -30 to 70: the dark
                  current, leak, background and hot-pixel rates scale from the preset's
                  25 degC by ``SensorPreset.at_temperature``, doubling every 6.5 degC).
``[biases]``      bias currents in amperes (``i_on_a`` ... ``i_refr_a``), overriding the set.
``[pixel]``       any ``PixelParams`` field by name; overrides what biases and preset derive.
                  ``pr_pole`` defaults to true here (as in every built-in), unlike
                  ``PixelParams``, whose default is the paper's single pole.
``[optics]``      ``Optics`` fields (``focal_length_m``, ``f_number``, ``extra_blur_sigma_px``...),
                  and the PSF shape: ``psf = "gaussian"`` (default) | ``"airy"`` | ``"moffat"``
                  | ``"image"`` with its keys (``spider_*``, ``moffat_*``, ``psf_file*``,
                  ``psf_subpixel``, ``psf_half_width_px``; the lens-and-camera guide, "PSF shapes").
``[sampling]``    ``rate_hz`` (the floor rate of the whole array), ``max_shift_px`` (default
                  0.25: no target moves further between samples), ``sparse`` (sub-sample only
                  the pixels near moving targets; default true), ``chunk_samples``,
                  ``max_events`` (most events of one engine call; default 1e8, see
                  ``Sensor.max_events``), ``pre_roll_s`` (the sensor watches the scene this
                  long before t = 0, its events dropped; default 0),
                  ``pre_roll_rate_hz`` (its sampling rate; default ``rate_hz``) and
                  ``static_step_s`` (the longest step of a pixel whose light is constant,
                  in a sparse run with the continuous noise model and the exact low-pass;
                  default 0.2, 0 = every pixel at ``rate_hz``; ``simulate``).
``[background]``  ``photon_rate_ph_s`` per pixel, or ``sky_mag_per_arcsec2``.
``[photometry]``  how magnitudes become electrons on a preset with a QE curve
                  (``evstwin.spectra``): ``band`` (``"V"``, default, ``"G"`` or a CSV of
                  wavelength_nm,response), ``spectrum`` (of every magnitude source without its
                  own: ``"sun"``, default, ``"night-sky"``, ``"flat"``, ``"blackbody:5800"``,
                  ``"bv:0.65"``, ``"led:630:20"`` or a CSV of wavelength_nm,photon flux),
                  ``sky_spectrum`` (the background's, default ``"night-sky"``),
                  ``transmission_file`` (the optics' curve, wavelength_nm,T, times
                  ``optics.transmission``) and ``filter_file`` (a filter's curve).
``[hot_pixels]``  an explicit hot-pixel map, in place of the draw of ``pixel.hot_pixel_fraction``:
                  ``pixels = [[x, y, rate_hz], ...]`` and/or ``file = "map.npy"`` (a
                  (height, width) array of rates [Hz], 0 = not hot); see
                  ``PixelParams.hot_pixel_rate_hz`` for what a rate means. An entry may be a
                  table ``{x, y, rate_hz, duty, burst_s, on_share, alternation}``: the pixel's
                  own telegraph and polarity chain (``evstwin.HotPixelChain``), each key not
                  given the ``pixel.hot_pixel_*`` value, except that an ``on_share`` without
                  ``alternation`` draws each event's polarity afresh (alternation 2 s (1 - s)).
``[[targets]]``   ``kind`` = ``static`` | ``linear`` | ``circular`` | ``rotating_bar`` |
                  ``tabulated`` | ``tle`` (two-line elements, placed by the pointing: see
                  below), its geometry, and one brightness: ``flux_ph_s``,
                  ``magnitude`` or ``light_curve = {t_s = [...], flux_ph_s|magnitude = [...]}``;
                  ``frame = "field"`` gives it in field coordinates (it moves with the star
                  field's drift as well; default ``"sensor"``). ``kind = "ghost"`` mirrors an
                  earlier target (``of``, ``centre_x_px``, ``centre_y_px``, ``magnification``)
                  with ``flux_fraction`` of its flux, or of its mean flux, steady, with
                  ``steady = true`` (``targets.MirroredTarget``). Any target may take its own
                  defocused PSF: ``defocus_radius_px`` and ``defocus_blur_sigma_px``,
                  ``defocus_obstruction_ratio``, ``defocus_spider_vanes``.
``[star_field]``  a random star field (``n_stars`` or ``density_per_deg2``, magnitudes, seed)
                  and its drift across the sensor, ``drift_px_s = [vx, vy]`` or
                  ``drift_arcsec_s = [wx, wy]`` (through the plate scale): every star moves,
                  and stars drift in from the area the drift sweeps during the run. A table
                  with only a drift makes no random stars (it moves the field-frame targets).
                  ``distribution = "all-sky"`` draws the sky's star counts instead of
                  the power law (``evstwin.sky.stars``; no n_stars/density_per_deg2: the
                  count follows from the field of view), scaled by ``density_scale``;
                  ``spectrum``: the random stars' (default ``photometry.spectrum``).
``[atmosphere]``  seeing, image motion and scintillation (``evstwin.sky.atmosphere``):
                  ``seeing_fwhm_arcsec`` (a Moffat of that FWHM, ``moffat_beta`` default
                  4.765, convolved with the optics' PSF), ``jitter_rms_arcsec`` and
                  ``jitter_tau_s`` (tip-tilt of the whole field), ``scintillation = true``
                  with ``site_altitude_m``, ``airmass`` or ``elevation_deg``,
                  ``scintillation_c_y``, ``wind_speed_m_s``, ``scintillation_tau_s``.
``[readout]``     the sensor's readout (``evstwin.readout``): ``enabled`` (default: true when
                  the preset has readout figures, as the DAVIS346 and IMX636 do), and
                  ``max_rate_hz``, ``fifo_depth``, ``tick_s`` overriding the preset's.

The sky (``evstwin.sky.scene``): ``start_utc`` (top level), ``[site]`` (``lat_deg``,
``lon_deg``, ``alt_m``, ``ut1_utc_s``, ``extinction_mag_per_airmass``) and ``[pointing]``
(``mode`` = ``staring`` | ``sidereal`` | ``target`` | ``table`` and its keys) place ``tle``
targets (``line1``, ``line2``, ``diameter_m`` + ``albedo`` or ``magnitude`` or a magnitude
``light_curve``) and the ``[star_field]``'s stars on the sky and project them on the sensor.

Top level: ``name``, ``description``, ``duration_s``, ``seed``, and ``base`` (a built-in
scenario this one starts from; its tables are merged key by key).

A scenario stays a plain nested dict until ``build`` turns it into objects, so the resolved
dict can be written beside the events and read back; ``set_value`` applies the CLI's
``--set key=value``. Every error is one line naming the key and what it accepts.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import sys
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from . import _core, psf
from .optics import PAPER_F_NUMBER, PAPER_FOCAL_LENGTH_M, Optics
from .pixel import HotPixelChain, PixelParams
from .presets import PRESETS, BiasSet, SensorPreset, get_bias_set, get_preset
from .readout import MAX_RATE_HZ, MAX_TICK_S, MIN_TICK_S, ReadoutParams
from .sensor import MAX_HOT_PIXEL_CHAINS, MAX_MAX_EVENTS
from .sky import scene as sky_scene
from .sky.atmosphere import (
    ATMOSPHERE_KEYS,
    MIN_SAMPLES_PER_SCINTILLATION_TAU,
    Atmosphere,
    atmosphere_from_table,
)
from .spectra import PHOTOMETRY_KEYS, SensorResponse
from .targets import (
    MAX_STARS,
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
    along_path,
    drift_px_s_from_arcsec,
    drifting,
    random_star_field,
    shifted,
    with_psf,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ARCSEC_RAD = math.pi / (180.0 * 3600.0)


class ScenarioError(ValueError):
    """A scenario key with a bad value: the message names the key and what it accepts."""


_PIXEL_TEXT_KEYS = ("dark_model", "lowpass")
_BIAS_KEYS = ("i_on_a", "i_off_a", "i_diff_a", "i_pr_a", "i_sf_a", "i_refr_a")
_OPTICS_KEYS = tuple(
    f.name for f in dataclasses.fields(Optics) if f.name not in ("width_px", "height_px", "pixel_pitch_m")
)
_BRIGHTNESS_KEYS = ("flux_ph_s", "magnitude", "light_curve")
_FRAMES = ("sensor", "field")
_DRIFT_KEYS = ("drift_px_s", "drift_arcsec_s")
_TARGET_KEYS: dict[str, tuple[str, ...]] = {
    "static": ("x_px", "y_px"),
    "linear": ("x0_px", "y0_px", "vx_px_s", "vy_px_s", "wx_arcsec_s", "wy_arcsec_s", "t0_s"),
    "circular": ("centre_x_px", "centre_y_px", "radius_px", "radius_m", "distance_m", "period_s",
                 "angular_rate_rad_s", "phase_rad"),
    "rotating_bar": ("centre_x_px", "centre_y_px", "radii_px", "radii_m", "distance_m", "period_s",
                     "angular_rate_rad_s", "phase_rad"),
    "tabulated": ("t_s", "x_px", "y_px", "outside"),
    "ghost": ("of", "centre_x_px", "centre_y_px", "magnification", "flux_fraction", "steady"),
    "tle": sky_scene.TLE_KEYS,
}
_TARGET_PSF_KEYS = ("defocus_radius_px", "defocus_blur_sigma_px", "defocus_obstruction_ratio", "defocus_spider_vanes")
"""Keys of any target that give it its own PSF (``psf.defocus_psf``): the radius, and the blur,
obstruction and vanes where they are not the optics' (a ghost formed behind the obstruction)."""
SCHEMA: dict[str, Any] = {
    "name": str,
    "description": str,
    "base": str,
    "duration_s": float,
    "seed": int,
    "sensor": {"preset": str, "width": int, "height": int, "roi": list, "bias_set": str, "k": float,
               "temperature_c": float},
    "biases": {k: float for k in _BIAS_KEYS},
    "pixel": {name: Any for name in PixelParams.field_names()},
    "optics": {k: Any for k in _OPTICS_KEYS},
    "sampling": {"rate_hz": float, "max_shift_px": float, "sparse": bool, "chunk_samples": int, "max_events": int,
                 "pre_roll_s": float, "pre_roll_rate_hz": float, "static_step_s": float},
    "background": {"photon_rate_ph_s": float, "sky_mag_per_arcsec2": float},
    "photometry": {k: str for k in PHOTOMETRY_KEYS},
    "hot_pixels": {"pixels": list, "file": str},
    "targets": list,
    "star_field": {"n_stars": int, "density_per_deg2": float, "mag_min": float, "mag_max": float,
                   "counts_slope": float, "seed": int, "drift_px_s": Any, "drift_arcsec_s": Any,
                   "distribution": str, "density_scale": float, "path": dict, "spectrum": str},
    "atmosphere": {k: Any for k in ATMOSPHERE_KEYS},
    "readout": {"enabled": bool, "max_rate_hz": float, "fifo_depth": int, "tick_s": float},
    # The sky (evstwin.sky.scene): when t = 0 is, where the observer stands, where the camera looks.
    "start_utc": str,
    "site": {k: float for k in sky_scene.SITE_KEYS},
    "pointing": {k: Any for k in sky_scene.POINTING_KEYS},
}
DEFAULT_SAMPLING = {"rate_hz": 1000.0, "max_shift_px": 0.25, "sparse": True, "chunk_samples": 50,
                    "static_step_s": 0.2}


# -- loading ------------------------------------------------------------------------------------


def builtin_names() -> list[str]:
    """Names of the built-in scenarios (``evstwin scenarios``)."""
    folder = resources.files("evstwin") / "scenarios"
    return sorted(p.name[: -len(".toml")] for p in folder.iterdir() if p.name.endswith(".toml"))


def load(source: str | Path | dict) -> dict[str, Any]:
    """A resolved scenario dict from a built-in name, a TOML path or a dict (validated)."""
    if isinstance(source, dict):
        raw = copy.deepcopy(source)
    else:
        raw = _read_toml(source)
    return resolve(raw)


def _read_toml(source: str | Path) -> dict[str, Any]:
    text_source = str(source)
    path = Path(text_source)
    if text_source in builtin_names():
        text = (resources.files("evstwin") / "scenarios" / f"{text_source}.toml").read_text()
        where = f"built-in scenario {text_source!r}"
    elif path.suffix == ".toml" or path.exists():
        if path.is_dir():
            raise ScenarioError(f"scenario {text_source!r} is a folder, not a scenario file (a TOML file or a "
                                "built-in name: `evstwin scenarios`)")
        if not path.is_file():
            raise ScenarioError(f"scenario file {text_source!r} does not exist")
        text = path.read_text()
        where = str(path)
    else:
        raise ScenarioError(
            f"scenario must be a built-in name ({', '.join(builtin_names())}) or a .toml path; got {text_source!r}"
        )
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{where}: invalid TOML: {exc}") from None


def resolve(raw: dict[str, Any]) -> dict[str, Any]:
    """Merge ``base`` chains, fill defaults and check every key (raises ScenarioError)."""
    seen: list[str] = []
    while "base" in raw:
        base_name = raw.pop("base")
        if not isinstance(base_name, str) or base_name not in builtin_names():
            raise ScenarioError(f"base must name a built-in scenario ({', '.join(builtin_names())}); got {base_name!r}")
        if base_name in seen:
            raise ScenarioError(f"base scenarios form a cycle: {' -> '.join(seen + [base_name])}")
        seen.append(base_name)
        raw = _merge(_read_toml(base_name), raw)
    _check_keys(raw)
    # An empty file, or one that forgot its sensor, would otherwise run a DAVIS346 with every
    # default and nobody would notice: a scenario names at least its sensor preset.
    if not isinstance(raw.get("sensor"), dict) or "preset" not in raw["sensor"]:
        raise ScenarioError(
            f"a scenario must name its sensor: [sensor] preset = one of {', '.join(sorted(PRESETS))} "
            "(or base = a built-in scenario)"
        )
    out = copy.deepcopy(raw)
    out.setdefault("name", "scenario")
    out.setdefault("duration_s", 1.0)
    out.setdefault("seed", 0)
    # Scenarios default to the photoreceptor pole on, as every built-in has it: without it the
    # shot-noise events depend on the sampling (the documentation's noise model page). Written into
    # the resolved scenario, so the file beside the events says which was used. PixelParams
    # keeps the paper's single pole for reproducing it.
    out.setdefault("pixel", {}).setdefault("pr_pole", True)
    sampling = dict(DEFAULT_SAMPLING)
    sampling.update(out.get("sampling", {}))
    out["sampling"] = sampling
    out.setdefault("targets", [])
    _check_values(out)
    return out


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = copy.deepcopy(base)
    for key, value in over.items():
        if isinstance(value, dict) and isinstance(out.get(key), dict):
            out[key] = _merge(out[key], value)
        else:
            out[key] = copy.deepcopy(value)
    return out


def _check_keys(raw: dict[str, Any]) -> None:
    for key, value in raw.items():
        if key not in SCHEMA:
            raise ScenarioError(f"unknown scenario key {key!r}; allowed: {', '.join(SCHEMA)}")
        spec = SCHEMA[key]
        if spec in (int, float, bool, str):
            _check_type(key, value, spec)
        elif isinstance(spec, dict):
            if not isinstance(value, dict):
                raise ScenarioError(f"{key} must be a table; got {value!r}")
            for sub in value:
                if sub not in spec:
                    raise ScenarioError(f"unknown scenario key '{key}.{sub}'; allowed: {', '.join(spec)}")
                _check_type(f"{key}.{sub}", value[sub], spec[sub])
        elif spec is list:
            if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
                raise ScenarioError(f"{key} must be an array of tables ([[{key}]]); got {value!r}")
            for i, target in enumerate(value):
                _check_target_keys(i, target)


def _check_type(key: str, value: Any, kind: Any) -> None:
    """A value of the declared type: an int is a whole number (not true/false, not 1.5), a
    float a finite number that fits a float; Any is checked where it is used. Every number
    anywhere in a scenario must fit a float (TOML integers do not have to)."""
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ScenarioError(f"{key} must be an integer; got {value!r}")
    elif kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ScenarioError(f"{key} must be a number; got {value!r}")
    elif kind is bool:
        if not isinstance(value, bool):
            raise ScenarioError(f"{key} must be true or false; got {value!r}")
    elif kind is str:
        if not isinstance(value, str):
            raise ScenarioError(f"{key} must be a string; got {value!r}")
    _check_numbers(key, value)


def _check_numbers(key: str, value: Any) -> None:
    if isinstance(value, bool):
        return
    if isinstance(value, int) and _too_big_for_float(value):
        text = str(value)
        raise ScenarioError(f"{key}: {text[:12]}...({len(text)} digits) does not fit a 64-bit float (|value| < 1.8e308)")
    if isinstance(value, float) and not math.isfinite(value):
        raise ScenarioError(f"{key} must be finite; got {value!r}")
    if isinstance(value, list):
        for i, v in enumerate(value):
            _check_numbers(f"{key}[{i}]", v)
    if isinstance(value, dict):
        for k, v in value.items():
            _check_numbers(f"{key}.{k}", v)


def _too_big_for_float(value: int) -> bool:
    try:
        float(value)
    except OverflowError:
        return True
    return False


def _check_target_keys(i: int, target: dict[str, Any]) -> None:
    kind = target.get("kind")
    if not isinstance(kind, str) or kind not in _TARGET_KEYS:
        raise ScenarioError(f"targets[{i}].kind must be one of {', '.join(_TARGET_KEYS)}; got {kind!r}")
    if kind == "tle":  # placed on the sky by the pointing; its brightness is checked by evstwin.sky.scene
        allowed = ("kind", "label") + _TARGET_KEYS[kind] + ("magnitude", "light_curve")
    else:
        brightness = () if kind == "ghost" else _BRIGHTNESS_KEYS  # a ghost's is its source's
        allowed = ("kind", "label") + (() if kind == "ghost" else ("frame", "halo", "spectrum")) + _TARGET_KEYS[kind] \
            + brightness + _TARGET_PSF_KEYS
    for key in target:
        if key not in allowed:
            raise ScenarioError(f"unknown scenario key 'targets[{i}].{key}' for kind {kind!r}; allowed: {', '.join(allowed)}")
        _check_numbers(f"targets[{i}].{key}", target[key])
    for key in _TARGET_PSF_KEYS[1:]:
        if key in target and "defocus_radius_px" not in target:
            raise ScenarioError(f"targets[{i}].{key} needs targets[{i}].defocus_radius_px")
    for key in ("centre_x_px", "centre_y_px", "magnification", "flux_fraction") + _TARGET_PSF_KEYS:
        if key in target and (kind == "ghost" or key in _TARGET_PSF_KEYS) and (
                isinstance(target[key], bool) or not isinstance(target[key], (int, float))):
            raise ScenarioError(f"targets[{i}].{key} must be a number; got {target[key]!r}")
    if kind == "ghost":
        for key in ("of", "flux_fraction"):
            if key not in target:
                raise ScenarioError(f"targets[{i}] (a ghost) needs {key}: the label of the target it mirrors "
                                    "and the share of its flux")
        if not isinstance(target["of"], str):
            raise ScenarioError(f"targets[{i}].of must be the label of an earlier target; got {target['of']!r}")
        if not isinstance(target.get("steady", False), bool):
            raise ScenarioError(f"targets[{i}].steady must be true or false; got {target['steady']!r}")
        return
    given = [k for k in _BRIGHTNESS_KEYS if k in target]
    if len(given) != 1 and kind != "tle":
        raise ScenarioError(
            f"targets[{i}] needs exactly one of {', '.join(_BRIGHTNESS_KEYS)}; got {', '.join(given) or 'none'}"
        )


def _check_values(s: dict[str, Any]) -> None:
    def number(key: str, value: Any, lo: float = -math.inf, hi: float = math.inf, lo_open: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ScenarioError(f"{key} must be a number; got {value!r}")
        v = float(value)
        if not (v > lo if lo_open else v >= lo) or not v <= hi or math.isnan(v):
            bound = f"> {lo:g}" if lo_open else f">= {lo:g}"
            extra = f" and <= {hi:g}" if hi < math.inf else ""
            raise ScenarioError(f"{key} must be {bound}{extra}; got {value!r}")
        return v

    number("duration_s", s["duration_s"], 0.0, 1e7, lo_open=True)
    if isinstance(s["seed"], bool) or not isinstance(s["seed"], int) or not 0 <= s["seed"] < 2**64:
        raise ScenarioError(f"seed must be an integer in [0, 2**64); got {s['seed']!r}")
    for dim in ("width", "height"):
        if dim in s["sensor"] and not 1 <= s["sensor"][dim] <= 65535:
            raise ScenarioError(f"sensor.{dim} must be in [1, 65535]; got {s['sensor'][dim]!r}")
    preset = s["sensor"]["preset"]
    if not isinstance(preset, str) or preset.lower() not in PRESETS:
        raise ScenarioError(f"sensor.preset must be one of {', '.join(sorted(PRESETS))}; got {preset!r}")
    sp = s["sampling"]
    number("sampling.rate_hz", sp["rate_hz"], 0.0, 1e7, lo_open=True)
    number("sampling.max_shift_px", sp["max_shift_px"], 0.0, 1e6, lo_open=True)  # large = no adaptation
    if not isinstance(sp["sparse"], bool):
        raise ScenarioError(f"sampling.sparse must be true or false; got {sp['sparse']!r}")
    if isinstance(sp["chunk_samples"], bool) or not isinstance(sp["chunk_samples"], int) or sp["chunk_samples"] < 1:
        raise ScenarioError(f"sampling.chunk_samples must be an integer >= 1; got {sp['chunk_samples']!r}")
    number("sampling.static_step_s", sp["static_step_s"], 0.0, 1e6)
    if "pre_roll_s" in sp:
        number("sampling.pre_roll_s", sp["pre_roll_s"], 0.0, 1e6)
    if "pre_roll_rate_hz" in sp:
        number("sampling.pre_roll_rate_hz", sp["pre_roll_rate_hz"], 0.0, 1e7, lo_open=True)
    if "max_events" in sp and not 1 <= sp["max_events"] <= MAX_MAX_EVENTS:
        raise ScenarioError(f"sampling.max_events must be in [1, {MAX_MAX_EVENTS}]; got {sp['max_events']!r}")
    bg = s.get("background", {})
    if len(bg) > 1:
        raise ScenarioError("background takes one of photon_rate_ph_s or sky_mag_per_arcsec2, not both")
    if "photon_rate_ph_s" in bg:
        number("background.photon_rate_ph_s", bg["photon_rate_ph_s"], 0.0, 1e20)
    if "sky_mag_per_arcsec2" in bg:
        number("background.sky_mag_per_arcsec2", bg["sky_mag_per_arcsec2"], -30.0, 40.0)
    sf = s.get("star_field", {})
    drifts = [k for k in _DRIFT_KEYS if k in sf]
    if len(drifts) > 1:
        raise ScenarioError(f"star_field takes one of drift_px_s or drift_arcsec_s, not both; got drift_px_s="
                            f"{sf['drift_px_s']!r}, drift_arcsec_s={sf['drift_arcsec_s']!r}")
    for key in drifts:
        v = sf[key]
        if not isinstance(v, list) or len(v) != 2 or not all(
                isinstance(c, (int, float)) and not isinstance(c, bool) for c in v):
            unit = "px/s" if key == "drift_px_s" else "arcsec/s"
            raise ScenarioError(f"star_field.{key} must be two numbers [vx, vy] ({unit}); got {v!r}")
    ro = s.get("readout", {})
    if "max_rate_hz" in ro:
        number("readout.max_rate_hz", ro["max_rate_hz"], 0.0, MAX_RATE_HZ, lo_open=True)
    if "fifo_depth" in ro and not 1 <= ro["fifo_depth"] < 2**63:
        raise ScenarioError(f"readout.fifo_depth must be an integer >= 1 (events); got {ro['fifo_depth']!r}")
    if "tick_s" in ro:
        number("readout.tick_s", ro["tick_s"], MIN_TICK_S, MAX_TICK_S)
    for i, t in enumerate(s["targets"]):
        if "frame" in t and t["frame"] not in _FRAMES:
            raise ScenarioError(f"targets[{i}].frame must be one of {', '.join(map(repr, _FRAMES))}; got {t['frame']!r}")
        if "flux_ph_s" in t:
            number(f"targets[{i}].flux_ph_s", t["flux_ph_s"], 0.0, 1e25)
        if "magnitude" in t:
            number(f"targets[{i}].magnitude", t["magnitude"], -30.0, 40.0)


# -- --set ----------------------------------------------------------------------------------------


def parse_assignment(text: str) -> tuple[str, Any]:
    """``'pixel.theta_on=0.25'`` -> ``('pixel.theta_on', 0.25)``; the value is read as a TOML
    value (numbers, booleans, strings in quotes, arrays), else taken as a bare string."""
    if "=" not in text:
        raise ScenarioError(f"--set takes key=value (e.g. pixel.theta_on=0.25); got {text!r}")
    key, _, value_text = text.partition("=")
    key = key.strip()
    try:
        value = tomllib.loads(f"v = {value_text.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        value = value_text.strip()
    return key, value


def set_value(scenario: dict[str, Any], key: str, value: Any) -> dict[str, Any]:
    """A copy of the (resolved) scenario with one dotted key set, re-validated.
    ``targets.0.flux_ph_s`` addresses the first target."""
    out = copy.deepcopy(scenario)
    parts = key.split(".")
    node: Any = out
    for depth, part in enumerate(parts[:-1]):
        path = ".".join(parts[: depth + 1])
        if isinstance(node, list):
            if not part.isdigit() or int(part) >= len(node):
                raise ScenarioError(f"{path}: index must be 0..{len(node) - 1}; got {part!r}")
            node = node[int(part)]
        elif not isinstance(node, dict):
            parent = ".".join(parts[:depth])
            raise ScenarioError(f"{parent} is a value ({node!r}), not a table: {key!r} does not exist")
        else:
            if part not in node:
                if depth == 0 and part in SCHEMA and isinstance(SCHEMA[part], dict):
                    node[part] = {}
                else:
                    allowed = SCHEMA if depth == 0 else node
                    raise ScenarioError(f"unknown scenario key {path!r}; allowed: {', '.join(allowed)}")
            node = node[part]
    last = parts[-1]
    if isinstance(node, list):
        raise ScenarioError(f"{key}: give a field of one element, e.g. {key}.0.<field>")
    if not isinstance(node, dict):
        raise ScenarioError(f"{'.'.join(parts[:-1])} is a value ({node!r}), not a table: {key!r} does not exist")
    if last == "cutoff_hz" and parts[0] == "pixel" and value in ("none", "None", "off"):
        value = None
    if node is out and last not in SCHEMA:
        raise ScenarioError(f"unknown scenario key {key!r}; allowed: {', '.join(SCHEMA)}")
    if node is out and isinstance(SCHEMA[last], dict) and not isinstance(value, dict):
        raise ScenarioError(f"{key} is a table: set one of its keys, e.g. {key}.{next(iter(SCHEMA[last]))}=...")
    node[last] = value
    if out.get("pixel", {}).get("cutoff_hz", 0) is None:
        # TOML has no null: a cutoff of None is written as the string "none" in the dict.
        out["pixel"]["cutoff_hz"] = "none"
    return resolve(out)


# -- building ----------------------------------------------------------------------------------


@dataclass
class Scene:
    """A scenario turned into objects, ready to simulate."""

    scenario: dict[str, Any]
    preset: SensorPreset
    width: int
    height: int
    params: PixelParams
    optics: Optics
    targets: list[Target]
    background_ph_s: float
    duration_s: float
    seed: int
    rate_hz: float
    max_shift_px: float
    sparse: bool
    chunk_samples: int
    max_events: int | None = None
    """sampling.max_events: the cap on one engine call's events (None: the engine's default)."""
    pre_roll_s: float = 0.0
    """sampling.pre_roll_s [s]: the sensor starts watching the scene this long before t = 0
    (rounded up to whole pre-roll samples, ``pre_roll_samples``) and its events before t = 0
    are dropped, so that every pixel starts the recording with its history: the reference
    where its last event left it, its noise, leak and hot-pixel phases (``simulate``)."""
    static_step_s: float = 0.0
    """sampling.static_step_s [s]: the longest step of a pixel whose light is constant (0: every
    pixel at rate_hz). In a sparse run with the continuous noise model and the exact low-pass
    (whose statistics do not depend on the step: the engine refines an interval where a
    crossing is plausible), a pixel no moving source touches and that has settled is advanced
    once per ``static_step_s``, rounded down to whole base intervals (``simulate``)."""
    pre_roll_rate_hz: float | None = None
    """sampling.pre_roll_rate_hz: the pre-roll's sampling rate [Hz] (None: rate_hz). Whole
    frames, no sub-sampling: a pre-roll only sets the pixels' state, and with the continuous
    noise model that state does not depend on the sampling, so a slow scene can be pre-rolled
    at a fraction of the run's rate."""
    field_stars: int = 0
    """How many of the last ``targets`` the ``[star_field]`` made. Rendered like the others,
    but not written as ground-truth tracks when they drift: thousands of tracks would cost 32
    bytes per star per sample, and the resolved scenario (seed, drift) makes them again."""
    readout: ReadoutParams | None = None
    """The readout applied to the events (None: off, the engine's times kept)."""
    hot_pixel_rates_hz: np.ndarray | None = None
    """[hot_pixels]: the (height, width) hot-pixel rates [Hz], or None (the draw applies)."""
    hot_pixel_chains: dict[tuple[int, int], HotPixelChain] = dataclasses.field(default_factory=dict)
    """[hot_pixels]: {(x, y): chain} of the listed pixels with a telegraph and polarity chain of
    their own (a table entry with duty, burst_s, on_share or alternation)."""
    roi: tuple[int, int, int, int] | None = None
    """sensor.roi: (x0, y0, w, h) of the sensor this scene simulates (``width`` x ``height`` =
    w x h, every coordinate the ROI's); None: the whole (window of the) sensor."""
    atmosphere: Atmosphere | None = None
    """[atmosphere]: the seeing that sets the PSF (the targets already carry the image motion
    and scintillation); None: no atmosphere, the optics' PSF."""

    @property
    def psf_sigma_px(self) -> float:
        """The Gaussian PSF's sigma [px] (``optics.psf_sigma_px``; the width of psf='gaussian')."""
        return float(self.optics.psf_sigma_px)

    @property
    def psf(self) -> psf.PSFShape:
        """The PSF its sources are rendered with (``optics.psf``, or with [atmosphere] seeing
        the seeing convolved with it; cached)."""
        if self.atmosphere is not None:
            return self.atmosphere.psf(self.optics)
        return psf.from_optics(self.optics)


def _wrap(key: str, fn: Any, *args: Any, **kwargs: Any) -> Any:
    try:
        return fn(*args, **kwargs)
    except (ValueError, TypeError) as exc:
        raise ScenarioError(f"{key}: {exc}") from None
    except ArithmeticError as exc:  # OverflowError: math.pow, float(int)...
        raise ScenarioError(f"{key}: a result overflows a 64-bit float ({exc})") from None


MAX_PSF_SIGMA_PX = 100.0
"""Widest PSF accepted [px]: its +-5 sigma window (1001 px a side, 1e6 pixels at 100 px) is
rendered around every source and sample before it is clipped to the sensor; a sigma of 1000 px
took 2.5 GB per source (the scenario fuzz ran out of memory on one)."""
MAX_SAMPLES = 10**9
"""Most samples a scenario may imply: duration x rate x the sub-sampling of its fastest target
(1e9 samples of even a 64 x 64 window are 4e12 pixel-updates, a day of engine time)."""
MAX_CHUNK_BYTES = 2 * 2**30
"""Most memory one chunk's rendered rates may take [bytes]: chunk_samples frames of the whole
array (8 bytes a pixel), or in a sparse sub-sampled chunk the PSF windows of every moving target
that can be on the sensor at once (a drifting field's stars count only while they can touch
it) at every fine sample (about 32 bytes a window pixel)."""
MAX_PHOTON_RATE = 1e20
"""The engine's largest photon rate per pixel [photons/s] (``Sensor::MAX_RATE``)."""


def build(scenario: str | Path | dict, duration_s: float | None = None, seed: int | None = None) -> Scene:
    """Objects for a scenario (name, path or dict); duration_s and seed override the file's."""
    s = load(scenario)
    if duration_s is not None:
        s = set_value(s, "duration_s", float(duration_s))
    if seed is not None:
        s = set_value(s, "seed", int(seed))
    preset = get_preset(s["sensor"]["preset"])
    width = int(s["sensor"].get("width", preset.width))
    height = int(s["sensor"].get("height", preset.height))
    for name, value, full in (("width", width, preset.width), ("height", height, preset.height)):
        if not 1 <= value <= full:
            raise ScenarioError(f"sensor.{name} must be in [1, {full}] for preset {preset.name!r}; got {value}")

    # Pixel: preset defaults <- biases (a set, then single currents) <- [pixel] overrides.
    params = preset.pixel
    bias_table = s.get("biases", {})
    set_name = s["sensor"].get("bias_set")
    k = s["sensor"].get("k")
    if set_name or bias_table:
        base_set = _wrap("sensor.bias_set", get_bias_set, set_name) if set_name else None
        fields = {} if base_set is None else {f: getattr(base_set, f) for f in _BIAS_KEYS}
        fields.update(bias_table)
        missing = [f for f in ("i_on_a", "i_off_a", "i_diff_a") if fields.get(f) is None]
        if missing:
            raise ScenarioError(f"biases needs {', '.join(missing)} (or sensor.bias_set); got {sorted(bias_table)}")
        biases = _wrap("biases", BiasSet, **fields, name=set_name or "custom")
        derived = _wrap("sensor.k", biases.derived, *(() if k is None else (k,)))
        where = "biases" + (f" with sensor.k={k!r}" if k is not None else "") + (
            f" (sensor.bias_set={set_name!r})" if set_name else "")
        params = _wrap(where, params.replace, **derived)
    if "temperature_c" in s["sensor"]:
        params = _wrap("sensor.temperature_c", preset.at_temperature, params, s["sensor"]["temperature_c"])
    pixel = dict(s.get("pixel", {}))
    if pixel.get("cutoff_hz") in ("none", "None", "off"):
        pixel["cutoff_hz"] = None
    for key, value in pixel.items():
        if isinstance(value, int) and not isinstance(value, bool) and key not in _PIXEL_TEXT_KEYS:
            pixel[key] = float(value)
    # One key at a time, to name a bad one; but a hot pixel's ON share and alternation bound
    # each other (alternation <= 2 min(s, 1 - s)), so a pair that is valid together goes in
    # together, whatever the preset's alternation was.
    chain = ("hot_pixel_on_share", "hot_pixel_alternation")
    for key in pixel:
        together = [k for k in chain if k in pixel] if key in chain else [key]
        if key in chain and key != together[0]:
            continue
        params = _wrap(", ".join(f"pixel.{k}" for k in together), params.replace, **{k: pixel[k] for k in together})

    optics_kw = dict(s.get("optics", {}))
    optics = _wrap(
        "optics", preset.optics, optics_kw.pop("focal_length_m", PAPER_FOCAL_LENGTH_M),
        optics_kw.pop("f_number", PAPER_F_NUMBER), **optics_kw
    )
    optics = _wrap(f"optics={s.get('optics', {})}", optics.replace, width_px=width, height_px=height)
    response = _response(s, preset)
    spectral_optics: dict[str | None, Optics] = {}

    def optics_for(spectrum: str | None, key: str) -> Optics:
        """The optics whose zero point turns magnitudes of ``spectrum`` into engine photons."""
        if response is None:
            if spectrum is not None:
                why = ("optics.zero_point_ph_s_m2 is given (magnitudes count its photons)"
                       if "zero_point_ph_s_m2" in s.get("optics", {}) else
                       f"preset {preset.name!r} has no QE curve (it counts the V band's photons)")
                raise ScenarioError(f"{key}={spectrum!r} needs a sensor with a QE curve: {why}")
            return optics
        if spectrum not in spectral_optics:
            zp = _wrap(key, response.zero_point_ph_s_m2, spectrum)
            spectral_optics[spectrum] = optics.replace(zero_point_ph_s_m2=zp)
        return spectral_optics[spectrum]

    optics = optics_for(None, "photometry.spectrum")

    # The run's end: whole base samples, as simulate runs them (the drift sweeps until then).
    t_end = max(1, math.ceil(float(s["duration_s"]) * float(s["sampling"]["rate_hz"]) - 1e-9)) / float(
        s["sampling"]["rate_hz"])
    sigma = float(_wrap(f"optics={s.get('optics', {})}", lambda: optics.psf_sigma_px))
    if not sigma <= MAX_PSF_SIGMA_PX:
        raise ScenarioError(
            f"optics give a PSF sigma of {sigma:.3g} px (> {MAX_PSF_SIGMA_PX:g}): check optics.mean_wavelength_m, "
            f"optics.f_number and optics.extra_blur_sigma_px; got {s.get('optics', {})}"
        )
    site_alt: float | None = None
    if sky_scene.uses_sky(s):
        table = s.get("atmosphere") or {}
        if table.get("scintillation") and "airmass" not in table and "elevation_deg" not in table:
            raise ScenarioError("atmosphere.scintillation in a scenario on the sky needs atmosphere.airmass or "
                                "atmosphere.elevation_deg (the pointing's elevation changes over a pass; the "
                                "scintillation's strength is set once, as X^3): give the one for your run")
        alt = s.get("site", {}).get("alt_m")
        site_alt = None if alt is None else float(alt)
    atmosphere = _atmosphere(s, optics, site_altitude_m=site_alt)
    if atmosphere is not None and atmosphere.seeing_fwhm_arcsec is not None:
        shape = _wrap(f"atmosphere.seeing_fwhm_arcsec={atmosphere.seeing_fwhm_arcsec!r} with optics={s.get('optics', {})}",
                      atmosphere.psf, optics)
    else:
        shape = _psf_shape(optics, s.get("optics", {}))
    drift, drift_key = _field_drift(s, optics)
    path = _field_path(s)
    moves = drift != (0.0, 0.0)
    # Satellites from elements and stars on the sky, through the pointing (evstwin.sky.scene).
    sky = None
    if sky_scene.uses_sky(s):
        try:
            sky = sky_scene.build_sky(s, optics, width, height, t_end, shape.half_width_px + 2.0)
        except (ValueError, TypeError) as exc:  # the message names the key
            raise ScenarioError(str(exc)) from None
        satellites = iter(sky.satellites)
    targets: list[Target] = []
    sources: list[str] = []  # the key each target comes from, for errors
    for i, table in enumerate(s["targets"]):
        if table["kind"] == "tle":
            if sky is None:  # pragma: no cover - uses_sky is true whenever a tle target exists
                raise ScenarioError(f"targets[{i}] (kind 'tle') needs start_utc, [site] and [pointing]")
            targets.append(next(satellites))
            sources.append(f"targets[{i}] (tle, through pointing={s.get('pointing')})")
            continue
        uses_magnitude = "magnitude" in table or (isinstance(table.get("light_curve"), dict)
                                                  and "magnitude" in table["light_curve"])
        label = f"targets[{i}]" + (f" (a magnitude, through optics={s.get('optics', {})})" if uses_magnitude else "")
        if table["kind"] == "ghost":
            made = [_wrap(f"targets[{i}]", _ghost, table, targets, width, height)]
        else:
            made = _wrap(label, _target, table, optics_for(table.get("spectrum"), f"targets[{i}].spectrum"),
                         width, height)
        source = f"targets[{i}]"
        if table.get("frame") == "field" and moves:
            made = [drifting(t, *drift) for t in made]
            source += f" (frame='field', moved by {drift_key})"
        if table.get("frame") == "field" and path is not None:
            made = [along_path(t, path) for t in made]
            source += " (frame='field', along star_field.path)"
        if "defocus_radius_px" in table:
            own = _wrap(f"targets[{i}].defocus_radius_px with optics={s.get('optics', {})}", _defocus, table, optics)
            made = [with_psf(t, own) for t in made]
        if table.get("halo", "follows") != "follows":
            if atmosphere is not None and atmosphere.scintillation is not None:
                # Each target's scintillation is its own stream: the core and its halo copy
                # would twinkle apart.
                raise ScenarioError(f"targets[{i}].halo='steady' with [atmosphere] scintillation is not supported")
            targets.extend(_steady_halo(i, table, made, shape))
            sources.extend([source] * len(made) + [source + " (its halo, at its mean flux)"] * len(made))
            continue
        targets.extend(made)
        sources.extend([source] * len(made))
    field_stars = 0
    sf = dict(s.get("star_field", {}))
    sf.pop("path", None)
    star_spectrum = sf.pop("spectrum", None)
    if star_spectrum is not None and sky is not None:
        raise ScenarioError(f"star_field.spectrum={star_spectrum!r} applies to a random star field; stars placed on "
                            "the sky by [pointing] take photometry.spectrum")
    drift_only = (any(k in sf for k in _DRIFT_KEYS) and "n_stars" not in sf and "density_per_deg2" not in sf
                  and sf.get("distribution") != "all-sky")
    if sky is not None and sky.stars:
        targets.extend(sky.stars)
        sources.extend([f"star_field (on the sky, through pointing={s.get('pointing')})"] * len(sky.stars))
        field_stars = len(sky.stars)
    elif sky is None and sf and not drift_only:
        for key in _DRIFT_KEYS:
            sf.pop(key, None)
        n_stars = sf.get("n_stars")
        # The stars that drift in come from the area the drift sweeps past the sensor.
        swept = (width * height + height * abs(drift[0]) * t_end + width * abs(drift[1]) * t_end) / (width * height)
        if n_stars is None and ("density_per_deg2" in sf or sf.get("distribution") == "all-sky"):
            px_deg = optics.plate_scale_arcsec_per_px / 3600.0
            density = sf.get("density_per_deg2")
            if density is None:
                from .sky import stars as sky_stars

                density = _wrap("star_field", sky_stars.density_per_deg2,
                                sf.get("mag_min", sky_stars.STAR_FIELD_MAG_MIN),
                                sf.get("mag_max", sky_stars.STAR_FIELD_MAG_MAX), sf.get("density_scale", 1.0))
            n_stars = density * width * height * px_deg * px_deg
        if n_stars is not None and n_stars > 0 and not n_stars * swept <= MAX_STARS:
            which = "star_field.n_stars" if "n_stars" in sf else "star_field.density_per_deg2"
            if n_stars <= MAX_STARS:  # the drift brings in the rest
                which = f"{drift_key} (it sweeps {swept:.3g} times the sensor area over {t_end:g} s), {which}"
            total = n_stars * swept
            raise ScenarioError(f"star_field gives {total:.3g} stars (> {MAX_STARS:g}, about "
                                f"{total * 300 / 1e9:.3g} GB of targets): lower {which}; got star_field="
                                f"{s['star_field']}")
        slope = sf.get("counts_slope")
        if slope is not None and not -5.0 <= slope <= 5.0:
            raise ScenarioError(f"star_field.counts_slope must be in [-5, 5] (dex per magnitude; ~0.4 for stars); "
                                f"got {slope!r}")
        # A path (a slew) brings in stars from up to its largest offset beyond the field.
        margin = 0.0 if path is None else float(np.max(np.hypot(path.dx_px, path.dy_px)))
        stars = _wrap("star_field", random_star_field, width, height, optics_for(star_spectrum, "star_field.spectrum"),
                      **sf, drift_px_s=drift, duration_s=t_end, margin_px=margin)
        stars = [along_path(t, path) for t in stars]
        targets.extend(stars)
        sources.extend([f"star_field (moved by {drift_key})" if moves else "star_field"] * len(stars))
        field_stars = len(stars)

    bg = s.get("background", {})
    if "sky_mag_per_arcsec2" in bg:
        sky_optics = optics if response is None else optics_for(response.sky_spectrum, "photometry.sky_spectrum")
        background = float(_wrap(f"background.sky_mag_per_arcsec2 through optics={s.get('optics', {})}",
                                 sky_optics.background_ph_s_per_px, bg["sky_mag_per_arcsec2"]))
    else:
        background = float(bg.get("photon_rate_ph_s", 0.0))
    _check_peak_rate(background, dict(bg), targets, sources, shape, s.get("optics", {}))
    if (params.dark_model == "none" or params.dark_rate_e_per_s == 0.0) and not background >= 1e-30:
        # Pixels away from every target see the background alone, and the log photoreceptor
        # needs a current: the engine would refuse the first frame.
        raise ScenarioError(
            f"with no dark current (pixel.dark_model={params.dark_model!r}, pixel.dark_rate_e_per_s="
            f"{params.dark_rate_e_per_s:g}) the background must be >= 1e-30 photons/s per pixel; got "
            f"background={dict(bg)} ({background:.3g} photons/s)"
        )
    readout = _readout(s, preset)
    hot, hot_chains = _hot_pixel_map(s.get("hot_pixels"), width, height, params)
    roi = _roi(s["sensor"].get("roi"), width, height)
    if roi is not None:
        x0, y0, width, height = roi
        reach = max([shape.half_width_px] + [t.psf.half_width_px for t in targets if t.psf is not None])
        targets, sources, field_stars = _into_roi(targets, sources, field_stars, roi, reach, t_end)
        hot = None if hot is None else np.ascontiguousarray(hot[y0 : y0 + height, x0 : x0 + width])
        hot_chains = {(x - x0, y - y0): c for (x, y), c in hot_chains.items()
                      if 0 <= x - x0 < width and 0 <= y - y0 < height}
    sp = s["sampling"]
    if atmosphere is not None:
        targets = _atmosphere_on(atmosphere, s, targets, optics, t_end)
    _check_work(s, width, height, shape, targets, sources)
    _check_pre_roll(s, targets, sources, field_stars, moves, atmosphere)
    _check_intervals(params, float(sp["rate_hz"]))
    return Scene(
        roi=roi,
        scenario=s, preset=preset, width=width, height=height, params=params, optics=optics, targets=targets,
        background_ph_s=background, duration_s=float(s["duration_s"]), seed=int(s["seed"]),
        rate_hz=float(sp["rate_hz"]), max_shift_px=float(sp["max_shift_px"]), sparse=bool(sp["sparse"]),
        hot_pixel_rates_hz=hot, hot_pixel_chains=hot_chains,
        chunk_samples=int(sp["chunk_samples"]), max_events=sp.get("max_events"), field_stars=field_stars,
        pre_roll_s=float(sp.get("pre_roll_s", 0.0)),
        pre_roll_rate_hz=None if "pre_roll_rate_hz" not in sp else float(sp["pre_roll_rate_hz"]),
        static_step_s=float(sp["static_step_s"]),
        readout=readout, atmosphere=atmosphere,
    )


def _response(s: dict[str, Any], preset: SensorPreset) -> SensorResponse | None:
    """[photometry] on the preset's QE curve: how magnitudes become engine photons (None: the
    preset has no QE curve, or optics.zero_point_ph_s_m2 is given, and magnitudes count the
    zero point's photons)."""
    table = dict(s.get("photometry", {}))
    if preset.qe is None or "zero_point_ph_s_m2" in s.get("optics", {}):
        if table:
            why = (f"preset {preset.name!r} has no QE curve" if preset.qe is None
                   else "optics.zero_point_ph_s_m2 is given")
            raise ScenarioError(f"[photometry] {table} needs a sensor with a QE curve and no optics.zero_point_ph_s_m2; "
                                f"{why}")
        return None
    from .spectra import band, spectrum_from_name, transmission_from_table

    _wrap("photometry.band", band, table.get("band", "V"))
    for key in ("spectrum", "sky_spectrum"):
        if key in table:
            _wrap(f"photometry.{key}", spectrum_from_name, table[key])
    for key in ("transmission_file", "filter_file"):
        if key in table:
            _wrap(f"photometry.{key}", transmission_from_table, table[key], f"photometry.{key}")
    kwargs = {"band_name": table.pop("band", "V"), **table}
    return _wrap("photometry", SensorResponse, preset.qe, preset.pixel.electrons_per_photon, **kwargs)


def _atmosphere(s: dict[str, Any], optics: Optics, elevation_deg: float | None = None,
                site_altitude_m: float | None = None) -> Atmosphere | None:
    """[atmosphere] as an Atmosphere (None without the table). ``elevation_deg`` and
    ``site_altitude_m``: the hook for a pointing computed from an orbit and a site, used where
    the table gives no airmass, elevation_deg or site_altitude_m."""
    table = s.get("atmosphere")
    if table is None:
        return None
    atmosphere: Atmosphere = _wrap("atmosphere", atmosphere_from_table, table, elevation_deg, site_altitude_m)
    if atmosphere.scintillation is not None:
        tau = float(atmosphere.scintillation_tau_s(optics))  # type: ignore[arg-type]
        rate = float(s["sampling"]["rate_hz"])
        if rate * tau < MIN_SAMPLES_PER_SCINTILLATION_TAU:
            raise ScenarioError(
                f"atmosphere.scintillation: its correlation time is {tau:.3g} s (the aperture's D_eff / wind_speed_m_s, "
                f"or scintillation_tau_s) and sampling.rate_hz={s['sampling']['rate_hz']!r} samples it {rate * tau:.3g} "
                f"times: raise sampling.rate_hz to at least {math.ceil(MIN_SAMPLES_PER_SCINTILLATION_TAU / tau)} "
                f"({MIN_SAMPLES_PER_SCINTILLATION_TAU} samples per correlation time)"
            )
    return atmosphere


def _atmosphere_on(atmosphere: Atmosphere, s: dict[str, Any], targets: list[Target], optics: Optics,
                   t_end: float) -> list[Target]:
    """Every target (star field included) seen through the image motion and scintillation
    over [0, t_end], drawn from the scenario's seed."""
    out: list[Target] = _wrap(f"atmosphere={s['atmosphere']}", atmosphere.apply, targets, optics, t_end, int(s["seed"]))
    return out


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


def _readout(s: dict[str, Any], preset: SensorPreset) -> ReadoutParams | None:
    """[readout] over the preset's figures: on by default where the preset has figures or the
    table gives some; a preset without them needs readout.max_rate_hz and readout.fifo_depth."""
    table = dict(s.get("readout", {}))
    enabled = table.pop("enabled", preset.readout is not None or bool(table))
    if not enabled:
        return None
    if preset.readout is None and not {"max_rate_hz", "fifo_depth"} <= set(table):
        missing = [k for k in ("max_rate_hz", "fifo_depth") if k not in table]
        raise ScenarioError(f"preset {preset.name!r} has no readout figures: readout.enabled=true needs "
                            f"{' and '.join('readout.' + k for k in missing)}; got readout={s.get('readout', {})}")
    return _wrap(f"readout={s.get('readout', {})}", preset.readout_params, **table)


def _peak_flux(target: Target) -> float:
    b = target.brightness
    return float(np.max(b.flux_ph_s)) if isinstance(b, LightCurve) else float(b)


def _check_peak_rate(background: float, bg: dict[str, Any], targets: list[Target], sources: list[str],
                     shape: psf.PSFShape, optics: dict[str, Any]) -> None:
    """The engine refuses a pixel above 1e20 photons/s: make sure none can get there, before
    the run, naming what sets it. Bound: the background plus, from every source, its largest
    flux times the largest share one pixel gets of the PSF (a source centred on it; the
    rendered window is normalised to its own mass)."""
    share = shape.max_pixel_share
    peaks = [_peak_flux(t) for t in targets]
    summed = float(np.sum(peaks)) if peaks else 0.0  # inf, not OverflowError, past 1.8e308
    total = background + share * summed
    if total <= MAX_PHOTON_RATE:
        return
    where = f"background={bg} gives {background:.3g} photons/s per pixel"
    if peaks:
        k = int(np.argmax(peaks))
        where += (f"; {share:.3g} of the sources' peak fluxes adds {share * summed:.3g}, the brightest "
                  f"{sources[k]} at {peaks[k]:.3g} photons/s")
    raise ScenarioError(f"a pixel could receive {total:.3g} photons/s (> {MAX_PHOTON_RATE:g}, the engine's limit): "
                        f"{where}; optics={optics}")


def _check_intervals(params: PixelParams, rate_hz: float) -> None:
    """The engine's limits on the sample interval, checked for the longest one (1 / rate_hz),
    so what builds also runs (the engine would refuse it at the first sample, naming no key)."""
    dt = 1.0 / rate_hz
    noise = max(1.0, params.shot_noise_factor) * params.shot_noise_rate_hz * dt
    if noise > 0.5:
        raise ScenarioError(
            f"pixel.shot_noise_rate_hz={params.shot_noise_rate_hz:g} x max(1, pixel.shot_noise_factor="
            f"{params.shot_noise_factor:g}) / sampling.rate_hz={rate_hz:g} = {noise:.3g} must be <= 0.5 (eq. 13-15 "
            "draw at most one noise event per sample): raise sampling.rate_hz or lower the noise rate"
        )
    if params.lowpass == "euler" and params.cutoff_hz is not None and 2 * math.pi * params.cutoff_hz * dt > 2:
        raise ScenarioError(
            f"pixel.lowpass='euler' (eq. 7) is unstable when 2 pi pixel.cutoff_hz / sampling.rate_hz > 2; got "
            f"cutoff_hz={params.cutoff_hz:g}, rate_hz={rate_hz:g}: use lowpass='exact' or a higher rate"
        )


def _check_work(s: dict[str, Any], width: int, height: int, shape: psf.PSFShape, targets: list[Target],
                sources: list[str]) -> None:
    """The samples and the memory of one chunk a scenario implies, bounded before it runs,
    each error naming the keys that set it (sub-sampling as ``simulate`` does it: the base
    interval divided so that no target moves more than max_shift_px between samples)."""
    sp = s["sampling"]
    duration, rate, shift, chunk = float(s["duration_s"]), float(sp["rate_hz"]), float(sp["max_shift_px"]), sp["chunk_samples"]
    n_pre = pre_roll_samples(float(sp.get("pre_roll_s", 0.0)), rate, sp.get("pre_roll_rate_hz"))[0]
    n_base = max(1.0, math.ceil(duration * rate - 1e-9)) + n_pre
    if not n_base <= MAX_SAMPLES:
        pre = (f", sampling.pre_roll_s={sp['pre_roll_s']!r} x sampling.pre_roll_rate_hz="
               f"{sp.get('pre_roll_rate_hz', sp['rate_hz'])!r} = {n_pre:.3g} more") if n_pre else ""
        raise ScenarioError(f"duration_s x sampling.rate_hz = {n_base - n_pre:.3g} samples{pre} (> {MAX_SAMPLES:g}"
                            f"{' in all' if n_pre else ''}); got duration_s={s['duration_s']!r}, "
                            f"sampling.rate_hz={sp['rate_hz']!r}")
    frame_bytes = 8.0 * width * height
    if not chunk * frame_bytes <= MAX_CHUNK_BYTES:
        raise ScenarioError(
            f"sampling.chunk_samples={chunk} frames of {width}x{height} pixels take {chunk * frame_bytes / 2**30:.3g} GiB "
            f"(> {MAX_CHUNK_BYTES / 2**30:g} GiB): lower sampling.chunk_samples"
        )
    moving = []
    for i, target in enumerate(targets):
        speed = float(_wrap(sources[i], target.max_speed_px_s, 0.0, duration))
        if not speed >= 0.0:  # NaN
            raise ScenarioError(f"{sources[i]}: its speed is not a number ({speed!r} px/s)")
        if speed > 0.0:
            moving.append((speed, i))
    if not moving:
        return
    speed, i = max(moving)
    ratio = speed / rate / shift
    n_sub = max(1.0, math.ceil(ratio - 1e-9)) if ratio <= MAX_SAMPLES else ratio  # ceil(inf) would raise
    n_total = n_base * n_sub
    why = (f"{sources[i]} moves {speed:.3g} px/s, sub-sampled to sampling.max_shift_px={sp['max_shift_px']!r} at "
           f"sampling.rate_hz={sp['rate_hz']!r}: {n_sub:.3g} sub-samples per base sample")
    if not n_total <= MAX_SAMPLES:
        raise ScenarioError(f"{why}, {n_total:.3g} samples over duration_s={s['duration_s']!r} (> {MAX_SAMPLES:g})")
    if not 1.0 / rate / n_sub >= 1e-12:
        raise ScenarioError(f"{why}, {1.0 / rate / n_sub:.3g} s apart (< 1e-12 s, the engine's shortest interval)")
    if n_sub > 1 and sp["sparse"]:
        # The widest window any moving target renders at the fine rate (a defocused ghost's
        # may be wider; a halo is rendered at the base rate, one frame at a time).
        sharp = [psf.sharp_part(shape)] + [psf.sharp_part(targets[j].psf) for _, j in moving  # type: ignore[arg-type]
                                           if targets[j].psf is not None]
        half = max([p.half_width_px for p in sharp if p is not None], default=0)
        window = min((2 * half + 1) ** 2, width * height)
        fine = max(chunk, n_sub) + n_sub  # the fine samples of one sparse chunk, at most
        # Windows off the sensor are skipped: a drifting field's stars, most of them outside
        # at any one time on a long run, count only while they can touch it.
        n_win = _most_windows_at_once([targets[j] for _, j in moving], width, height, half, duration)
        need = fine * n_win * window * 32.0
        if not need <= MAX_CHUNK_BYTES:
            raise ScenarioError(
                f"{why}; one chunk of {fine:.3g} fine samples renders {n_win} moving PSF windows of {window} px "
                f"each, {need / 2**30:.3g} GiB (> {MAX_CHUNK_BYTES / 2**30:g} GiB): raise sampling.max_shift_px or "
                "lower sampling.chunk_samples"
            )


def _most_windows_at_once(targets: list[Target], width: int, height: int, half: int, duration_s: float) -> int:
    """The most of these moving targets whose PSF windows (half-width ``half`` px) overlap the
    sensor at one time in [0, duration_s]: exact for linear targets (each is on for one time
    interval; the count is the deepest overlap of the intervals), every other one counted
    as always on."""
    linear = [t for t in targets if isinstance(t, LinearTarget)]
    others = len(targets) - len(linear)
    if not linear:
        return others
    x0 = np.array([t.x0_px for t in linear])
    y0 = np.array([t.y0_px for t in linear])
    vx = np.array([t.vx_px_s for t in linear])
    vy = np.array([t.vy_px_s for t in linear])
    t0 = np.array([t.t0_s for t in linear])
    start = np.zeros(len(linear))
    end = np.full(len(linear), duration_s)
    for p0, v, size in ((x0, vx, width), (y0, vy, height)):
        lo, hi = -half - 0.5, size - 0.5 + half  # the centres whose window touches the sensor [px]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            ta, tb = t0 + (lo - p0) / v, t0 + (hi - p0) / v
        inside = (p0 >= lo) & (p0 <= hi)
        first = np.where(v == 0.0, np.where(inside, -np.inf, np.inf), np.minimum(ta, tb))
        last = np.where(v == 0.0, np.where(inside, np.inf, -np.inf), np.maximum(ta, tb))
        unknown = np.isnan(first) | np.isnan(last)  # inf - inf at absurd values: count it as on
        first, last = np.where(unknown, -np.inf, first), np.where(unknown, np.inf, last)
        start, end = np.maximum(start, first), np.minimum(end, last)
    on = start <= end
    # Sweep the interval ends in time order, an interval's start before another's end at a tie.
    times = np.concatenate([start[on], end[on]])
    steps = np.concatenate([np.ones(int(on.sum()), np.int64), -np.ones(int(on.sum()), np.int64)])
    order = np.lexsort((-steps, times))
    deepest = int(np.cumsum(steps[order]).max(initial=0))
    return others + deepest


MAX_HOT_PIXEL_RATE_HZ = 1e6
"""The engine's largest hot-pixel rate [Hz] (``Sensor::set_hot_pixel_rates``)."""


HOT_PIXEL_CHAIN_KEYS = tuple(f.name for f in dataclasses.fields(HotPixelChain))
"""The keys of a ``[hot_pixels] pixels`` table entry that give the pixel a chain of its own."""


def _hot_pixel_map(table: dict[str, Any] | None, width: int, height: int,
                   params: PixelParams) -> tuple[np.ndarray | None, dict[tuple[int, int], HotPixelChain]]:
    """[hot_pixels] as a (height, width) array of rates [Hz] (None: no map, the draw applies)
    and the listed pixels' own chains. A file's map comes first; listed pixels are set over it."""
    if not table:
        return None, {}
    rates = np.zeros((height, width))
    if "file" in table:
        path = table["file"]
        try:
            loaded = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise ScenarioError(f"hot_pixels.file={path!r} cannot be read as a .npy array: {exc}") from None
        if not isinstance(loaded, np.ndarray) or loaded.shape != (height, width) or loaded.dtype.kind not in "iuf":
            raise ScenarioError(f"hot_pixels.file={path!r} must hold a ({height}, {width}) array of rates [Hz] (the "
                                f"sensor's height, width); got {getattr(loaded, 'dtype', '?')} {getattr(loaded, 'shape', '?')}")
        bad = ~((loaded >= 0) & (loaded <= MAX_HOT_PIXEL_RATE_HZ))
        if bad.any():
            y, x = (int(v) for v in np.argwhere(bad)[0])
            raise ScenarioError(f"hot_pixels.file={path!r}: rates must be in [0, {MAX_HOT_PIXEL_RATE_HZ:g}] Hz; got "
                                f"{loaded[y, x]!r} at (x, y)=({x}, {y})")
        rates[:] = loaded
    pixels = table.get("pixels", [])
    if not isinstance(pixels, list):
        raise ScenarioError(f"hot_pixels.pixels must be an array of [x, y, rate_hz] or {{x, y, rate_hz, ...}}; got "
                            f"{pixels!r}")
    chains: dict[tuple[int, int], HotPixelChain] = {}
    listed: dict[tuple[int, int], int] = {}
    for i, entry in enumerate(pixels):
        key = f"hot_pixels.pixels[{i}]"
        x, y, r, own = _hot_pixel_entry(key, entry)
        if not (0 <= x < width and 0 <= y < height):
            raise ScenarioError(f"{key}={entry!r} lies off the {width}x{height} sensor")
        if (x, y) in listed:
            raise ScenarioError(f"{key}: pixel (x, y) = ({x}, {y}) is listed twice, also as "
                                f"hot_pixels.pixels[{listed[(x, y)]}]")
        listed[(x, y)] = i
        if not 0.0 <= r <= MAX_HOT_PIXEL_RATE_HZ:
            raise ScenarioError(f"{key}: rate_hz must be in [0, {MAX_HOT_PIXEL_RATE_HZ:g}]; got {entry!r}")
        rates[y, x] = r
        if own:
            base = HotPixelChain.of(params)
            fields = {name: float(own.get(name, getattr(base, name))) for name in HOT_PIXEL_CHAIN_KEYS}
            if "on_share" in own and "alternation" not in own:
                # A share of its own with the params' alternation would be a chain of another
                # pixel's memory (or no chain at all: 0.78 is out of reach at a share of 0.98).
                fields["alternation"] = 2.0 * fields["on_share"] * (1.0 - fields["on_share"])
            try:
                _core.validate_hot_pixel_chain(fields["duty"], fields["burst_s"], fields["on_share"],
                                               fields["alternation"], f"{key}.")
            except ValueError as exc:
                inherited = [f"{name} from pixel.hot_pixel_{name}" for name in HOT_PIXEL_CHAIN_KEYS
                             if name not in own and not (name == "alternation" and "on_share" in own)]
                raise ScenarioError(str(exc) + (f" ({', '.join(inherited)})" if inherited else "")) from None
            chains[(x, y)] = HotPixelChain(**fields)
    if len(chains) > MAX_HOT_PIXEL_CHAINS:
        raise ScenarioError(f"hot_pixels.pixels: at most {MAX_HOT_PIXEL_CHAINS} pixels may have a chain of their own; "
                            f"got {len(chains)}")
    return rates, chains


def _hot_pixel_entry(key: str, entry: Any) -> tuple[int, int, float, dict[str, float]]:
    """One ``[hot_pixels] pixels`` entry as (x, y, rate_hz, its own chain's keys)."""
    def number(v: Any) -> bool:
        return isinstance(v, (int, float)) and not isinstance(v, bool)

    if isinstance(entry, dict):
        known = ("x", "y", "rate_hz", *HOT_PIXEL_CHAIN_KEYS)
        unknown = sorted(set(entry) - set(known))
        if unknown:
            raise ScenarioError(f"{key} has unknown key(s) {unknown}; known: {list(known)}")
        missing = [k for k in ("x", "y", "rate_hz") if k not in entry]
        if missing:
            raise ScenarioError(f"{key} must give x, y and rate_hz; {', '.join(missing)} missing in {entry!r}")
        for name, value in entry.items():
            if not number(value) or (name in ("x", "y") and isinstance(value, float) and not value.is_integer()):
                what = "a whole pixel coordinate" if name in ("x", "y") else "a number"
                raise ScenarioError(f"{key}.{name} must be {what}; got {name}={value!r}")
        own = {k: float(v) for k, v in entry.items() if k in HOT_PIXEL_CHAIN_KEYS}
        return int(entry["x"]), int(entry["y"]), float(entry["rate_hz"]), own
    ok = isinstance(entry, list) and len(entry) == 3 and all(number(v) for v in entry)
    if not ok or any(isinstance(v, float) and not v.is_integer() for v in entry[:2]):
        raise ScenarioError(f"{key} must be [x, y, rate_hz] (whole pixel coordinates and a rate in Hz) or a table "
                            f"{{x, y, rate_hz, duty, burst_s, on_share, alternation}}; got {entry!r}")
    return int(entry[0]), int(entry[1]), float(entry[2]), {}


def pre_roll_samples(pre_roll_s: float, rate_hz: float, pre_roll_rate_hz: float | None = None) -> tuple[int, float]:
    """(n, dt): a pre-roll of ``pre_roll_s`` takes n samples dt apart before t = 0, the last at
    t = 0 (dt = 1 / pre_roll_rate_hz, or 1 / rate_hz without one; n = 0 without a pre-roll)."""
    dt = 1.0 / (pre_roll_rate_hz if pre_roll_rate_hz else rate_hz)
    return (math.ceil(pre_roll_s / dt - 1e-9) if pre_roll_s > 0.0 else 0), dt


def _check_pre_roll(s: dict[str, Any], targets: list[Target], sources: list[str], field_stars: int, moves: bool,
                    atmosphere: Any) -> None:
    """What a pre-roll (sampling.pre_roll_s) cannot do yet, refused by name: a target that
    cannot be placed before t = 0 (a table that starts there, a satellite's pass), a drifting
    field of random stars and an atmosphere's motion or scintillation (both drawn for [0,
    duration_s] only: the stars that would cross the sensor before t = 0, and the atmosphere
    there, are missing)."""
    sp = s["sampling"]
    n_pre, dt = pre_roll_samples(float(sp.get("pre_roll_s", 0.0)), float(sp["rate_hz"]), sp.get("pre_roll_rate_hz"))
    if not n_pre:
        return
    t0 = -n_pre * dt
    key = f"sampling.pre_roll_s={sp['pre_roll_s']!r}"
    if field_stars and moves:
        raise ScenarioError(f"{key} with a drifting [star_field] of random stars is not supported: the stars are "
                            "drawn for [0, duration_s] only, so those crossing the sensor before t = 0 would be missing")
    if atmosphere is not None and (atmosphere.motion is not None or atmosphere.scintillation is not None):
        raise ScenarioError(f"{key} with [atmosphere] image motion or scintillation is not supported: they are drawn "
                            "for [0, duration_s] only")
    t = np.array([t0, 0.5 * t0])
    for target, source in zip(targets, sources):
        try:
            target.position_px(t)
            target.flux_ph_s(t)
            target.max_speed_px_s(t0, 0.0)
        except ValueError as exc:
            raise ScenarioError(f"{key}: {source} cannot be placed before t = 0 ({exc}); give it a track that "
                                "covers the pre-roll, or no pre-roll") from None


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
                float(table["x0_px"]), float(table["y0_px"]), float(table.get("wx_arcsec_s", 0.0)) * ARCSEC_RAD,
                float(table.get("wy_arcsec_s", 0.0)) * ARCSEC_RAD, optics, b, float(table.get("t0_s", 0.0)), label)]
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


def to_toml(scenario: dict[str, Any]) -> str:
    """The scenario as TOML text (what ``evstwin simulate`` takes back)."""
    import tomli_w

    return tomli_w.dumps(_plain(scenario))


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value
