"""The sensor: a width x height array of pixels, stateful and streaming."""

from __future__ import annotations

import operator
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

from . import _core
from .pixel import PixelParams

EVENT_DTYPE: np.dtype = _core.EVENT_DTYPE
"""Event record (declared once, in C++): t [us, int64], x, y [uint16], p [uint8, 1 = ON]."""

TRACE_DTYPE: np.dtype = _core.TRACE_DTYPE
"""Probe record: current_a [A], log_current, filtered, reference [ln(I / 1 A)]."""


class Sensor:
    """An event sensor of ``width`` x ``height`` identical pixels (mismatch aside).

    ``run`` consumes photon rates chunk by chunk and returns the events of each chunk; the
    state carries over, so cutting a recording into chunks gives the same events as one call.
    The same ``seed`` gives the same events bit for bit whatever ``num_threads`` is.
    """

    def __init__(
        self,
        width: int,
        height: int,
        params: PixelParams | None = None,
        seed: int = 0,
        num_threads: int | None = None,
        max_events: int | None = None,
    ) -> None:
        params = PixelParams() if params is None else params
        if not isinstance(params, PixelParams):
            raise TypeError(f"params must be an evstwin.PixelParams; got {type(params).__name__}")
        width = _as_int("width", width)
        height = _as_int("height", height)
        seed = _as_int("seed", seed)
        if not 0 <= seed < 2**64:
            raise ValueError(f"seed must be in [0, 2**64); got seed={seed}")
        if num_threads is not None:
            num_threads = _as_int("num_threads", num_threads)
        self.params = params
        self._core = _core.Sensor(width, height, params.to_core(), seed, num_threads)
        if max_events is not None:
            self.max_events = max_events

    @property
    def max_events(self) -> int:
        """Most events one ``run``/``run_pixels`` call may produce (default
        ``DEFAULT_MAX_EVENTS``, 1e8: about 4 GB while collected). A call that passes it raises
        ValueError while producing them, before memory runs out; ``reset()`` the sensor then."""
        return int(self._core.max_events)

    @max_events.setter
    def max_events(self, value: int) -> None:
        value = _as_int("max_events", value)
        if value < 1:
            raise ValueError(f"max_events must be >= 1; got max_events={value}")
        self._core.max_events = value

    @property
    def width(self) -> int:
        return int(self._core.width)

    @property
    def height(self) -> int:
        return int(self._core.height)

    @property
    def seed(self) -> int:
        return int(self._core.seed)

    @property
    def samples_seen(self) -> int:
        """Samples consumed since construction or the last reset."""
        return int(self._core.samples_seen)

    @property
    def last_time_s(self) -> float:
        """Time of the last sample consumed [s] (-inf before the first)."""
        return float(self._core.last_time_s)

    @property
    def num_threads(self) -> int:
        return int(self._core.num_threads)

    def run(self, photon_rate: npt.ArrayLike, t_s: npt.ArrayLike) -> np.ndarray:
        """Advance the sensor through the samples and return their events.

        photon_rate: (T, height, width) float32/float64 array, photons/s arriving on each
            pixel at each sample time (read without a copy when C-contiguous).
        t_s: the T sample times [s], strictly increasing, after the previous run's last.

        Returns an EVENT_DTYPE array sorted by t (microseconds, from t = 0 s). The first
        sample after construction or reset only sets the steady state: no event fires.
        """
        return self._core.run(_as_array(photon_rate), _as_array(t_s, "t_s"))

    def run_probe(
        self, photon_rate: npt.ArrayLike, t_s: npt.ArrayLike, pixels: Sequence[tuple[int, int]]
    ) -> tuple[np.ndarray, np.ndarray]:
        """Like run, and also return a (T, len(pixels)) TRACE_DTYPE array of the internal
        signals (current, log current, filtered level, reference) of the pixels (x, y)."""
        index = []
        for x, y in pixels:
            if not (0 <= x < self.width and 0 <= y < self.height):
                raise ValueError(f"pixels must lie on the {self.width}x{self.height} sensor; got (x, y)=({x}, {y})")
            index.append(int(y) * self.width + int(x))
        events, trace = self._core.run_probe(_as_array(photon_rate), _as_array(t_s, "t_s"), index)
        return events, trace

    def run_pixels(self, pixels: npt.ArrayLike, photon_rate: npt.ArrayLike, t_s: npt.ArrayLike) -> np.ndarray:
        """Advance only some pixels through their own, finer sample times.

        pixels: row-major indices ``y * width + x`` (no repeats); photon_rate: (T, len(pixels))
        photons/s; t_s: T times [s] after every listed pixel's last sample. A later ``run``
        skips, for these pixels, the samples they have already passed, so a pixel near a fast
        source can be sub-sampled while the rest of the array keeps the base rate. Each
        pixel's random numbers follow its own sample counter. Returns the events, sorted.
        """
        return self._core.run_pixels(_as_array(pixels, "pixels"), _as_array(photon_rate), _as_array(t_s, "t_s"))

    def reset(self) -> None:
        """Forget the past (the next sample is a first sample); mismatch is kept."""
        self._core.reset()

    def thresholds(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-pixel (theta_on, theta_off), each (height, width), mismatch included."""
        return self._core.thresholds(True), self._core.thresholds(False)

    def __repr__(self) -> str:
        return f"Sensor({self.width}x{self.height}, seed={self.seed}, samples_seen={self.samples_seen})"


def _as_int(name: str, value: object) -> int:
    if isinstance(value, bool):
        raise TypeError(f"{name} must be an integer; got {name}={value!r}")
    try:
        return operator.index(value)  # type: ignore[arg-type]
    except TypeError:
        raise TypeError(f"{name} must be an integer; got {name}={value!r}") from None


def _as_array(value: npt.ArrayLike, name: str = "photon_rate") -> np.ndarray:
    if isinstance(value, np.ndarray):
        return value
    try:
        return np.asarray(value)
    except (ValueError, TypeError) as exc:
        raise TypeError(f"{name} must be array-like; got {type(value).__name__}: {exc}") from None
