"""The atmosphere between the sky and the telescope: seeing, image motion and scintillation.

Three effects, each optional, each seeded and deterministic (the random numbers are drawn once,
when the scene is built, from ``numpy.random.default_rng(SeedSequence([seed, purpose, ...]))``:
the events do not depend on the thread count or on how the run is cut into chunks).

Seeing (the PSF)
----------------
A star seen through turbulence is a Moffat profile (Moffat 1969, A&A 3, 455)
``I(r) ~ (1 + r^2 / alpha^2)^(-beta)`` whose FWHM is the site's seeing. In pixels,

    FWHM_px = seeing_fwhm_arcsec / plate_scale_arcsec_per_px    (``Optics.plate_scale_arcsec_per_px``)

with ``beta = 4.765`` by default, the Moffat fitted to the long-exposure PSF of Kolmogorov
turbulence (Trujillo et al. 2001, MNRAS 328, 977; real stars often fit 2.5-4.5 because of
the telescope's own wings). The atmosphere's PSF is then *convolved* with the optics' own PSF,
as the two act in series (the image of a point is the telescope's PSF of every point of the
seeing disc):

* ``Optics.psf = "gaussian"`` (default): the Moffat convolved with the Gaussian of sigma
  ``Optics.psf_sigma_px`` = hypot(diffraction sigma of paper eq. 17, ``extra_blur_sigma_px``);
* ``"airy"`` or ``"image"``: the optics' tabulated PSF (its 1/k-px cells) convolved cell by
  cell with the Moffat integrated over the same cells (:func:`seeing_psf`);
* ``"moffat"``: refused (the optics would already be a seeing PSF: give the seeing once).

The result is a :class:`evstwin.psf.KernelPSF` (flux conserved: each sub-pixel phase's window
sums to 1; ``captured_fraction`` is what the tapered window keeps before that).

Image motion (tip-tilt jitter)
------------------------------
The whole field moves together (the tilt of the wavefront over the aperture, wind shake of
the mount): every source's position gets the same offset ``(dx(t), dy(t))``. Each axis is an
Ornstein-Uhlenbeck process (a stationary Gauss-Markov process) with standard deviation
``rms_arcsec`` per axis and autocorrelation ``exp(-|lag| / tau_s)`` (its correlation time,
the integral of the normalised autocorrelation, is ``tau_s``). It is drawn exactly on a grid
of step ``tau_s / 16`` (``x[k+1] = rho x[k] + sqrt(1 - rho^2) sigma eps``, rho = exp(-1/16),
x[0] from the stationary law) and interpolated linearly in between, so the positions the
renderer sees are continuous and their speed is bounded (the sampling follows it: a jittering
source is a moving target). The linear interpolation lowers the variance between grid points
by at most (1 - rho) / 2 = 3 % (1 % averaged over time). An OU process has a Lorentzian
spectrum (falling as f^-2); real tip-tilt falls faster (f^-11/3 above ~0.3 v / D, Conan et al.
1995, JOSA A 12, 1559): this model has more high-frequency motion than the atmosphere, a
conservative choice for an event sensor, which responds to change. Typical figures: tip-tilt
of 0.2-0.5 arcsec rms per axis for 1 arcsec seeing on small telescopes; tau 10-100 ms.

Scintillation
-------------
The flux of every point source is multiplied by a log-normal, time-correlated factor
``m(t) = exp(s g(t) - s^2 / 2)`` (mean 1) where g is a unit-variance OU process with correlation
time ``tau_c``, drawn independently for each source (stars further apart than an isoplanatic
patch, a few arcsec, twinkle independently). Its strength comes from Young's (1967, AJ 72, 747)
long-exposure formula with the empirical correction of Osborn et al. (2015, MNRAS 452, 1707,
their eq. 7):

    sigma_Y^2(t) = 1e-5 C_Y^2 D^(-4/3) t^(-1) X^3 exp(-2 h_obs / H)

the variance of the relative flux averaged over an exposure of t seconds, for an aperture of
diameter D [m] at airmass X = sec(zenith distance), observatory altitude h_obs [m], turbulence
scale height H = 8000 m. C_Y = 1 is Young's original approximation; Osborn et al. show it
underestimates the median scintillation at the major observatories, whose median profiles give
C_Y of about 1.3-1.7: 1.5 is the default (the value their paper and later users adopt for a
typical site). The formula holds for t >> tau_c and D >> r_F, the Fresnel scale
sqrt(lambda h) ~ 7 cm for lambda = 0.55 um and turbulence at h = 10 km (Kenyon et al. 2006,
PASP 118, 924): below r_F the aperture no longer averages the speckle, and the variance stops
growing as D shrinks. We use ``D_eff = max(D, r_F)`` in the formula and in the correlation
time ``tau_c = D_eff / v_wind`` (the pattern, frozen, is blown across the aperture by the wind
at the altitude of the turbulence, 10-40 m/s; default 20 m/s; Dravins et al. 1997, PASP 109,
173 and 1998, PASP 110, 610 measured ms timescales on small apertures). ``tau_c`` can also
be given directly.

Matching the model to the formula: for t >> tau_c the variance of the mean of m over t is
``(2 / t) integral_0^inf cov(lag) d lag``, with ``cov(lag) = exp(s^2 exp(-lag / tau_c)) - 1``,
i.e. ``2 tau_c G(s^2) / t`` with ``G(x) = Ei(x) - gamma - ln x = sum_k x^k / (k k!)``. Setting it
equal to sigma_Y^2(t) (both fall as 1/t) fixes ``s^2`` by ``G(s^2) = sigma_Y^2(1 s) x 1 s / (2
tau_c)``; the instantaneous scintillation index (variance of m) is then ``exp(s^2) - 1``. The
process is drawn on a grid of step ``tau_c / 8`` and interpolated linearly (a source's
``LightCurve``). The event sensor has no exposure: it sees m(t) itself, so the simulation's
sample rate must resolve tau_c (``build`` asks for at least
:data:`MIN_SAMPLES_PER_SCINTILLATION_TAU` samples per tau_c).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from .._checks import finite, in_range, non_negative, positive
from ..optics import Optics
from ..psf import KernelPSF, PSFShape, from_optics, moffat_alpha_px, moffat_psf, with_halo
from ..psf.shapes import DEFAULT_TAIL_FRACTION, _default_half, _grid
from ..targets import DriftingTarget, LightCurve, MirroredTarget, PathTarget, Target, adopt
from ..targets.base import _interval, _times
from .photometry import airmass_kasten_young

KOLMOGOROV_MOFFAT_BETA = 4.765
"""Moffat beta of long-exposure Kolmogorov seeing (Trujillo et al. 2001, MNRAS 328, 977)."""
SCINTILLATION_SCALE_HEIGHT_M = 8000.0
"""Scale height H of the turbulence in Young's formula [m] (Young 1967; Osborn et al. 2015)."""
YOUNG_COEFFICIENT = 1e-5
"""Young's variance coefficient for D in m and t in s (Osborn et al. 2015, eq. 7)."""
OSBORN_C_Y = 1.5
"""Default empirical correction C_Y of Young's formula: a typical site's median (Osborn et al.
2015: Young's approximation, C_Y = 1, underestimates the median scintillation)."""
FRESNEL_SCALE_M = math.sqrt(0.55e-6 * 10_000.0)
"""Fresnel scale sqrt(lambda h) [m] for lambda = 0.55 um and turbulence at h = 10 km (7.4 cm):
the smallest aperture Young's D^(-4/3) law holds for (Kenyon et al. 2006)."""
DEFAULT_WIND_SPEED_M_S = 20.0
"""Wind speed at the altitude of the scintillating turbulence [m/s] (10-40 m/s at ~10 km)."""
JITTER_STEPS_PER_TAU = 16
"""Grid points per correlation time of the image-motion process."""
SCINTILLATION_STEPS_PER_TAU = 8
"""Grid points per correlation time of the scintillation process."""
MIN_SAMPLES_PER_SCINTILLATION_TAU = 2
"""The fewest simulation samples (sampling.rate_hz x tau_c) per correlation time of the
scintillation that a scene (and ``limiting-magnitude --scintillation``) accepts: the event
sensor sees m(t) itself, so a slower sampling would step over its fluctuations."""
MAX_PROCESS_SAMPLES = 50_000_000
"""Most grid values of the atmosphere's random processes in one scene (400 MB of float64):
the image motion's two axes plus every source's scintillation, over the run."""

