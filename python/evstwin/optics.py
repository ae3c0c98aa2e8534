"""Optics and photometry: from a star's magnitude (or a lab source) to photons/s on the sensor.

The output of this module is what the PSF (``evstwin.psf``) spreads over the pixels: the photon
flux of a point source at the focal plane [photons/s], its position in pixel coordinates and
the width of its image [px].

Conventions
-----------
* Pixel coordinates: pixel centres at integers, pixel ``(i, j)`` (row ``i``, column ``j``)
  covers ``x`` in ``[j - 0.5, j + 0.5]`` and ``y`` in ``[i - 0.5, i + 0.5]``; ``x`` grows to
  the right (columns), ``y`` downwards (rows). The principal point is the sensor centre,
  ``((width - 1) / 2, (height - 1) / 2)``.
* Camera frame for finite-distance sources: ``z`` along the optical axis (away from the
  camera), ``x`` along the pixel ``x`` axis, ``y`` along the pixel ``y`` axis, in metres.
* Fluxes here are photons/s *arriving at the focal plane*; the sensor engine applies the
  pixel fill factor and the photodiode quantum efficiency (paper eq. 1-2) itself.

Photometric zero point
----------------------
A V = 0 star gives ``ZERO_POINT_V_PH_S_M2`` = 8.79e9 photons/s/m^2 inside the Johnson V
band: f_nu = 3640 Jy (Bessell 1979, PASP 91, 589; 3636 Jy in Bessell, Castelli & Plez 1998,
A&A 333, 231, Table A2) over d(lambda)/lambda = 0.16, i.e. N = f_nu / h * 0.16 photons per
second per m^2 (the tabulation of J. Huchra's "Magnitudes" notes, Harvard CfA Ay145).
An unfiltered silicon sensor sees more than the V band: for an A0V (colour 0) star
``broadband_zero_point_ph_s_m2(0.4e-6, 1.0e-6)`` gives about 4.4e10 photons/s/m^2 (5x, 1.7 mag
brighter), but the real figure depends on the star's spectrum and on the sensor's QE curve,
which the engine treats as flat. Pick the zero point that matches how your magnitudes were
measured: it is a field of ``Optics``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from ._checks import array, finite, in_range, integer, non_negative, positive
from .constants import ARCSEC_PER_RAD, JANSKY_W_M2_HZ, PLANCK_J_S

V_BAND_ZERO_FLUX_JY = 3640.0
"""Spectral flux density f_nu of a V = 0 star [Jy]. Bessell (1979); 3636 Jy in Bessell,
Castelli & Plez (1998) Table A2 (the 0.1 % difference is far below any other uncertainty)."""
V_BAND_FRACTIONAL_WIDTH = 0.16
"""Johnson V band width d(lambda)/lambda (0.088 um at 0.55 um), as tabulated with the
zero point above."""
ZERO_POINT_V_PH_S_M2 = V_BAND_ZERO_FLUX_JY * JANSKY_W_M2_HZ / PLANCK_J_S * V_BAND_FRACTIONAL_WIDTH
"""Photons/s/m^2 from a V = 0 star inside the V band: f_nu / h * d(lambda)/lambda = 8.79e9."""

# f_nu of a zero-magnitude (A0V, all colours 0) star at the band centres [um, Jy]:
# U B V R I from Bessell (1979), J H K from Campins, Rieke & Lebofsky (1985), as tabulated in
# Huchra's Ay145 notes. Used only by broadband_zero_point_ph_s_m2 for a broadband estimate.
_A0V_LAMBDA_M = np.array([0.36, 0.44, 0.55, 0.64, 0.79, 1.26, 1.60, 2.22]) * 1e-6
_A0V_FNU_JY = np.array([1810.0, 4260.0, 3640.0, 3080.0, 2550.0, 1600.0, 1080.0, 670.0])

DAVIS346_MEAN_WAVELENGTH_M = 0.7e-6
"""Mean wavelength Lambda of the DAVIS346 sensitivity range [m] used in the PSF width
(paper eq. 17). Assumption: the middle of the ~0.4-1.0 um response of a front-illuminated
silicon photodiode; iniVation does not give a spectral curve in the sources at hand."""
DAVIS346_PIXEL_PITCH_M = 18.5e-6
"""DAVIS346 pixel pitch [m] (paper sec. 3.1)."""
DARK_SKY_V_MAG_PER_ARCSEC2 = 21.9
"""Zenith V-band brightness of a dark moonless site [mag/arcsec^2] (La Palma, Benn & Ellison
1998, 21.9 V). Suburban skies are 19-20; the full Moon brightens V by ~3 mag."""

ArrayLike = npt.ArrayLike
FloatOrArray = float | np.ndarray


# ---------------------------------------------------------------------------------------------
_PHYSICAL_RANGES = {
    "focal_length_m": (1e-5, 1e4),
    "f_number": (1e-2, 1e5),
    "pixel_pitch_m": (1e-8, 1e-1),
    "mean_wavelength_m": (1e-10, 1e-1),
    "aperture_diameter_m": (1e-7, 1e4),
    "zero_point_ph_s_m2": (1e-20, 1e40),
}
"""Bounds on the optics' lengths [m] and zero point, far outside any real camera or telescope
(the focal length from 10 um to 10 km): within them the plate scale, PSF, fluxes and the sky
background stay finite (a focal length of 1e-300 m overflowed them; found by fuzzing)."""

def _scalar_or_array(a: np.ndarray) -> FloatOrArray:
    return float(a) if a.ndim == 0 else a


# ---------------------------------------------------------------------------------------------
# photometry without optics


def broadband_zero_point_ph_s_m2(lambda_min_m: float, lambda_max_m: float) -> float:
    """Photons/s/m^2 from a zero-magnitude A0V star (all colours 0) between two wavelengths.

    Integrates N = integral f_nu / (h lambda) d(lambda), with f_nu interpolated linearly
    between the U..K band centres (0.36-2.22 um; Bessell 1979, Campins et al. 1985). A coarse
    estimate for unfiltered sensors: e.g. 0.4-1.0 um gives ~4.4e10, against 8.79e9 in V.
    """
    lo = positive("lambda_min_m", lambda_min_m)
    hi = positive("lambda_max_m", lambda_max_m)
    if not lo < hi:
        raise ValueError(f"need lambda_min_m < lambda_max_m; got {lo:g} and {hi:g}")
    if lo < _A0V_LAMBDA_M[0] or hi > _A0V_LAMBDA_M[-1]:
        raise ValueError(
            f"wavelengths must lie in [{_A0V_LAMBDA_M[0]:g}, {_A0V_LAMBDA_M[-1]:g}] m; "
            f"got lambda_min_m={lo:g}, lambda_max_m={hi:g}"
        )
    lam = np.linspace(lo, hi, 4001)
    integrand = np.interp(lam, _A0V_LAMBDA_M, _A0V_FNU_JY) * JANSKY_W_M2_HZ / (PLANCK_J_S * lam)
    return float(np.sum(0.5 * (integrand[1:] + integrand[:-1]) * np.diff(lam)))


# ---------------------------------------------------------------------------------------------

PAPER_FOCAL_LENGTH_M = 0.041
"""The paper's lab lens (sec. 3.1): 41 mm (Fujinon 7-70 mm zoom) [m]; :class:`Optics`'s default,
and a scenario's when [optics] gives no focal_length_m."""
PAPER_F_NUMBER = 1.8
"""The paper's lab lens's focal ratio (sec. 3.1): f/1.8; :class:`Optics`'s default, and a
scenario's when [optics] gives no f_number."""


