"""PSF shapes beyond the Gaussian: ``KernelPSF`` tabulated at sub-pixel phases from ``airy_psf``
(diffraction), ``moffat_psf`` (seeing) or ``defocus_psf`` (an out-of-focus pupil); measured
images are :mod:`evstwin.psf.measured`, the halo and ``from_optics`` :mod:`evstwin.psf.halo`
(the package docstring, ``evstwin.psf``)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import numpy.typing as npt

from .. import _core
from .._checks import finite, in_range, integer, non_negative
from .render import PSFShape, _scatter, pixel_fractions

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
            # ((1 - b) ((1 - a) T[q, p] + a T[q, p + 1]) + b ((1 - a) T[q + 1, p] + a T[q + 1, p + 1]))
            # times the flux, in one pass (the NumPy expression took seven, each with a
            # temporary of the whole chunk): the same operations in the same order, the same bits.
            return _core.bilinear_phase_mix(table, q, p, np.ascontiguousarray(a), np.ascontiguousarray(b),
                                            np.ascontiguousarray(flux[s], dtype=np.float64))

        return _scatter(width, height, x, y, flux, self.half_width_px, weights, offset)

    def dense_terms(self, shape: tuple[int, ...], x: float, y: float,
                    flux: float) -> tuple[slice, slice, list[np.ndarray], list[float]] | None:
        """The (rows, cols) slices of a (height, width) image a source at (x, y) covers, and the
        table slices and coefficients ``add_dense`` adds there, in its order (the phases with a
        non-zero bilinear weight); None if the window misses the image."""
        k, h, table = self.subpixel, self.half_width_px, self.table
        cx, cy = math.floor(x + 0.5), math.floor(y + 0.5)
        tx, ty = (x - cx + 0.5) * k, (y - cy + 0.5) * k
        p, q = min(max(math.floor(tx), 0), k - 1), min(max(math.floor(ty), 0), k - 1)
        a, b = tx - p, ty - q
        height, width = shape
        x0, y0 = cx - h, cy - h
        xs, ys, xe, ye = max(0, x0), max(0, y0), min(width, x0 + 2 * h + 1), min(height, y0 + 2 * h + 1)
        if xs >= xe or ys >= ye:
            return None
        rows, cols = slice(ys - y0, ye - y0), slice(xs - x0, xe - x0)
        terms, coef = [], []
        for (qq, pp), w in (((q, p), (1.0 - a) * (1.0 - b)), ((q, p + 1), a * (1.0 - b)),
                            ((q + 1, p), (1.0 - a) * b), ((q + 1, p + 1), a * b)):
            if w != 0.0:
                terms.append(table[qq, pp, rows, cols])
                coef.append(flux * w)
        return slice(ys, ye), slice(xs, xe), terms, coef

    def add_dense(self, image: np.ndarray, x: float, y: float, flux: float) -> None:
        """Add one source to a (height, width) image in place: the values ``contributions``
        gives (the same bilinear mix of phases, summed in another order), written as one
        slice of the image, which for a wide window (a halo's 1025 px) costs a third of the
        flat indices and bincount of the general path."""
        if not flux > 0.0:
            return
        window = self.dense_terms(image.shape, x, y, flux)
        if window is None:
            return
        rows, cols, terms, coef = window
        out = image[rows, cols]
        if (out.dtype == np.float64 and out.flags.aligned and out.strides[-1] == out.itemsize
                and out.strides[0] % out.itemsize == 0):
            # out += coef[0] terms[0], then coef[1] terms[1], ..., as one pass over the window
            # (NumPy's was two a term, with a window-sized temporary each): the same bits.
            _core.add_scaled_terms(out, terms, coef)
        else:
            for term, c in zip(terms, coef):
                out += c * term


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
    return integer("psf_half_width_px", half_width_px, 1, MAX_KERNEL_HALF_PX)


def _subpixel(value: int) -> int:
    return integer("psf_subpixel", value, 1, 32)


def _pupil_options(
    obstruction_ratio: float, spider_vanes: int, spider_width_ratio: float, spider_angle_deg: float,
    extra_blur_sigma_px: float, subpixel: int, max_vanes: int,
) -> tuple[float, int, float, float, float, int]:
    """The pupil and blur arguments ``airy_psf`` and ``defocus_psf`` share, each checked in turn
    (ValueError naming the first bad one): (obstruction_ratio, spider_vanes, spider_width_ratio,
    spider_angle_deg, extra_blur_sigma_px, subpixel)."""
    eps = in_range("obstruction_ratio", obstruction_ratio, 0.0, 1.0, hi_open=True)
    integer("spider_vanes", spider_vanes, 0, max_vanes)
    width = in_range("spider_width_ratio", spider_width_ratio, 0.0, 0.5, hi_open=True)
    angle_deg = finite("spider_angle_deg", spider_angle_deg)
    blur = non_negative("extra_blur_sigma_px", extra_blur_sigma_px)
    return eps, int(spider_vanes), width, angle_deg, blur, _subpixel(subpixel)


def _close_vanes(
    open_: np.ndarray, ux: np.ndarray, uy: np.ndarray, vanes: int, angle_rad: float, half_width: float
) -> None:
    """Close, in place, the shadows of ``vanes`` radial bars ``2 half_width`` wide (in the units
    of the coordinates ux, uy) from the centre out, the first at ``angle_rad`` from +x towards
    +y, the others equally spaced."""
    for v in range(vanes):
        th = angle_rad + 2.0 * math.pi * v / vanes
        c, s = math.cos(th), math.sin(th)
        along = ux * c + uy * s
        across = uy * c - ux * s
        open_ &= ~((along >= 0.0) & (np.abs(across) <= half_width))


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
    _close_vanes(open_, ux, uy, spider_vanes, math.radians(spider_angle_deg), 0.5 * spider_width_ratio)
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
    lam = finite("lambda_n_px", lambda_n_px)
    if not 0.02 <= lam <= 50.0:
        raise ValueError("airy PSF: mean_wavelength_m x f_number / pixel_pitch_m (lambda N) must be in [0.02, 50] px "
                         f"(under 0.02 px the pattern is far inside a pixel: use psf='gaussian'); got {lam:.4g} px")
    eps, vanes, w, angle, blur, k = _pupil_options(
        obstruction_ratio, spider_vanes, spider_width_ratio, spider_angle_deg, extra_blur_sigma_px, subpixel, 64
    )
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
    p = pupil(n_p, eps, vanes, w, angle)
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
    params = {"lambda_n_px": lam, "obstruction_ratio": eps, "spider_vanes": vanes,
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
    f = in_range("moffat_fwhm_px", fwhm_px, 0.05, 100.0)
    be = finite("moffat_beta", beta)
    if not 1.0 < be <= 1000.0:
        raise ValueError(f"moffat_beta must be > 1 (a finite flux) and <= 1000; got moffat_beta={beta!r}")
    blur = non_negative("extra_blur_sigma_px", extra_blur_sigma_px)
    k = _subpixel(subpixel)
    alpha = moffat_alpha_px(f, be)
    with np.errstate(over="ignore"):
        radius = alpha * math.sqrt(max(0.0, math.exp(math.log(DEFAULT_TAIL_FRACTION) / (1.0 - be)) - 1.0))
    h = _half_from("moffat", half_width_px, _default_half(radius, blur))
    return _moffat_kernel(f, be, blur, k, h)


def _moffat_kernel(f: float, be: float, blur: float, k: int, h: int) -> KernelPSF:
    """``moffat_psf``'s table, its arguments checked (h may exceed MAX_KERNEL_HALF_PX for a halo)."""
    alpha = moffat_alpha_px(f, be)
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


# -- defocus --------------------------------------------------------------------------------------


def defocus_psf(
    radius_px: float,
    obstruction_ratio: float = 0.0,
    spider_vanes: int = 0,
    spider_width_ratio: float = 0.01,
    spider_angle_deg: float = 0.0,
    extra_blur_sigma_px: float = 0.0,
    subpixel: int = 2,
    half_width_px: int | None = None,
) -> KernelPSF:
    """A source far out of focus: the geometric image of the pupil, a uniform disc of radius
    ``radius_px`` less the central obstruction's shadow (``obstruction_ratio`` of the radius)
    and the spider vanes' (``spider_width_ratio`` of the diameter wide, as ``pupil``), blurred
    by a Gaussian of ``extra_blur_sigma_px`` (seeing, the rest of the optics). Diffraction is
    left out: it matters only within lambda N of the edge. Lens ghosts (a reflection focused
    far from the sensor) and deliberately defocused photometry look like this.

    radius_px in [0.5, 120]; the default window's taper starts past radius + 5 sigma of the
    blur, h in [2, 128] px. ``subpixel`` defaults to 2: a disc pixels wide needs no finer
    phases (its pixel values change by ~(1/k)^2/8 of their curvature, only at the edge).
    """
    r = in_range("defocus_radius_px", radius_px, 0.5, 120.0)
    eps, vanes, width, angle_deg, blur, k = _pupil_options(
        obstruction_ratio, spider_vanes, spider_width_ratio, spider_angle_deg, extra_blur_sigma_px, subpixel, 16
    )
    h = _half_from("defocus", half_width_px, _default_half(r, blur))
    # Cells at least 8 across the smaller of the radius and the vanes' shadow (2 r width wide).
    finest = min(r, max(2.0 * r * width, 0.25) if vanes else r)
    m = max(1, math.ceil(8.0 / (k * finest)))
    m = max(1, min(m, _MAX_GRID_SIDE // (2 * k * (h + 1))))
    n = _grid("defocus", h, k, m)
    cell = 1.0 / (k * m)
    c = _cell_centres(n, cell)
    ux, uy = c[None, :], c[:, None]
    rr = np.hypot(ux, uy)
    open_ = (rr <= r) & (rr >= eps * r)
    _close_vanes(open_, ux, uy, vanes, math.radians(angle_deg), width * r)
    mass = open_.astype(np.float64)
    total = mass.sum()
    if not total > 0.0:
        raise ValueError(f"defocus PSF: nothing of the pupil is open (obstruction_ratio={obstruction_ratio!r}, "
                         f"spider_vanes={spider_vanes!r}, spider_width_ratio={spider_width_ratio!r})")
    mass /= total
    mass = _blur(mass, blur, cell)
    params = {"radius_px": r, "obstruction_ratio": eps, "spider_vanes": vanes,
              "spider_width_ratio": width, "extra_blur_sigma_px": blur}
    return KernelPSF(mass, k, m, h, "defocus", params)
