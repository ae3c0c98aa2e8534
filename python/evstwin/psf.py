"""Point-spread function rendering (paper eq. 17): point sources -> photons/s on each pixel.

Eq. 17 integrates a circular Gaussian of standard deviation sigma over each pixel's bounds:

    lambda_ij = Phi / 4 (erf(x+) - erf(x-)) (erf(y+) - erf(y-)),  x+- = (x_ij+- - x0) / (sqrt(2) sigma)

Pixel convention (the same as ``optics``): pixel centres at integer coordinates; pixel
``(i, j)`` (row i, column j) covers ``x`` in ``[j - 0.5, j + 0.5]`` and ``y`` in
``[i - 0.5, i + 0.5]``; images are ``(height, width)`` arrays indexed ``[i, j] = [y, x]``.

The output is photons/s *arriving on each pixel's full area*: no fill factor is applied here
(the sensor engine applies the fill factor and the photodiode QE itself).

Windowing and flux conservation
-------------------------------
Each source is evaluated only on a square window of ``2 h + 1`` pixels a side centred on the
pixel nearest to it, ``h = max(2, ceil(window_sigmas * sigma))``, so the cost per source does
not depend on the sensor size. Every window edge lies at least ``h >= window_sigmas * sigma``
from the source, so the flux outside the window is at most ``erfc(window_sigmas / sqrt 2)``
per axis, 2 erfc(...) in 2-D: 1.1e-6 of the flux for the default 5 sigma (3.9e-9 at 6 sigma).

With ``normalize=True`` (default) each axis profile is divided by its in-window integral, so a
source whose window lies on the sensor deposits exactly its flux (to rounding), and a source
near an edge deposits its flux times the in-sensor share of its window, which differs from the
exact in-sensor share of the untruncated Gaussian by at most the tail above. Per-pixel values
then exceed eq. 17 by the factor 1 / (1 - tail) <= 1 + 1.2e-6. ``normalize=False`` gives eq. 17
exactly on the window and drops the tail. The erf differences are formed from erfc of the
distance to the centre, so far-tail pixels keep full relative precision.
Other shapes
------------
Every renderer takes, in place of ``sigma_px``, a ``PSFShape``: ``GaussianPSF`` (the above),
or a ``KernelPSF`` tabulated at sub-pixel phases from ``airy_psf`` (the diffraction pattern of
an obstructed pupil with spider vanes), ``moffat_psf`` (a seeing halo) or ``image_psf`` (a
PSF image); ``from_optics`` builds the one an ``Optics`` names (its ``psf`` field). All
renderers, and ``simulate``'s sparse chunks, go through ``contributions``. ``KernelPSF``
states the sub-pixel accuracy, the taper that cuts a shape at its window and what the
window keeps (``captured_fraction``).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.special import erfc

from .optics import Optics, _array, _finite, _non_negative, _positive

_SQRT2 = math.sqrt(2.0)
_CHUNK_ELEMENTS = 1 << 21
"""Bound on window pixels processed at once (memory ~ 40 bytes each)."""


class PixelValues(NamedTuple):
    """Sparse image: the pixels touched by some sources and their photons/s.

    ``flat_index`` is the pixel index ``y * width + x`` (int64, sorted, unique); recover the
    coordinates with ``y, x = np.divmod(flat_index, width)``. ``value`` is photons/s [float64].
    """

    flat_index: np.ndarray
    value: np.ndarray


MAX_WINDOW_HALF_PX = 2048
"""Largest half width of the window rendered per source [px]: 4097 px a side, 1.7e7 pixels
and about 400 MB while one source is rendered (the whole window is computed, then clipped to
the sensor). A wider PSF is refused with a ValueError instead of exhausting memory."""


def window_half_width_px(sigma_px: float, window_sigmas: float = 5.0) -> int:
    """Half width h [px] of the square window (2 h + 1 pixels a side) rendered per source."""
    s = _positive("sigma_px", sigma_px)
    w = _positive("window_sigmas", window_sigmas)
    half = w * s
    if not half <= MAX_WINDOW_HALF_PX:
        raise ValueError(f"window_sigmas x sigma_px must be at most {MAX_WINDOW_HALF_PX} px (a {2 * MAX_WINDOW_HALF_PX + 1}"
                         f" px window, ~400 MB per source); got sigma_px={sigma_px!r}, window_sigmas={window_sigmas!r}: "
                         f"{half:.3g} px")
    return max(2, math.ceil(half))


def pixel_fractions(
    centre_px: npt.ArrayLike, sigma_px: npt.ArrayLike, first_px: npt.ArrayLike, n_px: int
) -> np.ndarray:
    """1-D share of a unit Gaussian on pixels ``first_px .. first_px + n_px - 1`` (unnormalised).

    ``0.5 (erf(b) - erf(a))`` for each pixel ``[p - 0.5, p + 0.5]``, computed from erfc for
    precision in the tails. Shapes: centre, sigma, first broadcast to (n,); result (n, n_px).
    """
    c, s, f = np.broadcast_arrays(
        np.atleast_1d(np.asarray(centre_px, np.float64)),
        np.atleast_1d(np.asarray(sigma_px, np.float64)),
        np.atleast_1d(np.asarray(first_px, np.float64)),
    )
    edges = f[:, None] - 0.5 + np.arange(n_px + 1, dtype=np.float64)
    u = (edges - c[:, None]) / (_SQRT2 * s[:, None])
    return _erf_differences(u)


def _erf_differences(u: np.ndarray) -> np.ndarray:
    """0.5 (erf(u[:, k+1]) - erf(u[:, k])) without cancellation, for increasing u rows."""
    t = erfc(np.abs(u))
    ta, tb = t[:, :-1], t[:, 1:]
    a, b = u[:, :-1], u[:, 1:]
    return np.where(a >= 0.0, 0.5 * (ta - tb), np.where(b <= 0.0, 0.5 * (tb - ta), 1.0 - 0.5 * (ta + tb)))


def _window_contributions(
    width: int,
    height: int,
    x: np.ndarray,
    y: np.ndarray,
    flux: np.ndarray,
    sigma: np.ndarray,
    half: int,
    normalize: bool,
    offset: np.ndarray | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(flat index, photons/s) of every in-sensor window pixel of every source, in chunks.

    x, y, flux, sigma: 1-D, same length, validated. offset: per-source int64 added to the
    flat index (frame offsets for render_frames).
    """
    k = 2 * half + 1
    steps = np.arange(k + 1, dtype=np.float64)

    def weights(s: np.ndarray, cx: np.ndarray, cy: np.ndarray) -> np.ndarray:
        xs, ys, ss = x[s], y[s], sigma[s]
        fx0 = cx - half
        fy0 = cy - half
        scale = 1.0 / (_SQRT2 * ss)[:, None]
        ux = (fx0[:, None] - 0.5 + steps - xs[:, None]) * scale
        uy = (fy0[:, None] - 0.5 + steps - ys[:, None]) * scale
        px = _erf_differences(ux)
        py = _erf_differences(uy)
        if normalize:
            # The outer edges straddle the centre (they are >= half >= 2 px away from it).
            ex = erfc(np.abs(ux[:, [0, -1]]))
            ey = erfc(np.abs(uy[:, [0, -1]]))
            px /= (1.0 - 0.5 * (ex[:, 0] + ex[:, 1]))[:, None]
            py /= (1.0 - 0.5 * (ey[:, 0] + ey[:, 1]))[:, None]
        return (flux[s][:, None, None] * py[:, :, None]) * px[:, None, :]

    return _scatter(width, height, x, y, flux, half, weights, offset)


