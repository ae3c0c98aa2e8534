"""Per-event labels (why each event fired): from the engine through simulate into every format
with a label column and back, and the refusal of the formats without one."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import evstwin
from evstwin import EVENT_DTYPE, EVENT_LABELS, PixelParams, Sensor
from evstwin.cli import main
from evstwin.io import _isolation, iter_events, open_event_writer, read_events, read_time_window, write_events
from evstwin.scenario import build
from evstwin.simulate import SimulationResult, simulate, simulate_to_file

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_simulate import NOISE_FREE, spinning  # noqa: E402

SIGNAL, SHOT_NOISE, LEAK, BACKGROUND, HOT_PIXEL = range(5)
LABELLED = [".h5", ".hdf5", ".npz", ".txt", ".csv"]
UNLABELLED = [(".aedat4", "AEDAT 4.0"), (".raw", "Prophesee RAW"), (".dat", "Prophesee DAT"), (".es", "Event Stream")]
HOT = {"hot_pixel_fraction": 0.01, "hot_pixel_rate_hz": 200.0, "hot_pixel_rate_sigma": 0.0}
# The paper's sec. 2.4 leak and eq. 12 background (the DAVIS346 preset's measured background has
# no eq. 12 part and a slow leak), so that with noise on every label shows up in half a second.
PAPER_BACKGROUND = {"leak_rate_hz": 0.1, "leak_rate_sigma": 0.0, "shot_noise_rate_hz": 0.05}


def events_and_labels(n: int = 5000, seed: int = 4) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    ev = np.zeros(n, EVENT_DTYPE)
    ev["t"] = np.sort(rng.integers(0, 3_000_000, n))
    ev["t"][1] = ev["t"][0]
    ev["x"] = rng.integers(0, 346, n)
    ev["y"] = rng.integers(0, 260, n)
    ev["p"] = rng.integers(0, 2, n)
    labels = rng.integers(0, 5, n).astype(np.uint8)
    labels[:3] = (0, 4, 255)  # the whole uint8 range is kept, not only today's codes
    return ev, labels


def test_the_codes_are_the_engines() -> None:
    assert EVENT_LABELS == {0: "signal", 1: "shot_noise", 2: "leak", 3: "background", 4: "hot_pixel"}
    assert evstwin.EVENT_LABELS is EVENT_LABELS and "EVENT_LABELS" in evstwin.__all__


@pytest.mark.parametrize("isolated", [True, False], ids=["child", "in-process"])
@pytest.mark.parametrize("suffix", LABELLED)
def test_labels_round_trip_byte_for_byte(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, suffix: str, isolated: bool
) -> None:
    monkeypatch.setattr(_isolation, "ENABLED", isolated)
    ev, labels = events_and_labels()
    path = write_events(tmp_path / f"a{suffix}", ev, {"width": 346, "height": 260}, labels=labels)
    back, meta, back_labels = read_events(path, labels=True)
    assert back.tobytes() == ev.tobytes()
    assert back_labels.dtype == np.uint8 and back_labels.tobytes() == labels.tobytes()
    assert meta["has_labels"] is True
    # Read without asking: the events as ever, and the label column does not leak into them.
    plain, plain_meta = read_events(path)
    assert plain.dtype == EVENT_DTYPE and plain.tobytes() == ev.tobytes() and plain_meta["has_labels"]
    # Chunk by chunk, the labels stay with their events.
    pairs = list(iter_events(path, chunk=333).labeled())
    assert max(len(e) for e, _ in pairs) == 333
    assert all(len(e) == len(c) for e, c in pairs)
    assert np.concatenate([c for _, c in pairs]).tobytes() == labels.tobytes()
    assert np.concatenate([e for e, _ in pairs]).tobytes() == ev.tobytes()
    window = read_time_window(path, 1_000_000, 2_000_000)
    keep = (ev["t"] >= 1_000_000) & (ev["t"] < 2_000_000)
    assert window.tobytes() == ev[keep].tobytes()


@pytest.mark.parametrize("suffix", [".h5", ".npz", ".txt"])
def test_labels_written_chunk_by_chunk_equal_one_write(tmp_path: Path, suffix: str) -> None:
    ev, labels = events_and_labels()
    one = write_events(tmp_path / f"one{suffix}", ev, {"width": 346, "height": 260}, labels=labels)
    with open_event_writer(tmp_path / f"chunks{suffix}", {"width": 346, "height": 260}, labels=True) as w:
        assert w.labels
        for start in range(0, len(ev), 777):
            w.write(ev[start : start + 777], labels=labels[start : start + 777])
        w.write(ev[:0], labels=labels[:0])
    chunked = tmp_path / f"chunks{suffix}"
    if suffix != ".h5":  # HDF5 files differ in allocation, not content
        assert chunked.read_bytes() == one.read_bytes()
    assert read_events(chunked, labels=True)[2].tobytes() == labels.tobytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([one.name, chunked.name])  # no side files


def test_a_writer_takes_labels_exactly_when_opened_for_them(tmp_path: Path) -> None:
    ev, labels = events_and_labels(100)
    with open_event_writer(tmp_path / "a.npz", {"width": 346, "height": 260}, labels=True) as w:
        with pytest.raises(ValueError, match="opened with labels=True"):
            w.write(ev)
        with pytest.raises(ValueError, match="99 labels for 100 events"):
            w.write(ev, labels=labels[:-1])
        with pytest.raises(ValueError, match=r"codes in \[0, 255\]"):
            w.write(ev, labels=labels.astype(np.int64) + 300)
        with pytest.raises(TypeError, match="integer"):
            w.write(ev, labels=labels.astype(np.float64))
        w.write(ev, labels=labels.astype(np.int64))  # the writer is still usable; ints are taken
    assert read_events(tmp_path / "a.npz", labels=True)[2].tobytes() == labels.tobytes()
    with open_event_writer(tmp_path / "b.h5", {"width": 346, "height": 260}) as w:
        with pytest.raises(ValueError, match="open it with labels=True"):
            w.write(ev, labels=labels)
        w.write(ev)
    assert not read_events(tmp_path / "b.h5")[1]["has_labels"]


@pytest.mark.parametrize("suffix", [".h5", ".npz", ".txt"])
def test_an_aborted_labelled_write_leaves_nothing(tmp_path: Path, suffix: str) -> None:
    ev, labels = events_and_labels(100)
    with pytest.raises(KeyboardInterrupt), open_event_writer(
        tmp_path / f"a{suffix}", {"width": 346, "height": 260}, labels=True
    ) as w:
        w.write(ev, labels=labels)
        raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("suffix", LABELLED)
def test_files_without_labels_read_as_before(tmp_path: Path, suffix: str) -> None:
    ev, _ = events_and_labels()
    path = write_events(tmp_path / f"a{suffix}", ev, {"width": 346, "height": 260})
    result = read_events(path)
    assert len(result) == 2 and result[0].tobytes() == ev.tobytes() and result[1]["has_labels"] is False
    with pytest.raises(ValueError, match=rf"a{suffix}' has no label column"):
        read_events(path, labels=True)
    if suffix in (".txt", ".csv"):
        assert "label" not in path.read_text().split("\n", 3)[1]
    # What read_events describes is not content: writing it back gives the same file.
    again = write_events(tmp_path / f"b{suffix}", *read_events(path))
    assert read_events(again)[1]["has_labels"] is False


def test_the_label_column_is_described_in_the_file(tmp_path: Path) -> None:
    import h5py

    ev, labels = events_and_labels(10)
    h5 = write_events(tmp_path / "a.h5", ev, {"width": 346, "height": 260}, labels=labels)
    with h5py.File(h5) as f:
        column = f["events/label"]
        assert column.dtype == np.uint8 and column.chunks == f["events/t"].chunks
        assert "4 = hot_pixel" in column.attrs["codes"]
    txt = write_events(tmp_path / "a.txt", ev, {"width": 346, "height": 260}, labels=labels)
    lines = txt.read_text().splitlines()
    assert lines[1] == "# t x y p label" and lines[2].startswith("# label: 0 = signal, 1 = shot_noise")
    assert lines[3].split() == [str(v) for v in (*ev[0].tolist(), labels[0])]


def test_a_foreign_text_file_with_a_label_column(tmp_path: Path) -> None:
    """The ``t x y p label`` text of denoising data sets, in seconds, with a row of names, and
    unsorted: the labels are sorted with their events."""
    path = tmp_path / "dnd.txt"
    path.write_text("t x y p label\n0.000200 3 4 1 1\n0.000100 5 6 -1 0\n0.000300 7 8 1 1\n")
    events, meta, labels = read_events(path, labels=True)
    assert events["t"].tolist() == [100, 200, 300] and labels.tolist() == [0, 1, 1]
    assert meta["resorted"] and meta["has_labels"]
    bad = tmp_path / "bad.txt"
    bad.write_text("1 2 3 1 0\n2 2 3 1\n")
    with pytest.raises(ValueError, match=r"bad.txt'.* columns changed from 5 to 4"):
        read_events(bad, labels=True)


@pytest.mark.parametrize(("suffix", "title"), UNLABELLED)
def test_formats_without_a_label_column_refuse_labels(tmp_path: Path, suffix: str, title: str) -> None:
    ev, labels = events_and_labels(10)
    message = rf"cannot write labels to .*a{suffix}': {title}.* files have no label column; write \.h5"
    with pytest.raises(ValueError, match=message):
        write_events(tmp_path / f"a{suffix}", ev, labels=labels)
    with pytest.raises(ValueError, match=message):
        open_event_writer(tmp_path / f"a{suffix}", {"width": 346, "height": 260}, labels=True)
    with pytest.raises(ValueError, match=message):
        simulate_to_file(spinning(250.0), tmp_path / f"a{suffix}", duration_s=0.01, labels=True)
    assert list(tmp_path.iterdir()) == []


def test_hot_pixel_and_signal_labels_from_the_engine() -> None:
    """A noise-free sensor with one hot pixel of an explicit map, and a spot sweeping across
    the other side of the array: the hot pixel's events are all 'hot_pixel', the spot's 'signal'."""
    width, height = 32, 8
    params = PixelParams(**NOISE_FREE)
    rates = np.zeros((height, width))
    rates[1, 2] = 300.0
    sensor = Sensor(width, height, params, seed=5, hot_pixel_rates_hz=rates)
    t = np.arange(1, 401) * 1e-3
    frames = np.full((t.size, height, width), 3.5e7)
    x = (8 + 20 * t / t[-1]).astype(int)
    frames[np.arange(t.size), 6, x] = 1e10
    events = sensor.run(frames, t)
    labels = sensor.last_labels()
    assert labels.dtype == np.uint8 and len(labels) == len(events)
    at_hot = (events["x"] == 2) & (events["y"] == 1)
    assert at_hot.sum() > 20 and np.all(labels[at_hot] == HOT_PIXEL)
    assert (~at_hot).sum() > 20 and np.all(labels[~at_hot] == SIGNAL)


def test_simulated_labels_name_the_hot_pixels_and_the_moving_source() -> None:
    result = simulate(spinning(250.0, **HOT), labels=True)
    assert result.labels is not None and len(result.labels) == len(result.events)
    scene = build(spinning(250.0, **HOT))
    hot = Sensor(scene.width, scene.height, scene.params, seed=scene.seed).hot_pixel_rates_hz().ravel() > 0
    pixel = result.events["y"].astype(np.int64) * scene.width + result.events["x"]
    labels = result.labels
    assert np.all(labels[~hot[pixel]] == SIGNAL) and np.sum(~hot[pixel]) > 1000  # the source, noise-free
    assert np.all(hot[pixel[labels == HOT_PIXEL]]) and np.sum(labels == HOT_PIXEL) > 1000
    # Hot pixels away from the source's 15 px circle fire nothing but 'hot_pixel'.
    ys, xs = np.divmod(np.arange(scene.width * scene.height), scene.width)
    far = hot & (np.abs(np.hypot(xs - 32.0, ys - 24.0) - 15.0) > 6.0)
    assert far.sum() > 5 and np.all(labels[far[pixel]] == HOT_PIXEL)
    assert simulate(spinning(250.0, **HOT)).labels is None  # not asked for


def test_sparse_merge_keeps_each_events_label() -> None:
    """Sub-sampled chunks merge run_pixels' and run's events with a sort: their labels follow,
    so the sparse way gives the dense way's labels as it gives its events."""
    sparse = simulate(spinning(250.0, sparse=True, **HOT), labels=True)
    dense = simulate(spinning(250.0, sparse=False, **HOT), labels=True)
    assert sparse.sub_sampled_chunks > 0
    assert sparse.events.tobytes() == dense.events.tobytes()
    assert sparse.labels is not None and dense.labels is not None
    assert sparse.labels.tobytes() == dense.labels.tobytes()
    assert set(np.unique(sparse.labels)) == {SIGNAL, HOT_PIXEL}


