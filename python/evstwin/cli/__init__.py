"""The ``evstwin`` command (also ``python -m evstwin``): one thin function per command over
the Python API, grouped by what the user is doing.

    evstwin simulate SCENARIO -o OUT      evstwin scenarios          (cli.simulate)
    evstwin info | show | movie | compare | timing | calibrate-noise (cli.recordings)
    evstwin fit | sweep | limiting-magnitude                         (cli.tuning)
    evstwin characterize PRESET                                      (cli.characterize)

Errors are one line on stderr (``evstwin: error: ...``) and exit status 2; nothing is
written then. Ctrl-C is one line (``evstwin: interrupted``) and exit status 130, at any
moment after start-up: an output folder is then either complete or absent
(:func:`._common.staged_folder`), and a sweep keeps its finished rows for ``--resume``.
"""

from __future__ import annotations

import argparse
import atexit
import os
import signal
import sys
from collections.abc import Sequence
from typing import NoReturn

from .._core import __version__
from .._extras import MissingExtraError
from . import characterize, recordings, simulate, tuning


def build_parser() -> argparse.ArgumentParser:
    """The whole ``evstwin`` argument parser; each command module registers its own."""
    ap = argparse.ArgumentParser(
        prog="evstwin", description="Physics-based digital twin of event cameras (DAVIS346, IMX636, Prophesee Gen3 VGA) for "
                                    "space-situational awareness."
    )
    ap.add_argument("--version", action="version", version=f"evstwin {__version__}")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")
    simulate.register(sub)
    recordings.register(sub)
    tuning.register(sub)
    characterize.register(sub)
    return ap


INTERRUPTED = "evstwin: interrupted"


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; returns the exit status (0 ok, 1 some jobs failed, 2 bad input or a
    missing extra, 130 interrupted)."""
    ap = build_parser()
    try:
        args = ap.parse_args(argv)
        status = int(args.func(args) or 0)
        sys.stdout.flush()
        return status
    except KeyboardInterrupt as exc:
        print(f"{INTERRUPTED}{': ' + str(exc) if str(exc) else ''}", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # `evstwin scenarios | head -2`: the reader left; not an error of ours. Point stdout
        # at /dev/null so the interpreter's final flush does not raise again.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    except MissingExtraError as exc:
        print(f"evstwin: error: {exc}", file=sys.stderr)
        return 2
    except (ValueError, TypeError, OSError) as exc:
        # OSError covers a missing file, a directory where a file was expected, no space
        # left and permissions: each names its path in the message.
        print(f"evstwin: error: {_one_line(exc)}", file=sys.stderr)
        return 2


def run() -> NoReturn:
    """The ``evstwin`` console command: :func:`main` on ``sys.argv``, then exit with its
    status. A Ctrl-C that comes once the command has returned (its output complete), while
    the interpreter shuts down, is held rather than raised in a finaliser, where Python
    would print "Exception ignored in ..." and exit 0: the exit is then status 130 and one
    line, like a Ctrl-C during the command."""
    late: list[int] = []

    def _late_interrupt() -> None:  # registered first, so it runs after every other atexit
        if late:
            print(INTERRUPTED, file=sys.stderr)
            for stream in (sys.stdout, sys.stderr):
                try:
                    stream.flush()
                except (OSError, ValueError):
                    pass
            os._exit(130)

    atexit.register(_late_interrupt)
    status = main()
    signal.signal(signal.SIGINT, lambda signum, frame: late.append(signum))
    _forget_escaped_interrupt()
    sys.exit(status)


def _forget_escaped_interrupt() -> None:
    """Clear CPython's note that a KeyboardInterrupt escaped code run from a string.

    ``exec``/``eval`` of a string (dataclasses and namedtuple build their methods so, at
    import time) runs through ``run_eval_code_obj``, which sets the interpreter's
    "unhandled KeyboardInterrupt" flag when a KeyboardInterrupt leaves it, even though
    :func:`main` catches it further up; ``Py_RunMain`` checks that flag after finalising
    and then kills the process with SIGINT (exit status -2) whatever ``sys.exit`` said: a
    Ctrl-C that landed in such code (~1 run in 20 of ``show`` interrupted while drawing,
    whose matplotlib imports build dataclasses) printed the one line and then died by
    SIGINT. ``run_eval_code_obj`` clears the flag on entry, so running an empty string
    through it clears a stale one; the interrupt itself has been handled (status 130)."""
    exec("")  # runs nothing: see the docstring


def _one_line(exc: BaseException) -> str:
    if isinstance(exc, OSError) and exc.filename is not None and exc.strerror:
        return f"{exc.filename}: {exc.strerror}"
    return " ".join(str(exc).split("\n")).strip() or type(exc).__name__


__all__ = ["build_parser", "main", "run"]
