"""The engine's block kernels against its per-pixel path: the same events, bit for bit.

``Sensor.run`` advances whole blocks of pixels with a block kernel (``step_block`` in
pixel.hpp) when every pixel of the block stands at the sample's start; ``run_probe`` with a
probe pixel takes the per-pixel path (``advance``) for the whole sensor. The two must give
the same events and labels, byte for byte, for every configuration, and both must stay the
same across thread counts and chunkings.
"""

from __future__ import annotations

import numpy as np
import pytest

from evstwin import PixelParams, Sensor
from evstwin.sensor import set_simd_level, simd_level, simd_levels

W, H = 23, 17  # 391 pixels: a full block and a partial one

CONFIGS: dict[str, dict[str, object]] = {
    "default": {"threshold_sigma": 0.03},
    "pole": {"pr_pole": True, "threshold_sigma": 0.03},
    "pole_no_cutoff": {"pr_pole": True, "cutoff_hz": None},
    # A pole fast enough for a dt > 1 on bright pixels: continuous_finish refines the interval
    # there, which the block kernels' quiet and bridge stages must leave to it (review: a
    # bridge stage without that exclusion passed every other scene here).
    "pole_refine": {"pr_pole": True, "pr_cutoff_ref_hz": 3e5},
    "background": {"shot_noise_rate_hz": 5.0, "shot_noise_on_rate_hz": 8.0, "shot_noise_off_rate_hz": 3.0,
                   "background_rate_sigma": 0.7, "shot_noise_factor": 2.0},
    "background_strong": {"shot_noise_rate_hz": 300.0, "background_rate_sigma": 1.0, "refractory_s": 0.0},
    "no_background": {"shot_noise_rate_hz": 0.0},
    "leak": {"leak_rate_hz": 5.0, "leak_rate_sigma": 0.4, "leak_random_phase": True},
    # A leak that grows with the photocurrent (3e15 Hz/A: ~5 Hz at the spot's 1.6 fA, 5e-3 Hz on
    # its background), ON and OFF, and an OFF leak that ignores the light.
    "leak_light": {"leak_rate_hz": 0.5, "leak_photocurrent_hz_per_a": 3e15, "leak_rate_sigma": 0.4},
    "leak_off": {"leak_rate_hz": 5.0, "leak_rate_sigma": 0.4, "leak_polarity": "off"},
    "leak_light_off": {"leak_rate_hz": 0.5, "leak_photocurrent_hz_per_a": 3e15, "leak_polarity": "off",
                       "shot_noise_rate_hz": 3.0},
    "leak_light_off_pole": {"pr_pole": True, "leak_rate_hz": 1.0, "leak_photocurrent_hz_per_a": 3e15,
                            "leak_polarity": "off", "leak_rate_sigma": 0.4},
    "leak_light_off_sampled": {"noise_model": "sampled", "leak_rate_hz": 0.5, "leak_photocurrent_hz_per_a": 3e15,
                               "leak_polarity": "off"},
    "hot": {"hot_pixel_fraction": 0.05, "hot_pixel_rate_hz": 80.0, "hot_pixel_rate_sigma": 0.5},
    "noiseless": {"photon_shot_noise": False, "dark_model": "none"},
    "dark_only": {"photon_shot_noise": False},
    "euler": {"lowpass": "euler", "cutoff_hz": 30.0},
    # The source follower alone with thresholds its noise crosses, over intervals up to 0.3 b dt:
    # continuous_finish refines those longer than 1/8 (refine_sf_and_compare), which the vector
    # kernel's bridge stage must leave to it.
    "sf_refine": {"cutoff_hz": 100.0, "theta_on": 0.05, "theta_off": 0.04},
    "fast": {"cutoff_hz": 2000.0, "refractory_s": 1e-4, "theta_on": 0.05, "theta_off": 0.04},
    "sampled": {"noise_model": "sampled", "threshold_sigma": 0.03},
    "sampled_pole": {"noise_model": "sampled", "pr_pole": True},
}


