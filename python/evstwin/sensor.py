"""The sensor: a width x height array of pixels, stateful and streaming."""

from __future__ import annotations

import contextlib
import numbers
from collections.abc import Iterator, Mapping, Sequence

import numpy as np
import numpy.typing as npt

from . import _core
from ._checks import integer
from .pixel import HotPixelChain, PixelParams

EVENT_DTYPE: np.dtype = _core.EVENT_DTYPE
"""Event record (declared once, in C++): t [us, int64], x, y [uint16], p [uint8, 1 = ON]."""

EVENT_LABELS: dict[int, str] = dict(_core.EVENT_LABELS)
"""Why an event fired, code -> name (declared once, in C++: ``EventLabel`` in params.hpp): 0
signal (the scene's light changed), 1 shot_noise (photon and dark-current shot noise), 2 leak,
3 background (eq. 12 background activity), 4 hot_pixel. The codes of ``Sensor.last_labels()``,
``SimulationResult.labels`` and the label column of event files."""

TRACE_DTYPE: np.dtype = _core.TRACE_DTYPE
"""Probe record: current_a [A], log_current, filtered, reference [ln(I / 1 A)]."""

MAX_THREADS: int = int(_core.Sensor.MAX_THREADS)
"""Most engine threads (1024): far above any machine's cores, far below the few thousand at
which the OpenMP runtime exits or crashes."""

MAX_PIXELS: int = int(_core.Sensor.MAX_PIXELS)
"""Most pixels of one sensor (2**26, 8192 x 8192, each keeping ``STATE_BYTES_PER_PIXEL`` bytes of
state), refused up front."""

STATE_BYTES_PER_PIXEL: int = int(_core.Sensor.STATE_BYTES_PER_PIXEL)
"""Bytes of engine state each pixel keeps between calls."""

DEFAULT_MAX_EVENTS: int = int(_core.Sensor.DEFAULT_MAX_EVENTS)
"""Events one ``run`` call may produce by default (1e8, about 3 GB while collected)."""

MAX_MAX_EVENTS = 2**32 - 1
"""Largest ``max_events`` (the engine sorts one call's events with 32-bit indices)."""

MAX_HOT_PIXEL_CHAINS: int = int(_core.Sensor.MAX_HOT_PIXEL_CHAINS)
"""Most pixels with a chain of their own (``Sensor::set_hot_pixel_chains``: a 16-bit index)."""


def simd_levels() -> list[str]:
    """The SIMD levels of the engine's batched loops (Philox, the ziggurat) that this processor
    and build can run, lowest first: 'baseline' (what the build targets: SSE2 on x86-64), then
    'avx2' and 'avx512' where supported. Every level gives the same events, bit for bit."""
    return list(_core.simd_levels())


def simd_level() -> str:
    """The SIMD level the engine uses now: the best of ``simd_levels()`` unless set."""
    return str(_core.simd_level())


