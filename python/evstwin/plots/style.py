"""What every figure shares: the fixed colours, the resolution, saving as PNG, subsampling for scatter plots."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._extras import require

if TYPE_CHECKING:  # pragma: no cover
    from matplotlib.colors import to_rgb
    from matplotlib.figure import Figure
else:
    to_rgb = require("matplotlib.colors").to_rgb
    Figure = require("matplotlib.figure").Figure
if TYPE_CHECKING:  # pragma: no cover
    pass


PathLike = str | Path


LabelledEvents = tuple[str, np.ndarray]


ON_COLOUR = "#e34a1b"


OFF_COLOUR = "#2066b0"


TOTAL_COLOUR = "#404040"


KIND_COLOURS: dict[str, str] = {"total": TOTAL_COLOUR, "on": ON_COLOUR, "off": OFF_COLOUR}


KIND_LABELS: dict[str, str] = {"total": "all events", "on": "ON events", "off": "OFF events"}


DPI = 120


MAX_SCATTER_POINTS = 20000


"""Cap on the events drawn per recording in a scatter plot (evenly spaced in time order)."""


def save(fig: Figure, path: PathLike, dpi: int = DPI) -> Path:
    """Write ``fig`` as a PNG of exactly figsize * dpi pixels and return the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, format="png")
    return path


def subsample(events: np.ndarray, max_points: int = MAX_SCATTER_POINTS) -> np.ndarray:
    """At most ``max_points`` events, evenly spaced in the (time) order, deterministic."""
    if events.size <= max_points:
        return events
    idx = np.linspace(0, events.size - 1, max_points).round().astype(np.int64)
    return events[idx]


def _unit(value_unit: str) -> str:
    return "events" if value_unit == "events" else "events/s"


def _value_label(kind: str, value_unit: str) -> str:
    """x label of a per-pixel histogram: 'ON events per pixel [events]' or, compared by rate,
    'ON event rate per pixel [events/s]'."""
    prefix = {"total": "", "on": "ON ", "off": "OFF "}[kind]
    if value_unit == "events":
        return f"{prefix}events per pixel [events]"
    return f"{prefix}event rate per pixel [events/s]"
