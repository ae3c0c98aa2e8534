"""Background activity measured on a recording of a static or dark scene, as the engine's
eq. 12 model (``evstwin calibrate-noise``).

:func:`calibrate_noise` reads a recording twice in chunks (memory: two counts per pixel plus
the events of a few busy pixels) and returns a :class:`NoiseCalibration`; its
:meth:`~NoiseCalibration.to_toml` is a scenario fragment ``evstwin simulate`` takes, its
:meth:`~NoiseCalibration.summary` the text the command prints. The rules, each stated where
it is applied:

* **Background per polarity.** The count ``N`` of a pixel is Poisson with mean ``m L``, ``L``
  log-normal of mean 1 and sigma ``s`` (the engine's eq. 12 clock times its per-pixel factor).
  The rate is the mean count over the non-hot pixels / the duration, with two standard
  errors: Poisson (sqrt of the events) and the pixels' scatter (what a new draw of the
  pixels would give: it includes the spread of the rates). ``s`` is the maximum-likelihood
  fit of that Poisson-log-normal mixture to the per-pixel counts (the moment estimate
  ``ln(1 + (var - m) / m^2)`` is reported beside it: at a fraction of an event per pixel it
  rests on the few pixels with several events and is often undefined); its standard error
  from the curvature of the log-likelihood. The engine has one ``background_rate_sigma``:
  the event-count-weighted mean of the two.
* **Hot pixels.** A pixel is hot when its ON or its OFF count is improbable under the fitted
  background: tail probability ``P(N >= n)`` below ``alpha / 2`` per polarity (``alpha`` =
  1e-6 by default: about ``alpha`` false hot pixels per pixel of a pure Poisson-log-normal
  sensor). The background is fitted again without them until no new pixel is flagged.
* **Each hot pixel's telegraph.** Its successive intervals are split at a gap
  ``g = d + mu ln(2 n)`` (``d`` the dead time, ``mu`` the within-burst exponential mean,
  ``n`` the intervals: fewer than 0.5 within-burst intervals are expected above ``g``);
  ``mu`` starts as ``(median interval - d) / ln 2`` and is then the mean of the intervals
  below ``g`` less ``d``, until ``g`` settles. The rate while active is ``rho`` = 1 / mean interval below g;
  the active time ``events / rho``, the duty ``active / duration``; quiet periods are
  exponential, so the mean excess of the gaps above ``g`` estimates their mean ``q`` (the
  short ones hidden under ``g`` included) and the mean burst is ``q duty / (1 - duty)``. The
  engine's rate ``r`` (an exponential clock after a dead time ``d``) is
  ``rho / (1 - rho d)``, with ``d`` the refractory period of the scenario written.
* **Refractory period.** The ``k``-th shortest interval between two successive events of one
  pixel among the hot and the busiest pixels, ``k = max(1, n / 1000)`` of their ``n``
  intervals: the shortest for up to 2000 intervals, and not fooled by the rare coincidence of
  two independent sources in one pixel (a hot pixel's own background); an upper bound on the
  dead time, suggested, not written.
* **Stationarity.** The background rate in the first and the last tenth of the recording.

Everything measured goes into eq. 12 (``shot_noise_on_rate_hz``, ``shot_noise_off_rate_hz``,
``background_rate_sigma``) and the leak is set to 0: a dark recording cannot tell eq. 12's
events from threshold crossings of the filtered shot noise, so the thresholds of the scenario
must stay high enough that the latter do not fire in the dark (true of the IMX636 preset; the
DAVIS346 preset's 0.093 OFF threshold adds about 5e-3 Hz OFF per pixel in the dark).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..analysis import CountedRecording
from ..sensor import EVENT_DTYPE
from .comparison import PathLike
from .noise_models import (
    ALPHA,
    SIGMA_MAX,
    engine_rate,
    find_hot_pixels,
    fit_poisson_lognormal,
    pln_logpmf,
    pln_logsf,
    telegraph,
)

BUSY_PIXELS = 64
"""Besides the hot pixels, the busiest pixels whose intervals give the refractory period."""
MAX_EVENTS_PER_PIXEL = 1_000_000
"""Events kept per busy pixel for the telegraph fit and the intervals (the first ones)."""


@dataclass(frozen=True)
class Background:
    """The eq. 12 background of one polarity over the non-hot pixels of the window."""

    polarity: str
    events: int
    pixels: int
    rate_hz: float
    """Mean rate per pixel [Hz]."""
    rate_se_hz: float
    """Its standard error from the scatter of the pixels' counts [Hz]."""
    rate_se_poisson_hz: float
    """Its Poisson standard error, sqrt(events) / (pixels x duration) [Hz]."""
    sigma: float
    """Maximum-likelihood log-normal sigma of the per-pixel rates (0 without events)."""
    sigma_se: float | None
    sigma_moment: float | None
    """The moment estimate; None where the variance does not exceed the mean."""


