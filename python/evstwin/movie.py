"""A recording as a movie (MP4 or GIF), rendered by faery (``evstwin[io]``).

Any file :func:`evstwin.io.iter_events` reads is cut to a time window, cut into frames of
``speed / frame_rate_hz`` seconds of recording time each, and each frame drawn by faery's
renderer (``Render``: every pixel's last event, weighted by a decay of its age: exponential,
linear, window or cumulative with time constant ``tau_s``) through a diverging colour map
OFF colour -> background -> ON colour, then encoded by faery's MP4 (H.264) or GIF encoder.
Where the file holds the simulation's ground truth (``meta['truth']``: ``t_s``, ``x_px``,
``y_px`` of each target), each target's true place at the frame's time is drawn as a square
outline in its own colour (the legend is printed). With ``color_by='label'`` a file with a label
column (``evstwin simulate --labels``) shows why each event fired: the signal's events in the
ON/OFF colours, each kind of noise (shot noise, leak, background, hot pixel) in its own colour;
faery renders each kind as its own layer, with the same decay, and a pixel takes the colour of
the layer that stands out most from the background there. The file appears under its name only once
it is complete: it is written under a hidden name beside it and renamed at the end; an error
or Ctrl-C removes it.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ._extras import require
from .io import iter_events
from .io._common import one_line, remove_quietly, temporary_path, to_faery
from .sensor import EVENT_DTYPE, EVENT_LABELS

DECAYS = ("exponential", "linear", "window", "cumulative")
SUFFIXES = (".mp4", ".gif")
MAX_FRAMES = 100_000
"""Most frames one movie may have (a typo in --frame-rate or --speed otherwise renders for hours)."""
TRUTH_COLORS = ("#FFD700", "#00BFFF", "#FF69B4", "#7FFF00", "#FFA500", "#BA55D3", "#40E0D0", "#FFFFFF")
"""Colours of the ground-truth markers, one per target in the file's order (repeating)."""
COLOR_BY = ("polarity", "label")
LABEL_COLORS: dict[int, str] = {1: "#E040FB", 2: "#FF7043", 3: "#9E9E9E", 4: "#FF1744"}
"""Colour of each noise label (codes of ``EVENT_LABELS`` other than 0, the signal) with ``color_by='label'``."""
SIGNAL = 0
"""The label code of the signal's events (``EVENT_LABELS[0]``)."""
_HEX = re.compile(r"^#?([0-9a-fA-F]{6})$")


@dataclass(frozen=True)
class MovieOptions:
    """How a recording becomes frames. Times in seconds of the recording; colours '#RRGGBB'."""

    t0_s: float = 0.0
    """Start of the movie after the recording's first event [s]."""
    duration_s: float | None = None
    """Length of recording shown [s]; None: to the last event."""
    frame_rate_hz: float = 30.0
    """Frames per second of the video."""
    speed: float = 1.0
    """Recording time per second of video: each frame spans ``speed / frame_rate_hz`` seconds."""
    decay: str = "exponential"
    tau_s: float | None = None
    """The decay's time constant [s]; None: one frame's span."""
    on_color: str = "#F4C20D"
    off_color: str = "#1E88E5"
    background: str = "#000000"
    scale: int = 1
    """Each sensor pixel becomes scale x scale video pixels (nearest)."""
    truth: bool = True
    color_by: str = "polarity"
    """'polarity': every event in the ON/OFF colours; 'label': noise events in their label's colour."""

    @property
    def frame_span_s(self) -> float:
        return self.speed / self.frame_rate_hz

    def check(self) -> None:
        """ValueError naming the option for anything a movie cannot be made with."""
        checks = [
            (self.t0_s >= 0, "--t0", self.t0_s, "must be >= 0 s"),
            (self.duration_s is None or self.duration_s > 0, "--duration", self.duration_s, "must be > 0 s"),
            (math.isfinite(self.frame_rate_hz) and 0 < self.frame_rate_hz <= 1000, "--frame-rate",
             self.frame_rate_hz, "must be in (0, 1000] Hz"),
            (math.isfinite(self.speed) and self.speed > 0, "--speed", self.speed, "must be > 0"),
            (self.decay in DECAYS, "--decay", self.decay, f"must be one of {', '.join(DECAYS)}"),
            (self.tau_s is None or (math.isfinite(self.tau_s) and self.tau_s > 0), "--tau", self.tau_s,
             "must be > 0 s"),
            (1 <= self.scale <= 16, "--scale", self.scale, "must be an integer in 1..16"),
            (self.color_by in COLOR_BY, "--color-by", self.color_by, f"must be one of {', '.join(COLOR_BY)}"),
        ]
        for ok, option, value, rule in checks:
            if not ok:
                raise ValueError(f"{option} {rule}; got {value!r}")
        for option, value in (("--on-color", self.on_color), ("--off-color", self.off_color),
                              ("--background", self.background)):
            parse_color(value, option)


