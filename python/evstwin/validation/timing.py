"""Event-timing bias: the delay of each event after the true crossing of a source over its pixel."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .. import analysis
from ..analysis import same_value_groups

TruthTrack = Mapping[str, np.ndarray]


def _crossings(
    name_index: int, track: TruthTrack, radius_px: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Closest approaches of one sampled track to every pixel centre within radius_px.

    The track is linear between samples. A pixel's closest approach on a segment is the foot
    of the perpendicular from its centre; it counts when it falls inside the segment
    (0 <= u < 1) and lies within radius_px. Stationary segments have no crossing.
    Returns (x, y, t_s, distance_px, flux_ph_s, speed_px_s, target index, lead_s) arrays;
    lead_s is how long before its closest approach the source came within radius_px of the
    pixel centre (sqrt(radius^2 - distance^2) / speed).
    """
    t = np.asarray(track["t_s"], dtype=np.float64)
    xs = np.asarray(track["x_px"], dtype=np.float64)
    ys = np.asarray(track["y_px"], dtype=np.float64)
    flux = np.broadcast_to(np.asarray(track["flux_ph_s"], dtype=np.float64), t.shape)
    if not (t.shape == xs.shape == ys.shape) or t.ndim != 1:
        raise ValueError(
            f"truth arrays t_s, x_px, y_px must be 1-D of one length; got {t.shape}, {xs.shape}, {ys.shape}"
        )
    if t.size >= 2 and np.any(np.diff(t) < 0):
        raise ValueError("truth t_s must be increasing")
    x0, x1, y0, y1 = xs[:-1], xs[1:], ys[:-1], ys[1:]
    dt = np.diff(t)
    dx, dy = x1 - x0, y1 - y0
    len2 = dx * dx + dy * dy
    seg = np.nonzero((len2 > 0) & (dt > 0))[0]
    empty = np.zeros(0)
    if seg.size == 0:
        return (empty.astype(np.int64),) * 2 + (empty,) * 4 + (empty.astype(np.int64), empty)  # type: ignore[return-value]
    xmin = np.floor(np.minimum(x0, x1)[seg] - radius_px).astype(np.int64)
    xmax = np.ceil(np.maximum(x0, x1)[seg] + radius_px).astype(np.int64)
    ymin = np.floor(np.minimum(y0, y1)[seg] - radius_px).astype(np.int64)
    ymax = np.ceil(np.maximum(y0, y1)[seg] + radius_px).astype(np.int64)
    nx, ny = xmax - xmin + 1, ymax - ymin + 1
    n = nx * ny
    owner = np.repeat(np.arange(seg.size), n)
    local = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
    px = xmin[owner] + local % nx[owner]
    py = ymin[owner] + local // nx[owner]
    s = seg[owner]
    u = ((px - x0[s]) * dx[s] + (py - y0[s]) * dy[s]) / len2[s]
    cx, cy = x0[s] + u * dx[s], y0[s] + u * dy[s]
    dist = np.hypot(px - cx, py - cy)
    keep = (u >= 0) & (u < 1) & (dist <= radius_px) & (px >= 0) & (py >= 0)
    s, u, px, py, dist = s[keep], u[keep], px[keep], py[keep], dist[keep]
    tc = t[s] + u * dt[s]
    fc = flux[s] + u * (flux[s + 1] - flux[s])
    speed = np.sqrt(len2[s]) / dt[s]
    lead = np.sqrt(np.maximum(radius_px * radius_px - dist * dist, 0.0)) / speed
    return px, py, tc, dist, fc, speed, np.full(px.size, name_index, dtype=np.int64), lead


TIMING_DTYPE_FIELDS = [("t_us", "<i8"), ("x", "<u2"), ("y", "<u2"), ("p", "u1"), ("t_true_s", "<f8"),
                      ("delay_s", "<f8"), ("distance_px", "<f8"), ("flux_ph_s", "<f8"), ("speed_px_s", "<f8")]


