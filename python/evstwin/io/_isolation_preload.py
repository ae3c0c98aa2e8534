"""Imported once by the fork server that starts the decoding children (see ``_isolation``), so
that each child starts with evstwin, h5py and the optional decoders already loaded."""

from __future__ import annotations

import contextlib

import h5py  # noqa: F401

from . import _registry  # noqa: F401  (every format module)

for _name in ("aedat", "faery"):
    with contextlib.suppress(ImportError):
        __import__(_name)
