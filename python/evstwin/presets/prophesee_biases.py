"""Prophesee sensor biases in the vendor's own names and units -> pixel parameters.

A Prophesee camera is tuned through named biases (``bias_diff_on``, ``bias_diff_off``,
``bias_diff``, ``bias_fo``, ``bias_pr``, ``bias_hpf``, ``bias_refr``): absolute voltages in mV
on the Gen3 VGA sensor, offsets in DAC codes from the chip's factory default on the IMX636.
No public source maps them to a contrast threshold, a cutoff or a dead time. The laws here
come from the DVS pixel circuit (Lichtsteiner, Posch & Delbruck 2008) with its transistors in
weak inversion, and each is anchored so that the vendor's default gives the preset's own
values exactly (default biases: the same events, bit for bit). What a bias moves:

* Gen3 (voltage biases): ``theta_on`` proportional to ``bias_diff_on - bias_diff`` and
  ``theta_off`` to ``bias_diff - bias_diff_off`` (the vendor: "the contrast sensitivity is
  expressed as the difference" of these values); ``cutoff_hz`` and ``1 / refractory_s``
  proportional to a subthreshold bias current, ``exp(kappa dV / U_T)`` of the bias voltage's
  change, U_T at the sensor's temperature.
* IMX636 (current-DAC codes): each code sets a bias current proportional to it; a threshold
  moves by ``k ln(N / N0)`` (the comparator level a subthreshold current sets, as in the
  paper's eq. 8-9), ``cutoff_hz`` follows ``N_fo / N_fo0`` and ``refractory_s``
  ``N_refr0 / N_refr``.

A bias the twin has no counterpart for (``bias_hpf``: no high-pass filter; ``bias_pr``: the
photoreceptor's pole follows the photocurrent alone) or that the vendor's driver does not let a
user change accepts only its default, and says why otherwise. Every law and constant, with its
source or the assumption behind it, is in ``PropheseeBiases.sources`` and ``.assumptions``,
which the presets reference shows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

from .._checks import finite
from ..constants import BOLTZMANN_J_K, ELEMENTARY_CHARGE_C
from ..pixel import PixelParams
from .biases import K_THRESHOLD_DAVIS346, SF_KAPPA

PROPHESEE_BIAS_NAMES = ("bias_diff_on", "bias_diff_off", "bias_diff", "bias_fo", "bias_pr", "bias_hpf", "bias_refr")
"""Every Prophesee bias name a scenario's ``[biases]`` table accepts (each preset takes the
ones its sensor has)."""
ZERO_CELSIUS_K = 273.15
"""0 degC in kelvin."""

DacKind = Literal["voltage", "current"]


def thermal_voltage_at_v(temperature_c: float) -> float:
    """U_T = k_B T / q [V] at ``temperature_c`` [degC] (25.69 mV at 25 degC)."""
    t_k = finite("temperature_c", temperature_c) + ZERO_CELSIUS_K
    if t_k <= 0.0:
        raise ValueError(f"temperature_c must be above absolute zero; got temperature_c={temperature_c!r}")
    return BOLTZMANN_J_K * t_k / ELEMENTARY_CHARGE_C


@dataclass(frozen=True)
class VendorBias:
    """One Prophesee bias as the vendor's driver exposes it, and what it moves in the twin."""

    name: str
    """The vendor's name (``bias_diff_on`` ...)."""
    default: int
    """The vendor's default in the preset's unit: mV (Gen3) or 0, the factory default's offset (IMX636)."""
    allowed: tuple[int, int]
    """The range the vendor's driver allows [unit of ``default``]; outside it a value is refused."""
    recommended: tuple[int, int] | None
    """The range the vendor recommends (None: the driver gives none beyond ``allowed``)."""
    moves: str
    """The PixelParams field the bias sets (``theta_on``, ``theta_off``, ``cutoff_hz``,
    ``refractory_s``; both thresholds for a reference), or "" where only the default is
    accepted."""
    effect: str
    """What the vendor says the bias does."""
    law: str
    """How the twin maps it (or why it accepts only the default)."""


