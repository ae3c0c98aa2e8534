"""Ctrl-C at any point of a command: exit status 130 and one line, and an output folder that
is complete or absent (a sweep keeps its finished rows and says --resume runs the rest).

Each command runs in its own process group and gets SIGINT at the group, as a terminal's
Ctrl-C reaches the command and every worker it started. The points are taken after the
command has started working (its first message, or its staging folder): Python's own
start-up, before evstwin's code runs, is not evstwin's to handle."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from evstwin.cli._common import staged_folder

DAVIS = Path(__file__).resolve().parents[1] / "data" / "davis346_road_cut.aedat4"  # 2000 events over 50 ms
SHOW_FILES = {"event_rate.png", "frames.png", "histograms.png", "xyt.png"}
COMPARE_FILES = {"compare.json", "bin_error.png", "percent_error.png", "histograms.png", "frames.png", "xyt.png",
                 "event_rate.png", "mcreynolds_seed0.h5", "mcreynolds_seed1.h5", "bin_error_mc.png",
                 "percent_error_mc.png"}
FIT_FILES = {"best.toml", "compare", "convergence.png", "fit.json", "history.csv"}

pytestmark = pytest.mark.skipif(not hasattr(os, "killpg"), reason="needs process groups")


def _interrupt(args: list[str], cwd: Path, started: Callable[[str], bool], after_s: float) -> tuple[int, str]:
    """Run ``evstwin ARGS`` in its own process group; once ``started(stderr so far)`` holds,
    wait ``after_s`` and send SIGINT to the group. Returns (exit status, stderr)."""
    err_path = cwd / "stderr.txt"
    with open(err_path, "w") as err:
        proc = subprocess.Popen(
            [sys.executable, "-m", "evstwin", *args], cwd=cwd, stdout=subprocess.DEVNULL, stderr=err,
            start_new_session=True,
            # A test run started in the background by a non-interactive shell ignores SIGINT,
            # and its children inherit that: restore the terminal's default.
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )
        try:
            deadline = time.monotonic() + 120
            while proc.poll() is None and not started(err_path.read_text()) and time.monotonic() < deadline:
                time.sleep(0.05)
            time.sleep(after_s)
            with contextlib.suppress(ProcessLookupError):
                os.killpg(proc.pid, signal.SIGINT)
            proc.wait(timeout=60)
        finally:
            if proc.poll() is None:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
            with contextlib.suppress(ProcessLookupError):  # no worker may outlive the test
                os.killpg(proc.pid, signal.SIGKILL)
    return proc.returncode, err_path.read_text()


def _check_one_line(rc: int, err: str) -> str:
    """An interrupted run's stderr: no traceback, one ``evstwin: interrupted`` line, last."""
    assert rc == 130, err
    for noise in ("Traceback", "KeyboardInterrupt", "Exception ignored"):
        assert noise not in err, err
    lines = [line for line in err.replace("\r", "\n").splitlines() if line.strip()]
    assert [line for line in lines if "interrupted" in line] == [lines[-1]], err
    assert lines[-1].startswith("evstwin: interrupted"), err
    return lines[-1]


def _check_whole_or_none(cwd: Path, name: str, files: set[str], rc: int, err: str) -> bool:
    """The folder holds every file or does not exist, and no staging folder is left.
    Returns whether the run was interrupted."""
    assert not [p.name for p in cwd.iterdir() if p.name.startswith(f".{name}.")], list(cwd.iterdir())
    out = cwd / name
    if rc == 0:  # finished before the signal: complete
        assert {p.name for p in out.iterdir()} == files
        return False
    _check_one_line(rc, err)
    assert not out.exists(), sorted(p.name for p in out.iterdir())
    return True


@pytest.mark.parametrize("after_s", [0.0, 1.0, 2.5])
def test_compare_interrupted_leaves_all_or_nothing(tmp_path: Path, after_s: float) -> None:
    rc, err = _interrupt(["compare", str(DAVIS), "mcreynolds", "--runs", "2", "--out", "c"], tmp_path,
                         lambda e: "simulating" in e, after_s)
    interrupted = _check_whole_or_none(tmp_path, "c", COMPARE_FILES, rc, err)
    assert interrupted or after_s > 0  # the first point lands while it simulates


