"""The engine against an independent NumPy implementation of the same model
(bench/numpy_reference.py): identical events without noise, equal statistics with it."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np

from evstwin import PixelParams, Sensor

_spec = importlib.util.spec_from_file_location(
    "numpy_reference", Path(__file__).resolve().parents[2] / "bench" / "numpy_reference.py"
)
assert _spec and _spec.loader
numpy_reference = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(numpy_reference)


def spots(n: int, w: int, h: int, dt: float = 1e-3) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(n) * dt
    yy, xx = np.mgrid[0:h, 0:w]
    rate = np.full((n, h, w), 2e7)
    for cx, cy, r, period in [(10, 8, 5, 0.05), (25, 10, 4, 0.08)]:
        phase = 2 * math.pi * t / period
        xc, yc = cx + r * np.cos(phase), cy + r * np.sin(phase)
        rate += 3e9 * np.exp(-((xx[None] - xc[:, None, None]) ** 2 + (yy[None] - yc[:, None, None]) ** 2) / 1.5)
    return rate, t


def test_noise_free_events_identical_to_numpy_reference() -> None:
    params = PixelParams(
        photon_shot_noise=False, dark_model="none", shot_noise_rate_hz=0.0, leak_rate_hz=3.0,
        refractory_s=2e-4, cutoff_hz=300.0, leak_random_phase=False,
    )
    rate, t = spots(150, 36, 20)
    ours = Sensor(36, 20, params).run(rate, t)
    theirs = numpy_reference.reference_events(36, 20, params, rate, t)
    assert len(ours) > 1000
    assert ours.tobytes() == theirs.tobytes()


def test_noisy_statistics_match_numpy_reference() -> None:
    # The reference implements the paper's sampled noise and its lockstep leak.
    params = PixelParams(leak_rate_hz=1.0, shot_noise_rate_hz=2.0, threshold_sigma=0.03, dark_rate_e_per_s=2000.0,
                         noise_model="sampled", leak_random_phase=False)
    rate, t = spots(400, 36, 20)
    ours = Sensor(36, 20, params, seed=1).run(rate, t)
    theirs = numpy_reference.reference_events(36, 20, params, rate, t, seed=1)
    for pol in (0, 1):
        a, b = np.sum(ours["p"] == pol), np.sum(theirs["p"] == pol)
        assert abs(a - b) < 5 * math.sqrt(a + b), (pol, a, b)
