"""Make every figure of the documentation from shipped commands, all together.

    python docs/make_figures.py [--recordings DIR] [--only NAME,...] [--workers N]

Each figure is the PNG an ``evstwin`` command draws, copied into ``docs/figures/`` under the
name the pages use. The commands are listed below, once, with the figure they make; the pages
quote the same commands. The two comparison figures need the real DAVIS346 recording
``davis346_road.aedat4`` (the aedat 2.3.0 package's ``tests/data/test_data.aedat4`` from
PyPI) in ``--recordings DIR``; without it they are left as they are, and the script says so.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

FIGURES = Path(__file__).resolve().parent / "figures"
MAX_BYTES = 400_000  # a figure stays small in git


@dataclass(frozen=True)
class Figure:
    name: str  # file name under docs/figures
    commands: tuple[tuple[str, ...], ...]  # evstwin arguments, run in order in a scratch folder
    made: str  # the PNG the last command writes, relative to the scratch folder
    needs: str = ""  # a recording file name under --recordings, if any


def figures(workers: int) -> list[Figure]:
    w = str(workers)
    return [
        Figure("timing_bias.png", (
            ("simulate", "mcreynolds", "-o", "mc.h5", "--duration", "2", "--no-progress"),
            ("timing", "mc.h5", "--out", "timing"),
        ), "timing/timing_bias.png"),
        Figure("timing_by_setting.png", (
            ("simulate", "mcreynolds-run1", "-o", "run1.h5", "--duration", "2", "--no-progress"),
            ("simulate", "mcreynolds", "-o", "mc.h5", "--duration", "2", "--no-progress"),
            ("simulate", "mcreynolds-run3", "-o", "run3.h5", "--duration", "2", "--no-progress"),
            ("timing", "run1.h5", "mc.h5", "run3.h5", "--out", "timing3"),
        ), "timing3/timing_by_setting.png"),
        Figure("geo_stare_frames.png", (
            ("simulate", "geo-stare", "-o", "geo.h5", "--duration", "5", "--no-progress"),
            ("show", "geo.h5", "--out", "geo", "--window", "1"),
        ), "geo/frames.png"),
        Figure("leo_pass_xyt.png", (
            ("simulate", "leo-pass", "-o", "iss.h5", "--duration", "10", "--set", "pointing.at_s=5", "--no-progress"),
            ("show", "iss.h5", "--out", "iss", "--window", "3"),
        ), "iss/xyt.png"),
        Figure("limiting_magnitude.png", (
            ("limiting-magnitude", "--out", "lim", "--workers", w, "--no-progress"),
        ), "lim/limiting_magnitude.png"),
        Figure("limiting_magnitude_setup.png", (
            ("limiting-magnitude", "--preset", "imx636", "--focal-length-mm", "200", "--f-number", "2.8",
             "--sky-mag", "21", "--seeing-arcsec", "2", "--pointing", "staring",
             "--jitter-rms-arcsec", "1", "--rates-arcsec-s", "3,10,30,100,300,1000", "--magnitudes", "6:13:1",
             "--workers", w, "--no-progress", "--out", "lim-setup"),
        ), "lim-setup/limiting_magnitude.png"),
        Figure("limiting_magnitude_gen3_validation.png", (
            ("limiting-magnitude", "--preset", "prophesee_gen3_vga", "--focal-length-mm", "85", "--f-number", "1.4",
             "--sky-mag", "20.3", "--pointing", "sidereal", "--rates-arcsec-s", "15.04", "--magnitudes", "8:11:0.25",
             "--runs", "3", "--duration", "20", "--workers", w, "--no-progress", "--out", "lim-gen3"),
        ), "lim-gen3/limiting_magnitude.png"),
        Figure("characterize_imx636.png", (
            ("characterize", "imx636", "--out", "bench-imx636", "--no-progress"),
        ), "bench-imx636/characterize.png"),
        Figure("compare_frames.png", (
            ("compare", "{rec}", "mcreynolds", "--out", "cmp", "--duration", "2.36", "--runs", "2"),
        ), "cmp/frames.png", needs="davis346_road.aedat4"),
        Figure("compare_histograms.png", (
            ("compare", "{rec}", "mcreynolds", "--out", "cmp", "--duration", "2.36", "--runs", "2"),
        ), "cmp/histograms.png", needs="davis346_road.aedat4"),
    ]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--recordings", type=Path, help="folder holding the real recordings the comparisons need")
    ap.add_argument("--only", help="comma-separated figure names (default: all)")
    ap.add_argument("--workers", type=int, default=2, help="worker processes for the tuning commands (default 2)")
    args = ap.parse_args(argv)
    chosen = figures(args.workers)
    if args.only:
        names = set(args.only.split(","))
        unknown = names - {f.name for f in chosen}
        if unknown:
            ap.error(f"--only: unknown figure(s) {sorted(unknown)}; known: {[f.name for f in chosen]}")
        chosen = [f for f in chosen if f.name in names]
    done: dict[tuple[str, ...], bool] = {}
    with tempfile.TemporaryDirectory(prefix="evstwin-figures-") as scratch:
        for fig in chosen:
            rec = None
            if fig.needs:
                rec = (args.recordings / fig.needs) if args.recordings else None
                if rec is None or not rec.exists():
                    print(f"{fig.name}: left as it is (needs {fig.needs} in --recordings)")
                    continue
            t0 = time.perf_counter()
            for cmd in fig.commands:
                cmd = tuple(str(rec) if a == "{rec}" else a for a in cmd)
                if done.get(cmd):
                    continue
                # outputs of an earlier figure's identical command are reused; others start clean
                full = [sys.executable, "-m", "evstwin", *cmd]
                if "--out" in cmd or "-o" in cmd:
                    full.append("--force")
                print("$ evstwin " + " ".join(cmd), flush=True)
                subprocess.run(full, cwd=scratch, check=True)
                done[cmd] = True
            made = Path(scratch) / fig.made
            size = made.stat().st_size
            if size > MAX_BYTES:
                raise SystemExit(f"{fig.name}: {size} bytes, over {MAX_BYTES}: make the figure smaller")
            shutil.copyfile(made, FIGURES / fig.name)
            print(f"{fig.name}: {size // 1000} kB in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
