"""The chunk loop of one simulation: a :class:`~evstwin.scenario.Scene` sampled chunk by chunk
into photon rates (dense frames, or the sparse sub-sampled windows of moving targets) and run
through the sensor and the readout, with the ground truth of the moving targets. What
:mod:`evstwin.simulate` drives; the sampling rules are its module docstring's."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

import numpy as np

from . import psf
from .readout import Readout
from .scenario import Scene, pre_roll_samples
from .sensor import Sensor
from .targets import LightCurve, LinearTarget, Target, psf_groups


def _tracked(scene: Scene) -> list[Target]:
    """The targets whose tracks go into the ground truth: all but a star field's stars."""
    return scene.targets[: len(scene.targets) - scene.field_stars]


def _names(moving: Sequence[Target]) -> list[str]:
    names: list[str] = []
    for j, target in enumerate(moving):
        name = target.label or f"target{j}"
        names.append(f"{name}#{j}" if name in names else name)
    return names


def _is_static(target: Target, duration_s: float, start_s: float = 0.0) -> bool:
    return not isinstance(target.brightness, LightCurve) and target.max_speed_px_s(start_s, duration_s) == 0.0


class _LinearColumns:
    """The constant-flux LinearTargets among ``targets`` (a drifting star field: thousands),
    sampled in one array operation instead of one call each, with the same arithmetic
    (``x0 + vx (t - t0)``), so the same values; ``others``: the columns of the rest."""

    def __init__(self, targets: Sequence[Target]) -> None:
        cols: list[int] = []
        lin: list[LinearTarget] = []
        flux: list[float] = []
        for j, t in enumerate(targets):
            b = t.brightness
            if isinstance(t, LinearTarget) and type(t) is LinearTarget and not isinstance(b, LightCurve):
                cols.append(j)
                lin.append(t)
                flux.append(float(b))
        self.cols = np.array(cols, np.int64)
        self.others = sorted(set(range(len(targets))) - set(cols))
        self.x0 = np.array([t.x0_px for t in lin], np.float64)
        self.y0 = np.array([t.y0_px for t in lin], np.float64)
        self.vx = np.array([t.vx_px_s for t in lin], np.float64)
        self.vy = np.array([t.vy_px_s for t in lin], np.float64)
        self.t0 = np.array([t.t0_s for t in lin], np.float64)
        self.flux = np.array(flux, np.float64)
        self.max_speed_px_s = max((t.max_speed_px_s(0.0, 0.0) for t in lin), default=0.0)

    def sample(self, t: np.ndarray, x: np.ndarray, y: np.ndarray, f: np.ndarray,
               only: np.ndarray | None = None) -> None:
        """Fill their columns of the (T, S) arrays x, y [px] and f [photons/s] at times t [s]
        (only those among the columns ``only``, where given)."""
        keep = slice(None) if only is None else np.isin(self.cols, only)
        cols = self.cols[keep]
        if not cols.size:
            return
        dt = t[:, None] - self.t0[None, keep]
        x[:, cols] = self.x0[keep] + self.vx[keep] * dt
        y[:, cols] = self.y0[keep] + self.vy[keep] * dt
        f[:, cols] = self.flux[keep]


SUB_SAMPLED_UNIT_SAMPLES = 150
"""Fine samples in a unit of the fine-sampling decision (see ``_Runner._engine_chunks``): a
fixed figure, not ``chunk_samples``, so that the chunking does not change the events. A unit
samples finely every pixel a fast source comes near during it, so a longer unit samples more
pixels finely (never fewer: only more accurate) but makes fewer, longer engine calls; each
call has a fixed cost (its parallel region, each block's copy into the kernel's arrays, the
events' collection). 4 s of ``mcreynolds`` (13 fine samples a base interval, so 3, 7, 11,
15 and 19 base intervals a unit for 50 to 250): 2.19-2.35 s at 50, 1.90-1.99 at 100,
1.88-1.90 at 150, 2.01-2.03 at 200, 2.15-2.17 at 250, with 144, 151, 160, 182 and 203 M
pixel-updates; the events 133,326, 133,339, 133,556, 133,553 and 133,505 (quiet 2-core
machine, two runs each; ``python bench/bench_simulate.py --duration 4 --threads 2
--unit-samples N``)."""

SPARSE_SYNC_S = 8.0
"""Sensor time between the moments every pixel stands at the same time in a run with time
steps per pixel (``sampling.static_step_s``) [s]. In between, a pixel whose light stays
constant waits and crosses the period in one long step; its events come out at the period's
end, sorted with the others'. A longer period spares full-frame steps (each reads and writes
every pixel's state, 0.4 GB for the IMX636 array, at a cost that does not depend on the
period's length) and holds more events back."""

