"""The readout between the pixels and the event stream: limited rate, a FIFO, a timestamp clock.

The engine gives every event its ideal time (rounded to the microsecond). A real sensor reads
its pixels out through an arbiter and a serialiser (or, on Prophesee sensors, an event-rate
controller) with a maximum event rate: when the pixels fire faster, events queue and leave
late, and once the buffer is full they are lost. ``Readout`` models that, on the engine's
sorted events, chunk by chunk (the C++ ``evstwin::Readout``, cpp/include/evstwin/readout.hpp):

* one server: event i leaves at ``d_i = max(a_i, d_(i-1) + 1 / max_rate_hz)`` (a_i its
  arrival, the engine's time); an event that finds the readout idle leaves at once;
* a FIFO of ``fifo_depth`` events: an accepted event waits from its arrival until it leaves;
  an arriving event that finds ``fifo_depth`` events waiting is dropped and counted (it takes
  no service time);
* the output time is ``d_i`` floored to the timestamp ``tick_s``, as a counter latches it when
  the event leaves, then floored to the record's integer microsecond.

Deterministic, exact (integer multiples of 10 ps), and streaming: the state carried between calls
is a few integers, so any chunking gives the same bytes as one call, and the output stays
sorted by time. Below saturation, with a 1 us tick, every event keeps its time.

What it is not: a model of the arbiter's order (equal times are served in input order, i.e.
the engine's row-major order), of a pixel blocked while its request waits (here a pixel's
later events queue behind it; the engine's refractory period already bounds one pixel's
rate), or of Prophesee's ERC, which thins events over time windows rather than queueing them.

Timing caveat: the engine rounds ideal times to the nearest microsecond; a real counter
floors them, so real timestamps are on average 0.5 us earlier than these (below the tick).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import _core
from ._checks import finite, integer

TIME_UNIT_S: float = float(_core.Readout.TIME_UNIT_S)
"""The model's clock (10 ps): times, services and delays are whole multiples of it."""
MAX_RATE_HZ: float = float(_core.Readout.MAX_RATE_HZ)
"""Highest max_rate_hz (1e11 Hz: a service time of at least one unit of the model's clock)."""
MIN_TICK_S: float = float(_core.Readout.MIN_TICK_S)
MAX_TICK_S: float = float(_core.Readout.MAX_TICK_S)
MAX_QUEUE_DELAY_S: float = float(_core.Readout.MAX_QUEUE_DELAY_S)
"""Most fifo_depth / max_rate_hz [s] (1e6 s), the longest delay a kept event can suffer: it
keeps every departure within the model clock's range."""
MAX_FIFO_DEPTH = 2**63 - 1


def _rate(value: Any) -> float:
    v = finite("max_rate_hz", value)
    if not 0.0 < v <= MAX_RATE_HZ:
        raise ValueError(f"max_rate_hz must be > 0 and <= {MAX_RATE_HZ:g} Hz; got max_rate_hz={value!r}")
    return v


def _depth(value: Any) -> int:
    v = integer("fifo_depth", value)
    if not 1 <= v <= MAX_FIFO_DEPTH:
        raise ValueError(f"fifo_depth must be an integer >= 1 (events); got fifo_depth={value!r}")
    return v


def _queue(depth: int, rate_hz: float) -> None:
    if not depth / rate_hz <= MAX_QUEUE_DELAY_S:
        raise ValueError(
            f"fifo_depth / max_rate_hz (the longest delay a kept event can suffer) must be <= {MAX_QUEUE_DELAY_S:g} s; "
            f"got fifo_depth={depth}, max_rate_hz={rate_hz!r}"
        )


def _tick(value: Any) -> float:
    v = finite("tick_s", value)
    if not MIN_TICK_S <= v <= MAX_TICK_S:
        raise ValueError(f"tick_s must be in [{MIN_TICK_S:g}, {MAX_TICK_S:g}] s (> 0); got tick_s={value!r}")
    return v


@dataclass(frozen=True)
class ReadoutParams:
    """A readout's figures: ``max_rate_hz`` [events/s], ``fifo_depth`` [events], ``tick_s``
    [s, default 1 us, the timestamp clock of the DAVIS346 and IMX636], and where they come from.
    Checked at construction (ValueError naming the field and value)."""

    max_rate_hz: float
    fifo_depth: int
    tick_s: float = 1e-6
    sources: tuple[str, ...] = ()
    assumptions: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "max_rate_hz", _rate(self.max_rate_hz))
        object.__setattr__(self, "fifo_depth", _depth(self.fifo_depth))
        object.__setattr__(self, "tick_s", _tick(self.tick_s))
        _queue(self.fifo_depth, self.max_rate_hz)

    @property
    def service_s(self) -> float:
        """Time the readout takes per event [s] (1 / max_rate_hz)."""
        return 1.0 / self.max_rate_hz

    @property
    def max_queue_delay_s(self) -> float:
        """Longest delay a kept event can suffer [s]: a full FIFO ahead of it, fifo_depth / rate."""
        return self.fifo_depth / self.max_rate_hz

    def replace(self, **changes: Any) -> ReadoutParams:
        return dataclasses.replace(self, **changes)

    def readout(self) -> Readout:
        """A fresh ``Readout`` with these figures."""
        return Readout(self.max_rate_hz, self.fifo_depth, self.tick_s)


