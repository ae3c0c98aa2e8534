"""Targets made from other targets: carried by a drifting or moving field, shifted into a
window's coordinates, mirrored as a ghost, held at their mean flux, rendered with a PSF of
their own."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from .._checks import finite
from .base import Brightness, LightCurve, Target, _interval, _table, _table_times, _times, mean_flux_ph_s
from .kinds import CircularTarget, LinearTarget, StaticTarget, TabulatedTarget

if TYPE_CHECKING:
    from ..psf import PSFShape

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
