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
                  ``evstwin.presets.BIAS_SETS``, DAVIS bias currents: the DAVIS346 presets
                  only; ``"none"``: the preset's own biases, dropping a ``base``'s set),
                  ``k`` (eq. 8-9 factor, with the currents),
                  ``temperature_c`` (the sensor's temperature [degC], -30 to 70: the dark
                  current, leak, background and hot-pixel rates scale from the preset's
                  25 degC by ``SensorPreset.at_temperature``, doubling every 6.5 degC).
``[biases]``      bias currents in amperes (``i_on_a`` ... ``i_refr_a``), overriding the set.
                  On a Prophesee preset, the vendor's biases in its own names and units instead
                  (mV on ``prophesee_gen3_vga``, offsets in DAC codes from the factory default
                  on ``imx636``; ``evstwin.presets.prophesee_biases`` gives each law, range and
                  source, the presets reference lists them): ``bias_diff_on`` sets the ON
                  threshold (raising it raises theta_on); ``bias_diff_off`` sets the OFF
                  threshold (on Gen3 its distance below bias_diff; on the IMX636 raising it
                  raises theta_off); ``bias_diff`` is the comparators' reference, accepted only
                  at its default; ``bias_fo`` sets the source follower's cutoff_hz (Gen3: lower
                  is faster); ``bias_refr`` sets the refractory period; ``bias_pr`` (Gen3's
                  photoreceptor amplifier, which the twin does not model) accepts only its
                  default; ``bias_hpf`` (a high-pass filter the twin lacks) accepts only its
                  default. They cannot be mixed with the currents or ``bias_set``; the DAVIS346
                  presets have none.
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
                  default 0: every pixel at ``rate_hz``; the noise model page says where
                  long steps keep the statistics; ``simulate``).
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

from .assignment import parse_assignment, set_value
from .building import Scene, build
from .hot_pixels import HOT_PIXEL_CHAIN_KEYS, MAX_HOT_PIXEL_RATE_HZ
from .limits import MAX_CHUNK_BYTES, MAX_PHOTON_RATE, MAX_PSF_SIGMA_PX, MAX_SAMPLES, pre_roll_samples
from .schema import DEFAULT_SAMPLING, SCHEMA, ScenarioError, builtin_names, load, resolve, to_toml

__all__ = [
    "DEFAULT_SAMPLING",
    "HOT_PIXEL_CHAIN_KEYS",
    "MAX_CHUNK_BYTES",
    "MAX_HOT_PIXEL_RATE_HZ",
    "MAX_PHOTON_RATE",
    "MAX_PSF_SIGMA_PX",
    "MAX_SAMPLES",
    "SCHEMA",
    "Scene",
    "ScenarioError",
    "build",
    "builtin_names",
    "load",
    "parse_assignment",
    "pre_roll_samples",
    "resolve",
    "set_value",
    "to_toml",
]
