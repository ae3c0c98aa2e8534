"""What every target is: the :class:`Target` interface, its brightness (a constant flux or a
:class:`LightCurve`) and the checks of times and tables the kinds of target share."""

from __future__ import annotations

import abc
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
import numpy.typing as npt

from .._checks import array, finite, non_negative
from ..optics import Optics

if TYPE_CHECKING:
    from ..psf import PSFShape

Outside = Literal["raise", "hold"]


def _times(t_s: npt.ArrayLike) -> np.ndarray:
    return array("t_s", t_s)


def _table(name: str, t_name: str, t: np.ndarray, values: npt.ArrayLike) -> np.ndarray:
    v = array(name, values)
    if v.shape != t.shape:
        raise ValueError(f"{name} must have the shape of {t_name} {t.shape}; got {v.shape}")
    return v


def _table_times(name: str, t_s: npt.ArrayLike) -> np.ndarray:
    t = np.array(array(name, t_s))  # own copy, made read-only below
    if t.ndim != 1 or t.size < 1:
        raise ValueError(f"{name} must be a non-empty 1-D array; got shape {t.shape}")
    if t.size > 1:
        d = np.diff(t)
        if np.any(d <= 0.0):
            k = int(np.flatnonzero(d <= 0.0)[0])
            raise ValueError(
                f"{name} must be strictly increasing; got {name}[{k}]={t[k]!r} then {name}[{k + 1}]={t[k + 1]!r}"
            )
    t.setflags(write=False)
    return t


@dataclass(frozen=True, eq=False)
class LightCurve:
    """Flux versus time, interpolated linearly between table points.

    t_s: strictly increasing times [s]; flux_ph_s: photons/s at each, >= 0 (> 0 if
    ``log_interp``). Outside the table the end values are held; with ``periodic=True`` the
    table repeats with period ``t_s[-1] - t_s[0]`` (give the closing point: a curve whose
    last flux differs from its first jumps at each period).
    log_interp: interpolate ln(flux), i.e. linearly in magnitude (``from_magnitudes``).
    """

    t_s: np.ndarray
    flux_ph_s: np.ndarray
    log_interp: bool = False
    periodic: bool = False

    def __post_init__(self) -> None:
        t = _table_times("t_s", self.t_s)
        flux = np.array(_table("flux_ph_s", "t_s", t, self.flux_ph_s))
        array("flux_ph_s", flux, min_value=0.0, strict=self.log_interp)
        if self.periodic and t.size < 2:
            raise ValueError(f"a periodic light curve needs at least 2 points; got t_s of size {t.size}")
        flux.setflags(write=False)
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "flux_ph_s", flux)

    @classmethod
    def from_magnitudes(
        cls, t_s: npt.ArrayLike, magnitude: npt.ArrayLike, optics: Optics, periodic: bool = False
    ) -> LightCurve:
        """A light curve given in magnitudes, converted with ``optics.flux_from_magnitude``
        and interpolated linearly in magnitude."""
        t = _table_times("t_s", t_s)
        mag = _table("magnitude", "t_s", t, magnitude)
        flux = np.asarray(optics.flux_from_magnitude(mag), np.float64).reshape(t.shape)
        return cls(t, flux, True, periodic)

    def __call__(self, t_s: npt.ArrayLike) -> np.ndarray:
        """Flux [photons/s] at the times t_s [s] (shape of t_s)."""
        t = _times(t_s)
        if self.periodic:
            t0 = self.t_s[0]
            t = t0 + np.mod(t - t0, self.t_s[-1] - t0)
        if self.log_interp:
            return np.exp(np.interp(t, self.t_s, np.log(self.flux_ph_s)))
        return np.interp(t, self.t_s, self.flux_ph_s)


Brightness = float | LightCurve
"""A constant flux [photons/s] or a LightCurve."""


def _check_brightness(value: object) -> Brightness:
    if isinstance(value, LightCurve):
        return value
    return non_negative("brightness", value)


