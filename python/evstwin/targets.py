"""Targets: where point sources are on the sensor [px] and how bright they are [photons/s].

Every target answers, for an array of times ``t_s`` [s]:

* ``position_px(t_s) -> (x, y)``: arrays shaped like ``t_s``, pixel coordinates (centres at
  integers, x right, y down: see ``optics``);
* ``velocity_px_s(t_s) -> (vx, vy)`` [px/s];
* ``flux_ph_s(t_s)``: photons/s at the focal plane (before fill factor and QE);
* ``max_speed_px_s(t0_s, t1_s)``: the largest speed on [t0, t1] [px/s], to choose the sample
  rate so that no target moves more than a fraction of a pixel between samples
  (docs/development/decisions.md, "Sampling never skips a track's pixels").

Brightness is a constant flux [photons/s] or a ``LightCurve`` (a table of times and fluxes,
or of magnitudes through an ``Optics``: a tumbling satellite). For a constant magnitude use
``optics.flux_from_magnitude(mag)``.

Positions are unbounded: a target may leave the sensor (the renderer then skips it).

A star field that drifts across the sensor (a telescope's tracking error, a staring camera)
moves every star at once: ``random_star_field(..., drift_px_s=(vx, vy), duration_s=D)``
gives LinearTargets, including the stars that drift in during the run, and ``drifting(target,
vx, vy)`` carries any target given in field coordinates along with the field.
"""

from __future__ import annotations

import abc
import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Literal

import numpy as np
import numpy.typing as npt

from ._checks import array, finite, integer, non_negative, positive
from .optics import Optics
from .sky.stars import STAR_FIELD_COUNTS_SLOPE, STAR_FIELD_MAG_MAX, STAR_FIELD_MAG_MIN

if TYPE_CHECKING:
    from .psf import PSFShape

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


