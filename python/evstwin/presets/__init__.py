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

The Prophesee presets carry their biases in the vendor's own names and units instead
(``SensorPreset.vendor_biases``, ``evstwin.presets.prophesee_biases``): ``bias_diff_on`` ...
in mV on the Gen3 VGA, in DAC codes from the factory default on the IMX636.
"""

from __future__ import annotations

from ..constants import ELEMENTARY_CHARGE_C
from .biases import (
    BIAS_SETS,
    FAST_PR_SLOW_SF_BALANCED_TH,
    K_THRESHOLD_DAVIS346,
    K_THRESHOLD_TEXT,
    PAPER_RUN_1,
    PAPER_RUN_3,
    REFRACTORY_CALIBRATION_CURRENT_A,
    REFRACTORY_CALIBRATION_S,
    REFRACTORY_CHARGE_C,
    SF_CALIBRATION_CURRENT_A,
    SF_CALIBRATION_CUTOFF_HZ,
    SF_KAPPA,
    SF_LOAD_CAPACITANCE_F,
    TABLE3_DARK,
    THERMAL_VOLTAGE_V,
    BiasSet,
    cutoff_from_bias,
    dark_rate_eq3,
    get_bias_set,
    refractory_from_bias,
    thresholds_from_biases,
)
from .davis346 import (
    DAVIS346,
    DAVIS346_BACKGROUND_SOURCE,
    DAVIS346_PAPER,
    DAVIS346_READOUT,
    DAVIS346_RECORDING,
    paper_run_params,
)
from .gen3_vga import (
    GEN3_VGA_CUTOFF_HZ,
    GEN3_VGA_DARK_RATE_E_PER_S,
    GEN3_VGA_THETA,
    PROPHESEE_GEN3_VGA,
)
from .imx636 import (
    IMX636,
    IMX636_ABSORPTION_PER_M,
    IMX636_COLLECTION_DEPTH_M,
    IMX636_READOUT,
    IMX636_RECORDING,
    IMX636_THETA,
    IMX636_THETA_OFF,
    IMX636_THETA_ON,
)
from .prophesee_biases import (
    GEN3_BIASES,
    IMX636_BIASES,
    IMX636_FACTORY_CODES,
    PROPHESEE_BIAS_NAMES,
    PropheseeBiases,
    VendorBias,
    thermal_voltage_at_v,
)
from .sensor_preset import (
    DARK_DOUBLING_C,
    FSI_COLLECTION_DEPTH_M,
    FSI_TRANSMISSION,
    QE_REFERENCE_WAVELENGTH_M,
    READOUT_FIFO_ASSUMPTION,
    TEMPERATURE_RANGE_C,
    TEMPERATURE_SCALED_FIELDS,
    SensorPreset,
)

PRESETS: dict[str, SensorPreset] = {p.name: p for p in (DAVIS346, IMX636, PROPHESEE_GEN3_VGA, DAVIS346_PAPER)}
VENDOR_BIAS_PRESETS: tuple[str, ...] = tuple(name for name, p in PRESETS.items() if p.vendor_biases is not None)
"""The presets whose biases are the vendor's own names and units (``SensorPreset.vendor_biases``)."""
"""Built-in sensor presets by name."""


def get_preset(name: str) -> SensorPreset:
    """A built-in sensor preset by name, case-insensitive (ValueError listing the names)."""
    try:
        return PRESETS[name.lower()]
    except (KeyError, AttributeError):
        raise ValueError(f"unknown sensor preset {name!r}; known: {sorted(PRESETS)}") from None


__all__ = [
    "BIAS_SETS",
    "DARK_DOUBLING_C",
    "DAVIS346",
    "DAVIS346_BACKGROUND_SOURCE",
    "DAVIS346_PAPER",
    "DAVIS346_READOUT",
    "DAVIS346_RECORDING",
    "ELEMENTARY_CHARGE_C",
    "FAST_PR_SLOW_SF_BALANCED_TH",
    "FSI_COLLECTION_DEPTH_M",
    "FSI_TRANSMISSION",
    "GEN3_BIASES",
    "GEN3_VGA_CUTOFF_HZ",
    "GEN3_VGA_DARK_RATE_E_PER_S",
    "GEN3_VGA_THETA",
    "IMX636",
    "IMX636_ABSORPTION_PER_M",
    "IMX636_BIASES",
    "IMX636_FACTORY_CODES",
    "IMX636_COLLECTION_DEPTH_M",
    "IMX636_READOUT",
    "IMX636_RECORDING",
    "IMX636_THETA",
    "IMX636_THETA_OFF",
    "IMX636_THETA_ON",
    "K_THRESHOLD_DAVIS346",
    "K_THRESHOLD_TEXT",
    "PAPER_RUN_1",
    "PAPER_RUN_3",
    "PRESETS",
    "VENDOR_BIAS_PRESETS",
    "PROPHESEE_BIAS_NAMES",
    "PROPHESEE_GEN3_VGA",
    "QE_REFERENCE_WAVELENGTH_M",
    "READOUT_FIFO_ASSUMPTION",
    "REFRACTORY_CALIBRATION_CURRENT_A",
    "REFRACTORY_CALIBRATION_S",
    "REFRACTORY_CHARGE_C",
    "SF_CALIBRATION_CURRENT_A",
    "SF_CALIBRATION_CUTOFF_HZ",
    "SF_KAPPA",
    "SF_LOAD_CAPACITANCE_F",
    "TABLE3_DARK",
    "TEMPERATURE_RANGE_C",
    "TEMPERATURE_SCALED_FIELDS",
    "THERMAL_VOLTAGE_V",
    "cutoff_from_bias",
    "dark_rate_eq3",
    "get_bias_set",
    "get_preset",
    "paper_run_params",
    "refractory_from_bias",
    "thermal_voltage_at_v",
    "thresholds_from_biases",
    "BiasSet",
    "PropheseeBiases",
    "SensorPreset",
    "VendorBias",
]
