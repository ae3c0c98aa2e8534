"""A measured PSF: an image (``.npy`` or FITS) resampled to the sensor's pixels and tabulated
at sub-pixel phases like the computed shapes."""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np
import numpy.typing as npt

from .._checks import in_range, non_negative
from .shapes import (
    DEFAULT_SUBPIXEL,
    KernelPSF,
    _blur,
    _default_half,
    _grid,
    _half_from,
    _subpixel,
)


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
    o = in_range("psf_file_oversampling", oversampling, 1e-3, 1e3)
    blur = non_negative("extra_blur_sigma_px", extra_blur_sigma_px)
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




@functools.lru_cache(maxsize=4)
def _image_from_file(path: str, stamp: int, oversampling: float, blur: float, subpixel: int,
                     half_width_px: int | None) -> KernelPSF:
    return image_psf(load_psf_image(path), oversampling, blur, subpixel, half_width_px)