@dataclass(frozen=True)
class PropheseeBiases:
    """A Prophesee sensor's biases: their names, units, ranges and constraints, and the laws
    that map them onto the preset's pixel parameters (``derive``)."""

    sensor: str
    """The sensor these biases belong to."""
    dac: DacKind
    """'voltage': absolute bias voltages in mV (Gen3); 'current': offsets in codes of a
    current DAC from the chip's factory default (IMX636)."""
    unit: str
    """The unit of every bias value."""
    biases: tuple[VendorBias, ...]
    """The sensor's biases."""
    factory_codes: tuple[tuple[str, int], ...] = ()
    """'current' only: the factory register codes N0 the offsets add to (assumed; see
    assumptions), by bias name."""
    threshold_margin: int = 1
    """'voltage' only: the least distance [mV] the vendor's driver keeps between
    ``bias_diff_on`` (above) or ``bias_diff_off`` (below) and ``bias_diff``."""
    kappa: float = SF_KAPPA
    """Subthreshold slope factor of the bias transistors (the exponential laws' slope)."""
    threshold_k: float = K_THRESHOLD_DAVIS346
    """'current' only: k of ``Delta theta = k ln(N / N0)`` [ln units per e-fold of bias current]."""
    register_max: int = 255
    """'current' only: the top code of the 8-bit bias registers."""
    sources: tuple[str, ...] = ()
    assumptions: tuple[str, ...] = ()

    # -- names, defaults, checks ---------------------------------------------------------------

    def names(self) -> tuple[str, ...]:
        """The bias names this sensor has."""
        return tuple(b.name for b in self.biases)

    def bias(self, name: str) -> VendorBias:
        """One bias by name (ValueError naming the sensor's biases otherwise)."""
        for b in self.biases:
            if b.name == name:
                return b
        raise ValueError(f"biases.{name}: the {self.sensor} has no {name}; its biases: {', '.join(self.names())}")

    def defaults(self) -> dict[str, int]:
        """Every bias at the vendor's default."""
        return {b.name: b.default for b in self.biases}

    def _code(self, name: str, offset: int) -> int:
        return dict(self.factory_codes)[name] + offset

    def check(self, values: dict[str, Any]) -> dict[str, int]:
        """``values`` (name -> value, any subset) checked and completed with the defaults.

        ValueError, one line naming the key and the value, for: a name this sensor lacks, a
        value that is not a whole number of the unit, a value outside the vendor's allowed
        range, a bias the twin accepts only at its default, and the vendor's constraints
        between biases (Gen3: ``bias_diff_on >= bias_diff + 1`` and ``bias_diff_off <= bias_diff - 1``
        mV; IMX636: a register code in 1..255 from the assumed factory code).
        """
        out = self.defaults()
        for name, value in values.items():
            b = self.bias(name)
            v = finite(f"biases.{name}", value)
            if not float(v).is_integer():
                raise ValueError(f"biases.{name}={value!r} must be a whole number of {self.unit} (the vendor's "
                                 "driver takes integers)")
            iv = int(v)
            lo, hi = b.allowed
            if not lo <= iv <= hi:
                raise ValueError(f"biases.{name}={value!r} is outside the range the vendor's driver allows for the "
                                 f"{self.sensor}, [{lo}, {hi}] {self.unit}")
            if not b.moves and iv != b.default:
                raise ValueError(f"biases.{name}={value!r}: {b.law}; only its default {b.default} {self.unit} is "
                                 "accepted")
            out[name] = iv
        if self.dac == "voltage":
            m = self.threshold_margin
            if out["bias_diff_on"] < out["bias_diff"] + m:
                raise ValueError(f"biases.bias_diff_on={out['bias_diff_on']} must be >= bias_diff + {m} = "
                                 f"{out['bias_diff'] + m} mV: the ON threshold is the distance above bias_diff")
            if out["bias_diff_off"] > out["bias_diff"] - m:
                raise ValueError(f"biases.bias_diff_off={out['bias_diff_off']} must be <= bias_diff - {m} = "
                                 f"{out['bias_diff'] - m} mV: the OFF threshold is the distance below bias_diff")
        else:
            for name, _ in self.factory_codes:
                code = self._code(name, out[name])
                if not 1 <= code <= self.register_max and self.bias(name).moves:
                    n0 = dict(self.factory_codes)[name]
                    raise ValueError(
                        f"biases.{name}={out[name]} puts its register at {code} (the assumed factory code {n0} plus "
                        f"the offset), outside 1..{self.register_max} where its current DAC gives a current: use an "
                        f"offset in [{1 - n0}, {self.register_max - n0}]")
        return out

    # -- the laws ------------------------------------------------------------------------------

    def derive(self, values: dict[str, Any], base: PixelParams, temperature_c: float = 25.0) -> dict[str, float]:
        """The PixelParams fields ``values`` set, from ``base`` (the preset's pixel: its values
        are the ones the vendor defaults give), at ``temperature_c`` [degC] (U_T of the
        exponential laws). Every given value is checked (``check``); the defaults give back
        ``base``'s theta_on, theta_off, cutoff_hz and refractory_s exactly."""
        v = self.check(values)
        d = self.defaults()
        if base.cutoff_hz is None:
            raise ValueError(f"biases: the {self.sensor}'s preset has no source-follower cutoff for bias_fo to scale")
        if self.dac == "voltage":
            on0 = d["bias_diff_on"] - d["bias_diff"]
            off0 = d["bias_diff"] - d["bias_diff_off"]
            theta_on = base.theta_on * ((v["bias_diff_on"] - v["bias_diff"]) / on0)
            theta_off = base.theta_off * ((v["bias_diff"] - v["bias_diff_off"]) / off0)
            u_t_mv = 1e3 * thermal_voltage_at_v(temperature_c)
            # bias_fo: a pFET from the rail, its current exp(kappa (V_dd - V) / U_T): lower V, more current.
            cutoff = base.cutoff_hz * math.exp(-self.kappa * (v["bias_fo"] - d["bias_fo"]) / u_t_mv)
            # bias_refr: an nFET, exp(kappa V / U_T): higher V, more recharge current, shorter dead time.
            refractory = base.refractory_s * math.exp(-self.kappa * (v["bias_refr"] - d["bias_refr"]) / u_t_mv)
        else:
            n = {name: self._code(name, v[name]) for name, _ in self.factory_codes}
            n0 = dict(self.factory_codes)
            k = self.threshold_k
            theta_on = base.theta_on + k * math.log(n["bias_diff_on"] / n0["bias_diff_on"])
            theta_off = base.theta_off + k * math.log(n["bias_diff_off"] / n0["bias_diff_off"])
            cutoff = base.cutoff_hz * (n["bias_fo"] / n0["bias_fo"])
            refractory = base.refractory_s * (n0["bias_refr"] / n["bias_refr"])
        for field, theta, keys in (("theta_on", theta_on, "bias_diff_on"), ("theta_off", theta_off, "bias_diff_off")):
            if not theta > 0.0:
                given = ", ".join(f"{key}={v[key]}" for key in (keys, "bias_diff"))
                raise ValueError(f"biases ({given} {self.unit}) give {field} = {theta:.4g} <= 0 ln units: "
                                 "raise the threshold bias")
        return {"theta_on": theta_on, "theta_off": theta_off, "cutoff_hz": cutoff, "refractory_s": refractory}

    def pixel_params(self, values: dict[str, Any], base: PixelParams, temperature_c: float = 25.0) -> PixelParams:
        """``base`` with the fields ``derive`` sets."""
        return base.replace(**self.derive(values, base, temperature_c))


