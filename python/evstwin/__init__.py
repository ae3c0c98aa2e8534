"""evstwin: a physics-based digital twin of event-based vision sensors, for SSA."""

from __future__ import annotations

from ._core import __version__
from .pixel import PixelParams
from .sensor import EVENT_DTYPE, TRACE_DTYPE, Sensor

__all__ = ["EVENT_DTYPE", "TRACE_DTYPE", "PixelParams", "Sensor", "__version__"]
