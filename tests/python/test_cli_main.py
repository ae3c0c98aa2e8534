"""The command's shell: one-line errors, outputs checked before any work, pipes, extras."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from evstwin.cli import main


def test_scenarios_into_a_closed_pipe_is_quiet() -> None:
    # `evstwin scenarios | head -1`: the reader leaves early; no BrokenPipeError traceback.
    proc = subprocess.run(
        f"{sys.executable} -m evstwin scenarios | head -1", shell=True, capture_output=True, text=True, timeout=60
    )
    assert proc.returncode == 0
    assert len(proc.stdout.splitlines()) == 1
    assert "Traceback" not in proc.stderr and "BrokenPipe" not in proc.stderr


def test_every_scenario_description_is_a_whole_sentence(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["scenarios"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) >= 5
    for line in lines:
        assert not line.rstrip().endswith((" through", " a", " the", ",")), line


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda p: p.mkdir(), "is a directory; give a file name"),
        (lambda p: p.write_bytes(b"old"), "exists; pass --force to overwrite it"),
    ],
)
def test_simulate_checks_its_output_before_simulating(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                      make, message: str) -> None:
    out = tmp_path / "o.h5"
    make(out)
    # A 10 s full-size run would take seconds: the error must come before any of it.
    assert main(["simulate", "mcreynolds", "-o", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and str(out) in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o.h5"]


def test_simulate_into_a_missing_folder_and_force(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "mcreynolds", "-o", str(tmp_path / "no" / "o.h5"), "--no-progress"]) == 2
    assert "folder" in capsys.readouterr().err and not (tmp_path / "no").exists()
    out = tmp_path / "o.npz"
    out.write_bytes(b"old")
    args = ["simulate", "mcreynolds", "-o", str(out), "--duration", "0.02", "--no-progress", "--force",
            "--set", "sensor.width=32", "--set", "sensor.height=24"]
    assert main(args) == 0
    assert out.stat().st_size > 100


def test_an_empty_scenario_file_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    toml = tmp_path / "empty.toml"
    toml.write_text("")
    assert main(["simulate", str(toml), "-o", str(tmp_path / "o.h5"), "--no-progress"]) == 2
    assert "must name its sensor" in capsys.readouterr().err
    assert not (tmp_path / "o.h5").exists()


def test_a_missing_extra_is_one_line_naming_it() -> None:
    # matplotlib blocked: drawing must say which extra to install, not print a traceback.
    code = (
        "import sys; sys.modules['matplotlib'] = None\n"
        "from evstwin._extras import require\n"
        "try:\n    require('matplotlib.pyplot')\nexcept ImportError as e:\n    print(e)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60).stdout
    assert out.strip() == "figures needs the 'matplotlib' package: pip install 'evstwin[plot]'"


@pytest.mark.parametrize(("env", "expected"), [(None, "PASSIVE"), ("active", "active")])
def test_openmp_threads_wait_passively_unless_the_user_says(env: str | None, expected: str) -> None:
    # Spinning OpenMP threads made the default thread count 2-2.5x slower than one thread on a
    # machine with a busy core (bench/bench_threads_loaded.py measures it); the user's choice wins.
    import os

    environ = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"}
    if env is not None:
        environ["OMP_WAIT_POLICY"] = env
    code = "import os, evstwin; print(os.environ['OMP_WAIT_POLICY'])"
    out = subprocess.run([sys.executable, "-c", code], env=environ, capture_output=True, text=True,
                         timeout=60, check=True).stdout
    assert out.strip() == expected


def test_default_thread_count_leaves_a_busy_core_alone() -> None:
    # With another process spinning, the default engine thread count drops by at least one
    # core (on a 2-core machine: one thread, which measured no slower than --threads 1).
    import os

    from evstwin.simulate import default_num_threads

    cores = len(os.sched_getaffinity(0))
    assert 1 <= default_num_threads() <= cores
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        import time

        time.sleep(0.3)  # let it start spinning
        assert default_num_threads() <= max(1, cores - 1)
    finally:
        busy.kill()
        busy.wait()


def test_the_core_imports_without_any_extra() -> None:
    # The engine, scenes, HDF5/NPZ/text files, statistics and tuning compute need only NumPy,
    # SciPy and h5py: every extra blocked, they still import, simulate and write an .h5.
    code = (
        "import sys\n"
        "for m in ('matplotlib', 'aedat', 'faery', 'optuna', 'cmaes', 'dask', 'distributed'):\n"
        "    sys.modules[m] = None\n"
        "import evstwin, evstwin.tune, evstwin.validation, evstwin.analysis, evstwin.io, evstwin.cli\n"
        "r = evstwin.simulate('mcreynolds', duration_s=0.02, sets=['sensor.width=32', 'sensor.height=24'])\n"
        "evstwin.write_events(sys.argv[1], r.events, r.meta)\n"
        "print(len(evstwin.read_events(sys.argv[1])[0]) == len(r.events))\n"
        "try:\n    evstwin.read_events('tests/data/davis346_road_cut.aedat4')\n"
        "except ImportError as e:\n    print(e)\n"
    )
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        out = subprocess.run([sys.executable, "-c", code, f"{tmp}/o.h5"], capture_output=True, text=True,
                             timeout=120, check=True, cwd=str(Path(__file__).resolve().parents[2])).stdout
    lines = out.strip().splitlines()
    assert lines[0] == "True"
    assert "pip install 'evstwin[io]'" in lines[1]


def test_help_and_messages_say_what_a_user_needs(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from evstwin.cli import build_parser
    from evstwin.presets import PRESETS

    parser = build_parser()
    for preset in PRESETS.values():  # every preset's camera is named in the description
        # davis346_paper is the paper's variant of the DAVIS346, not another camera
        name = {"prophesee_gen3_vga": "Gen3 VGA", "davis346_paper": "DAVIS346"}.get(preset.name, preset.name.upper())
        assert name in (parser.description or ""), name
    threads = next(a for a in parser._subparsers._group_actions[0].choices["simulate"]._actions  # type: ignore[union-attr]
                   if a.dest == "threads")
    assert "all cores" not in (threads.help or "") and "busy" in (threads.help or "")
    folder = tmp_path / "adir"
    folder.mkdir()
    for argv, message in ((["info", str(folder)], "is a folder, not an event file"),
                          (["simulate", str(folder), "-o", str(tmp_path / "x.h5")], "is a folder, not a scenario file")):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert message in err and "suffix ''" not in err and "does not exist" not in err and err.count("\n") == 1
    assert main(["simulate", "leo-pass", "--duration", "3", "-o", str(tmp_path / "x.h5"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "pointing.at_s" in err and "--set pointing.at_s=" in err and err.count("\n") == 1
    assert list(folder.parent.iterdir()) == [folder]