def timing_bias(
    events: np.ndarray,
    truth: Mapping[str, TruthTrack],
    radius_px: float = 1.0,
    max_delay_s: float | None = 0.3,
) -> np.ndarray:
    """Delay of each event after the crossing of a source over its pixel that caused it:
    the table of :func:`timing_attribution` (its counts dropped)."""
    return timing_attribution(events, truth, radius_px, max_delay_s)[0]


def timing_attribution(
    events: np.ndarray,
    truth: Mapping[str, TruthTrack],
    radius_px: float = 1.0,
    max_delay_s: float | None = 0.3,
) -> tuple[np.ndarray, dict[str, int]]:
    """Delay of each event after the crossing of a source over its pixel that caused it, and
    how many events no crossing explains.

    truth: target name -> {'t_s', 'x_px', 'y_px', 'flux_ph_s'}: the sampled track [s, px] of
        the source centre (pixel (x, y) covers [x - 0.5, x + 0.5] x [y - 0.5, y + 0.5], its
        centre at integer coordinates) and its photon flux [photons/s] (scalar or per
        sample). The track is linear between samples.
    radius_px: a source crosses a pixel when its track passes within this distance of the
        pixel centre [px] (default 1 px); it lights the pixel from when it comes that close.
    max_delay_s: the longest delay after the closest approach attributed to a crossing [s]
        (default 0.3 s; None: until the pixel's next crossing).

    A crossing's time is when the interpolated track passes closest to the pixel centre. An
    event is caused by the pixel's latest crossing whose source had come within
    ``radius_px`` of the pixel centre by the event's time (any target): causes come first, so
    an event is never given to a later pass, and its delay (event time - crossing time [s])
    is at least minus the time the source takes from that radius to its closest approach.
    An event more than ``max_delay_s`` after that crossing, or before any, is unexplained;
    so is an event on a pixel no moving source crossed. Since a later crossing takes over
    from the time its source comes close, the table stops changing once ``max_delay_s``
    covers the slowest response (or the time between passes, whichever is shorter).

    Returns (table, counts). The table has one row per attributed event, sorted by event
    time: target (name), t_us, x, y, p (the event), t_true_s, delay_s, distance_px (closest
    approach), flux_ph_s and speed_px_s (of the source at the crossing). counts: 'events'
    (all), 'attributed', 'unexplained' (on a crossed pixel, but before its first crossing
    or more than ``max_delay_s`` after one) and 'off_track' (on pixels no source crossed).
    """
    events = analysis._check_events(events)
    names = list(truth.keys())
    parts = [_crossings(i, truth[n], float(radius_px)) for i, n in enumerate(names)]
    name_len = max([len(str(n)) for n in names] + [1])
    dtype = np.dtype([("target", f"U{name_len}"), *TIMING_DTYPE_FIELDS])
    counts = {"events": int(events.size), "attributed": 0, "unexplained": 0, "off_track": int(events.size)}
    if not parts or events.size == 0:
        return np.zeros(0, dtype=dtype), counts
    cx, cy, ct, cd, cf, cs, ci, cl = (np.concatenate([p[j] for p in parts]) for j in range(8))
    if ct.size == 0:
        return np.zeros(0, dtype=dtype), counts
    ex = events["x"].astype(np.int64)
    ey = events["y"].astype(np.int64)
    et_s = events["t"].astype(np.int64) * 1e-6
    width = int(max(cx.max(), ex.max())) + 1
    ckey = cy * width + cx
    ekey = ey * width + ex
    # One sorted int64 key per (pixel, time [us]) of each crossing's start (its source within
    # radius_px of the pixel centre), so that searchsorted finds, for each event, the latest
    # crossing of its pixel that had started by then.
    t_start = ct - cl
    t0 = min(float(t_start.min()), float(et_s.min()))
    cs_us = np.floor((t_start - t0) * 1e6).astype(np.int64)
    et_us = np.floor((et_s - t0) * 1e6).astype(np.int64)
    span = int(max(cs_us.max(), et_us.max())) + 2
    if int(max(ckey.max(), ekey.max())) + 1 > (2**62) // span:
        raise ValueError("time span x sensor size too large for the crossing index")
    ccomp = ckey * span + cs_us
    order = np.argsort(ccomp, kind="stable")
    ccomp_sorted, ckey_sorted = ccomp[order], ckey[order]
    before = np.searchsorted(ccomp_sorted, ekey * span + et_us, side="right") - 1
    nc = ccomp_sorted.size
    crossed_pixels = np.unique(ckey)
    on_track = np.isin(ekey, crossed_pixels)
    has = (before >= 0) & (ckey_sorted[np.clip(before, 0, nc - 1)] == ekey)
    c_all = order[np.clip(before, 0, nc - 1)]
    delay_all = et_s - ct[c_all]
    ok = has & (delay_all >= -cl[c_all] - 1e-6)  # started, to the microsecond of the key
    if max_delay_s is not None:
        ok &= delay_all <= max_delay_s
    ev = np.nonzero(ok)[0]
    c = c_all[ev]
    out = np.zeros(ev.size, dtype=dtype)
    out["target"] = np.asarray(names, dtype=object)[ci[c]].astype(str) if ev.size else []
    out["t_us"] = events["t"][ev]
    out["x"] = events["x"][ev]
    out["y"] = events["y"][ev]
    out["p"] = events["p"][ev]
    out["t_true_s"] = ct[c]
    out["delay_s"] = delay_all[ev]
    out["distance_px"] = cd[c]
    out["flux_ph_s"] = cf[c]
    out["speed_px_s"] = cs[c]
    counts.update(attributed=int(ev.size), unexplained=int(on_track.sum()) - int(ev.size),
                  off_track=int((~on_track).sum()))
    return out, counts