# ---------------------------------------------------------------------------------------------
# The sources, once each.

OPENEB_GEN3 = (
    "Prophesee OpenEB 3.0 (github.com/prophesee-ai/openeb, commit ce9249e), hal_psee_plugins/src/devices/gen3/"
    "gen3_ll_biases.cpp: the Gen3 (PPS3MVCD) user biases are voltages in mV (Mode::Voltage, a 0-1800 mV DAC "
    "calibrated per mV), defaults bias_diff 300, bias_diff_on 375, bias_diff_off 225, bias_fo 1725, bias_pr 1500, "
    "bias_refr 1500, bias_hpf 1500 (as in resources/biases/gen3_CD_standard.bias); ranges bias_fo 1650-1800, "
    "bias_pr 1200-1800, bias_refr 1300-1800, the others 0-1800; bias_diff not modifiable; the driver clamps "
    "bias_diff_on to >= bias_diff + 1 and bias_diff_off to <= bias_diff - 1"
)
OPENEB_GEN31 = (
    "OpenEB 5.1.1 (commit 0499c95), gen31_ll_biases.cpp: the transistor each Gen3.1 bias drives, in the same "
    "bias generator: bias_fo RailP (a pFET from the supply rail), bias_pr and bias_hpf PMOSThick, bias_refr "
    "NMOSThin, the three diff biases voltages on NMOSThin gates; its checks bias_diff_on >= bias_diff + 75 mV "
    "and bias_diff_off <= bias_diff - 65 mV (Gen3.1 only)"
)
PSEE_GEN3_DOC = (
    "Prophesee Metavision docs, 'Bias Tuning on Gen3 Sensor' (docs.prophesee.ai/hw/manuals/biases.html): "
    "'The contrast sensitivity is expressed as the difference between bias_diff_on and bias_diff values (for "
    "positive light changes) and bias_diff and bias_diff_off values (for negative light changes)'; 'bias_diff "
    "stands for the threshold reference voltage and should not be modified'; 'Decreasing bias_fo value will "
    "increase the bandwidth'; 'High bias_pr value leads to small bias currents in the amplifier and also limits "
    "the bandwidth of the photoreceptor'; bias_refr sets 'the refractory period during which the Change "
    "Detector ... is switched off'"
)
PSEE_BIASES_DOC = (
    "Prophesee Metavision docs, 'Biases' (docs.prophesee.ai/stable/hw/manuals/biases.html): bias_diff_on and "
    "bias_diff_off set the ON and OFF contrast thresholds, bias_fo the pixel's low-pass filter, bias_hpf its "
    "high-pass filter; OpenEB psee_hal_utils.cpp: bias_diff is the 'reference value for comparison with "
    "bias_diff_on and bias_diff_off'"
)
OPENEB_IMX636 = (
    "OpenEB 5.1.1, hal_psee_plugins/src/devices/imx636/imx636_ll_biases.cpp, include/devices/imx636/"
    "imx636_bias_settings.h and imx636_bias_settings_iterator.h: six biases, each an offset from the chip's "
    "factory default register (read at start-up; the register 0-255); allowed offsets bias_diff_on, bias_diff_off, "
    "bias_diff and bias_fo -150..+200, bias_hpf 0..255, bias_refr -50..+255; recommended bias_diff_on -85..+140, "
    "bias_diff_off -35..+190, bias_diff -25..+23, bias_fo -35..+55, bias_hpf 0..120, bias_refr -20..+235; "
    "imx636_CD_standard.bias sets every offset to 0; no check between biases"
)
OPENEB_GEN41 = (
    "OpenEB 5.1.1, gen41_ll_biases.cpp and resources/biases/gen41_CD_standard.bias (Prophesee's Gen4.1, the "
    "pixel generation of the IMX636): absolute codes bias_diff 80, bias_diff_on 115, bias_diff_off 52, "
    "bias_fo 74, bias_hpf 0, bias_refr 68; checks bias_diff_on >= bias_diff + 15, bias_diff_off <= bias_diff - 15"
)
EVK4_IDAC = (
    "neuromorphicsystems/neuromorphic-drivers, drivers/src/devices/prophesee_evk4.rs: the EVK4's (IMX636) bias "
    "registers are read and written as idac_ctl, the code of a current DAC; its issue #6 quotes one EVK4's "
    "factory codes bias_fo 83, bias_hpf 0, bias_diff_on 102, bias_diff 77, bias_diff_off 73, bias_refr 20"
)
DVS_CIRCUIT = (
    "Lichtsteiner, Posch & Delbruck (2008), 'A 128x128 120 dB 15 us latency asynchronous temporal contrast "
    "vision sensor', IEEE JSSC 43(2), 566: the DVS pixel, a logarithmic photoreceptor (U_T/kappa per e-fold of "
    "photocurrent), a source-follower buffer, a capacitive change amplifier and ON/OFF comparators whose "
    "thresholds are voltage distances from the amplifier's reset level; Prophesee's pixels (Posch et al. 2011, "
    "IEEE JSSC 46(1), 259, the ATIS) share that chain. Weak inversion: a MOSFET's current I0 exp(kappa V_gs / U_T), "
    "U_T = k_B T / q (Mead 1989, 'Analog VLSI and Neural Systems'; Liu et al. 2002, 'Analog VLSI: Circuits and "
    "Principles')"
)

