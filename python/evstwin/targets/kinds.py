"""The kinds of target that move by themselves: static, linear, circular (and a rotating bar of
them) and tabulated tracks."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from .._checks import finite, positive
from ..optics import Optics
from .base import (
    Brightness,
    LightCurve,
    Outside,
    Target,
    _check_brightness,
    _drift,
    _interval,
    _table,
    _table_times,
    _times,
)


@dataclass(frozen=True, eq=False)
class StaticTarget(Target):
    """A source fixed on the sensor (a star seen by a tracking mount, a lab LED at rest)."""

    x_px: float
    y_px: float
    brightness: Brightness
    label: str = ""

    def __post_init__(self) -> None:
        finite("x_px", self.x_px)
        finite("y_px", self.y_px)
        object.__setattr__(self, "brightness", _check_brightness(self.brightness))

    def position_px(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        t = _times(t_s)
        return np.full(t.shape, float(self.x_px)), np.full(t.shape, float(self.y_px))

    def velocity_px_s(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        t = _times(t_s)
        return np.zeros(t.shape), np.zeros(t.shape)

    def max_speed_px_s(self, t0_s: float, t1_s: float) -> float:
        _interval(t0_s, t1_s)
        return 0.0


@dataclass(frozen=True, eq=False)
class LinearTarget(Target):
    """Constant velocity: ``x = x0 + vx (t - t0)``, ``y = y0 + vy (t - t0)`` [px]."""

    x0_px: float
    y0_px: float
    vx_px_s: float
    vy_px_s: float
    brightness: Brightness
    t0_s: float = 0.0
    label: str = ""

    def __post_init__(self) -> None:
        for name in ("x0_px", "y0_px", "vx_px_s", "vy_px_s", "t0_s"):
            finite(name, getattr(self, name))
        object.__setattr__(self, "brightness", _check_brightness(self.brightness))

    @classmethod
    def from_angular_velocity(
        cls,
        x0_px: float,
        y0_px: float,
        wx_rad_s: float,
        wy_rad_s: float,
        optics: Optics,
        brightness: Brightness,
        t0_s: float = 0.0,
        label: str = "",
    ) -> LinearTarget:
        """From an angular rate across the sky [rad/s] through the plate scale. Small-angle:
        pixel velocity = angular rate / ``optics.plate_scale_rad_per_px``; the tangent-plane
        stretch (1 + tan^2 of the off-axis angle, ~1 % in the corners of a DAVIS346 behind 41 mm)
        is neglected."""
        k = optics.plate_scale_rad_per_px
        wx = finite("wx_rad_s", wx_rad_s)
        wy = finite("wy_rad_s", wy_rad_s)
        return cls(x0_px, y0_px, wx / k, wy / k, brightness, t0_s, label)

    def position_px(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        dt = _times(t_s) - self.t0_s
        return self.x0_px + self.vx_px_s * dt, self.y0_px + self.vy_px_s * dt

    def velocity_px_s(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        t = _times(t_s)
        return np.full(t.shape, float(self.vx_px_s)), np.full(t.shape, float(self.vy_px_s))

    def max_speed_px_s(self, t0_s: float, t1_s: float) -> float:
        _interval(t0_s, t1_s)
        return math.hypot(self.vx_px_s, self.vy_px_s)


@dataclass(frozen=True, eq=False)
class CircularTarget(Target):
    """Uniform circular motion (the paper's rotating lab sources, sec. 3.1):

    ``x = cx + r cos(w t + phase)``, ``y = cy + r sin(w t + phase)`` [px]. w > 0 turns from
    +x towards +y, i.e. clockwise on a displayed image (whose y axis points down).
    """

    centre_x_px: float
    centre_y_px: float
    radius_px: float
    angular_rate_rad_s: float
    brightness: Brightness
    phase_rad: float = 0.0
    label: str = ""

    def __post_init__(self) -> None:
        finite("centre_x_px", self.centre_x_px)
        finite("centre_y_px", self.centre_y_px)
        positive("radius_px", self.radius_px)
        finite("angular_rate_rad_s", self.angular_rate_rad_s)
        finite("phase_rad", self.phase_rad)
        object.__setattr__(self, "brightness", _check_brightness(self.brightness))

    @classmethod
    def with_period(
        cls,
        centre_x_px: float,
        centre_y_px: float,
        radius_px: float,
        period_s: float,
        brightness: Brightness,
        phase_rad: float = 0.0,
        reverse: bool = False,
        label: str = "",
    ) -> CircularTarget:
        """From the period of one turn [s] (> 0); ``reverse=True`` turns the other way."""
        w = 2.0 * math.pi / positive("period_s", period_s)
        return cls(centre_x_px, centre_y_px, radius_px, -w if reverse else w, brightness, phase_rad, label)

    @property
    def period_s(self) -> float:
        """Time of one turn [s] (inf when not turning)."""
        w = abs(self.angular_rate_rad_s)
        return math.inf if w == 0.0 else 2.0 * math.pi / w

    def position_px(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        a = self.angular_rate_rad_s * _times(t_s) + self.phase_rad
        return self.centre_x_px + self.radius_px * np.cos(a), self.centre_y_px + self.radius_px * np.sin(a)

    def velocity_px_s(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        a = self.angular_rate_rad_s * _times(t_s) + self.phase_rad
        v = self.radius_px * self.angular_rate_rad_s
        return -v * np.sin(a), v * np.cos(a)

    def max_speed_px_s(self, t0_s: float, t1_s: float) -> float:
        _interval(t0_s, t1_s)
        return abs(self.angular_rate_rad_s) * self.radius_px


def aligned_rotating_targets(
    centre_x_px: float,
    centre_y_px: float,
    radii_px: Sequence[float],
    angular_rate_rad_s: float,
    brightness: Brightness | Sequence[Brightness],
    phase_rad: float = 0.0,
) -> list[CircularTarget]:
    """Sources on one rotating bar (the paper's lab scene: aligned rotating light sources).

    radii_px: signed distances along the bar [px], non-zero; a negative radius puts the source
    on the other side of the centre (phase + pi). brightness: one for all or one per source.
    """
    radii = [finite(f"radii_px[{k}]", r) for k, r in enumerate(radii_px)]
    if isinstance(brightness, (LightCurve, int, float, np.floating, np.integer)):
        levels: list[Brightness] = [brightness] * len(radii)  # type: ignore[list-item]
    else:
        levels = list(brightness)
        if len(levels) != len(radii):
            raise ValueError(
                f"brightness must be one value or one per radius ({len(radii)}); got {len(levels)}"
            )
    out = []
    for k, (r, b) in enumerate(zip(radii, levels)):
        if r == 0.0:
            raise ValueError(f"radii_px[{k}] must be non-zero (a source on the axis does not move); got 0")
        phase = phase_rad if r > 0 else phase_rad + math.pi
        out.append(
            CircularTarget(centre_x_px, centre_y_px, abs(r), angular_rate_rad_s, b, phase, label=f"bar[{k}]")
        )
    return out


@dataclass(frozen=True, eq=False)
class TabulatedTarget(Target):
    """A trajectory given as a table (t_s, x_px, y_px), interpolated linearly.

    outside: times outside [t_s[0], t_s[-1]] either ``"raise"`` (default: a ValueError naming
    the time, so a simulation longer than its ephemeris fails loudly) or ``"hold"`` (the end
    positions, at rest).
    """

    t_s: np.ndarray
    x_px: np.ndarray
    y_px: np.ndarray
    brightness: Brightness
    outside: Outside = "raise"
    label: str = ""

    def __post_init__(self) -> None:
        t = _table_times("t_s", self.t_s)
        x = np.array(_table("x_px", "t_s", t, self.x_px))
        y = np.array(_table("y_px", "t_s", t, self.y_px))
        if self.outside not in ("raise", "hold"):
            raise ValueError(f"outside must be 'raise' or 'hold'; got outside={self.outside!r}")
        x.setflags(write=False)
        y.setflags(write=False)
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "x_px", x)
        object.__setattr__(self, "y_px", y)
        object.__setattr__(self, "brightness", _check_brightness(self.brightness))

    def _check_range(self, t: np.ndarray, name: str = "t_s") -> None:
        if self.outside == "raise" and t.size:
            lo, hi = float(t.min()), float(t.max())
            if lo < self.t_s[0] or hi > self.t_s[-1]:
                bad = lo if lo < self.t_s[0] else hi
                what = f"TabulatedTarget {self.label!r}" if self.label else "TabulatedTarget"
                raise ValueError(
                    f"{name}={bad!r} is outside the table [{self.t_s[0]!r}, {self.t_s[-1]!r}] s of {what} (outside='raise')"
                )

    def _segment_velocity(self) -> tuple[np.ndarray, np.ndarray]:
        dt = np.diff(self.t_s)
        return np.diff(self.x_px) / dt, np.diff(self.y_px) / dt

    def position_px(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        t = _times(t_s)
        self._check_range(t)
        return np.interp(t, self.t_s, self.x_px), np.interp(t, self.t_s, self.y_px)

    def velocity_px_s(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Velocity of the segment containing each time (the later one at an inner table
        point, the last one at the last point; 0 outside the table with outside='hold')."""
        t = _times(t_s)
        self._check_range(t)
        if self.t_s.size < 2:
            return np.zeros(t.shape), np.zeros(t.shape)
        vx, vy = self._segment_velocity()
        k = np.clip(np.searchsorted(self.t_s, t, side="right") - 1, 0, self.t_s.size - 2)
        inside = (t >= self.t_s[0]) & (t <= self.t_s[-1])
        return np.where(inside, vx[k], 0.0), np.where(inside, vy[k], 0.0)

    def max_speed_px_s(self, t0_s: float, t1_s: float) -> float:
        t0, t1 = _interval(t0_s, t1_s)
        self._check_range(np.array([t0, t1]), "t0_s/t1_s")
        if self.t_s.size < 2:
            return 0.0
        vx, vy = self._segment_velocity()
        speed = np.hypot(vx, vy)
        touch = (self.t_s[1:] >= t0) & (self.t_s[:-1] <= t1)
        return float(speed[touch].max()) if np.any(touch) else 0.0



def drift_px_s_from_arcsec(wx_arcsec_s: float, wy_arcsec_s: float, optics: Optics) -> tuple[float, float]:
    """A field drift across the sky [arcsec/s] in pixels per second through the plate scale
    (``optics.plate_scale_arcsec_per_px``; small-angle, as ``LinearTarget.from_angular_velocity``)."""
    k = optics.plate_scale_arcsec_per_px
    return _drift("drift_px_s", (finite("wx_arcsec_s", wx_arcsec_s) / k, finite("wy_arcsec_s", wy_arcsec_s) / k))
