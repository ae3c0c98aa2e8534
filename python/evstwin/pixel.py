"""Pixel parameters: the Python face of the C++ ``evstwin::PixelParams``.

Every default is read from the C++ struct, the one place it is written; the docstring of
each field gives its unit and its source in the paper (*Event-based Vision Sensor Physics-Based Digital Twin for Tuning SSA Use*, "the paper").
"""

from __future__ import annotations

import dataclasses
import numbers
from dataclasses import dataclass
from typing import Any, Literal

from . import _core

_DEFAULT = _core.PixelParams()

DarkModel = Literal["poisson", "paper", "none"]
LowPass = Literal["exact", "euler"]
NoiseModel = Literal["continuous", "sampled"]
LeakPolarity = Literal["on", "off"]
_ENUMS = {"dark_model": ("poisson", "paper", "none"), "lowpass": ("exact", "euler"),
          "noise_model": ("continuous", "sampled"), "leak_polarity": ("on", "off")}
_OPTIONAL = ("cutoff_hz", "shot_noise_on_rate_hz", "shot_noise_off_rate_hz")


@dataclass(frozen=True)
class PixelParams:
    """Parameters shared by every pixel of a sensor (defaults: the paper's DAVIS346 pixel).

    Thresholds are in natural-log units of photocurrent: an ON event fires when
    ``ln I`` (after the low-pass) has risen by ``theta_on`` since the last event.
    """

    theta_on: float = _DEFAULT.theta_on
    """ON threshold [ln units], > 0. Paper sec. 3.1 (Table 1 biases): 0.2061."""
    theta_off: float = _DEFAULT.theta_off
    """OFF threshold magnitude [ln units], > 0. Paper sec. 3.1: 0.093."""
    refractory_s: float = _DEFAULT.refractory_s
    """Dead time after each event [s], in [0, 1]. 1 ms, inside McReynolds et al.'s 0.33-10 ms."""
    cutoff_hz: float | None = _DEFAULT.cutoff_hz
    """Source-follower low-pass cutoff [Hz] (eq. 6); None = no filter. Paper: 10 Hz."""
    lowpass: LowPass = _DEFAULT.lowpass  # type: ignore[assignment]
    """'exact' first-order update (default) or 'euler' (eq. 7, unstable for 2 pi fc dt > 2)."""
    leak_rate_hz: float = _DEFAULT.leak_rate_hz
    """Leak event rate f_leak [Hz] (eq. 10-11). Paper: 0.1 Hz."""
    shot_noise_rate_hz: float = _DEFAULT.shot_noise_rate_hz
    """Statistical shot-noise rate R_n [Hz] of each polarity in the dark (eq. 12). Paper: 0.05 Hz."""
    shot_noise_on_rate_hz: float | None = _DEFAULT.shot_noise_on_rate_hz
    """Eq. 12's R_n of ON events [Hz]; None = shot_noise_rate_hz. Sets the background's ON
    rate independently of the thresholds (a real sensor's background is rarely symmetric)."""
    shot_noise_off_rate_hz: float | None = _DEFAULT.shot_noise_off_rate_hz
    """Eq. 12's R_n of OFF events [Hz]; None = shot_noise_rate_hz."""
    background_rate_sigma: float = _DEFAULT.background_rate_sigma
    """Log-normal spread of eq. 12's rates across pixels (sigma of ln rate, mean kept), in [0, 3]."""
    leak_rate_sigma: float = _DEFAULT.leak_rate_sigma
    """Log-normal spread of the leak rate across pixels (sigma of ln rate, mean kept), in [0, 3]."""
    leak_random_phase: bool = _DEFAULT.leak_random_phase
    """Start every pixel at a random phase of its leak cycle, so the leak is stationary from
    t = 0 (True); False reproduces the paper, where every pixel leaks in lockstep."""
    leak_photocurrent_hz_per_a: float = _DEFAULT.leak_photocurrent_hz_per_a
    """Rise of the leak rate with the photocurrent [Hz/A], >= 0 (Nozaki & Delbruck 2017:
    parasitic photocurrent in the reset switch's junction). A pixel leaks at
    (leak_rate_hz + leak_photocurrent_hz_per_a * I_photo) * s, I_photo = e *
    electrons_per_photon * photon rate (the mean photocurrent, not the dark current), s its
    log-normal factor (leak_rate_sigma), which scales both parts (one junction, one capacitor).
    0 (default): a leak that ignores the light (the paper's)."""
    leak_polarity: LeakPolarity = _DEFAULT.leak_polarity  # type: ignore[assignment]
    """Direction of the leak's drift: 'on' (default, the paper's: the reference falls and the
    leak fires ON events) or 'off' (it rises and the leak fires OFF events, as on the IMX636)."""
    hot_pixel_fraction: float = _DEFAULT.hot_pixel_fraction
    """Share of hot (flickering) pixels, drawn per seed, in [0, 1]."""
    hot_pixel_rate_hz: float = _DEFAULT.hot_pixel_rate_hz
    """Median hot-pixel rate r [Hz]: after each event the pixel is dead for refractory_s and then
    fires after an exponential wait of rate r, alternating ON and OFF (r / (1 + r refractory_s)
    events a second)."""
    hot_pixel_rate_sigma: float = _DEFAULT.hot_pixel_rate_sigma
    """Log-normal spread of the hot-pixel rates (sigma of ln r), in [0, 3]."""
    hot_pixel_duty: float = _DEFAULT.hot_pixel_duty
    """Share of the time a hot pixel is active (random telegraph: it flickers in bursts and
    fires only while active), in [1e-6, 1]; 1 = always active. Mean rate: duty x r / (1 + r
    refractory_s)."""
    hot_pixel_burst_s: float = _DEFAULT.hot_pixel_burst_s
    """Mean length of a hot pixel's active period [s] (exponential); quiet periods last
    burst (1 - duty) / duty on average."""
    hot_pixel_on_share: float = _DEFAULT.hot_pixel_on_share
    """Long-run share of a hot pixel's events that are ON, in (0, 1); 0.5 with alternation 1
    is strict alternation (the default)."""
    hot_pixel_alternation: float = _DEFAULT.hot_pixel_alternation
    """Share of a hot pixel's successive events of opposite polarity, in [0, 2 min(on_share,
    1 - on_share)]: its polarities are a two-state chain that switches from ON with probability
    alternation / (2 on_share) and from OFF alternation / (2 (1 - on_share)). The real IMX636
    hot pixel: on_share 0.59, alternation 0.78."""
    noise_model: NoiseModel = _DEFAULT.noise_model  # type: ignore[assignment]
    """'continuous' (default): shot noise as a white process through the photoreceptor pole and
    source follower, advanced exactly between samples with threshold crossings inside an
    interval (Brownian bridge), so its statistics do not depend on the sampling; 'sampled': the
    paper's Poisson count per sample (noise grows as samples shorten), for reproduction."""
    shot_noise_factor: float = _DEFAULT.shot_noise_factor
    """F of eq. 12: the noise rate at I_max as a fraction of R_n. Paper: 0.25."""
    shot_noise_i_max_a: float = _DEFAULT.shot_noise_i_max_a
    """I_max of eq. 12 [A]. Paper: 3.16 nA."""
    dark_rate_e_per_s: float = _DEFAULT.dark_rate_e_per_s
    """Mean dark-current electron rate [e-/s] (eq. 4). Paper (iniVation): 18000."""
    dark_model: DarkModel = _DEFAULT.dark_model  # type: ignore[assignment]
    """'poisson': Poisson(rate*dt) electrons per sample (default, physical); 'paper': eq. 4
    literally, Poisson(rate) per sample whatever dt; 'none'."""
    photon_shot_noise: bool = _DEFAULT.photon_shot_noise
    """Poisson statistics of the signal electrons (on by default)."""
    threshold_sigma: float = _DEFAULT.threshold_sigma
    """Per-pixel threshold mismatch, Gaussian sigma as a fraction of the threshold, in [0, 1]."""
    fill_factor: float = _DEFAULT.fill_factor
    """Photodiode share of the pixel area. DAVIS346: 0.22 (paper sec. 3.1)."""
    internal_qe: float = _DEFAULT.internal_qe
    """Internal quantum efficiency eta_i (eq. 2). Table 3: 1."""
    transmission: float = _DEFAULT.transmission
    """Transmission coefficient tau (eq. 2). Table 3: 0.68."""
    absorption_per_m: float = _DEFAULT.absorption_per_m
    """Absorption coefficient alpha [1/m] (eq. 2). Table 3: 3e4."""
    depletion_width_m: float = _DEFAULT.depletion_width_m
    """Depletion width W [m] (eq. 2). Table 3: 1.1637e-7."""
    pr_pole: bool = _DEFAULT.pr_pole
    """Photoreceptor pole in series, cutoff pr_cutoff_ref_hz * I / pr_ref_current_a (off)."""
    pr_cutoff_ref_hz: float = _DEFAULT.pr_cutoff_ref_hz
    """Photoreceptor cutoff [Hz] at the reference current (an order-of-magnitude estimate)."""
    pr_ref_current_a: float = _DEFAULT.pr_ref_current_a
    """Reference photocurrent [A] for pr_cutoff_ref_hz."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name in _ENUMS:
                if not isinstance(value, str):
                    raise TypeError(f"{f.name} must be a string; got {f.name}={value!r}")
                allowed = _ENUMS[f.name]
                if value not in allowed:
                    raise ValueError(f"{f.name} must be one of {', '.join(map(repr, allowed))}; got {f.name}={value!r}")
            elif f.name in ("photon_shot_noise", "pr_pole", "leak_random_phase"):
                if not isinstance(value, bool):
                    raise TypeError(f"{f.name} must be True or False; got {f.name}={value!r}")
            elif f.name in _OPTIONAL and value is None:
                pass
            elif isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise TypeError(f"{f.name} must be a number; got {f.name}={value!r}")
            else:
                try:
                    float(value)
                except OverflowError:  # an int (or Fraction) beyond 1.8e308
                    raise ValueError(f"{f.name} must fit a 64-bit float; got a number of {len(str(value))} "
                                     "digits") from None
        self.to_core().validate()

    def to_core(self) -> Any:
        """The C++ struct (raises ValueError naming a bad enum value)."""
        core = _core.PixelParams()
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            numeric = isinstance(value, numbers.Real) and not isinstance(value, bool)
            setattr(core, f.name, float(value) if numeric else value)
        return core

    def replace(self, **changes: Any) -> PixelParams:
        """A copy with some fields changed (unknown names raise TypeError)."""
        names = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise TypeError(f"unknown PixelParams field(s) {unknown}; known: {sorted(names)}")
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @property
    def electrons_per_photon(self) -> float:
        """Signal electrons per photon arriving on the pixel (fill factor x eq. 2 / e)."""
        return float(self.to_core().electrons_per_photon())

    @classmethod
    def field_names(cls) -> list[str]:
        return [f.name for f in dataclasses.fields(cls)]


@dataclass(frozen=True)
class HotPixelChain:
    """One hot pixel's own telegraph and polarity chain, in place of what ``PixelParams``'
    ``hot_pixel_duty``, ``hot_pixel_burst_s``, ``hot_pixel_on_share`` and
    ``hot_pixel_alternation`` give every other hot pixel (``Sensor(hot_pixel_chains=...)``; a
    scenario's ``[hot_pixels]`` table entries). Real hot pixels differ: the IMX636 recording's
    flickering pixel fires ON 0.59 of the time in short bursts, its leaky one 0.98 in one burst
    of a second. The fields mean what the ``PixelParams`` fields of the same name mean."""

    duty: float
    """Share of the time the pixel is active, in [1e-6, 1]."""
    burst_s: float
    """Mean active period [s] (exponential), in [1e-6, 1e6]."""
    on_share: float
    """Long-run share of ON events, in [1e-6, 1 - 1e-6]."""
    alternation: float
    """Share of successive events of opposite polarity, in [0, 2 min(on_share, 1 - on_share)];
    2 on_share (1 - on_share): each event's polarity drawn afresh."""

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise TypeError(f"HotPixelChain.{f.name} must be a number; got {f.name}={value!r}")
        _core.validate_hot_pixel_chain(float(self.duty), float(self.burst_s), float(self.on_share),
                                       float(self.alternation), "HotPixelChain.")

    @classmethod
    def of(cls, params: PixelParams) -> HotPixelChain:
        """The chain ``params`` gives every hot pixel."""
        return cls(params.hot_pixel_duty, params.hot_pixel_burst_s, params.hot_pixel_on_share,
                   params.hot_pixel_alternation)