def _scatter(
    width: int,
    height: int,
    x: np.ndarray,
    y: np.ndarray,
    flux: np.ndarray,
    half: int,
    weights: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray],
    offset: np.ndarray | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """The window of every source with flux > 0 that touches the sensor, in chunks: (flat
    index, photons/s) of its in-sensor pixels. ``weights(s, cx, cy)`` gives the photons/s
    (len(s), 2 half + 1, 2 half + 1) of sources ``s`` on windows centred on pixel (cx, cy)."""
    cx = np.floor(x + 0.5)
    cy = np.floor(y + 0.5)
    keep = (
        (flux > 0.0)
        & (cx + half >= 0)
        & (cx - half <= width - 1)
        & (cy + half >= 0)
        & (cy - half <= height - 1)
    )
    sel = np.flatnonzero(keep)
    k = 2 * half + 1
    chunk = max(1, _CHUNK_ELEMENTS // (k * k))
    out: list[tuple[np.ndarray, np.ndarray]] = []
    for start in range(0, sel.size, chunk):
        s = sel[start : start + chunk]
        fx0 = cx[s] - half
        fy0 = cy[s] - half
        w = weights(s, cx[s], cy[s])
        cols = fx0.astype(np.int64)[:, None] + np.arange(k, dtype=np.int64)
        rows = fy0.astype(np.int64)[:, None] + np.arange(k, dtype=np.int64)
        vx = (cols >= 0) & (cols < width)
        vy = (rows >= 0) & (rows < height)
        idx = rows[:, :, None] * width + cols[:, None, :]
        if offset is not None:
            idx = idx + offset[s][:, None, None]
        if vx.all() and vy.all():  # every window fully on the sensor: no masking
            out.append((idx.reshape(-1), w.reshape(-1)))
        else:
            m = vy[:, :, None] & vx[:, None, :]
            out.append((idx[m], w[m]))
    return out


def contributions(
    width: int,
    height: int,
    x: np.ndarray,
    y: np.ndarray,
    flux: np.ndarray,
    psf: npt.ArrayLike | PSFShape,
    sigma: np.ndarray | None = None,
    window_sigmas: float = 5.0,
    normalize: bool = True,
    offset: np.ndarray | None = None,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """(flat index, photons/s) chunks of every in-sensor window pixel of every source: the one
    function every renderer goes through (``render_*`` and ``simulate``'s sparse chunks).

    x, y, flux: 1-D float64 source arrays of one length (validated as ``_sources`` does).
    psf: a ``PSFShape``, or a Gaussian sigma [px] (a scalar or per source; ``sigma``, if
    given, is it already validated and broadcast). window_sigmas, normalize: the Gaussian's
    window (a shape carries its own). offset: int64 per source added to the flat index.
    """
    if isinstance(psf, PSFShape):
        if window_sigmas != 5.0 or normalize is not True:
            raise ValueError("window_sigmas and normalize apply to a Gaussian sigma_px; a PSF shape carries its own "
                             f"window (GaussianPSF(sigma_px, window_sigmas, normalize)); got {psf!r}")
        return psf.contributions(width, height, x, y, flux, offset)
    if sigma is None:
        sigma = np.ascontiguousarray(np.broadcast_to(_array("sigma_px", psf, min_value=0.0, strict=True), x.shape))
    half = window_half_width_px(float(sigma.max()) if sigma.size else 1.0, window_sigmas)
    return _window_contributions(width, height, x, y, flux, sigma, half, normalize, offset)


def _accumulate(flat: np.ndarray, idx: np.ndarray, w: np.ndarray) -> None:
    """flat[idx] += w with repeated indices summed; O(n + span) when the indices are dense
    (bincount over their range), O(n) scattered otherwise (ufunc.at), never O(flat.size)."""
    if idx.size == 0:
        return
    lo = int(idx.min())
    span = int(idx.max()) - lo + 1
    if span <= 8 * idx.size + 4096:
        flat[lo : lo + span] += np.bincount(idx - lo, weights=w, minlength=span)
    else:
        np.add.at(flat, idx, w.astype(flat.dtype, copy=False))


def _check_size(width: int, height: int) -> tuple[int, int]:
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v <= 0:
            raise ValueError(f"{name} must be a positive integer; got {name}={v!r}")
    return int(width), int(height)


def _sources(
    x_px: npt.ArrayLike,
    y_px: npt.ArrayLike,
    flux_ph_s: npt.ArrayLike,
    sigma_px: npt.ArrayLike | PSFShape,
    shape: tuple[int, ...] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    x = _array("x_px", x_px)
    y = _array("y_px", y_px)
    flux = _array("flux_ph_s", flux_ph_s, min_value=0.0)
    sigma = np.ones(()) if isinstance(sigma_px, PSFShape) else _array("sigma_px", sigma_px, min_value=0.0, strict=True)
    try:
        if shape is None:
            shape = np.broadcast_shapes(x.shape, y.shape, flux.shape, sigma.shape)
        x, y, flux, sigma = (np.broadcast_to(a, shape) for a in (x, y, flux, sigma))
    except ValueError:
        raise ValueError(
            f"x_px, y_px, flux_ph_s, sigma_px must broadcast together{'' if shape is None else f' to {shape}'}; "
            f"got shapes {np.shape(x_px)}, {np.shape(y_px)}, {np.shape(flux_ph_s)}, {np.shape(sigma)}"
        ) from None
    return tuple(np.ascontiguousarray(a).reshape(-1) for a in (x, y, flux, sigma))  # type: ignore[return-value]


def render_points(
    width: int,
    height: int,
    x_px: npt.ArrayLike,
    y_px: npt.ArrayLike,
    flux_ph_s: npt.ArrayLike,
    sigma_px: npt.ArrayLike | PSFShape,
    out: np.ndarray | None = None,
    window_sigmas: float = 5.0,
    normalize: bool = True,
) -> np.ndarray:
    """Render point sources into a (height, width) image of photons/s per pixel (eq. 17).

    x_px, y_px: source centres [px] (pixel-centre convention of this module); flux_ph_s:
    photons/s of each source at the focal plane, >= 0; sigma_px: PSF sigma [px], > 0 (e.g.
    ``Optics.psf_sigma_px``), or a ``PSFShape`` (``Optics.psf_shape()``; then window_sigmas
    and normalize stay at their defaults: the shape has its own window). All four broadcast
    together (scalars = one source).
    out: optional C-contiguous float64/float32 (height, width) array the sources are *added*
    to (pre-fill it with a background); a new zero image otherwise.
    window_sigmas, normalize: see the module docstring (5 sigma, renormalised window).
    Cost grows with the number of sources and their window, not with the sensor size (except
    allocating ``out``).
    """
    width, height = _check_size(width, height)
    x, y, flux, sigma = _sources(x_px, y_px, flux_ph_s, sigma_px)
    parts = contributions(width, height, x, y, flux, sigma_px, sigma, window_sigmas, normalize)
    if out is None:
        out = np.zeros((height, width), np.float64)
    else:
        _check_out(out, (height, width))
    flat = out.reshape(-1)
    for idx, w in parts:
        _accumulate(flat, idx, w)
    return out


def render_window(
    width: int,
    height: int,
    x_px: npt.ArrayLike,
    y_px: npt.ArrayLike,
    flux_ph_s: npt.ArrayLike,
    sigma_px: npt.ArrayLike | PSFShape,
    window_sigmas: float = 5.0,
    normalize: bool = True,
) -> PixelValues:
    """Sparse ``render_points``: only the pixels inside some source's window, summed.

    Returns ``PixelValues(flat_index, value)``: flat indices ``y * width + x`` (sorted, unique) of
    every on-sensor pixel within a window of a source with flux > 0 (values may be 0 far in
    a narrow PSF's tail), and their photons/s. An isolated source well inside the sensor
    touches exactly (2 h + 1)^2 pixels (``window_half_width_px``), whatever the sensor size.
    """
    width, height = _check_size(width, height)
    x, y, flux, sigma = _sources(x_px, y_px, flux_ph_s, sigma_px)
    parts = contributions(width, height, x, y, flux, sigma_px, sigma, window_sigmas, normalize)
    if not parts:
        return PixelValues(np.zeros(0, np.int64), np.zeros(0, np.float64))
    idx = np.concatenate([p[0] for p in parts])
    w = np.concatenate([p[1] for p in parts])
    index, inverse = np.unique(idx, return_inverse=True)
    value = np.bincount(inverse.reshape(-1), weights=w, minlength=index.size)
    return PixelValues(index.astype(np.int64, copy=False), value)


def render_frames(
    width: int,
    height: int,
    x_px: npt.ArrayLike,
    y_px: npt.ArrayLike,
    flux_ph_s: npt.ArrayLike,
    sigma_px: npt.ArrayLike | PSFShape,
    background_ph_s: npt.ArrayLike = 0.0,
    out: np.ndarray | None = None,
    window_sigmas: float = 5.0,
    normalize: bool = True,
    dtype: npt.DTypeLike = np.float64,
) -> np.ndarray:
    """Render T samples of S sources: a (T, height, width) array of photons/s per pixel.

    x_px, y_px: (T, S) source centres [px] at each sample; flux_ph_s, sigma_px: broadcastable
    to (T, S) (e.g. (S,) for constant values, a scalar for all); sigma_px may be a ``PSFShape``
    (as in ``render_points``). background_ph_s: photons/s
    per pixel added everywhere, >= 0, broadcastable to (T, height, width) (a scalar, a
    (height, width) map, or ``b[:, None, None]`` for one value per sample).
    out: optional C-contiguous (T, height, width) float64/float32 array, overwritten.
    dtype: of a new output (float64 default; float32 halves the memory, the engine takes both).
    All sources of all samples are rendered in one vectorised pass (windows as in
    ``render_points``); the feed for ``Sensor.run``. Sources that do not move (a star field
    seen by a tracking mount) are cheaper rendered once with ``render_points`` and passed as
    ``background_ph_s``.
    """
    width, height = _check_size(width, height)
    xa = np.asarray(x_px)
    if xa.ndim != 2 or np.shape(y_px) != xa.shape:
        raise ValueError(
            f"x_px and y_px must be (T, S) arrays of the same shape; got shapes {np.shape(x_px)} and {np.shape(y_px)}"
        )
    n_t, n_s = xa.shape
    x, y, flux, sigma = _sources(x_px, y_px, flux_ph_s, sigma_px, shape=(n_t, n_s))
    bg = _array("background_ph_s", background_ph_s, min_value=0.0)
    shape = (n_t, height, width)
    try:
        bg = np.broadcast_to(bg, shape)
    except ValueError:
        raise ValueError(
            f"background_ph_s must broadcast to {shape}; got shape {np.shape(background_ph_s)}"
        ) from None
    if out is None:
        dt = np.dtype(dtype)
        if dt not in (np.dtype(np.float64), np.dtype(np.float32)):
            raise ValueError(f"dtype must be float64 or float32; got dtype={dt}")
        out = np.empty(shape, dt)
    else:
        _check_out(out, shape)
    out[...] = bg
    if x.size:
        offset = np.repeat(np.arange(n_t, dtype=np.int64) * (height * width), n_s)
        flat = out.reshape(-1)
        for idx, w in contributions(width, height, x, y, flux, sigma_px, sigma, window_sigmas, normalize, offset):
            _accumulate(flat, idx, w)
    return out


def _check_out(out: np.ndarray, shape: tuple[int, ...]) -> None:
    if not isinstance(out, np.ndarray):
        raise TypeError(f"out must be a numpy array; got {type(out).__name__}")
    if out.shape != shape:
        raise ValueError(f"out must have shape {shape}; got {out.shape}")
    if out.dtype not in (np.dtype(np.float64), np.dtype(np.float32)):
        raise ValueError(f"out must be float64 or float32; got dtype={out.dtype}")
    if not out.flags.c_contiguous or not out.flags.writeable:
        raise ValueError("out must be C-contiguous and writeable")


# ---------------------------------------------------------------------------------------------
# PSF shapes


class PSFShape:
    """A PSF the renderers take in place of ``sigma_px``: ``GaussianPSF`` or ``KernelPSF``.

    ``contributions`` is the one place sources become pixel values: ``render_points``,
    ``render_window``, ``render_frames`` and the sparse renderer of ``simulate`` all call it.
    """

    half_width_px: int
    """Half width h of the square window (2 h + 1 pixels a side) rendered around a source."""

    def contributions(
        self, width: int, height: int, x: np.ndarray, y: np.ndarray, flux: np.ndarray,
        offset: np.ndarray | None = None,
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        """(flat index, photons/s) chunks of every in-sensor window pixel of every source.

        x, y, flux: 1-D float64 arrays of the same length (validated); offset: int64 per
        source added to the flat index (the frame of each source in ``render_frames``)."""
        raise NotImplementedError

    @property
    def max_pixel_share(self) -> float:
        """The largest share of a source's flux that one pixel can receive."""
        raise NotImplementedError


@dataclass(frozen=True)
class GaussianPSF(PSFShape):
    """The Gaussian of paper eq. 17 integrated over each pixel (the default shape)."""

    sigma_px: float
    window_sigmas: float = 5.0
    normalize: bool = True

    def __post_init__(self) -> None:
        _positive("sigma_px", self.sigma_px)
        object.__setattr__(self, "half_width_px", window_half_width_px(self.sigma_px, self.window_sigmas))

    def contributions(
        self, width: int, height: int, x: np.ndarray, y: np.ndarray, flux: np.ndarray,
        offset: np.ndarray | None = None,
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        sigma = np.full(x.size, float(self.sigma_px))
        return _window_contributions(width, height, x, y, flux, sigma, self.half_width_px, self.normalize, offset)

    @property
    def max_pixel_share(self) -> float:
        s = _SQRT2 * float(self.sigma_px)
        return (math.erf(0.5 / s) / math.erf((self.half_width_px + 0.5) / s)) ** 2


DEFAULT_SUBPIXEL = 8
"""Sub-pixel phases per pixel (and axis) of a tabulated PSF (``Optics.psf_subpixel``)."""
DEFAULT_TAIL_FRACTION = 0.01
"""Flux an Airy or Moffat default window leaves outside (before renormalising): 1 %."""
DEFAULT_MAX_HALF_PX = 128
"""Largest default half width of a tabulated PSF's window [px] (257 px a side)."""
MAX_KERNEL_HALF_PX = 256
"""Largest half width of a tabulated PSF's window [px] one may ask for (``psf_half_width_px``)."""
MOFFAT_DEFAULT_BETA = 4.765
"""Moffat beta of Kolmogorov seeing (Trujillo et al. 2001, MNRAS 328, 977)."""
_MAX_GRID_SIDE = 3072
"""Most samples a side of the grid a tabulated PSF is computed on (72 MB of float64)."""
_MAX_TRANSFORM_WORK = 2e9
"""Most complex multiply-adds of one Airy transform (about 5 s on 2 cores)."""
_MAX_TABLE_ELEMENTS = 1 << 25
"""Most values in a phase table: (k + 1)^2 (2 h + 1)^2 float64, 256 MB."""
_MAX_PUPIL_SIDE = 2048
"""Most pupil samples across D for the diffraction integral."""


class KernelPSF(PSFShape):
    """A PSF tabulated as pixel values at (k + 1) x (k + 1) sub-pixel phases.

    Built from ``mass``, the PSF's flux in the cells of a square grid of ``n`` cells a side,
    each ``1 / (k m)`` px wide, centred on the source (cell edges at multiples of the cell size
    from it), normalised so that the untruncated PSF has unit flux. The PSF is cut at radius h
    from the source with a cosine taper over its outer ``taper_width_px(h)`` (``taper``): every
    phase's window then holds all of it, so a source crossing a pixel boundary (its window
    re-centred by one pixel) changes no pixel value at all, where a hard cut at the window's
    edge would switch the wings' light on and off in the edge pixels. The grid is binned to
    cells 1 / k px wide, then, for each phase p = 0..k per axis (the source ``-0.5 + p / k``
    px from the centre of its nearest pixel), summed exactly over the pixels of a (2 h + 1)^2
    window: the pixel edges then fall on cell edges. Each phase's window is divided by its own
    sum, so every source deposits exactly its flux when the window is on the sensor;
    ``captured_fraction`` is the least of those sums (the flux the window holds before that).

    Rendering a source at fractional offset (fx, fy) interpolates the four nearest phases
    bilinearly: flux is conserved, the centroid moves continuously with the source (no steps
    a moving source would turn into spurious events), and a pixel's value is exact at the
    phases and off by at most (1 / k)^2 / 8 times its second derivative with respect to the
    source position in between (measured: 0.3 % of the peak for a sigma = 1 px Gaussian at
    k = 8, ``tests/python/test_psf_shapes.py``). Detail finer than 1 / k px (a core far
    narrower than a pixel) is resolved in the table but spread linearly over 1 / k px of motion.
    """

    def __init__(self, mass: np.ndarray, subpixel: int, cell_per_fine: int, half_width_px: int, kind: str,
                 params: dict[str, Any] | None = None) -> None:
        k, m, h = int(subpixel), int(cell_per_fine), int(half_width_px)
        n_f = 2 * k * (h + 1)
        if mass.shape != (n_f * m, n_f * m):
            raise ValueError(f"mass must be {n_f * m} x {n_f * m} cells; got {mass.shape}")
        c = _cell_centres(n_f * m, 1.0 / (k * m))
        mass = mass * taper(np.hypot(c[:, None], c[None, :]), h)
        fine = mass.reshape(n_f, m, n_f, m).sum(axis=(1, 3)) if m > 1 else mass
        self.kind = kind
        self.params = dict(params or {})
        self.subpixel = k
        self.half_width_px = h
        self.fine = fine
        """Flux in cells 1 / k px wide around the source ((n_f, n_f), n_f = 2 k (h + 1))."""
        tx = _phase_bins(fine, k, h)  # (rows, p, j)
        ty = _phase_bins(np.moveaxis(tx, 0, -1), k, h)  # (p, j, q, i)
        table = np.ascontiguousarray(ty.transpose(2, 0, 3, 1))  # (q, p, i, j)
        sums = table.sum(axis=(2, 3))
        if not np.all(sums > 0.0):
            raise ValueError(f"{kind} PSF: no flux inside its {2 * h + 1} px window")
        self.captured_fraction = float(sums.min())
        """Least share of the untruncated PSF's flux inside the window, over the phases."""
        table /= sums[:, :, None, None]
        self.table = table
        """Pixel values of a unit source, (q, p, i, j): y phase, x phase, window row, column."""

    def __repr__(self) -> str:
        return (f"KernelPSF(kind={self.kind!r}, half_width_px={self.half_width_px}, subpixel={self.subpixel}, "
                f"captured_fraction={self.captured_fraction:.4g}, {self.params})")

    @property
    def max_pixel_share(self) -> float:
        return float(self.table.max())

    def contributions(
        self, width: int, height: int, x: np.ndarray, y: np.ndarray, flux: np.ndarray,
        offset: np.ndarray | None = None,
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        k, table = self.subpixel, self.table

        def phase(v: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            t = (v - c + 0.5) * k
            p = np.clip(np.floor(t), 0, k - 1).astype(np.intp)
            return p, t - p

        def weights(s: np.ndarray, cx: np.ndarray, cy: np.ndarray) -> np.ndarray:
            p, a = phase(x[s], cx)
            q, b = phase(y[s], cy)
            a3, b3 = a[:, None, None], b[:, None, None]
            w = ((1.0 - b3) * ((1.0 - a3) * table[q, p] + a3 * table[q, p + 1])
                 + b3 * ((1.0 - a3) * table[q + 1, p] + a3 * table[q + 1, p + 1]))
            w *= flux[s][:, None, None]
            return w

        return _scatter(width, height, x, y, flux, self.half_width_px, weights, offset)


def taper_width_px(half_width_px: int) -> float:
    """Width [px] of the cosine taper at the edge of a tabulated PSF: h / 8, at least 0.5 px."""
    return max(0.5, half_width_px / 8.0)


def taper(r_px: np.ndarray, half_width_px: int) -> np.ndarray:
    """1 within h - w of the source, 0.5 (1 + cos(pi (r - h + w) / w)) out to h, 0 beyond
    (w = ``taper_width_px(h)``)."""
    w = taper_width_px(half_width_px)
    t = np.clip((r_px - (half_width_px - w)) / w, 0.0, 1.0)
    return 0.5 * (1.0 + np.cos(math.pi * t))


def _phase_bins(f: np.ndarray, k: int, h: int) -> np.ndarray:
    """Sums of k consecutive cells along the last axis for every pixel j = -h..h and phase
    p = 0..k: (..., n_f) -> (..., k + 1, 2 h + 1). Pixel j at phase p takes the cells
    k (j + h + 1) - p .. + k - 1 (see ``KernelPSF``)."""
    n = k * (2 * h + 1)
    lead = f.shape[:-1]
    return np.stack([f[..., k - p : k - p + n].reshape(*lead, 2 * h + 1, k).sum(axis=-1) for p in range(k + 1)],
                    axis=-2)


def _cell_centres(n: int, cell_px: float) -> np.ndarray:
    """Centres [px] of n cells of a grid centred on the source, cell edges at multiples of cell_px."""
    return (np.arange(n, dtype=np.float64) + 0.5 - 0.5 * n) * cell_px


def _grid(kind: str, half_width_px: int, subpixel: int, cell_per_fine: int) -> int:
    n = 2 * subpixel * (half_width_px + 1) * cell_per_fine
    if n > _MAX_GRID_SIDE:
        raise ValueError(f"{kind} PSF: a window of psf_half_width_px={half_width_px} at psf_subpixel={subpixel} needs "
                         f"a grid of {n} samples a side (> {_MAX_GRID_SIDE}): lower psf_half_width_px or psf_subpixel")
    if (subpixel + 1) ** 2 * (2 * half_width_px + 1) ** 2 > _MAX_TABLE_ELEMENTS:
        raise ValueError(f"{kind} PSF: psf_half_width_px={half_width_px} at psf_subpixel={subpixel} needs a phase table "
                         f"over {_MAX_TABLE_ELEMENTS * 8 >> 20} MB: lower one of them")
    return n


def _default_half(radius_px: float, blur_sigma_px: float) -> int:
    """A window whose taper starts past radius_px plus 5 sigma of the blur: h = 8/7 of that."""
    return int(min(DEFAULT_MAX_HALF_PX, max(2, math.ceil((radius_px + 5.0 * blur_sigma_px) * 8.0 / 7.0 - 1e-9))))


def _blur(mass: np.ndarray, sigma_px: float, cell_px: float) -> np.ndarray:
    """Convolve a cell-flux grid with a Gaussian of sigma_px, integrated over the cells (erf
    differences); flux blurred past the grid's edge is lost (counted in captured_fraction)."""
    if sigma_px <= 0.0:
        return mass
    from scipy.signal import fftconvolve

    r = min(math.ceil(5.0 * sigma_px / cell_px), mass.shape[0])
    g = pixel_fractions(0.0, sigma_px / cell_px, -r, 2 * r + 1)[0]
    out = fftconvolve(mass, g[None, :], mode="same")
    out = fftconvolve(out, g[:, None], mode="same")
    return np.maximum(out, 0.0)  # FFT round-off can leave -1e-20 in empty cells


def _half_from(kind: str, half_width_px: int | None, default: int) -> int:
    if half_width_px is None:
        return default
    if isinstance(half_width_px, bool) or not isinstance(half_width_px, (int, np.integer)) \
            or not 1 <= half_width_px <= MAX_KERNEL_HALF_PX:
        raise ValueError(f"psf_half_width_px must be an integer in [1, {MAX_KERNEL_HALF_PX}]; "
                         f"got psf_half_width_px={half_width_px!r}")
    return int(half_width_px)


def _subpixel(value: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 1 <= value <= 32:
        raise ValueError(f"psf_subpixel must be an integer in [1, 32]; got psf_subpixel={value!r}")
    return int(value)


# -- diffraction -------------------------------------------------------------------------------


def pupil(n: int, obstruction_ratio: float = 0.0, spider_vanes: int = 0, spider_width_ratio: float = 0.01,
          spider_angle_deg: float = 0.0, supersample: int = 4) -> np.ndarray:
    """Transmission of the pupil on n x n samples across the diameter D, in [0, 1].

    A disc of diameter D less a central disc of ``obstruction_ratio`` D and ``spider_vanes``
    radial bars ``spider_width_ratio`` D wide from the centre out, the first at
    ``spider_angle_deg`` from the +x (column) axis towards +y (rows), the others equally
    spaced. Each sample is the open share of its area (``supersample``^2 points)."""
    ss = max(1, min(supersample, _MAX_GRID_SIDE // n))
    u = (np.arange(n * ss, dtype=np.float64) + 0.5 - 0.5 * n * ss) / (n * ss)
    ux, uy = u[None, :], u[:, None]
    r2 = ux * ux + uy * uy
    open_ = (r2 <= 0.25) & (r2 >= 0.25 * obstruction_ratio**2)
    for v in range(spider_vanes):
        th = math.radians(spider_angle_deg) + 2.0 * math.pi * v / spider_vanes
        c, s = math.cos(th), math.sin(th)
        along = ux * c + uy * s
        across = uy * c - ux * s
        open_ &= ~((along >= 0.0) & (np.abs(across) <= 0.5 * spider_width_ratio))
    return open_.reshape(n, ss, n, ss).mean(axis=(1, 3))


def airy_psf(
    lambda_n_px: float,
    obstruction_ratio: float = 0.0,
    spider_vanes: int = 0,
    spider_width_ratio: float = 0.01,
    spider_angle_deg: float = 0.0,
    extra_blur_sigma_px: float = 0.0,
    subpixel: int = DEFAULT_SUBPIXEL,
    half_width_px: int | None = None,
) -> KernelPSF:
    """The diffraction PSF of an obstructed pupil with spider vanes, integrated over pixels.

    lambda_n_px: mean wavelength x f-number / pixel pitch (``Optics``: lambda N in px), in
    [0.02, 50]; the first dark ring of the unobstructed pupil is at 1.22 lambda N.
    The intensity is |FT(pupil)|^2 at lambda N per pupil diameter (Fraunhofer), computed as a
    matrix Fourier transform (Soummer et al. 2007, Opt. Express 15, 15935) of the pupil
    (``pupil``; at least 256 samples across D and 3x the window's extent in lambda N, so its
    periodic copies lie far outside the window) at points spaced at most lambda N / 4 and
    1 / (k m) px, summed into cells; normalised by Parseval (the pupil's sum of squares), so
    the cells hold the share of the whole (untruncated) PSF. Optionally convolved with the
    Gaussian ``extra_blur_sigma_px`` [px]. Default window: the taper (``KernelPSF``) starts
    past the radius 2 lambda N / (pi^2 0.01) = 20 lambda N, where 1 - EE of the Airy pattern
    (asymptotically 2 / (pi v), v = pi r / (lambda N)) is 1 %, plus 5 sigma of the blur; h in
    [2, 128] px (a 1 % cut for lambda N up to 5.5 px; ``captured_fraction`` says what it keeps).
    """
    lam = _finite("lambda_n_px", lambda_n_px)
    if not 0.02 <= lam <= 50.0:
        raise ValueError("airy PSF: mean_wavelength_m x f_number / pixel_pitch_m (lambda N) must be in [0.02, 50] px "
                         f"(under 0.02 px the pattern is far inside a pixel: use psf='gaussian'); got {lam:.4g} px")
    eps = _finite("obstruction_ratio", obstruction_ratio)
    if not 0.0 <= eps < 1.0:
        raise ValueError(f"obstruction_ratio must be in [0, 1); got obstruction_ratio={obstruction_ratio!r}")
    if isinstance(spider_vanes, bool) or not isinstance(spider_vanes, (int, np.integer)) or not 0 <= spider_vanes <= 64:
        raise ValueError(f"spider_vanes must be an integer in [0, 64]; got spider_vanes={spider_vanes!r}")
    w = _finite("spider_width_ratio", spider_width_ratio)
    if not 0.0 <= w < 0.5:
        raise ValueError(f"spider_width_ratio must be in [0, 0.5); got spider_width_ratio={spider_width_ratio!r}")
    angle = _finite("spider_angle_deg", spider_angle_deg)
    blur = _non_negative("extra_blur_sigma_px", extra_blur_sigma_px)
    k = _subpixel(subpixel)
    h = _half_from("airy", half_width_px, _default_half(2.0 * lam / (math.pi**2 * DEFAULT_TAIL_FRACTION), blur))
    m = max(1, math.ceil(4.0 / (k * lam)))  # cells <= lambda N / 4
    n = _grid("airy", h, k, m)
    cell = 1.0 / (k * m)
    x = _cell_centres(n, cell) / lam  # lambda N units
    n_p = max(256, 2 * math.ceil(1.5 * float(np.abs(x).max())))
    if n_p > _MAX_PUPIL_SIDE:
        raise ValueError(f"airy PSF: a {2 * h + 1} px window is {float(np.abs(x).max()):.3g} lambda N wide and needs "
                         f"{n_p} pupil samples (> {_MAX_PUPIL_SIDE}): lower psf_half_width_px")
    work = n / 2 * n_p * (n + n_p)
    if work > _MAX_TRANSFORM_WORK:
        raise ValueError(f"airy PSF: a {2 * h + 1} px window at psf_subpixel={k} for lambda N = {lam:.3g} px needs "
                         f"{work:.3g} multiply-adds (> {_MAX_TRANSFORM_WORK:g}): lower psf_half_width_px or psf_subpixel")
    p = pupil(n_p, eps, int(spider_vanes), w, angle)
    u = (np.arange(n_p, dtype=np.float64) + 0.5 - 0.5 * n_p) / n_p
    a = np.exp(-2j * math.pi * np.outer(x, u))  # (n, n_p): E = a p a^T / n_p^2
    b = p @ a.T  # (n_p, n): sum over the pupil's columns
    intensity = np.empty((n, n))
    half = n // 2
    rows = max(1, (1 << 21) // n)
    for r0 in range(half, n, rows):
        r1 = min(n, r0 + rows)
        e = a[r0:r1] @ b
        intensity[r0:r1] = e.real**2 + e.imag**2
    intensity[:half] = intensity[half:][::-1, ::-1]  # |E(-x)| = |E(x)| for a real pupil
    # Density per (lambda N)^2: |E|^2 / integral |P|^2 (Parseval), and for the real, binary pupil
    # integral |P|^2 = its area = sum P du^2 with du = 1 / n_p (sum P^2 would count the grey edge
    # samples' scatter far outside the window: 0.25 % too little in the core at 256 samples);
    # times the cell area in (lambda N)^2.
    norm = float(np.sum(p)) * n_p**2
    mass = intensity * ((cell / lam) ** 2 / norm)
    mass = _blur(mass, blur, cell)
    params = {"lambda_n_px": lam, "obstruction_ratio": eps, "spider_vanes": int(spider_vanes),
              "spider_width_ratio": w, "spider_angle_deg": angle, "extra_blur_sigma_px": blur}
    return KernelPSF(mass, k, m, h, "airy", params)


# -- seeing ------------------------------------------------------------------------------------


def moffat_alpha_px(fwhm_px: float, beta: float) -> float:
    """Moffat core width alpha [px] for a FWHM: FWHM = 2 alpha sqrt(2^(1/beta) - 1)."""
    return fwhm_px / (2.0 * math.sqrt(2.0 ** (1.0 / beta) - 1.0))


def moffat_enclosed_energy(r_px: npt.ArrayLike, fwhm_px: float, beta: float) -> np.ndarray:
    """Share of a Moffat's flux within radius r: 1 - (1 + r^2 / alpha^2)^(1 - beta)."""
    a = moffat_alpha_px(fwhm_px, beta)
    r = np.asarray(r_px, np.float64)
    return 1.0 - (1.0 + (r / a) ** 2) ** (1.0 - beta)


def moffat_psf(
    fwhm_px: float,
    beta: float = MOFFAT_DEFAULT_BETA,
    extra_blur_sigma_px: float = 0.0,
    subpixel: int = DEFAULT_SUBPIXEL,
    half_width_px: int | None = None,
) -> KernelPSF:
    """A Moffat profile I(r) = (beta - 1) / (pi alpha^2) (1 + r^2 / alpha^2)^(-beta) (Moffat
    1969, A&A 3, 455), integrated over pixels.

    fwhm_px in [0.05, 100], beta > 1. Cells are sampled at their centre, at least 4 per alpha
    (and per 1 / k px). The wings hold 1 - EE(r) = (1 + r^2 / alpha^2)^(1 - beta) beyond r:
    the default window's taper (``KernelPSF``) starts past the radius where that is 1 %, plus 5
    sigma of the blur, h in [2, 128] px (beta = 4.765, FWHM 3 px: h = 7; beta = 2.5, FWHM 3 px:
    h = 14; beta <= 1.5 reaches the 128 px cap and ``captured_fraction`` says what it keeps).
    """
    f = _finite("moffat_fwhm_px", fwhm_px)
    if not 0.05 <= f <= 100.0:
        raise ValueError(f"moffat_fwhm_px must be in [0.05, 100]; got moffat_fwhm_px={fwhm_px!r}")
    be = _finite("moffat_beta", beta)
    if not 1.0 < be <= 1000.0:
        raise ValueError(f"moffat_beta must be > 1 (a finite flux) and <= 1000; got moffat_beta={beta!r}")
    blur = _non_negative("extra_blur_sigma_px", extra_blur_sigma_px)
    k = _subpixel(subpixel)
    alpha = moffat_alpha_px(f, be)
    with np.errstate(over="ignore"):
        radius = alpha * math.sqrt(max(0.0, math.exp(math.log(DEFAULT_TAIL_FRACTION) / (1.0 - be)) - 1.0))
    h = _half_from("moffat", half_width_px, _default_half(radius, blur))
    m = max(1, math.ceil(4.0 / (k * alpha)))
    m = max(1, min(m, _MAX_GRID_SIDE // (2 * k * (h + 1))))
    n = _grid("moffat", h, k, m)
    cell = 1.0 / (k * m)
    c = _cell_centres(n, cell)
    r2 = c[:, None] ** 2 + c[None, :] ** 2
    mass = ((be - 1.0) / (math.pi * alpha * alpha) * cell * cell) * (1.0 + r2 / (alpha * alpha)) ** (-be)
    mass = _blur(mass, blur, cell)
    params = {"fwhm_px": f, "beta": be, "alpha_px": alpha, "extra_blur_sigma_px": blur}
    return KernelPSF(mass, k, m, h, "moffat", params)


# -- measured -----------------------------------------------------------------------------------


def load_psf_image(path: str | Path) -> np.ndarray:
    """A PSF image from a ``.npy`` file, or a FITS file (``.fits``, ``.fit``, ``.fts``; needs
    astropy), checked: 2-D, finite, >= 0, with a positive sum. Not normalised."""
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"psf_file={str(path)!r} does not exist or is not a file")
    suffix = p.suffix.lower()
    if suffix == ".npy":
        try:
            data = np.load(p, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise ValueError(f"psf_file={str(path)!r} is not a readable .npy array ({exc})") from None
    elif suffix in (".fits", ".fit", ".fts"):
        try:
            from astropy.io import fits
        except ImportError:
            raise ValueError(f"psf_file={str(path)!r}: reading FITS needs astropy: pip install 'evstwin[fits]'") from None
        try:
            data = fits.getdata(p)
        except (OSError, ValueError, TypeError) as exc:
            raise ValueError(f"psf_file={str(path)!r} is not a readable FITS image ({exc})") from None
    else:
        raise ValueError(f"psf_file must be a .npy or .fits file; got psf_file={str(path)!r}")
    return check_psf_image(data, f"psf_file={str(path)!r}")


def check_psf_image(image: npt.ArrayLike, name: str = "psf image") -> np.ndarray:
    """The image as float64 if it is a usable PSF (2-D, finite, >= 0, positive sum)."""
    try:
        a = np.asarray(image, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a 2-D array of real numbers") from None
    if a.ndim != 2 or a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"{name} must be a 2-D image; got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} has {int(np.count_nonzero(~np.isfinite(a)))} NaN or infinite values")
    if np.any(a < 0.0):
        raise ValueError(f"{name} has negative values (the least is {float(a.min()):g})")
    if not a.sum() > 0.0:
        raise ValueError(f"{name} sums to 0: no flux")
    return a


def _overlap(n_cells: int, cell_px: float, n_img: int, img_px: float) -> np.ndarray:
    """(n_cells, n_img): share of each image pixel inside each cell, both grids centred on 0."""
    ce = (np.arange(n_cells + 1, dtype=np.float64) - 0.5 * n_cells) * cell_px
    ie = (np.arange(n_img + 1, dtype=np.float64) - 0.5 * n_img) * img_px
    lo = np.maximum(ce[:-1, None], ie[None, :-1])
    hi = np.minimum(ce[1:, None], ie[None, 1:])
    return np.clip(hi - lo, 0.0, None) / img_px


def image_psf(
    image: npt.ArrayLike,
    oversampling: float,
    extra_blur_sigma_px: float = 0.0,
    subpixel: int = DEFAULT_SUBPIXEL,
    half_width_px: int | None = None,
) -> KernelPSF:
    """A PSF given as an image with ``oversampling`` image pixels per sensor pixel per axis.

    The image is normalised to unit sum; its centre (the middle of the array, between two
    pixels for an even size) is the source position. Each image pixel is taken as uniform over
    its area and shared among the 1 / k px cells by area (exact flux; where a sensor pixel's
    edge cuts an image pixel of width d, each side gets its share of the area, which misplaces
    d^2 / 8 |dI/dx| per unit of edge: 0.7 % of the peak per axis for a sigma = 1 px Gaussian at
    d = 1/4 px). Default window: the taper (``KernelPSF``) starts past the image's corners
    (sqrt 2 max(ny, nx) / (2 oversampling) px) plus 5 sigma of the blur, h in [2, 128] px;
    ``captured_fraction`` is the share it keeps.
    """
    img = check_psf_image(image)
    o = _finite("psf_file_oversampling", oversampling)
    if not 1e-3 <= o <= 1e3:
        raise ValueError(f"psf_file_oversampling must be in [0.001, 1000]; got psf_file_oversampling={oversampling!r}")
    blur = _non_negative("extra_blur_sigma_px", extra_blur_sigma_px)
    k = _subpixel(subpixel)
    img = img / img.sum()
    extent = max(img.shape) / (2.0 * o)
    h = _half_from("image", half_width_px, _default_half(math.sqrt(2.0) * extent, blur))
    n = _grid("image", h, k, 1)
    cell = 1.0 / k
    mass = _overlap(n, cell, img.shape[0], 1.0 / o) @ img @ _overlap(n, cell, img.shape[1], 1.0 / o).T
    mass = _blur(mass, blur, cell)
    params = {"shape": img.shape, "oversampling": o, "extra_blur_sigma_px": blur}
    return KernelPSF(mass, k, 1, h, "image", params)


# -- from an Optics ----------------------------------------------------------------------------


def from_optics(optics: Optics) -> PSFShape:
    """The PSF an ``Optics`` describes (its ``psf`` field and the fields of that shape).

    Tabulated shapes take 0.01-2 s to build; they are cached (the last 4 optics; an image
    file is read again when its modification time changes)."""
    if optics.psf == "image":
        p = Path(str(optics.psf_file))
        try:
            stamp = p.stat().st_mtime_ns
        except OSError:
            stamp = -1  # load_psf_image names the missing file
        return _image_from_file(str(p), stamp, float(optics.psf_file_oversampling),  # type: ignore[arg-type]
                                float(optics.extra_blur_sigma_px), optics.psf_subpixel, optics.psf_half_width_px)
    return _from_optics(optics)


@functools.lru_cache(maxsize=4)
def _from_optics(optics: Optics) -> PSFShape:
    if optics.psf == "gaussian":
        return GaussianPSF(optics.psf_sigma_px)
    blur, k, h = optics.extra_blur_sigma_px, optics.psf_subpixel, optics.psf_half_width_px
    if optics.psf == "airy":
        lam = optics.mean_wavelength_m * optics.f_number / optics.pixel_pitch_m
        return airy_psf(lam, optics.obstruction_ratio, optics.spider_vanes, optics.spider_width_ratio,
                        optics.spider_angle_deg, blur, k, h)
    if optics.psf == "moffat":
        beta = MOFFAT_DEFAULT_BETA if optics.moffat_beta is None else optics.moffat_beta
        return moffat_psf(optics.moffat_fwhm, beta, blur, k, h)
    raise ValueError(f"psf must be one of gaussian, airy, moffat, image; got psf={optics.psf!r}")


@functools.lru_cache(maxsize=4)
def _image_from_file(path: str, stamp: int, oversampling: float, blur: float, subpixel: int,
                     half_width_px: int | None) -> KernelPSF:
    return image_psf(load_psf_image(path), oversampling, blur, subpixel, half_width_px)