def format_unexplained(counts: Mapping[str, int], max_delay_s: float | None) -> str:
    """One line: how many events a crossing explains, and how many it does not (count and
    share of the events on crossed pixels)."""
    on_track = counts["attributed"] + counts["unexplained"]
    share = counts["unexplained"] / on_track if on_track else 0.0
    window = "" if max_delay_s is None else f" or over {max_delay_s:g} s after one"
    return (f"{counts['attributed']} events attributed to a crossing; {counts['unexplained']} "
            f"({100 * share:.1f} % of the {on_track} on crossed pixels) unexplained: before the "
            f"pixel's first crossing{window}; {counts['off_track']} on pixels no source crossed")


def _bin_edges(values: np.ndarray, bins: int | Sequence[float] | np.ndarray, log: bool) -> np.ndarray:
    if np.ndim(bins) == 1:
        return np.asarray(bins, dtype=np.float64)
    n = int(bins)  # type: ignore[arg-type]
    lo, hi = float(values.min()), float(values.max())
    if log and lo > 0:
        if hi == lo:
            return np.array([lo / 1.001, hi * 1.001])
        return np.geomspace(lo, hi, n + 1)
    if hi == lo:
        return np.array([lo - 0.5, hi + 0.5])
    return np.linspace(lo, hi, n + 1)




