"""The :class:`SensorPreset` type (a sensor as data, each number with its source), its
temperature scaling, and the parts the camera presets share: the readout FIFO assumption and
the front-illuminated silicon photodiode (its yield and QE curve)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .._checks import finite, positive, size
from ..optics import Optics
from ..pixel import PixelParams
from ..readout import ReadoutParams
from ..sensor import Sensor
from ..spectra import QECurve, silicon_absorption_per_m, silicon_qe_curve
from .biases import BiasSet
from .prophesee_biases import PropheseeBiases

DARK_DOUBLING_C = 6.5
"""Temperature rise [degC] that doubles a pixel's dark current: the middle of the 5-8 degC
that Theuwissen gives for CMOS image sensors (Harvest Imaging blog, "How to measure dark
current", September 2009: "the dark current can double for every 5 degC ... 8 degC"). No
published figure for these event sensors was at hand (Nozaki & Delbruck 2017, IEEE TED 64,
3239, measured the DAVIS's leak against temperature; its numbers were not reachable)."""
TEMPERATURE_RANGE_C = (-30.0, 70.0)
"""Temperatures [degC] ``at_temperature`` accepts: the span over which image-sensor dark
current is usually characterised (an assumption; beyond it other leakage paths take over)."""
TEMPERATURE_SCALED_FIELDS = (
    "dark_rate_e_per_s", "leak_rate_hz", "shot_noise_rate_hz", "shot_noise_on_rate_hz", "shot_noise_off_rate_hz",
    "hot_pixel_rate_hz",
)
"""PixelParams fields ``at_temperature`` scales: the dark current and the rates it drives
(the leak: junction leakage in the reset switch, Nozaki & Delbruck 2017; the dark background;
hot pixels, pixels of high dark current)."""


# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SensorPreset:
    """A sensor as data: geometry, default pixel parameters, and where each number comes from."""

    name: str
    description: str
    width: int
    """Pixels per row."""
    height: int
    """Rows."""
    pixel_pitch_m: float
    """Pixel pitch [m]."""
    fill_factor: float
    """Share of the light arriving on a pixel that reaches its photodiode (= pixel.fill_factor)."""
    back_illuminated: bool
    mean_wavelength_m: float
    """Mean wavelength of the sensitivity range [m], for the diffraction PSF (eq. 17)."""
    pixel: PixelParams
    """Default pixel parameters."""
    biases: BiasSet | None
    """The bias set ``pixel`` was derived from (None if not bias-based)."""
    qe_notes: str
    sources: tuple[str, ...]
    assumptions: tuple[str, ...]
    readout: ReadoutParams | None = None
    """The readout's maximum event rate, FIFO depth and timestamp tick (``evstwin.readout``);
    None: an ideal readout (``simulate`` then keeps the engine's times unless the scenario
    gives ``[readout]`` figures)."""
    qe: QECurve | None = None
    """Spectral quantum efficiency (``evstwin.spectra``): magnitudes become electrons through
    it and the source's spectrum. None: the paper's convention, a magnitude counts the photons
    of the V band (``Optics.zero_point_ph_s_m2``) and the pixel's yield applies to them all."""
    dark_reference_temperature_c: float = 25.0
    """Temperature [degC] at which ``pixel``'s dark current, leak, background and hot-pixel
    rates hold (``at_temperature``)."""
    dark_doubling_c: float = DARK_DOUBLING_C
    """Temperature rise [degC] that doubles the dark current and the rates it drives."""
    vendor_biases: PropheseeBiases | None = None
    """The sensor's biases in the vendor's own names and units (``[biases] bias_diff_on`` ...)
    and the laws that map them onto ``pixel`` (``evstwin.presets.prophesee_biases``); None: the
    sensor has none (the DAVIS346's biases are currents, ``BiasSet``)."""

    def __post_init__(self) -> None:
        size(self.width, self.height)
        positive("pixel_pitch_m", self.pixel_pitch_m)
        positive("mean_wavelength_m", self.mean_wavelength_m)
        ff = finite("fill_factor", self.fill_factor)
        if not 0.0 < ff <= 1.0:
            raise ValueError(f"fill_factor must be in (0, 1]; got fill_factor={self.fill_factor!r}")
        if self.pixel.fill_factor != ff:
            raise ValueError(
                f"pixel.fill_factor={self.pixel.fill_factor!r} must equal the preset's fill_factor={ff!r}"
            )

    def at_temperature(self, params: PixelParams, temperature_c: float) -> PixelParams:
        """``params`` with the dark current and the rates it drives (leak, eq. 12 background,
        hot pixels) moved from ``dark_reference_temperature_c`` to ``temperature_c`` by
        ``2 ** ((T - T_ref) / dark_doubling_c)`` (see ``DARK_DOUBLING_C``). ValueError outside
        ``TEMPERATURE_RANGE_C``, where the law has not been shown to hold."""
        t = finite("temperature_c", temperature_c)
        lo, hi = TEMPERATURE_RANGE_C
        if not lo <= t <= hi:
            raise ValueError(f"temperature_c must be in [{lo:g}, {hi:g}] degC (the range of the dark-current law "
                             f"2^(dT/{self.dark_doubling_c:g} degC)); got temperature_c={temperature_c!r}")
        factor = 2.0 ** ((t - self.dark_reference_temperature_c) / self.dark_doubling_c)
        return params.replace(**{name: getattr(params, name) * factor for name in TEMPERATURE_SCALED_FIELDS
                                 if getattr(params, name) is not None})  # None: the per-polarity rate unset

    def readout_params(self, **overrides: Any) -> ReadoutParams | None:
        """The preset's readout figures with overrides (``max_rate_hz``, ``fifo_depth``,
        ``tick_s``); None if the preset has none and no overrides are given. A preset without
        figures needs both max_rate_hz and fifo_depth (ValueError naming the missing ones)."""
        if self.readout is not None:
            return self.readout.replace(**overrides)
        if not overrides:
            return None
        missing = [k for k in ("max_rate_hz", "fifo_depth") if k not in overrides]
        if missing:
            raise ValueError(f"preset {self.name!r} has no readout figures: give {' and '.join(missing)}")
        return ReadoutParams(**overrides)

    def pixel_params(self, biases: BiasSet | None = None, **overrides: Any) -> PixelParams:
        """The preset's pixel parameters, re-derived from ``biases`` if given, then overrides
        (e.g. ``get_preset('davis346').pixel_params(PAPER_RUN_3, dark_rate_e_per_s=290)``)."""
        if biases is not None:
            return biases.pixel_params(self.pixel, **overrides)
        return self.pixel.replace(**overrides)

    def optics(self, focal_length_m: float, f_number: float, **kwargs: Any) -> Optics:
        """An ``Optics`` on this sensor (pitch, size and mean wavelength filled in)."""
        kwargs.setdefault("pixel_pitch_m", self.pixel_pitch_m)
        kwargs.setdefault("mean_wavelength_m", self.mean_wavelength_m)
        kwargs.setdefault("width_px", self.width)
        kwargs.setdefault("height_px", self.height)
        return Optics(focal_length_m=focal_length_m, f_number=f_number, **kwargs)

    def sensor(self, params: PixelParams | None = None, seed: int = 0, num_threads: int | None = None) -> Sensor:
        """An ``evstwin.Sensor`` of this size (params default: ``self.pixel``)."""
        return Sensor(
            self.width,
            self.height,
            self.pixel if params is None else params,
            seed=seed,
            num_threads=num_threads,
        )


READOUT_FIFO_ASSUMPTION = (
    "readout FIFO depth 4096 events: no datasheet gives the depth of the buffer between the pixel "
    "array and the link; 4096 is a typical FPGA block-RAM FIFO (assumption). It bounds the worst "
    "queueing delay at fifo_depth / max_rate_hz; change it with [readout] fifo_depth"
)


QE_REFERENCE_WAVELENGTH_M = 550e-9
"""Wavelength [m] whose photons the engine counts for a front-illuminated preset with a QE
curve: the pixel's yield (``PixelParams.electrons_per_photon``) is the curve's QE there."""
FSI_COLLECTION_DEPTH_M = 2e-6
"""Depth [m] from which a front-illuminated 0.18 um CMOS photodiode collects its electrons
(depletion plus diffusion; an assumption: no figure for these pixels was found). It sets the
red and near-infrared response: QE at 700 nm is 1 - exp(-1890/cm x 2 um) = 31 % of the
optical factor, at 550 nm 72 %."""
FSI_TRANSMISSION = 0.68
"""Share of the light entering a front-illuminated photodiode through its dielectric stack:
the paper's Table 3 tau, kept."""


def _fsi_pixel(base: PixelParams, fill_factor: float) -> PixelParams:
    """``base`` with a front-illuminated silicon photodiode whose yield is its QE curve's at
    ``QE_REFERENCE_WAVELENGTH_M`` (eq. 2 with silicon's alpha there and the collection depth)."""
    return base.replace(fill_factor=fill_factor, internal_qe=1.0, transmission=FSI_TRANSMISSION,
                        absorption_per_m=float(silicon_absorption_per_m(QE_REFERENCE_WAVELENGTH_M)),
                        depletion_width_m=FSI_COLLECTION_DEPTH_M)


def _fsi_qe(fill_factor: float, what: str) -> QECurve:
    return silicon_qe_curve(
        fill_factor * FSI_TRANSMISSION, FSI_COLLECTION_DEPTH_M,
        f"{what}: eq. 2 with silicon's absorption spectrum (Green 2008), fill factor {fill_factor:g} x "
        f"transmission {FSI_TRANSMISSION:g} x (1 - exp(-alpha(lambda) x {FSI_COLLECTION_DEPTH_M * 1e6:g} um)); no "
        "measured QE curve of this sensor was found (Taverni et al. 2018, IEEE TCAS-II 65, 677, measured the "
        "DAVIS346's; its numbers were not reachable)")