class Readout:
    """A streaming readout (see the module doc): feed it the events of each chunk in time order.

    ``process(events)`` returns the kept events with their readout times; the counters say what
    happened since construction or ``reset()``. Bad parameters raise ValueError naming the
    argument and value; unsorted events (within a call or against the previous call) raise
    ValueError and leave the readout as it was.
    """

    def __init__(self, max_rate_hz: float, fifo_depth: int, tick_s: float = 1e-6) -> None:
        rate, depth = _rate(max_rate_hz), _depth(fifo_depth)
        _queue(depth, rate)
        self._core = _core.Readout(rate, depth, _tick(tick_s))

    @classmethod
    def from_params(cls, params: ReadoutParams) -> Readout:
        return cls(params.max_rate_hz, params.fifo_depth, params.tick_s)

    def process(self, events: np.ndarray) -> np.ndarray:
        """The kept events of ``events`` (EVENT_DTYPE, sorted by t [us]), with their output
        times, sorted by time; a new array that owns its memory."""
        return self._core.process(events)

    def process_with_delays(self, events: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """As ``process``, plus each kept event's queueing delay [s] (departure - arrival,
        before the tick; float64, a whole number of the model's 10 ps)."""
        return self._core.process_with_delays(events)

    def process_with_index(self, events: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Like ``process``, and each kept event's index into ``events`` (uint64; the FIFO keeps
        the order), to carry per-event data such as labels along."""
        return self._core.process_with_index(events)

    def reset(self) -> None:
        """An empty, idle readout with zeroed counters."""
        self._core.reset()

    @property
    def max_rate_hz(self) -> float:
        return float(self._core.max_rate_hz)

    @property
    def fifo_depth(self) -> int:
        return int(self._core.fifo_depth)

    @property
    def tick_s(self) -> float:
        """The tick as given [s]; the model uses it rounded to a whole 10 ps."""
        return float(self._core.tick_s)

    @property
    def n_in(self) -> int:
        """Events offered."""
        return int(self._core.n_in)

    @property
    def n_out(self) -> int:
        """Events kept (n_in - n_dropped)."""
        return int(self._core.n_out)

    @property
    def n_dropped(self) -> int:
        """Events lost to a full FIFO."""
        return int(self._core.n_dropped)

    @property
    def n_dropped_on(self) -> int:
        """Of the dropped events, the ON ones (p = 1)."""
        return int(self._core.n_dropped_on)

    @property
    def n_delayed(self) -> int:
        """Kept events that left after they arrived (delay > 0 before the tick)."""
        return int(self._core.n_delayed)

    @property
    def max_delay_s(self) -> float:
        """Worst queueing delay of a kept event [s] (0.0 if none waited)."""
        return float(self._core.max_delay_s)

    @property
    def peak_waiting(self) -> int:
        """Most events waiting at once (<= fifo_depth)."""
        return int(self._core.peak_waiting)

    def stats(self) -> dict[str, Any]:
        """The figures and counters as a plain dict (what ``simulate`` writes into its meta)."""
        return {
            "max_rate_hz": self.max_rate_hz,
            "fifo_depth": self.fifo_depth,
            "tick_s": self.tick_s,
            "n_in": self.n_in,
            "n_out": self.n_out,
            "n_dropped": self.n_dropped,
            "n_dropped_on": self.n_dropped_on,
            "n_delayed": self.n_delayed,
            "max_delay_s": self.max_delay_s,
            "peak_waiting": self.peak_waiting,
        }

    def __repr__(self) -> str:
        return (f"Readout(max_rate_hz={self.max_rate_hz:g}, fifo_depth={self.fifo_depth}, tick_s={self.tick_s:g}; "
                f"{self.n_in} in, {self.n_dropped} dropped, worst delay {self.max_delay_s:.3g} s)")


__all__ = ["MAX_QUEUE_DELAY_S", "MAX_RATE_HZ", "MAX_TICK_S", "MIN_TICK_S", "TIME_UNIT_S", "Readout", "ReadoutParams"]
