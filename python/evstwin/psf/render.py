"""The pixel-integrated rendering of point sources (paper eq. 17) and the PSFShape interface
(the package docstring, ``evstwin.psf``, says what they do)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt
from scipy.special import erfc

from .._checks import array, positive, size

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
    s = positive("sigma_px", sigma_px)
    w = positive("window_sigmas", window_sigmas)
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
            idx += offset[s][:, None, None]  # in place: no second window-sized temporary
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
        sigma = np.ascontiguousarray(np.broadcast_to(array("sigma_px", psf, min_value=0.0, strict=True), x.shape))
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


def _sources(
    x_px: npt.ArrayLike,
    y_px: npt.ArrayLike,
    flux_ph_s: npt.ArrayLike,
    sigma_px: npt.ArrayLike | PSFShape,
    shape: tuple[int, ...] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    x = array("x_px", x_px)
    y = array("y_px", y_px)
    flux = array("flux_ph_s", flux_ph_s, min_value=0.0)
    sigma = np.ones(()) if isinstance(sigma_px, PSFShape) else array("sigma_px", sigma_px, min_value=0.0, strict=True)
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
    ``Optics.psf_sigma_px``), or a ``PSFShape`` (``psf.from_optics(optics)``; then window_sigmas
    and normalize stay at their defaults: the shape has its own window). All four broadcast
    together (scalars = one source).
    out: optional C-contiguous float64/float32 (height, width) array the sources are *added*
    to (pre-fill it with a background); a new zero image otherwise.
    window_sigmas, normalize: see the module docstring (5 sigma, renormalised window).
    Cost grows with the number of sources and their window, not with the sensor size (except
    allocating ``out``).
    """
    width, height = size(width, height)
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
    width, height = size(width, height)
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
    width, height = size(width, height)
    xa = np.asarray(x_px)
    if xa.ndim != 2 or np.shape(y_px) != xa.shape:
        raise ValueError(
            f"x_px and y_px must be (T, S) arrays of the same shape; got shapes {np.shape(x_px)} and {np.shape(y_px)}"
        )
    n_t, n_s = xa.shape
    x, y, flux, sigma = _sources(x_px, y_px, flux_ph_s, sigma_px, shape=(n_t, n_s))
    bg = array("background_ph_s", background_ph_s, min_value=0.0)
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
        source added to the flat index (the frame of each source in ``render_frames``). The
        arrays returned are the caller's: ``simulate`` overwrites the indices in place, so a
        shape must not return arrays it keeps."""
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
        positive("sigma_px", self.sigma_px)
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


