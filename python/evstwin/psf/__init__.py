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
window keeps (``captured_fraction``). ``Optics.halo_fraction`` adds a wide Moffat halo of
scattered light to any shape (``CompositePSF``: the two rendered apart and summed).
"""


from __future__ import annotations

from ..optics import MAX_HALO_HALF_PX
from .halo import (
    HALO_SUBPIXEL,
    CompositePSF,
    from_optics,
    halo_psf,
    sharp_part,
    smooth_part,
    with_halo,
)
from .measured import (
    check_psf_image,
    image_psf,
    load_psf_image,
)
from .render import (
    MAX_WINDOW_HALF_PX,
    GaussianPSF,
    PixelValues,
    PSFShape,
    contributions,
    pixel_fractions,
    render_frames,
    render_points,
    render_window,
    window_half_width_px,
)
from .shapes import (
    DEFAULT_MAX_HALF_PX,
    DEFAULT_SUBPIXEL,
    DEFAULT_TAIL_FRACTION,
    MAX_KERNEL_HALF_PX,
    MOFFAT_DEFAULT_BETA,
    KernelPSF,
    airy_psf,
    defocus_psf,
    moffat_alpha_px,
    moffat_enclosed_energy,
    moffat_psf,
    pupil,
    taper,
    taper_width_px,
)

__all__ = [
    "PixelValues",
    "MAX_WINDOW_HALF_PX",
    "window_half_width_px",
    "pixel_fractions",
    "contributions",
    "render_points",
    "render_window",
    "render_frames",
    "PSFShape",
    "GaussianPSF",
    "DEFAULT_SUBPIXEL",
    "DEFAULT_TAIL_FRACTION",
    "DEFAULT_MAX_HALF_PX",
    "MAX_KERNEL_HALF_PX",
    "MAX_HALO_HALF_PX",
    "MOFFAT_DEFAULT_BETA",
    "KernelPSF",
    "CompositePSF",
    "HALO_SUBPIXEL",
    "halo_psf",
    "with_halo",
    "sharp_part",
    "smooth_part",
    "taper_width_px",
    "taper",
    "pupil",
    "airy_psf",
    "moffat_alpha_px",
    "moffat_enclosed_energy",
    "moffat_psf",
    "defocus_psf",
    "load_psf_image",
    "check_psf_image",
    "image_psf",
    "from_optics",
]
