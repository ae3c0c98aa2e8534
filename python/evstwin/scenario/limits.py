"""The bounds a scenario must keep to run: the engine's photon-rate and sample-interval limits,
the samples and the memory one run implies, and what a pre-roll cannot do; each checked before
the run, its error naming the keys that set it."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .. import psf
from ..pixel import PixelParams
from ..targets import LightCurve, LinearTarget, Target
from .schema import ScenarioError, _wrap

MAX_PSF_SIGMA_PX = 100.0
"""Widest PSF accepted [px]: its +-5 sigma window (1001 px a side, 1e6 pixels at 100 px) is
rendered around every source and sample before it is clipped to the sensor; a sigma of 1000 px
took 2.5 GB per source (the scenario fuzz ran out of memory on one)."""
MAX_SAMPLES = 10**9
"""Most samples a scenario may imply: duration x rate x the sub-sampling of its fastest target
(1e9 samples of even a 64 x 64 window are 4e12 pixel-updates, a day of engine time)."""
MAX_CHUNK_BYTES = 2 * 2**30
"""Most memory one chunk's rendered rates may take [bytes]: chunk_samples frames of the whole
array (8 bytes a pixel), or in a sparse sub-sampled chunk the PSF windows of every moving target
that can be on the sensor at once (a drifting field's stars count only while they can touch
it) at every fine sample (about 32 bytes a window pixel)."""
MAX_PHOTON_RATE = 1e20
"""The engine's largest photon rate per pixel [photons/s] (``Sensor::MAX_RATE``)."""


def _peak_flux(target: Target) -> float:
    b = target.brightness
    return float(np.max(b.flux_ph_s)) if isinstance(b, LightCurve) else float(b)


def _check_peak_rate(background: float, bg: dict[str, Any], targets: list[Target], sources: list[str],
                     shape: psf.PSFShape, optics: dict[str, Any]) -> None:
    """The engine refuses a pixel above 1e20 photons/s: make sure none can get there, before
    the run, naming what sets it. Bound: the background plus, from every source, its largest
    flux times the largest share one pixel gets of the PSF (a source centred on it; the
    rendered window is normalised to its own mass)."""
    share = shape.max_pixel_share
    peaks = [_peak_flux(t) for t in targets]
    summed = float(np.sum(peaks)) if peaks else 0.0  # inf, not OverflowError, past 1.8e308
    total = background + share * summed
    if total <= MAX_PHOTON_RATE:
        return
    where = f"background={bg} gives {background:.3g} photons/s per pixel"
    if peaks:
        k = int(np.argmax(peaks))
        where += (f"; {share:.3g} of the sources' peak fluxes adds {share * summed:.3g}, the brightest "
                  f"{sources[k]} at {peaks[k]:.3g} photons/s")
    raise ScenarioError(f"a pixel could receive {total:.3g} photons/s (> {MAX_PHOTON_RATE:g}, the engine's limit): "
                        f"{where}; optics={optics}")


def _check_intervals(params: PixelParams, rate_hz: float) -> None:
    """The engine's limits on the sample interval, checked for the longest one (1 / rate_hz),
    so what builds also runs (the engine would refuse it at the first sample, naming no key)."""
    dt = 1.0 / rate_hz
    noise = max(1.0, params.shot_noise_factor) * params.shot_noise_rate_hz * dt
    if noise > 0.5:
        raise ScenarioError(
            f"pixel.shot_noise_rate_hz={params.shot_noise_rate_hz:g} x max(1, pixel.shot_noise_factor="
            f"{params.shot_noise_factor:g}) / sampling.rate_hz={rate_hz:g} = {noise:.3g} must be <= 0.5 (eq. 13-15 "
            "draw at most one noise event per sample): raise sampling.rate_hz or lower the noise rate"
        )
    if params.lowpass == "euler" and params.cutoff_hz is not None and 2 * math.pi * params.cutoff_hz * dt > 2:
        raise ScenarioError(
            f"pixel.lowpass='euler' (eq. 7) is unstable when 2 pi pixel.cutoff_hz / sampling.rate_hz > 2; got "
            f"cutoff_hz={params.cutoff_hz:g}, rate_hz={rate_hz:g}: use lowpass='exact' or a higher rate"
        )