_PURPOSE_JITTER = 1
_PURPOSE_SCINTILLATION = 2


# -- seeing -------------------------------------------------------------------------------------


def seeing_fwhm_px(seeing_fwhm_arcsec: float, optics: Optics) -> float:
    """The seeing FWHM in pixels: seeing [arcsec] / ``optics.plate_scale_arcsec_per_px``."""
    seeing = positive("seeing_fwhm_arcsec", seeing_fwhm_arcsec)
    return seeing / optics.plate_scale_arcsec_per_px


def seeing_psf(optics: Optics, seeing_fwhm_arcsec: float, beta: float = KOLMOGOROV_MOFFAT_BETA) -> PSFShape:
    """The PSF of a star seen through this seeing with these optics: a Moffat of FWHM
    ``seeing_fwhm_px`` and exponent ``beta`` convolved with the optics' own PSF (module
    docstring). Uses the optics' ``psf_subpixel`` and, for a Gaussian optics,
    ``psf_half_width_px``. Cached (the last 8 combinations). The seeing blurs the core: an
    optics' scattered-light halo (``halo_fraction``), far wider than any seeing, is added
    to it unchanged (a ``CompositePSF``)."""
    if not isinstance(optics, Optics):
        raise TypeError(f"optics must be an Optics; got {optics!r}")
    seeing = positive("seeing_fwhm_arcsec", seeing_fwhm_arcsec)
    b = finite("moffat_beta", beta)
    if not 1.0 < b <= 1000.0:
        raise ValueError(f"moffat_beta must be > 1 (a finite flux) and <= 1000; got moffat_beta={beta!r}")
    if optics.psf == "moffat":
        raise ValueError("optics.psf='moffat' is already a seeing PSF: give the seeing once (optics psf='gaussian', "
                         f"'airy' or 'image' with the atmosphere's seeing); got optics psf='moffat', "
                         f"seeing_fwhm_arcsec={seeing_fwhm_arcsec!r}")
    fwhm = seeing / optics.plate_scale_arcsec_per_px
    if not 0.05 <= fwhm <= 100.0:
        raise ValueError(f"seeing_fwhm_arcsec={seeing_fwhm_arcsec!r} is {fwhm:.3g} px at "
                         f"{optics.plate_scale_arcsec_per_px:.4g} arcsec/px; it must be in [0.05, 100] px (a seeing "
                         "far inside a pixel changes nothing: leave it out)")
    if optics.halo_fraction > 0.0:
        core = _seeing_psf(optics.replace(halo_fraction=0.0, halo_fwhm_px=None), seeing, b)
        return with_halo(core, optics)
    return _seeing_psf(optics, seeing, b)


