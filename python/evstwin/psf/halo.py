"""The scattered-light halo: a wide Moffat added to any core shape (``Optics.halo_fraction``),
the two rendered apart (:class:`CompositePSF`), and the PSF an ``Optics`` names
(:func:`from_optics`)."""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from ..optics import Optics, check_halo_shape
from .measured import _image_from_file
from .render import GaussianPSF, PSFShape
from .shapes import MOFFAT_DEFAULT_BETA, KernelPSF, _moffat_kernel, airy_psf, moffat_psf

HALO_SUBPIXEL = 2
"""Sub-pixel phases of a halo's table: a halo at least 2 px wide (``Optics.halo_fwhm_px``)
varies so slowly within a pixel that bilinear interpolation between half-pixel phases is off
by at most (1/2)^2 / 8 of its second derivative, 0.3 % of its peak at the narrowest (and the
table is 16 times smaller than at 8 phases)."""


class CompositePSF(PSFShape):
    """A core shape holding ``1 - halo_fraction`` of each source's flux plus a wide Moffat
    halo holding the rest (``Optics.halo_fraction``): the two are rendered apart and add up,
    each with its own window, so the halo's 2 h + 1 = 513 px window does not make the core's
    fine sub-pixel table 4x larger. Flux is conserved by each part, hence by the sum."""

    def __init__(self, core: PSFShape, halo: KernelPSF, halo_fraction: float) -> None:
        f = float(halo_fraction)
        if not 0.0 < f < 1.0:
            raise ValueError(f"halo_fraction must be in (0, 1); got halo_fraction={halo_fraction!r}")
        self.core = core
        self.halo = halo
        self.halo_fraction = f
        self.kind = f"{getattr(core, 'kind', 'gaussian')}+halo"
        self.half_width_px = max(core.half_width_px, halo.half_width_px)

    def __repr__(self) -> str:
        return f"CompositePSF(core={self.core!r}, halo={self.halo!r}, halo_fraction={self.halo_fraction:g})"

    @property
    def max_pixel_share(self) -> float:
        return (1.0 - self.halo_fraction) * self.core.max_pixel_share + self.halo_fraction * self.halo.max_pixel_share

    @functools.cached_property
    def core_part(self) -> PSFShape:
        """The core alone with its share of the flux (the parts add up to the whole; one
        object per composite, so that sources rendered with it group together)."""
        return ScaledPSF(self.core, 1.0 - self.halo_fraction)

    @functools.cached_property
    def halo_part(self) -> PSFShape:
        """The halo alone with its share of the flux."""
        return ScaledPSF(self.halo, self.halo_fraction, smooth=True)

    def contributions(
        self, width: int, height: int, x: np.ndarray, y: np.ndarray, flux: np.ndarray,
        offset: np.ndarray | None = None,
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        return (self.core_part.contributions(width, height, x, y, flux, offset)
                + self.halo_part.contributions(width, height, x, y, flux, offset))


class ScaledPSF(PSFShape):
    """``shape`` with every source's flux times ``factor`` (a ``CompositePSF``'s part).
    ``smooth``: a halo, which a moving source changes slowly enough to sample at the base
    rate (``smooth_part``)."""

    def __init__(self, shape: PSFShape, factor: float, smooth: bool = False) -> None:
        self.shape = shape
        self.factor = float(factor)
        self.smooth = bool(smooth)
        self.half_width_px = shape.half_width_px

    def __repr__(self) -> str:
        return f"ScaledPSF({self.shape!r}, {self.factor:g})"

    @property
    def max_pixel_share(self) -> float:
        return self.factor * self.shape.max_pixel_share

    def contributions(
        self, width: int, height: int, x: np.ndarray, y: np.ndarray, flux: np.ndarray,
        offset: np.ndarray | None = None,
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        return self.shape.contributions(width, height, x, y, flux * self.factor, offset)

    def add_dense(self, image: np.ndarray, x: float, y: float, flux: float) -> None:
        """``KernelPSF.add_dense`` of the scaled shape (a halo's part)."""
        self.shape.add_dense(image, x, y, flux * self.factor)  # type: ignore[attr-defined]


def sharp_part(shape: PSFShape) -> PSFShape | None:
    """What of a shape a fast source must be sampled finely for: a composite's core, nothing
    of a halo alone, the whole of any other shape."""
    if isinstance(shape, CompositePSF):
        return shape.core_part
    return None if getattr(shape, "smooth", False) else shape


def smooth_part(shape: PSFShape) -> PSFShape | None:
    """What of a shape changes slowly wherever a source moves: a composite's halo, a halo
    alone, nothing of any other shape (``simulate`` samples it at the base rate)."""
    if isinstance(shape, CompositePSF):
        return shape.halo_part
    return shape if getattr(shape, "smooth", False) else None


@functools.lru_cache(maxsize=4)
def halo_psf(fwhm_px: float, beta: float, half_width_px: int) -> KernelPSF:
    """The halo of ``CompositePSF``: a Moffat of this FWHM [px] and beta, tabulated at
    ``HALO_SUBPIXEL`` phases on a (2 h + 1)^2 window (``moffat_psf``; its taper and
    ``captured_fraction`` apply). Cached."""
    check_halo_shape(fwhm_px, beta, half_width_px)
    shape = _moffat_kernel(float(fwhm_px), float(beta), 0.0, HALO_SUBPIXEL, int(half_width_px))
    shape.kind = "halo"
    return shape


def with_halo(core: PSFShape, optics: Optics) -> PSFShape:
    """``core`` as it is without a halo (``optics.halo_fraction == 0``), else a
    ``CompositePSF`` of it and the optics' halo."""
    if optics.halo_fraction == 0.0:
        return core
    return _composite(core, float(optics.halo_fwhm_px), float(optics.halo_beta),  # type: ignore[arg-type]
                      int(optics.halo_half_width_px), float(optics.halo_fraction))


@functools.lru_cache(maxsize=8)
def _composite(core: PSFShape, fwhm_px: float, beta: float, half_width_px: int, fraction: float) -> CompositePSF:
    # One object per core and halo: a scene's targets rendered with it, or with its parts,
    # are grouped by identity (targets.psf_groups).
    return CompositePSF(core, halo_psf(fwhm_px, beta, half_width_px), fraction)


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
        core = _image_from_file(str(p), stamp, float(optics.psf_file_oversampling),  # type: ignore[arg-type]
                                float(optics.extra_blur_sigma_px), optics.psf_subpixel, optics.psf_half_width_px)
        return with_halo(core, optics)
    return with_halo(_from_optics(optics), optics)


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