def parse_color(text: str, option: str) -> tuple[int, int, int]:
    """'#RRGGBB' (or 'RRGGBB') as (r, g, b) 0..255, or ValueError naming ``option``."""
    match = _HEX.match(str(text).strip())
    if match is None:
        raise ValueError(f"{option} takes a colour as #RRGGBB (e.g. #F4C20D); got {text!r}")
    value = int(match[1], 16)
    return (value >> 16) & 255, (value >> 8) & 255, value & 255


@dataclass
class Movie:
    """What :func:`render_movie` wrote."""

    path: Path
    frames: int
    size_px: tuple[int, int]
    window_us: tuple[int, int]
    events: int
    legend: dict[str, str]
    """What each colour means: a label or a target ("truth NAME") -> its colour(s)."""


def render_movie(path_in: str | os.PathLike[str], out: str | os.PathLike[str], options: MovieOptions,
                 *, size: tuple[int, int] | None = None,
                 progress: Callable[[int, int], None] | None = None) -> Movie:
    """Render ``path_in`` into ``out`` (``.mp4`` or ``.gif``); ``progress(done, total)`` is
    called after each frame. Raises ValueError (one line, naming the option) for bad options,
    a window past the end of the recording or an empty one."""
    options.check()
    out = Path(out)
    if out.suffix.lower() not in SUFFIXES:
        raise ValueError(f"--out {out}: a movie is .mp4 or .gif; got the suffix {out.suffix!r}")
    faery = require("faery", "movies")
    events, labels, meta, window = _window(path_in, options, size)
    width, height = int(meta["width"]), int(meta["height"])
    span_us = window[1] - window[0]
    period_us = options.frame_span_s * 1e6
    frames = math.ceil(span_us / period_us - 1e-9)
    if frames > MAX_FRAMES:
        raise ValueError(
            f"{frames} frames ({span_us * 1e-6:.6g} s at {options.frame_span_s:.6g} s a frame) is more than "
            f"{MAX_FRAMES}: shorten --duration, or raise --speed or lower --frame-rate"
        )
    tau_us = round((options.tau_s if options.tau_s is not None else options.frame_span_s) * 1e6)
    off, bg, on = (parse_color(c, o) for c, o in ((options.off_color, "--off-color"),
                                                  (options.background, "--background"),
                                                  (options.on_color, "--on-color")))
    frames_us = (window[0], window[0] + round(frames * period_us))
    window_array = _window_array_class()

    def rendered(chosen: np.ndarray, low: tuple[int, int, int], high: tuple[int, int, int]) -> Any:
        """faery's frames of ``chosen`` events over the whole window (empty frames included)."""
        colormap = faery.Colormap.diverging_from_triplet("evstwin", _hex(low), _hex(bg), _hex(high))
        stream = (window_array(to_faery(chosen), (width, height), frames_us)
                  .regularize(frequency_hz=1e6 / period_us, start=window[0] * faery.us)
                  .render(decay=options.decay, tau=tau_us * faery.us, colormap=colormap))
        return stream.scale(options.scale) if options.scale > 1 else stream

    legend: dict[str, str] = {}
    layers: list[Any] = []
    if labels is None:
        stream = rendered(events, off, on)
    else:  # the signal in the ON/OFF colours below one layer per kind of noise in the window
        stream = rendered(events[labels == SIGNAL], off, on)
        legend[EVENT_LABELS[SIGNAL]] = f"ON {_hex(on)}, OFF {_hex(off)}"
        for code, color in LABEL_COLORS.items():
            if (labels == code).any():
                rgb = parse_color(color, "label colour")
                layers.append(rendered(events[labels == code], rgb, rgb))
                legend[EVENT_LABELS[code]] = color
    tracks = _truth_tracks(meta) if options.truth else {}
    truth_legend = {name: TRUTH_COLORS[i % len(TRUTH_COLORS)] for i, name in enumerate(tracks)}
    legend.update({f"truth {name}": f"{color} square" for name, color in truth_legend.items()})
    video = (width * options.scale, height * options.scale)
    if out.suffix.lower() == ".mp4":  # H.264 (yuv420) takes even sizes: one background row/column more
        video = (video[0] + video[0] % 2, video[1] + video[1] % 2)
    if tracks or layers or video != (width * options.scale, height * options.scale):
        stream = _Finish(stream, layers, tracks, truth_legend, options.scale, (width, height), video, bg)
    done = [0]

    def on_progress(state: Any) -> None:
        if progress is not None and hasattr(state.frame, "index"):
            done[0] += 1
            progress(done[0], frames)

    tmp = temporary_path(out, "partial").with_suffix(out.suffix)
    # faery writes FILE.write and renames it FILE at its end
    partials = (tmp, tmp.with_suffix(tmp.suffix + ".write"))
    try:
        try:
            stream.to_file(tmp, frame_rate=options.frame_rate_hz, on_progress=on_progress,
                           file_type=out.suffix.lower().lstrip("."))
        except (ValueError, OSError):
            raise
        except Exception as exc:  # noqa: BLE001 - faery's encoders raise plain Exception
            raise ValueError(f"--out {out}: faery could not write the movie: {one_line(exc)}") from exc
        from ._signals import sigint_deferred

        with sigint_deferred():
            os.replace(tmp, out)
    except BaseException:
        remove_quietly(*partials)
        raise
    return Movie(out, frames, video, window, len(events), legend)


