"""``evstwin movie``: a recording as a GIF or MP4 through faery (issue 31, item 14)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from evstwin.cli import main
from evstwin.io import write_events
from evstwin.movie import LABEL_COLORS, MovieOptions, over_background, parse_color, render_movie
from evstwin.sensor import EVENT_DTYPE, EVENT_LABELS

Image = pytest.importorskip("PIL.Image", reason="Pillow comes with matplotlib")

ON, OFF, GOLD = (0, 255, 0), (255, 0, 0), (255, 215, 0)


def recording(path: Path, truth: bool = False, labels: bool = False) -> Path:
    """A 32 x 24 recording spanning 200 ms: an ON event at (5, 7) and an OFF event at (20, 10)
    10 ms in, and two events at (0, 0) that open and close the span. With ``labels``: the ON
    event is the signal's, the OFF event shot noise, the two at (0, 0) a hot pixel's."""
    events = np.zeros(4, EVENT_DTYPE)
    events["t"] = [0, 10_000, 10_000, 199_999]
    events["x"] = [0, 5, 20, 0]
    events["y"] = [0, 7, 10, 0]
    events["p"] = [1, 1, 0, 1]
    meta: dict = {"width": 32, "height": 24}
    if truth:  # a target standing at (10, 12) for the whole span
        meta["truth"] = {"sat": {"t_s": np.array([0.0, 0.2]), "x_px": np.array([10.0, 10.0]),
                                 "y_px": np.array([12.0, 12.0]), "flux_ph_s": np.array([1e6, 1e6])}}
    write_events(path, events, meta, labels=np.array([4, 0, 1, 4], np.uint8) if labels else None)
    return path


def frames(gif: Path, period_ms: int = 40) -> list[np.ndarray]:
    """Every frame of a GIF at ``period_ms`` a frame (the encoder stores a run of identical
    frames once, with their summed duration)."""
    out = []
    with Image.open(gif) as im:
        for i in range(im.n_frames):
            im.seek(i)
            repeats, rest = divmod(int(im.info["duration"]), period_ms)
            assert rest == 0 and repeats >= 1
            out += [np.asarray(im.convert("RGB")).astype(int)] * repeats
    return out


def close(pixel: np.ndarray, rgb: tuple[int, int, int]) -> bool:
    return bool(np.max(np.abs(pixel - np.array(rgb))) <= 12)  # GIF palettes round colours a little


def test_a_gif_has_the_frames_and_colours_asked_for(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rec = recording(tmp_path / "r.h5")
    out = tmp_path / "r.gif"
    # 200 ms at 25 frames/s and speed 1: 5 frames of 40 ms; a window decay of one frame: a
    # pixel shows the colour of an event of its own frame, at full strength.
    assert main(["movie", str(rec), "--out", str(out), "--frame-rate", "25", "--decay", "window", "--scale", "2",
                 "--on-color", "#00FF00", "--off-color", "#FF0000", "--no-progress"]) == 0
    assert "wrote" in capsys.readouterr().out
    got = frames(out)
    assert len(got) == 5 and got[0].shape == (48, 64, 3)
    first = got[0]
    assert close(first[2 * 7, 2 * 5], ON) and close(first[2 * 7 + 1, 2 * 5 + 1], ON)   # the ON event's pixel
    assert close(first[2 * 10, 2 * 20], OFF)                                           # the OFF event's pixel
    assert close(first[2 * 3, 2 * 15], (0, 0, 0))                                      # no event: background
    assert close(got[2][2 * 7, 2 * 5], (0, 0, 0))  # two frames later the window has passed
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def test_the_ground_truth_is_drawn_where_the_file_has_it(tmp_path: Path) -> None:
    rec = recording(tmp_path / "t.h5", truth=True)
    render_movie(rec, tmp_path / "t.gif", MovieOptions(frame_rate_hz=25.0, decay="window"))
    first = frames(tmp_path / "t.gif")[0]
    # a square outline of half-side 3 px around pixel (10, 12): its top edge on row 9, its
    # left edge on column 7; its centre stays clear
    assert close(first[9, 10], GOLD) and close(first[12, 7], GOLD) and close(first[12, 10], (0, 0, 0))
    render_movie(rec, tmp_path / "n.gif", MovieOptions(frame_rate_hz=25.0, decay="window", truth=False))
    assert close(frames(tmp_path / "n.gif")[0][9, 10], (0, 0, 0))


def test_labels_as_colours_show_why_each_event_fired(tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    rec = recording(tmp_path / "l.h5", labels=True)
    out = tmp_path / "l.gif"
    assert main(["movie", str(rec), "--out", str(out), "--frame-rate", "25", "--decay", "window", "--color-by",
                 "label", "--on-color", "#00FF00", "--off-color", "#FF0000", "--no-progress"]) == 0
    printed = capsys.readouterr().out
    first = frames(out)[0]
    assert close(first[7, 5], ON)                                   # the signal's ON event: the ON colour
    assert close(first[10, 20], parse_color(LABEL_COLORS[1], ""))   # an OFF event of shot noise: its label's
    assert close(first[0, 0], parse_color(LABEL_COLORS[4], ""))     # the hot pixel's
    assert close(first[3, 15], (0, 0, 0))
    assert f"{EVENT_LABELS[1]}: {LABEL_COLORS[1]}" in printed and f"{EVENT_LABELS[2]}:" not in printed  # no leak
    # by polarity the same file shows the shot-noise event in the OFF colour
    render_movie(rec, tmp_path / "p.gif", MovieOptions(frame_rate_hz=25.0, decay="window", off_color="#FF0000"))
    assert close(frames(tmp_path / "p.gif")[0][10, 20], OFF)


def test_layers_meet_where_they_stand_out_most() -> None:
    background = np.array([0, 0, 0, 255], np.uint8)
    dim, bright = (np.array([[[v, v, v, 255]]], np.uint8) for v in (40, 200))
    red, green = (np.array([[rgb + [255]]], np.uint8) for rgb in ([90, 0, 0], [0, 90, 0]))
    # per pixel the layer farthest from the background (summed |RGB|: 120 against 600), the
    # first where they tie (red and green both 90 away)
    assert over_background([dim, bright], background)[0, 0, 0] == 200
    assert over_background([red, green], background)[0, 0].tolist() == [90, 0, 0, 255]
    assert over_background([green, red], background)[0, 0].tolist() == [0, 90, 0, 255]


def test_a_window_past_the_last_event_has_all_its_frames(tmp_path: Path) -> None:
    rec = recording(tmp_path / "r.h5")  # events up to 200 ms; 400 ms asked at 25 frames/s: 10 frames
    movie = render_movie(rec, tmp_path / "r.gif", MovieOptions(frame_rate_hz=25.0, duration_s=0.4, decay="window"))
    got = frames(tmp_path / "r.gif")
    assert movie.frames == len(got) == 10 and close(got[9][0, 0], (0, 0, 0))


def test_an_mp4_is_written_whole(tmp_path: Path) -> None:
    rec = recording(tmp_path / "r.h5")
    movie = render_movie(rec, tmp_path / "r.mp4", MovieOptions(frame_rate_hz=50.0, scale=2))
    data = (tmp_path / "r.mp4").read_bytes()
    assert data[4:8] == b"ftyp" and movie.frames == 10 and movie.size_px == (64, 48)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.h5", "r.mp4"]


def test_an_mp4_of_an_odd_sized_sensor_is_padded_to_even(tmp_path: Path) -> None:
    events = np.zeros(2, EVENT_DTYPE)
    events["t"] = [0, 99_999]
    events["x"], events["y"] = [0, 32], [0, 24]
    write_events(tmp_path / "odd.h5", events, {"width": 33, "height": 25})
    movie = render_movie(tmp_path / "odd.h5", tmp_path / "odd.mp4", MovieOptions())  # H.264 takes even sizes
    assert movie.size_px == (34, 26) and (tmp_path / "odd.mp4").read_bytes()[4:8] == b"ftyp"
    assert render_movie(tmp_path / "odd.h5", tmp_path / "odd.gif", MovieOptions()).size_px == (33, 25)


def test_an_interrupted_movie_leaves_nothing(tmp_path: Path) -> None:
    rec = recording(tmp_path / "r.h5")

    def interrupt(done: int, total: int) -> None:
        if done == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        render_movie(rec, tmp_path / "r.gif", MovieOptions(frame_rate_hz=25.0), progress=interrupt)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.h5"]


@pytest.mark.parametrize(("args", "message"), [
    (["--out", "m.avi"], "--out m.avi: a movie is .mp4 or .gif; got the suffix '.avi'"),
    (["--out", "m.gif", "--t0", "5"], "--t0 5 s is past the recording's end (0.199999 s after its first event)"),
    (["--out", "m.gif", "--frame-rate", "0"], "--frame-rate must be in (0, 1000] Hz; got 0.0"),
    (["--out", "m.gif", "--on-color", "green"], "--on-color takes a colour as #RRGGBB (e.g. #F4C20D); got 'green'"),
    (["--out", "m.gif", "--speed", "1e-9"], "6000000000 frames (0.2 s at 3.33333e-11 s a frame) is more than 100000"),
    (["--out", "r.h5"], "--out r.h5 exists; pass --force to overwrite it"),
    (["--out", "m.gif", "--color-by", "label"], "--color-by label: r.h5 has no label column"),
])
def test_bad_input_is_one_line_and_writes_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                  monkeypatch: pytest.MonkeyPatch, args: list[str],
                                                  message: str) -> None:
    monkeypatch.chdir(tmp_path)
    recording(tmp_path / "r.h5")
    assert main(["movie", "r.h5", "--no-progress", *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("evstwin: error: ") and message in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.h5"]
