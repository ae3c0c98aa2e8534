"""Event files: read and write ``EVENT_DTYPE`` arrays in the formats of the field, whole or in chunks.

``read_events(path)`` / ``write_events(path, events, meta)`` take and give whole arrays;
``iter_events(path)`` and ``open_event_writer(path, meta)`` do the same chunk by chunk with
memory O(chunk); ``read_time_window(path, t0, t1)`` reads a time window (from the HDF5
millisecond index without scanning). The file's suffix picks the format:

========================  ==========================================================  ==========
suffix                    format                                                      module
========================  ==========================================================  ==========
``.h5``, ``.hdf5``        evstwin HDF5 layout: ``/events/{t,x,y,p}``, ``/ms_to_idx``,   hdf5
                          root attributes, ground truth under ``/truth`` (h5py)
``.npz``                  NumPy zip: ``events`` plus scalar and truth entries          numpy_files
``.txt``, ``.csv``        one ``t x y p`` line per event, ``#`` header comments        text
``.aedat4``               AEDAT 4.0 (iniVation DV, DAVIS): aedat reads, faery writes  aedat
``.raw``                  Prophesee EVT 3.0 / EVT 2.0 (faery reads and writes EVT     prophesee
                          2.0; evstwin's own encoder writes EVT 3.0)
``.dat``                  Prophesee DAT 2.0 (CD events), faery                        prophesee
``.es``                   Event Stream (DVS), faery                                   eventstream
========================  ==========================================================  ==========

Labels (why each event fired, uint8 codes of ``evstwin.EVENT_LABELS``) are an optional column
of ``.h5``/``.hdf5`` (``/events/label``), ``.npz`` (``label``) and ``.txt``/``.csv`` (a fifth
column): ``write_events(..., labels=codes)``, ``open_event_writer(..., labels=True)`` then
``write(events, labels=codes)``, ``read_events(..., labels=True) -> (events, meta, labels)``,
``iter_events(path).labeled()``; ``meta['has_labels']`` says whether a file has them. The other
formats have no label column and refuse labels with ValueError naming the format.

h5py and NumPy are core dependencies; ``aedat`` and ``faery`` come with ``pip install
'evstwin[io]'`` and are imported only when an AEDAT/RAW/DAT/ES file is read or written.

Times are integer microseconds from the recording's own time origin (real recordings are not
shifted to 0 unless ``t0_zero=True``). Polarity ``p`` is 1 for ON, 0 for OFF. Only
``.h5``/``.hdf5`` and ``.npz`` hold the whole ``meta`` (scenario, ground truth, extra scalars);
the other formats hold the events and the sensor size (plus, for ``.raw``, the EVT version).

Every writer writes a hidden temporary file in the destination directory and renames it onto
the final name only once it is complete, so a failed or interrupted write never leaves a
truncated file under the final name (an existing file there is left untouched). A writer checks
the free space before each chunk and at close (OSError ENOSPC naming the path, 512 KiB to spare),
removes its temporary files on every failure, removes those a dead writer of the same path left,
and holds a lock beside the output so that a second writer of the same path is refused.

Files decoded by native libraries (``.aedat4``, ``.h5``/``.hdf5``, ``.raw``, ``.dat``, ``.es``)
are decoded in a child process (:mod:`evstwin.io._isolation`): a decoder that aborts or spins on
a corrupted file becomes a one-line ValueError naming the file, not a dead or hung caller.
"""

from __future__ import annotations

from ._common import RAW_FORMATS
from ._registry import supported_read_suffixes, supported_write_suffixes
from .reader import EventStream, iter_events, read_events, read_time_window
from .writer import EventWriter, check_writable, open_event_writer, write_events

__all__ = [
    "RAW_FORMATS",
    "EventStream",
    "EventWriter",
    "check_writable",
    "iter_events",
    "open_event_writer",
    "read_events",
    "read_time_window",
    "supported_read_suffixes",
    "supported_write_suffixes",
    "write_events",
]
