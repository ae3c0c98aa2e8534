"""The characterisation bench: the twin of a preset through the tests event-sensor vendors
publish, beside the published figures.

A small array (``size_px`` square) of the preset's pixels under uniform light of a warm-white
source (a 3000 K black body: Prophesee characterises its sensors with a 3000 K warm-white LED,
light given at the focal plane, "Event-Based Vision sensor characteristics", Prophesee
knowledge base) at illuminances from 0.01 to 10,000 lux:

* **background activity**: events per pixel per second under steady light;
* **latency**: after the light doubles (a +100 % step, ln 2 = 0.69 in log units, about three
  thresholds of the presets), the median and 90th percentile over pixels of the first ON
  event's delay;
* **response** and **low-light cutoff**: the share of pixels that fire ON within
  ``RESPONSE_WINDOW_S`` of the step, beyond what the background fires in that time; the cutoff
  is the illuminance at which half respond (log-interpolated between the grid's points);
* **contrast sensitivity**: at ``CONTRAST_LUX`` the share of pixels that fire ON after steps of
  increasing contrast; the contrast threshold is the step at which half respond. The leak is
  paused for this test: it sets each pixel's reference at a random point of its cycle (up to a
  whole threshold away), so a small step would fire the pixels the leak brought close, which
  is not what a contrast threshold measures.

``biases`` (``evstwin characterize PRESET --bias bias_diff_on=+40``) runs the bench on a Prophesee
preset's pixel at other settings of the vendor's biases (``SensorPreset.vendor_biases``); the
published figures beside it are the vendor's for its default biases.

Lux become the engine's photons through the source's spectrum and the preset's QE curve
(``evstwin.spectra.photons_per_lumen``); a preset without a curve (``davis346_paper``) counts
the photons between 300 and 1100 nm.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from . import spectra
from ._checks import integer
from .presets import VENDOR_BIAS_PRESETS, SensorPreset, get_preset
from .sensor import Sensor

BENCH_SPECTRUM = "blackbody:3000"
"""The bench's light: a 3000 K black body for Prophesee's 3000 K warm-white LED."""
DEFAULT_LUX: tuple[float, ...] = (0.01, 0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 100.0, 1000.0, 10000.0)
"""Illuminances at the focal plane [lux]."""
STEP_FACTOR = 2.0
"""The latency and response step: the light doubles."""
RESPONSE_WINDOW_S = 0.5
"""How long after the step a pixel may take to count as responding [s]."""
SETTLE_S = 0.5
"""Steady light before anything is measured [s] (the pixels' start-up transient)."""
BACKGROUND_S = 10.0
"""Steady light over which the background is counted [s] (sampled every 10 ms: the light is
constant and the continuous noise model does not depend on the sampling)."""
MAX_SIZE_PX = 128
"""Largest bench array a side [px] (its frames after the step take 600 x size^2 x 8 bytes)."""
CONTRAST_LUX = 1000.0
"""Illuminance of the contrast-sensitivity steps [lux]."""
CONTRAST_STEPS: tuple[float, ...] = (0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.5, 0.6, 0.8, 1.0)
"""Contrast steps (Weber: (L_after - L_before) / L_before)."""


@dataclass(frozen=True)
class PublishedFigure:
    """A figure a vendor or a paper publishes, to set beside the twin's."""

    quantity: str
    """One of ``latency_s``, ``low_light_cutoff_lux``, ``contrast_threshold``."""
    value: float
    condition: str
    source: str
    kind: str
    """datasheet, vendor-doc, paper-measured or secondary (quoted by another source)."""


PUBLISHED: dict[str, tuple[PublishedFigure, ...]] = {
    "imx636": (
        PublishedFigure("latency_s", 100e-6, "below, at 1000 lux", "Prophesee, IMX636 product brief (2024) and EVK4 "
                        "page: '<100 us @ 1000 lux', as quoted by public notes", "secondary"),
        PublishedFigure("low_light_cutoff_lux", 0.08, "", "a camera datasheet of the IMX646 (the IMX636's 4.86 um "
                        "sibling): 'low light cutoff 0.08 lux'", "secondary"),
        PublishedFigure("contrast_threshold", 0.25, "nominal", "the same IMX646 camera datasheet: 'Nominal contrast "
                        "threshold 25 %'", "secondary"),
    ),
    "prophesee_gen3_vga": (
        PublishedFigure("latency_s", 200e-6, "typical, illuminance not stated", "CenturyArks SilkyEvCam-USB "
                        "specification Rev 1.02 (PPS3MVCD), Table 1: 'Typical Latency 200us'", "secondary"),
    ),
}
"""Published figures per preset, and which set the preset (calibration) or only check it
(validation): the IMX636's thresholds average ln(1.25), its 25 % CT (calibration); its source
follower comes from a recording, so its latency and low-light cutoff are validation. The Gen3
VGA's source follower is calibrated on its 200 us latency (``presets.GEN3_VGA_CUTOFF_HZ``)."""
CALIBRATED: dict[str, tuple[str, ...]] = {"imx636": ("contrast_threshold",), "prophesee_gen3_vga": ("latency_s",)}
"""Published quantities a preset was set from: the bench marks them 'calibration', the rest 'validation'."""


@dataclass
class CharacterizationResult:
    """The twin's figures on the bench (see the module doc), per illuminance."""

    preset: str
    lux: list[float]
    photons_per_px_s: list[float]
    """The engine's photons per pixel per second at each illuminance."""
    background_hz: list[float]
    """Events per pixel per second under steady light."""
    latency_median_s: list[float]
    latency_p90_s: list[float]
    response_fraction: list[float]
    low_light_cutoff_lux: float
    """Where half the pixels respond [lux]; -inf: below the grid's lowest, nan: above its highest."""
    contrast_lux: float
    contrasts: list[float]
    contrast_response: list[float]
    contrast_threshold: float
    size_px: int
    seed: int
    published: list[dict[str, Any]] = field(default_factory=list)
    biases: dict[str, float] = field(default_factory=dict)
    """The vendor's biases set away from the preset's (empty: its defaults)."""

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def twin_value(self, quantity: str, condition_lux: float | None = None) -> float:
        """The twin's figure comparable with a published ``quantity``."""
        if quantity == "low_light_cutoff_lux":
            return self.low_light_cutoff_lux
        if quantity == "contrast_threshold":
            return self.contrast_threshold
        if quantity == "latency_s":
            lux = 1000.0 if condition_lux is None else condition_lux
            i = int(np.argmin(np.abs(np.log10(np.array(self.lux)) - math.log10(lux))))
            return self.latency_median_s[i]
        raise ValueError(f"unknown quantity {quantity!r}")

    def to_text(self) -> str:
        lines = [f"characterisation of {self.preset} ({self.size_px} x {self.size_px} pixels, seed {self.seed}; "
                 f"light: {BENCH_SPECTRUM}, at the focal plane)"
                 + ("" if not self.biases else "; biases " + ", ".join(f"{k}={v:g}" for k, v in self.biases.items())),
                 f"{'lux':>9}  {'photons/px/s':>12}  {'background [Hz/px]':>18}  {'latency median':>14}  "
                 f"{'latency p90':>11}  {'respond':>7}",
                 "-" * 82]
        for i, lux in enumerate(self.lux):
            lines.append(f"{lux:9.3g}  {self.photons_per_px_s[i]:12.3g}  {self.background_hz[i]:18.3g}  "
                         f"{_fmt_s(self.latency_median_s[i]):>14}  {_fmt_s(self.latency_p90_s[i]):>11}  "
                         f"{self.response_fraction[i]:7.2f}")
        lines.append(f"low-light cutoff (half the pixels fire within {RESPONSE_WINDOW_S:g} s of a x{STEP_FACTOR:g} "
                     f"step): {_fmt_lux(self.low_light_cutoff_lux, self.lux[0])}")
        lines.append(f"contrast threshold at {self.contrast_lux:g} lux (half the pixels fire ON): "
                     f"{_fmt_pct(self.contrast_threshold, self.contrasts[0])}")
        if self.published:
            lines.append("published figures beside the twin's"
                         + (" (the vendor's, at its default biases):" if self.biases else ":"))
            for p in self.published:
                lines.append(f"  {p['quantity']:<22} published {p['value']:<9.3g} ({p['condition'] or 'no condition'}) "
                             f"twin {p['twin']:.3g}  ratio {p['ratio']:.2f}  ({p['role']}) [{p['kind']}] {p['source']}")
        return "\n".join(lines)


def _fmt_s(value: float) -> str:
    if not math.isfinite(value):
        return "none"
    return f"{value * 1e6:.0f} us" if value < 1e-2 else f"{value * 1e3:.1f} ms"


def _fmt_lux(value: float, lowest: float) -> str:
    if value == -math.inf:
        return f"below {lowest:g} lux (half respond at the grid's lowest: give lower --lux)"
    return f"{value:.3g} lux" if math.isfinite(value) else "not reached in the grid"


def _fmt_pct(value: float, lowest: float) -> str:
    if value == -math.inf:
        return f"below {lowest * 100:g} % (the smallest step tried)"
    return f"{value * 100:.1f} %" if math.isfinite(value) else "not reached"


def photons_per_px_s(preset: SensorPreset, lux: float, spectrum: str = BENCH_SPECTRUM) -> float:
    """The engine's photon rate on one pixel [photons/s] under ``lux`` at the focal plane of
    light with ``spectrum``: photons per lumen over the pixel's area, weighted by the preset's
    QE curve relative to its pixel's yield (so the engine's yield gives the curve's electrons)."""
    if not (math.isfinite(lux) and lux >= 0.0):
        raise ValueError(f"lux must be finite and >= 0; got {lux!r}")
    s = spectra.spectrum_from_name(spectrum)
    per_lumen = spectra.photons_per_lumen(s)
    area = preset.pixel_pitch_m**2
    if preset.qe is None:
        return float(lux * per_lumen * area)
    n = s.photon_flux / float(np.sum(s.photon_flux))  # shape: photons per grid step, summing to 1
    weighted = float(np.sum(n * preset.qe.on_grid())) / preset.pixel.electrons_per_photon
    return float(lux * per_lumen * area * weighted)


def _first_on_after(events: np.ndarray, n_px: int, width: int, t0_s: float, t1_s: float) -> np.ndarray:
    """Per pixel, the first ON event's time in [t0_s, t1_s) [s], inf where none."""
    t = events["t"].astype(np.float64) * 1e-6
    sel = (events["p"] == 1) & (t >= t0_s) & (t < t1_s)
    k = events["y"][sel].astype(np.int64) * width + events["x"][sel].astype(np.int64)
    first = np.full(n_px, np.inf)
    np.minimum.at(first, k, t[sel])
    return first


def _run_step(preset: SensorPreset, rate: float, factor: float, size_px: int, seed: int,
              num_threads: int | None, leak: bool = True) -> tuple[float, np.ndarray, float]:
    """(background events per pixel per second, per-pixel first-ON delays after the step [s]
    (inf: none within the window), the background ON rate [Hz per pixel]) of one illuminance."""
    params = preset.pixel if leak else preset.pixel.replace(leak_rate_hz=0.0, leak_photocurrent_hz_per_a=0.0)
    sensor = Sensor(size_px, size_px, params, seed=seed, num_threads=num_threads)
    dt = 1e-3
    t_step = SETTLE_S + BACKGROUND_S
    before = np.arange(0.0, t_step - 5e-3, 1e-2)
    before = np.append(before, t_step - 1e-6)  # the light rises over the last microsecond
    after = t_step + np.concatenate([[0.0], np.arange(1e-5, 1e-3, 1e-5), np.arange(1e-3, RESPONSE_WINDOW_S + 1e-9, dt)])
    t_s = np.concatenate([before, after])
    rates = np.where(t_s < t_step, rate, rate * factor)
    frames = np.broadcast_to(rates[:, None, None], (t_s.size, size_px, size_px)).astype(np.float64)
    events = sensor.run(np.ascontiguousarray(frames), t_s)
    n_px = size_px * size_px
    t = events["t"].astype(np.float64) * 1e-6
    steady = (t >= SETTLE_S) & (t < t_step)
    background = float(np.count_nonzero(steady)) / (n_px * BACKGROUND_S)
    on_background = float(np.count_nonzero(steady & (events["p"] == 1))) / (n_px * BACKGROUND_S)
    first = _first_on_after(events, n_px, size_px, t_step - 0.5e-6, t_step + RESPONSE_WINDOW_S)
    return background, first - (t_step - 0.5e-6), on_background


def _responding(delays: np.ndarray, on_background_hz: float) -> float:
    """Share of pixels that fired ON after the step beyond the share the background's ON events
    would fire in the window (Poisson), corrected as the detect objective's excess fraction."""
    fired = float(np.mean(np.isfinite(delays)))
    chance = 1.0 - math.exp(-on_background_hz * RESPONSE_WINDOW_S)
    return (fired - chance) / (1.0 - chance) if chance < 1.0 else math.nan


def _half_point(x: Sequence[float], y: Sequence[float], log_x: bool) -> float:
    """The first x at which y reaches 0.5 going up the grid, interpolated (in log x if asked);
    nan if it never does; -inf if it already does at the grid's first point (below the grid)."""
    for i, v in enumerate(y):
        if math.isfinite(v) and v >= 0.5:
            if i == 0:
                return -math.inf
            x0, x1, y0 = x[i - 1], x[i], y[i - 1]
            y0 = y0 if math.isfinite(y0) else 0.0
            f = (0.5 - y0) / (v - y0) if v != y0 else 0.0
            if log_x:
                return float(10 ** (math.log10(x0) + f * (math.log10(x1) - math.log10(x0))))
            return float(x0 + f * (x1 - x0))
    return math.nan


def characterize(preset: str | SensorPreset, lux: Sequence[float] = DEFAULT_LUX, size_px: int = 32, seed: int = 0,
                 num_threads: int | None = None, contrast_lux: float = CONTRAST_LUX,
                 contrasts: Sequence[float] = CONTRAST_STEPS,
                 progress: Callable[[int, int], None] | None = None,
                 biases: Mapping[str, float] | None = None) -> CharacterizationResult:
    """Run the bench (module doc) on a preset's pixel; ``progress(done, total)`` after each run.
    ``biases``: the vendor's biases by name (a Prophesee preset's ``vendor_biases``: mV on the
    Gen3 VGA, code offsets on the IMX636), mapped onto the pixel at the preset's temperature."""
    p = get_preset(preset) if isinstance(preset, str) else preset
    if biases:
        if p.vendor_biases is None:
            raise ValueError(f"--bias: preset {p.name!r} has no Prophesee biases (only "
                             f"{', '.join(VENDOR_BIAS_PRESETS)} have)")
        p = replace(p, pixel=p.vendor_biases.pixel_params(dict(biases), p.pixel, p.dark_reference_temperature_c))
    integer("size_px", size_px, 4, MAX_SIZE_PX)
    grid = sorted(float(v) for v in lux)
    if not grid or not all(math.isfinite(v) and 1e-6 <= v <= 1e6 for v in grid):
        raise ValueError(f"lux must be illuminances in [1e-6, 1e6]; got {list(lux)!r}")
    steps = sorted(float(c) for c in contrasts)
    if not steps or not all(math.isfinite(c) and 0.0 < c <= 10.0 for c in steps):
        raise ValueError(f"contrasts must be steps in (0, 10]; got {list(contrasts)!r}")
    if not (math.isfinite(contrast_lux) and 1e-6 <= contrast_lux <= 1e6):
        raise ValueError(f"contrast_lux must be in [1e-6, 1e6]; got {contrast_lux!r}")
    total, done = len(grid) + len(steps), 0
    rates, background, median, p90, response = [], [], [], [], []
    for i, e in enumerate(grid):
        rate = photons_per_px_s(p, e)
        bg, delays, on_bg = _run_step(p, rate, STEP_FACTOR, size_px, seed + i, num_threads)
        fired = delays[np.isfinite(delays)]
        rates.append(rate)
        background.append(bg)
        median.append(float(np.median(fired)) if fired.size else math.nan)
        p90.append(float(np.percentile(fired, 90)) if fired.size else math.nan)
        response.append(_responding(delays, on_bg))
        done += 1
        if progress is not None:
            progress(done, total)
    s_curve = []
    base = photons_per_px_s(p, contrast_lux)
    for j, c in enumerate(steps):
        _, delays, on_bg = _run_step(p, base, 1.0 + c, size_px, seed + 1000 + j, num_threads, leak=False)
        s_curve.append(_responding(delays, on_bg))
        done += 1
        if progress is not None:
            progress(done, total)
    result = CharacterizationResult(
        preset=p.name, lux=grid, photons_per_px_s=rates, background_hz=background, latency_median_s=median,
        latency_p90_s=p90, response_fraction=response, low_light_cutoff_lux=_half_point(grid, response, True),
        contrast_lux=float(contrast_lux), contrasts=steps, contrast_response=s_curve,
        contrast_threshold=_half_point(steps, s_curve, False), size_px=size_px, seed=seed,
        biases={k: float(v) for k, v in (biases or {}).items()})
    for fig in PUBLISHED.get(p.name, ()):
        twin = result.twin_value(fig.quantity)
        role = "calibration" if fig.quantity in CALIBRATED.get(p.name, ()) else "validation"
        result.published.append({**asdict(fig), "twin": twin, "ratio": twin / fig.value if fig.value else math.nan,
                                 "role": role})
    return result


def plot_characterization(result: CharacterizationResult, path: Any) -> Any:
    """``characterize.png``: background, latency and response against lux, and the contrast
    S-curve, each with the published figures marked."""
    from pathlib import Path

    from . import plots
    from ._extras import require

    Figure = require("matplotlib.figure").Figure
    fig = Figure(figsize=(10.0, 7.5))
    axes = fig.subplots(2, 2)
    lux = np.array(result.lux)
    pub = {p["quantity"]: p for p in result.published}
    ax = axes[0, 0]
    exposure = result.size_px**2 * BACKGROUND_S  # pixel-seconds counted at each illuminance
    bg = np.array(result.background_hz)
    counts = np.rint(bg * exposure)
    seen = counts > 0
    ax.errorbar(lux[seen], bg[seen], yerr=np.sqrt(counts[seen]) / exposure, fmt="o-", color=plots.TOTAL_COLOUR,
                label="events / (pixels x time), Poisson error")
    if np.any(~seen):  # no event: an upper limit of one event (no log-axis zero)
        ax.plot(lux[~seen], np.full(int(np.sum(~seen)), 1.0 / exposure), "v", color=plots.TOTAL_COLOUR,
                label="no event: below one per run")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.legend(fontsize="small")
    ax.set(xlabel="illuminance at the focal plane [lux]", ylabel="background [events / pixel / s]",
           title=f"background activity under steady light ({BACKGROUND_S:g} s)")
    ax = axes[0, 1]
    ax.loglog(lux, np.array(result.latency_median_s) * 1e6, "o-", color=plots.ON_COLOUR, label="median")
    ax.loglog(lux, np.array(result.latency_p90_s) * 1e6, "s--", color=plots.ON_COLOUR, alpha=0.6, label="90th percentile")
    if "latency_s" in pub:
        ax.axhline(pub["latency_s"]["value"] * 1e6, color="k", ls=":", label=f"published ({pub['latency_s']['condition']})")
    ax.set(xlabel="illuminance at the focal plane [lux]", ylabel="latency [us]",
           title=f"latency of the first ON event after a x{STEP_FACTOR:g} step")
    ax.legend(fontsize="small")
    ax = axes[1, 0]
    ax.semilogx(lux, result.response_fraction, "o-", color=plots.ON_COLOUR)
    ax.axhline(0.5, color="grey", lw=0.8)
    if math.isfinite(result.low_light_cutoff_lux):  # -inf (below the grid) and nan draw nothing
        ax.axvline(result.low_light_cutoff_lux, color=plots.ON_COLOUR, ls="--", label="twin's cutoff")
    if "low_light_cutoff_lux" in pub:
        ax.axvline(pub["low_light_cutoff_lux"]["value"], color="k", ls=":", label="published cutoff")
    ax.set(xlabel="illuminance at the focal plane [lux]", ylabel="share of pixels responding",
           title=f"response to a x{STEP_FACTOR:g} step within {RESPONSE_WINDOW_S:g} s", ylim=(-0.05, 1.05))
    ax.legend(fontsize="small")
    ax = axes[1, 1]
    ax.plot(np.array(result.contrasts) * 100, result.contrast_response, "o-", color=plots.ON_COLOUR)
    ax.axhline(0.5, color="grey", lw=0.8)
    if "contrast_threshold" in pub:
        ax.axvline(pub["contrast_threshold"]["value"] * 100, color="k", ls=":", label="published CT")
        ax.legend(fontsize="small")
    ax.set(xlabel="contrast step [%]", ylabel="share of pixels firing ON", ylim=(-0.05, 1.05),
           title=f"contrast sensitivity at {result.contrast_lux:g} lux")
    fig.suptitle(f"{result.preset}: the twin on the characterisation bench ({result.size_px}x{result.size_px} px, "
                 f"{BENCH_SPECTRUM} light)")
    fig.tight_layout()
    return plots.save(fig, Path(path))
