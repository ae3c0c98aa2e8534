"""evstwin: a physics-based digital twin of event-based vision sensors, for SSA.

The engine (C++, ``Sensor``) turns photons/s on each pixel into events; around it:
optics and PSF (``evstwin.optics``, ``evstwin.psf``), targets and scenarios
(``evstwin.targets``, ``evstwin.scenario``), the end-to-end ``simulate``, event files
(``read_events``, ``write_events``), the paper's validation (``evstwin.validation``) and
tuning (``evstwin.tune``).
"""

from __future__ import annotations

import os

# OpenMP threads that wait at the end of a parallel region sleep instead of spinning: on a
# machine where another process keeps a core busy, spinning threads steal the time the
# working ones need (the default thread count ran 2-2.5x slower than one thread). libgomp
# reads this once, when the engine loads it, so it must be set before ``_core`` is imported;
# a value the user set is kept.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from ._core import __version__
from .io import read_events, write_events
from .pixel import HotPixelChain, PixelParams
from .presets import thresholds_from_biases
from .sensor import EVENT_DTYPE, EVENT_LABELS, TRACE_DTYPE, Sensor
from .simulate import simulate, simulate_to_file

__all__ = [
    "EVENT_DTYPE",
    "EVENT_LABELS",
    "TRACE_DTYPE",
    "HotPixelChain",
    "PixelParams",
    "Sensor",
    "__version__",
    "read_events",
    "simulate",
    "simulate_to_file",
    "thresholds_from_biases",
    "write_events",
]