@dataclass(frozen=True, eq=False)
class DriftingTarget(Target):
    """A target given in field coordinates, carried by a field that drifts across the sensor
    at (vx_px_s, vy_px_s) [px/s] and seen through an offset (dx_px, dy_px) [px] (a sensor
    window's coordinates): ``position = target.position_px(t) + (dx, dy) + v t`` (field and
    sensor coordinates coincide at t = 0, the start of a simulation). Its velocity is its own
    plus the drift; brightness and label are the target's.

    Use :func:`drifting` and :func:`shifted`, which give the plain kind of target where the
    result is one (static, linear, circular, tabulated), and this wrapper for the others.
    """

    target: Target
    vx_px_s: float
    vy_px_s: float
    dx_px: float = 0.0
    dy_px: float = 0.0
    brightness: Brightness = dataclasses.field(init=False)
    label: str = dataclasses.field(init=False)

    def __post_init__(self) -> None:
        adopt(self, self.target)
        for name in ("vx_px_s", "vy_px_s", "dx_px", "dy_px"):
            finite(name, getattr(self, name))

    def position_px(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        t = _times(t_s)
        x, y = self.target.position_px(t)
        return x + self.dx_px + self.vx_px_s * t, y + self.dy_px + self.vy_px_s * t

    def flux_ph_s(self, t_s: npt.ArrayLike) -> np.ndarray:
        return self.target.flux_ph_s(t_s)  # the wrapped target's (it may compute its own)

    def velocity_px_s(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        vx, vy = self.target.velocity_px_s(t_s)
        return vx + self.vx_px_s, vy + self.vy_px_s

    def max_speed_px_s(self, t0_s: float, t1_s: float) -> float:
        """Exact for tabulated targets (the fastest segment plus the drift); for the others
        the bound |own| + |drift| (reached by a circular target once per turn), which only
        ever samples more finely than needed."""
        inner = self.target
        if self.vx_px_s == 0.0 and self.vy_px_s == 0.0:
            return inner.max_speed_px_s(t0_s, t1_s)
        if isinstance(inner, TabulatedTarget) and inner.t_s.size >= 2:
            t0, t1 = _interval(t0_s, t1_s)
            inner._check_range(np.array([t0, t1]), "t0_s/t1_s")
            vx, vy = inner._segment_velocity()
            touch = (inner.t_s[1:] >= t0) & (inner.t_s[:-1] <= t1)
            speed = float(np.hypot(vx[touch] + self.vx_px_s, vy[touch] + self.vy_px_s).max(initial=0.0))
            if t0 < inner.t_s[0] or t1 > inner.t_s[-1]:  # outside a 'hold' table: at rest in the field
                speed = max(speed, math.hypot(self.vx_px_s, self.vy_px_s))
            return speed
        return inner.max_speed_px_s(t0_s, t1_s) + math.hypot(self.vx_px_s, self.vy_px_s)


def drifting(target: Target, vx_px_s: float, vy_px_s: float) -> Target:
    """``target``, given in field coordinates, as seen on the sensor while the field drifts at
    (vx_px_s, vy_px_s) [px/s] (field and sensor coordinates coincide at t = 0).

    A static target becomes ``LinearTarget(x, y, vx, vy)``; a linear one a LinearTarget with
    the velocities summed (exact, and sampled with the other linear targets in one array
    operation); any other a :class:`DriftingTarget`. A zero drift returns ``target`` itself.
    """
    vx = finite("vx_px_s", vx_px_s)
    vy = finite("vy_px_s", vy_px_s)
    if vx == 0.0 and vy == 0.0:
        return target
    if isinstance(target, StaticTarget):
        return with_psf(LinearTarget(target.x_px, target.y_px, vx, vy, target.brightness, 0.0, target.label), target.psf)
    if isinstance(target, LinearTarget):
        # x0 + v (t - t0) + d t = (x0 + d t0) + (v + d)(t - t0)
        return with_psf(LinearTarget(target.x0_px + vx * target.t0_s, target.y0_px + vy * target.t0_s,
                                     target.vx_px_s + vx, target.vy_px_s + vy, target.brightness, target.t0_s,
                                     target.label), target.psf)
    return DriftingTarget(target, vx, vy)


def shifted(target: Target, dx_px: float, dy_px: float) -> Target:
    """``target`` in coordinates whose origin is moved by (-dx_px, -dy_px): every position
    plus (dx_px, dy_px) [px] (a sensor window's coordinates: dx = -x0, dy = -y0). The same
    kind of target where the shift is a change of its constants, else a :class:`DriftingTarget`
    with that offset."""
    dx, dy = finite("dx_px", dx_px), finite("dy_px", dy_px)
    if dx == 0.0 and dy == 0.0:
        return target
    out: Target
    if isinstance(target, StaticTarget):
        out = dataclasses.replace(target, x_px=target.x_px + dx, y_px=target.y_px + dy)
    elif isinstance(target, LinearTarget):
        out = dataclasses.replace(target, x0_px=target.x0_px + dx, y0_px=target.y0_px + dy)
    elif isinstance(target, CircularTarget):
        out = dataclasses.replace(target, centre_x_px=target.centre_x_px + dx, centre_y_px=target.centre_y_px + dy)
    elif isinstance(target, TabulatedTarget):
        out = dataclasses.replace(target, x_px=target.x_px + dx, y_px=target.y_px + dy)
    elif isinstance(target, DriftingTarget):
        out = dataclasses.replace(target, dx_px=target.dx_px + dx, dy_px=target.dy_px + dy)
    else:
        out = DriftingTarget(target, 0.0, 0.0, dx, dy)
    return with_psf(out, target.psf)


def psf_groups(targets: Sequence[Target], scene_psf: PSFShape) -> list[tuple[PSFShape, np.ndarray]]:
    """The targets' indices grouped by the PSF they are rendered with: the scene's first
    (possibly empty), then each distinct own PSF (``Target.psf``) in order of appearance."""
    own: dict[int, tuple[PSFShape, list[int]]] = {}
    plain: list[int] = []
    for j, t in enumerate(targets):
        if t.psf is None or t.psf is scene_psf:
            plain.append(j)
        else:
            own.setdefault(id(t.psf), (t.psf, []))[1].append(j)
    groups = [(scene_psf, np.array(plain, np.int64))]
    groups += [(shape, np.array(cols, np.int64)) for shape, cols in own.values()]
    return groups


def with_psf(target: Target, psf: PSFShape | None) -> Target:
    """``target`` rendered with its own PSF (None: the scene's). Returns a copy; the target
    classes are frozen, and the PSF is not part of their constructor."""
    if psf is target.psf:
        return target
    out = dataclasses.replace(target) if dataclasses.is_dataclass(target) else target  # type: ignore[type-var]
    object.__setattr__(out, "psf", psf)
    return out


def adopt(wrapper: Target, inner: object, brightness: bool = True) -> None:
    """In a wrapper's ``__post_init__``: check that it wraps a Target and take its label, PSF
    and (unless the wrapper sets its own) brightness."""
    if not isinstance(inner, Target):
        raise TypeError(f"target must be a Target; got {inner!r}")
    if brightness:
        object.__setattr__(wrapper, "brightness", inner.brightness)
    object.__setattr__(wrapper, "label", inner.label)
    object.__setattr__(wrapper, "psf", inner.psf)


@dataclass(frozen=True, eq=False)
class MirroredTarget(Target):
    """A ghost of ``source``: its image reflected through (centre_x_px, centre_y_px) and
    scaled, ``position = c - magnification (source - c)``, with ``flux_fraction`` of its flux
    at every time (a light curve included). A reflection between lens surfaces or the sensor
    window forms an image of a bright star on the far side of the optical axis, moving the
    opposite way, usually defocused (give it its own PSF with :func:`with_psf`).

    ``steady=True``: the ghost keeps ``flux_fraction`` of the source's *mean* flux (a light
    curve's time average over its table, :func:`mean_flux_ph_s`) and does not follow the light
    curve. For a source whose light curve stands for more than its flux (a star's curve read
    from its own events also holds its image's jitter, which a wide defocused ghost does not
    see: ``imx636-pointsource``).
    """

    source: Target
    centre_x_px: float
    centre_y_px: float
    magnification: float = 1.0
    flux_fraction: float = 1.0
    label: str = "ghost"
    steady: bool = False
    brightness: Brightness = dataclasses.field(init=False)

    def __post_init__(self) -> None:
        if not isinstance(self.source, Target):
            raise TypeError(f"source must be a Target; got {self.source!r}")
        finite("centre_x_px", self.centre_x_px)
        finite("centre_y_px", self.centre_y_px)
        m = finite("magnification", self.magnification)
        if not m > 0.0:
            raise ValueError(f"magnification must be > 0; got magnification={self.magnification!r}")
        f = finite("flux_fraction", self.flux_fraction)
        if not 0.0 < f <= 1.0:
            raise ValueError(f"flux_fraction must be in (0, 1]; got flux_fraction={self.flux_fraction!r}")
        # Its own brightness, the source's scaled (not a flux_ph_s override): wrappers that
        # take a target's brightness (drifting, shifted, the atmosphere) then keep the share.
        if not isinstance(self.steady, bool):
            raise ValueError(f"steady must be True or False; got steady={self.steady!r}")
        b = self.source.brightness
        if self.steady:
            scaled: Brightness = f * mean_flux_ph_s(b)
        else:
            scaled = dataclasses.replace(b, flux_ph_s=f * b.flux_ph_s) if isinstance(b, LightCurve) else f * float(b)
        object.__setattr__(self, "brightness", scaled)

    def position_px(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        x, y = self.source.position_px(t_s)
        m = self.magnification
        return self.centre_x_px - m * (x - self.centre_x_px), self.centre_y_px - m * (y - self.centre_y_px)

    def velocity_px_s(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        vx, vy = self.source.velocity_px_s(t_s)
        return -self.magnification * vx, -self.magnification * vy

    def max_speed_px_s(self, t0_s: float, t1_s: float) -> float:
        return self.magnification * self.source.max_speed_px_s(t0_s, t1_s)

    def flux_ph_s(self, t_s: npt.ArrayLike) -> np.ndarray:
        if self.steady:  # brightness is then the share of the source's mean flux, a number
            return np.full(np.shape(_times(t_s)), float(self.brightness))  # type: ignore[arg-type]
        return self.flux_fraction * self.source.flux_ph_s(t_s)


@dataclass(frozen=True, eq=False)
class SteadyTarget(Target):
    """``target`` where it is, at its *mean* flux (``mean_flux_ph_s``) instead of its light
    curve: the scattered-light halo of a star whose light curve stands for seeing (light
    moved about within the seeing disc, which leaves the total that the optics scatter
    unchanged; ``imx636-pointsource``). Its label is the target's with ``-halo``; its PSF the
    target's (give it its own with :func:`with_psf`)."""

    target: Target
    brightness: Brightness = dataclasses.field(init=False)
    label: str = dataclasses.field(init=False)

    def __post_init__(self) -> None:
        adopt(self, self.target, brightness=False)
        object.__setattr__(self, "brightness", mean_flux_ph_s(self.target.brightness))
        object.__setattr__(self, "label", f"{self.target.label}-halo" if self.target.label else "halo")

    def position_px(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        return self.target.position_px(t_s)

    def velocity_px_s(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        return self.target.velocity_px_s(t_s)

    def max_speed_px_s(self, t0_s: float, t1_s: float) -> float:
        return self.target.max_speed_px_s(t0_s, t1_s)


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


@dataclass(frozen=True, eq=False)
class FieldPath:
    """An offset of the whole field on the sensor against time, on top of any steady drift: a
    mount's slew, a wind shake, a tabulated pointing error. ``(dx_px, dy_px)`` at ``t_s``
    (strictly increasing, at least 2 points), linear in between, held at the end values
    outside the table."""

    t_s: np.ndarray
    dx_px: np.ndarray
    dy_px: np.ndarray

    def __post_init__(self) -> None:
        t = _table_times("path.t_s", self.t_s)
        if t.size < 2:
            raise ValueError(f"path.t_s needs at least 2 points; got {t.size}")
        object.__setattr__(self, "t_s", t)
        for name in ("dx_px", "dy_px"):
            v = np.array(_table(f"path.{name}", "path.t_s", t, getattr(self, name)))
            v.setflags(write=False)
            object.__setattr__(self, name, v)

    def offset_px(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        t = _times(t_s)
        return np.interp(t, self.t_s, self.dx_px), np.interp(t, self.t_s, self.dy_px)

    def _slopes(self) -> tuple[np.ndarray, np.ndarray]:
        dt = np.diff(self.t_s)
        return np.diff(self.dx_px) / dt, np.diff(self.dy_px) / dt

    def velocity_px_s(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """The segment's slope (the later segment at a table point), 0 outside the table."""
        t = _times(t_s)
        vx, vy = self._slopes()
        k = np.searchsorted(self.t_s, t, side="right") - 1
        inside = (k >= 0) & (k < vx.size)
        kk = np.clip(k, 0, vx.size - 1)
        return np.where(inside, vx[kk], 0.0), np.where(inside, vy[kk], 0.0)

    def max_speed_px_s(self, t0_s: float, t1_s: float) -> float:
        t0, t1 = _interval(t0_s, t1_s)
        vx, vy = self._slopes()
        touch = (self.t_s[1:] >= t0) & (self.t_s[:-1] <= t1)
        return float(np.hypot(vx[touch], vy[touch]).max(initial=0.0))


@dataclass(frozen=True, eq=False)
class PathTarget(Target):
    """``target`` carried by a field that moves along ``path`` (its position plus the path's
    offset; brightness, label and PSF the target's). Use :func:`along_path`."""

    target: Target
    path: FieldPath
    brightness: Brightness = dataclasses.field(init=False)
    label: str = dataclasses.field(init=False)

    def __post_init__(self) -> None:
        adopt(self, self.target)

    def position_px(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        t = _times(t_s)
        x, y = self.target.position_px(t)
        dx, dy = self.path.offset_px(t)
        return x + dx, y + dy

    def velocity_px_s(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        vx, vy = self.target.velocity_px_s(t_s)
        wx, wy = self.path.velocity_px_s(t_s)
        return vx + wx, vy + wy

    def max_speed_px_s(self, t0_s: float, t1_s: float) -> float:
        """A bound: the target's own largest speed plus the path's (only ever samples more finely)."""
        return self.target.max_speed_px_s(t0_s, t1_s) + self.path.max_speed_px_s(t0_s, t1_s)

    def flux_ph_s(self, t_s: npt.ArrayLike) -> np.ndarray:
        return self.target.flux_ph_s(t_s)


def along_path(target: Target, path: FieldPath | None) -> Target:
    """``target`` moved with the field along ``path`` (None: unchanged)."""
    return target if path is None else PathTarget(target, path)


def drift_px_s_from_arcsec(wx_arcsec_s: float, wy_arcsec_s: float, optics: Optics) -> tuple[float, float]:
    """A field drift across the sky [arcsec/s] in pixels per second through the plate scale
    (``optics.plate_scale_arcsec_per_px``; small-angle, as ``LinearTarget.from_angular_velocity``)."""
    k = optics.plate_scale_arcsec_per_px
    return _drift("drift_px_s", (finite("wx_arcsec_s", wx_arcsec_s) / k, finite("wy_arcsec_s", wy_arcsec_s) / k))


# ---------------------------------------------------------------------------------------------


MAX_STARS = 1_000_000
"""Most stars of a random star field: each becomes a target (about 300 bytes, 25 us to make)
rendered at every sample; 1e6 already take 0.3 GB and 25 s to build. Refused up front."""
_STAR_BYTES = 300


def random_star_field(
    width: int,
    height: int,
    optics: Optics,
    n_stars: int | None = None,
    density_per_deg2: float | None = None,
    mag_min: float = STAR_FIELD_MAG_MIN,
    mag_max: float = STAR_FIELD_MAG_MAX,
    counts_slope: float = STAR_FIELD_COUNTS_SLOPE,
    seed: int = 0,
    drift_px_s: Sequence[float] = (0.0, 0.0),
    duration_s: float = 0.0,
    distribution: str = "uniform",
    density_scale: float = 1.0,
    margin_px: float = 0.0,
) -> list[StaticTarget] | list[LinearTarget]:
    """Random stars, uniform over the sensor, with power-law or the sky's magnitude counts.

    distribution: ``"uniform"`` (default, as before: the power law below, and n_stars or
    density_per_deg2) or ``"all-sky"``: the sky's star counts (``evstwin.sky.stars``: the
    all-sky average N(< V) of Tycho-2 + UCAC4, V in [0, 16]) between mag_min and mag_max,
    times density_scale (galactic latitude is not modelled: scale it yourself). The number
    of stars then follows from the optics: a Poisson count of that density over the field
    (give neither n_stars nor density_per_deg2; counts_slope does not apply).

    Give exactly one of ``n_stars`` or ``density_per_deg2`` (stars per square degree between
    mag_min and mag_max; the count is then Poisson over the ``width x height`` pixel field at
    ``optics.plate_scale_rad_per_px``). Magnitudes follow dN/dm ~ 10^(counts_slope m) on
    [mag_min, mag_max]: 0.6 is a uniform Euclidean population; all-sky star counts grow by
    roughly 0.4-0.5 dex per magnitude for 6 < V < 15 (an approximation: the slope flattens
    towards faint magnitudes and depends on galactic latitude). Fluxes come from
    ``optics.flux_from_magnitude``; each star's label is ``"star <k> mag=<m>"``.
    Positions cover the whole sensor area, x in [-0.5, width - 0.5), y likewise.
    The same arguments and seed give the same stars (numpy ``default_rng(seed)``, PCG64).

    drift_px_s: (vx, vy) [px/s], the velocity of the whole field across the sensor (a
    telescope's tracking error, a staring camera; ``drift_px_s_from_arcsec`` converts a rate on
    the sky). With a non-zero drift the stars are LinearTargets at (x0 + vx t, y0 + vy t) with
    the positions above at t = 0, and the field also holds the stars that drift onto the
    sensor during ``duration_s`` [s]: the area the drift sweeps past the sensor, at the same
    density (``n_stars / (width height)`` per px^2 with n_stars, a Poisson count). The
    count on the sensor is then the same in distribution at every time in [0, duration_s].
    The stars on the sensor at t = 0 are those of the field without drift (their random
    numbers come first). With no drift (the default) they are StaticTargets, as before.
    ``margin_px`` [px] adds, at the same density, the stars of a frame that wide around that
    area (drawn last, from their own stream, so the others do not change): the ones a field
    path (a slew of up to margin_px) brings in.
    """
    width = integer("width", width, 1)
    height = integer("height", height, 1)
    lo = finite("mag_min", mag_min)
    hi = finite("mag_max", mag_max)
    if not lo <= hi:
        raise ValueError(f"need mag_min <= mag_max; got mag_min={mag_min!r}, mag_max={mag_max!r}")
    alpha = non_negative("counts_slope", counts_slope)
    seed = integer("seed", seed, 0)
    vx, vy = _drift("drift_px_s", drift_px_s)
    duration = non_negative("duration_s", duration_s)
    if distribution not in ("uniform", "all-sky"):
        raise ValueError(f"distribution must be 'uniform' or 'all-sky'; got distribution={distribution!r}")
    if distribution == "all-sky":
        from .sky import stars

        if n_stars is not None or density_per_deg2 is not None:
            raise ValueError("distribution='all-sky' takes its density from the sky's star counts: give neither n_stars "
                             f"nor density_per_deg2; got n_stars={n_stars!r}, density_per_deg2={density_per_deg2!r}")
        density_per_deg2 = stars.density_per_deg2(lo, hi, density_scale)
    elif density_scale != 1.0:
        raise ValueError(f"density_scale applies to distribution='all-sky'; got density_scale={density_scale!r} with "
                         f"distribution={distribution!r}")
    if (n_stars is None) == (density_per_deg2 is None):
        raise ValueError(
            f"give exactly one of n_stars and density_per_deg2; got n_stars={n_stars!r}, density_per_deg2={density_per_deg2!r}"
        )
    rng = np.random.default_rng(seed)
    # Where a star must be at t = 0 to be on the sensor at some time in [0, duration]: the
    # sensor plus two strips swept by its leading edges moving by d = -v duration (disjoint
    # from the sensor and from each other; their union is the sensor's Minkowski sum with
    # the segment [0, d]).
    dx, dy = -vx * duration, -vy * duration
    strip_x = height * abs(dx)  # swept by the edge x = width - 0.5 (dx > 0) or -0.5 [px^2]
    strip_y = width * abs(dy)
    area_px2 = width * height + strip_x + strip_y
    swept = "" if area_px2 == width * height else (
        f" and the area drift_px_s={drift_px_s!r} sweeps past it over duration_s={duration_s!r}")
    if n_stars is not None:
        n = integer("n_stars", n_stars, 0)
        per_px2 = n / (width * height)
        mean = per_px2 * area_px2 if n else 0.0
        if n > MAX_STARS:
            raise ValueError(f"n_stars must be at most {MAX_STARS:,} (each star is a target, ~{_STAR_BYTES} bytes, "
                             f"rendered every sample); got n_stars={n:,}, {n * _STAR_BYTES / 1e9:.3g} GB")
        if not mean <= MAX_STARS:
            raise ValueError(f"n_stars={n:,} on the {width}x{height} sensor{swept} gives {mean:.3g} stars, more than "
                             f"{MAX_STARS:,} ({mean * _STAR_BYTES / 1e9:.3g} GB)")
    else:
        density = non_negative("density_per_deg2", density_per_deg2)
        px_deg = math.degrees(optics.plate_scale_rad_per_px)
        per_px2 = density * px_deg * px_deg
        on_sensor = density * width * height * px_deg * px_deg  # this order: the same draws as before drifts
        mean = on_sensor + per_px2 * (strip_x + strip_y) if per_px2 > 0.0 else 0.0
        if not mean <= MAX_STARS:
            raise ValueError(
                f"density_per_deg2={density_per_deg2!r} gives {mean:.3g} stars on the {width}x{height} field{swept} "
                f"({area_px2 * px_deg * px_deg:.3g} deg2), more than {MAX_STARS:,} ({mean * _STAR_BYTES / 1e9:.3g} GB)"
            )
        n = int(rng.poisson(on_sensor))
    x = rng.uniform(-0.5, width - 0.5, n)
    y = rng.uniform(-0.5, height - 0.5, n)
    u = rng.uniform(0.0, 1.0, n)
    if strip_x + strip_y > 0.0 and per_px2 > 0.0:
        n_x = int(rng.poisson(per_px2 * strip_x))
        along, s = rng.uniform(-0.5, height - 0.5, n_x), rng.uniform(0.0, 1.0, n_x)
        xs = (width - 0.5 if dx > 0 else -0.5) + s * dx
        ys = along + s * dy
        n_y = int(rng.poisson(per_px2 * strip_y))
        along, s = rng.uniform(-0.5, width - 0.5, n_y), rng.uniform(0.0, 1.0, n_y)
        x = np.concatenate([x, xs, along + s * dx])
        y = np.concatenate([y, ys, (height - 0.5 if dy > 0 else -0.5) + s * dy])
        u = np.concatenate([u, rng.uniform(0.0, 1.0, n_x + n_y)])
        n = x.size
    margin = non_negative("margin_px", margin_px)
    if margin > 0.0 and per_px2 > 0.0:
        # The frame: the bounding box of the sensor and its strips, widened by the margin, less
        # the sensor and strips themselves (rejection, at the same density).
        bx0, bx1 = -0.5 + min(dx, 0.0), width - 0.5 + max(dx, 0.0)
        by0, by1 = -0.5 + min(dy, 0.0), height - 0.5 + max(dy, 0.0)
        fx0, fx1, fy0, fy1 = bx0 - margin, bx1 + margin, by0 - margin, by1 + margin
        frame_rng = np.random.default_rng([seed, 1])
        n_f = int(frame_rng.poisson(per_px2 * (fx1 - fx0) * (fy1 - fy0)))
        fx, fy = frame_rng.uniform(fx0, fx1, n_f), frame_rng.uniform(fy0, fy1, n_f)
        fu = frame_rng.uniform(0.0, 1.0, n_f)
        in_sensor = (fx >= -0.5) & (fx < width - 0.5) & (fy >= -0.5) & (fy < height - 0.5)
        keep = ~in_sensor
        with np.errstate(divide="ignore", invalid="ignore"):
            if dx != 0.0:  # the strip swept by the x edge: edge + s d, s in [0, 1), sheared by dy
                sx = (fx - (width - 0.5 if dx > 0 else -0.5)) / dx
                along = fy - sx * dy
                keep &= ~((sx >= 0.0) & (sx < 1.0) & (along >= -0.5) & (along < height - 0.5))
            if dy != 0.0:
                sy = (fy - (height - 0.5 if dy > 0 else -0.5)) / dy
                along = fx - sy * dx
                keep &= ~((sy >= 0.0) & (sy < 1.0) & (along >= -0.5) & (along < width - 0.5))
        if not (n + int(keep.sum())) <= MAX_STARS:
            raise ValueError(f"margin_px={margin_px!r} around the {width}x{height} field gives {n + int(keep.sum())} "
                             f"stars, more than {MAX_STARS:,}")
        x, y, u = np.concatenate([x, fx[keep]]), np.concatenate([y, fy[keep]]), np.concatenate([u, fu[keep]])
        n = x.size
    if distribution == "all-sky":
        from .sky import stars

        mag = stars.draw_magnitudes(u, lo, hi)
    elif alpha == 0.0 or hi == lo:
        mag = lo + (hi - lo) * u
    else:
        # inverse CDF of dN/dm ~ 10^(alpha m) on [lo, hi], relative to lo (no overflow)
        mag = lo + np.log10(1.0 + u * (10.0 ** (alpha * (hi - lo)) - 1.0)) / alpha
    flux = np.asarray(optics.flux_from_magnitude(mag), np.float64).reshape(-1)
    if vx == 0.0 and vy == 0.0:
        return [
            StaticTarget(float(x[k]), float(y[k]), float(flux[k]), label=f"star {k} mag={mag[k]:.3f}")
            for k in range(n)
        ]
    return [
        LinearTarget(float(x[k]), float(y[k]), vx, vy, float(flux[k]), label=f"star {k} mag={mag[k]:.3f}")
        for k in range(n)
    ]


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