def test_show_interrupted_while_drawing_leaves_nothing(tmp_path: Path) -> None:
    # The staging folder appears when drawing starts: the signal lands between figures.
    rc, err = _interrupt(["show", str(DAVIS), "--out", "s"], tmp_path,
                         lambda e: any(p.name.startswith(".s.") for p in tmp_path.iterdir()), 0.2)
    assert _check_whole_or_none(tmp_path, "s", SHOW_FILES, rc, err)


def test_movie_interrupted_while_rendering_leaves_nothing(tmp_path: Path) -> None:
    # 50 ms at a thousandth of real time: 1500 frames, the signal lands while they are encoded
    rc, err = _interrupt(["movie", str(DAVIS), "--out", "m.mp4", "--speed", "0.001"], tmp_path,
                         lambda e: "rendering" in e, 0.3)
    if rc == 0:
        pytest.skip("the movie was finished before the signal")  # not expected
    _check_one_line(rc, err)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["stderr.txt"]


@pytest.mark.parametrize("after_s", [0.0, 3.0])
def test_fit_interrupted_leaves_all_or_nothing(tmp_path: Path, after_s: float) -> None:
    rc, err = _interrupt(["fit", str(DAVIS), "--scenario", "mcreynolds", "--budget", "2", "--workers", "1",
                          "--out", "f"], tmp_path, lambda e: "estimate" in e, after_s)
    _check_whole_or_none(tmp_path, "f", FIT_FILES, rc, err)


def _sweep_args(tmp_path: Path) -> list[str]:
    return ["sweep", "--scenario", "mcreynolds", "--set", "sensor.width=32", "--set", "sensor.height=24",
            "--grid", "pixel.theta_on=0.2,0.25,0.3,0.35,0.4,0.45", "--objective", "noise", "--duration", "0.05",
            "--workers", "1", "--out", "sw"]


def test_sweep_interrupted_before_a_row_keeps_nothing(tmp_path: Path) -> None:
    rc, err = _interrupt(_sweep_args(tmp_path), tmp_path, lambda e: "estimate" in e, 0.0)
    line = _check_one_line(rc, err)
    assert "nothing was kept" in line
    assert not (tmp_path / "sw").exists()


