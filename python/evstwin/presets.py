"""Sensor presets and bias currents -> pixel parameters.

A ``SensorPreset`` is data: the geometry of a sensor, its default ``PixelParams`` and the
sources of every number. A ``BiasSet`` holds the six DAVIS bias currents [A] and turns them
into pixel parameters:

* thresholds (paper eq. 8-9, Nozaki & Delbruck 2017): ``theta_on = k ln(I_ON / I_diff)``,
  ``theta_off = k ln(I_diff / I_OFF)`` with ``k = kappa_n C2 / (kappa_p^2 C1)``. The paper's
  text says k ~ 1/14, but every threshold printed in its Tables 1 and 2 is reproduced (to
  0.1 %) by ``k = 0.0659`` (~1/15.17), the default here (docs/development/decisions.md, "Thresholds");
* refractory period from I_refr (a charge model, calibrated; see ``refractory_from_bias``);
* source-follower cutoff from I_sf (subthreshold g_m / 2 pi C, calibrated; see
  ``cutoff_from_bias``).
The photoreceptor bias I_pr is kept for the record but not mapped: the engine's photoreceptor
bandwidth follows the photocurrent (``PixelParams.pr_pole``), which limits it in the dark.

Every derived value can be overridden (``BiasSet.pixel_params(**overrides)``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from ._checks import finite, positive
from .constants import BOLTZMANN_J_K, ELEMENTARY_CHARGE_C
from .optics import DAVIS346_MEAN_WAVELENGTH_M, Optics
from .pixel import PixelParams
from .readout import ReadoutParams
from .spectra import QECurve, silicon_absorption_per_m, silicon_qe_curve

# ---------------------------------------------------------------------------------------------
# constants

K_THRESHOLD_DAVIS346 = 0.0659
"""kappa_n C2 / (kappa_p^2 C1) of eq. 8-9 that reproduces all six thresholds of the paper's
Tables 1-2 (e.g. 0.0659 ln(0.85 uA / 235.3 nA) = 0.0846). The documentation's "decisions and measured dead ends", "Thresholds"."""
K_THRESHOLD_TEXT = 1.0 / 14.0
"""The paper's text approximation of the same factor (sec. 2.4, after its ref. [13])."""

THERMAL_VOLTAGE_V = BOLTZMANN_J_K * 300.0 / ELEMENTARY_CHARGE_C
"""U_T = k_B T / q at 300 K [V] (25.85 mV)."""

SF_KAPPA = 0.7
"""Subthreshold slope factor kappa of the source follower (a typical CMOS value; assumption)."""
SF_CALIBRATION_CURRENT_A = 834.7e-15
"""I_sf of the paper's Table 1 "Slow SF" bias set [A]..."""
SF_CALIBRATION_CUTOFF_HZ = 10.0
"""...mapped to the paper's f_c = 10 Hz (sec. 2.2, "a typical value")."""
SF_LOAD_CAPACITANCE_F = (
    SF_KAPPA * SF_CALIBRATION_CURRENT_A / (2.0 * math.pi * THERMAL_VOLTAGE_V * SF_CALIBRATION_CUTOFF_HZ)
)
"""Capacitance the source follower drives [F], implied by the calibration above: 360 fF.
Not a published DAVIS346 figure: it is of the order of a change-amplifier input capacitance
C1 plus wiring in an 18.5 um pixel, but treat it as a one-point calibration of f_c ~ I_sf."""

REFRACTORY_CALIBRATION_CURRENT_A = 4.7e-9
"""I_refr of the paper's Table 1 bias set [A]..."""
REFRACTORY_CALIBRATION_S = 1e-3
"""...mapped to a 1 ms refractory period (the engine default), inside the 330 us - 10 ms that
McReynolds et al. measured on the DAVIS346 (paper sec. 2.4, its ref. [12])."""
REFRACTORY_CHARGE_C = REFRACTORY_CALIBRATION_S * REFRACTORY_CALIBRATION_CURRENT_A
"""Effective charge Q = C dV recharged through I_refr [C]: 4.7 pC (assumption). The measured
330 us - 10 ms then corresponds to I_refr from 14 nA down to 0.47 nA. 4.7 pC would be pF x V,
far above any in-pixel node: the nominal bias-generator current is evidently not the current
in the pixel's refractory transistor, so Q is an effective constant, not a capacitance."""


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
# bias -> parameter models


