"""Which pixels a comparison looks at: a region of interest (ROI) and a pixel mask.

* :class:`Roi` -- a rectangle ``(x0, y0, width, height)`` [px] of the sensor. Events inside
  it are kept and shifted to the ROI's own coordinates (``x - x0``, ``y - y0``), so a cropped
  recording is a ``width x height`` recording; the simulation of the same ROI is the scenario
  with ``sensor.roi`` set (:func:`evstwin.scenario.build`), whose events come out in the same
  coordinates.
* A mask -- pixels left out of every per-pixel statistic of both recordings (their events
  too): listed (:func:`parse_pixel_list`, :func:`read_pixel_file`) or found by
  :func:`hot_pixels`.

Everything here is checked before anything is simulated: an ROI off the sensor or empty, a
listed pixel off the sensor, or an ROI with no pixel left after masking is one ValueError
naming the value.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Union

import numpy as np

RoiLike = Union["Roi", Sequence[int], str]

HOT_FALSE_ALARMS = 0.01
"""Default of :func:`hot_pixels`' ``false_alarms``: the expected number of ordinary pixels
(Poisson at the rest's mean) flagged per recording, whatever its size (a Bonferroni bound)."""


@dataclass(frozen=True)
class Roi:
    """A rectangle of the sensor [px]: columns ``x0 .. x0 + width - 1``, rows ``y0 .. y0 +
    height - 1``."""

    x0: int
    y0: int
    width: int
    height: int

    @classmethod
    def of(cls, value: RoiLike) -> Roi:
        """An ROI from a Roi, ``(x0, y0, w, h)`` or the text ``'X0,Y0,W,H'``."""
        if isinstance(value, Roi):
            return value
        text = value if isinstance(value, str) else None
        parts: list[Any] = value.replace(" ", "").split(",") if isinstance(value, str) else list(value)
        try:
            if len(parts) != 4:
                raise ValueError
            nums = [int(p) if isinstance(p, str) else p for p in parts]
            if any(isinstance(v, bool) or not float(v).is_integer() for v in nums):
                raise ValueError
            x0, y0, w, h = (int(v) for v in nums)
        except (TypeError, ValueError):
            shown = text if text is not None else value
            raise ValueError(f"roi takes X0,Y0,W,H in whole pixels (e.g. 980,520,300,200); got {shown!r}") from None
        return cls(x0, y0, w, h)

    def __str__(self) -> str:
        return f"{self.x0},{self.y0},{self.width},{self.height}"

    def as_tuple(self) -> tuple[int, int, int, int]:
        return (self.x0, self.y0, self.width, self.height)

    @property
    def pixel_count(self) -> int:
        return self.width * self.height

    def check(self, sensor_width: int, sensor_height: int, what: str = "roi") -> Roi:
        """Raise ValueError (naming the value) unless the ROI is non-empty and inside the
        ``sensor_width x sensor_height`` sensor; return self."""
        if self.width < 1 or self.height < 1:
            raise ValueError(f"{what} {self} is empty: width and height must be >= 1 px")
        if self.x0 < 0 or self.y0 < 0 or self.x0 + self.width > sensor_width or self.y0 + self.height > sensor_height:
            raise ValueError(
                f"{what} {self} (columns {self.x0}..{self.x0 + self.width - 1}, rows {self.y0}.."
                f"{self.y0 + self.height - 1}) is not inside the {sensor_width}x{sensor_height} sensor"
            )
        return self

    def crop(self, events: np.ndarray) -> np.ndarray:
        """The events inside the ROI, in its coordinates (a copy; order kept)."""
        x = events["x"].astype(np.int64)
        y = events["y"].astype(np.int64)
        keep = (x >= self.x0) & (x < self.x0 + self.width) & (y >= self.y0) & (y < self.y0 + self.height)
        out = events[keep].copy()
        out["x"] -= out["x"].dtype.type(self.x0)
        out["y"] -= out["y"].dtype.type(self.y0)
        return out


def parse_pixel_list(text: str) -> list[tuple[int, int]]:
    """``'x,y;x,y'`` -> [(x, y), ...] (whole pixels; spaces ignored; empty entries skipped)."""
    out: list[tuple[int, int]] = []
    for item in text.split(";"):
        item = item.strip()
        if not item:
            continue
        out.append(_pixel(item.replace(" ", ",").split(","), item))
    return out


def read_pixel_file(path: str | Path) -> list[tuple[int, int]]:
    """Pixels listed in a text file, one ``x,y`` (or ``x y``) a line; ``#`` starts a comment."""
    out: list[tuple[int, int]] = []
    with open(path, encoding="utf-8") as fh:
        for n, line in enumerate(fh, 1):
            line = line.split("#", 1)[0].strip()
            if line:
                try:
                    out.append(_pixel(line.replace(",", " ").split(), line))
                except ValueError as exc:
                    raise ValueError(f"{path}:{n}: {exc}") from None
    return out


def _pixel(parts: Sequence[str], text: str) -> tuple[int, int]:
    parts = [p for p in parts if p]
    try:
        if len(parts) != 2:
            raise ValueError
        return int(parts[0]), int(parts[1])
    except ValueError:
        raise ValueError(f"a masked pixel is x,y in whole pixels; got {text!r}") from None


def mask_array(
    pixels: Iterable[tuple[int, int]], sensor_width: int, sensor_height: int, roi: Roi | None = None
) -> np.ndarray:
    """A (height, width) bool array of the ROI (the sensor when None), True at the listed
    pixels (given in sensor coordinates) that fall inside it. A pixel off the sensor is an
    error; one on the sensor but outside the ROI is simply not in it."""
    r = roi or Roi(0, 0, sensor_width, sensor_height)
    mask = np.zeros((r.height, r.width), dtype=bool)
    for x, y in pixels:
        if not (0 <= x < sensor_width and 0 <= y < sensor_height):
            raise ValueError(f"masked pixel ({x}, {y}) is not on the {sensor_width}x{sensor_height} sensor")
        if r.x0 <= x < r.x0 + r.width and r.y0 <= y < r.y0 + r.height:
            mask[y - r.y0, x - r.x0] = True
    return mask


def hot_pixels(
    counts: np.ndarray, mask: np.ndarray | None = None, false_alarms: float = HOT_FALSE_ALARMS
) -> np.ndarray:
    """Pixels whose event count is improbable under a Poisson fit of the rest.

    counts: (height, width) per-pixel event counts (both polarities). mask: pixels already
    left out (not tested, not in the fit). The rule, repeated until no pixel is added: the
    mean ``lam`` of the counts of the pixels neither masked nor flagged so far; a pixel is
    flagged when ``P(X >= count) < false_alarms / N`` for ``X ~ Poisson(lam)``, N the pixels
    tested. On a recording whose pixels all fire as Poisson processes of one rate, the
    expected number of pixels flagged wrongly is at most ``false_alarms`` (default
    :data:`HOT_FALSE_ALARMS`, 0.01: about one recording in a hundred loses one ordinary
    pixel).

    The rule assumes the pixels share one rate: on a scene with a signal (a moving source, a
    lit area) it flags the signal's busiest pixels as well, and on a sensor whose background
    rates spread log-normally across pixels it flags the top of that spread. Use it on dark or
    static regions (choose the ROI), or list the pixels. Returns the (height, width) bool
    array of flagged pixels.
    """
    from scipy.special import gammainc

    if not (isinstance(false_alarms, (int, float)) and 0 < false_alarms < 1):
        raise ValueError(f"false_alarms must be in (0, 1); got {false_alarms!r}")
    c = np.asarray(counts, dtype=np.float64)
    tested = np.ones(c.shape, dtype=bool) if mask is None else ~np.asarray(mask, dtype=bool)
    n = int(np.count_nonzero(tested))
    hot = np.zeros(c.shape, dtype=bool)
    if n == 0:
        return hot
    level = false_alarms / n
    for _ in range(64):
        rest = tested & ~hot
        if not rest.any():
            break
        lam = float(c[rest].mean())
        # P(X >= k) for X ~ Poisson(lam) is the regularised lower incomplete gamma P(k, lam)
        # (k >= 1); a count of 0 is never improbably high.
        with np.errstate(invalid="ignore"):
            tail = np.where(c >= 1, gammainc(np.maximum(c, 1.0), lam) if lam > 0 else 0.0, 1.0)
        new = tested & (tail < level) & ~hot
        if not new.any():
            break
        hot |= new
    return hot


def check_mask_leaves_pixels(mask: np.ndarray, roi: Roi | None, what: str = "the mask") -> int:
    """The number of pixels left; ValueError when none."""
    left = int(mask.size - np.count_nonzero(mask))
    if left == 0:
        where = f"the roi {roi}" if roi is not None else "the sensor"
        raise ValueError(f"{what} leaves no pixel of {where} ({mask.size} px, {mask.size} masked)")
    return left


def describe(roi: Roi | None, mask: np.ndarray | None) -> str:
    """One line on the pixels compared, for reports."""
    parts = []
    if roi is not None:
        parts.append(f"roi {roi} ({roi.width}x{roi.height} px from ({roi.x0}, {roi.y0}), in its own coordinates)")
    if mask is not None and mask.any():
        parts.append(f"{int(np.count_nonzero(mask))} pixel(s) masked")
    return "; ".join(parts)
