"""The ``evstwin`` command (also ``python -m evstwin``): one thin function per command over
the Python API, grouped by what the user is doing.

    evstwin simulate SCENARIO -o OUT      evstwin scenarios          (cli.simulate)
    evstwin info | show | compare | timing                           (cli.recordings)
    evstwin fit | sweep | limiting-magnitude                         (cli.tuning)

Errors are one line on stderr (``evstwin: error: ...``) and exit status 2; nothing is
written then.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from typing import Optional

from .._core import __version__
from . import recordings, simulate, tuning


def build_parser() -> argparse.ArgumentParser:
    """The whole ``evstwin`` argument parser; each command module registers its own."""
    ap = argparse.ArgumentParser(
        prog="evstwin", description="Physics-based digital twin of event cameras (DAVIS346, IMX636) for SSA."
    )
    ap.add_argument("--version", action="version", version=f"evstwin {__version__}")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")
    simulate.register(sub)
    recordings.register(sub)
    tuning.register(sub)
    return ap


def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = build_parser()
    args = ap.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print("evstwin: interrupted", file=sys.stderr)
        return 130
    except (ValueError, TypeError, FileNotFoundError, FileExistsError, NotADirectoryError, PermissionError) as exc:
        print(f"evstwin: error: {exc}", file=sys.stderr)
        return 2


__all__ = ["build_parser", "main"]