def thresholds_from_biases(
    i_on_a: float, i_diff_a: float, i_off_a: float, k: float = K_THRESHOLD_DAVIS346
) -> tuple[float, float]:
    """(theta_on, theta_off) [ln units, both > 0] from the comparator biases [A] (eq. 8-9).

    ``theta_on = k ln(i_on_a / i_diff_a)``, ``theta_off = k ln(i_diff_a / i_off_a)``; k
    defaults to 0.0659 (see module doc; ``K_THRESHOLD_TEXT`` = 1/14 is the text's value).
    Raises ValueError naming the currents when one is not > 0 or a threshold is not > 0
    (the biases must satisfy I_ON > I_diff > I_OFF).
    """
    on = positive("i_on_a", i_on_a)
    diff = positive("i_diff_a", i_diff_a)
    off = positive("i_off_a", i_off_a)
    kk = positive("k", k)
    theta_on = kk * math.log(on / diff)
    theta_off = kk * math.log(diff / off)
    if theta_on <= 0.0:
        raise ValueError(
            f"theta_on = k ln(i_on_a / i_diff_a) = {theta_on:.4g} is not > 0: the ON threshold needs "
            f"i_on_a > i_diff_a; got i_on_a={on:g} A, i_diff_a={diff:g} A"
        )
    if theta_off <= 0.0:
        raise ValueError(
            f"theta_off = k ln(i_diff_a / i_off_a) = {theta_off:.4g} is not > 0: the OFF threshold needs "
            f"i_diff_a > i_off_a; got i_diff_a={diff:g} A, i_off_a={off:g} A"
        )
    return theta_on, theta_off


# Table 3 of the paper: the photodiode material constants of eq. 3.
TABLE3_DARK = {
    "hole_diffusion_m2_s": 6.4632e-4,
    "electron_diffusion_m2_s": 0.0129,
    "hole_diffusion_length_m": 5.685e-6,
    "electron_diffusion_length_m": 2.542e-5,
    "acceptor_m3": 1e23,
    "donor_m3": 1e23,
    "intrinsic_m3": 2.1e12,
    "depletion_width_m": 1.1637e-7,
}


def dark_rate_eq3(
    tau_g_s: float,
    pixel_pitch_m: float = 18.5e-6,
    fill_factor: float = 0.22,
    **constants: float,
) -> float:
    """Mean dark-electron rate [e-/s] of eq. 1 and 3 (the ``physics`` dark-current model):
    ``J = (e D_h / (L_h N_d) + e D_e / (L_e N_a)) n_i^2 + e W n_i / tau_g`` over the
    photodiode area ``pitch^2 * fill_factor``, divided by e.

    tau_g_s: generation lifetime [s], which the paper does not give (a parameter). The other
    constants default to Table 3 (``TABLE3_DARK``; override by name). With them the rate is
    tiny (about 2 e-/s of diffusion plus 18 e-/s at tau_g = 1 us, against the 18000 e-/s
    iniVation quotes): Table 3's n_i = 2.1e12 m^-3 is far below silicon's ~1e16 m^-3, so use
    it to explore, not as a calibrated figure. Feed the result to
    ``PixelParams.dark_rate_e_per_s`` with ``dark_model='poisson'``.
    """
    unknown = sorted(set(constants) - set(TABLE3_DARK))
    if unknown:
        raise TypeError(f"unknown eq. 3 constant(s) {unknown}; known: {sorted(TABLE3_DARK)}")
    c = dict(TABLE3_DARK, **constants)
    for name, value in [("tau_g_s", tau_g_s), ("pixel_pitch_m", pixel_pitch_m), ("fill_factor", fill_factor), *c.items()]:
        positive(name, value)
    diffusion = (c["hole_diffusion_m2_s"] / (c["hole_diffusion_length_m"] * c["donor_m3"])
                 + c["electron_diffusion_m2_s"] / (c["electron_diffusion_length_m"] * c["acceptor_m3"])) * c["intrinsic_m3"] ** 2
    generation = c["depletion_width_m"] * c["intrinsic_m3"] / tau_g_s
    # J / e [electrons / (s m^2)] times the photodiode area.
    return float((diffusion + generation) * pixel_pitch_m**2 * fill_factor)


def refractory_from_bias(i_refr_a: float, charge_c: float = REFRACTORY_CHARGE_C) -> float:
    """Refractory period [s] = Q / I_refr: the time I_refr takes to recharge the reset node.

    Q defaults to the calibrated 4.7 pC (1 ms at the paper's Table 1 I_refr = 4.7 nA; see
    ``REFRACTORY_CHARGE_C``). A model assumption: the inverse dependence is the circuit's,
    the constant is fitted, not measured.
    """
    return positive("charge_c", charge_c) / positive("i_refr_a", i_refr_a)


def cutoff_from_bias(
    i_sf_a: float,
    capacitance_f: float = SF_LOAD_CAPACITANCE_F,
    kappa: float = SF_KAPPA,
    thermal_voltage_v: float = THERMAL_VOLTAGE_V,
) -> float:
    """Source-follower low-pass cutoff [Hz]: f_c = g_m / (2 pi C) with g_m = kappa I_sf / U_T.

    The subthreshold transconductance of the follower charging its load capacitance. With the
    default (calibrated) C = 360 fF the paper's I_sf = 834.7 fA gives its 10 Hz; the model
    says f_c scales as I_sf, which is the part to trust. In the dark the photoreceptor, not
    the follower, may set the bandwidth (see ``PixelParams.pr_pole``).
    """
    i = positive("i_sf_a", i_sf_a)
    c = positive("capacitance_f", capacitance_f)
    return (
        positive("kappa", kappa)
        * i
        / (2.0 * math.pi * positive("thermal_voltage_v", thermal_voltage_v) * c)
    )


# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class BiasSet:
    """The DAVIS pixel bias currents [A]. The three comparator currents are required; I_pr,
    I_sf and I_refr may be None when a source does not give them (their parameters are then
    left at the base ``PixelParams``' values).

    Validation at construction: every given current finite and > 0, and I_ON > I_diff > I_OFF
    (both thresholds > 0).
    """

    i_on_a: float
    """ON threshold bias I_ON [A]."""
    i_off_a: float
    """OFF threshold bias I_OFF [A]."""
    i_diff_a: float
    """Change-amplifier bias I_diff [A]."""
    i_pr_a: float | None = None
    """Photoreceptor bias I_pr [A] (recorded, not mapped)."""
    i_sf_a: float | None = None
    """Source-follower bias I_sf [A] -> cutoff_hz."""
    i_refr_a: float | None = None
    """Refractory bias I_refr [A] -> refractory_s."""
    name: str = ""
    source: str = ""

    def __post_init__(self) -> None:
        for f in ("i_on_a", "i_off_a", "i_diff_a", "i_pr_a", "i_sf_a", "i_refr_a"):
            v = getattr(self, f)
            if v is not None or f in ("i_on_a", "i_off_a", "i_diff_a"):
                object.__setattr__(self, f, positive(f, v))
        thresholds_from_biases(self.i_on_a, self.i_diff_a, self.i_off_a)

    def thresholds(self, k: float = K_THRESHOLD_DAVIS346) -> tuple[float, float]:
        """(theta_on, theta_off) [ln units] by eq. 8-9."""
        return thresholds_from_biases(self.i_on_a, self.i_diff_a, self.i_off_a, k)

    @property
    def refractory_s(self) -> float | None:
        """Refractory period [s] from I_refr (``refractory_from_bias``), None if not given."""
        return None if self.i_refr_a is None else refractory_from_bias(self.i_refr_a)

    @property
    def cutoff_hz(self) -> float | None:
        """Source-follower cutoff [Hz] from I_sf (``cutoff_from_bias``), None if not given."""
        return None if self.i_sf_a is None else cutoff_from_bias(self.i_sf_a)

    def derived(self, k: float = K_THRESHOLD_DAVIS346) -> dict[str, float]:
        """The PixelParams fields these biases set: theta_on, theta_off and, when the
        currents are given, refractory_s and cutoff_hz."""
        theta_on, theta_off = self.thresholds(k)
        out = {"theta_on": theta_on, "theta_off": theta_off}
        if self.refractory_s is not None:
            out["refractory_s"] = self.refractory_s
        if self.cutoff_hz is not None:
            out["cutoff_hz"] = self.cutoff_hz
        return out

    def pixel_params(
        self, base: PixelParams | None = None, *, k: float = K_THRESHOLD_DAVIS346, **overrides: Any
    ) -> PixelParams:
        """``base`` (default ``PixelParams()``) with the derived values, then ``overrides``
        (any PixelParams field, derived ones included; unknown names raise TypeError)."""
        base = PixelParams() if base is None else base
        changes: dict[str, Any] = dict(self.derived(k))
        changes.update(overrides)
        return base.replace(**changes)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


_PAPER = "the paper (Event-based Vision Sensor Physics-Based Digital Twin for Tuning SSA Use)"

FAST_PR_SLOW_SF_BALANCED_TH = BiasSet(
    i_pr_a=15.0e-6,
    i_sf_a=834.7e-15,
    i_refr_a=4.7e-9,
    i_on_a=186.9e-9,
    i_off_a=2.0e-9,
    i_diff_a=8.2e-9,
    name="fast_pr_slow_sf_balanced_th",
    source=f"{_PAPER}, Table 1 (after McReynolds et al.): theta 0.2061 / 0.093",
)
"""The bias set of the real DAVIS346 recording the paper validates against (Table 1)."""

PAPER_RUN_1 = BiasSet(
    i_on_a=0.85e-6,
    i_off_a=69e-9,
    i_diff_a=235.3e-9,
    name="paper_run_1",
    source=f"{_PAPER}, Table 2 run 1 (run 2 has the same biases): theta 0.0846 / 0.0809",
)
"""Table 2 runs 1-2 (the paper gives only the comparator currents)."""

PAPER_RUN_3 = BiasSet(
    i_on_a=0.75e-6,
    i_off_a=0.55e-9,
    i_diff_a=15.03e-9,
    name="paper_run_3",
    source=f"{_PAPER}, Table 2 run 3: theta 0.2578 / 0.2181",
)
"""Table 2 run 3."""