def _check_work(s: dict[str, Any], width: int, height: int, shape: psf.PSFShape, targets: list[Target],
                sources: list[str]) -> None:
    """The samples and the memory of one chunk a scenario implies, bounded before it runs,
    each error naming the keys that set it (sub-sampling as ``simulate`` does it: the base
    interval divided so that no target moves more than max_shift_px between samples)."""
    sp = s["sampling"]
    duration, rate, shift, chunk = float(s["duration_s"]), float(sp["rate_hz"]), float(sp["max_shift_px"]), sp["chunk_samples"]
    n_pre = pre_roll_samples(float(sp.get("pre_roll_s", 0.0)), rate, sp.get("pre_roll_rate_hz"))[0]
    n_base = max(1.0, math.ceil(duration * rate - 1e-9)) + n_pre
    if not n_base <= MAX_SAMPLES:
        pre = (f", sampling.pre_roll_s={sp['pre_roll_s']!r} x sampling.pre_roll_rate_hz="
               f"{sp.get('pre_roll_rate_hz', sp['rate_hz'])!r} = {n_pre:.3g} more") if n_pre else ""
        raise ScenarioError(f"duration_s x sampling.rate_hz = {n_base - n_pre:.3g} samples{pre} (> {MAX_SAMPLES:g}"
                            f"{' in all' if n_pre else ''}); got duration_s={s['duration_s']!r}, "
                            f"sampling.rate_hz={sp['rate_hz']!r}")
    frame_bytes = 8.0 * width * height
    if not chunk * frame_bytes <= MAX_CHUNK_BYTES:
        raise ScenarioError(
            f"sampling.chunk_samples={chunk} frames of {width}x{height} pixels take {chunk * frame_bytes / 2**30:.3g} GiB "
            f"(> {MAX_CHUNK_BYTES / 2**30:g} GiB): lower sampling.chunk_samples"
        )
    moving = []
    for i, target in enumerate(targets):
        speed = float(_wrap(sources[i], target.max_speed_px_s, 0.0, duration))
        if not speed >= 0.0:  # NaN
            raise ScenarioError(f"{sources[i]}: its speed is not a number ({speed!r} px/s)")
        if speed > 0.0:
            moving.append((speed, i))
    if not moving:
        return
    speed, i = max(moving)
    ratio = speed / rate / shift
    n_sub = max(1.0, math.ceil(ratio - 1e-9)) if ratio <= MAX_SAMPLES else ratio  # ceil(inf) would raise
    n_total = n_base * n_sub
    why = (f"{sources[i]} moves {speed:.3g} px/s, sub-sampled to sampling.max_shift_px={sp['max_shift_px']!r} at "
           f"sampling.rate_hz={sp['rate_hz']!r}: {n_sub:.3g} sub-samples per base sample")
    if not n_total <= MAX_SAMPLES:
        raise ScenarioError(f"{why}, {n_total:.3g} samples over duration_s={s['duration_s']!r} (> {MAX_SAMPLES:g})")
    if not 1.0 / rate / n_sub >= 1e-12:
        raise ScenarioError(f"{why}, {1.0 / rate / n_sub:.3g} s apart (< 1e-12 s, the engine's shortest interval)")
    if n_sub > 1 and sp["sparse"]:
        # The widest window any moving target renders at the fine rate (a defocused ghost's
        # may be wider; a halo is rendered at the base rate, one frame at a time).
        sharp = [psf.sharp_part(shape)] + [psf.sharp_part(targets[j].psf) for _, j in moving  # type: ignore[arg-type]
                                           if targets[j].psf is not None]
        half = max([p.half_width_px for p in sharp if p is not None], default=0)
        window = min((2 * half + 1) ** 2, width * height)
        fine = max(chunk, n_sub) + n_sub  # the fine samples of one sparse chunk, at most
        # Windows off the sensor are skipped: a drifting field's stars, most of them outside
        # at any one time on a long run, count only while they can touch it.
        n_win = _most_windows_at_once([targets[j] for _, j in moving], width, height, half, duration)
        need = fine * n_win * window * 32.0
        if not need <= MAX_CHUNK_BYTES:
            raise ScenarioError(
                f"{why}; one chunk of {fine:.3g} fine samples renders {n_win} moving PSF windows of {window} px "
                f"each, {need / 2**30:.3g} GiB (> {MAX_CHUNK_BYTES / 2**30:g} GiB): raise sampling.max_shift_px or "
                "lower sampling.chunk_samples"
            )