def scene(kind: str, n: int, seed: int, dtype: type = np.float64) -> tuple[np.ndarray, np.ndarray]:
    """Irregular sample times and (n, H, W) photon rates: a moving bright spot on a uniform
    background, darkness, or a gradient with a different rate on every pixel (no rate that
    the block kernel could share between pixels)."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(2e-4, 3e-3, n))
    if kind == "dark":
        rate = np.full((n, H, W), 1.0)
    elif kind == "bright":
        # A bright uniform field (every 37th pixel dim) whose light steps up half-way.
        rate = np.full((n, H, W), 3e9)
        rate.reshape(n, -1)[:, ::37] = 5e5
        rate[n // 2 :] *= 1.5
    elif kind == "gradient":
        rate = np.broadcast_to(np.geomspace(1e3, 1e8, H * W).reshape(H, W), (n, H, W)) * (1 + 0.3 * np.sin(t))[:, None, None]
    else:
        yy, xx = np.mgrid[0:H, 0:W]
        cx = 3 + 16 * t / t[-1]
        cy = 8 + 5 * np.sin(2 * np.pi * t / 0.1)
        rate = 2e4 + 3e7 * np.exp(-((xx - cx[:, None, None]) ** 2 + (yy - cy[:, None, None]) ** 2) / 6.0)
    return t, rate.astype(dtype)


def same(a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray]) -> bool:
    return a[0].tobytes() == b[0].tobytes() and a[1].tobytes() == b[1].tobytes()


def run_calls(params: PixelParams, kind: str, per_pixel: bool, threads: int, chunks: list[int],
              sparse: bool, every: int = 7, ahead: int = 0, first: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Events and labels of a run cut into `chunks`, through the kernel or the per-pixel path,
    with (sparse) a finer sampling of every `every`-th pixel from pixel `first` on between the
    chunks (run_pixels): to 1.5 base intervals past the chunk's end, or (ahead > 0) exactly to
    the base sample `ahead` samples into the next chunk."""
    dtype = np.float32 if kind == "spot32" else np.float64
    t, rate = scene(kind if kind in ("dark", "gradient", "bright") else "spot", 160, 3, dtype)
    sensor = Sensor(W, H, params, seed=5, num_threads=threads)
    sub = np.arange(first, W * H, every, dtype=np.uint32)
    events, labels = [], []
    edges = [0, *np.cumsum(chunks)]
    for a, b in zip(edges[:-1], edges[1:]):
        if per_pixel:
            ev, _ = sensor.run_probe(rate[a:b], t[a:b], [(0, 0)])
        else:
            ev = sensor.run(rate[a:b], t[a:b])
        events.append(ev)
        labels.append(sensor.last_labels())
        if sparse and b < len(t) - 1:
            # Past the next base sample: the next run skips it for these pixels, then advances
            # them from their own time (not the block's), so the block leaves the kernel once.
            tt = t[b - 1] + np.linspace(1e-5, 1.5 * (t[b + 1] - t[b - 1]), 9)
            if ahead:
                tt = np.concatenate([np.linspace(t[b - 1], t[b + ahead], 9, endpoint=False)[1:], [t[b + ahead]]])
            rr = np.ascontiguousarray(rate[b].reshape(-1)[sub] * (1 + 0.5 * np.sin(np.arange(9)))[:, None], dtype)
            events.append(sensor.run_pixels(sub, rr, tt))
            labels.append(sensor.last_labels())
    return np.concatenate(events), np.concatenate(labels)


@pytest.mark.parametrize("name", sorted(CONFIGS))
@pytest.mark.parametrize("kind", ["spot", "spot32", "dark", "gradient", "bright"])
def test_block_kernel_gives_the_per_pixel_events(name: str, kind: str) -> None:
    params = PixelParams(**CONFIGS[name])  # type: ignore[arg-type]
    kernel = run_calls(params, kind, per_pixel=False, threads=1, chunks=[160], sparse=False)
    per_pixel = run_calls(params, kind, per_pixel=True, threads=1, chunks=[160], sparse=False)
    assert len(kernel[0]) > 0 or kind == "dark"
    assert same(kernel, per_pixel), f"{name}/{kind}: {len(kernel[0])} events (kernel), {len(per_pixel[0])} (per pixel)"


@pytest.mark.parametrize("name", ["default", "pole", "background_strong", "hot", "leak", "leak_light_off", "sampled",
                                  "leak_light_off_sampled"])
def test_block_kernel_with_sparse_calls_threads_and_chunks(name: str) -> None:
    params = PixelParams(**CONFIGS[name])  # type: ignore[arg-type]
    ref = run_calls(params, "spot", per_pixel=True, threads=1, chunks=[50, 3, 107], sparse=True)
    for threads, chunks in [(1, [50, 3, 107]), (2, [50, 3, 107])]:
        assert same(run_calls(params, "spot", per_pixel=False, threads=threads, chunks=chunks, sparse=True), ref)
    plain = run_calls(params, "spot", per_pixel=False, threads=1, chunks=[160], sparse=False)
    for threads, chunks in [(2, [160]), (1, [1, 40, 119]), (2, [80, 80])]:
        assert same(run_calls(params, "spot", per_pixel=False, threads=threads, chunks=chunks, sparse=False), plain)


@pytest.mark.parametrize("name", ["default", "pole", "background_strong", "hot", "leak_light_off_pole"])
@pytest.mark.parametrize("every", [1, 2, 3, 7])
def test_block_kernel_with_pixels_held_past_samples(name: str, every: int) -> None:
    """Pixels that run_pixels took exactly to a base sample a few samples into the next call
    (so the vector kernel carries them, held, and takes them in again mid-call) and blocks
    where 1/7 to all of the pixels stand ahead: the per-pixel path's events and labels."""
    params = PixelParams(**CONFIGS[name])  # type: ignore[arg-type]
    chunks = [50, 6, 104]
    ref = run_calls(params, "spot", per_pixel=True, threads=1, chunks=chunks, sparse=True, every=every, ahead=3)
    assert len(ref[0]) > 0
    for threads in (1, 2):
        got = run_calls(params, "spot", per_pixel=False, threads=threads, chunks=chunks, sparse=True, every=every,
                        ahead=3)
        assert same(got, ref), f"{name}, every {every}th pixel held, {threads} threads"


