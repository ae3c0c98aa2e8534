"""``[hot_pixels]``: an explicit hot-pixel map (a file and listed pixels) and the listed pixels'
own telegraph and polarity chains."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from .. import _core
from ..pixel import HotPixelChain, PixelParams
from ..sensor import MAX_HOT_PIXEL_CHAINS
from .schema import ScenarioError

MAX_HOT_PIXEL_RATE_HZ = 1e6
"""The engine's largest hot-pixel rate [Hz] (``Sensor::set_hot_pixel_rates``)."""


HOT_PIXEL_CHAIN_KEYS = tuple(f.name for f in dataclasses.fields(HotPixelChain))
"""The keys of a ``[hot_pixels] pixels`` table entry that give the pixel a chain of its own."""


def _hot_pixel_map(table: dict[str, Any] | None, width: int, height: int,
                   params: PixelParams) -> tuple[np.ndarray | None, dict[tuple[int, int], HotPixelChain]]:
    """[hot_pixels] as a (height, width) array of rates [Hz] (None: no map, the draw applies)
    and the listed pixels' own chains. A file's map comes first; listed pixels are set over it."""
    if not table:
        return None, {}
    rates = np.zeros((height, width))
    if "file" in table:
        path = table["file"]
        try:
            loaded = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as exc:
            raise ScenarioError(f"hot_pixels.file={path!r} cannot be read as a .npy array: {exc}") from None
        if not isinstance(loaded, np.ndarray) or loaded.shape != (height, width) or loaded.dtype.kind not in "iuf":
            raise ScenarioError(f"hot_pixels.file={path!r} must hold a ({height}, {width}) array of rates [Hz] (the "
                                f"sensor's height, width); got {getattr(loaded, 'dtype', '?')} {getattr(loaded, 'shape', '?')}")
        bad = ~((loaded >= 0) & (loaded <= MAX_HOT_PIXEL_RATE_HZ))
        if bad.any():
            y, x = (int(v) for v in np.argwhere(bad)[0])
            raise ScenarioError(f"hot_pixels.file={path!r}: rates must be in [0, {MAX_HOT_PIXEL_RATE_HZ:g}] Hz; got "
                                f"{loaded[y, x]!r} at (x, y)=({x}, {y})")
        rates[:] = loaded
    pixels = table.get("pixels", [])
    if not isinstance(pixels, list):
        raise ScenarioError(f"hot_pixels.pixels must be an array of [x, y, rate_hz] or {{x, y, rate_hz, ...}}; got "
                            f"{pixels!r}")
    chains: dict[tuple[int, int], HotPixelChain] = {}
    listed: dict[tuple[int, int], int] = {}
    for i, entry in enumerate(pixels):
        key = f"hot_pixels.pixels[{i}]"
        x, y, r, own = _hot_pixel_entry(key, entry)
        if not (0 <= x < width and 0 <= y < height):
            raise ScenarioError(f"{key}={entry!r} lies off the {width}x{height} sensor")
        if (x, y) in listed:
            raise ScenarioError(f"{key}: pixel (x, y) = ({x}, {y}) is listed twice, also as "
                                f"hot_pixels.pixels[{listed[(x, y)]}]")
        listed[(x, y)] = i
        if not 0.0 <= r <= MAX_HOT_PIXEL_RATE_HZ:
            raise ScenarioError(f"{key}: rate_hz must be in [0, {MAX_HOT_PIXEL_RATE_HZ:g}]; got {entry!r}")
        rates[y, x] = r
        if own:
            base = HotPixelChain.of(params)
            fields = {name: float(own.get(name, getattr(base, name))) for name in HOT_PIXEL_CHAIN_KEYS}
            if "on_share" in own and "alternation" not in own:
                # A share of its own with the params' alternation would be a chain of another
                # pixel's memory (or no chain at all: 0.78 is out of reach at a share of 0.98).
                fields["alternation"] = 2.0 * fields["on_share"] * (1.0 - fields["on_share"])
            try:
                _core.validate_hot_pixel_chain(fields["duty"], fields["burst_s"], fields["on_share"],
                                               fields["alternation"], f"{key}.")
            except ValueError as exc:
                inherited = [f"{name} from pixel.hot_pixel_{name}" for name in HOT_PIXEL_CHAIN_KEYS
                             if name not in own and not (name == "alternation" and "on_share" in own)]
                raise ScenarioError(str(exc) + (f" ({', '.join(inherited)})" if inherited else "")) from None
            chains[(x, y)] = HotPixelChain(**fields)
    if len(chains) > MAX_HOT_PIXEL_CHAINS:
        raise ScenarioError(f"hot_pixels.pixels: at most {MAX_HOT_PIXEL_CHAINS} pixels may have a chain of their own; "
                            f"got {len(chains)}")
    return rates, chains


def _hot_pixel_entry(key: str, entry: Any) -> tuple[int, int, float, dict[str, float]]:
    """One ``[hot_pixels] pixels`` entry as (x, y, rate_hz, its own chain's keys)."""
    def number(v: Any) -> bool:
        return isinstance(v, (int, float)) and not isinstance(v, bool)

    if isinstance(entry, dict):
        known = ("x", "y", "rate_hz", *HOT_PIXEL_CHAIN_KEYS)
        unknown = sorted(set(entry) - set(known))
        if unknown:
            raise ScenarioError(f"{key} has unknown key(s) {unknown}; known: {list(known)}")
        missing = [k for k in ("x", "y", "rate_hz") if k not in entry]
        if missing:
            raise ScenarioError(f"{key} must give x, y and rate_hz; {', '.join(missing)} missing in {entry!r}")
        for name, value in entry.items():
            if not number(value) or (name in ("x", "y") and isinstance(value, float) and not value.is_integer()):
                what = "a whole pixel coordinate" if name in ("x", "y") else "a number"
                raise ScenarioError(f"{key}.{name} must be {what}; got {name}={value!r}")
        own = {k: float(v) for k, v in entry.items() if k in HOT_PIXEL_CHAIN_KEYS}
        return int(entry["x"]), int(entry["y"]), float(entry["rate_hz"]), own
    ok = isinstance(entry, list) and len(entry) == 3 and all(number(v) for v in entry)
    if not ok or any(isinstance(v, float) and not v.is_integer() for v in entry[:2]):
        raise ScenarioError(f"{key} must be [x, y, rate_hz] (whole pixel coordinates and a rate in Hz) or a table "
                            f"{{x, y, rate_hz, duty, burst_s, on_share, alternation}}; got {entry!r}")
    return int(entry[0]), int(entry[1]), float(entry[2]), {}