def _most_windows_at_once(targets: list[Target], width: int, height: int, half: int, duration_s: float) -> int:
    """The most of these moving targets whose PSF windows (half-width ``half`` px) overlap the
    sensor at one time in [0, duration_s]: exact for linear targets (each is on for one time
    interval; the count is the deepest overlap of the intervals), every other one counted
    as always on."""
    linear = [t for t in targets if isinstance(t, LinearTarget)]
    others = len(targets) - len(linear)
    if not linear:
        return others
    x0 = np.array([t.x0_px for t in linear])
    y0 = np.array([t.y0_px for t in linear])
    vx = np.array([t.vx_px_s for t in linear])
    vy = np.array([t.vy_px_s for t in linear])
    t0 = np.array([t.t0_s for t in linear])
    start = np.zeros(len(linear))
    end = np.full(len(linear), duration_s)
    for p0, v, size in ((x0, vx, width), (y0, vy, height)):
        lo, hi = -half - 0.5, size - 0.5 + half  # the centres whose window touches the sensor [px]
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            ta, tb = t0 + (lo - p0) / v, t0 + (hi - p0) / v
        inside = (p0 >= lo) & (p0 <= hi)
        first = np.where(v == 0.0, np.where(inside, -np.inf, np.inf), np.minimum(ta, tb))
        last = np.where(v == 0.0, np.where(inside, np.inf, -np.inf), np.maximum(ta, tb))
        unknown = np.isnan(first) | np.isnan(last)  # inf - inf at absurd values: count it as on
        first, last = np.where(unknown, -np.inf, first), np.where(unknown, np.inf, last)
        start, end = np.maximum(start, first), np.minimum(end, last)
    on = start <= end
    # Sweep the interval ends in time order, an interval's start before another's end at a tie.
    times = np.concatenate([start[on], end[on]])
    steps = np.concatenate([np.ones(int(on.sum()), np.int64), -np.ones(int(on.sum()), np.int64)])
    order = np.lexsort((-steps, times))
    deepest = int(np.cumsum(steps[order]).max(initial=0))
    return others + deepest


def pre_roll_samples(pre_roll_s: float, rate_hz: float, pre_roll_rate_hz: float | None = None) -> tuple[int, float]:
    """(n, dt): a pre-roll of ``pre_roll_s`` takes n samples dt apart before t = 0, the last at
    t = 0 (dt = 1 / pre_roll_rate_hz, or 1 / rate_hz without one; n = 0 without a pre-roll)."""
    dt = 1.0 / (pre_roll_rate_hz if pre_roll_rate_hz else rate_hz)
    return (math.ceil(pre_roll_s / dt - 1e-9) if pre_roll_s > 0.0 else 0), dt


def _check_pre_roll(s: dict[str, Any], targets: list[Target], sources: list[str], field_stars: int, moves: bool,
                    atmosphere: Any) -> None:
    """What a pre-roll (sampling.pre_roll_s) cannot do yet, refused by name: a target that
    cannot be placed before t = 0 (a table that starts there, a satellite's pass), a drifting
    field of random stars and an atmosphere's motion or scintillation (both drawn for [0,
    duration_s] only: the stars that would cross the sensor before t = 0, and the atmosphere
    there, are missing)."""
    sp = s["sampling"]
    n_pre, dt = pre_roll_samples(float(sp.get("pre_roll_s", 0.0)), float(sp["rate_hz"]), sp.get("pre_roll_rate_hz"))
    if not n_pre:
        return
    t0 = -n_pre * dt
    key = f"sampling.pre_roll_s={sp['pre_roll_s']!r}"
    if field_stars and moves:
        raise ScenarioError(f"{key} with a drifting [star_field] of random stars is not supported: the stars are "
                            "drawn for [0, duration_s] only, so those crossing the sensor before t = 0 would be missing")
    if atmosphere is not None and (atmosphere.motion is not None or atmosphere.scintillation is not None):
        raise ScenarioError(f"{key} with [atmosphere] image motion or scintillation is not supported: they are drawn "
                            "for [0, duration_s] only")
    t = np.array([t0, 0.5 * t0])
    for target, source in zip(targets, sources):
        try:
            target.position_px(t)
            target.flux_ph_s(t)
            target.max_speed_px_s(t0, 0.0)
        except ValueError as exc:
            raise ScenarioError(f"{key}: {source} cannot be placed before t = 0 ({exc}); give it a track that "
                                "covers the pre-roll, or no pre-roll") from None
