"""Bias currents -> pixel parameters: the models (paper eq. 8-9, the refractory charge, the
source follower's subthreshold cutoff, eq. 3's dark current), their calibration constants,
and the :class:`BiasSet` of six DAVIS bias currents with the paper's sets."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from .._checks import positive
from ..constants import BOLTZMANN_J_K, ELEMENTARY_CHARGE_C
from ..pixel import PixelParams

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
