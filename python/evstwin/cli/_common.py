"""What every command shares: output paths that are never overwritten silently."""

from __future__ import annotations

import argparse
from pathlib import Path


def add_force(p: argparse.ArgumentParser) -> None:
    p.add_argument("--force", action="store_true", help="overwrite existing outputs (default: refuse)")


def check_output_file(path: str | Path, force: bool, option: str = "--output") -> Path:
    """Refuse an output file that exists (unless ``force``) or whose folder is missing, before
    any work is done."""
    p = Path(path)
    if p.is_dir():
        raise ValueError(f"{option} {p} is a directory; give a file name")
    if p.exists() and not force:
        raise FileExistsError(f"{option} {p} exists; pass --force to overwrite it")
    if not p.parent.is_dir():
        raise FileNotFoundError(f"{option} {p}: folder {p.parent} does not exist")
    return p


def check_output_dir(path: str | Path, force: bool, option: str = "--out") -> Path:
    """Refuse an output folder that is a file, or that already holds files (unless ``force``).
    The folder is not created here: a command creates it only once its inputs are checked."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise NotADirectoryError(f"{option} {p} is a file, not a folder")
    if p.is_dir() and any(p.iterdir()) and not force:
        raise FileExistsError(f"{option} {p} is not empty; pass --force to overwrite its files")
    return p


def add_size(p: argparse.ArgumentParser) -> None:
    p.add_argument("--size", type=parse_size, metavar="W,H",
                   help="sensor size in pixels for recordings whose header has none (e.g. Prophesee Gen3 "
                        "EVT2 files); default: the header, the camera plugin's size, else the events' extent")


def parse_size(text: str) -> tuple[int, int]:
    """``'640,480'`` -> (640, 480); argparse turns the ValueError into a one-line usage error."""
    parts = text.replace("x", ",").split(",")
    try:
        width, height = (int(v) for v in parts)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--size takes W,H in pixels (e.g. 640,480); got {text!r}") from None
    if not (1 <= width <= 65535 and 1 <= height <= 65535):
        raise argparse.ArgumentTypeError(f"--size W,H must each be in 1..65535; got {text!r}")
    return width, height
