"""The formats by file suffix, and the lookup that names the supported suffixes when it fails."""

from __future__ import annotations

from pathlib import Path

from . import aedat, eventstream, hdf5, numpy_files, prophesee, text
from ._common import FileFormat

FORMATS: dict[str, FileFormat] = {
    ".h5": hdf5.FORMAT,
    ".hdf5": hdf5.FORMAT,
    ".npz": numpy_files.FORMAT,
    ".txt": text.TXT_FORMAT,
    ".csv": text.CSV_FORMAT,
    ".aedat4": aedat.FORMAT,
    ".raw": prophesee.RAW_FORMAT,
    ".dat": prophesee.DAT_FORMAT,
    ".es": eventstream.FORMAT,
}


def supported_read_suffixes() -> tuple[str, ...]:
    """File suffixes ``read_events`` understands (lower case, with the dot)."""
    return tuple(s for s, f in FORMATS.items() if f.open_source is not None)


def supported_write_suffixes() -> tuple[str, ...]:
    """File suffixes ``write_events`` can produce (lower case, with the dot)."""
    return tuple(s for s, f in FORMATS.items() if f.open_encoder is not None)


def format_for(path: Path, action: str) -> FileFormat:
    """The format of ``path`` for ``action`` ('read' or 'write'), or ValueError naming the suffix."""
    if action == "read" and path.is_dir():
        raise ValueError(f"cannot read events: {str(path)!r} is a folder, not an event file")
    fmt = FORMATS.get(path.suffix.lower())
    usable = supported_read_suffixes() if action == "read" else supported_write_suffixes()
    if fmt is None or (fmt.open_source if action == "read" else fmt.open_encoder) is None:
        raise ValueError(
            f"cannot {action} events: {str(path)!r} has the unknown suffix {path.suffix!r}; "
            f"supported: {', '.join(usable)}"
        )
    return fmt
