"""Optional dependencies, imported where they are needed.

The engine, scenes and the HDF5 / NPZ / text files need only NumPy, SciPy and h5py. Heavier
libraries come with extras (``pip install 'evstwin[plot]'`` and so on; ``[all]`` installs
every one), and a missing one is reported in one line that names the extra to install.
"""

from __future__ import annotations

import importlib
from types import ModuleType

# module -> (extra that installs it, what it is used for)
EXTRAS: dict[str, tuple[str, str]] = {
    "matplotlib": ("plot", "figures"),
    "aedat": ("io", "reading AEDAT4 files"),
    "faery": ("io", "Prophesee RAW/DAT and Event Stream files, AEDAT4 writing"),
    "optuna": ("tune", "the Optuna samplers of fit"),
    "cmaes": ("tune", "fit --sampler cmaes"),
    "dask": ("dask", "running jobs on a Dask cluster"),
    "distributed": ("dask", "running jobs on a Dask cluster"),
}


class MissingExtraError(ImportError):
    """An optional dependency is not installed; the message names the extra to install."""


def require(module: str, purpose: str | None = None) -> ModuleType:
    """Import ``module`` (e.g. ``"matplotlib.pyplot"``), or raise :class:`MissingExtraError`
    naming the extra that installs it."""
    from ._signals import sigint_deferred

    try:
        # A Ctrl-C during the import waits until it has ended: a C extension interrupted
        # half-way through its initialisation turns the KeyboardInterrupt into an ImportError
        # ("needs the 'matplotlib' package") and can leave a module that crashes the
        # interpreter as it shuts down.
        with sigint_deferred():
            return importlib.import_module(module)
    except ImportError as exc:
        if _caused_by_interrupt(exc):
            raise KeyboardInterrupt from None
        top = module.split(".", 1)[0]
        extra, used_for = EXTRAS.get(top, ("all", "this feature"))
        raise MissingExtraError(
            f"{purpose or used_for} needs the '{top}' package: pip install 'evstwin[{extra}]'"
        ) from exc


def _caused_by_interrupt(exc: BaseException) -> bool:
    """Whether a KeyboardInterrupt is in ``exc``'s chain (an import interrupted outside the
    main thread, where the Ctrl-C cannot be deferred)."""
    seen: set[int] = set()
    cause: BaseException | None = exc
    while cause is not None and id(cause) not in seen:
        if isinstance(cause, KeyboardInterrupt):
            return True
        seen.add(id(cause))
        cause = cause.__cause__ or cause.__context__
    return False


__all__ = ["EXTRAS", "MissingExtraError", "require"]
