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
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.special import erfc

from .optics import _array, _positive

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
    steps = np.arange(k + 1, dtype=np.float64)
    chunk = max(1, _CHUNK_ELEMENTS // (k * k))
    out: list[tuple[np.ndarray, np.ndarray]] = []
    for start in range(0, sel.size, chunk):
        s = sel[start : start + chunk]
        xs, ys, ss = x[s], y[s], sigma[s]
        fx0 = cx[s] - half
        fy0 = cy[s] - half
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
        cols = fx0.astype(np.int64)[:, None] + np.arange(k, dtype=np.int64)
        rows = fy0.astype(np.int64)[:, None] + np.arange(k, dtype=np.int64)
        vx = (cols >= 0) & (cols < width)
        vy = (rows >= 0) & (rows < height)
        w = (flux[s][:, None, None] * py[:, :, None]) * px[:, None, :]
        idx = rows[:, :, None] * width + cols[:, None, :]
        if offset is not None:
            idx = idx + offset[s][:, None, None]
        if vx.all() and vy.all():  # every window fully on the sensor: no masking
            out.append((idx.reshape(-1), w.reshape(-1)))
        else:
            m = vy[:, :, None] & vx[:, None, :]
            out.append((idx[m], w[m]))
    return out


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
    sigma_px: npt.ArrayLike,
    shape: tuple[int, ...] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    x = _array("x_px", x_px)
    y = _array("y_px", y_px)
    flux = _array("flux_ph_s", flux_ph_s, min_value=0.0)
    sigma = _array("sigma_px", sigma_px, min_value=0.0, strict=True)
    try:
        if shape is None:
            shape = np.broadcast_shapes(x.shape, y.shape, flux.shape, sigma.shape)
        x, y, flux, sigma = (np.broadcast_to(a, shape) for a in (x, y, flux, sigma))
    except ValueError:
        raise ValueError(
            f"x_px, y_px, flux_ph_s, sigma_px must broadcast together{'' if shape is None else f' to {shape}'}; "
            f"got shapes {np.shape(x_px)}, {np.shape(y_px)}, {np.shape(flux_ph_s)}, {np.shape(sigma_px)}"
        ) from None
    return tuple(np.ascontiguousarray(a).reshape(-1) for a in (x, y, flux, sigma))  # type: ignore[return-value]


def render_points(
    width: int,
    height: int,
    x_px: npt.ArrayLike,
    y_px: npt.ArrayLike,
    flux_ph_s: npt.ArrayLike,
    sigma_px: npt.ArrayLike,
    out: np.ndarray | None = None,
    window_sigmas: float = 5.0,
    normalize: bool = True,
) -> np.ndarray:
    """Render point sources into a (height, width) image of photons/s per pixel (eq. 17).

    x_px, y_px: source centres [px] (pixel-centre convention of this module); flux_ph_s:
    photons/s of each source at the focal plane, >= 0; sigma_px: PSF sigma [px], > 0 (e.g.
    ``Optics.psf_sigma_px``). All four broadcast together (scalars = one source).
    out: optional C-contiguous float64/float32 (height, width) array the sources are *added*
    to (pre-fill it with a background); a new zero image otherwise.
    window_sigmas, normalize: see the module docstring (5 sigma, renormalised window).
    Cost grows with the number of sources and their window, not with the sensor size (except
    allocating ``out``).
    """
    width, height = _check_size(width, height)
    x, y, flux, sigma = _sources(x_px, y_px, flux_ph_s, sigma_px)
    half = window_half_width_px(float(sigma.max()) if sigma.size else 1.0, window_sigmas)
    if out is None:
        out = np.zeros((height, width), np.float64)
    else:
        _check_out(out, (height, width))
    flat = out.reshape(-1)
    for idx, w in _window_contributions(width, height, x, y, flux, sigma, half, normalize):
        _accumulate(flat, idx, w)
    return out


def render_window(
    width: int,
    height: int,
    x_px: npt.ArrayLike,
    y_px: npt.ArrayLike,
    flux_ph_s: npt.ArrayLike,
    sigma_px: npt.ArrayLike,
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
    half = window_half_width_px(float(sigma.max()) if sigma.size else 1.0, window_sigmas)
    parts = _window_contributions(width, height, x, y, flux, sigma, half, normalize)
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
    sigma_px: npt.ArrayLike,
    background_ph_s: npt.ArrayLike = 0.0,
    out: np.ndarray | None = None,
    window_sigmas: float = 5.0,
    normalize: bool = True,
    dtype: npt.DTypeLike = np.float64,
) -> np.ndarray:
    """Render T samples of S sources: a (T, height, width) array of photons/s per pixel.

    x_px, y_px: (T, S) source centres [px] at each sample; flux_ph_s, sigma_px: broadcastable
    to (T, S) (e.g. (S,) for constant values, a scalar for all). background_ph_s: photons/s
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
        half = window_half_width_px(float(sigma.max()), window_sigmas)
        offset = np.repeat(np.arange(n_t, dtype=np.int64) * (height * width), n_s)
        flat = out.reshape(-1)
        for idx, w in _window_contributions(width, height, x, y, flux, sigma, half, normalize, offset):
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
