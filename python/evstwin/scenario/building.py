"""A resolved scenario turned into objects: :func:`build` makes the :class:`Scene` ``simulate``
runs (pixel parameters, optics and PSF, targets and star field, background, readout, hot
pixels, ROI, atmosphere), checked against the limits of :mod:`evstwin.scenario.limits`."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .. import psf
from ..constants import ARCSEC_PER_DEG
from ..optics import PAPER_F_NUMBER, PAPER_FOCAL_LENGTH_M, Optics
from ..pixel import HotPixelChain, PixelParams
from ..presets import (
    PROPHESEE_BIAS_NAMES,
    VENDOR_BIAS_PRESETS,
    BiasSet,
    SensorPreset,
    get_bias_set,
    get_preset,
)
from ..readout import ReadoutParams
from ..sky import scene as sky_scene
from ..sky import stars as sky_stars
from ..sky.atmosphere import MIN_SAMPLES_PER_SCINTILLATION_TAU, Atmosphere, atmosphere_from_table
from ..spectra import SensorResponse, band, spectrum_from_name, transmission_from_table
from ..targets import MAX_STARS, Target, along_path, drifting, random_star_field, with_psf
from .assignment import set_value
from .hot_pixels import _hot_pixel_map
from .limits import MAX_PSF_SIGMA_PX, _check_intervals, _check_peak_rate, _check_pre_roll, _check_work
from .schema import _BIAS_KEYS, _DRIFT_KEYS, _PIXEL_TEXT_KEYS, ScenarioError, _wrap, load
from .target_tables import (
    _defocus,
    _field_drift,
    _field_path,
    _ghost,
    _into_roi,
    _psf_shape,
    _roi,
    _steady_halo,
    _target,
)


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
    crossing is plausible), each unit of ``static_step_s`` (rounded down to whole base
    intervals) is one ``Sensor.run_sparse`` step: a pixel no moving source touches, that has
    settled and whose noise stays clear of its thresholds takes long steps, waiting while its
    light is constant (``simulate``; the performance page measures it)."""
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

    # Pixel: preset defaults <- biases (a set, then single currents; or the vendor's biases)
    # <- [pixel] overrides.
    params = preset.pixel
    bias_table = dict(s.get("biases", {}))
    vendor = {name: bias_table.pop(name) for name in PROPHESEE_BIAS_NAMES if name in bias_table}
    set_name = _bias_set_name(s)
    k = s["sensor"].get("k")
    if vendor:
        params = _vendor_biases(s, preset, vendor, bias_table)
    elif preset.vendor_biases is not None:
        _refuse_davis_currents(preset, set_name, bias_table, k)
    elif set_name or bias_table:
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
            px_deg = optics.plate_scale_arcsec_per_px / ARCSEC_PER_DEG
            density = sf.get("density_per_deg2")
            if density is None:
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


def _bias_set_name(s: dict[str, Any]) -> str | None:
    """sensor.bias_set; None where it is absent or ``"none"``: the preset's own biases, also
    where a ``base`` scenario names a set (a Prophesee preset over ``geo-stare``)."""
    name = s["sensor"].get("bias_set")
    return None if name is None or name.lower() == "none" else name


def _refuse_davis_currents(preset: SensorPreset, set_name: str | None, currents: dict[str, Any], k: Any) -> None:
    """Refuse any DAVIS bias current (sensor.bias_set, biases.i_on_a ..., sensor.k) given for
    a preset with Prophesee biases: eq. 8-9 and the follower's and refractory laws are the DAVIS
    pixel's circuit, so on the IMX636 they would give it a DAVIS346's thresholds, 10 Hz follower
    and 1 ms refractory period under its own name (what ``geo-stare`` with only
    ``sensor.preset=imx636`` set gave before this was refused)."""
    given = ([f"sensor.bias_set={set_name!r}"] if set_name else []) + [
        f"biases.{name}={value!r}" for name, value in currents.items()] + ([f"sensor.k={k!r}"] if k is not None else [])
    if given:
        raise ScenarioError(
            f"{', '.join(given)}: the DAVIS bias currents (and their eq. 8-9 factor) do not apply to preset "
            f"{preset.name!r}, whose biases are "
            f"Prophesee's (biases.{', biases.'.join(PROPHESEE_BIAS_NAMES)}); set sensor.bias_set=\"none\" for the "
            "preset's own biases (a base scenario's set included), or give pixel.theta_on, pixel.theta_off, "
            "pixel.cutoff_hz ... directly")


def _vendor_biases(s: dict[str, Any], preset: SensorPreset, vendor: dict[str, Any],
                   currents: dict[str, Any]) -> PixelParams:
    """The preset's pixel with the vendor's biases of [biases] (``bias_diff_on`` ...) mapped
    onto it (``SensorPreset.vendor_biases``), at sensor.temperature_c (U_T of the exponential
    laws; default the preset's reference temperature)."""
    first = next(iter(vendor))
    if preset.vendor_biases is None:
        raise ScenarioError(
            f"biases.{first}: preset {preset.name!r} has no Prophesee biases (its biases are the DAVIS bias "
            f"currents, biases.{', biases.'.join(_BIAS_KEYS)}, or sensor.bias_set); Prophesee biases: "
            f"{', '.join(VENDOR_BIAS_PRESETS)}")
    mixed = [f"biases.{k}" for k in currents] + (["sensor.bias_set"] if _bias_set_name(s) else []) + (
        ["sensor.k"] if "k" in s["sensor"] else [])
    if mixed:
        raise ScenarioError(f"biases.{first} (a Prophesee bias) cannot be combined with {', '.join(mixed)} (the "
                            "DAVIS bias currents): give one or the other")
    temperature_c = s["sensor"].get("temperature_c", preset.dark_reference_temperature_c)
    try:
        return preset.vendor_biases.pixel_params(vendor, preset.pixel, temperature_c)
    except (ValueError, TypeError) as exc:  # each message names its key and value
        raise ScenarioError(str(exc)) from None


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