def test_sweep_interrupted_after_rows_says_resume_runs_the_rest(tmp_path: Path) -> None:
    table = tmp_path / "sw" / "sweep.csv"

    def two_rows(_: str) -> bool:
        return table.exists() and table.read_text().count("\n") >= 3  # header and two rows

    rc, err = _interrupt(_sweep_args(tmp_path), tmp_path, two_rows, 0.0)
    if rc == 0:
        pytest.skip("the sweep finished before the signal")  # six runs of 50 ms: not expected
    line = _check_one_line(rc, err)
    rows = table.read_text().count("\n") - 1
    assert f"{rows} of 6 runs are in sw/sweep.csv" in line and "--resume" in line
    # --resume runs only the rest: six rows in the end, the kept ones unchanged.
    kept = table.read_text().splitlines()[1:]
    proc = subprocess.run([sys.executable, "-m", "evstwin", *_sweep_args(tmp_path), "--resume", "--no-progress"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    final = table.read_text().splitlines()[1:]
    assert len(final) == 6 and set(kept) <= set(final)
    assert f"({len(kept)} resumed)" in proc.stdout


def test_a_late_ctrl_c_is_one_line_and_status_130(tmp_path: Path) -> None:
    # Ctrl-C once the command has returned, while the interpreter shuts down: not "Exception
    # ignored in ..." and status 0, but the interrupt's line and 130.
    code = (
        "import atexit, os, signal, sys\n"
        "import evstwin.cli as cli\n"
        "def command():\n"
        "    atexit.register(os.kill, os.getpid(), signal.SIGINT)  # runs before run()'s own\n"
        "    return 0\n"
        "cli.main = command\n"
        "cli.run()\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60,
                          preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert proc.returncode == 130
    assert proc.stderr == "evstwin: interrupted\n"


def test_an_interrupt_that_left_code_run_from_a_string_is_still_status_130(tmp_path: Path) -> None:
    # A Ctrl-C that lands in code exec'd from a string (dataclasses and namedtuple build their
    # methods so while matplotlib imports) set CPython's "unhandled KeyboardInterrupt" flag, and
    # `python -m` (Py_RunMain) killed the process with SIGINT at exit (status -2) after the one line.
    (tmp_path / "interrupted_cli_31.py").write_text(
        "import sys\n"
        "import evstwin.cli as cli\n"
        "from evstwin.cli import recordings\n"
        "def interrupted(args):\n"
        "    exec('raise KeyboardInterrupt')  # as a Ctrl-C inside a dataclass's generated code\n"
        "recordings.cmd_info = interrupted\n"
        "sys.argv = ['evstwin', 'info', 'x.h5']\n"
        "cli.run()\n"
    )
    proc = subprocess.run([sys.executable, "-m", "interrupted_cli_31"], capture_output=True, text=True, timeout=60,
                          cwd=tmp_path, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert (proc.returncode, proc.stderr) == (130, "evstwin: interrupted\n")


def test_a_ctrl_c_during_an_optional_import_waits_for_it_and_is_not_a_missing_package(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from evstwin._extras import require

    # A module whose import is interrupted half-way: the import finishes, then the Ctrl-C is raised.
    (tmp_path / "slow_extra_31.py").write_text(
        "import os, signal, time\n"
        "os.kill(os.getpid(), signal.SIGINT)\n"
        "time.sleep(0.05)\n"
        "COMPLETE = True\n")
    # A C extension turns an interrupt during its initialisation into an ImportError.
    (tmp_path / "c_like_extra_31.py").write_text(
        "try:\n"
        "    raise KeyboardInterrupt\n"
        "except KeyboardInterrupt:\n"
        "    raise ImportError('numpy.core.multiarray failed to import')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    # Python's own Ctrl-C handler, even where the test run inherited an ignored SIGINT
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            require("slow_extra_31")
        assert sys.modules["slow_extra_31"].COMPLETE
        with pytest.raises(KeyboardInterrupt):
            require("c_like_extra_31")
    finally:
        signal.signal(signal.SIGINT, previous)
        for name in ("slow_extra_31", "c_like_extra_31"):
            sys.modules.pop(name, None)


def test_staged_folder_is_whole_or_absent(tmp_path: Path) -> None:
    out = tmp_path / "new" / "deeper" / "out"
    with pytest.raises(KeyboardInterrupt), staged_folder(out) as stage:
        (stage.path / "a.txt").write_text("half")
        raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []  # the parents made for it are gone too
    with staged_folder(out) as stage:
        (stage.path / "sub").mkdir()
        (stage.path / "a.json").write_text(json.dumps({"file": str(stage.path / "sub" / "x.h5"),
                                                       "note": f"see {stage.path}/sub/x.h5 here"}))
        assert not out.exists()
    assert sorted(p.name for p in out.iterdir()) == ["a.json", "sub"]
    data = json.loads((out / "a.json").read_text())
    assert data == {"file": str(out / "sub" / "x.h5"), "note": f"see {out}/sub/x.h5 here"}
    assert stage.final_of(stage.path / "sub") == out / "sub"
    assert [p.name for p in out.parent.iterdir()] == ["out"]


def test_staged_folder_with_force_replaces_namesakes_and_keeps_the_rest(tmp_path: Path) -> None:
    out = tmp_path / "out"
    (out / "compare").mkdir(parents=True)
    (out / "compare" / "old.png").write_text("old")
    (out / "mine.txt").write_text("the user's")
    (out / "best.toml").write_text("old")
    with staged_folder(out) as stage:
        (stage.path / "compare").mkdir()
        (stage.path / "compare" / "new.png").write_text("new")
        (stage.path / "best.toml").write_text("new")
    assert sorted(p.name for p in out.iterdir()) == ["best.toml", "compare", "mine.txt"]
    assert [p.name for p in (out / "compare").iterdir()] == ["new.png"]
    assert (out / "best.toml").read_text() == "new" and (out / "mine.txt").read_text() == "the user's"
    assert [p.name for p in tmp_path.iterdir()] == ["out"]
