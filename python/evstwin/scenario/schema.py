"""The scenario's schema: its keys and their types, loading (built-in names, TOML files, ``base``
chains), the checks of every key's type and range, and writing a scenario back as TOML.

A bad key or value is a :class:`ScenarioError`, one line naming the key and what it accepts.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import sys
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from ..optics import Optics
from ..pixel import PixelParams
from ..presets import PRESETS, PROPHESEE_BIAS_NAMES
from ..readout import MAX_RATE_HZ, MAX_TICK_S, MIN_TICK_S
from ..sensor import MAX_MAX_EVENTS
from ..sky import scene as sky_scene
from ..sky.atmosphere import ATMOSPHERE_KEYS
from ..spectra import PHOTOMETRY_KEYS

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


class ScenarioError(ValueError):
    """A scenario key with a bad value: the message names the key and what it accepts."""



def _wrap(key: str, fn: Any, *args: Any, **kwargs: Any) -> Any:
    try:
        return fn(*args, **kwargs)
    except (ValueError, TypeError) as exc:
        raise ScenarioError(f"{key}: {exc}") from None
    except ArithmeticError as exc:  # OverflowError: math.pow, float(int)...
        raise ScenarioError(f"{key}: a result overflows a 64-bit float ({exc})") from None


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
    "biases": {k: float for k in _BIAS_KEYS + PROPHESEE_BIAS_NAMES},
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
                    "static_step_s": 0.0}


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