def set_simd_level(level: str) -> None:
    """Force the engine's SIMD level, process-wide (for tests and benchmarks; the events do not
    change). Raises ValueError for a level not in ``simd_levels()``."""
    _core.set_simd_level(level)


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
        hot_pixel_rates_hz: npt.ArrayLike | None = None,
        hot_pixel_chains: Mapping[tuple[int, int], HotPixelChain] | None = None,
    ) -> None:
        """hot_pixel_rates_hz: an explicit hot-pixel map, (height, width) rates r [Hz] (0 = not
        hot; see ``PixelParams.hot_pixel_rate_hz`` for what r means), in place of the pixels that
        ``params.hot_pixel_fraction`` would draw.

        hot_pixel_chains: {(x, y): HotPixelChain}, hot pixels with a telegraph and polarity
        chain of their own (whenever they are hot, by the draw or the map); every other pixel
        draws exactly what it draws without them."""
        params = PixelParams() if params is None else params
        if not isinstance(params, PixelParams):
            raise TypeError(f"params must be an evstwin.PixelParams; got {type(params).__name__}")
        width = _in_range("width", integer("width", width), 1, 65535)
        height = _in_range("height", integer("height", height), 1, 65535)
        if width * height > MAX_PIXELS:
            raise ValueError(
                f"width * height must be at most {MAX_PIXELS} pixels (8192 x 8192); got width={width}, "
                f"height={height}: {width * height} pixels, {width * height * STATE_BYTES_PER_PIXEL / 1e9:.3g} GB of pixel state"
            )
        seed = integer("seed", seed)
        if not 0 <= seed < 2**64:
            raise ValueError(f"seed must be in [0, 2**64); got seed={seed}")
        if num_threads is not None:
            num_threads = _in_range("num_threads", integer("num_threads", num_threads), 1, MAX_THREADS, "or None")
        self.params = params
        self._core = _core.Sensor(width, height, params.to_core(), seed, num_threads)
        if max_events is not None:
            self.max_events = max_events
        if hot_pixel_rates_hz is not None:
            rates = np.asarray(hot_pixel_rates_hz, dtype=np.float64)
            if rates.shape != (height, width):
                raise ValueError(f"hot_pixel_rates_hz must have the sensor's shape (height, width) = ({height}, {width}); "
                                 f"got shape {rates.shape}")
            self._core.set_hot_pixel_rates(rates.ravel())
        if hot_pixel_chains:
            self._set_hot_pixel_chains(hot_pixel_chains)

    def _set_hot_pixel_chains(self, chains: Mapping[tuple[int, int], HotPixelChain]) -> None:
        if not isinstance(chains, Mapping):
            raise TypeError(f"hot_pixel_chains must be a mapping {{(x, y): HotPixelChain}}; got {type(chains).__name__}")
        width, height = self._core.width, self._core.height
        if len(chains) > MAX_HOT_PIXEL_CHAINS:
            raise ValueError(f"hot_pixel_chains may hold at most {MAX_HOT_PIXEL_CHAINS} pixels; got "
                             f"{len(chains)}")
        pixels = []
        for key, chain in chains.items():
            ok = (isinstance(key, tuple) and len(key) == 2
                  and all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in key))
            if not ok:
                raise TypeError(f"hot_pixel_chains keys must be (x, y) pixel coordinates; got {key!r}")
            x, y = int(key[0]), int(key[1])
            if not (0 <= x < width and 0 <= y < height):
                raise ValueError(f"hot_pixel_chains[{key!r}] lies off the {width}x{height} sensor")
            if not isinstance(chain, HotPixelChain):
                raise TypeError(f"hot_pixel_chains[{key!r}] must be an evstwin.HotPixelChain; got {type(chain).__name__}")
            pixels.append(y * width + x)
        values = list(chains.values())
        self._core.set_hot_pixel_chains(pixels, [c.duty for c in values], [c.burst_s for c in values],
                                        [c.on_share for c in values], [c.alternation for c in values])

    def hot_pixel_rates_hz(self) -> np.ndarray:
        """Each pixel's hot rate r [Hz] (0 = not hot), (height, width): the draw or the map."""
        return np.asarray(self._core.hot_pixel_rates())

    def last_labels(self) -> np.ndarray:
        """Why each event of the last ``run``/``run_probe``/``run_pixels`` call fired, in the
        order of its events: uint8 codes, named in ``EVENT_LABELS`` (signal, shot_noise, leak,
        background, hot_pixel). Shot-noise labels need the continuous noise model (the sampled
        model's noise is inside the signal)."""
        return np.asarray(self._core.last_labels())

    @property
    def max_events(self) -> int:
        """Most events one ``run``/``run_probe``/``run_pixels`` call may produce (default
        ``DEFAULT_MAX_EVENTS``, 1e8: about 3 GB while collected, so a flood of events stops with
        a ValueError long before memory runs out). Counted while the events are produced; a
        call that passes it may leave the pixels half advanced, and the sensor refuses further
        calls (RuntimeError) until ``reset()``. Raise it, up to 2**32 - 1, if memory allows;
        or give ``max_events=`` to one call."""
        return int(self._core.max_events)

    @max_events.setter
    def max_events(self, value: int) -> None:
        self._core.max_events = _max_events(value)

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

    def run(self, photon_rate: npt.ArrayLike, t_s: npt.ArrayLike, *, max_events: int | None = None) -> np.ndarray:
        """Advance the sensor through the samples and return their events.

        photon_rate: (T, height, width) float32/float64 array, photons/s arriving on each
            pixel at each sample time (read without a copy when C-contiguous).
        t_s: the T sample times [s], strictly increasing, after the previous run's last.

        max_events: this call's cap on its events (default: the sensor's ``max_events``).

        Big-endian or unaligned arrays are converted to native values (one copy).

        Returns an EVENT_DTYPE array sorted by t (microseconds, from t = 0 s). The first
        sample after construction or reset only sets the steady state: no event fires.
        """
        with self._cap(max_events):
            return self._core.run(_as_array(photon_rate), _as_array(t_s, "t_s"))

    def run_probe(
        self, photon_rate: npt.ArrayLike, t_s: npt.ArrayLike, pixels: Sequence[tuple[int, int]], *,
        max_events: int | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Like run, and also return a (T, len(pixels)) TRACE_DTYPE array of the internal
        signals (current, log current, filtered level, reference) of the pixels (x, y), each
        listed once."""
        index = []
        for j, xy in enumerate(pixels):
            try:
                x, y = (integer("pixels", v) for v in xy)
            except (TypeError, ValueError):
                raise TypeError(f"pixels must be (x, y) pairs of integers; got pixels[{j}]={xy!r}") from None
            if not (0 <= x < self.width and 0 <= y < self.height):
                raise ValueError(f"pixels must lie on the {self.width}x{self.height} sensor; got (x, y)=({x}, {y})")
            index.append(y * self.width + x)
        with self._cap(max_events):
            events, trace = self._core.run_probe(_as_array(photon_rate), _as_array(t_s, "t_s"), index)
        return events, trace

    def run_pixels(
        self, pixels: npt.ArrayLike, photon_rate: npt.ArrayLike, t_s: npt.ArrayLike, *, max_events: int | None = None
    ) -> np.ndarray:
        """Advance only some pixels through their own, finer sample times.

        pixels: row-major indices ``y * width + x`` (no repeats); photon_rate: (T, len(pixels))
        photons/s; t_s: T times [s] after every listed pixel's last sample. A later ``run``
        skips, for these pixels, the samples they have already passed, so a pixel near a fast
        source can be sub-sampled while the rest of the array keeps the base rate. Each
        pixel's random numbers follow its own sample counter. Returns the events, sorted.
        max_events: this call's cap on its events (default: the sensor's ``max_events``).
        """
        with self._cap(max_events):
            return self._core.run_pixels(_as_array(pixels, "pixels"), _as_array(photon_rate), _as_array(t_s, "t_s"))

    def run_sparse(
        self, static_rate: npt.ArrayLike, t_s: npt.ArrayLike, *, base_every: int = 1, group_base_samples: int = 1,
        light_sample: npt.ArrayLike = (), light_pixel: npt.ArrayLike = (), light_rate: npt.ArrayLike = (),
        reach_pixel: npt.ArrayLike | None = None, max_events: int | None = None,
    ) -> np.ndarray:
        """Advance every pixel through one step of a sparse scene, with time steps per pixel.

        static_rate: (height, width) photons/s, the light that stays constant over the step.
        t_s: the step's fine sample times [s], after the previous call's last; the last ends
            the step, where every pixel stands afterwards.
        base_every: fine samples per base sample (``t_s[k]`` is a base time where
            ``(k + 1) % base_every == 0``; ``len(t_s)`` must be a multiple).
        group_base_samples: base samples per group, the granularity of the per-pixel choice.
        light_sample, light_pixel, light_rate: the moving sources' light as entries: at sample
            ``light_sample[i]`` pixel ``light_pixel[i]`` (row-major) receives ``light_rate[i]``
            more photons/s (the pixels of a PSF stamp; entries of one sample and pixel add).

        reach_pixel: None (every pixel stands at the step's end afterwards), or the pixels
            (row-major) that must, besides those the step's light moved: the others wait, their
            light constant, for a later step to take them on in one long step at its static
            light. List every pixel whose static light changes at this step's end. A later
            step's events may then precede this one's in time; they are in order again after a
            step with ``reach_pixel=None``.

        In each group, a pixel some entry lights takes the fine samples; one whose levels still
        relax after a source left it (``settle_time_s``), or whose noise would have its long
        steps refined more finely than the base samples, the base samples; every other pixel
        one long exact step. Needs the continuous noise model and the exact low-pass. Returns
        the step's events sorted by (t, pixel); ``last_pixel_updates`` counts the steps taken.
        """
        with self._cap(max_events):
            return self._core.run_sparse(
                _as_array(static_rate, "static_rate"), _as_array(t_s, "t_s"), base_every, group_base_samples,
                np.asarray(light_sample, np.int64), np.asarray(light_pixel, np.int64),
                np.asarray(light_rate, np.float64), None if reach_pixel is None else np.asarray(reach_pixel, np.int64))

    @property
    def last_pixel_updates(self) -> int:
        """Pixel-updates of the last ``run_sparse`` call (long steps, fine and base samples)."""
        return int(self._core.last_pixel_updates)

    def settle_time_s(self, photon_rate: float) -> float:
        """How long a pixel's levels keep relaxing after its light stops changing [s], at a
        constant photon rate: five time constants of the slower of the source follower and
        the photoreceptor pole (at that light's current)."""
        return float(self._core.settle_time_s(float(photon_rate)))

    @contextlib.contextmanager
    def _cap(self, max_events: int | None) -> Iterator[None]:
        """The sensor's max_events, or for one call the given one."""
        if max_events is None:
            yield
            return
        saved = self._core.max_events
        self._core.max_events = _max_events(max_events)
        try:
            yield
        finally:
            self._core.max_events = saved

    def reset(self) -> None:
        """Forget the past (the next sample is a first sample); mismatch is kept."""
        self._core.reset()

    def thresholds(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-pixel (theta_on, theta_off), each (height, width), mismatch included."""
        return self._core.thresholds(True), self._core.thresholds(False)

    def __repr__(self) -> str:
        return f"Sensor({self.width}x{self.height}, seed={self.seed}, samples_seen={self.samples_seen})"


def _in_range(name: str, value: int, lo: int, hi: int, extra: str = "") -> int:
    if not lo <= value <= hi:
        raise ValueError(f"{name} must be in [{lo}, {hi}]{' (' + extra + ')' if extra else ''}; got {name}={value}")
    return value


def _max_events(value: object) -> int:
    return _in_range("max_events", integer("max_events", value), 1, MAX_MAX_EVENTS)


def _as_array(value: npt.ArrayLike, name: str = "photon_rate") -> np.ndarray:
    if isinstance(value, np.ndarray):
        return value
    try:
        return np.asarray(value)
    except (ValueError, TypeError) as exc:
        raise TypeError(f"{name} must be array-like; got {type(value).__name__}: {exc}") from None