BIAS_SETS: dict[str, BiasSet] = {b.name: b for b in (FAST_PR_SLOW_SF_BALANCED_TH, PAPER_RUN_1, PAPER_RUN_3)}
"""Built-in bias sets by name."""


def get_bias_set(name: str) -> BiasSet:
    """A built-in bias set by name (ValueError listing the names otherwise)."""
    try:
        return BIAS_SETS[name.lower()]
    except (KeyError, AttributeError):
        raise ValueError(f"unknown bias set {name!r}; known: {sorted(BIAS_SETS)}") from None


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

    def __post_init__(self) -> None:
        for f in ("width", "height"):
            v = getattr(self, f)
            if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
                raise ValueError(f"{f} must be a positive integer; got {f}={v!r}")
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

    def sensor(self, params: PixelParams | None = None, seed: int = 0, num_threads: int | None = None) -> Any:
        """An ``evstwin.Sensor`` of this size (params default: ``self.pixel``)."""
        from .sensor import Sensor

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

DAVIS346_READOUT = ReadoutParams(
    max_rate_hz=12e6,
    fifo_depth=4096,
    tick_s=1e-6,
    sources=(
        "iniVation, DAVIS346 datasheet (inivation.com/wp-content/uploads/2019/08/DAVIS346.pdf, now "
        "docs.inivation.com/_static/hardware_guides/davis346.pdf): 'Bandwidth 12 MEvents/second', "
        "min. latency ~20 us. Not reachable from the machine this was written on: the figure is as "
        "quoted from that datasheet by two independent public sources; check it against your copy",
        "iniVation libcaer, davis.h (DAVIS_CONFIG_MUX_TIMESTAMP_RUN: the timestamp generator gives "
        "'microsecond accurate timestamps'); iniVation AEDAT 2.0 docs: 'Timestamps tick is 1 us'",
    ),
    assumptions=(READOUT_FIFO_ASSUMPTION,),
)
"""DAVIS346 readout: 12 Mev/s (the camera's bandwidth), 1 us timestamps, FIFO assumed."""

IMX636_READOUT = ReadoutParams(
    max_rate_hz=1.066e9,
    fifo_depth=4096,
    tick_s=1e-6,
    sources=(
        "Sony Semiconductor Solutions, event-based vision sensor page "
        "(sony-semicon.com/en/products/is/industry/evs.html) and Prophesee's IMX636 page: maximum "
        "event rate 1.066 Gevents/s (quoted as '1.06 Gevents/s' and '1066 Mev/s'). Not reachable "
        "from the machine this was written on: the figure is as quoted by public secondary sources",
        "Prophesee Metavision docs, EVT 2.0 / 3.0 formats and EventCD: timestamps in microseconds",
    ),
    assumptions=(
        READOUT_FIFO_ASSUMPTION,
        "1.066 Gev/s is the sensor's own readout. A camera delivers less: the EVK4's USB 3 link "
        "(1.6 Gbps in Prophesee's EVK docs) and the sensor's event-rate controller (ERC, which "
        "thins events in time windows instead of queueing them) set the rate you see; give "
        "[readout] max_rate_hz for your camera",
    ),
)
"""IMX636 readout: 1.066 Gev/s (the sensor's), 1 us timestamps, FIFO assumed."""

DAVIS346_RECORDING = (
    "a public DAVIS346 recording (the test data of the aedat package 2.3.0 on PyPI, tests/data/test_data.aedat4: "
    "2.36 s of a road in daylight)"
)
"""The real DAVIS346 recording the preset's background was measured on."""
DAVIS346_BACKGROUND_SOURCE = (
    f"{DAVIS346_RECORDING}, its static upper half (y < 120, 41,520 pixels): 289 events, all ON, "
    "2.95e-3 +- 0.18e-3 Hz per pixel, log-normal spread sigma 1.51 +- 0.14, 0 OFF (an OFF rate "
    "below 3.1e-5 Hz at 95 %), no hot pixel (evstwin calibrate-noise davis346_road.aedat4 --roi 0,0,346,120)"
)
"""Where the DAVIS346 preset's leak and background figures come from."""

_DAVIS346_BASE = PixelParams(
    # photodiode, paper Table 3 and sec. 3.1
    fill_factor=0.22,
    internal_qe=1.0,
    transmission=0.68,
    absorption_per_m=3e4,
    depletion_width_m=1.1637e-7,
    # noise: dark current from the paper's sec. 2.1; the background measured on the real
    # DAVIS346 road's static half (DAVIS346_BACKGROUND_SOURCE): all of it ON, so a leak, spread
    # log-normally across pixels; no eq. 12 background (0 OFF events there). The paper's own
    # sec. 2.4 figures (leak 0.1 Hz, R_n 0.05 Hz) stay in its run scenarios and paper_run_params.
    dark_rate_e_per_s=18000.0,
    leak_rate_hz=2.95e-3,
    leak_rate_sigma=1.51,
    shot_noise_rate_hz=0.0,
    shot_noise_factor=0.25,
    shot_noise_i_max_a=3.16e-9,
)