def _hex(rgb: tuple[int, int, int]) -> str:
    return "#{:02X}{:02X}{:02X}".format(*rgb)


def _window(path: str | os.PathLike[str], options: MovieOptions, size: tuple[int, int] | None
            ) -> tuple[np.ndarray, np.ndarray | None, Mapping[str, Any], tuple[int, int]]:
    """The events of the window [first + t0, first + t0 + duration) in one pass over the file
    (memory: the window's events), their labels (``color_by='label'``; else None), the file's
    meta and the window [us]."""
    stream = iter_events(path, size=size)
    by_label = options.color_by == "label"
    if by_label and not stream.meta.get("has_labels"):
        raise ValueError(f"--color-by label: {path} has no label column (simulate with --labels; "
                         ".h5, .npz, .txt and .csv files carry one)")
    chunks: Iterator[tuple[np.ndarray, np.ndarray | None]] = (
        stream.labeled() if by_label else ((chunk, None) for chunk in stream))
    kept: list[np.ndarray] = []
    kept_labels: list[np.ndarray] = []
    first: int | None = None
    last: int | None = None
    start = end = 0
    for chunk, chunk_labels in chunks:
        if not len(chunk):
            continue
        if first is None:
            first = int(chunk["t"][0])
            start = first + round(options.t0_s * 1e6)
            end = start + round(options.duration_s * 1e6) if options.duration_s is not None else 0
        last = int(chunk["t"][-1])
        t = chunk["t"]
        keep = (t >= start) if options.duration_s is None else ((t >= start) & (t < end))
        if keep.any():
            kept.append(chunk[keep])
            if chunk_labels is not None:
                kept_labels.append(chunk_labels[keep])
    if first is None or last is None:
        raise ValueError(f"{path} holds no events: nothing to show")
    if start > last:
        raise ValueError(f"--t0 {options.t0_s:g} s is past the recording's end ({(last - first) * 1e-6:.6g} s after "
                         f"its first event): nothing to show")
    if options.duration_s is None:
        end = last + 1
    events = np.concatenate(kept) if kept else np.empty(0, EVENT_DTYPE)
    labels = (np.concatenate(kept_labels) if kept_labels else np.empty(0, np.uint8)) if by_label else None
    if len(events) > 1:
        order = np.argsort(events["t"], kind="stable")
        events = events[order]
        labels = labels[order] if labels is not None else None
    return events, labels, stream.meta, (start, end)


def _window_array_class() -> Any:
    faery = require("faery", "movies")

    class WindowArray(faery.events_stream.Array):  # type: ignore[misc, name-defined]
        """faery's array of events with the movie's window as its time range, so that every layer
        has a frame for every period of the window, before the first event and after the last."""

        def __init__(self, events: np.ndarray, dimensions: tuple[int, int], window_us: tuple[int, int]) -> None:
            super().__init__(events, dimensions)
            self.window_us = window_us

        def time_range(self) -> tuple[Any, Any]:
            return (faery.Time(microseconds=self.window_us[0]), faery.Time(microseconds=self.window_us[1]))

    return WindowArray


