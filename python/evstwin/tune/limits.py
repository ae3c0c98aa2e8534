"""``limiting_magnitude``: the faintest magnitude detected against angular rate.

For a real setup (:class:`Setup`: a lens, a sensor preset and its biases, a sky, the seeing,
the pointing) or any scenario whose first target becomes the mover. The rate is the target's
angular rate *relative to the stars*, along the sensor's +x axis (taken as east, the direction
of the GEO belt and of prograde orbits); the pointing sets how the target and the stars move on
the sensor (:class:`PointingDetectObjective`):

* ``sidereal``: the mount tracks the stars: stars at rest, the target moves at the rate;
* ``staring``: the mount is fixed to the ground: the stars drift west (-x) at the sidereal
  rate 15.041 arcsec/s x cos(declination), the target at its rate less that (a GEO object,
  at 15.041 arcsec/s relative to the stars at declination 0, is at rest);
* ``target``: the mount tracks the target: the target at rest, the stars drift at the rate (-x).

A target at rest on the sensor fires only through the atmosphere's scintillation and image
motion or the noise: it is measured as a static source (``static_detect_metrics``).
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .._checks import finite, positive
from ..constants import ARCSEC_PER_RAD
from ..optics import PAPER_F_NUMBER, PAPER_FOCAL_LENGTH_M
from ..scenario import build, load, parse_assignment, set_value
from ..sky.earth import EARTH_ROTATION_RAD_S
from ._types import PathLike
from .objectives import DetectObjective
from .sweep import SweepResult, _atomic_write_text, _csv_text, _fmt_num, sweep

DEFAULT_RATES_ARCSEC_S: tuple[float, ...] = (5.0, 15.04, 50.0, 150.0, 500.0)


"""Angular rates [arcsec/s]: slow drifts, GEO at the sidereal rate, MEO to LEO."""


DEFAULT_MAGNITUDES: tuple[float, ...] = (6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0)


"""Visual magnitudes (V zero point of :mod:`evstwin.optics`)."""


UNDETERMINED_CHANCE = 0.5
"""Where noise alone fires at least this share of the pixels in a track's time (the mean
``chance_fraction`` over the magnitudes of a rate), detection cannot be told from noise: the
rate's limit is "undetermined", not a magnitude."""

SIDEREAL_RATE_ARCSEC_S = EARTH_ROTATION_RAD_S * ARCSEC_PER_RAD
"""The stars' apparent rate at declination 0 [arcsec/s]: 360 deg per sidereal day (86164.0905 s)."""
POINTINGS = ("sidereal", "staring", "target")
"""Pointing modes of the limiting-magnitude map (module docstring)."""


def limiting_magnitude_scenario() -> dict[str, Any]:
    """The default scenario of :func:`limiting_magnitude`: ``geo-stare`` (0.5 m f/4 telescope,
    1.9 arcsec/px, silicon-like photodiode, 20 mag/arcsec^2 sky, its bias set) without the star
    field, on a 128 x 64 px window for 4 s, the satellite starting 4 px from the left edge."""
    s = load("geo-stare")
    s.pop("star_field", None)
    s["name"] = "limiting-magnitude"
    s["description"] = "geo-stare without stars, 128 x 64 px window: a linear mover across it"
    s["duration_s"] = 4.0
    s["sensor"] = dict(s["sensor"], width=128, height=64)
    s["targets"] = [
        {
            "kind": "linear",
            "label": "target",
            "x0_px": 4.0,
            "y0_px": 31.5,
            "wx_arcsec_s": 15.04,
            "wy_arcsec_s": 0.0,
            "magnitude": 8.0,
        }
    ]
    return load(s)