_DAVIS346_SOURCES = (
    f"{_PAPER}, sec. 3.1: 346 x 260 pixels, 18.5 um pitch, 22 % fill factor",
    f"{_PAPER}, Table 1: bias set 'Fast PR, Slow SF, Balanced TH' (McReynolds et al.)",
    f"{_PAPER}, sec. 2.1: dark rate 18000 e-/s (iniVation, its ref. [11])",
    f"{_PAPER}, sec. 2.4: F 0.25, I_max 3.16 nA (its leak 0.1 Hz and R_n 0.05 Hz: the run scenarios)",
    DAVIS346_BACKGROUND_SOURCE,
    "Nozaki & Delbruck (2017), IEEE Trans. Electron Devices (the paper's ref. [15]): eq. 8-9",
    "k = 0.0659 reproduces every threshold of the paper's Tables 1-2 (K_THRESHOLD_DAVIS346)",
)
_DAVIS346_ASSUMPTIONS = (
    "refractory 1 ms from I_refr = 4.7 nA via the calibrated Q = 4.7 pC (REFRACTORY_CHARGE_C)",
    "cutoff 10 Hz from I_sf = 834.7 fA via the calibrated C = 360 fF (SF_LOAD_CAPACITANCE_F)",
    "mean wavelength 0.7 um: the middle of a silicon photodiode's ~0.4-1.0 um response",
    "background measured in daylight only: the leak is taken as independent of the light (the "
    "paper's eq. 10-11); in the dark the twin adds its own filtered shot noise of the 18000 e-/s "
    "dark current; no dark DAVIS346 recording was at hand to check that",
    "the real background comes on the camera's 40 ms frame cycle (APS readout coupling); the "
    "twin's leak is not locked to it, so its rate matches and its timing does not",
    "dark current, leak and background hold at 25 degC and double every 6.5 degC (DARK_DOUBLING_C); the "
    "paper does not give the temperature of its 18000 e-/s",
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


DAVIS346 = SensorPreset(
    name="davis346",
    description="iniVation DAVIS346 (2nd generation, front-illuminated), the sensor of the paper",
    width=346,
    height=260,
    pixel_pitch_m=18.5e-6,
    fill_factor=0.22,
    back_illuminated=False,
    mean_wavelength_m=DAVIS346_MEAN_WAVELENGTH_M,
    pixel=FAST_PR_SLOW_SF_BALANCED_TH.pixel_params(_fsi_pixel(_DAVIS346_BASE, 0.22)),
    biases=FAST_PR_SLOW_SF_BALANCED_TH,
    qe_notes=(
        "Front-illuminated, 22 % fill factor, no microlens gain assumed; QE from silicon's absorption "
        "spectrum over a 2 um collection depth through the paper's 0.68 transmission: 10 % at 550 nm (the "
        "engine's reference photon), 15 % peak, 4.6 % at 700 nm. davis346_paper keeps the paper's 0.35 %."
    ),
    sources=_DAVIS346_SOURCES + ("Green (2008), Sol. Energy Mater. Sol. Cells 92, 1305: silicon's absorption",),
    assumptions=_DAVIS346_ASSUMPTIONS + (
        "collection depth 2 um (FSI_COLLECTION_DEPTH_M) and the paper's transmission 0.68: they set the QE curve",
    ),
    readout=DAVIS346_READOUT,
    qe=_fsi_qe(0.22, "DAVIS346"),
)
"""The DAVIS346 as a camera: the paper's geometry, biases and dark current, the measured
background, and a silicon QE curve (about 15 % at its peak) in place of the paper's 0.35 %."""

DAVIS346_PAPER = dataclasses.replace(
    DAVIS346,
    name="davis346_paper",
    description="the paper's DAVIS346: its Table 3 photodiode (0.35 % of photons absorbed), kept to reproduce it",
    pixel=FAST_PR_SLOW_SF_BALANCED_TH.pixel_params(_DAVIS346_BASE),
    qe=None,
    qe_notes=(
        "Front-illuminated, 22 % fill factor, no microlens gain assumed. Photon-to-electron "
        "efficiency by eq. 2 with Table 3: tau (1 - exp(-alpha W)) = 0.68 x 0.0035 = 0.24 % of the "
        "photons on the photodiode (x 0.22 fill factor): the paper's constants, kept as given. No "
        "spectrum: a magnitude counts the V band's photons (the paper's scenes are lab LEDs given in photons/s)."
    ),
    sources=_DAVIS346_SOURCES + (f"{_PAPER}, Table 3: alpha, eta_i, tau, W",),
    assumptions=_DAVIS346_ASSUMPTIONS,
)
"""The paper's DAVIS346 with its Table 1 biases (theta 0.2060 / 0.0930, 1 ms, 10 Hz) and its
Table 3 photodiode: what the paper's tables and its section 3 were computed with. Everything
else is the DAVIS346 preset's."""

IMX636_RECORDING = (
    "a public Prophesee EVK4 recording (the test data of the faery package, tests/data/evt3.raw: 10.77 s of a "
    "point source on a dark field)"
)
"""The real IMX636 recording the preset's background figures were measured on."""
IMX636_THETA = math.log(1.25)
"""A 25 % contrast step [ln units]: the nominal contrast threshold quoted for Sony's 4.86 um
event sensors (a camera datasheet of the IMX646, the IMX636's sibling), the Gen3 preset's."""
IMX636_THETA_ON = 0.235
IMX636_THETA_OFF = 0.21
"""The IMX636 preset's thresholds [ln units]: a 25 % step on average, split by the EVK4
recording's ON/OFF ratio of 0.91 within 200 px of its star (``imx636-pointsource``)."""
IMX636_COLLECTION_DEPTH_M = 5e-6
"""Depth [m] from which the IMX636's back-illuminated photodiode collects (an assumption: a
few um of epitaxial silicon is typical of BSI pixels). With the paper's 0.68 surface
transmission it gives a QE of 68 % in the blue-green, 43 % at 690 nm, 24 % at 800 nm."""
IMX636_ABSORPTION_PER_M = 2.0e5
"""Silicon's absorption at 690 nm [1/m] (Green 2008: 2.04e5): the IMX636 preset's engine counts
690 nm photons, its yield 0.68 (1 - exp(-2e5 x 5 um)) = 43 %, the QE curve's there."""

IMX636 = SensorPreset(
    name="imx636",
    description="Sony IMX636 (Prophesee Gen4.1 HD), as in the Prophesee EVK4 HD",
    width=1280,
    height=720,
    pixel_pitch_m=4.86e-6,
    fill_factor=1.0,
    back_illuminated=True,
    mean_wavelength_m=DAVIS346_MEAN_WAVELENGTH_M,
    pixel=_DAVIS346_BASE.replace(
        fill_factor=1.0,
        absorption_per_m=IMX636_ABSORPTION_PER_M,
        depletion_width_m=IMX636_COLLECTION_DEPTH_M,
        theta_on=IMX636_THETA_ON,
        theta_off=IMX636_THETA_OFF,
        refractory_s=1.3e-4,
        cutoff_hz=2000.0,
        pr_pole=True,
        leak_rate_hz=0.0,
        shot_noise_on_rate_hz=2.2e-4,
        shot_noise_off_rate_hz=1.69e-3,
        shot_noise_factor=1.0,
        background_rate_sigma=1.41,
        hot_pixel_fraction=1.0 / (1280 * 720),
        hot_pixel_rate_hz=1170.0,
        hot_pixel_duty=0.13,
        hot_pixel_burst_s=0.046,
        hot_pixel_on_share=0.59,
        hot_pixel_alternation=0.78,
    ),
    biases=None,
    qe_notes=(
        "Back-illuminated stacked sensor with microlenses: fill_factor 1.0 stands for an effective "
        "optical fill factor near 1 (Prophesee measures QE over the whole 4.86 um pixel). QE from silicon's "
        "absorption spectrum over a 5 um collection depth through the paper's 0.68 transmission: 68 % peak, "
        "43 % at 690 nm (the engine's reference photon). No measured curve was found (Prophesee publishes it "
        "as a figure only)."
    ),
    sources=(
        (
            "Finateu et al., 'A 1280x720 back-illuminated stacked temporal contrast event-based vision "
            "sensor with 4.86 um pixels, ...', ISSCC 2020: 1280 x 720, 4.86 um, BSI stacked"
        ),
        (
            f"{IMX636_RECORDING} (10.77 s, dark field): refractory 130 us, the shortest interval between two "
            "events of its hot pixel (131 us)"
        ),
        (
            f"{IMX636_RECORDING}, dark corner x >= 980, y >= 520 (60,000 pixels; `evstwin calibrate-noise "
            "... --roi 980,520,300,200`): background 2.20e-4 Hz ON and 1.69e-3 Hz OFF per pixel, log-normal "
            "spread sigma 2.58 (ON) and 1.26 (OFF), 1.41 event-weighted; one ON-leaky pixel (1224, 658) apart "
            "(113 events, 111 ON); no leak beyond the ON background"
        ),
        (
            f"{IMX636_RECORDING}: one hot pixel in 921,600 at (187, 261), 1447 events (134 Hz, 78 % of "
            "successive events alternate polarity) in bursts (`calibrate-noise ... --roi 0,0,240,720`): "
            "1015 Hz while active, i.e. r = 1170 Hz with 130 us dead time, duty 0.13, mean burst 46 ms; "
            "854 of its events ON (0.59), switching polarity after 66 % of its ON events and 95 % of its OFF "
            "events: the two-state chain of hot_pixel_on_share 0.59 and hot_pixel_alternation 0.78"
        ),
    ),
    assumptions=(
        "fill factor 1.0 (BSI + microlens, effective)",
        (
            "thresholds ln(1.25) = 0.223 both ways (a 25 % contrast step), far enough above the filtered "
            "shot noise that the dark background comes from eq. 12 as measured; Prophesee biases are DAC "
            "settings, not the currents of eq. 8-9, so measure theta with S-curves (McReynolds et al. 2024, "
            "arXiv:2404.07656) for a given camera"
        ),
        (
            "QE: collection depth 5 um and transmission 0.68 (IMX636_COLLECTION_DEPTH_M); a simulator's 0.6 "
            "(dvs_performance_metrics, Gen4 config) is the only other figure found"
        ),
        (
            "dark rate 18000 e-/s at 25 degC, the DAVIS346's: no primary IMX636 figure was found (a simulator "
            "uses 5.5 fA = 34,000 e-/s, dvs_performance_metrics); the recording's fluxes are set against it"
        ),
        (
            "source follower 2 kHz: the EVK4 recording's star core follows ms-scale image motion (the 10 Hz of "
            "the DAVIS346's Table 1 bias would smear it); Prophesee quotes a pixel latency under 100 us at "
            "1000 lux (IMX636 product brief 2024, as quoted by public notes)"
        ),
        "mean wavelength 0.7 um as for the DAVIS346",
        "eq. 12's illumination factor F = 1 (the recording is dark: it says nothing about F)",
    ),
    readout=IMX636_READOUT,
    qe=silicon_qe_curve(
        0.68, IMX636_COLLECTION_DEPTH_M,
        "IMX636: eq. 2 with silicon's absorption spectrum (Green 2008), transmission 0.68 x (1 - exp(-alpha(lambda) x "
        "5 um)), fill factor 1 (BSI with microlenses); an assumption, no measured curve was found"),
)
"""Sony IMX636 / Prophesee EVK4: geometry sourced; refractory period, background (rates per
polarity, their spread, hot pixels), thresholds' ON/OFF split and the source follower from a
real recording; QE curve and dark current assumed."""

GEN3_VGA_DARK_RATE_E_PER_S = 18000.0 * (15.0**2 * 0.25) / (18.5**2 * 0.22)
"""The Gen3 VGA preset's dark current [e-/s]: the DAVIS346's 18,000 e-/s scaled by photodiode
area (15 um x 15 um x 0.25 against 18.5 um x 18.5 um x 0.22): 13,450 e-/s. Both are 0.18 um
CMOS front-illuminated pixels; a dark current grows with the junction's area (assumption)."""
GEN3_VGA_CUTOFF_HZ = 150.0
"""The Gen3 VGA preset's source-follower cutoff [Hz], calibrated on one published figure: the
PPS3MVCD's typical latency of 200 us (CenturyArks SilkyEvCam-USB specification, Table 1; taken
at 1000 lux, as Prophesee states its latencies): ``evstwin characterize prophesee_gen3_vga``
gives a median of 202 us at 1000 lux with 150 Hz (130 Hz: 233 us, 300 Hz: 93 us)."""
GEN3_VGA_THETA = IMX636_THETA  # the same assumed 25 % contrast step (no Gen3 figure at hand)
"""The Gen3 VGA preset's ON and OFF thresholds [ln units]: a 25 % contrast step, as assumed for
the IMX636 (Prophesee's biases are DAC settings, not currents)."""

PROPHESEE_GEN3_VGA = SensorPreset(
    name="prophesee_gen3_vga",
    description="Prophesee Gen3 VGA (PPS3MVCD, 3rd generation), as in the Gen3 EVK and the SSA studies of 2019-2020",
    width=640,
    height=480,
    pixel_pitch_m=15e-6,
    fill_factor=0.25,
    back_illuminated=False,
    mean_wavelength_m=DAVIS346_MEAN_WAVELENGTH_M,
    pixel=_fsi_pixel(_DAVIS346_BASE, 0.25).replace(
        dark_rate_e_per_s=GEN3_VGA_DARK_RATE_E_PER_S,
        theta_on=GEN3_VGA_THETA,
        theta_off=GEN3_VGA_THETA,
        refractory_s=1e-3,
        cutoff_hz=GEN3_VGA_CUTOFF_HZ,
        pr_pole=True,
    ),
    biases=None,
    qe_notes=(
        "Front-illuminated 0.18 um CMOS pixel (Gen3 predates the stacked BSI Gen4 of Finateu et al. 2020), "
        "fill factor 25 % (assumed, see assumptions); QE from silicon's absorption spectrum over a 2 um "
        "collection depth through 0.68 transmission, as for the DAVIS346: 17 % peak, 12 % at 550 nm."
    ),
    sources=(
        "Prophesee, Gen3 VGA CD sensor (PPS3MVCD) and its evaluation kit: 640 x 480 pixels, 15 um pitch "
        "(as quoted by Prophesee's product pages and in the Metavision docs' list of sensor generations: Gen3 "
        "sensors use EVT 2.0). Not reachable from the machine this was written on: the figures are as quoted "
        "by secondary sources; check them against your datasheet",
        "Afshar, Nicholson, van Schaik & Cohen (2020), 'Event-based object detection and tracking for space "
        "situational awareness', IEEE Sensors J. 20(24), 15117; Cohen, Afshar, Morreale, Bessell, Wabnitz, "
        "Rutten & van Schaik (2019), 'Event-based sensing for space situational awareness', J. Astronaut. "
        "Sci. 66, 125: the Prophesee VGA-class sensor in the field's published SSA observations, beside "
        "the DAVIS240/346 and, later, the IMX636",
    ),
    assumptions=(
        "fill factor 0.25: the order of the figure quoted for Gen3 pixels (secondary sources; not verified)",
        "thresholds ln(1.25) = 0.223 both ways, a 25 % contrast step, as for the IMX636 preset",
        "refractory 1 ms as the DAVIS346 preset's; the photoreceptor pole on",
        "source follower 150 Hz, calibrated on the typical latency of 200 us (GEN3_VGA_CUTOFF_HZ), taken at 1000 lux",
        "dark rate 13,450 e-/s at 25 degC (GEN3_VGA_DARK_RATE_E_PER_S: the DAVIS346's per photodiode area) and "
        "the DAVIS346's background (a 2.95e-3 Hz leak, sigma 1.51, no eq. 12 rate; no Gen3 background figures "
        "at hand: measure them with `evstwin calibrate-noise` on a Gen3 recording)",
        "QE: collection depth 2 um and transmission 0.68, as for the DAVIS346 (FSI_COLLECTION_DEPTH_M)",
        "mean wavelength 0.7 um as for the DAVIS346",
        "readout FIFO depth assumed (READOUT_FIFO_ASSUMPTION)",
    ),
    readout=ReadoutParams(
        max_rate_hz=50e6,
        fifo_depth=4096,
        tick_s=1e-6,
        sources=(
            "CenturyArks SilkyEvCam-USB specification Rev 1.02 (PPS3MVCD sensor), Table 1: 'Maximum readout "
            "throughput 50Mevents/s', 'Typical Latency 200us' (as quoted by public notes)",
        ),
        assumptions=(READOUT_FIFO_ASSUMPTION,),
    ),
    qe=_fsi_qe(0.25, "Prophesee Gen3 VGA"),
)
"""Prophesee Gen3 VGA: geometry and readout as published (640 x 480, 15 um, 50 Mev/s); pixel figures assumed."""

PRESETS: dict[str, SensorPreset] = {p.name: p for p in (DAVIS346, IMX636, PROPHESEE_GEN3_VGA, DAVIS346_PAPER)}
"""Built-in sensor presets by name."""


def get_preset(name: str) -> SensorPreset:
    """A built-in sensor preset by name, case-insensitive (ValueError listing the names)."""
    try:
        return PRESETS[name.lower()]
    except (KeyError, AttributeError):
        raise ValueError(f"unknown sensor preset {name!r}; known: {sorted(PRESETS)}") from None


def paper_run_params(run: int, base: PixelParams | None = None, **overrides: Any) -> PixelParams:
    """Pixel parameters of the paper's simulation runs 1-3 (Table 2, sec. 3.3).

    1: Table 2 run-1 biases, shot and leak noise on, 18000 e-/s dark;
    2: same biases, no shot or leak noise, 18000 e-/s;
    3: run-3 biases, no shot or leak noise, 290 e-/s.
    Everything else from ``base`` (default: the davis346_paper preset, so 1 ms and 10 Hz). The paper
    used eq. 4 literally for the dark current: pass ``dark_model='paper'`` to do the same.
    """
    base = DAVIS346_PAPER.pixel if base is None else base
    if run == 1:
        changes: dict[str, Any] = dict(
            PAPER_RUN_1.derived(), dark_rate_e_per_s=18000.0, shot_noise_rate_hz=0.05, leak_rate_hz=0.1
        )
    elif run == 2:
        changes = dict(
            PAPER_RUN_1.derived(), dark_rate_e_per_s=18000.0, shot_noise_rate_hz=0.0, leak_rate_hz=0.0
        )
    elif run == 3:
        changes = dict(
            PAPER_RUN_3.derived(), dark_rate_e_per_s=290.0, shot_noise_rate_hz=0.0, leak_rate_hz=0.0
        )
    else:
        raise ValueError(f"run must be 1, 2 or 3 (the paper's Table 2); got run={run!r}")
    changes.update(overrides)
    return base.replace(**changes)
