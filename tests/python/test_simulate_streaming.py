"""simulate_to_file streams events and ground truth into the file: the same file as the
in-memory run, memory that does not grow with the duration, nothing left by a failure."""

from __future__ import annotations

import importlib
import tracemalloc
from pathlib import Path

import numpy as np
import pytest

from evstwin import EVENT_DTYPE
from evstwin.io import read_events
from evstwin.simulate import simulate, simulate_to_file

simulate_module = importlib.import_module("evstwin.simulate")  # the module, not the function

SMALL = ["sensor.width=64", "sensor.height=48"]


def noisy(duration_s: float) -> dict:
    """A 48 x 32 dark sensor, one pole, 18000 e-/s dark current and about
    200 shot-noise events per pixel and second (eq. 12-15), so the events outweigh everything
    else in memory."""
    return {
        "name": "dark", "duration_s": duration_s,
        "sensor": {"preset": "davis346", "width": 48, "height": 32},
        "pixel": {"pr_pole": False, "dark_rate_e_per_s": 18000.0, "shot_noise_rate_hz": 100.0},
        "sampling": {"rate_hz": 1000.0, "chunk_samples": 100},
        "targets": [{"kind": "linear", "x0_px": 2.0, "y0_px": 16.0, "vx_px_s": 4.0, "vy_px_s": 0.0,
                     "flux_ph_s": 1e9, "label": "mover"}],
    }


@pytest.mark.parametrize("suffix", [".h5", ".npz"])
def test_streamed_file_equals_the_in_memory_run(tmp_path: Path, suffix: str) -> None:
    memory = simulate("mcreynolds", duration_s=0.3, sets=SMALL)
    stats = simulate_to_file("mcreynolds", tmp_path / f"o{suffix}", duration_s=0.3, sets=SMALL)
    events, meta = read_events(tmp_path / f"o{suffix}")
    assert np.array_equal(events, memory.events)
    assert stats.n_events == len(memory.events) and stats.n_on == int(np.sum(memory.events["p"] == 1))
    assert stats.path == tmp_path / f"o{suffix}"
    assert set(meta["truth"]) == set(memory.meta["truth"]) == {f"led[{i}]" for i in range(5)}
    for name, fields in memory.meta["truth"].items():
        for field, values in fields.items():
            assert np.array_equal(meta["truth"][name][field], values), (name, field)
        assert np.all(np.diff(fields["t_s"]) > 0)  # one row per rendered time, in order
    assert meta["scenario"] == memory.meta["scenario"] and meta["duration_s"] == memory.meta["duration_s"]


def _traced_peak(path: Path, duration_s: float) -> tuple[int, int]:
    tracemalloc.start()
    try:
        stats = simulate_to_file(noisy(duration_s), path)
        return tracemalloc.get_traced_memory()[1], stats.n_events
    finally:
        tracemalloc.stop()


def test_memory_does_not_grow_with_the_duration(tmp_path: Path) -> None:
    peak_short, n_short = _traced_peak(tmp_path / "short.h5", 0.5)
    peak_long, n_long = _traced_peak(tmp_path / "long.h5", 2.0)
    assert n_long > 3.5 * n_short > 0
    # 4x the events and truth rows, and the peak stays within the chunk-sized noise of the short
    # run; the long run's events alone would be four times that margin.
    assert peak_long < peak_short + 0.25 * n_long * EVENT_DTYPE.itemsize, (peak_short, peak_long, n_long)
    assert len(read_events(tmp_path / "long.h5")[0]) == n_long


def test_a_failure_half_way_leaves_no_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    calls = {"n": 0}
    original = simulate_module._Runner._dense

    def failing(self, t):  # the engine fails on the 5th chunk, after some were written
        calls["n"] += 1
        if calls["n"] == 5:
            raise KeyboardInterrupt
        return original(self, t)

    monkeypatch.setattr(simulate_module._Runner, "_dense", failing)
    with pytest.raises(KeyboardInterrupt):
        simulate_to_file(noisy(1.0), tmp_path / "o.h5")
    assert calls["n"] == 5
    assert list(tmp_path.iterdir()) == []  # neither the file nor its temporary or truth spool