def _truth_tracks(meta: Mapping[str, Any]) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """name -> (t_us, x_px, y_px) of every target with a sampled track."""
    out: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    for name, fields in (meta.get("truth") or {}).items():
        if not isinstance(fields, Mapping) or not all(k in fields for k in ("t_s", "x_px", "y_px")):
            continue
        t = np.asarray(fields["t_s"], np.float64) * 1e6
        x, y = np.asarray(fields["x_px"], np.float64), np.asarray(fields["y_px"], np.float64)
        if t.ndim == 1 and t.shape == x.shape == y.shape and len(t):
            out[str(name)] = (t, x, y)
    return out


def _finish_class() -> Any:
    faery = require("faery", "movies")

    class Finish(faery.frame_stream.FiniteRegularFrameFilter):  # type: ignore[misc, name-defined]
        """The layers of the other labels over the parent's frames (each pixel from the layer
        farthest from the background), square outlines at each target's true place at the
        frame's time; frames padded with the background to ``video`` (width, height)."""

        def __init__(self, parent: Any, layers: list[Any],
                     tracks: Mapping[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
                     legend: Mapping[str, str], scale: int, sensor: tuple[int, int], video: tuple[int, int],
                     background: tuple[int, int, int]) -> None:
            self.init(parent=parent)
            self.layers = layers
            self.tracks = tracks
            self.colors = {name: parse_color(legend[name], "legend") for name in tracks}
            self.scale = scale
            self.sensor = sensor
            self.video = video
            self.background = np.array([*background, 255], np.uint8)

        def dimensions(self) -> tuple[int, int]:
            return self.video

        def __iter__(self) -> Iterator[Any]:
            for frame, *others in zip(self.parent, *self.layers, strict=True):
                pixels = np.empty((self.video[1], self.video[0], 4), np.uint8)
                pixels[...] = self.background
                rows, cols = frame.pixels.shape[:2]
                pixels[:rows, :cols] = over_background([frame.pixels, *(o.pixels for o in others)],
                                                       self.background)
                t_us = float(frame.t.to_microseconds())
                for name, (t, x, y) in self.tracks.items():
                    if not t[0] <= t_us <= t[-1]:
                        continue
                    draw_square(pixels, float(np.interp(t_us, t, x)), float(np.interp(t_us, t, y)),
                                self.colors[name], self.scale, self.sensor)
                yield faery.frame_stream.Frame(t=frame.t, pixels=pixels)

    return Finish


def _Finish(parent: Any, layers: list[Any], tracks: Any, legend: Any, scale: int,  # noqa: N802
            sensor: tuple[int, int], video: tuple[int, int], background: tuple[int, int, int]) -> Any:
    return _finish_class()(parent, layers, tracks, legend, scale, sensor, video, background)


def over_background(layers: list[np.ndarray], background: np.ndarray) -> np.ndarray:
    """Per pixel, the RGBA value of the layer farthest from ``background`` (summed |RGB|
    difference; the first layer where they tie): the composite of layers drawn on one background."""
    if len(layers) == 1:
        return layers[0]
    stack = np.stack(layers)
    distance = np.abs(stack[..., :3].astype(np.int16) - background[:3].astype(np.int16)).sum(axis=-1)
    choice = np.argmax(distance, axis=0)
    return np.take_along_axis(stack, choice[None, ..., None], axis=0)[0]


MARKER_HALF_PX = 3
"""Half the side of a ground-truth marker, in sensor pixels (at least 3 video pixels)."""


def draw_square(pixels: np.ndarray, x_px: float, y_px: float, rgb: tuple[int, int, int], scale: int,
                sensor: tuple[int, int]) -> None:
    """A square outline centred on sensor pixel (x_px, y_px) drawn into RGBA ``pixels`` (in place);
    nothing where the centre is off the sensor."""
    width, height = sensor
    if not (-0.5 <= x_px < width - 0.5 and -0.5 <= y_px < height - 0.5):
        return
    cx, cy = (x_px + 0.5) * scale, (y_px + 0.5) * scale
    half = max(3, MARKER_HALF_PX * scale)
    rows, cols = pixels.shape[:2]
    x0, x1 = int(math.floor(cx - half)), int(math.floor(cx + half))
    y0, y1 = int(math.floor(cy - half)), int(math.floor(cy + half))
    color = np.array([*rgb, 255], np.uint8)
    with contextlib.suppress(IndexError):
        for yy in (y0, y1):
            if 0 <= yy < rows:
                pixels[yy, max(x0, 0):min(x1 + 1, cols)] = color
        for xx in (x0, x1):
            if 0 <= xx < cols:
                pixels[max(y0, 0):min(y1 + 1, rows), xx] = color


__all__ = ["COLOR_BY", "DECAYS", "LABEL_COLORS", "MovieOptions", "Movie", "draw_square", "over_background",
           "parse_color", "render_movie"]