# ---------------------------------------------------------------------------------------------
# Gen3 VGA (PPS3MVCD): absolute mV.

_FOLLOW = "a subthreshold bias current, exp(kappa dV / U_T) of the bias voltage's change"
_G3 = {"bias_diff_on": 375, "bias_diff_off": 225, "bias_diff": 300, "bias_fo": 1725, "bias_pr": 1500, "bias_hpf": 1500,
       "bias_refr": 1500}  # the vendor's Gen3 defaults [mV] (OPENEB_GEN3)
_G3_ON = _G3["bias_diff_on"] - _G3["bias_diff"]
_G3_OFF = _G3["bias_diff"] - _G3["bias_diff_off"]
GEN3_BIASES = PropheseeBiases(
    sensor="Prophesee Gen3 VGA (PPS3MVCD)",
    dac="voltage",
    unit="mV",
    biases=(
        VendorBias("bias_diff_on", _G3["bias_diff_on"], (0, 1800), None, "theta_on",
                   "sets the ON contrast threshold with bias_diff: their difference",
                   f"theta_on = theta_on0 (bias_diff_on - bias_diff) / {_G3_ON} mV"),
        VendorBias("bias_diff_off", _G3["bias_diff_off"], (0, 1800), None, "theta_off",
                   "sets the OFF contrast threshold with bias_diff: their difference",
                   f"theta_off = theta_off0 (bias_diff - bias_diff_off) / {_G3_OFF} mV"),
        VendorBias("bias_diff", _G3["bias_diff"], (0, 1800), None, "",
                   "the threshold reference voltage; 'should not be modified'",
                   "the vendor's Gen3 driver does not let bias_diff be changed (OpenEB gen3: not modifiable)"),
        VendorBias("bias_fo", _G3["bias_fo"], (1650, 1800), None, "cutoff_hz",
                   "the source-follower buffer's bandwidth: lower is faster, and noisier",
                   f"cutoff_hz proportional to {_FOLLOW}: cutoff0 exp(-kappa (bias_fo - {_G3['bias_fo']} mV) / U_T)"),
        VendorBias("bias_pr", _G3["bias_pr"], (1200, 1800), None, "",
                   "the photoreceptor amplifier's bias current: higher is a smaller current and less bandwidth",
                   "the twin's photoreceptor pole follows the photocurrent alone (PixelParams.pr_pole); it has no "
                   "amplifier-limited pole for bias_pr to move"),
        VendorBias("bias_hpf", _G3["bias_hpf"], (0, 1800), None, "",
                   "the pixel's high-pass cut-off",
                   "the twin's pixel has no high-pass filter for bias_hpf to set"),
        VendorBias("bias_refr", _G3["bias_refr"], (1300, 1800), None, "refractory_s",
                   "the refractory period, the dead time after each event",
                   f"1 / refractory_s proportional to {_FOLLOW}: refractory0 exp(-kappa (bias_refr - {_G3['bias_refr']} mV) "
                   "/ U_T)"),
    ),
    threshold_margin=1,
    sources=(OPENEB_GEN3, PSEE_GEN3_DOC, OPENEB_GEN31, DVS_CIRCUIT),
    assumptions=(
        "thresholds: the comparators trip at a voltage distance from the change amplifier's reset level; one "
        "e-fold of photocurrent moves the amplifier's output by A U_T / kappa, so theta (ln units) is proportional "
        "to the distance (bias_diff_on - bias_diff for ON, bias_diff - bias_diff_off for OFF) and vanishes with it. "
        "Anchored at the vendor's default 75 mV = the preset's theta 0.223 (a 25 % step, itself assumed): one "
        "e-fold is 336 mV at the comparators, a change-amplifier gain A of about 9 with kappa 0.7 and U_T 25.7 mV "
        "(no published Gen3 figure). Only the proportionality is the circuit's",
        "the thresholds do not follow the temperature (A U_T / kappa grows with T; the preset's thresholds hold "
        "at every sensor.temperature_c)",
        "bias_fo and bias_refr: gate voltages of transistors in weak inversion, so cutoff_hz and 1 / refractory_s "
        "follow the current, exp(kappa dV / U_T), kappa 0.7 (SF_KAPPA, typical CMOS), U_T = k_B T / q at "
        "sensor.temperature_c (default 25 degC): 1 mV is a factor exp(0.7 / 25.7) = 1.028. Exact at the vendor "
        "default; far from it the transistor may leave weak inversion: over the driver's ranges the law spans "
        "1650 mV = 7.7x to 1800 mV = 0.13x the cutoff and 1300 mV = 233x to 1800 mV = 2.8e-4x the dead time, an "
        "extrapolation at the ends",
        "bias_fo's direction is the vendor's (lower = faster) and Gen3.1's transistor type (RailP, a pFET from "
        "the rail); bias_refr's is Gen3.1's type (NMOSThin: a higher gate voltage, more recharge current, a "
        "shorter dead time), assumed the same on Gen3: the vendor's text gives no direction",
        "bias_diff, bias_pr, bias_hpf accept only their defaults (see each bias's law)",
        "the driver's ranges and its bias_diff_on >= bias_diff + 1, bias_diff_off <= bias_diff - 1 mV are "
        "enforced (the driver clamps silently; the twin refuses); Gen3.1's wider margins (75 / 65 mV) belong to "
        "that chip",
    ),
)
"""The Gen3 VGA sensor's biases: absolute mV, laws anchored on the prophesee_gen3_vga preset."""