@pytest.mark.parametrize("name", ["default", "pole", "hot", "sampled"])
@pytest.mark.parametrize("ahead", [0, 3])
def test_block_kernel_where_run_pixels_moved_one_block_of_two(name: str, ahead: int) -> None:
    """run() starts a block's first sample without reading its states where its last call left
    every pixel at that call's end and nothing moved them since (Sensor::block_synced_). Here
    run_pixels moves pixels of the second block only (every other one from pixel 256 on), so
    between calls the first block stays as run() left it and the second does not, over calls
    of 50, 4, 5 and 101 samples: the per-pixel path's events and labels, with 1 and 2 threads."""
    params = PixelParams(**CONFIGS[name])  # type: ignore[arg-type]
    chunks = [50, 4, 5, 101]
    ref = run_calls(params, "spot", per_pixel=True, threads=1, chunks=chunks, sparse=True, every=2, ahead=ahead,
                    first=256)
    assert len(ref[0]) > 0
    for threads in (1, 2):
        got = run_calls(params, "spot", per_pixel=False, threads=threads, chunks=chunks, sparse=True, every=2,
                        ahead=ahead, first=256)
        assert same(got, ref), f"{name}, {threads} threads"


@pytest.mark.parametrize("name", ["default", "pole", "sampled"])
def test_block_kernel_where_pixels_stand_past_a_whole_call(name: str) -> None:
    """Pixels that run_pixels took past the end of the next run() call: that call holds them
    throughout, so its block does not end with every pixel at the call's end, and the call
    after it must find them where they stand (at the base sample they were taken to) rather
    than at its start (Sensor::block_synced_ stays clear). The per-pixel path's events and
    labels, 1 and 2 threads."""
    params = PixelParams(**CONFIGS[name])  # type: ignore[arg-type]
    t, rate = scene("spot", 160, 3)
    sub = np.arange(300, W * H, 3, dtype=np.uint32)  # the second block's pixels only

    def calls(per_pixel: bool, threads: int) -> tuple[np.ndarray, np.ndarray]:
        sensor = Sensor(W, H, params, seed=5, num_threads=threads)
        events, labels = [], []

        def run(a: int, b: int) -> None:
            events.append(sensor.run_probe(rate[a:b], t[a:b], [(0, 0)])[0] if per_pixel else sensor.run(rate[a:b], t[a:b]))
            labels.append(sensor.last_labels())

        run(0, 50)
        # Fine samples from t[49] to exactly t[56]: past the next call's end (t[52]).
        tt = np.concatenate([np.linspace(t[49], t[56], 15, endpoint=False)[1:], [t[56]]])
        rr = np.ascontiguousarray(rate[50].reshape(-1)[sub] * (1 + 0.5 * np.sin(np.arange(len(tt))))[:, None])
        events.append(sensor.run_pixels(sub, rr, tt))
        labels.append(sensor.last_labels())
        for a, b in [(50, 53), (53, 60), (60, 160)]:
            run(a, b)
        return np.concatenate(events), np.concatenate(labels)

    ref = calls(True, 1)
    assert len(ref[0]) > 0
    for threads in (1, 2):
        assert same(calls(False, threads), ref), f"{name}, {threads} threads"


@pytest.mark.parametrize("name", ["default", "pole", "background_strong", "hot", "fast", "sampled", "leak_light_off",
                                  "leak_light_off_pole"])
def test_every_simd_level_gives_the_scalar_events(name: str) -> None:
    """The batched Philox and ziggurat (simd.hpp) at every level this processor runs, against
    the per-pixel path's scalar ones: the same events and labels, byte for byte."""
    params = PixelParams(**CONFIGS[name])  # type: ignore[arg-type]
    levels = simd_levels()
    assert levels[0] == "baseline" and simd_level() in levels
    scalar = run_calls(params, "spot", per_pixel=True, threads=1, chunks=[50, 3, 107], sparse=True)
    before = simd_level()
    try:
        for level in levels:
            set_simd_level(level)
            assert simd_level() == level
            got = run_calls(params, "spot", per_pixel=False, threads=2, chunks=[50, 3, 107], sparse=True)
            assert same(got, scalar), f"{name}: SIMD level {level} changed the events"
    finally:
        set_simd_level(before)


def test_set_simd_level_refuses_an_unknown_level() -> None:
    with pytest.raises(ValueError, match="got level='avx1024'"):
        set_simd_level("avx1024")
