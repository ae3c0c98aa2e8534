"""Ctrl-C and the processes evstwin starts: a terminal delivers SIGINT to every process of
its group, and a worker or decoder child that raised KeyboardInterrupt would print its own
traceback (or die half-way through its imports); the parent alone handles it and stops them."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator


@contextlib.contextmanager
def children_without_sigint() -> Iterator[None]:
    """Block SIGINT in this thread while the block starts processes (the forkserver, pool
    workers): they inherit the blocked mask through fork and exec, so a Ctrl-C at a terminal,
    which reaches every process of the group, never interrupts them (not even while they
    import, before :func:`ignore_sigint` runs); the parent gets it, after the block at the
    latest, and stops them. A no-op where there is no ``pthread_sigmask``."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    from multiprocessing import resource_tracker

    # Started first: starting it unblocks SIGINT again (Python 3.11's resource_tracker
    # blocks and then *unblocks* the signals it hides from the tracker).
    resource_tracker.ensure_running()
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        # Another thread (a pool's manager, a progress bar's) may still take the signal, and
        # Python would raise it here, between a child's fork and its registration with its
        # pool, leaving a child nobody stops: held until the block ends.
        with sigint_deferred():
            yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def ignore_sigint() -> None:
    """Worker-process initialiser: Ctrl-C at a terminal reaches every process of the group,
    and a worker that raised KeyboardInterrupt would print its own traceback; the parent
    stops the workers instead."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextlib.contextmanager
def sigint_deferred() -> Iterator[None]:
    """Hold a Ctrl-C that arrives inside the block until the block has ended, then raise it
    (KeyboardInterrupt): for steps that must not stop half-way. Outside the main thread,
    where Python handles no signal, the block just runs."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught and callable(previous):
        previous(signal.SIGINT, None)