# ---------------------------------------------------------------------------------------------
# IMX636: offsets in current-DAC codes from the chip's factory default.

IMX636_FACTORY_CODES = (("bias_diff_on", 115), ("bias_diff_off", 52), ("bias_diff", 80), ("bias_fo", 74),
                        ("bias_hpf", 0), ("bias_refr", 20))
"""The IMX636's factory register codes N0 the offsets add to (assumed, per chip in reality):
Gen4.1's standard file for all but bias_refr, whose 20 is the one code that keeps the vendor's
recommended offsets (-20..+235) inside the 8-bit register."""
_N0 = dict(IMX636_FACTORY_CODES)

IMX636_BIASES = PropheseeBiases(
    sensor="Sony IMX636 (Prophesee EVK4)",
    dac="current",
    unit="DAC codes from the factory default",
    biases=(
        VendorBias("bias_diff_on", 0, (-150, 200), (-85, 140), "theta_on",
                   "controls the light sensitivity for ON events (the ON contrast threshold)",
                   f"theta_on = theta_on0 + k ln(({_N0['bias_diff_on']} + offset) / {_N0['bias_diff_on']}), "
                   f"k = {K_THRESHOLD_DAVIS346:g}"),
        VendorBias("bias_diff_off", 0, (-150, 200), (-35, 190), "theta_off",
                   "controls the light sensitivity for OFF events (the OFF contrast threshold)",
                   f"theta_off = theta_off0 + k ln(({_N0['bias_diff_off']} + offset) / {_N0['bias_diff_off']}), "
                   f"k = {K_THRESHOLD_DAVIS346:g}"),
        VendorBias("bias_diff", 0, (-150, 200), (-25, 23), "",
                   "reference value for comparison with bias_diff_on and bias_diff_off",
                   "how bias_diff moves the IMX636's OFF threshold is not public (its OFF code runs the other way "
                   "to Gen4.1's), and the vendor recommends leaving it"),
        VendorBias("bias_fo", 0, (-150, 200), (-35, 55), "cutoff_hz",
                   "controls the pixel low-pass cut-off frequency",
                   f"cutoff_hz = cutoff0 ({_N0['bias_fo']} + offset) / {_N0['bias_fo']}"),
        VendorBias("bias_hpf", 0, (0, 255), (0, 120), "",
                   "controls the pixel high-pass cut-off frequency",
                   "the twin's pixel has no high-pass filter for bias_hpf to set"),
        VendorBias("bias_refr", 0, (-50, 255), (-20, 235), "refractory_s",
                   "controls the refractory period during which the change detector is switched off after an event",
                   f"refractory_s = refractory0 x {_N0['bias_refr']} / ({_N0['bias_refr']} + offset)"),
    ),
    factory_codes=IMX636_FACTORY_CODES,
    threshold_k=K_THRESHOLD_DAVIS346,
    sources=(OPENEB_IMX636, PSEE_BIASES_DOC, OPENEB_GEN41, EVK4_IDAC, DVS_CIRCUIT),
    assumptions=(
        "each register is the code N of a current DAC (idac_ctl, as the EVK4 driver names it), the bias current "
        "proportional to N (a linear DAC); the offsets add to the chip's factory codes, which are per chip and "
        "not published: assumed Gen4.1's standard file (bias_diff_on 115, bias_diff_off 52, bias_diff 80, bias_fo "
        "74, bias_hpf 0) and bias_refr 20. The vendor's recommended offsets bear them out: from 115 and from 20 "
        "the recommended maxima +140 and +235 land on 255, the register's top, and 52 and 74 keep every "
        "recommended offset inside it. An offset whose code leaves 1..255 is refused",
        "thresholds: a comparator level set by a subthreshold current moves by (U_T / kappa) ln(I / I0); referred "
        "to the photoreceptor's log input through the change amplifier this is Delta theta = k ln(N / N0), the "
        "form of the paper's eq. 8-9. k = 0.0659 is the DAVIS346's (K_THRESHOLD_DAVIS346): the IMX636's capacitor "
        "ratio is not public. Over the recommended offsets theta_on spans 0.146-0.287 and theta_off 0.136-0.311",
        "directions: raising bias_diff_on raises theta_on (the vendor: it sets the ON threshold; Gen4.1 keeps it "
        "above bias_diff). Raising bias_diff_off raises theta_off on the IMX636: its recommended offsets leave far "
        "more room upward (-35..+190), as bias_diff_on's do (-85..+140), and a Gen4.1-style OFF level (below "
        "bias_diff) could not take +190 from a factory code of 35-65, which that range implies; a third-party EVK4 "
        "tool says the same ('Increase to reduce OFF events on IMX636/GenX320'). Gen4.1's own check (bias_diff_off "
        "<= bias_diff - 15) reads the other way: this direction is the least certain part",
        "bias_fo: the source follower's cutoff is its transconductance over its load, kappa I / (2 pi U_T C): "
        "proportional to the bias current, so to the code (74 + offset) / 74, anchored at the preset's 2 kHz. "
        "That a higher code means more current, so more bandwidth, is assumed (the vendor gives no direction)",
        "bias_refr: the reset node is recharged by the bias current, so refractory_s = refractory0 x 20 / (20 + "
        "offset), anchored at the preset's 130 us (more code, more current, a shorter dead time: assumed)",
        "bias_diff and bias_hpf accept only 0 (see each bias's law); the IMX636 has no bias_pr in the vendor's "
        "driver",
    ),
)
"""The IMX636's biases: offsets in current-DAC codes, laws anchored on the imx636 preset."""
