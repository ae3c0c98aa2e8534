"""The commands on recordings (info, show, compare, timing) as a new user meets them: inputs
checked before anything is written or simulated, outputs never overwritten silently,
progress, help that says every default."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
import pytest

from evstwin.cli import build_parser, main

DATA = Path(__file__).resolve().parents[1] / "data"
DAVIS = DATA / "davis346_road_cut.aedat4"  # 346 x 260, 2000 real events over 50 ms
EVK4 = DATA / "imx636_cut_evt3.raw"  # 1280 x 720


def one_line_error(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    assert err.startswith("evstwin: error: ") and err.count("\n") == 1, err
    return err


@pytest.mark.parametrize(
    "argv",
    [
        ["compare", "nonexist.aedat4", "mcreynolds", "--out", "{out}"],
        ["show", "nonexist.h5", "--out", "{out}"],
        ["compare", str(DAVIS), "no-such-scenario", "--out", "{out}"],
        ["timing", "nonexist.h5", "--out", "{out}"],
    ],
)
def test_bad_inputs_leave_no_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    out = tmp_path / "out"
    assert main([a.replace("{out}", str(out)) for a in argv]) == 2
    one_line_error(capsys)
    assert not out.exists()


def test_info_of_a_directory_is_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "d.h5").mkdir()
    assert main(["info", str(tmp_path / "d.h5")]) == 2
    assert "d.h5" in one_line_error(capsys)


def test_size_mismatch_is_found_before_simulating(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cmp"
    assert main(["compare", str(EVK4), "mcreynolds", "--out", str(out)]) == 2
    err = one_line_error(capsys)
    assert "346x260" in err and "1280x720" in err
    assert not out.exists()


def test_compare_simulates_the_recordings_span_with_progress(tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cmp"
    assert main(["compare", str(DAVIS), "mcreynolds", "--out", str(out), "--runs", "2"]) == 0
    err = capsys.readouterr().err
    assert "simulating 0.049926 s per run" in err  # the cut's span, not the scenario's 10 s
    assert "2/2" in err  # the per-run progress bar finished
    report = json.loads((out / "compare.json").read_text())
    assert report["monte_carlo"]["runs"] == 2
    from evstwin.io import read_events

    _, meta = read_events(out / "mcreynolds_seed1.h5")
    assert meta["duration_s"] == pytest.approx(0.049926, abs=0.004)  # whole 4 ms samples
    # The same folder again is refused, then allowed with --force.
    assert main(["compare", str(DAVIS), str(out / "mcreynolds_seed0.h5"), "--out", str(out)]) == 2
    assert "--force" in one_line_error(capsys)
    assert main(["compare", str(DAVIS), str(out / "mcreynolds_seed0.h5"), "--out", str(out), "--force"]) == 0


def test_show_takes_a_time_window_and_refuses_a_full_folder(tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "figs"
    assert main(["show", str(DAVIS), "--out", str(out), "--t0", "0.01", "--window", "0.005"]) == 0
    assert (out / "frames.png").is_file() and (out / "xyt.png").is_file()
    assert main(["show", str(DAVIS), "--out", str(out)]) == 2
    assert "not empty" in one_line_error(capsys)
    assert main(["show", str(DAVIS), "--out", str(out), "--window", "0"]) == 2
    assert "--window" in one_line_error(capsys)


def test_show_past_the_end_says_so_and_writes_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "figs"
    assert main(["show", str(DAVIS), "--out", str(out), "--t0", "100"]) == 2
    err = one_line_error(capsys)
    assert "--t0 100 s is past the end" in err and "0.049926 s" in err  # the cut's span
    assert not out.exists() and list(tmp_path.iterdir()) == []


def _slow_recording(path: Path, rate_hz: float, duration_s: float) -> None:
    """A 64 x 48 recording: a source crossing it at 5 px/s, one event every 1/rate_hz s."""
    from evstwin import write_events
    from evstwin.sensor import EVENT_DTYPE

    t_us = np.arange(0, round(duration_s * 1e6), round(1e6 / rate_hz))
    ev = np.zeros(t_us.size, EVENT_DTYPE)
    ev["t"], ev["x"], ev["y"], ev["p"] = t_us, (t_us * 5e-6).astype(int) % 64, 24, t_us % 2
    write_events(path, ev, {"width": 64, "height": 48})


@pytest.mark.parametrize(("rate_hz", "duration_s", "window"), [
    (100.0, 10.0, "3.3 s"),  # 1,000 events in all, fewer than 3 x 1,000: the span, in thirds
    (50_000.0, 1.0, "0.02 s"),  # 1,000 events (the floor for 3,072 px) every 20 ms
])
def test_show_chooses_its_window_from_the_recording(tmp_path: Path, rate_hz: float, duration_s: float,
                                                    window: str) -> None:
    from evstwin.validation import show

    _slow_recording(tmp_path / "slow.npz", rate_hz, duration_s)
    notes: list[str] = []
    show(tmp_path / "slow.npz", tmp_path / "figs", notes=notes)
    assert len(notes) == 1 and f"3 of {window} " in notes[0]


def test_show_draws_small_counts_one_bin_per_count(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from evstwin import plots
    from evstwin.validation import show

    seen = {}
    real = plots.plot_count_histograms

    def spy(edges, hists, path, **kw):  # type: ignore[no-untyped-def]
        seen["edges"] = edges
        return real(edges, hists, path, **kw)

    monkeypatch.setattr(plots, "plot_count_histograms", spy)
    show(DAVIS, tmp_path / "figs", window_s=0.01)  # at most 12 events a pixel
    np.testing.assert_array_equal(seen["edges"]["total"], np.arange(0, 14))
    fig = plots.fig_count_histograms(seen["edges"], [("cut", {k: np.ones(e.size - 1) for k, e in seen["edges"].items()})])
    ax = fig.axes[0]
    assert ax.get_xlim() == (-0.5, 12.5)  # each count's bar centred on it
    ticks = [t for t in ax.get_xticks() if -0.5 <= t <= 12.5]
    assert ticks and all(float(t).is_integer() for t in ticks)
    assert "one bin per count" in fig.texts[0].get_text()


@pytest.mark.parametrize(("flag", "value"), [("--radius-px", "-1"), ("--radius-px", "0"), ("--max-delay-s", "0")])
def test_timing_refuses_non_positive_limits(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                            flag: str, value: str) -> None:
    assert main(["timing", str(DAVIS), "--out", str(tmp_path / "t"), flag, value]) == 2
    assert flag in one_line_error(capsys)
    assert not (tmp_path / "t").exists()


def test_every_argument_has_help_that_states_its_default() -> None:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    missing = []
    for name, command in sub.choices.items():
        for action in command._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            if not action.help:
                missing.append(f"{name} {action.dest}: no help")
            elif action.default not in (None, False, [], argparse.SUPPRESS) and "default" not in action.help:
                missing.append(f"{name} {action.dest}: default {action.default!r} not stated")
    assert not missing, missing


def test_size_reaches_the_readers(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", str(DAVIS), "--size", "400,300"]) == 0
    assert "400 x 300 px (120000 pixels) (--size)" in capsys.readouterr().out
    for argv in (["info", str(EVK4), "--size", "346,260"],
                 ["show", str(EVK4), "--size", "346,260", "--out", str(tmp_path / "s")],
                 ["compare", str(EVK4), str(DAVIS), "--size", "346,260", "--out", str(tmp_path / "c")]):
        assert main(argv) == 2
        assert "outside the size given 346x260" in one_line_error(capsys)
    assert not (tmp_path / "s").exists() and not (tmp_path / "c").exists()


def test_compare_states_the_simulated_duration_in_its_report(tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "cmp"
    assert main(["compare", str(DAVIS), "mcreynolds", "--out", str(out), "--duration", "0.02"]) == 0
    assert "simulating 0.02 s per run (--duration)" in capsys.readouterr().err
    assert json.loads((out / "compare.json").read_text())["simulated_duration_s"] == 0.02