def timing_bias_summary(
    table: np.ndarray,
    by: str = "target",
    bins: int | Sequence[float] | np.ndarray = 5,
    percentiles: Sequence[float] = (5, 25, 50, 75, 95),
    split_polarity: bool = False,
) -> list[dict[str, Any]]:
    """Delay statistics per group of a :func:`timing_bias` table.

    by: 'target' (one group per name), 'polarity' (ON, OFF), 'flux' (``bins`` log-spaced
        flux bins [photons/s] between the smallest and largest, or explicit edges) or 'speed'
        (``bins`` linear speed bins [px/s], or edges). Bins are [lo, hi), the last [lo, hi];
        a flux or speed taking no more than ``bins`` values (values within
        :data:`~evstwin.analysis.SAME_VALUE_TOLERANCE` of each other are one) has one group per value, named by
        its median (a single speed is one row, not a 7.883..7.883 bin).
    split_polarity: one row per group and polarity (key ``polarity``, 'ON'/'OFF'): ON and OFF
        delays differ by an order of magnitude in the dark, and a median of both describes
        neither.
    Returns one dict per non-empty group: group (name, value or [lo, hi]), n, mean_s, std_s
    and p<q>_s for each percentile q (delays in seconds; the median is p50_s).
    """
    if by not in ("target", "polarity", "flux", "speed"):
        raise ValueError(f"by must be 'target', 'polarity', 'flux' or 'speed'; got {by!r}")
    delay = np.asarray(table["delay_s"], dtype=np.float64)
    groups: list[tuple[Any, np.ndarray]] = []
    if delay.size == 0:
        return []
    if by == "target":
        names, inv = np.unique(table["target"], return_inverse=True)
        groups = [(str(n), inv == i) for i, n in enumerate(names)]
    elif by == "polarity":
        groups = [("ON", table["p"] != 0), ("OFF", table["p"] == 0)]
    else:
        col = "flux_ph_s" if by == "flux" else "speed_px_s"
        vals = np.asarray(table[col], dtype=np.float64)
        distinct, inverse = np.unique(vals, return_inverse=True)
        which = same_value_groups(distinct)[inverse]
        n_groups = int(which.max()) + 1 if which.size else 0
        # A few values (at most ``bins``, those within SAME_VALUE_TOLERANCE one): one group each.
        if np.ndim(bins) == 0 and n_groups <= int(bins):  # type: ignore[arg-type]
            groups = [(float(np.median(vals[which == i])), which == i) for i in range(n_groups)]
        else:
            edges = _bin_edges(vals, bins, log=(by == "flux"))
            idx = np.searchsorted(edges, vals, side="right") - 1
            idx[vals == edges[-1]] = edges.size - 2
            groups = [([float(edges[i]), float(edges[i + 1])], idx == i) for i in range(edges.size - 1)]
    rows: list[tuple[Any, np.ndarray, str | None]]
    if split_polarity and by != "polarity":
        on = np.asarray(table["p"]) != 0
        rows = [(label, mask & sel, pol) for label, mask in groups for pol, sel in (("ON", on), ("OFF", ~on))]
    else:
        rows = [(label, mask, None) for label, mask in groups]
    out = []
    for label, mask, pol in rows:
        d = delay[mask]
        if d.size == 0:
            continue
        row: dict[str, Any] = {"group": label}
        if pol is not None:
            row["polarity"] = pol
        row |= {
            "n": int(d.size),
            "mean_s": float(d.mean()),
            "std_s": float(d.std(ddof=1)) if d.size > 1 else None,
        }
        for q, v in zip(percentiles, np.percentile(d, list(percentiles))):
            row[f"p{q:g}_s"] = float(v)
        out.append(row)
    return out


def format_timing_bias_summary(rows: Sequence[Mapping[str, Any]], by: str = "target") -> str:
    """A text table of :func:`timing_bias_summary` rows (delays in ms)."""
    if not rows:
        return "no event attributed to a crossing"
    pkeys = [k for k in rows[0] if k.startswith("p") and k.endswith("_s")]
    split = "polarity" in rows[0]
    head = [by] + (["polarity"] if split else []) + ["n", "mean [ms]"] + [k[:-2] + " [ms]" for k in pkeys]
    body = []
    for r in rows:
        g = r["group"]
        if isinstance(g, list):
            gtxt = f"{g[0]:.4g}..{g[1]:.4g}"
        elif isinstance(g, float):
            gtxt = f"{g:.4g}"
        else:
            gtxt = str(g)
        body.append([gtxt] + ([str(r["polarity"])] if split else []) + [str(r["n"]), f"{1e3 * r['mean_s']:.3f}"]
                    + [f"{1e3 * r[k]:.3f}" for k in pkeys])
    widths = [max(len(x) for x in col) for col in zip(head, *body)]
    lines = ["  ".join(c.rjust(w) for c, w in zip(row, widths)) for row in [head] + body]
    return "\n".join(lines)