MAX_HALO_HALF_PX = 512
"""Largest half width of a halo's window [px] (1025 px a side: a table of 9 phases, 76 MB)."""


def check_halo_shape(fwhm_px: float | None, beta: float, half_width_px: int) -> None:
    """The ranges of a halo's shape (``Optics.halo_*``; ``psf.halo_psf``): FWHM in [2, 200] px
    (None: not given), beta in (1, 10], an integer half width in [8, MAX_HALO_HALF_PX]."""
    if fwhm_px is not None:
        in_range("halo_fwhm_px", fwhm_px, 2.0, 200.0)
    in_range("halo_beta", beta, 1.0, 10.0, lo_open=True, note="(a finite flux)")
    integer("halo_half_width_px", half_width_px, 8, MAX_HALO_HALF_PX)


@dataclass(frozen=True)
class Optics:
    """A lens or telescope in front of a sensor: PSF width, plate scale, photometry, projection.

    Defaults: the paper's lab setup (sec. 3.1), a 41 mm f/1.8 lens on a DAVIS346.
    """

    focal_length_m: float = PAPER_FOCAL_LENGTH_M
    """Focal length f [m]. Paper sec. 3.1: 41 mm (Fujinon 7-70 mm zoom)."""
    f_number: float = PAPER_F_NUMBER
    """Focal ratio N (sets the diffraction PSF, eq. 17). Paper: f/1.8."""
    pixel_pitch_m: float = DAVIS346_PIXEL_PITCH_M
    """Pixel pitch [m]. DAVIS346: 18.5 um."""
    mean_wavelength_m: float = DAVIS346_MEAN_WAVELENGTH_M
    """Mean wavelength Lambda of the sensitivity range [m] (eq. 17); 0.7 um, an assumption."""
    extra_blur_sigma_px: float = 0.0
    """Extra Gaussian blur [px] added in quadrature (defocus, seeing, aberrations, jitter).
    The diffraction sigma alone is 0.03 px for the paper's setup: real images are wider."""
    transmission: float = 1.0
    """Optics throughput in [0, 1] (lens/mirror losses, filters). Not the photodiode's
    transmission coefficient tau of eq. 2 (Table 3: 0.68), which the engine applies."""
    aperture_diameter_m: float | None = None
    """Entrance pupil diameter D [m]; None = focal_length_m / f_number. Used for the
    collecting area only (the PSF uses f_number)."""
    obstruction_ratio: float = 0.0
    """Central obstruction as a fraction of D (telescope secondary mirror), in [0, 1)."""
    focus_distance_m: float = math.inf
    """Distance the lens is focused on [m]; inf for the sky. Sets the lens-sensor distance
    (thin lens), hence the scale of finite-distance scenes and the defocus of other depths."""
    width_px: int = 346
    """Sensor width [px] (principal point and field of view). DAVIS346: 346."""
    height_px: int = 260
    """Sensor height [px]. DAVIS346: 260."""
    zero_point_ph_s_m2: float = ZERO_POINT_V_PH_S_M2
    """Photons/s/m^2 from a magnitude-0 star (default: V band, 8.79e9; see module doc)."""
    psf: str = "gaussian"
    """PSF shape (``evstwin.psf``): ``gaussian`` (paper eq. 17, sigma ``psf_sigma_px``),
    ``airy`` (diffraction by the pupil: obstruction and spider vanes, plus the extra blur),
    ``moffat`` (a seeing halo: ``moffat_fwhm_px`` or ``moffat_fwhm_arcsec``, ``moffat_beta``)
    or ``image`` (``psf_file`` sampled ``psf_file_oversampling`` times per sensor pixel)."""
    spider_vanes: int = 0
    """Number of spider vanes holding the secondary mirror (``airy`` only), 0..64: radial bars
    from the centre out, equally spaced; each diffracts a spike perpendicular to itself."""
    spider_width_ratio: float = 0.01
    """Width of each vane as a fraction of D, in [0, 0.5) (``airy``, with spider_vanes > 0)."""
    spider_angle_deg: float = 0.0
    """Direction of the first vane [deg] from the pixel +x axis towards +y (``airy``)."""
    moffat_beta: float | None = None
    """Moffat exponent beta > 1 (``moffat``); None = 4.765 (Trujillo et al. 2001, MNRAS 328,
    977: the Moffat fit to Kolmogorov seeing; fits to real stars often give 2.5-4.5)."""
    moffat_fwhm_px: float | None = None
    """Moffat FWHM [px], in [0.05, 100] (``moffat``; or moffat_fwhm_arcsec, not both)."""
    moffat_fwhm_arcsec: float | None = None
    """Moffat FWHM [arcsec], converted with the plate scale (``moffat``; seeing)."""
    psf_file: str | None = None
    """Path of a 2-D PSF image (``image``): ``.npy``, or ``.fits``/``.fit`` with astropy."""
    psf_file_oversampling: float | None = None
    """Image pixels per sensor pixel along each axis (``image``; 4 = pixels a quarter wide)."""
    psf_subpixel: int = 8
    """Sub-pixel phases per pixel of a tabulated (non-Gaussian) PSF, 1..32; positions in
    between are interpolated bilinearly (``evstwin.psf``, "Tabulated shapes")."""
    psf_half_width_px: int | None = None
    """Half width of a tabulated PSF's window [px] (2 h + 1 a side), 1..256; None = the radius
    holding 99 % of the flux (Airy, Moffat) or the image's extent, in [2, 128]."""
    halo_fraction: float = 0.0
    """Share of every source's flux scattered into a wide halo, in [0, 1): the rest keeps the
    ``psf`` shape. Light scattered by dust and micro-roughness on the optics, and a sensor
    window's reflections, spreads a point source's light over hundreds of pixels as a power
    law (an aureole); an event camera turns a faint halo into events wherever it moves across
    pixels near the dark-current level. 0 (the default) = no halo."""
    halo_fwhm_px: float | None = None
    """FWHM [px] of the halo, a Moffat profile, in [2, 200] (needed when halo_fraction > 0)."""
    halo_beta: float = 1.5
    """Moffat exponent of the halo, in (1, 10]: far from its core the halo falls as
    r^(-2 beta) (1.5: r^-3, the usual slope of scattered light in telescopes)."""
    halo_half_width_px: int = 256
    """Half width of the halo's window [px], 8..512 (the cost of rendering a source grows with
    its square; ``python bench/bench_psf.py``)."""

    def __post_init__(self) -> None:
        f = positive("focal_length_m", self.focal_length_m)
        positive("f_number", self.f_number)
        positive("pixel_pitch_m", self.pixel_pitch_m)
        positive("mean_wavelength_m", self.mean_wavelength_m)
        non_negative("extra_blur_sigma_px", self.extra_blur_sigma_px)
        in_range("transmission", self.transmission, 0.0, 1.0, lo_open=True)
        in_range("obstruction_ratio", self.obstruction_ratio, 0.0, 1.0, hi_open=True)
        s = float(self.focus_distance_m)
        if math.isnan(s) or s <= f:
            raise ValueError(
                f"focus_distance_m must exceed focal_length_m={f:g} (or be inf); got focus_distance_m={self.focus_distance_m!r}"
            )
        for name in ("width_px", "height_px"):
            integer(name, getattr(self, name), 1)
        positive("zero_point_ph_s_m2", self.zero_point_ph_s_m2)
        self._check_psf_fields()
        if self.aperture_diameter_m is None:
            object.__setattr__(self, "aperture_diameter_m", f / float(self.f_number))
        else:
            positive("aperture_diameter_m", self.aperture_diameter_m)
        for name, (lo, hi) in _PHYSICAL_RANGES.items():
            v = float(getattr(self, name))
            if not lo <= v <= hi:
                raise ValueError(f"{name} must be in [{lo:g}, {hi:g}] (a physical range: beyond it the image "
                                 f"computations overflow); got {name}={getattr(self, name)!r}")

    def _check_psf_fields(self) -> None:
        """The PSF shape's fields: each in its range, and only the chosen shape's set."""
        kinds = ("gaussian", "airy", "moffat", "image")
        if not isinstance(self.psf, str) or self.psf not in kinds:
            raise ValueError(f"psf must be one of {', '.join(kinds)}; got psf={self.psf!r}")
        for name, lo, hi in (("spider_vanes", 0, 64), ("psf_subpixel", 1, 32), ("psf_half_width_px", 1, 256)):
            v = getattr(self, name)
            if v is None and name == "psf_half_width_px":
                continue
            integer(name, v, lo, hi)
        in_range("spider_width_ratio", self.spider_width_ratio, 0.0, 0.5, hi_open=True)
        finite("spider_angle_deg", self.spider_angle_deg)
        if self.moffat_beta is not None:
            b = finite("moffat_beta", self.moffat_beta)
            if not 1.0 < b <= 1000.0:
                raise ValueError(f"moffat_beta must be > 1 (a finite flux) and <= 1000; got moffat_beta={self.moffat_beta!r}")
        if self.moffat_fwhm_px is not None:
            in_range("moffat_fwhm_px", self.moffat_fwhm_px, 0.05, 100.0)
        if self.moffat_fwhm_arcsec is not None:
            positive("moffat_fwhm_arcsec", self.moffat_fwhm_arcsec)
        if self.psf_file is not None and (not isinstance(self.psf_file, str) or not self.psf_file):
            raise ValueError(f"psf_file must be a non-empty path string; got psf_file={self.psf_file!r}")
        if self.psf_file_oversampling is not None:
            o = finite("psf_file_oversampling", self.psf_file_oversampling)
            if not 1e-3 <= o <= 1e3:
                raise ValueError("psf_file_oversampling (image pixels per sensor pixel) must be in [0.001, 1000]; "
                                 f"got psf_file_oversampling={self.psf_file_oversampling!r}")
        own = {"moffat": ("moffat_beta", "moffat_fwhm_px", "moffat_fwhm_arcsec"),
               "image": ("psf_file", "psf_file_oversampling")}
        for kind, names in own.items():
            for name in names:
                if self.psf != kind and getattr(self, name) is not None:
                    raise ValueError(f"{name} applies to psf={kind!r}; got {name}={getattr(self, name)!r} with "
                                     f"psf={self.psf!r}")
        if self.psf == "moffat" and (self.moffat_fwhm_px is None) == (self.moffat_fwhm_arcsec is None):
            raise ValueError("psf='moffat' needs one of moffat_fwhm_px or moffat_fwhm_arcsec; got "
                             f"moffat_fwhm_px={self.moffat_fwhm_px!r}, moffat_fwhm_arcsec={self.moffat_fwhm_arcsec!r}")
        hf = in_range("halo_fraction", self.halo_fraction, 0.0, 1.0, hi_open=True)
        check_halo_shape(self.halo_fwhm_px, self.halo_beta, self.halo_half_width_px)
        if (hf > 0.0) != (self.halo_fwhm_px is not None):
            raise ValueError("halo_fraction > 0 and halo_fwhm_px go together (a halo needs its width, a width its "
                             f"share); got halo_fraction={self.halo_fraction!r}, halo_fwhm_px={self.halo_fwhm_px!r}")
        if self.psf == "image" and (self.psf_file is None or self.psf_file_oversampling is None):
            raise ValueError("psf='image' needs psf_file and psf_file_oversampling (image pixels per sensor pixel); "
                             f"got psf_file={self.psf_file!r}, psf_file_oversampling={self.psf_file_oversampling!r}")

    def replace(self, **changes: Any) -> Optics:
        """A copy with some fields changed. A derived aperture is derived again unless given."""
        derived = math.isclose(float(self.aperture_diameter_m), self.focal_length_m / self.f_number)  # type: ignore[arg-type]
        lens_changed = "focal_length_m" in changes or "f_number" in changes
        if derived and lens_changed and "aperture_diameter_m" not in changes:
            changes["aperture_diameter_m"] = None
        return dataclasses.replace(self, **changes)

    # -- geometry -----------------------------------------------------------------------------

    @property
    def image_distance_m(self) -> float:
        """Lens-to-sensor distance v [m]: f when focused at infinity, else f s / (s - f)."""
        s = self.focus_distance_m
        f = self.focal_length_m
        return f if math.isinf(s) else f * s / (s - f)

    @property
    def plate_scale_rad_per_px(self) -> float:
        """Angle subtended by one pixel [rad/px]: pitch / v (pitch / f for the sky)."""
        return self.pixel_pitch_m / self.image_distance_m

    @property
    def plate_scale_arcsec_per_px(self) -> float:
        """Plate scale [arcsec/px]."""
        return self.plate_scale_rad_per_px * ARCSEC_PER_RAD

    @property
    def field_of_view_rad(self) -> tuple[float, float]:
        """Full field of view (horizontal, vertical) [rad] of the width_px x height_px sensor."""
        v = self.image_distance_m
        return (
            2.0 * math.atan(0.5 * self.width_px * self.pixel_pitch_m / v),
            2.0 * math.atan(0.5 * self.height_px * self.pixel_pitch_m / v),
        )

    @property
    def principal_point_px(self) -> tuple[float, float]:
        """Where the optical axis meets the sensor (x, y) [px]: the sensor centre."""
        return (0.5 * (self.width_px - 1), 0.5 * (self.height_px - 1))

    def project_to_px(
        self, x_m: ArrayLike, y_m: ArrayLike, z_m: ArrayLike
    ) -> tuple[FloatOrArray, FloatOrArray]:
        """Pinhole projection of camera-frame points [m] to pixel coordinates [px].

        ``x_px = cx + v / pitch * x / z`` (and likewise y), with v the lens-sensor distance
        (``image_distance_m``) and (cx, cy) the sensor centre. z must be > 0 (in front).
        A point at a depth other than ``focus_distance_m`` is blurred: see ``defocus_sigma_px``.
        """
        x = array("x_m", x_m)
        y = array("y_m", y_m)
        z = array("z_m", z_m, min_value=0.0, strict=True)
        k = self.image_distance_m / self.pixel_pitch_m
        cx, cy = self.principal_point_px
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
            px, py = cx + k * x / z, cy + k * y / z
        _finite_image("x_m, y_m, z_m", px, py)
        return _scalar_or_array(px), _scalar_or_array(py)

    def length_to_px(self, length_m: ArrayLike, distance_m: ArrayLike) -> FloatOrArray:
        """Image size [px] of a length [m] seen face-on at a distance [m] (e.g. a radius)."""
        length = array("length_m", length_m)
        d = array("distance_m", distance_m, min_value=0.0, strict=True)
        with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
            size = length * self.image_distance_m / (d * self.pixel_pitch_m)
        _finite_image("length_m / distance_m", size)
        return _scalar_or_array(size)

    # -- PSF ----------------------------------------------------------------------------------

    @property
    def diffraction_sigma_px(self) -> float:
        """Gaussian sigma of the diffraction PSF [px]: 0.45 Lambda N / pitch (paper eq. 17)."""
        return 0.45 * self.mean_wavelength_m * self.f_number / self.pixel_pitch_m

    @property
    def psf_sigma_px(self) -> float:
        """PSF sigma [px]: sqrt(diffraction_sigma_px^2 + extra_blur_sigma_px^2)."""
        return math.hypot(self.diffraction_sigma_px, self.extra_blur_sigma_px)

    @property
    def moffat_fwhm(self) -> float:
        """The Moffat FWHM [px] (from moffat_fwhm_arcsec through the plate scale if given)."""
        if self.moffat_fwhm_px is not None:
            return float(self.moffat_fwhm_px)
        if self.moffat_fwhm_arcsec is None:
            raise ValueError(f"psf={self.psf!r} has no Moffat FWHM")
        fwhm = float(self.moffat_fwhm_arcsec) / self.plate_scale_arcsec_per_px
        if not 0.05 <= fwhm <= 100.0:
            raise ValueError(f"moffat_fwhm_arcsec={self.moffat_fwhm_arcsec!r} is {fwhm:.3g} px at "
                             f"{self.plate_scale_arcsec_per_px:.3g} arcsec/px; it must be in [0.05, 100] px")
        return fwhm

    def defocus_sigma_px(self, object_distance_m: ArrayLike) -> FloatOrArray:
        """Geometric defocus blur of a point at this distance [m], as a Gaussian sigma [px].

        Thin lens: the point focuses at v_o = f d / (d - f) while the sensor sits at v; the
        blur circle on the sensor has diameter c = D |v_o - v| / v_o, and a uniform disc of
        diameter c has a per-axis sigma of c / 4. Add it in quadrature to the PSF through
        ``extra_blur_sigma_px`` if it matters (0 at the focus distance).
        """
        d = array("object_distance_m", object_distance_m)
        f = self.focal_length_m
        if np.any(d <= f):
            raise ValueError(f"object_distance_m must exceed focal_length_m={f:g}; got {object_distance_m!r}")
        with np.errstate(divide="ignore", invalid="ignore"):
            v_o = np.where(np.isinf(d), f, f * d / (d - f))
        c = float(self.aperture_diameter_m) * np.abs(v_o - self.image_distance_m) / v_o  # type: ignore[arg-type]
        return _scalar_or_array(c / 4.0 / self.pixel_pitch_m)

    # -- photometry ---------------------------------------------------------------------------

    @property
    def collecting_area_m2(self) -> float:
        """Entrance pupil area [m^2]: pi D^2 / 4 (1 - obstruction_ratio^2)."""
        d = float(self.aperture_diameter_m)  # type: ignore[arg-type]
        return math.pi * d * d / 4.0 * (1.0 - self.obstruction_ratio**2)

    @property
    def _throughput_m2(self) -> float:
        return self.collecting_area_m2 * self.transmission

    def flux_from_magnitude(self, mag: ArrayLike) -> FloatOrArray:
        """Photons/s at the focal plane from a star of this magnitude (array-able).

        ``zero_point_ph_s_m2 * 10**(-0.4 mag) * collecting_area_m2 * transmission``; no
        atmosphere (space-based, or fold the extinction into ``mag``).
        """
        m = array("mag", mag)
        return _scalar_or_array(self.zero_point_ph_s_m2 * 10.0 ** (-0.4 * m) * self._throughput_m2)

    def magnitude_from_flux(self, flux_ph_s: ArrayLike) -> FloatOrArray:
        """The inverse of ``flux_from_magnitude``: magnitude of a source giving this flux [ph/s]."""
        flux = array("flux_ph_s", flux_ph_s, min_value=0.0, strict=True)
        return _scalar_or_array(-2.5 * np.log10(flux / (self.zero_point_ph_s_m2 * self._throughput_m2)))

    def flux_from_intensity(self, intensity_ph_s_sr: ArrayLike, distance_m: ArrayLike) -> FloatOrArray:
        """Photons/s at the focal plane from a small source at a finite distance (a lab LED).

        ``I * A / d^2 * transmission``: radiant intensity I [photons/s/sr] times the solid angle
        of the entrance pupil seen from the source (valid for D << d: 22.8 mm at 63 cm).
        """
        i = array("intensity_ph_s_sr", intensity_ph_s_sr, min_value=0.0)
        d = array("distance_m", distance_m, min_value=0.0, strict=True)
        return _scalar_or_array(i * self._throughput_m2 / (d * d))

    def background_ph_s_per_px(
        self, sky_mag_per_arcsec2: ArrayLike = DARK_SKY_V_MAG_PER_ARCSEC2
    ) -> FloatOrArray:
        """Uniform sky background [photons/s per pixel] from a surface brightness [mag/arcsec^2].

        ``zero_point * 10**(-0.4 mu) * (plate scale in arcsec)^2 * area * transmission``.
        Default 21.9 mag/arcsec^2, a dark site in V (Benn & Ellison 1998). For a lab or a
        measured background give the photons/s per pixel directly to the renderer instead.
        """
        mu = array("sky_mag_per_arcsec2", sky_mag_per_arcsec2)
        pixel_arcsec2 = self.plate_scale_arcsec_per_px**2
        return _scalar_or_array(
            self.zero_point_ph_s_m2 * 10.0 ** (-0.4 * mu) * pixel_arcsec2 * self._throughput_m2
        )

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def _finite_image(names: str, *values: np.ndarray) -> None:
    """Refuse image coordinates that overflowed (a distance of 1e-320 m, a size of 1e300 m)."""
    for v in values:
        if not np.all(np.isfinite(v)):
            raise ValueError(f"{names} give image coordinates that overflow a 64-bit float (not finite px): "
                             "a distance too small or a length too large")
