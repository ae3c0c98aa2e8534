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


def add_region(p: argparse.ArgumentParser) -> None:
    """``--roi``, ``--mask-pixels``, ``--mask-file`` and ``--mask-hot``: the pixels compared."""
    p.add_argument("--roi", type=parse_roi, metavar="X0,Y0,W,H",
                   help="compare only this rectangle of the sensor [px]: the recordings' events are cut to it "
                        "and shifted to its corner, and scenarios simulate it alone (sensor.roi)")
    p.add_argument("--mask-pixels", metavar="X,Y;X,Y",
                   help="pixels (sensor coordinates) left out of both recordings' statistics, e.g. '187,261;5,9'")
    p.add_argument("--mask-file", metavar="FILE",
                   help="a text file of pixels to leave out, one 'x,y' or 'x y' a line ('#' comments)")
    p.add_argument("--mask-hot", action="store_true",
                   help="also leave out the real recording's hot pixels: counts improbable under a Poisson fit of "
                        "the other pixels (at most 0.01 ordinary pixels flagged per recording; README, Validation)")


def parse_roi(text: str) -> tuple[int, int, int, int]:
    """``'980,520,300,200'`` -> (980, 520, 300, 200); whether it lies on the sensor is checked
    once the sensor is known."""
    from ..validation.region import Roi

    try:
        return Roi.of(text).as_tuple()
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc).replace("roi takes", "--roi takes")) from None


def region_args(args: argparse.Namespace) -> tuple[tuple[int, int, int, int] | None, list[tuple[int, int]], bool]:
    """(roi, listed pixels, mask_hot) from the options of :func:`add_region`."""
    from ..validation.region import parse_pixel_list, read_pixel_file

    pixels: list[tuple[int, int]] = []
    if args.mask_pixels:
        try:
            pixels += parse_pixel_list(args.mask_pixels)
        except ValueError as exc:
            raise ValueError(f"--mask-pixels {args.mask_pixels!r}: {exc}") from None
    if args.mask_file:
        try:
            pixels += read_pixel_file(args.mask_file)
        except OSError as exc:
            raise ValueError(f"--mask-file {args.mask_file}: {exc.strerror or exc}") from None
    return args.roi, pixels, bool(args.mask_hot)
