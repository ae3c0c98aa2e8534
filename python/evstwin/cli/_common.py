"""What every command shares: output paths that are never overwritten silently, and output
folders that appear whole or not at all."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import secrets
import shutil
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from .._signals import sigint_deferred


def add_force(p: argparse.ArgumentParser) -> None:
    p.add_argument("--force", action="store_true", help="overwrite existing outputs (default: refuse)")


def add_sets(p: argparse.ArgumentParser, help_text: str) -> None:
    """The repeatable ``--set KEY=VALUE`` scenario override (into ``args.sets``); ``help_text``
    says what it overrides for this command."""
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE", help=help_text)


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


class StagedFolder:
    """An output folder being written: the command writes into :attr:`path`, a hidden sibling
    of :attr:`final` (``.NAME.partial-XXXXXXXX``), which :func:`staged_folder` renames to
    ``final`` once the command has finished."""

    def __init__(self, path: Path, final: Path) -> None:
        self.path = path
        self.final = final

    def final_of(self, p: str | Path) -> Path:
        """Where ``p`` (a path in the staging folder) will be once the folder is in place."""
        try:
            return self.final / Path(p).relative_to(self.path)
        except ValueError:
            return Path(p)

    def relocated(self, text: str) -> str:
        """``text`` with every path into the staging folder made a path into :attr:`final`
        (the staging folder's name is unique: nothing else matches)."""
        for old, new in ((str(self.path), str(self.final)),
                         (os.path.abspath(self.path), os.path.abspath(self.final))):
            text = text.replace(old + os.sep, new + os.sep)
            if text == old:
                text = new
        return text


@contextlib.contextmanager
def staged_folder(path: str | Path) -> Iterator[StagedFolder]:
    """Write an output folder whole or not at all: the block writes into a new hidden sibling
    of ``path``; when it ends without an exception the sibling takes ``path``'s name (one
    rename for a new or empty folder; with ``--force`` into a folder holding files, each of
    the new entries replaces its namesake), and paths to the staging folder in the JSON files
    written are made paths to ``path``. Any exception, Ctrl-C included, removes the staging
    folder and the parent folders made for it: nothing is left under ``path``. Ctrl-C while
    the folder is put in place waits until it is (then raises KeyboardInterrupt)."""
    final = Path(path)
    parent = final.absolute().parent
    made = [d for d in (parent, *parent.parents) if not d.exists()]
    stage: StagedFolder | None = None
    try:
        parent.mkdir(parents=True, exist_ok=True)
        while stage is None:  # os.mkdir, not mkdtemp: the folder gets the umask's mode, not 0700
            candidate = final.parent / f".{final.name}.partial-{secrets.token_hex(4)}"
            with contextlib.suppress(FileExistsError):
                candidate.mkdir()
                stage = StagedFolder(candidate, final)
        yield stage
        with sigint_deferred():
            _relocate_json(stage)
            _publish(stage.path, final)
    except BaseException:
        with sigint_deferred():
            if stage is not None:
                shutil.rmtree(stage.path, ignore_errors=True)
            for d in made:  # innermost first; stops at the first that is not empty
                try:
                    d.rmdir()
                except OSError:
                    break
        raise


def _publish(stage: Path, final: Path) -> None:
    """Put the finished staging folder in place of ``final``."""
    if not final.exists() or (final.is_dir() and not any(final.iterdir())):
        try:
            os.replace(stage, final)  # POSIX replaces an empty folder in one rename
            return
        except OSError:
            if not final.is_dir() or any(final.iterdir()):
                raise
            final.rmdir()
            os.replace(stage, final)
            return
    for entry in sorted(stage.iterdir()):  # --force into a folder holding files
        dest = final / entry.name
        if dest.is_dir() and not dest.is_symlink():
            shutil.rmtree(dest)
        elif entry.is_dir() and (dest.exists() or dest.is_symlink()):
            dest.unlink()
        os.replace(entry, dest)
    stage.rmdir()


def _relocate_json(stage: StagedFolder) -> None:
    """Paths into the staging folder, in the JSON files written there, as paths into the final one."""
    for path in stage.path.rglob("*.json"):
        data = json.loads(path.read_text(encoding="utf-8"))
        fixed = _relocate(data, stage)
        if fixed != data:
            path.write_text(json.dumps(fixed, indent=1), encoding="utf-8")


def _relocate(obj: Any, stage: StagedFolder) -> Any:
    if isinstance(obj, str):
        return stage.relocated(obj)
    if isinstance(obj, list):
        return [_relocate(v, stage) for v in obj]
    if isinstance(obj, dict):
        return {k: _relocate(v, stage) for k, v in obj.items()}
    return obj


@contextlib.contextmanager
def resumable(path: str | Path, total_runs: int) -> Iterator[None]:
    """A sweep writing into ``path``: its ``sweep.csv`` gains a row as each run finishes,
    and that is what ``--resume`` continues. Ctrl-C inside the block says how many runs the
    table holds and that ``--resume`` runs the rest; where none had finished, the table and
    a folder made for it are removed again (nothing to resume)."""
    out = Path(path)
    existed = out.is_dir()
    before = set(out.iterdir()) if existed else set()
    try:
        yield
    except KeyboardInterrupt:
        with sigint_deferred():
            table = out / "sweep.csv"
            rows = _csv_rows(table)
            if rows:
                raise KeyboardInterrupt(
                    f"{rows} of {total_runs} runs are in {table}: the same command with --resume runs the rest"
                ) from None
            if out.is_dir():
                for entry in set(out.iterdir()) - before:
                    if entry.is_file():
                        entry.unlink()
                if not existed:
                    with contextlib.suppress(OSError):
                        out.rmdir()
        raise KeyboardInterrupt("no run had finished; nothing was kept") from None


def _csv_rows(path: Path) -> int:
    """Complete data rows of a CSV written row by row (a row cut by a kill ends without a
    newline and is not counted)."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return 0
    return max(0, text.count("\n") - 1)


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
                        "the other pixels (at most 0.01 ordinary pixels flagged per recording; the documentation's validation page)")


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
