"""Spectra, photometric bands and quantum efficiency: a magnitude becomes electrons, once per
source and sensor.

A magnitude is given in a band (Johnson V, Gaia G or a user's table) for a source with a
spectrum (the Sun's for a sunlit satellite, a star's from its colour or temperature, the night
sky's, an LED's, a flat one or a user's table). The band fixes the spectrum's scale; the optics'
transmission and the sensor's quantum efficiency QE(lambda) then give electrons per second per
square metre of aperture:

    e- / s / m^2 = integral n(lambda) T(lambda) QE(lambda) dlambda,

with n the photon spectral flux [photons s^-1 m^-2 m^-1] whose band count matches the magnitude.
The engine takes "photons/s arriving on a pixel" and turns them into electrons with the
pixel's yield ``PixelParams.electrons_per_photon`` (paper eq. 1-2); for a sensor with a QE
curve the scene layer hands it ``electrons / yield`` (:func:`zero_point_ph_s_m2`), so a source's
colour changes what a pixel collects and nothing is integrated in the pixel loop.

Magnitudes are Vega magnitudes. Band counts are computed in the AB system (f_nu = 3631 Jy,
Oke & Gunn 1983) and moved to Vega by each band's published AB - Vega offset, so no Vega
spectrum is needed.

Wavelengths in metres; every curve is sampled on a 0.5 nm grid from 300 to 1100 nm (the span
where silicon responds), :data:`GRID_M`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from .constants import BOLTZMANN_J_K, JANSKY_W_M2_HZ, PLANCK_J_S, SPEED_OF_LIGHT_M_S
from .optics import _A0V_FNU_JY, _A0V_LAMBDA_M

GRID_M = np.arange(300.0, 1100.0 + 0.25, 0.5) * 1e-9
"""Wavelength grid of every integral [m]: 300-1100 nm every 0.5 nm."""
AB_ZERO_FNU_JY = 3631.0
"""f_nu of an AB magnitude 0 source [Jy] (Oke & Gunn 1983, ApJ 266, 713)."""
SUN_TEFF_K = 5772.0
"""Nominal effective temperature of the Sun [K] (IAU 2015 Resolution B3; Prsa et al. 2016, AJ 152, 41)."""
NIGHT_SKY_UBVRI_MAG_ARCSEC2 = {"U": 22.3, "B": 22.6, "V": 21.6, "R": 20.9, "I": 19.7}
"""Dark-time zenith night-sky brightness at ESO Paranal [mag/arcsec^2], averaged over
April 2000 - September 2001 (Patat 2003, A&A 400, 1183, "UBVRI night sky brightness during
sunspot maximum at ESO-Paranal"): the shape of :func:`night_sky`."""
_UBVRI = ("U", "B", "V", "R", "I")
MIN_LED_FWHM_M = 2e-9
"""Narrowest LED line accepted [m]: four grid steps across its FWHM."""


class SpectrumError(ValueError):
    """A spectrum, band or QE curve that cannot be used: the message names it and what is accepted."""


def _integrate(y: np.ndarray, x: np.ndarray) -> float:
    """Trapezoid rule (numpy.trapezoid, named trapz before NumPy 2.0)."""
    fn = getattr(np, "trapezoid", None) or getattr(np, "trapz")
    return float(fn(y, x))


def _photons_per_wavelength_from_fnu(fnu_w_m2_hz: np.ndarray | float, wavelength_m: np.ndarray) -> np.ndarray:
    """Photon spectral flux n_lambda [photons s^-1 m^-2 m^-1] of a source of spectral flux
    density f_nu: f_lambda = f_nu c / lambda^2 and one photon carries h c / lambda, so
    n_lambda = f_nu / (h lambda)."""
    return np.asarray(fnu_w_m2_hz, np.float64) / (PLANCK_J_S * wavelength_m)


@dataclass(frozen=True)
class Spectrum:
    """A photon spectral flux [photons s^-1 m^-2 m^-1] up to a scale, on :data:`GRID_M`
    (zero outside the span it was given on); ``name`` says what it is."""

    name: str
    photon_flux: np.ndarray = field(repr=False)
    """Relative photon spectral flux on GRID_M (>= 0, not all zero)."""
    span_m: tuple[float, float] = (float(GRID_M[0]), float(GRID_M[-1]))
    """The wavelengths the spectrum is known over [m] (a table's first and last rows)."""

    def __post_init__(self) -> None:
        n = np.asarray(self.photon_flux, np.float64)
        if n.shape != GRID_M.shape or not np.all(np.isfinite(n)) or np.any(n < 0) or not np.any(n > 0):
            raise SpectrumError(f"spectrum {self.name!r} must be finite, >= 0 and not all zero on 300-1100 nm")
        object.__setattr__(self, "photon_flux", n)


def _tabulated(wavelength_m: np.ndarray, values: np.ndarray) -> np.ndarray:
    """values at wavelength_m interpolated onto GRID_M, zero outside the table."""
    return np.interp(GRID_M, wavelength_m, values, left=0.0, right=0.0)


def blackbody(temperature_k: float) -> Spectrum:
    """Planck's law in photons: n_lambda proportional to lambda^-4 / (exp(h c / lambda k T) - 1)."""
    t = float(temperature_k)
    if not (math.isfinite(t) and 500.0 <= t <= 100000.0):
        raise SpectrumError(f"blackbody temperature must be in [500, 100000] K; got {temperature_k!r}")
    x = PLANCK_J_S * SPEED_OF_LIGHT_M_S / (GRID_M * BOLTZMANN_J_K * t)
    n = (GRID_M / 1e-6) ** -4 / np.expm1(x)
    return Spectrum(f"blackbody {t:g} K", n / n.max())


def temperature_from_bv(bv: float) -> float:
    """Effective temperature [K] of a star of colour B - V (Ballesteros 2012, EPL 97, 34008):
    ``T = 4600 (1 / (0.92 (B-V) + 1.7) + 1 / (0.92 (B-V) + 0.62))``; 5778 K at 0.65 (the Sun).
    Valid for -0.4 <= B - V <= 2.0 (the range of the stars it was fitted to)."""
    c = float(bv)
    if not (math.isfinite(c) and -0.4 <= c <= 2.0):
        raise SpectrumError(f"B-V colour must be in [-0.4, 2.0] (Ballesteros 2012's range); got {bv!r}")
    return 4600.0 * (1.0 / (0.92 * c + 1.7) + 1.0 / (0.92 * c + 0.62))


def star(bv: float) -> Spectrum:
    """A star of colour B - V as a black body at :func:`temperature_from_bv` (a black body
    misses a star's absorption lines and Balmer jump: a broadband approximation)."""
    t = temperature_from_bv(bv)
    return Spectrum(f"star B-V {float(bv):g} ({t:.0f} K)", blackbody(t).photon_flux)


def sun() -> Spectrum:
    """The Sun as a black body at its nominal 5772 K (:data:`SUN_TEFF_K`): the light of a
    sunlit satellite (its colour is the Sun's for a grey surface). A broadband approximation:
    the real solar spectrum falls below it in the blue and ultraviolet."""
    return Spectrum(f"sun ({SUN_TEFF_K:g} K black body)", blackbody(SUN_TEFF_K).photon_flux)


def night_sky() -> Spectrum:
    """The moonless night sky's broadband shape: Patat's (2003) UBVRI brightnesses at Paranal
    (:data:`NIGHT_SKY_UBVRI_MAG_ARCSEC2`) as photon fluxes at the bands' centres through the
    zero-magnitude fluxes of Bessell (1979) (``evstwin.optics``), log-interpolated between them
    and held flat beyond U (below 360 nm) and I (above 790 nm). Assumption: the real sky
    brightens further in the near infrared (OH airglow bands between 0.7 and 1 um), so this
    shape underestimates the sky a silicon sensor sees there."""
    lam = _A0V_LAMBDA_M[:5]
    mags = np.array([NIGHT_SKY_UBVRI_MAG_ARCSEC2[b] for b in _UBVRI])
    n = _photons_per_wavelength_from_fnu(_A0V_FNU_JY[:5] * JANSKY_W_M2_HZ * 10.0 ** (-0.4 * mags), lam)
    log_n = np.interp(GRID_M, lam, np.log(n))
    out = np.exp(log_n)
    return Spectrum("night sky (Paranal UBVRI, Patat 2003)", out / out.max())


def led(peak_m: float, fwhm_m: float) -> Spectrum:
    """An LED: a Gaussian line of photons at peak_m [m] with full width at half maximum
    fwhm_m [m] (at least :data:`MIN_LED_FWHM_M`), inside 300-1100 nm."""
    peak, fwhm = float(peak_m), float(fwhm_m)
    if not (math.isfinite(peak) and GRID_M[0] <= peak <= GRID_M[-1]):
        raise SpectrumError(f"LED peak must be in [300, 1100] nm; got {peak * 1e9:g} nm")
    if not (math.isfinite(fwhm) and MIN_LED_FWHM_M <= fwhm <= 500e-9):
        raise SpectrumError(f"LED FWHM must be in [2, 500] nm; got {fwhm * 1e9:g} nm")
    sigma = fwhm / (2.0 * math.sqrt(2.0 * math.log(2.0)))
    n = np.exp(-0.5 * ((GRID_M - peak) / sigma) ** 2)
    return Spectrum(f"LED {peak * 1e9:g} nm FWHM {fwhm * 1e9:g} nm", n)


def flat() -> Spectrum:
    """Equal photons per wavelength across 300-1100 nm."""
    return Spectrum("flat", np.ones_like(GRID_M))


def _read_table(path: Path, what: str) -> tuple[np.ndarray, np.ndarray, dict[str, str]]:
    """(wavelength_m, values, header flags) of a CSV ``wavelength_nm,value`` with ``#``
    comments; a comment ``# key=value`` sets a flag."""
    flags: dict[str, str] = {}
    rows: list[tuple[float, float]] = []
    try:
        text = path.read_text()
    except OSError as exc:
        raise SpectrumError(f"{what} file {str(path)!r} cannot be read ({exc.strerror or exc})") from None
    for n, line in enumerate(text.splitlines(), 1):
        line = line.strip()
        if line.startswith("#"):
            key, eq, value = line[1:].strip().partition("=")
            if eq and " " not in key.strip():
                flags[key.strip()] = value.strip()
            continue
        if not line or line[0].isalpha():
            continue  # blank or the header row
        parts = line.split(",")
        try:
            w, v = float(parts[0]), float(parts[1])
        except (ValueError, IndexError):
            raise SpectrumError(f"{what} file {str(path)!r} line {n}: expected 'wavelength_nm,value'; got {line!r}") from None
        rows.append((w, v))
    if len(rows) < 2:
        raise SpectrumError(f"{what} file {str(path)!r} needs at least two rows 'wavelength_nm,value'")
    arr = np.array(rows)
    w_m, values = arr[:, 0] * 1e-9, arr[:, 1]
    if not (np.all(np.isfinite(arr)) and np.all(np.diff(w_m) > 0) and np.all(values >= 0) and np.any(values > 0)):
        raise SpectrumError(f"{what} file {str(path)!r}: wavelengths must increase and values be finite, >= 0, "
                            "not all zero")
    return w_m, values, flags


def from_table(path: str | Path, energy: bool = False) -> Spectrum:
    """A user's spectrum: CSV rows ``wavelength_nm,flux`` (``#`` comments), photons per
    wavelength, or energy per wavelength with ``energy=True`` (or a ``# energy=true`` line),
    converted by lambda / (h c)."""
    p = Path(path)
    w_m, v, flags = _read_table(p, "spectrum")
    if energy or flags.get("energy", "").lower() == "true":
        v = v * w_m / (PLANCK_J_S * SPEED_OF_LIGHT_M_S)
    n = _tabulated(w_m, v)
    if not np.any(n > 0):
        raise SpectrumError(f"spectrum file {str(p)!r} has no light between 300 and 1100 nm")
    return Spectrum(f"table {p.name}", n, (float(w_m[0]), float(w_m[-1])))


SPECTRUM_FORMS = ("sun", "night-sky", "flat", "blackbody:<K>", "bv:<B-V>", "led:<peak nm>:<FWHM nm>", "<path>.csv")
"""The spectrum names a scenario accepts (:func:`spectrum_from_name`)."""


def spectrum_from_name(text: str) -> Spectrum:
    """A spectrum from a scenario's string: ``sun``, ``night-sky``, ``flat``,
    ``blackbody:5800`` (K), ``bv:0.65`` (a star of that B - V), ``led:630:20`` (peak and FWHM
    in nm) or the path of a CSV table (:func:`from_table`)."""
    if not isinstance(text, str) or not text.strip():
        raise SpectrumError(f"spectrum must be one of {', '.join(SPECTRUM_FORMS)}; got {text!r}")
    t = text.strip()
    low = t.lower()
    simple = {"sun": sun, "night-sky": night_sky, "flat": flat}
    if low in simple:
        return simple[low]()
    kind, _, rest = low.partition(":")
    try:
        if kind == "blackbody" and rest:
            return blackbody(float(rest))
        if kind == "bv" and rest:
            return star(float(rest))
        if kind == "led" and rest.count(":") == 1:
            peak, fwhm = (float(x) for x in rest.split(":"))
            return led(peak * 1e-9, fwhm * 1e-9)
    except ValueError as exc:
        if isinstance(exc, SpectrumError):
            raise
        raise SpectrumError(f"spectrum {text!r}: expected numbers in {', '.join(SPECTRUM_FORMS)}") from None
    if low.endswith(".csv"):
        return from_table(t)
    raise SpectrumError(f"spectrum must be one of {', '.join(SPECTRUM_FORMS)}; got {text!r}")


@dataclass(frozen=True)
class Band:
    """A photometric band: its response per photon on GRID_M (peak 1) and the offset that turns
    its AB magnitudes into Vega magnitudes (``m_AB - m_Vega``)."""

    name: str
    response: np.ndarray = field(repr=False)
    ab_minus_vega_mag: float
    source: str

    def ab_zero_point_ph_s_m2(self) -> float:
        """Photons/s/m^2 through the band from an AB magnitude 0 source (f_nu = 3631 Jy)."""
        n = _photons_per_wavelength_from_fnu(AB_ZERO_FNU_JY * JANSKY_W_M2_HZ, GRID_M)
        return float(_integrate(n * self.response, GRID_M))

    def count_ph_s_m2(self, spectrum: Spectrum) -> float:
        """Photons/s/m^2 of ``spectrum`` (as scaled) through the band."""
        return float(_integrate(spectrum.photon_flux * self.response, GRID_M))

    def scale_for(self, spectrum: Spectrum, magnitude: float) -> float:
        """The factor that gives ``spectrum`` the Vega magnitude ``magnitude`` in this band."""
        count = self.count_ph_s_m2(spectrum)
        if not count > 0.0:
            raise SpectrumError(f"spectrum {spectrum.name!r} has no light in band {self.name!r}: its magnitude there "
                                "is undefined; give the magnitude in a band the source shines in")
        lo, hi = self.span_m
        if spectrum.span_m[0] > lo or spectrum.span_m[1] < hi:
            raise SpectrumError(f"spectrum {spectrum.name!r} covers {spectrum.span_m[0] * 1e9:g}-"
                                f"{spectrum.span_m[1] * 1e9:g} nm but band {self.name!r} spans {lo * 1e9:g}-"
                                f"{hi * 1e9:g} nm: give the spectrum over the whole band")
        m_ab = float(magnitude) + self.ab_minus_vega_mag
        return self.ab_zero_point_ph_s_m2() * 10.0 ** (-0.4 * m_ab) / count

    @property
    def span_m(self) -> tuple[float, float]:
        """Where the response exceeds 1 % of its peak [m]."""
        inside = GRID_M[self.response > 0.01]
        return float(inside[0]), float(inside[-1])


def _band_file(name: str) -> Path:
    return Path(str(resources.files("evstwin") / "data" / "bands" / name))


def _band_from_file(path: Path, name: str, ab_minus_vega_mag: float, source: str) -> Band:
    w_m, v, flags = _read_table(path, "band")
    if flags.get("energy_response", "").lower() == "true":
        v = v * w_m  # per unit energy -> per photon (Bessell & Murphy 2012)
    r = _tabulated(w_m, v)
    if not np.any(r > 0):
        raise SpectrumError(f"band file {str(path)!r} has no response between 300 and 1100 nm")
    response = r / r.max()
    response.flags.writeable = False  # band() is cached: one array for every caller
    return Band(name, response, ab_minus_vega_mag, source)


BANDS: dict[str, tuple[str, float, str]] = {
    "V": ("johnson_v.csv", 0.02,
          "Johnson V, Bessell (1990) PASP 102, 1181; V_AB - V_Vega = 0.02 (Blanton & Roweis 2007, AJ 133, 734, Table 1)"),
    "G": ("gaia_g.csv", 0.8010 - 0.6874,
          "Gaia G (DR3), Riello et al. (2021) A&A 649, A3; G_AB - G_Vega = 25.8010 - 25.6874 (the DR3 zero points)"),
}
"""Built-in bands: file, AB - Vega offset [mag], source."""
_BAND_ALIASES = {"v": "V", "johnson-v": "V", "johnson_v": "V", "g": "G", "gaia-g": "G", "gaia_g": "G"}


@functools.lru_cache(maxsize=64)
def band(name: str) -> Band:
    """A band by name (``V`` / ``johnson-v``, ``G`` / ``gaia-g``) or the path of a CSV of
    ``wavelength_nm,response`` per photon (its magnitudes are then taken as AB)."""
    if not isinstance(name, str) or not name.strip():
        raise SpectrumError(f"band must be V, G or the path of a .csv response; got {name!r}")
    key = _BAND_ALIASES.get(name.strip().lower())
    if key is not None:
        file, offset, source = BANDS[key]
        return _band_from_file(_band_file(file), key, offset, source)
    if name.strip().lower().endswith(".csv"):
        p = Path(name.strip())
        return _band_from_file(p, p.name, 0.0, f"user band {p.name} (AB magnitudes)")
    raise SpectrumError(f"band must be V, G or the path of a .csv response; got {name!r}")


@dataclass(frozen=True)
class QECurve:
    """A sensor's quantum efficiency: electrons per photon arriving on a pixel's area (fill
    factor and microlens included), against wavelength; ``source`` says where it comes from."""

    wavelength_m: tuple[float, ...]
    qe: tuple[float, ...]
    source: str

    def __post_init__(self) -> None:
        w = np.asarray(self.wavelength_m, np.float64)
        q = np.asarray(self.qe, np.float64)
        if (w.ndim != 1 or w.shape != q.shape or w.size < 2 or not np.all(np.isfinite(w)) or not np.all(np.isfinite(q))
                or np.any(np.diff(w) <= 0) or np.any(q < 0) or np.any(q > 1) or not np.any(q > 0)):
            raise SpectrumError("a QE curve needs increasing wavelengths and QE values in [0, 1], not all zero; got "
                                f"{len(self.wavelength_m)} wavelengths and {len(self.qe)} values")
        if w[0] < GRID_M[0] - 1e-12 or w[-1] > GRID_M[-1] + 1e-12:
            raise SpectrumError(f"a QE curve must lie within 300-1100 nm; got {w[0] * 1e9:g}-{w[-1] * 1e9:g} nm")

    def on_grid(self) -> np.ndarray:
        """QE on GRID_M (zero outside the curve)."""
        return _tabulated(np.asarray(self.wavelength_m), np.asarray(self.qe))

    @property
    def peak(self) -> float:
        """The curve's largest QE."""
        return float(max(self.qe))

    @property
    def span_m(self) -> tuple[float, float]:
        """Where QE exceeds 1 % of its peak [m]."""
        q = self.on_grid()
        inside = GRID_M[q > 0.01 * q.max()]
        return float(inside[0]), float(inside[-1])


def electrons_per_s_m2(spectrum: Spectrum, magnitude: float, band_: Band, qe: QECurve,
                       transmission: np.ndarray | None = None) -> float:
    """Electrons per second per m^2 of aperture from a source of ``spectrum`` with Vega
    ``magnitude`` in ``band_``, through a transmission curve on GRID_M (None: 1) onto ``qe``."""
    lo, hi = qe.span_m
    if spectrum.span_m[0] > lo or spectrum.span_m[1] < hi:
        raise SpectrumError(f"spectrum {spectrum.name!r} covers {spectrum.span_m[0] * 1e9:g}-{spectrum.span_m[1] * 1e9:g}"
                            f" nm but the sensor responds over {lo * 1e9:g}-{hi * 1e9:g} nm (its QE curve above 1 % of "
                            "peak): give the spectrum over that range")
    n = spectrum.photon_flux * band_.scale_for(spectrum, magnitude)
    t = 1.0 if transmission is None else transmission
    return float(_integrate(n * t * qe.on_grid(), GRID_M))


def zero_point_ph_s_m2(spectrum: Spectrum, band_: Band, qe: QECurve, electrons_per_photon: float,
                       transmission: np.ndarray | None = None) -> float:
    """What the engine should receive for magnitude 0 [photons/s/m^2 of aperture]: the
    electrons of :func:`electrons_per_s_m2` divided by the pixel's yield (so that the
    engine's photons times ``electrons_per_photon`` are those electrons). It replaces
    ``Optics.zero_point_ph_s_m2`` for that source on that sensor."""
    y = float(electrons_per_photon)
    if not (math.isfinite(y) and y > 0.0):
        raise SpectrumError(f"electrons_per_photon must be > 0; got {electrons_per_photon!r}")
    return electrons_per_s_m2(spectrum, 0.0, band_, qe, transmission) / y


def transmission_from_table(path: str | Path, what: str = "transmission") -> np.ndarray:
    """A transmission or filter curve on GRID_M from CSV rows ``wavelength_nm,T`` with T in
    [0, 1]; zero outside the table (a filter blocks what it does not list)."""
    p = Path(path)
    w_m, v, _ = _read_table(p, what)
    if np.any(v > 1.0):
        raise SpectrumError(f"{what} file {str(p)!r}: a transmission must be in [0, 1]; got up to {v.max():g}")
    return _tabulated(w_m, v)


# -- silicon and the eye -------------------------------------------------------------------------


@functools.cache
def _data_table(*parts: str) -> tuple[np.ndarray, np.ndarray]:
    path = Path(str(resources.files("evstwin").joinpath("data", *parts)))
    w_m, v, _ = _read_table(path, "data")
    w_m.flags.writeable = v.flags.writeable = False  # shared by every caller (cached)
    return w_m, v


def silicon_absorption_per_m(wavelength_m: float | np.ndarray) -> np.ndarray:
    """Absorption coefficient of crystalline silicon at 300 K [1/m] (Green 2008, Sol. Energy
    Mater. Sol. Cells 92, 1305; tabulated every 10 nm, log-interpolated), 300-1100 nm."""
    w_m, alpha_per_cm = _data_table("sensors", "silicon_absorption_green2008.csv")
    w = np.asarray(wavelength_m, np.float64)
    if np.any(w < w_m[0] - 1e-15) or np.any(w > w_m[-1] + 1e-15):
        raise SpectrumError(f"silicon's absorption is tabulated for {w_m[0] * 1e9:g}-{w_m[-1] * 1e9:g} nm; got "
                            f"{np.min(w) * 1e9:g}-{np.max(w) * 1e9:g} nm")
    return np.exp(np.interp(w, w_m, np.log(alpha_per_cm * 100.0)))


def silicon_qe_curve(optical_factor: float, collection_depth_m: float, source: str) -> QECurve:
    """QE of a silicon photodiode that collects the electrons freed within
    ``collection_depth_m`` of its surface: ``optical_factor (1 - exp(-alpha(lambda) d))``, the
    paper's eq. 2 with silicon's absorption spectrum in place of one alpha (optical_factor =
    fill factor x transmission x internal QE), every 10 nm from 300 to 1100 nm."""
    f, d = float(optical_factor), float(collection_depth_m)
    if not (math.isfinite(f) and 0.0 < f <= 1.0):
        raise SpectrumError(f"optical_factor must be in (0, 1]; got {optical_factor!r}")
    if not (math.isfinite(d) and 1e-8 <= d <= 1e-3):
        raise SpectrumError(f"collection_depth_m must be in [1e-8, 1e-3] m; got {collection_depth_m!r}")
    w = np.arange(300.0, 1100.0 + 1.0, 10.0) * 1e-9
    qe = f * -np.expm1(-silicon_absorption_per_m(w) * d)
    return QECurve(tuple(float(x) for x in w), tuple(float(x) for x in qe), source)


LUMINOUS_EFFICACY_LM_W = 683.0
"""Maximum luminous efficacy K_m [lm/W] at 555 nm (540 THz; the SI definition of the candela)."""


def photopic() -> np.ndarray:
    """The CIE 1924 photopic luminous efficiency V(lambda) on GRID_M (zero outside 380-780 nm)."""
    w_m, v = _data_table("photometry", "cie1924_photopic.csv")
    return _tabulated(w_m, v)


def photons_per_lumen(spectrum: Spectrum) -> float:
    """Photons per lumen of light with this spectrum's shape, counted over 300-1100 nm:
    one lux on a surface is this many photons per second per m^2. Lumens are
    ``K_m integral P(lambda) V(lambda) dlambda`` with P the spectral power (photons times
    h c / lambda)."""
    power = spectrum.photon_flux * PLANCK_J_S * SPEED_OF_LIGHT_M_S / GRID_M
    lumens = LUMINOUS_EFFICACY_LM_W * _integrate(power * photopic(), GRID_M)
    if not lumens > 0.0:
        raise SpectrumError(f"spectrum {spectrum.name!r} has no visible light (380-780 nm): lux are undefined")
    return _integrate(spectrum.photon_flux, GRID_M) / lumens


PHOTOMETRY_KEYS = ("band", "spectrum", "sky_spectrum", "transmission_file", "filter_file")
"""Keys of a scenario's ``[photometry]`` table (:class:`SensorResponse`)."""


class SensorResponse:
    """How magnitudes of a scene become the engine's photons on one sensor: a band, the
    default spectrum of its magnitude sources, the sky's spectrum, the optics' transmission
    curve and a filter, and the sensor's QE curve with the yield of the preset's pixel.

    :meth:`zero_point_ph_s_m2` is computed once per spectrum (cached). A pixel whose yield is
    changed afterwards (a ``[pixel]`` override of its fill factor, say) scales the QE curve by
    the same factor: the engine applies its own yield to these photons."""

    def __init__(self, qe: QECurve, reference_electrons_per_photon: float, band_name: str = "V",
                 spectrum: str = "sun", sky_spectrum: str = "night-sky", transmission_file: str | None = None,
                 filter_file: str | None = None) -> None:
        self.qe = qe
        self.yield_ = float(reference_electrons_per_photon)
        self.band = band(band_name)
        self.default_spectrum = spectrum
        self.sky_spectrum = sky_spectrum
        t = np.ones_like(GRID_M)
        if transmission_file is not None:
            t = t * transmission_from_table(transmission_file, "photometry.transmission_file")
        if filter_file is not None:
            t = t * transmission_from_table(filter_file, "photometry.filter_file")
        self.transmission = t
        self._cache: dict[str, float] = {}
        self.zero_point_ph_s_m2(spectrum)  # an unknown spectrum or band fails here, once
        self.zero_point_ph_s_m2(sky_spectrum)

    def zero_point_ph_s_m2(self, spectrum: str | None = None) -> float:
        """Engine photons/s/m^2 of aperture for magnitude 0 of ``spectrum`` (a name of
        :func:`spectrum_from_name`; None: the default) in the band."""
        name = self.default_spectrum if spectrum is None else spectrum
        if name not in self._cache:
            zp = zero_point_ph_s_m2(spectrum_from_name(name), self.band, self.qe, self.yield_, self.transmission)
            if not zp > 0.0:
                raise SpectrumError(f"spectrum {name!r} gives no electrons through the optics' transmission, the filter "
                                    "and the sensor's QE curve")
            self._cache[name] = zp
        return self._cache[name]