def test_labels_of_a_chunked_simulation_equal_those_of_one_run() -> None:
    def run(chunk_samples: int) -> SimulationResult:
        scenario = spinning(250.0, sparse=False, noise=True, **HOT, **PAPER_BACKGROUND)
        scenario["sampling"]["chunk_samples"] = chunk_samples
        return simulate(scenario, labels=True)

    chunked, whole = run(7), run(1000)  # 1000: every sample after t = 0 in one engine call
    assert chunked.events.tobytes() == whole.events.tobytes()
    assert chunked.labels is not None and whole.labels is not None
    assert chunked.labels.tobytes() == whole.labels.tobytes()
    # With noise on, the leak, background and hot-pixel processes all show up.
    assert {SIGNAL, LEAK, BACKGROUND, HOT_PIXEL} <= set(np.unique(whole.labels).tolist())


@pytest.mark.parametrize("suffix", [".h5", ".npz", ".csv"])
def test_streamed_labels_equal_the_in_memory_run(tmp_path: Path, suffix: str) -> None:
    scenario = spinning(250.0, noise=True, **HOT)
    memory = simulate(scenario, labels=True)
    stats = simulate_to_file(scenario, tmp_path / f"o{suffix}", labels=True)
    events, meta, labels = read_events(tmp_path / f"o{suffix}", labels=True)
    assert stats.n_events == len(memory.events) and events.tobytes() == memory.events.tobytes()
    assert memory.labels is not None and labels.tobytes() == memory.labels.tobytes()
    simulate_to_file(scenario, tmp_path / f"plain{suffix}")
    assert read_events(tmp_path / f"plain{suffix}")[1]["has_labels"] is False  # off by default


def test_cli_simulate_labels(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "mc.npz"
    args = ["simulate", "mcreynolds", "--duration", "0.05", "--set", "sensor.width=64",
            "--set", "sensor.height=48", "--no-progress"]
    assert main([*args, "-o", str(out), "--labels"]) == 0
    events, _, labels = read_events(out, labels=True)
    assert len(labels) == len(events) > 0 and set(np.unique(labels)) <= set(EVENT_LABELS)
    assert main([*args, "-o", str(tmp_path / "mc.es"), "--labels"]) != 0
    assert "Event Stream files have no label column" in capsys.readouterr().err
    assert not (tmp_path / "mc.es").exists()