@dataclass(frozen=True)
class Setup:
    """A real observing setup for :func:`limiting_magnitude`: the scenario it stands for is
    :meth:`scenario` (a window of the sensor, the first target a linear mover).

    preset: a sensor preset name (``evstwin.presets.PRESETS``); bias_set: one of its bias sets
    (``BIAS_SETS``; None: the preset's own); focal_length_m; f_number or aperture_diameter_m
    (one at least; with both, the aperture sets the collecting area and the f-number the
    diffraction PSF); transmission: of the optics, (0, 1]; sky_mag_per_arcsec2: the sky's
    surface brightness (V; 21.9 dark site, 18 city); seeing_fwhm_arcsec: None = no atmosphere
    PSF; pointing: one of :data:`POINTINGS`; declination_deg: of the field, for the stars'
    drift when staring; width_px, height_px: the simulated window; duration_s; rate_hz:
    sampling floor; stars: an all-sky star field (``evstwin.sky.stars``) from stars_mag_min to
    stars_mag_max; jitter_rms_arcsec, jitter_tau_s, scintillation, site_altitude_m, airmass:
    the rest of ``[atmosphere]`` (``evstwin.sky.atmosphere``).
    """

    preset: str
    focal_length_m: float
    f_number: float | None = None
    aperture_diameter_m: float | None = None
    bias_set: str | None = None
    transmission: float = 0.8
    sky_mag_per_arcsec2: float = 21.0
    seeing_fwhm_arcsec: float | None = 2.0
    pointing: str = "sidereal"
    declination_deg: float = 0.0
    width_px: int = 128
    height_px: int = 64
    duration_s: float = 4.0
    rate_hz: float = 100.0
    stars: bool = True
    stars_mag_min: float = 4.0
    stars_mag_max: float = 14.0
    jitter_rms_arcsec: float = 0.0
    jitter_tau_s: float = 0.05
    scintillation: bool = False
    site_altitude_m: float = 0.0
    airmass: float = 1.0

    def __post_init__(self) -> None:
        from ..presets import PRESETS

        if not isinstance(self.preset, str) or self.preset.lower() not in PRESETS:
            raise ValueError(f"preset must be one of {', '.join(sorted(PRESETS))}; got preset={self.preset!r}")
        if self.pointing not in POINTINGS:
            raise ValueError(f"pointing must be one of {', '.join(POINTINGS)}; got pointing={self.pointing!r}")
        for name in ("focal_length_m", "duration_s", "rate_hz"):
            positive(name, getattr(self, name))
        if self.f_number is None and self.aperture_diameter_m is None:
            raise ValueError("give f_number or aperture_diameter_m (the lens); got neither")
        for name in ("f_number", "aperture_diameter_m", "seeing_fwhm_arcsec"):
            if getattr(self, name) is not None:
                positive(name, getattr(self, name))
        dec = finite("declination_deg", self.declination_deg)
        if not -90.0 < dec < 90.0:
            raise ValueError(f"declination_deg must be in (-90, 90); got declination_deg={self.declination_deg!r}")
        sky = finite("sky_mag_per_arcsec2", self.sky_mag_per_arcsec2)
        if not 10.0 <= sky <= 30.0:
            raise ValueError(f"sky_mag_per_arcsec2 must be in [10, 30]; got sky_mag_per_arcsec2={self.sky_mag_per_arcsec2!r}")
        for name in ("width_px", "height_px"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not 16 <= v <= 4096:
                raise ValueError(f"{name} must be an integer in [16, 4096]; got {name}={v!r}")

    @property
    def f_ratio(self) -> float:
        """The f-number the optics get: f_number, else focal length / aperture."""
        return float(self.f_number) if self.f_number is not None else self.focal_length_m / float(self.aperture_diameter_m)  # type: ignore[arg-type]

    def scenario(self) -> dict[str, Any]:
        """The scenario (resolved) this setup stands for; the target starts 4 px from the left
        edge, mid-height, at 15.04 arcsec/s and magnitude 8 (both set per grid point)."""
        sensor: dict[str, Any] = {"preset": self.preset.lower(), "width": self.width_px, "height": self.height_px}
        if self.bias_set is not None:
            sensor["bias_set"] = self.bias_set
        optics: dict[str, Any] = {"focal_length_m": self.focal_length_m, "f_number": self.f_ratio,
                                  "transmission": self.transmission}
        if self.aperture_diameter_m is not None:
            optics["aperture_diameter_m"] = self.aperture_diameter_m
        s: dict[str, Any] = {
            "name": "limiting-magnitude-setup",
            "description": self.describe(),
            "duration_s": self.duration_s,
            "sensor": sensor,
            "optics": optics,
            "background": {"sky_mag_per_arcsec2": self.sky_mag_per_arcsec2},
            "sampling": {"rate_hz": self.rate_hz},
            "targets": [{"kind": "linear", "label": "target", "x0_px": 4.0, "y0_px": (self.height_px - 1) / 2,
                         "wx_arcsec_s": 15.04, "wy_arcsec_s": 0.0, "magnitude": 8.0}],
        }
        if self.stars:
            s["star_field"] = {"distribution": "all-sky", "mag_min": self.stars_mag_min, "mag_max": self.stars_mag_max,
                               "seed": 1}
        atm: dict[str, Any] = {}
        if self.seeing_fwhm_arcsec is not None:
            atm["seeing_fwhm_arcsec"] = self.seeing_fwhm_arcsec
        if self.jitter_rms_arcsec > 0.0:
            atm.update(jitter_rms_arcsec=self.jitter_rms_arcsec, jitter_tau_s=self.jitter_tau_s)
        if self.scintillation:
            atm.update(scintillation=True, site_altitude_m=self.site_altitude_m, airmass=self.airmass)
        if atm:
            s["atmosphere"] = atm
        return load(s)

    def describe(self) -> str:
        """One line naming the setup (the figure's title)."""
        from ..presets import get_preset

        preset = get_preset(self.preset)
        d = self.aperture_diameter_m if self.aperture_diameter_m is not None else self.focal_length_m / self.f_ratio
        scale = preset.pixel_pitch_m / self.focal_length_m * ARCSEC_PER_RAD
        bias = f", biases {self.bias_set}" if self.bias_set else ""
        seeing = "no seeing" if self.seeing_fwhm_arcsec is None else f"seeing {self.seeing_fwhm_arcsec:g}\""
        extra = (f", jitter {self.jitter_rms_arcsec:g}\"" if self.jitter_rms_arcsec > 0 else "") + (
            ", scintillation" if self.scintillation else "")
        return (f"{preset.name}{bias}; {self.focal_length_m * 1e3:g} mm f/{self.f_ratio:.3g} (D {d * 1e3:.3g} mm), "
                f"{scale:.3g}\"/px; sky {self.sky_mag_per_arcsec2:g} mag/arcsec2, {seeing}{extra}; {self.pointing} "
                f"pointing, dec {self.declination_deg:g} deg")


def static_detect_metrics(events: np.ndarray, width: int, height: int, duration_s: float, x_px: float, y_px: float,
                          radius_px: float = 1.0, exclude_px: float = 3.0) -> dict[str, float]:
    """The :class:`DetectObjective` metrics for a source at rest at (x_px, y_px): its "track
    pixels" are the core pixels whose square lies within ``radius_px`` (Chebyshev) of it, each
    watched for the whole run; ``track_fraction`` is the share of them with an event,
    ``chance_fraction`` the share noise alone fires in that time, measured directly: the share
    of the pixels farther than ``exclude_px`` from the core (stars included) with an event (a
    hot pixel or a streaking star adds its pixels, not its rate spread over all of them),
    ``excess_fraction`` = (track - chance) / (1 - chance), ``snr`` the core's event rate per
    pixel over the noise's; latency: nan (nothing enters)."""
    xs = np.arange(width)
    ys = np.arange(height)
    core_x = xs[np.abs(xs - x_px) <= 0.5 + radius_px]
    core_y = ys[np.abs(ys - y_px) <= 0.5 + radius_px]
    core = np.zeros((height, width), dtype=bool)
    core[np.ix_(core_y, core_x)] = True
    far_x = np.abs(xs - x_px) > 0.5 + radius_px + exclude_px
    far_y = np.abs(ys - y_px) > 0.5 + radius_px + exclude_px
    noise = far_y[:, None] | far_x[None, :]
    ek = events["y"].astype(np.int64) * width + events["x"].astype(np.int64)
    n_core = int(core.sum())
    fired = np.zeros(width * height, dtype=bool)
    fired[ek] = True
    track_fraction = float(fired[core.reshape(-1)].mean()) if n_core else math.nan
    n_noise_px = int(noise.sum())
    n_noise_ev = int(np.count_nonzero(noise.reshape(-1)[ek]))
    noise_rate = n_noise_ev / (n_noise_px * duration_s) if n_noise_px and duration_s > 0 else math.nan
    n_sig = int(np.count_nonzero(core.reshape(-1)[ek]))
    signal_rate = n_sig / (n_core * duration_s) if n_core and duration_s > 0 else math.nan
    chance = float(fired[noise.reshape(-1)].mean()) if n_noise_px else math.nan
    excess = (track_fraction - chance) / (1.0 - chance) if math.isfinite(chance) and chance < 1.0 else math.nan
    snr = signal_rate / noise_rate if noise_rate > 0 else (math.inf if signal_rate > 0 else math.nan)
    return {
        "track_fraction": track_fraction, "excess_fraction": float(excess), "chance_fraction": chance,
        "track_events_per_s": n_sig / duration_s if duration_s > 0 else math.nan,
        "signal_rate_per_px_hz": signal_rate, "noise_rate_per_px_hz": noise_rate, "snr": float(snr),
        "latency_median_s": math.nan, "track_px": float(n_core),
    }


class PointingDetectObjective(DetectObjective):
    """The ``detect`` objective of a target whose rate relative to the stars is
    ``targets.0.wx_arcsec_s``, under a pointing (module docstring): ``prepare`` turns that rate
    into the target's and the star field's motion on the sensor; a target that moves less than
    1 px over the run is measured as a static source (:func:`static_detect_metrics`)."""

    def __init__(self, pointing: str = "sidereal", declination_deg: float = 0.0, target: str | None = None,
                 radius_px: float = 1.0, tail_s: float = 0.1, exclude_px: float = 3.0) -> None:
        super().__init__(target=target, radius_px=radius_px, tail_s=tail_s, exclude_px=exclude_px)
        if pointing not in POINTINGS:
            raise ValueError(f"pointing must be one of {', '.join(POINTINGS)}; got pointing={pointing!r}")
        dec = finite("declination_deg", declination_deg)
        if not -90.0 < dec < 90.0:
            raise ValueError(f"declination_deg must be in (-90, 90); got declination_deg={declination_deg!r}")
        self.pointing = pointing
        self.stars_arcsec_s = SIDEREAL_RATE_ARCSEC_S * math.cos(math.radians(dec))
        """The stars' drift rate when staring [arcsec/s]."""

    def motion(self, rate_arcsec_s: float) -> tuple[float, float]:
        """(target, stars) rates on the sensor along x [arcsec/s] for a rate relative to the stars."""
        if self.pointing == "sidereal":
            return rate_arcsec_s, 0.0
        if self.pointing == "staring":
            return rate_arcsec_s - self.stars_arcsec_s, -self.stars_arcsec_s
        return 0.0, -rate_arcsec_s

    def prepare(self, scenario: dict[str, Any]) -> dict[str, Any]:
        s = copy.deepcopy(scenario)
        target = s["targets"][0]
        rate = float(target["wx_arcsec_s"])
        on_sensor, stars = self.motion(rate)
        width = int(build_size(s)[0])
        target["wx_arcsec_s"] = on_sensor
        x0 = float(target.get("x0_px", 4.0))
        # At rest: mid-sensor; moving left (staring slower than the stars): mirrored start.
        target["x0_px"] = (width - 1) / 2 if self.pointing == "target" else (x0 if on_sensor >= 0 else width - 1 - x0)
        sf = s.setdefault("star_field", {})
        sf.pop("drift_px_s", None)
        if stars != 0.0:
            sf["drift_arcsec_s"] = [stars, 0.0]
        else:
            sf.pop("drift_arcsec_s", None)
        if not sf:
            s.pop("star_field")
        return load(s)

    def _at_rest(self, scenario: Mapping[str, Any]) -> bool:
        t = scenario["targets"][0]
        plate = _plate_arcsec(scenario)
        return abs(float(t.get("wx_arcsec_s", 0.0))) / plate * float(scenario["duration_s"]) < 1.0

    def check(self, scene: Any) -> None:
        if not self._at_rest(scene.scenario):
            super().check(scene)

    def evaluate(self, result: Any) -> dict[str, float]:
        scenario = result.meta["scenario"]
        if not self._at_rest(scenario):
            return super().evaluate(result)
        t = scenario["targets"][0]
        return static_detect_metrics(result.events, int(result.meta["width"]), int(result.meta["height"]),
                                     float(result.meta["duration_s"]), float(t["x0_px"]), float(t["y0_px"]),
                                     self.radius_px, self.exclude_px)


def build_size(scenario: dict[str, Any]) -> tuple[int, int]:
    """(width, height) of a scenario's sensor window [px], without building its targets."""
    from ..presets import get_preset

    preset = get_preset(scenario["sensor"]["preset"])
    return int(scenario["sensor"].get("width", preset.width)), int(scenario["sensor"].get("height", preset.height))


def _plate_arcsec(scenario: Mapping[str, Any]) -> float:
    """The plate scale [arcsec/px] of a (resolved) scenario's optics, as ``build`` makes them."""
    from ..presets import get_preset

    preset = get_preset(scenario["sensor"]["preset"])
    kw = dict(scenario.get("optics", {}))
    optics = preset.optics(kw.pop("focal_length_m", PAPER_FOCAL_LENGTH_M), kw.pop("f_number", PAPER_F_NUMBER), **kw)
    return float(optics.plate_scale_arcsec_per_px)


def _as_linear_mover(scenario: dict[str, Any]) -> dict[str, Any]:
    """The scenario with its first target made a linear mover (rate and magnitude set later),
    keeping its start position if it has one, else 4 px from the left edge, mid-height."""
    s = dict(scenario)
    sc = build(s)
    targets = list(s.get("targets", []))
    old = dict(targets[0]) if targets else {}
    new = {
        "kind": "linear",
        "label": str(old.get("label", "target")),
        "x0_px": float(old.get("x0_px", 4.0)),
        "y0_px": float(old.get("y0_px", (sc.height - 1) / 2)),
        "wx_arcsec_s": 15.04,
        "wy_arcsec_s": 0.0,
        "magnitude": float(old.get("magnitude", 8.0)),
    }
    s["targets"] = [new] + targets[1:]
    return load(s)


@dataclass
class LimitingMagnitudeResult:
    """The faintest magnitude meeting the criterion at each angular rate.

    ``table``: one row per rate: rate_arcsec_s (relative to the stars), rate_px_s (the same
    through the plate scale), target_px_s and stars_px_s (their motion on the sensor under the
    pointing), limiting_magnitude (nan when there is none), the criterion metric's mean at the
    limit, chance_fraction (the share of pixels noise alone fires in a track's time, mean over
    the magnitudes) and status: ``limit``, ``none`` (even the brightest magnitude fails) or
    ``undetermined`` (chance_fraction >= ``UNDETERMINED_CHANCE``: noise fires most pixels, so
    no magnitude can be told detected). The limit is the faintest magnitude reached going
    from bright to faint before the first that fails (a noise-dependent miss does not let a
    fainter success count). ``setup``: one line naming the setup (the figure's title)."""

    criterion: tuple[str, float]
    table: list[dict[str, Any]]
    sweep: SweepResult
    table_path: Path | None = None
    figure_path: Path | None = None
    setup: str = ""
    pointing: str = "sidereal"

    def criterion_text(self) -> str:
        """The detection criterion in words."""
        metric, threshold = self.criterion
        what = {
            "excess_fraction": "the share of the track's pixels that fire while the target is on them, beyond the "
                               "share noise elsewhere (stars included) fires in the same time",
            "track_fraction": "the share of the track's pixels that fire while the target is on them",
            "snr": "the event rate per pixel on the track over the rate elsewhere",
        }.get(metric, metric)
        return (f"detected: mean {metric} >= {threshold:g} over {self.sweep.runs} seed(s) ({what}; a target at rest "
                "on the sensor: its core pixels within 1 px, over the run)")

    def to_text(self) -> str:
        metric, threshold = self.criterion
        lines = [f"setup: {self.setup}"] if self.setup else []
        lines += [
            f"{'rate [arcsec/s]':>16}  {'rate [px/s]':>11}  {'target [px/s]':>13}  {'stars [px/s]':>12}  "
            f"{'limiting mag':>12}  {metric + ' at limit':>24}",
            "-" * 97,
        ]
        for r in self.table:
            limit = {"undetermined": "undetermined", "none": "none"}.get(str(r["status"]),
                                                                         _fmt_num(r["limiting_magnitude"]))
            lines.append(
                f"{r['rate_arcsec_s']:16.4g}  {r['rate_px_s']:11.4g}  {r['target_px_s']:13.4g}  {r['stars_px_s']:12.4g}  "
                f"{limit:>12}  {_fmt_num(r['metric_at_limit']):>24}"
            )
        if any(r["status"] == "undetermined" for r in self.table):
            lines.append(f"undetermined: noise alone fires >= {UNDETERMINED_CHANCE:g} of the pixels in a track's time "
                         "(chance_fraction): raise the thresholds or lower the noise")
        lines.append(f"pointing: {self.pointing} (rates relative to the stars)")
        lines.append(f"criterion: {self.criterion_text()}")
        return "\n".join(lines)


def limiting_magnitude(
    scenario: str | Path | dict | None = None,
    rates_arcsec_s: Sequence[float] = DEFAULT_RATES_ARCSEC_S,
    magnitudes: Sequence[float] = DEFAULT_MAGNITUDES,
    runs: int = 1,
    criterion: tuple[str, float] = ("excess_fraction", 0.5),
    out_dir: PathLike | None = None,
    resume: bool = False,
    scheduler: Any = None,
    workers: int | None = None,
    seed: int = 0,
    sets: Sequence[str] = (),
    duration_s: float | None = None,
    progress: bool = False,
    setup: Setup | None = None,
    pointing: str = "sidereal",
    declination_deg: float = 0.0,
) -> LimitingMagnitudeResult:
    """Limiting magnitude against angular rate for the scenario's bias configuration.

    setup: a real :class:`Setup` (lens, preset and biases, sky, seeing, pointing) in place of
    ``scenario`` (give one of them); its pointing and declination are used. pointing,
    declination_deg: for a scenario (module docstring; the scenario's star field, if any,
    drifts as the pointing says). Rates are relative to the stars.

    The scenario's first target becomes a linear mover along +x (``targets.0.wx_arcsec_s``)
    and a ``detect`` sweep runs over (rate, magnitude) x runs seeds; the criterion is
    ``mean(metric) >= threshold`` with a :class:`DetectObjective` metric. Default criterion:
    ``excess_fraction >= 0.5`` -- half the track's pixels fire, after correcting for those
    noise alone would fire (``track_fraction`` counts noise as detection, which makes a
    noisy bias look sensitive). scenario None: :func:`limiting_magnitude_scenario`.
    out_dir: the sweep's files plus ``limiting_magnitude.csv`` and ``limiting_magnitude.png``.
    """
    metric, threshold = criterion
    if metric not in DetectObjective.metrics:
        raise ValueError(
            f"criterion metric must be one of {', '.join(DetectObjective.metrics)}; got {metric!r}"
        )
    rates = [float(r) for r in rates_arcsec_s]
    mags = sorted(float(m) for m in magnitudes)
    if not rates or not mags:
        raise ValueError("limiting magnitude needs at least one rate and one magnitude")
    bad = [r for r in rates if not (math.isfinite(r) and r > 0)]
    if bad:
        raise ValueError(f"rates-arcsec-s must be finite and > 0; got {bad}")
    if setup is not None:
        if scenario is not None:
            raise ValueError("give a scenario or a setup, not both")
        pointing, declination_deg = setup.pointing, setup.declination_deg
        base = setup.scenario()
    else:
        base = load(limiting_magnitude_scenario() if scenario is None else scenario)
    objective = PointingDetectObjective(pointing, declination_deg)
    for text in sets:
        k, v = parse_assignment(text)
        base = set_value(base, k, v)
    base = _as_linear_mover(base)
    label = base["targets"][0]["label"]
    names = [t.get("label") for t in base["targets"]]
    if names.count(label) > 1:
        raise ValueError(f"target label {label!r} is not unique: give the targets distinct labels")
    objective.target = label
    grid = {"targets.0.wx_arcsec_s": rates, "targets.0.magnitude": mags}
    job_seconds = None
    if progress:
        # The estimate printed before the run: one job timed here, the fastest rate (the most
        # sub-sampling) and the brightest magnitude (the most events): the slowest point.
        from .execution import evaluate

        slowest: dict[str, Any] = {"targets.0.wx_arcsec_s": max(rates), "targets.0.magnitude": mags[0]}
        if duration_s is not None:
            slowest["duration_s"] = float(duration_s)
        t0 = time.perf_counter()
        try:
            evaluate(base, slowest, seed, objective)
            job_seconds = time.perf_counter() - t0
        except ValueError:
            job_seconds = None  # the sweep checks every point first and says what is wrong
    result = sweep(
        base,
        grid,
        objective=objective,
        runs=runs,
        out_dir=out_dir,
        resume=resume,
        scheduler=scheduler,
        workers=workers,
        duration_s=duration_s,
        seed=seed,
        progress=progress,
        job_seconds=job_seconds,
    )
    plate_arcsec = build(base).optics.plate_scale_arcsec_per_px
    setup_text = setup.describe() if setup is not None else f"scenario {base['name']}; {pointing} pointing"
    if sets:
        setup_text += "; " + ", ".join(sets)
    table: list[dict[str, Any]] = []
    for rate in rates:
        rows = {
            float(r["targets.0.magnitude"]): r for r in result.summary if r["targets.0.wx_arcsec_s"] == rate
        }
        limit, at_limit = math.nan, math.nan
        for m in mags:
            value = rows[m][f"mean_{metric}"]
            if not (rows[m]["runs"] > 0 and value >= threshold):
                break
            limit, at_limit = m, value
        chances = [rows[m]["mean_chance_fraction"] for m in mags if rows[m]["runs"] > 0]
        chance = float(np.nanmean(chances)) if chances and np.any(np.isfinite(chances)) else math.nan
        if math.isfinite(chance) and chance >= UNDETERMINED_CHANCE:
            status, limit, at_limit = "undetermined", math.nan, math.nan
        else:
            status = "limit" if math.isfinite(limit) else "none"
        on_sensor, stars = objective.motion(rate)
        table.append(
            {
                "rate_arcsec_s": rate,
                "rate_px_s": rate / plate_arcsec,
                "target_px_s": on_sensor / plate_arcsec,
                "stars_px_s": stars / plate_arcsec,
                "limiting_magnitude": limit,
                "metric_at_limit": at_limit,
                "chance_fraction": chance,
                "status": status,
            }
        )
    out = LimitingMagnitudeResult(criterion=(metric, float(threshold)), table=table, sweep=result, setup=setup_text,
                                  pointing=pointing)
    if out_dir is not None:
        o = Path(out_dir)
        out.table_path = o / "limiting_magnitude.csv"
        _atomic_write_text(
            out.table_path,
            _csv_text(["rate_arcsec_s", "rate_px_s", "target_px_s", "stars_px_s", "limiting_magnitude",
                       "metric_at_limit", "chance_fraction", "status"], table),
        )
    return out


def parse_float_list(text: str, what: str) -> list[float]:
    """'1,2,3' or 'lo:hi:step' (inclusive) -> floats; ValueError naming the argument."""
    text = text.strip()
    try:
        if ":" in text and "," not in text:
            parts = [float(p) for p in text.split(":")]
            if len(parts) != 3 or not parts[2] > 0 or parts[1] < parts[0]:
                raise ValueError
            n = math.floor((parts[1] - parts[0]) / parts[2] + 1e-9) + 1
            return [round(parts[0] + k * parts[2], 10) for k in range(n)]
        values = [float(p) for p in text.split(",") if p.strip()]
    except ValueError:
        raise ValueError(f"{what} takes numbers v1,v2,... or lo:hi:step; got {text!r}") from None
    if not values or not all(math.isfinite(v) for v in values):
        raise ValueError(f"{what} takes finite numbers v1,v2,... or lo:hi:step; got {text!r}")
    return values