def _interval(t0_s: float, t1_s: float) -> tuple[float, float]:
    t0 = finite("t0_s", t0_s)
    t1 = finite("t1_s", t1_s)
    if t1 < t0:
        raise ValueError(f"need t0_s <= t1_s; got t0_s={t0_s!r}, t1_s={t1_s!r}")
    return t0, t1


class Target(abc.ABC):
    """Common interface of all targets (see the module docstring)."""

    brightness: Brightness
    label: str
    psf: PSFShape | None = None
    """Its own PSF (a defocused ghost, an out-of-focus source), or None: the scene's. Set with
    :func:`with_psf`; the wrappers here (drifting, shifted, mirrored) keep it."""

    @abc.abstractmethod
    def position_px(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(x, y) [px] at the times t_s [s], each shaped like t_s."""

    @abc.abstractmethod
    def velocity_px_s(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """(vx, vy) [px/s] at the times t_s [s]."""

    @abc.abstractmethod
    def max_speed_px_s(self, t0_s: float, t1_s: float) -> float:
        """The largest speed [px/s] over [t0_s, t1_s]."""

    def flux_ph_s(self, t_s: npt.ArrayLike) -> np.ndarray:
        """Flux [photons/s] at the focal plane at the times t_s [s]."""
        t = _times(t_s)
        b = self.brightness
        if isinstance(b, LightCurve):
            return b(t)
        return np.full(t.shape, float(b))



def mean_flux_ph_s(brightness: Brightness) -> float:
    """A brightness's mean flux [photons/s]: a constant itself, a light curve's time average
    over its table (trapezoids between its points, linear or in ln as it interpolates; a
    one-point table its value)."""
    if not isinstance(brightness, LightCurve):
        return float(brightness)
    t, flux = brightness.t_s, brightness.flux_ph_s
    if t.size == 1:
        return float(flux[0])
    if brightness.log_interp:  # ln(flux) linear: the mean of an exponential over each step
        a, b = flux[:-1], flux[1:]
        ratio = np.log(b / a)
        step = np.where(np.abs(ratio) > 1e-12, (b - a) / np.where(ratio == 0.0, 1.0, ratio), a)
        return float(np.sum(step * np.diff(t)) / (t[-1] - t[0]))
    return float(np.sum(0.5 * (flux[:-1] + flux[1:]) * np.diff(t)) / (t[-1] - t[0]))


def _drift(name: str, value: object) -> tuple[float, float]:
    """Two finite numbers (vx, vy), or a ValueError naming ``name`` and the value."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, np.ndarray)) or len(value) != 2 or any(
        isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)) for v in value
    ):
        raise ValueError(f"{name} must be two numbers [vx, vy]; got {name}={value!r}")
    try:
        vx, vy = float(value[0]), float(value[1])
    except OverflowError:
        vx = vy = math.inf
    if not (math.isfinite(vx) and math.isfinite(vy)):
        raise ValueError(f"{name} must be finite; got {name}={value!r}")
    return vx, vy


def sample_targets(
    targets: Sequence[Target], t_s: npt.ArrayLike
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions [px] and fluxes [photons/s] of all targets at the times t_s [s]: (x, y, flux),
    each (T, S), ready for ``psf.render_frames``."""
    t = _times(t_s).reshape(-1)
    n = len(targets)
    x = np.empty((t.size, n))
    y = np.empty((t.size, n))
    f = np.empty((t.size, n))
    for k, target in enumerate(targets):
        x[:, k], y[:, k] = target.position_px(t)
        f[:, k] = target.flux_ph_s(t)
    return x, y, f


def max_speed_px_s(targets: Sequence[Target], t0_s: float, t1_s: float) -> float:
    """The largest speed of any of the targets over [t0_s, t1_s] [px/s] (0 for none)."""
    _interval(t0_s, t1_s)
    return max((target.max_speed_px_s(t0_s, t1_s) for target in targets), default=0.0)