_Chunk = tuple[np.ndarray, "np.ndarray | None"]
"""A chunk of events (sorted by t) and their labels (None when the runner keeps none)."""


class _Runner:
    """The chunk loop of one simulation."""

    def __init__(self, scene: Scene, num_threads: int | None,
                 truth_sink: Callable[[str, dict[str, np.ndarray]], None], labels: bool = False) -> None:
        self.scene = scene
        self.labels = labels
        self.sensor = Sensor(scene.width, scene.height, scene.params, seed=scene.seed, num_threads=num_threads,
                             hot_pixel_rates_hz=scene.hot_pixel_rates_hz, hot_pixel_chains=scene.hot_pixel_chains)
        self.psf = scene.psf
        self.dt = 1.0 / scene.rate_hz
        self.n_base = max(1, math.ceil(scene.duration_s * scene.rate_hz - 1e-9))
        self.t_end = self.n_base * self.dt
        # sampling.pre_roll_s: samples before t = 0, at pre_roll_rate_hz, whose events are
        # dropped. Pre-roll sample j is at (j - n_pre) dt_pre, the last exactly at t = 0; the
        # run's own samples then follow as without a pre-roll.
        self.n_pre, self.dt_pre = pre_roll_samples(scene.pre_roll_s, scene.rate_hz, scene.pre_roll_rate_hz)
        self.t_start = -self.n_pre * self.dt_pre if self.n_pre else 0.0
        t0 = time.perf_counter()
        static = [t for t in scene.targets if _is_static(t, self.t_end, self.t_start)]
        # Moving targets: the tracked ones first (their columns carry the ground truth), then
        # a drifting star field's stars.
        tracked = _tracked(scene)
        self.moving = [t for t in tracked if not _is_static(t, self.t_end, self.t_start)]
        n_tracked = len(self.moving)
        self.moving += [t for t in scene.targets[len(tracked):] if not _is_static(t, self.t_end, self.t_start)]
        self._linear = _LinearColumns(self.moving)
        # The moving targets by PSF: the scene's first (all of them, most often), then each
        # target's own (a defocused ghost).
        self._groups = psf_groups(self.moving, self.psf)
        # A scattered-light halo (psf.CompositePSF) changes slowly wherever it falls: the
        # sub-sampled path samples it at the base rate (_sparse), and only the cores decide
        # which pixels are sampled finely.
        self._fine_groups: list[tuple[psf.PSFShape, np.ndarray]] = []
        self._halo_groups: list[tuple[psf.PSFShape, np.ndarray]] = []
        for shape, cols in self._groups:
            sharp, smooth = psf.sharp_part(shape), psf.smooth_part(shape)
            if sharp is not None:
                self._fine_groups.append((sharp, cols))
            if smooth is not None:
                self._halo_groups.append((smooth, cols))
        self.static_map = np.full((scene.height, scene.width), scene.background_ph_s, np.float64)
        if static:
            x = np.array([float(t.position_px(0.0)[0]) for t in static])
            y = np.array([float(t.position_px(0.0)[1]) for t in static])
            f = np.array([float(t.flux_ph_s(0.0)) for t in static])
            for shape, cols in psf_groups(static, self.psf):
                psf.render_points(scene.width, scene.height, x[cols], y[cols], f[cols], shape, out=self.static_map)
        self.scene_s = time.perf_counter() - t0
        self.engine_s = 0.0
        self.pixel_updates = 0
        self.sub_sampled_chunks = 0
        # Ground truth goes out as it is made: rows of each moving target's track, at every time
        # the scene was rendered at (the fine rate where the run sub-sampled), in time order.
        self._truth_sink = truth_sink
        self._truth_t_last = -math.inf
        self.track_names = _names(self.moving[:n_tracked])
        self.half = self.psf.half_width_px
        # A pixel a source has left keeps the fine sampling until the source follower has
        # settled (5 time constants): the comparator interpolates linearly between samples
        # (eq. 16), and a fast decay sampled coarsely would cross its thresholds at other
        # times than the dense way's. The photoreceptor pole, when on, is slower still in the
        # dark, but by then its decay is smooth enough for the base rate (its chord error over
        # one base interval is below 1e-3 of the step); waiting for it would keep every
        # pixel a source ever passed sub-sampled for a quarter second.
        cutoff = scene.params.cutoff_hz
        self.settle_s = 5.0 / (2.0 * math.pi * cutoff) if cutoff is not None else 0.0
        # The sub-sampled dense path's per-pixel tables (16 bytes a pixel: 15 MB for the
        # IMX636), made when it first runs: a stepped run never needs them.
        self._hot_until: np.ndarray | None = None
        self._column_of: np.ndarray | None = None
        # The sensor's readout (rate limit, FIFO, timestamp tick) on each chunk's events as it
        # comes out of the engine: its state carries over, so the chunking changes nothing.
        self.readout = None if scene.readout is None else Readout.from_params(scene.readout)
        self.readout_s = 0.0
        # The big tables an engine call reads (the frames of a chunk, the hot pixels' fine
        # rates), kept from call to call: fresh ones are memory the kernel must zero first
        # (imx636-pointsource: ~0.35 GB a sub-sampled unit).
        self._buffers: dict[str, np.ndarray] = {}
        # Base intervals per unit of the fine-sampling decision: about SUB_SAMPLED_UNIT_SAMPLES
        # fine samples at the run's fastest, so a pixel is not sampled finely long before or
        # after a source is near it (it is for the whole unit if a source touches it in it).
        self.unit = max(1, SUB_SAMPLED_UNIT_SAMPLES // self._n_sub(0.0, self.t_end))
        # Long steps for the pixels whose light is constant (sampling.static_step_s): base
        # intervals per step, 1 where the run keeps every pixel at the base rate.
        self.static_every = self._static_every()

    # -- the loop --------------------------------------------------------------------------------

    def chunks(self, bar: Any = None) -> Iterator[_Chunk]:
        """The events, chunk by chunk in time order (each chunk sorted by t), each with its
        labels (in the same order) when the runner keeps them, with the readout's times and
        losses when the scene has a readout (a dropped event's label goes with it)."""
        for events, labels in self._engine_chunks(bar):
            if self.n_pre and events.size and events["t"][0] < 0:
                # The pre-roll's events are dropped (a chunk is sorted by t). An event in the
                # last nanosecond before t = 0 counts as 0 (Sensor::floor_us) and stays.
                keep = events["t"] >= 0
                events = events[keep]
                labels = None if labels is None else labels[keep]
            if self.readout is not None:
                r0 = time.perf_counter()
                if labels is None:
                    events = self.readout.process(events)
                else:
                    events, kept = self.readout.process_with_index(events)
                    labels = labels[kept]
                self.readout_s += time.perf_counter() - r0
            yield events, labels

    def _engine_chunks(self, bar: Any = None) -> Iterator[_Chunk]:
        """The engine's events, chunk by chunk in time order (each chunk sorted by t), each
        with its labels when the runner keeps them.

        Which pixels are sampled finely, and how finely, is decided per *unit*: a fixed run of
        base intervals aligned from t = 0 (``self.unit``, set by the scene's fastest source, not
        by ``chunk_samples``). Every pixel's time grid, and so its random numbers and events, is
        then the same whatever the chunking; ``chunk_samples`` only groups the units where
        nothing moves fast enough to need the fine rate, and the fine samples of a dense one.
        A pre-roll (``sampling.pre_roll_s``) comes first, whole frames at its own rate up to
        and including t = 0, without sub-sampling: its events are dropped, and it is there to
        leave each pixel's state where the scene's history puts it."""
        chunk = self.scene.chunk_samples
        yield self._dense(np.array([self.t_start]))
        for j in range(1, self.n_pre + 1, chunk):
            stop = min(j + chunk, self.n_pre + 1)
            yield self._dense((np.arange(j, stop) - self.n_pre) * self.dt_pre)
            if bar is not None:
                # The bar counts sensor time from t = 0; a long pre-roll (a minute for the
                # IMX636 frame's 12 s) says where it is beside it, not as a bar stuck at 0.
                done = (stop - 1) * self.dt_pre
                bar.set_postfix_str(f"pre-roll {done:.1f}/{self.n_pre * self.dt_pre:.1f} s"
                                    if stop <= self.n_pre else "")
        if self.static_every > 1:
            self._buffers.pop("frames", None)  # the dense samples' frames: not needed again
            yield from self._stepped_chunks(bar)
            return
        a = 0
        while a < self.n_base:
            u0 = a - a % self.unit
            b = min(u0 + self.unit, self.n_base)
            n_sub = self._n_sub(u0 * self.dt, b * self.dt)
            if n_sub == 1:
                # Base-rate units: group them into chunks of up to chunk_samples intervals.
                stop = min(a + chunk, self.n_base)
                while b < stop:
                    nb = min(b + self.unit, self.n_base)
                    if self._n_sub(b * self.dt, nb * self.dt) > 1:
                        break
                    b = nb
                b = min(b, stop)
                yield self._dense(np.arange(a + 1, b + 1) * self.dt)
            else:
                # A sub-sampled unit, whole: a base-rate chunk never ends inside one.
                self.sub_sampled_chunks += 1
                t_base, t_fine = self._fine_times(a, b, n_sub)
                if self.scene.sparse:
                    yield self._sparse(t_fine, t_base)
                else:
                    for j in range(0, t_fine.size, chunk):
                        yield self._dense(t_fine[j : j + chunk])
            if bar is not None:
                # Set, not added up: a sum of rounded steps drifted past the total (0.77 s at
                # 200 Hz ended at 0.7700000000000001 of 0.77: "clamping frac", a negative ETA).
                bar.n = min(round(b * self.dt, 6), bar.total)
                bar.update(0)  # displays at tqdm's own pace
            a = b

    def _static_every(self) -> int:
        """Base intervals per step of a pixel whose light is constant: sampling.static_step_s
        in whole base intervals, where the statistics do not depend on the step (a sparse run,
        the continuous noise model, the exact low-pass: the engine advances a pixel's noise
        exactly over any interval and refines one where a crossing is plausible; the
        documentation's noise model page measures it), and no halo changes the light of every
        pixel (a ``CompositePSF``'s smooth part is sampled at the base rate everywhere). Else 1.
        Which pixels then take long steps the engine decides (``Sensor.run_sparse``): a pixel
        whose noise would have its long steps refined more finely than the base samples (the
        DAVIS346 preset's dark pixel, a bright sky behind a fast pole) keeps the base rate."""
        sc, p = self.scene, self.scene.params
        if not (sc.sparse and sc.static_step_s > 0.0 and p.noise_model == "continuous" and p.lowpass == "exact"
                and not self._halo_groups):
            return 1
        return max(1, math.floor(sc.static_step_s / self.dt + 1e-9))

    def _stepped_chunks(self, bar: Any = None) -> Iterator[_Chunk]:
        """``_engine_chunks`` with time steps per pixel: units of ``static_every`` base intervals
        aligned from t = 0, each one ``Sensor.run_sparse`` step. Within a unit the engine
        chooses per group of ``self.unit`` base intervals: the pixels inside a moving source's
        window take the fine samples (``_n_sub`` per base interval), those a source has left
        and that still settle the base samples, every other pixel one long step, its light
        the static map's. A pixel whose static light stays the same at a unit's end waits
        there (the drifting stars' pixels are the ones that move); every pixel reaches the
        end of each sync period (``SPARSE_SYNC_S``), where the period's events come out in
        time order. Which pixel takes which grid depends on the units alone, not on the
        chunking."""
        sc = self.scene
        npix = sc.width * sc.height
        unit_s = self.static_every * self.dt
        # Sources that move less than max_shift_px in a unit (a drifting star field: 0.07-0.3
        # px/s, thousands of stars) need no sample between the unit's ends: they are rendered
        # into the unit's one frame. Only untracked ones of constant flux (the ground truth is
        # written at the times a tracked target is sampled; a light curve may change fast).
        n_tracked = len(self.track_names)
        slow = np.zeros(len(self.moving), bool)
        for j in self._linear.cols:
            if j >= n_tracked and self.moving[j].max_speed_px_s(self.t_start, self.t_end) * unit_s <= sc.max_shift_px:
                slow[j] = True
        fast_groups = [(shape, cols[~slow[cols]]) for shape, cols in self._fine_groups if (~slow[cols]).any()]
        slow_groups = [(shape, cols[slow[cols]]) for shape, cols in self._fine_groups if slow[cols].any()]
        # Each call samples only the sources it draws (thousands of slow stars at a unit's
        # fine times would be most of the scene layer's work).
        fast_cols = np.flatnonzero(~slow)
        slow_cols = np.flatnonzero(slow)
        npix_bits = (npix - 1).bit_length()
        empty_i, empty_f = np.zeros(0, np.int64), np.zeros(0)
        sync_every = max(1, math.ceil(SPARSE_SYNC_S / unit_s - 1e-9))

        # Where each slow source is drawn: moved only once it has drifted max_shift_px from
        # there (a star at 0.07 px/s every 3.6 s at 0.25 px), so a unit's end changes the
        # light of the few stars that moved, not of every star (each changed pixel takes a
        # long step there). The same bound on the position's error as drawing each unit at
        # its end, which the slow ones' speed keeps under max_shift_px.
        drawn_x = np.full(len(self.moving), np.nan)
        drawn_y = np.full(len(self.moving), np.nan)

        def unit_light(b: int, slot: int) -> np.ndarray:
            """The static light of the unit ending at base sample b: the static map, with the
            slow sources where they were last drawn (in buffer slot % 2: this unit's and the
            next's)."""
            if not slow_groups:
                return self.static_map
            out = self._buffer(f"unit_frame{slot % 2}", (sc.height, sc.width))
            x, y, f = self._sources(np.array([b * self.dt]), truth=not fast_groups, cols=slow_cols)
            shift = np.hypot(x[0, slow_cols] - drawn_x[slow_cols], y[0, slow_cols] - drawn_y[slow_cols])
            moved = slow_cols[~(shift <= sc.max_shift_px)]  # NaN: not drawn yet
            drawn_x[moved], drawn_y[moved] = x[0, moved], y[0, moved]
            out[:] = self.static_map
            for shape, cols in slow_groups:
                psf.render_points(sc.width, sc.height, drawn_x[cols], drawn_y[cols], f[0, cols], shape, out=out)
            return out

        pending: list[_Chunk] = []
        a, unit = 0, 0
        static_rate = unit_light(min(self.static_every, self.n_base), 0)
        while a < self.n_base:
            b = min(a - a % self.static_every + self.static_every, self.n_base)
            s0 = time.perf_counter()
            # The unit to the engine as a sparse scene: the static light and the fast sources'
            # windows at the fine times; the engine chooses each pixel's steps.
            # The base times at least: the engine samples at them the pixels that need it.
            n_sub = self._n_sub(a * self.dt, b * self.dt) if fast_groups else 1
            _, t = self._fine_times(a, b, n_sub)
            light_sample, light_pixel, light_rate = empty_i, empty_i, empty_f
            if fast_groups:
                self.sub_sampled_chunks += n_sub > 1
                x, y, f = self._sources(t, cols=fast_cols)
                parts = list(self._contribution_parts(x, y, f, fast_groups, stride=1 << npix_bits))
                if parts:
                    flat = np.concatenate([c[0] for c in parts])
                    light_sample, light_pixel = flat >> npix_bits, flat & ((1 << npix_bits) - 1)
                    light_rate = np.concatenate([c[1] for c in parts])
            unit += 1
            sync = b == self.n_base or unit % sync_every == 0
            next_rate = unit_light(min(b + self.static_every, self.n_base), unit) if b < self.n_base else static_rate
            reach: np.ndarray | None = None
            if not sync:
                # Only the pixels whose static light changes at the unit's end must be there.
                reach = np.flatnonzero(next_rate != static_rate) if next_rate is not static_rate else empty_i
            s1 = time.perf_counter()
            events = self.sensor.run_sparse(static_rate, t, base_every=n_sub, group_base_samples=self.unit,
                                            light_sample=light_sample, light_pixel=light_pixel, light_rate=light_rate,
                                            reach_pixel=reach)
            pending.append((events, self.sensor.last_labels() if self.labels else None))
            s2 = time.perf_counter()
            self.pixel_updates += self.sensor.last_pixel_updates
            self.scene_s += s1 - s0
            self.engine_s += s2 - s1
            static_rate = next_rate
            if sync:
                # Every pixel stands at b: the period's events, in order.
                events = np.concatenate([c[0] for c in pending])
                order = np.lexsort((events["y"].astype(np.int64) * sc.width + events["x"], events["t"]))
                codes = np.concatenate([c[1] for c in pending])[order] if self.labels else None  # type: ignore[misc]
                pending = []
                yield events[order], codes
            if bar is not None:
                bar.n = min(round(b * self.dt, 6), bar.total)
                bar.update(0)
            a = b

    def _fine_times(self, a: int, b: int, n_sub: int) -> tuple[np.ndarray, np.ndarray]:
        """The base times of intervals a+1..b and their n_sub fine times each [s]: the base
        times themselves where the fine index reaches n_sub, exactly."""
        k = np.arange(a + 1, b + 1)
        i = np.arange(1, n_sub + 1)
        t_fine = np.where(i[None, :] == n_sub, (k[:, None]) * self.dt,
                          (k[:, None] - 1 + i[None, :] / n_sub) * self.dt).reshape(-1)
        return k * self.dt, t_fine

    def _n_sub(self, t0: float, t1: float) -> int:
        if not self.moving:
            return 1
        speed = max((self.moving[j].max_speed_px_s(t0, t1) for j in self._linear.others), default=0.0)
        speed = max(speed, self._linear.max_speed_px_s)
        return max(1, math.ceil(speed * self.dt / self.scene.max_shift_px - 1e-9))

    def _sources(self, t: np.ndarray, truth: bool = True,
                 cols: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The sources' (T, S) positions and fluxes at the times t, written to the ground truth
        (new times at or after 0) unless ``truth`` is False. With ``cols``, only those columns
        (and the tracked ones, where the truth is written) are filled; the others are
        undefined."""
        n = len(self.moving)
        x = np.empty((t.size, n))
        y = np.empty((t.size, n))
        f = np.empty((t.size, n))
        if cols is not None and truth:
            cols = np.union1d(cols, np.arange(len(self.track_names)))
        self._linear.sample(t, x, y, f, only=cols)
        wanted = None if cols is None else set(cols.tolist())
        for j in self._linear.others:
            if wanted is not None and j not in wanted:
                continue
            target = self.moving[j]
            x[:, j], y[:, j] = target.position_px(t)
            f[:, j] = target.flux_ph_s(t)
        keep = (t > self._truth_t_last) & (t >= 0.0)  # chunks come in time order; never repeat a time
        if truth and keep.any():
            self._truth_t_last = float(t[keep][-1])
            for j, name in enumerate(self.track_names):
                self._truth_sink(name, {"t_s": t[keep], "x_px": x[keep, j], "y_px": y[keep, j],
                                        "flux_ph_s": f[keep, j]})
        return x, y, f

    def frames(self, t: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """The photon rates on every pixel at the times t_s: (len(t), height, width) photons/s,
        rendered into ``out`` (C-contiguous float64 of that shape) if given."""
        sc = self.scene
        if not self.moving:
            return np.broadcast_to(self.static_map, (t.size, sc.height, sc.width))
        x, y, f = self._sources(t)
        shape, cols = self._fine_groups[0]  # the scene's PSF (its core, with a halo) comes first
        frames = psf.render_frames(sc.width, sc.height, x[:, cols], y[:, cols], f[:, cols], shape,
                                   background_ph_s=self.static_map, out=out)
        if len(self._fine_groups) > 1:
            idx, val = self._contributions(x, y, f, self._fine_groups[1:])
            np.add.at(frames.reshape(-1), idx, val)
        for i in range(t.size):
            self._add_halos(frames[i], x[i], y[i], f[i])
        return frames

    def _add_halos(self, frame: np.ndarray, x: np.ndarray, y: np.ndarray, f: np.ndarray) -> None:
        """The moving sources' halos (the smooth parts) added to one (height, width) frame."""
        for shape, cols in self._halo_groups:
            for j in cols:
                shape.add_dense(frame, float(x[j]), float(y[j]), float(f[j]))  # type: ignore[attr-defined]

    def _dense(self, t: np.ndarray) -> _Chunk:
        s0 = time.perf_counter()
        sc = self.scene
        frames = self.frames(t, out=self._buffer("frames", (t.size, sc.height, sc.width)) if self.moving else None)
        s1 = time.perf_counter()
        events = self.sensor.run(frames, t)
        codes = self.sensor.last_labels() if self.labels else None
        s2 = time.perf_counter()
        self.scene_s += s1 - s0
        self.engine_s += s2 - s1
        self.pixel_updates += t.size * self.scene.width * self.scene.height
        return events, codes

    def _contributions(self, x: np.ndarray, y: np.ndarray, f: np.ndarray,
                       groups: Sequence[tuple[psf.PSFShape, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
        """Flat (sample * pixels + pixel) indices and photon rates of the (T, S) sources' windows,
        each group of columns through its PSF."""
        parts = list(self._contribution_parts(x, y, f, groups))
        if not parts:
            return np.zeros(0, np.int64), np.zeros(0)
        return np.concatenate([c[0] for c in parts]), np.concatenate([c[1] for c in parts])

    def _contribution_parts(self, x: np.ndarray, y: np.ndarray, f: np.ndarray,
                            groups: Sequence[tuple[psf.PSFShape, np.ndarray]],
                            stride: int | None = None) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """``_contributions`` as the renderer's chunks, in the order of their concatenation,
        rendered as they are taken: a block of whole samples at a time, of at most
        ``psf.render``'s chunk of window pixels (the order of the pixels, and so of every sum
        over them, is the one a single call gives). ``stride``: the flat index is
        sample * stride + pixel (default width * height; any stride >= it)."""
        sc = self.scene
        npix = sc.width * sc.height if stride is None else stride
        for shape, cols in groups:
            n_t, n_s = x.shape[0], cols.size
            k = 2 * int(shape.half_width_px) + 1
            block = max(1, psf.render._CHUNK_ELEMENTS // max(1, n_s * k * k))
            for t0 in range(0, n_t, block):
                t1 = min(n_t, t0 + block)
                sample = np.repeat(np.arange(t0, t1, dtype=np.int64), n_s)
                yield from psf.contributions(sc.width, sc.height, x[t0:t1, cols].reshape(-1),
                                             y[t0:t1, cols].reshape(-1), f[t0:t1, cols].reshape(-1), shape,
                                             offset=sample * npix)

    @property
    def hot_until(self) -> np.ndarray:
        """Each pixel's end of fine sampling [s] (-inf: none), flat."""
        if self._hot_until is None:
            self._hot_until = np.full(self.scene.width * self.scene.height, -np.inf)
        return self._hot_until

    @property
    def _column(self) -> np.ndarray:
        """Pixel -> its column in the hot list (valid for the pixels of the current list)."""
        if self._column_of is None:
            self._column_of = np.zeros(self.scene.width * self.scene.height, np.int64)
        return self._column_of

    def _buffer(self, name: str, shape: tuple[int, ...]) -> np.ndarray:
        """A C-contiguous float64 array of ``shape``, its memory reused from the last call with
        this name (contents undefined). Only for tables an engine call reads and drops."""
        size = math.prod(shape)
        buf = self._buffers.get(name)
        if buf is None or buf.size < size:
            buf = self._buffers[name] = np.empty(size, np.float64)
        return buf[:size].reshape(shape)

    def _lit(self, x: np.ndarray, y: np.ndarray, f: np.ndarray) -> np.ndarray:
        """Flat mask of the pixels inside the window of a fine-sampled source with flux > 0
        at any of the (T, S) positions: a PSF's window is the (2 h + 1)^2 pixels around the
        pixel the source is on (``psf.render``), those on the sensor. A difference table of
        the rectangles' corners, summed along both axes: linear in the rectangles and pixels."""
        sc = self.scene
        rects = []
        for shape, cols in self._fine_groups:
            h = int(shape.half_width_px)
            xs, ys, fs = x[:, cols].reshape(-1), y[:, cols].reshape(-1), f[:, cols].reshape(-1)
            with np.errstate(invalid="ignore"):
                cx, cy = np.floor(xs + 0.5), np.floor(ys + 0.5)
                on = (fs > 0.0) & (cx + h >= 0) & (cx - h <= sc.width - 1) & (cy + h >= 0) & (cy - h <= sc.height - 1)
            rects.append((np.clip(cx[on] - h, 0, sc.width).astype(np.int64),
                          np.clip(cx[on] + h + 1, 0, sc.width).astype(np.int64),
                          np.clip(cy[on] - h, 0, sc.height).astype(np.int64),
                          np.clip(cy[on] + h + 1, 0, sc.height).astype(np.int64)))
        covered = np.zeros((sc.height, sc.width), bool)
        if not any(r[0].size for r in rects):
            return covered.reshape(-1)
        # The table over the rectangles' bounding box only: a satellite's windows over a unit
        # cover a few hundred pixels of a million, and two cumulative sums over the whole
        # IMX636 array cost ~5 ms a unit.
        bx0 = min(int(r[0].min()) for r in rects if r[0].size)
        bx1 = max(int(r[1].max()) for r in rects if r[0].size)
        by0 = min(int(r[2].min()) for r in rects if r[0].size)
        by1 = max(int(r[3].max()) for r in rects if r[0].size)
        diff = np.zeros((by1 - by0 + 1, bx1 - bx0 + 1), np.int64)
        for x0, x1, y0, y1 in rects:
            np.add.at(diff, (y0 - by0, x0 - bx0), 1)
            np.add.at(diff, (y0 - by0, x1 - bx0), -1)
            np.add.at(diff, (y1 - by0, x0 - bx0), -1)
            np.add.at(diff, (y1 - by0, x1 - bx0), 1)
        covered[by0:by1, bx0:bx1] = diff.cumsum(axis=0).cumsum(axis=1)[: by1 - by0, : bx1 - bx0] > 0
        return covered.reshape(-1)

    def _with_halos(self, frames: np.ndarray, t_base: np.ndarray, t_fine: np.ndarray, hot: np.ndarray,
                    rates: np.ndarray) -> np.ndarray:
        """The base frames with the moving sources' halos added, and the halos added to the
        hot pixels' fine rates (in place), sampled at the base times and interpolated linearly
        in time between them: a halo at least 2 px wide, moved by 0.25 px or so between fine
        samples, changes too little within a base interval for its curvature in time to
        matter, and rendering its 513 px window at every fine sample would cost 10-100 times
        the cores'."""
        sc = self.scene
        t_halo = np.concatenate([[t_base[0] - self.dt], t_base])
        x, y, f = self._sources(t_halo, truth=False)
        out = self._buffer("frames", frames.shape)
        at_hot = np.empty((t_halo.size, hot.size))
        halo = np.empty((sc.height, sc.width))
        for i in range(t_halo.size):  # one frame at a time: a unit may hold ~100 base samples
            halo[:] = 0.0
            self._add_halos(halo, x[i], y[i], f[i])
            at_hot[i] = halo.reshape(-1)[hot]
            if i > 0:
                np.add(frames[i - 1], halo, out=out[i - 1])
        if hot.size:
            # Fine sample j lies in base interval k = j // n_sub, a share (j % n_sub + 1) / n_sub in.
            # One base interval at a time: the same arithmetic on each element, with temporaries
            # of n_sub rows, not of the whole (fine samples, hot pixels) table.
            n_sub = t_fine.size // t_base.size
            w = ((np.arange(n_sub) + 1) / n_sub)[:, None]
            for k in range(t_base.size):
                rates[k * n_sub : (k + 1) * n_sub] += (1.0 - w) * at_hot[k] + w * at_hot[k + 1]
        return out

    def _window_rates(self, hot: np.ndarray, x: np.ndarray, y: np.ndarray, f: np.ndarray) -> np.ndarray:
        """The (T, hot.size) photon rates of the pixels ``hot`` (flat indices, increasing) at
        the T times of the (T, S) sources: the static light plus the moving sources' sharp
        parts (``_fine_groups``). Every window pixel of those sources must be in ``hot``."""
        sc = self.scene
        npix = sc.width * sc.height
        column = self._column
        column[hot] = np.arange(hot.size)
        rates = self._buffer("rates", (x.shape[0], hot.size))
        rates[:] = self.static_map.reshape(-1)[hot][None, :]
        flat_rates = rates.reshape(-1)
        # The windows' flat indices with a power-of-two stride between samples, so that a shift
        # and a mask split them into (sample, pixel): NumPy's integer division by a scalar cost
        # ~10 times a shift (and its divmod by hand a division, a multiply and a subtraction).
        shift = (npix - 1).bit_length()
        for idx, val in self._contribution_parts(x, y, f, self._fine_groups,
                                                 stride=1 << shift):
            # Scatter-add only where the windows are (a bincount over every hot pixel and
            # sample would zero and add the whole table); the chunks in order, each
            # sequentially. The chunk's own index array becomes the target, in place.
            if val.size:
                pixel = idx & ((1 << shift) - 1)
                target = idx
                target >>= shift
                target *= hot.size
                target += column[pixel]
                np.add.at(flat_rates, target, val)
        return rates

    def _sparse(self, t_fine: np.ndarray, t_base: np.ndarray) -> _Chunk:
        s0 = time.perf_counter()
        sc = self.scene
        npix = sc.width * sc.height
        x, y, f = self._sources(t_fine)
        n_t = x.shape[0]
        # The windows' contributions chunk by chunk, never concatenated: a unit of a bright
        # star's 257 px window holds ~3e7 of them, and each whole-unit temporary was ~0.25 GB
        # of fresh memory for the kernel to zero (~15 % of imx636-pointsource's CPU).
        # Hot: lit by a moving window in this chunk, or still settling from an earlier one.
        # The lit pixels are the union of the windows' rectangles, known from the positions
        # alone: the hot set (and each hot pixel's column) is fixed before any window is
        # rendered, and each rendered chunk is added to the rates and dropped, instead of
        # every chunk of the unit being kept until the set was known (~3 x the rates table:
        # 0.3 GB of a 200 x 200 ROI inside a bright star's 257 px window).
        lit = self._lit(x, y, f)
        mask = (self.hot_until > t_fine[0]) | lit
        self.hot_until[lit] = t_fine[-1] + self.settle_s
        hot = np.flatnonzero(mask)
        rates = self._window_rates(hot, x, y, f)
        # Base frames for everyone else: their light is static in this chunk (hot pixels
        # have passed these times and are skipped by the engine), but for the halos.
        frames = np.broadcast_to(self.static_map, (t_base.size, sc.height, sc.width))
        if self._halo_groups:
            frames = self._with_halos(frames, t_base, t_fine, hot, rates)
        s1 = time.perf_counter()
        fine_events = self.sensor.run_pixels(hot, rates, t_fine)
        fine_codes = self.sensor.last_labels() if self.labels else None
        base_events = self.sensor.run(frames, t_base)
        base_codes = self.sensor.last_labels() if self.labels else None
        s2 = time.perf_counter()
        self.scene_s += s1 - s0
        self.engine_s += s2 - s1
        self.pixel_updates += hot.size * n_t + (npix - hot.size) * t_base.size
        events = np.concatenate([fine_events, base_events])
        # lexsort is stable: the labels, concatenated alike, take the same permutation.
        order = np.lexsort((events["y"].astype(np.int64) * sc.width + events["x"], events["t"]))
        if fine_codes is None or base_codes is None:
            return events[order], None
        return events[order], np.concatenate([fine_codes, base_codes])[order]
