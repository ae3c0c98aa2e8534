"""Objectives: what one simulation job measures (``match``, ``detect``, ``noise``)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ._types import PathLike, Recording


def _duration_of(events: np.ndarray, meta: Mapping[str, Any]) -> float:
    d = meta.get("duration_s")
    if d is not None:
        return float(d)
    if events.size == 0:
        raise ValueError("the real recording has no events and no duration_s")
    # A division, correctly rounded: 2359945 us is 2.359945 s, where * 1e-6 gave 2.3599449999999997.
    return (int(events["t"][-1]) - int(events["t"][0])) / 1e6


class Objective:
    """What a job measures on one simulation: numbers named in ``metrics``.

    Subclasses are plain picklable objects (they travel to worker processes). ``prepare``
    may change the scenario before it is simulated (after the job's overrides);
    ``duration_s`` fixes the simulated duration (None: the scenario's).
    """

    name: str = "objective"
    metrics: tuple[str, ...] = ()
    headline: tuple[str, ...] = ()
    """Metrics drawn in the sweep figure and printed in summaries (first = primary)."""
    duration_s: float | None = None

    def prepare(self, scenario: dict[str, Any]) -> dict[str, Any]:
        return scenario

    def check(self, scene: Any) -> None:
        """Raise ValueError now, in the main process, for what would make every job fail
        (called on each built scenario before any job runs)."""

    def evaluate(self, result: Any) -> dict[str, float]:  # pragma: no cover - abstract
        raise NotImplementedError


class MatchObjective(Objective):
    """Distance of the simulation to a real recording (:func:`evstwin.validation.compare`).

    Metrics: ``distance`` (dimensionless, 0 = identical; its formula is
    :data:`evstwin.validation.DISTANCE_FORMULA`), ``total_rel_error`` and
    ``on_off_ratio_rel_error`` (sim - real) / real, ``sim_events`` (count). The simulated
    duration is the real recording's.

    roi: ``(x0, y0, w, h)`` [px] of the sensor (or ``'X0,Y0,W,H'``): the real events are cut
    to it and shifted to its coordinates once, here, and every simulation runs the scenario
    with ``sensor.roi`` set (only those w x h pixels are simulated). mask_pixels: (x, y)
    pixels of the sensor left out of both recordings' statistics; mask_hot: also the real
    recording's hot pixels (:func:`evstwin.validation.region.hot_pixels`, with
    ``hot_false_alarms``). ``mask`` is the resulting (h, w) array (None: nothing masked).
    A bad ROI, a listed pixel off the sensor, or nothing left to compare raise ValueError here,
    before any job runs.
    """

    name = "match"
    metrics: tuple[str, ...] = ("distance", "total_rel_error", "on_off_ratio_rel_error", "sim_events")
    headline = ("distance",)

    def __init__(
        self,
        real_events: np.ndarray,
        real_meta: Mapping[str, Any],
        bin_width: float = 2.0,
        roi: Any = None,
        mask_pixels: Sequence[tuple[int, int]] = (),
        mask_hot: bool = False,
        hot_false_alarms: float | None = None,
    ) -> None:
        from ..validation.region import (
            HOT_FALSE_ALARMS,
            Roi,
            check_mask_leaves_pixels,
            describe,
            hot_pixels,
            mask_array,
        )

        self.real_meta = {
            k: v for k, v in real_meta.items() if k in ("width", "height", "duration_s", "path")
        }
        self.real_meta["duration_s"] = _duration_of(real_events, real_meta)
        self.duration_s = float(self.real_meta["duration_s"])
        if not self.duration_s > 0:
            raise ValueError(f"the real recording's duration must be > 0 s; got {self.duration_s:g}")
        self.sensor_width = int(real_meta["width"])
        self.sensor_height = int(real_meta["height"])
        self.roi = None if roi is None else Roi.of(roi).check(self.sensor_width, self.sensor_height)
        if self.roi is not None:
            real_events = self.roi.crop(real_events)
            self.real_meta["width"], self.real_meta["height"] = self.roi.width, self.roi.height
        self.real_events = real_events
        self.width = int(self.real_meta["width"])
        self.height = int(self.real_meta["height"])
        self.mask: np.ndarray | None = None
        if mask_pixels or mask_hot:
            mask = mask_array(mask_pixels, self.sensor_width, self.sensor_height, self.roi)
            if mask_hot:
                from ..analysis import pixel_counts

                alarms = HOT_FALSE_ALARMS if hot_false_alarms is None else hot_false_alarms
                mask |= hot_pixels(pixel_counts(real_events, self.width, self.height)["total"], mask, alarms)
            check_mask_leaves_pixels(mask, self.roi)
            self.mask = mask
        self.region = describe(self.roi, self.mask)
        self.bin_width = float(bin_width)

    def prepare(self, scenario: dict[str, Any]) -> dict[str, Any]:
        if self.roi is None:
            return scenario
        from ..scenario import set_value

        return set_value(scenario, "sensor.roi", list(self.roi.as_tuple()))

    def evaluate(self, result: Any) -> dict[str, float]:
        from ..validation import compare

        comp = compare(
            self.real_events,
            self.real_meta,
            [(result.events, result.meta)],
            bin_width=self.bin_width,
            mask=self.mask,
            region=self.region,
        )
        s = comp.sims[0]
        return {
            "distance": float(s.distance),
            "total_rel_error": float(s.total_rel_error),
            "on_off_ratio_rel_error": float(s.on_off_ratio_rel_error),
            "sim_events": float(result.events.size),
        }


class NoiseObjective(Objective):
    """Noise of an empty field: the scenario with its targets and star field removed (the
    background sky stays).

    Metrics [events/s per pixel]: ``noise_rate_per_px_hz`` (all events), ``on_rate_per_px_hz``,
    ``off_rate_per_px_hz``; ``active_px_fraction``: share of pixels with at least one event.
    """

    name = "noise"
    metrics = ("noise_rate_per_px_hz", "on_rate_per_px_hz", "off_rate_per_px_hz", "active_px_fraction")
    headline = ("noise_rate_per_px_hz",)

    def prepare(self, scenario: dict[str, Any]) -> dict[str, Any]:
        out = dict(scenario)
        out["targets"] = []
        out.pop("star_field", None)
        return out

    def evaluate(self, result: Any) -> dict[str, float]:
        w, h = int(result.meta["width"]), int(result.meta["height"])
        dur = float(result.meta["duration_s"])
        ev = result.events
        npix = w * h
        on = int(np.count_nonzero(ev["p"] == 1))
        active = np.unique(ev["y"].astype(np.int64) * w + ev["x"]).size if ev.size else 0
        return {
            "noise_rate_per_px_hz": ev.size / (npix * dur),
            "on_rate_per_px_hz": on / (npix * dur),
            "off_rate_per_px_hz": (ev.size - on) / (npix * dur),
            "active_px_fraction": active / npix,
        }


class DetectObjective(Objective):
    """How well an SSA target shows in the events, from the simulation's ground truth.

    target: name of a moving target in ``meta['truth']`` (its ``label``); None = the first.

    Definitions (track = the path of the target's centre, linear between truth samples):

    * track pixels: the pixels whose square the centre passes through, inside the sensor,
      except those it occupies at the track's first time (no entry to measure);
    * a track pixel's window: from the first time the centre comes within ``radius_px`` of
      the pixel's square (Chebyshev distance; the PSF wing arrives before the centre) to
      ``tail_s`` after the last time it is within it (the pixel's filters lag);
    * ``track_fraction``: share of track pixels with at least one event (either polarity) in
      their window;
    * ``track_events_per_s``: events in the track pixels' windows per second of recording;
    * ``signal_rate_per_px_hz``: the same events per second of window, per track pixel;
    * ``noise_rate_per_px_hz``: events per second per pixel on the pixels farther than
      ``exclude_px`` (Chebyshev) from every track pixel ("elsewhere"; stars included);
    * ``snr``: signal_rate_per_px_hz / noise_rate_per_px_hz, how much more often a pixel
      fires while the target is on it than a pixel elsewhere (inf when no noise);
    * ``chance_fraction``: the track_fraction noise alone would give, mean over track pixels
      of 1 - exp(-noise_rate_per_px_hz x window length) (Poisson);
    * ``excess_fraction``: the detection probability corrected for chance,
      (track_fraction - chance_fraction) / (1 - chance_fraction);
    * ``latency_median_s``: median over the track pixels that fired of the first event's time
      in the window minus the window's opening (the target's centre coming within radius_px of
      the pixel's square: its light arriving; resolved to 1/50 px of travel), so never
      negative; nan when none fired;
    * ``track_px``: number of track pixels.
    """

    name = "detect"
    metrics = (
        "track_fraction",
        "excess_fraction",
        "chance_fraction",
        "track_events_per_s",
        "signal_rate_per_px_hz",
        "noise_rate_per_px_hz",
        "snr",
        "latency_median_s",
        "track_px",
    )
    headline = ("excess_fraction", "snr", "latency_median_s")

    def __init__(
        self, target: str | None = None, radius_px: float = 1.0, tail_s: float = 0.1, exclude_px: float = 3.0
    ) -> None:
        for name, v in (("radius_px", radius_px), ("tail_s", tail_s), ("exclude_px", exclude_px)):
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a finite number >= 0; got {v!r}")
        self.target = target
        self.radius_px = float(radius_px)
        self.tail_s = float(tail_s)
        self.exclude_px = float(exclude_px)

    def check(self, scene: Any) -> None:
        from ..simulate import track_names

        names = track_names(scene)
        if not names:
            raise ValueError("the detect objective needs a moving target; the scenario has none")
        if self.target is not None and self.target not in names:
            raise ValueError(
                f"detect target {self.target!r} is not a moving target of the scenario; known: {', '.join(names)}"
            )

    def evaluate(self, result: Any) -> dict[str, float]:
        truth = result.meta.get("truth") or {}
        if not truth:
            raise ValueError(
                "the detect objective needs a moving target (the scenario has none in its truth)"
            )
        if self.target is None:
            name = next(iter(truth))
        elif self.target in truth:
            name = self.target
        else:
            raise ValueError(
                f"detect target {self.target!r} is not a moving target of the scenario; "
                f"known: {', '.join(truth)}"
            )
        return detect_metrics(
            result.events,
            int(result.meta["width"]),
            int(result.meta["height"]),
            float(result.meta["duration_s"]),
            truth[name],
            radius_px=self.radius_px,
            tail_s=self.tail_s,
            exclude_px=self.exclude_px,
        )


def _dense_track(t: np.ndarray, x: np.ndarray, y: np.ndarray, step_px: float) -> tuple[np.ndarray, ...]:
    """The track resampled so that no step exceeds ``step_px`` (linear between samples)."""
    if t.size < 2:
        return t, x, y
    seg = np.hypot(np.diff(x), np.diff(y))
    n = np.maximum(1, np.ceil(seg / step_px)).astype(np.int64)
    owner = np.repeat(np.arange(seg.size), n)
    frac = (np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)) / n[owner]
    td = np.append(t[owner] + frac * np.diff(t)[owner], t[-1])
    xd = np.append(x[owner] + frac * np.diff(x)[owner], x[-1])
    yd = np.append(y[owner] + frac * np.diff(y)[owner], y[-1])
    return td, xd, yd


def detect_metrics(
    events: np.ndarray,
    width: int,
    height: int,
    duration_s: float,
    track: Mapping[str, Any],
    radius_px: float = 1.0,
    tail_s: float = 0.1,
    exclude_px: float = 3.0,
) -> dict[str, float]:
    """The metrics of :class:`DetectObjective` for one target's truth track
    ({'t_s', 'x_px', 'y_px'} arrays [s, px]) on a width x height sensor [px]."""
    t = np.asarray(track["t_s"], dtype=np.float64)
    x = np.asarray(track["x_px"], dtype=np.float64)
    y = np.asarray(track["y_px"], dtype=np.float64)
    td, xd, yd = _dense_track(t, x, y, 0.02)  # entry times to 1/50 px of travel
    npix = width * height
    # Entry / exit of each pixel's square, and of its neighbourhood (square grown by radius_px).
    px_c, py_c = np.floor(xd + 0.5).astype(np.int64), np.floor(yd + 0.5).astype(np.int64)
    inside = (px_c >= 0) & (px_c < width) & (py_c >= 0) & (py_c < height)
    key = py_c[inside] * width + px_c[inside]
    t_in = td[inside]
    enter = np.full(npix, np.inf)
    np.minimum.at(enter, key, t_in)
    start_px = key[t_in == td[0]] if td.size else np.zeros(0, np.int64)
    track_mask = np.isfinite(enter)
    track_mask[start_px] = False
    track_idx = np.flatnonzero(track_mask)
    r = math.ceil(radius_px + 0.5)
    win_open = np.full(npix, np.inf)
    win_close = np.full(npix, -np.inf)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            qx, qy = px_c + dx, py_c + dy
            near = (
                (np.abs(xd - qx) <= 0.5 + radius_px)
                & (np.abs(yd - qy) <= 0.5 + radius_px)
                & (qx >= 0)
                & (qx < width)
                & (qy >= 0)
                & (qy < height)
            )
            k = qy[near] * width + qx[near]
            np.minimum.at(win_open, k, td[near])
            np.maximum.at(win_close, k, td[near])
    win_close = win_close + tail_s
    n_track = track_idx.size

    ex = events["x"].astype(np.int64)
    ey = events["y"].astype(np.int64)
    et = events["t"].astype(np.int64) * 1e-6
    ek = ey * width + ex
    on_track = track_mask[ek] & (et >= win_open[ek]) & (et <= win_close[ek])
    n_sig = int(np.count_nonzero(on_track))
    first = np.full(npix, np.inf)
    np.minimum.at(first, ek[on_track], et[on_track])
    fired = np.isfinite(first[track_idx])
    window_len = np.clip(
        np.minimum(win_close[track_idx], duration_s) - np.maximum(win_open[track_idx], 0.0), 0.0, None
    )

    # "Elsewhere": pixels farther than exclude_px (Chebyshev) from every track pixel.
    grid = np.zeros((height, width), dtype=bool)
    if n_track:
        grid.reshape(-1)[track_idx] = True
    k_px = math.floor(exclude_px)
    near = grid.copy()
    if k_px > 0 and n_track:
        from scipy.ndimage import binary_dilation

        near = binary_dilation(grid, structure=np.ones((2 * k_px + 1, 2 * k_px + 1), dtype=bool))
    noise_mask = ~near.reshape(-1)
    noise_mask[start_px] = False
    n_noise_px = int(np.count_nonzero(noise_mask))
    n_noise_ev = int(np.count_nonzero(noise_mask[ek]))
    noise_rate = n_noise_ev / (n_noise_px * duration_s) if n_noise_px and duration_s > 0 else math.nan
    sig_time = float(window_len.sum())
    signal_rate = n_sig / sig_time if sig_time > 0 else math.nan
    track_fraction = float(fired.mean()) if n_track else math.nan
    chance = (
        float(np.mean(1.0 - np.exp(-noise_rate * window_len)))
        if n_track and math.isfinite(noise_rate)
        else math.nan
    )
    if math.isfinite(chance) and chance < 1.0:
        excess = (track_fraction - chance) / (1.0 - chance)
    else:
        excess = math.nan
    if noise_rate > 0:
        snr = signal_rate / noise_rate
    elif noise_rate == 0:
        snr = math.inf if signal_rate > 0 else math.nan
    else:
        snr = math.nan
    latency = first[track_idx][fired] - win_open[track_idx][fired]  # events count from the window's opening
    return {
        "track_fraction": track_fraction,
        "excess_fraction": float(excess),
        "chance_fraction": chance,
        "track_events_per_s": n_sig / duration_s if duration_s > 0 else math.nan,
        "signal_rate_per_px_hz": signal_rate,
        "noise_rate_per_px_hz": noise_rate,
        "snr": float(snr),
        "latency_median_s": float(np.median(latency)) if latency.size else math.nan,
        "track_px": float(n_track),
    }


OBJECTIVES = ("match", "detect", "noise")


"""Objective names of :func:`sweep` and ``evstwin sweep --objective``."""


def make_objective(
    objective: str | Objective,
    real: Recording | PathLike | None = None,
    target: str | None = None,
    bin_width: float = 2.0,
    roi: Any = None,
    mask_pixels: Sequence[tuple[int, int]] = (),
    mask_hot: bool = False,
) -> Objective:
    """An :class:`Objective` from its name (``real`` is the recording of ``match``: events and
    meta, or a file; ``target`` the target of ``detect``; ``roi``, ``mask_pixels`` and
    ``mask_hot`` those of :class:`MatchObjective`), or the object itself."""
    if isinstance(objective, Objective):
        return objective
    if objective != "match" and (roi is not None or mask_pixels or mask_hot):
        raise ValueError(f"roi and pixel masks are for objective 'match'; got objective {objective!r}")
    if objective == "match":
        if real is None:
            raise ValueError("objective 'match' needs a real recording (--real FILE)")
        events, meta = _read_real(real)
        return MatchObjective(events, meta, bin_width=bin_width, roi=roi, mask_pixels=mask_pixels, mask_hot=mask_hot)
    if objective == "detect":
        return DetectObjective(target=target)
    if objective == "noise":
        return NoiseObjective()
    raise ValueError(f"objective must be one of {', '.join(OBJECTIVES)}; got {objective!r}")


def _read_real(real: Recording | PathLike) -> tuple[np.ndarray, dict[str, Any]]:
    if isinstance(real, tuple):
        events, meta = real
        return events, dict(meta)
    from ..io import read_events

    events, meta = read_events(real)
    return events, dict(meta)