@functools.lru_cache(maxsize=8)
def _seeing_psf(optics: Optics, seeing: float, beta: float) -> KernelPSF:
    fwhm = seeing / optics.plate_scale_arcsec_per_px
    if optics.psf == "gaussian":
        shape = moffat_psf(fwhm, beta, optics.psf_sigma_px, optics.psf_subpixel, optics.psf_half_width_px)
        shape.kind = "seeing"
        shape.params.update(seeing_fwhm_arcsec=seeing, optics_sigma_px=optics.psf_sigma_px)
        return shape
    inner = from_optics(optics)
    if not isinstance(inner, KernelPSF):  # pragma: no cover - airy and image are tabulated
        raise ValueError(f"optics psf={optics.psf!r} is not tabulated")
    return _convolved(inner, fwhm, beta, seeing)


def _convolved(inner: KernelPSF, fwhm_px: float, beta: float, seeing: float) -> KernelPSF:
    """``inner`` (cells 1/k px) convolved with a Moffat integrated over the same cells.

    The Moffat grid has an odd number of cells, one centred on the source, so that the full
    convolution of the even, source-centred inner grid is centred on a cell edge again once
    padded by one cell each side (a half-cell shift otherwise)."""
    from scipy.signal import fftconvolve

    k = inner.subpixel
    alpha = moffat_alpha_px(fwhm_px, beta)
    with np.errstate(over="ignore"):
        radius = alpha * math.sqrt(max(0.0, math.exp(math.log(DEFAULT_TAIL_FRACTION) / (1.0 - beta)) - 1.0))
    h_b = _default_half(radius, 0.0)
    h = inner.half_width_px + h_b + 1
    _grid("seeing", h, k, 1)
    n_b = 2 * k * (h_b + 1) - 1
    m = max(1, math.ceil(4.0 / (k * alpha)))  # sub-samples per cell: >= 4 per alpha
    sub = ((np.arange(n_b * m, dtype=np.float64) + 0.5) / m - 0.5 * n_b) / k
    r2 = sub[:, None] ** 2 + sub[None, :] ** 2
    density = (beta - 1.0) / (math.pi * alpha * alpha) * (1.0 + r2 / (alpha * alpha)) ** (-beta)
    moffat = density.reshape(n_b, m, n_b, m).sum(axis=(1, 3)) * (1.0 / (k * m)) ** 2
    full = np.maximum(fftconvolve(inner.fine, moffat, mode="full"), 0.0)
    mass = np.pad(full, 1)
    params = {"inner": inner.kind, **inner.params, "seeing_fwhm_arcsec": seeing, "fwhm_px": fwhm_px, "beta": beta}
    return KernelPSF(mass, k, 1, h, "seeing", params)