@dataclass(frozen=True)
class HotPixel:
    """One hot pixel (sensor coordinates) and its random-telegraph fit."""

    x: int
    y: int
    on: int
    off: int
    rate_hz: float
    """Mean rate over the recording [Hz]."""
    alternation: float
    """Share of successive events of opposite polarity (the engine's ``hot_pixel_alternation``)."""
    active_rate_hz: float
    """rho: events per second while active [Hz]."""
    engine_rate_hz: float
    """r: the engine's rate that fires rho per second after the dead time [Hz]."""
    duty: float
    burst_s: float
    """Mean active period [s]."""
    gaps: int
    """Quiet gaps seen (longer than ``gap_s``): burst_s rests on them (se ~ 1 / sqrt(gaps))."""
    gap_s: float
    min_interval_s: float


@dataclass(frozen=True)
class NoiseCalibration:
    """What :func:`calibrate_noise` measured; :meth:`to_toml` and :meth:`summary` present it."""

    path: str
    sensor: tuple[int, int]
    roi: tuple[int, int, int, int]
    """(x0, y0, width, height) [px] of the window measured."""
    duration_s: float
    alpha: float
    on: Background
    off: Background
    hot: list[HotPixel]
    refractory_s: float | None
    """The k-th shortest interval between two events of one busy pixel, k = max(1, n / 1000) of
    their n intervals [s]; None without two events."""
    refractory_intervals: int
    dead_time_s: float
    """The dead time the hot pixels' engine rates assume (the written scenario's)."""
    dead_time_source: str
    preset: str | None
    first_tenth_events: int
    last_tenth_events: int
    """Background events (both polarities, non-hot pixels) in the first and last tenth of the span."""
    notes: list[str] = field(default_factory=list)

    @property
    def pixels(self) -> int:
        return self.roi[2] * self.roi[3]

    @property
    def sigma(self) -> float:
        """The engine's one background_rate_sigma: the event-weighted mean of ON and OFF, at most 3."""
        n = self.on.events + self.off.events
        if n == 0:
            return 0.0
        return min(SIGMA_MAX, (self.on.events * self.on.sigma + self.off.events * self.off.sigma) / n)

    @property
    def first_tenth_hz(self) -> float:
        """Background rate per pixel in the first tenth of the recording [Hz]."""
        return self.first_tenth_events / (self.on.pixels * self.duration_s / 10)

    @property
    def last_tenth_hz(self) -> float:
        """Background rate per pixel in the last tenth of the recording [Hz]."""
        return self.last_tenth_events / (self.on.pixels * self.duration_s / 10)

    @property
    def stationarity_z(self) -> float:
        """(last - first tenth's events) / its Poisson standard error."""
        n1, n2 = self.first_tenth_events, self.last_tenth_events
        return (n2 - n1) / math.sqrt(n1 + n2) if n1 + n2 > 0 else 0.0

    def pixel_table(self) -> dict[str, Any]:
        """The ``[pixel]`` fields: eq. 12's rates and sigma, no leak, and the hot pixels' draw."""
        table: dict[str, Any] = {
            "shot_noise_on_rate_hz": _round(self.on.rate_hz),
            "shot_noise_off_rate_hz": _round(self.off.rate_hz),
            "background_rate_sigma": _round(self.sigma),
            "leak_rate_hz": 0.0,
            "hot_pixel_fraction": _round(len(self.hot) / self.pixels),
        }
        if self.hot:
            rates = np.array([h.engine_rate_hz for h in self.hot])
            table["hot_pixel_rate_hz"] = _round(float(np.median(rates)))
            table["hot_pixel_rate_sigma"] = _round(min(SIGMA_MAX, float(np.std(np.log(rates)))))
            table["hot_pixel_duty"] = _round(max(1e-6, min(1.0, float(np.median([h.duty for h in self.hot])))))
            table["hot_pixel_burst_s"] = _round(float(np.median([h.burst_s for h in self.hot])))
            # Polarities: the event-weighted ON share and alternation of the hot pixels, the
            # engine's two-state chain (kept within what a chain with that share can switch).
            n = np.array([h.on + h.off for h in self.hot], float)
            alternation = float(np.average([h.alternation for h in self.hot], weights=np.maximum(n - 1.0, 1e-9)))
            table["hot_pixel_on_share"], table["hot_pixel_alternation"] = _polarity_chain(
                sum(h.on for h in self.hot), int(n.sum()), alternation)
        return table

    def hot_pixel_table(self) -> dict[str, Any]:
        """``[hot_pixels] pixels = [{x, y, rate_hz, duty, burst_s, on_share, alternation}, ...]``:
        each hot pixel with its own telegraph and polarity chain (``evstwin.HotPixelChain``; real
        hot pixels differ: the IMX636 recording has one ON 0.59 of its events and one 0.98),
        coordinates relative to the window."""
        x0, y0 = self.roi[:2]
        return {"pixels": [{"x": h.x - x0, "y": h.y - y0, "rate_hz": _round(h.engine_rate_hz), **_chain_of(h)}
                           for h in self.hot]}

    def scenario(self) -> dict[str, Any]:
        """The scenario fragment as a dict (what :meth:`to_toml` writes under its header)."""
        out: dict[str, Any] = {
            "name": f"noise-{Path(self.path).stem}",
            "description": f"Background activity measured on {Path(self.path).name} by evstwin calibrate-noise.",
            "duration_s": _round(self.duration_s),
        }
        if self.preset is not None:
            out["sensor"] = {"preset": self.preset, "width": self.roi[2], "height": self.roi[3]}
        out["pixel"] = self.pixel_table()
        out["hot_pixels"] = self.hot_pixel_table()
        return out

    def to_toml(self) -> str:
        """The scenario fragment with a comment header: the recording, the window, every
        estimate with its uncertainty, and the rules."""
        import tomli_w

        s = self.scenario()
        head = {k: s[k] for k in ("name", "description", "duration_s")}
        parts = ["\n".join("# " + line if line else "#" for line in self._header_lines()), tomli_w.dumps(head)]
        if "sensor" in s:
            parts.append(tomli_w.dumps({"sensor": s["sensor"]}))
        pixel = tomli_w.dumps({"pixel": s["pixel"]})
        if self.refractory_s is not None:
            pixel += (f"# refractory_s = {_round(self.refractory_s)}  # measured (an upper bound on the dead "
                      "time); uncomment to use it\n")
        parts.append(pixel)
        rows = "".join("    { " + ", ".join(f"{k} = {v!r}" for k, v in entry.items()) + " },\n"
                       for entry in s["hot_pixels"]["pixels"])
        parts.append(f"[hot_pixels]\npixels = [\n{rows}]\n" if rows else "[hot_pixels]\npixels = []\n")
        return "\n".join(p.rstrip("\n") + "\n" for p in parts)

    def _header_lines(self) -> list[str]:
        x0, y0, w, h = self.roi
        sw, sh = self.sensor
        lines = [
            "evstwin calibrate-noise: the background activity of a static or dark recording as the engine's",
            "eq. 12 model. Merge into a scenario, or simulate as it is (evstwin simulate THIS.toml).",
            "",
            f"recording   {self.path} ({sw} x {sh} px)",
            f"window      x {x0}..{x0 + w - 1}, y {y0}..{y0 + h - 1} ({w} x {h} = {self.pixels} pixels); "
            "[hot_pixels] coordinates are relative to it",
            f"duration    {self.duration_s:.6g} s",
        ]
        if self.preset is None:
            lines.append(f"sensor      no built-in preset is {sw} x {sh}: add [sensor] preset = ... (and width, "
                         "height) to simulate it")
        else:
            lines.append(f"sensor      preset {self.preset}, cut to the window's {w} x {h} (its thresholds, "
                         "refractory period and everything not below come from it)")
        lines.append("")
        lines += self._estimate_lines()
        lines += [
            "",
            "Rules (python/evstwin/validation/noise.py):",
            "- rate: mean count of the non-hot pixels / duration; se from the pixels' scatter (Poisson se beside)",
            "- sigma: maximum likelihood of a Poisson-log-normal mixture of the per-pixel counts, se from its",
            "  curvature; the engine's one background_rate_sigma is the event-weighted mean of ON and OFF",
            f"- hot pixel: P(N >= n) < {self.alpha / 2:.3g} for its ON or OFF count under the fitted background "
            f"(about {self.alpha:.3g} false",
            "  alarms per pixel), refitted without the hot pixels until none is added",
            "- telegraph: intervals split at g = d + mu ln(2 n), mu = mean interval below g less d (iterated from",
            "  the median's); rate while active rho = 1 / mean interval below g;",
            "  duty = events / (rho duration); burst = q duty / (1 - duty), q = mean excess of the gaps over g;",
            "  engine rate r = rho / (1 - rho d), d the dead time",
            "- [hot_pixels]: each hot pixel with its own chain (duty, burst_s, on_share = ON / all, kept in",
            "  [1e-3, 1 - 1e-3], and alternation); [pixel] hot_pixel_* hold their medians (duty, burst) and",
            "  event-weighted means (ON share, alternation), for drawn hot pixels",
            "- refractory: the k-th shortest of the n intervals of the hot and busiest pixels, k = max(1, n / 1000)",
            "- all measured background goes into eq. 12 (leak_rate_hz = 0): keep the thresholds high enough that",
            "  the filtered shot noise does not cross them in the dark (check: simulate this file, compare rates)",
        ]
        return lines

    def _estimate_lines(self) -> list[str]:
        lines = []
        for b in (self.on, self.off):
            sig = "n/a" if b.events == 0 else f"{b.sigma:.3g}" + (f" +- {b.sigma_se:.2g}" if b.sigma_se else "")
            mom = "undefined" if b.sigma_moment is None else f"{b.sigma_moment:.3g}"
            lines.append(f"{b.polarity:3s} background {b.rate_hz:.4g} +- {b.rate_se_hz:.2g} Hz per pixel (Poisson se "
                         f"{b.rate_se_poisson_hz:.2g}; {b.events} events), sigma {sig} (moments: {mom})")
        lines.append(f"background_rate_sigma {self.sigma:.3g} (event-weighted; the engine has one for both)")
        lines.append(f"stationarity: {self.first_tenth_hz:.4g} Hz per pixel in the first tenth, "
                     f"{self.last_tenth_hz:.4g} in the last (z = {self.stationarity_z:+.2f})")
        if self.refractory_s is None:
            lines.append("refractory: no pixel has two events")
        else:
            k = max(1, self.refractory_intervals // 1000)
            which = "the shortest" if k == 1 else f"number {k} from the shortest"
            few = " (too few to say much)" if self.refractory_intervals < 100 else ""
            lines.append(f"refractory: {self.refractory_s * 1e6:.0f} us, {which} of {self.refractory_intervals} "
                         f"intervals of the busiest pixels{few} (suggested, not written)")
        lines.append(f"hot pixels: {len(self.hot)} of {self.pixels} (fraction {len(self.hot) / self.pixels:.3g}); "
                     f"engine rates assume a dead time of {self.dead_time_s * 1e6:.0f} us ({self.dead_time_source})")
        for hp in self.hot:
            lines.append(
                f"  ({hp.x}, {hp.y}): {hp.on + hp.off} events ({hp.on} ON), {hp.rate_hz:.4g} Hz mean, "
                f"{hp.active_rate_hz:.4g} Hz while active (r = {hp.engine_rate_hz:.4g} Hz), duty {hp.duty:.3g}, "
                f"bursts {hp.burst_s:.3g} s ({hp.gaps} gaps > {hp.gap_s * 1e3:.3g} ms), "
                f"{100 * hp.alternation:.0f} % alternate"
            )
        lines += [f"note: {n}" for n in self.notes]
        return lines

    def summary(self) -> str:
        """A short text for the terminal."""
        return "\n".join([f"{self.path}: window {self.roi[2]} x {self.roi[3]} at ({self.roi[0]}, {self.roi[1]}), "
                          f"{self.duration_s:.6g} s"] + self._estimate_lines())

    def write(self, path: PathLike) -> Path:
        """Write :meth:`to_toml` atomically (a temporary file beside it, then renamed)."""
        p = Path(path)
        tmp = p.with_name(f".{p.name}.{os.getpid()}.tmp")
        try:
            tmp.write_text(self.to_toml(), encoding="utf-8")
            os.replace(tmp, p)
        finally:
            tmp.unlink(missing_ok=True)
        return p


def _round(v: float) -> float:
    return float(f"{v:.4g}")


def _at_most(bound: float) -> float:
    """A bound written in 12 digits: within the engine's relative 1e-12 of it, and readable."""
    return float(f"{bound:.12g}")


def _chain_of(h: HotPixel) -> dict[str, float]:
    """One hot pixel's own chain as the engine takes it: its duty and bursts, its ON share
    (kept within [1e-3, 1 - 1e-3]: a pixel seen firing one polarity alone may fire the other)
    and its alternation (at most 2 min(s, 1 - s), what a chain with that share can switch). A
    pixel seen firing one polarity alone, never switching, gets alternation 0: its polarity is
    then its initial draw (ON with probability on_share) for the whole run."""
    share, alternation = _polarity_chain(h.on, h.on + h.off, h.alternation)
    return {"duty": _round(max(1e-6, min(1.0, h.duty))), "burst_s": _round(min(1e6, max(1e-6, h.burst_s))),
            "on_share": share, "alternation": alternation}


def _polarity_chain(on: int, events: int, alternation: float) -> tuple[float, float]:
    """(ON share, alternation) as the engine's chain takes them, in 4 digits: the share of ON
    events kept in [1e-3, 1 - 1e-3], the alternation at most 2 min(s, 1 - s)."""
    share = _round(min(1.0 - 1e-3, max(1e-3, on / max(1, events))))
    return share, min(_round(alternation), _at_most(2.0 * min(share, 1.0 - share)))



def _background(polarity: str, counts: np.ndarray, duration_s: float) -> Background:
    n = counts.size
    events = int(counts.sum())
    mean = events / n
    scatter = float(counts.std(ddof=1)) if n > 1 else 0.0
    sigma, sigma_se, moment = fit_poisson_lognormal(counts)
    return Background(polarity=polarity, events=events, pixels=n, rate_hz=mean / duration_s,
                      rate_se_hz=scatter / math.sqrt(n) / duration_s,
                      rate_se_poisson_hz=math.sqrt(events) / n / duration_s,
                      sigma=sigma, sigma_se=sigma_se, sigma_moment=moment)




# --- the recording -----------------------------------------------------------------------------


def _check_roi(roi: Sequence[int] | None, width: int, height: int) -> tuple[int, int, int, int]:
    if roi is None:
        return 0, 0, width, height
    x0, y0, w, h = (int(v) for v in roi)
    if w < 1 or h < 1 or x0 < 0 or y0 < 0 or x0 + w > width or y0 + h > height:
        raise ValueError(f"--roi {x0},{y0},{w},{h} is not inside the {width}x{height} sensor "
                         f"(x0, y0 >= 0, W, H >= 1, x0 + W <= {width}, y0 + H <= {height})")
    return x0, y0, w, h


def _in_roi(ev: np.ndarray, roi: tuple[int, int, int, int]) -> np.ndarray:
    """The events inside the window, in its coordinates (``Roi.crop``)."""
    from .region import Roi

    return Roi.of(roi).crop(ev)


def _pick_preset(preset: str | None, width: int, height: int, meta: dict[str, Any]) -> str | None:
    """The preset named; for "auto", a file simulated by evstwin names its own (its scenario's),
    a real one gets the built-in preset of its size, if any."""
    from ..presets import PRESETS, get_preset

    if preset is None or preset == "auto":
        scenario = meta.get("scenario")
        own = scenario.get("sensor", {}).get("preset") if isinstance(scenario, dict) else None
        if isinstance(own, str) and own.lower() in PRESETS:
            return get_preset(own).name
        return next((name for name, p in PRESETS.items() if (p.width, p.height) == (width, height)), None)
    if preset == "none":
        return None
    return get_preset(preset).name


def calibrate_noise(
    path: PathLike,
    roi: Sequence[int] | None = None,
    *,
    size: tuple[int, int] | None = None,
    preset: str | None = "auto",
    alpha: float = ALPHA,
    chunk: int | None = None,
) -> NoiseCalibration:
    """Measure the background of a static or dark recording (see the module's rules).

    roi: (x0, y0, width, height) [px] of the window measured; default the whole sensor.
    size: (width, height) for a recording whose header has none.
    preset: the ``[sensor] preset`` to write: "auto" (default: the preset of the scenario a file
        simulated by evstwin names, else the built-in preset of the recording's size, none if
        no preset has it), a preset name, or "none".
    alpha: false-alarm probability per pixel of the hot-pixel test (default 1e-6).

    ValueError (nothing computed) for a window outside the sensor or without events, a
    preset smaller than the window, or a bad alpha.
    """
    from ..io import iter_events
    from ..presets import get_preset
    from .report import READ_CHUNK

    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be in (0, 1); got {alpha}")
    if preset not in (None, "auto", "none"):
        get_preset(preset)  # an unknown name fails before the recording is read
    stream = iter_events(path, chunk=chunk or READ_CHUNK, size=size)
    meta = stream.meta
    window: tuple[int, int, int, int] | None = None
    if meta.get("width") is not None:
        window = _check_roi(roi, int(meta["width"]), int(meta["height"]))
        if roi is None:
            window = None  # the whole sensor: no cut needed
    # Pass 1: per-pixel counts in the window, and the whole recording's span.
    t_lo: int | None = None
    t_hi = 0
    parts: list[np.ndarray] = []
    rec: CountedRecording | None = None
    for ev in stream:
        if len(ev) == 0:
            continue
        t_lo = int(ev["t"].min()) if t_lo is None else min(t_lo, int(ev["t"].min()))
        t_hi = max(t_hi, int(ev["t"].max()))
        if meta.get("width") is None:
            parts.append(ev)  # the size is known at the end only
            continue
        if rec is None:
            w0 = window if window is not None else (0, 0, int(meta["width"]), int(meta["height"]))
            rec = CountedRecording.empty(w0[2], w0[3])
        rec.add(_in_roi(ev, window) if window is not None else ev)
    meta = stream.meta
    if meta.get("width") is None:
        raise ValueError(f"{path}: no events and no sensor size in the file; give the size (--size W,H)")
    sensor = (int(meta["width"]), int(meta["height"]))
    full = _check_roi(roi, *sensor)
    if rec is None:
        rec = CountedRecording.empty(full[2], full[3])
        for ev in parts:
            rec.add(_in_roi(ev, full))
    if rec.total == 0:
        raise ValueError(f"{path}: no events in the window x {full[0]}..{full[0] + full[2] - 1}, "
                         f"y {full[1]}..{full[1] + full[3] - 1}")
    assert t_lo is not None
    duration_s = float(meta["duration_s"]) if meta.get("duration_s") else (t_hi - t_lo) * 1e-6
    if not duration_s > 0:
        raise ValueError(f"{path}: the recording lasts 0 s; a rate needs a duration")
    chosen = _pick_preset(preset, *sensor, meta)
    notes: list[str] = []
    if chosen is not None:
        p = get_preset(chosen)
        if full[2] > p.width or full[3] > p.height:
            raise ValueError(f"the window {full[2]}x{full[3]} is larger than the {p.width}x{p.height} preset {chosen!r}")

    on, off = rec.on, rec.off
    hot_mask = find_hot_pixels(on, off, alpha)
    total = on + off
    order = np.argsort(total, kind="stable")[::-1]
    busy = [int(i) for i in order[:BUSY_PIXELS] if total[i] >= 2]
    wanted = sorted(set(busy) | {int(i) for i in np.flatnonzero(hot_mask)})

    # Pass 2: the events of the busy and hot pixels, and the background of the first and last tenth.
    tenth_us = (t_hi - t_lo) / 10
    first = last = 0
    kept: dict[int, list[np.ndarray]] = {i: [] for i in wanted}
    kept_n = dict.fromkeys(wanted, 0)
    wanted_arr = np.array(wanted, np.int64)
    for ev in iter_events(path, chunk=chunk or READ_CHUNK, size=size):
        ev = _in_roi(ev, full)
        if len(ev) == 0:
            continue
        flat = ev["y"].astype(np.int64) * full[2] + ev["x"].astype(np.int64)
        t = ev["t"]
        background = ~hot_mask[flat]
        first += int(np.count_nonzero(background & (t < t_lo + tenth_us)))
        last += int(np.count_nonzero(background & (t >= t_hi - tenth_us)))
        sel = np.isin(flat, wanted_arr)
        if not sel.any():
            continue
        sub, fsub = ev[sel], flat[sel]
        order_f = np.argsort(fsub, kind="stable")
        sub, fsub = sub[order_f], fsub[order_f]
        keys, starts = np.unique(fsub, return_index=True)
        for k, a, b in zip(keys, starts, list(starts[1:]) + [fsub.size]):
            k = int(k)
            room = MAX_EVENTS_PER_PIXEL - kept_n[k]
            if room > 0:
                kept[k].append(sub[a:min(b, a + room)])
                kept_n[k] += min(b - a, room)
    events_of = {}
    for k, chunks in kept.items():
        e = np.concatenate(chunks) if chunks else np.zeros(0, EVENT_DTYPE)
        events_of[k] = e[np.argsort(e["t"], kind="stable")]
    diffs = [np.diff(e["t"]) for e in events_of.values() if len(e) > 1]
    intervals = np.sort(np.concatenate(diffs)) if diffs else np.zeros(0, np.int64)
    n_intervals = int(intervals.size)
    # The k-th shortest, k = n / 1000: the shortest of a dead-time process, but not of two
    # independent sources that meet in one pixel (a hot pixel's own background).
    refractory = float(intervals[max(1, n_intervals // 1000) - 1]) * 1e-6 if n_intervals else None
    if any(kept_n[k] >= MAX_EVENTS_PER_PIXEL for k in kept_n):
        notes.append(f"busy pixels beyond {MAX_EVENTS_PER_PIXEL} events: their telegraph uses the first ones")

    if chosen is not None:
        dead_s, dead_source = float(get_preset(chosen).pixel.refractory_s), f"the {chosen} preset's refractory_s"
    elif refractory is not None:
        dead_s, dead_source = refractory, "the shortest interval measured"
    else:
        dead_s, dead_source = 0.0, "none measured"
    hot: list[HotPixel] = []
    for k in np.flatnonzero(hot_mask):
        e = events_of[int(k)]
        fit = telegraph(e["t"], e["p"], duration_s, dead_s)
        r, capped = engine_rate(fit["active_rate_hz"], dead_s)
        x, y = int(k) % full[2] + full[0], int(k) // full[2] + full[1]
        if capped:
            notes.append(f"hot pixel ({x}, {y}) fires {fit['active_rate_hz']:.4g} Hz while active, too fast for a "
                         f"{dead_s * 1e6:.0f} us dead time: r capped")
        hot.append(HotPixel(x=x, y=y, on=int(on[k]), off=int(off[k]), rate_hz=(on[k] + off[k]) / duration_s,
                            alternation=fit["alternation"], active_rate_hz=fit["active_rate_hz"], engine_rate_hz=r,
                            duty=fit["duty"], burst_s=fit["burst_s"], gaps=int(fit["gaps"]), gap_s=fit["gap_s"],
                            min_interval_s=fit["min_interval_s"]))
    rest = ~hot_mask
    if not rest.any():
        raise ValueError(f"{path}: every pixel of the window is hot; no background to measure")
    if chosen is not None and refractory is not None and refractory < dead_s:
        notes.append(f"an interval of {refractory * 1e6:.0f} us is shorter than the {chosen} preset's "
                     f"{dead_s * 1e6:.0f} us refractory period")
    bg_on, bg_off = _background("ON", on[rest], duration_s), _background("OFF", off[rest], duration_s)
    if max(bg_on.sigma, bg_off.sigma) > SIGMA_MAX:
        notes.append(f"a sigma above {SIGMA_MAX:g}: the engine's background_rate_sigma stops there")
    return NoiseCalibration(
        path=str(path), sensor=sensor, roi=full, duration_s=duration_s, alpha=alpha, on=bg_on, off=bg_off,
        hot=hot, refractory_s=refractory, refractory_intervals=n_intervals, dead_time_s=dead_s,
        dead_time_source=dead_source, preset=chosen, first_tenth_events=first, last_tenth_events=last, notes=notes,
    )


__all__ = [
    "ALPHA",
    "BUSY_PIXELS",
    "MAX_EVENTS_PER_PIXEL",
    "SIGMA_MAX",
    "Background",
    "HotPixel",
    "NoiseCalibration",
    "calibrate_noise",
    "engine_rate",
    "find_hot_pixels",
    "fit_poisson_lognormal",
    "pln_logpmf",
    "pln_logsf",
    "telegraph",
]