# -- random processes ---------------------------------------------------------------------------


def _rng(seed: int, purpose: int, index: int = 0) -> np.random.Generator:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**64:
        raise ValueError(f"seed must be an integer in [0, 2**64); got seed={seed!r}")
    return np.random.default_rng(np.random.SeedSequence([int(seed), purpose, index]))


def ou_process(rng: np.random.Generator, n_steps: int, rho: float, n_series: int = 1) -> np.ndarray:
    """``n_series`` stationary unit-variance AR(1) series of ``n_steps + 1`` values (an OU
    process sampled exactly at a step where its autocorrelation is rho): x[0] ~ N(0, 1),
    ``x[k+1] = rho x[k] + sqrt(1 - rho^2) eps[k]``. Shape (n_series, n_steps + 1)."""
    from scipy.signal import lfilter

    x0 = rng.standard_normal(n_series)
    eps = rng.standard_normal((n_series, n_steps))
    out = np.empty((n_series, n_steps + 1))
    out[:, 0] = x0
    if n_steps:
        out[:, 1:], _ = lfilter([math.sqrt(1.0 - rho * rho)], [1.0, -rho], eps, axis=1, zi=(rho * x0)[:, None])
    return out


@dataclass(frozen=True, eq=False)
class MotionPath:
    """The field's offset (dx_px, dy_px) [px] at the grid times t_s [s], linear in between
    (held at the end values outside the grid, which covers the run)."""

    t_s: np.ndarray
    dx_px: np.ndarray
    dy_px: np.ndarray

    def offset_px(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        t = _times(t_s)
        return np.interp(t, self.t_s, self.dx_px), np.interp(t, self.t_s, self.dy_px)

    def velocity_px_s(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """The velocity of the grid segment holding each time (0 outside the grid)."""
        t = _times(t_s)
        if self.t_s.size < 2:
            return np.zeros(t.shape), np.zeros(t.shape)
        dt = np.diff(self.t_s)
        vx, vy = np.diff(self.dx_px) / dt, np.diff(self.dy_px) / dt
        k = np.clip(np.searchsorted(self.t_s, t, side="right") - 1, 0, self.t_s.size - 2)
        inside = (t >= self.t_s[0]) & (t <= self.t_s[-1])
        return np.where(inside, vx[k], 0.0), np.where(inside, vy[k], 0.0)

    def max_speed_px_s(self, t0_s: float, t1_s: float) -> float:
        """The largest speed of the grid segments that overlap [t0_s, t1_s] [px/s]."""
        t0, t1 = _interval(t0_s, t1_s)
        if self.t_s.size < 2:
            return 0.0
        speed = np.hypot(np.diff(self.dx_px), np.diff(self.dy_px)) / np.diff(self.t_s)
        touch = (self.t_s[1:] >= t0) & (self.t_s[:-1] <= t1)
        return float(speed[touch].max()) if np.any(touch) else 0.0


@dataclass(frozen=True)
class ImageMotion:
    """Tip-tilt jitter of the whole field: an OU process per axis (module docstring).

    rms_arcsec: standard deviation per axis [arcsec], >= 0; tau_s: correlation time [s], > 0.
    """

    rms_arcsec: float
    tau_s: float

    def __post_init__(self) -> None:
        non_negative("jitter_rms_arcsec", self.rms_arcsec)
        positive("jitter_tau_s", self.tau_s)

    def grid_points(self, duration_s: float) -> int:
        """Grid values per axis over [0, duration_s]."""
        return math.ceil(non_negative("duration_s", duration_s) * JITTER_STEPS_PER_TAU / self.tau_s - 1e-9) + 1

    def path(self, optics: Optics, duration_s: float, seed: int) -> MotionPath:
        """The offsets [px] over [0, duration_s] (through ``optics.plate_scale_arcsec_per_px``)."""
        n = self.grid_points(duration_s)
        if 2 * n > MAX_PROCESS_SAMPLES:
            raise ValueError(f"image motion over duration_s={duration_s:g} with jitter_tau_s={self.tau_s:g} needs "
                             f"{2 * n:.3g} grid values (> {MAX_PROCESS_SAMPLES:g}): raise jitter_tau_s or shorten the run")
        dt = self.tau_s / JITTER_STEPS_PER_TAU
        rho = math.exp(-1.0 / JITTER_STEPS_PER_TAU)
        sigma_px = self.rms_arcsec / optics.plate_scale_arcsec_per_px
        xy = ou_process(_rng(seed, _PURPOSE_JITTER), n - 1, rho, 2) * sigma_px
        t = np.arange(n, dtype=np.float64) * dt
        return MotionPath(t, xy[0], xy[1])


def young_variance(aperture_m: float, exposure_s: float, airmass: float, altitude_m: float,
                   c_y: float = OSBORN_C_Y) -> float:
    """Osborn et al. (2015) eq. 7: variance of the relative flux over an exposure,
    ``1e-5 C_Y^2 D^(-4/3) t^(-1) X^3 exp(-2 h / 8000 m)`` (D in m, t in s, X airmass, h [m])."""
    d = positive("aperture_m", aperture_m)
    t = positive("exposure_s", exposure_s)
    x = finite("airmass", airmass)
    if x < 1.0:
        raise ValueError(f"airmass must be >= 1; got airmass={airmass!r}")
    h = finite("altitude_m", altitude_m)
    c = positive("c_y", c_y)
    return YOUNG_COEFFICIENT * c * c * d ** (-4.0 / 3.0) / t * x**3 * math.exp(-2.0 * h / SCINTILLATION_SCALE_HEIGHT_M)


def _g(x: float) -> float:
    """G(x) = sum_k x^k / (k k!) = Ei(x) - gamma - ln x (the series below x = 1e-6)."""
    from scipy.special import expi

    if x < 1e-6:
        return x + x * x / 4.0
    return float(expi(x) - np.euler_gamma - math.log(x))


@dataclass(frozen=True)
class Scintillation:
    """Scintillation of point sources (module docstring): Young's formula with Osborn et al.'s
    C_Y for the strength, a log-normal OU multiplier per source.

    altitude_m: observatory altitude [m] in [-500, 9000]; airmass: X >= 1 (sec of the zenith
    distance; at most 40); c_y: C_Y > 0 (default 1.5); wind_speed_m_s: > 0 (default 20);
    tau_s: the correlation time [s] (None: D_eff / wind speed).
    """

    altitude_m: float = 0.0
    airmass: float = 1.0
    c_y: float = OSBORN_C_Y
    wind_speed_m_s: float = DEFAULT_WIND_SPEED_M_S
    tau_s: float | None = None

    def __post_init__(self) -> None:
        in_range("site_altitude_m", self.altitude_m, -500.0, 9000.0, note="m")
        in_range("airmass", self.airmass, 1.0, 40.0, note="(1 at the zenith)")
        c = positive("scintillation_c_y", self.c_y)
        if c > 100.0:
            raise ValueError(f"scintillation_c_y must be in (0, 100]; got scintillation_c_y={self.c_y!r}")
        positive("wind_speed_m_s", self.wind_speed_m_s)
        if self.tau_s is not None:
            positive("scintillation_tau_s", self.tau_s)

    @staticmethod
    def effective_aperture_m(aperture_m: float) -> float:
        """max(D, r_F): the aperture Young's law is applied with [m]."""
        return max(positive("aperture_m", aperture_m), FRESNEL_SCALE_M)

    def correlation_time_s(self, aperture_m: float) -> float:
        """tau_c [s]: ``tau_s`` if given, else D_eff / wind_speed_m_s."""
        if self.tau_s is not None:
            return float(self.tau_s)
        return self.effective_aperture_m(aperture_m) / self.wind_speed_m_s

    def exposure_variance(self, aperture_m: float, exposure_s: float) -> float:
        """sigma_Y^2 of the flux averaged over ``exposure_s`` (Young-Osborn, with D_eff)."""
        return young_variance(self.effective_aperture_m(aperture_m), exposure_s, self.airmass, self.altitude_m, self.c_y)

    def log_variance(self, aperture_m: float) -> float:
        """s^2, the variance of ln m: the root of G(s^2) = sigma_Y^2(1 s) 1 s / (2 tau_c)."""
        from scipy.optimize import brentq

        target = self.exposure_variance(aperture_m, 1.0) / (2.0 * self.correlation_time_s(aperture_m))
        if target > _g(20.0):
            raise ValueError(f"scintillation: sigma_Y^2 t / (2 tau_c) = {target:.3g} needs an instantaneous log variance "
                             "above 20 (saturated scintillation, outside the log-normal weak regime): raise the "
                             "correlation time or check the aperture, airmass and altitude")
        return float(brentq(lambda x: _g(x) - target, 0.0, 20.0, xtol=1e-14, rtol=1e-12))

    def index(self, aperture_m: float) -> float:
        """The scintillation index, variance of the instantaneous multiplier: exp(s^2) - 1."""
        return math.expm1(self.log_variance(aperture_m))

    def multipliers(self, aperture_m: float, duration_s: float, n_sources: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
        """(t_s, m): grid times [s] over [0, duration_s] and each source's flux multiplier,
        (n_sources, len(t_s)), mean 1 (log-normal, module docstring). Source j's numbers
        come from its own stream (seed, purpose, j): adding a source changes no other's."""
        tau = self.correlation_time_s(aperture_m)
        n = math.ceil(non_negative("duration_s", duration_s) * SCINTILLATION_STEPS_PER_TAU / tau - 1e-9) + 1
        if n * n_sources > MAX_PROCESS_SAMPLES:
            raise ValueError(f"scintillation of {n_sources} sources over duration_s={duration_s:g} with a correlation time "
                             f"of {tau:.3g} s needs {n * n_sources:.3g} grid values (> {MAX_PROCESS_SAMPLES:g}): "
                             "fewer sources (star field), a shorter run or a longer scintillation_tau_s")
        s2 = self.log_variance(aperture_m)
        s = math.sqrt(s2)
        rho = math.exp(-1.0 / SCINTILLATION_STEPS_PER_TAU)
        m = np.empty((n_sources, n))
        for j in range(n_sources):
            m[j] = np.exp(s * ou_process(_rng(seed, _PURPOSE_SCINTILLATION, j), n - 1, rho)[0] - 0.5 * s2)
        return np.arange(n, dtype=np.float64) * (tau / SCINTILLATION_STEPS_PER_TAU), m


# -- the atmosphere on targets ------------------------------------------------------------------


def _plus(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) + (dx, dy): a target's own position or velocity plus the image motion's."""
    return a[0] + b[0], a[1] + b[1]


@dataclass(frozen=True, eq=False)
class AtmosphericTarget(Target):
    """A target seen through the atmosphere: its position plus the field's image motion
    (``motion``, or None) and its brightness replaced by ``brightness`` (the scintillating
    light curve, or the target's own). Label from the target."""

    target: Target
    motion: MotionPath | None
    brightness: Any
    scintillation: tuple[np.ndarray, np.ndarray] | None = None
    """(t_grid, multiplier): the flux is the target's times the multiplier interpolated."""
    label: str = dataclasses.field(init=False)

    def __post_init__(self) -> None:
        adopt(self, self.target, brightness=False)  # its brightness: the scintillating curve

    def position_px(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        own = self.target.position_px(t_s)
        return own if self.motion is None else _plus(own, self.motion.offset_px(t_s))

    def flux_ph_s(self, t_s: npt.ArrayLike) -> np.ndarray:
        flux = self.target.flux_ph_s(t_s)
        if self.scintillation is None:
            return flux
        t_grid, m = self.scintillation
        return flux * np.interp(np.asarray(t_s, np.float64), t_grid, m)

    def velocity_px_s(self, t_s: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        own = self.target.velocity_px_s(t_s)
        return own if self.motion is None else _plus(own, self.motion.velocity_px_s(t_s))

    def max_speed_px_s(self, t0_s: float, t1_s: float) -> float:
        """The target's own largest speed plus the motion's (a bound: exact when they align)."""
        own = self.target.max_speed_px_s(t0_s, t1_s)
        return own + (0.0 if self.motion is None else self.motion.max_speed_px_s(t0_s, t1_s))


@dataclass(frozen=True)
class Atmosphere:
    """What the ``[atmosphere]`` table of a scenario describes (module docstring).

    seeing_fwhm_arcsec: None (no seeing: the optics' PSF) or > 0; moffat_beta > 1;
    motion: tip-tilt jitter or None; scintillation: or None.
    """

    seeing_fwhm_arcsec: float | None = None
    moffat_beta: float = KOLMOGOROV_MOFFAT_BETA
    motion: ImageMotion | None = None
    scintillation: Scintillation | None = None

    def __post_init__(self) -> None:
        if self.seeing_fwhm_arcsec is not None:
            seeing = positive("seeing_fwhm_arcsec", self.seeing_fwhm_arcsec)
            if seeing > 3600.0:
                raise ValueError(f"seeing_fwhm_arcsec must be at most 3600 (1 degree); got "
                                 f"seeing_fwhm_arcsec={self.seeing_fwhm_arcsec!r}")
        b = finite("moffat_beta", self.moffat_beta)
        if not 1.0 < b <= 1000.0:
            raise ValueError(f"moffat_beta must be > 1 (a finite flux) and <= 1000; got moffat_beta={self.moffat_beta!r}")

    def psf(self, optics: Optics) -> PSFShape:
        """The PSF sources are rendered with: :func:`seeing_psf` with seeing, else the optics'."""
        if self.seeing_fwhm_arcsec is None:
            return from_optics(optics)
        return seeing_psf(optics, self.seeing_fwhm_arcsec, self.moffat_beta)

    def scintillation_tau_s(self, optics: Optics) -> float | None:
        """The scintillation's correlation time [s] with these optics (None: no scintillation)."""
        if self.scintillation is None:
            return None
        return self.scintillation.correlation_time_s(float(optics.aperture_diameter_m))  # type: ignore[arg-type]

    def apply(self, targets: list[Target], optics: Optics, duration_s: float, seed: int) -> list[Target]:
        """The targets seen through the image motion and scintillation over [0, duration_s]
        (the same list when there is neither). Target j's scintillation is its own stream."""
        if self.motion is None and self.scintillation is None:
            return list(targets)
        path = None
        if self.motion is not None and self.motion.rms_arcsec > 0.0:
            path = self.motion.path(optics, duration_s, seed)
        if any(_is_ghost(t) for t in targets):
            raise ValueError("a ghost (kind='ghost') with image motion or scintillation is not modelled: its light "
                             "and motion must follow its source's through the atmosphere, which they would not "
                             "(each target gets its own); leave out jitter_rms_arcsec and scintillation, or the ghost")
        curves: list[Any] = [t.brightness for t in targets]
        factors: list[tuple[np.ndarray, np.ndarray] | None] = [None] * len(targets)
        if self.scintillation is not None and targets:
            t_grid, m = self.scintillation.multipliers(float(optics.aperture_diameter_m), duration_s,  # type: ignore[arg-type]
                                                       len(targets), seed)
            # brightness: the product on the scintillation's grid (for the scene's bounds and
            # to mark the target as varying); flux_ph_s: the exact product at any time, so a
            # target's own light curve keeps its steps (a shadow entry, a flash).
            curves = [LightCurve(t_grid, t.flux_ph_s(t_grid) * m[j], log_interp=False) for j, t in enumerate(targets)]
            factors = [(t_grid, m[j]) for j in range(len(targets))]
        if path is None and self.scintillation is None:
            return list(targets)
        return [AtmosphericTarget(t, path, b, f) for t, b, f in zip(targets, curves, factors)]


def _is_ghost(target: Target) -> bool:
    """Whether a target is a MirroredTarget, bare or under offset/drift wrappers."""
    while isinstance(target, (DriftingTarget, PathTarget)):
        target = target.target
    return isinstance(target, MirroredTarget)


def airmass_from_elevation_deg(elevation_deg: float) -> float:
    """The airmass at an elevation in (0, 90] deg: Kasten & Young (1989), the one formula the
    sky uses for extinction too (``evstwin.sky.photometry.airmass_kasten_young``; 1 at the
    zenith, 37.9 at the horizon)."""
    el = in_range("elevation_deg", elevation_deg, 0.0, 90.0, lo_open=True, note="(above the horizon)")
    return float(airmass_kasten_young(el))


ATMOSPHERE_KEYS = ("seeing_fwhm_arcsec", "moffat_beta", "jitter_rms_arcsec", "jitter_tau_s", "scintillation",
                   "site_altitude_m", "airmass", "elevation_deg", "scintillation_c_y", "wind_speed_m_s",
                   "scintillation_tau_s")
"""The keys of a scenario's ``[atmosphere]`` table."""


def atmosphere_from_table(table: dict[str, Any], elevation_deg: float | None = None,
                          site_altitude_m: float | None = None) -> Atmosphere:
    """An :class:`Atmosphere` from a scenario's ``[atmosphere]`` table (ValueError naming the
    key). The hook for a pointing computed elsewhere: ``elevation_deg`` and
    ``site_altitude_m`` given here are used where the table gives none (the table's airmass
    or elevation_deg, and site_altitude_m, win)."""
    unknown = [k for k in table if k not in ATMOSPHERE_KEYS]
    if unknown:
        raise ValueError(f"unknown key atmosphere.{unknown[0]}; allowed: {', '.join(ATMOSPHERE_KEYS)}")
    if "airmass" in table and "elevation_deg" in table:
        raise ValueError(f"atmosphere takes one of airmass or elevation_deg, not both; got airmass={table['airmass']!r}, "
                         f"elevation_deg={table['elevation_deg']!r}")
    scint = table.get("scintillation", False)
    if not isinstance(scint, bool):
        raise ValueError(f"atmosphere.scintillation must be true or false; got {scint!r}")
    scint_keys = ("site_altitude_m", "airmass", "elevation_deg", "scintillation_c_y", "wind_speed_m_s",
                  "scintillation_tau_s")
    stray = [k for k in scint_keys if k in table and not scint and k not in ("airmass", "elevation_deg")]
    if stray:
        raise ValueError(f"atmosphere.{stray[0]}={table[stray[0]]!r} applies to scintillation: set "
                         "atmosphere.scintillation = true (or drop the key)")
    motion = None
    if "jitter_rms_arcsec" in table or "jitter_tau_s" in table:
        if "jitter_rms_arcsec" not in table or "jitter_tau_s" not in table:
            raise ValueError("image motion needs both atmosphere.jitter_rms_arcsec and atmosphere.jitter_tau_s; got "
                             f"{ {k: table[k] for k in ('jitter_rms_arcsec', 'jitter_tau_s') if k in table} }")
        motion = ImageMotion(_number("atmosphere.jitter_rms_arcsec", table["jitter_rms_arcsec"]),
                             _number("atmosphere.jitter_tau_s", table["jitter_tau_s"]))
        if not motion.rms_arcsec <= 3600.0 or not motion.tau_s <= 3600.0:
            raise ValueError(f"atmosphere.jitter_rms_arcsec and jitter_tau_s must be at most 3600; got "
                             f"jitter_rms_arcsec={motion.rms_arcsec!r}, jitter_tau_s={motion.tau_s!r}")
    scintillation = None
    if scint:
        if "airmass" in table:
            airmass = _number("atmosphere.airmass", table["airmass"])
        elif "elevation_deg" in table:
            airmass = airmass_from_elevation_deg(_number("atmosphere.elevation_deg", table["elevation_deg"]))
        elif elevation_deg is not None:
            airmass = airmass_from_elevation_deg(elevation_deg)
        else:
            airmass = 1.0
        altitude = table.get("site_altitude_m", 0.0 if site_altitude_m is None else site_altitude_m)
        kw: dict[str, Any] = {"altitude_m": _number("atmosphere.site_altitude_m", altitude), "airmass": airmass}
        for key, field in (("scintillation_c_y", "c_y"), ("wind_speed_m_s", "wind_speed_m_s"),
                           ("scintillation_tau_s", "tau_s")):
            if key in table:
                kw[field] = _number(f"atmosphere.{key}", table[key])
        scintillation = Scintillation(**kw)
    seeing = table.get("seeing_fwhm_arcsec")
    return Atmosphere(
        seeing_fwhm_arcsec=None if seeing is None else _number("atmosphere.seeing_fwhm_arcsec", seeing),
        moffat_beta=_number("atmosphere.moffat_beta", table.get("moffat_beta", KOLMOGOROV_MOFFAT_BETA)),
        motion=motion,
        scintillation=scintillation,
    )


def _number(key: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{key} must be a number; got {value!r}")
    return float(value)


__all__ = [
    "ATMOSPHERE_KEYS", "Atmosphere", "AtmosphericTarget", "DEFAULT_WIND_SPEED_M_S", "FRESNEL_SCALE_M",
    "ImageMotion", "KOLMOGOROV_MOFFAT_BETA", "MotionPath", "OSBORN_C_Y", "Scintillation", "airmass_from_elevation_deg",
    "atmosphere_from_table", "ou_process", "seeing_fwhm_px", "seeing_psf", "young_variance",
]
