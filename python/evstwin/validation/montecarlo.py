"""Mean and spread of every comparison number over N Monte Carlo runs (the paper's 20)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .comparison import Comparison, _jsonable, _label


@dataclass
class MonteCarloSummary:
    """Mean and sample standard deviation (ddof = 1; null for a single run) over ``runs``
    comparisons of every number of :meth:`Comparison.to_json_dict`, in the same layout.

    Histogram-shaped lists of different lengths (runs whose largest count differs) are padded
    with the empty bins they imply (0, and longer ``edges``). Undefined values (null, e.g. the
    percent error of a bin the real recording leaves empty) are left out of a mean; a value
    undefined in every run stays null. Strings equal in every run are kept, others listed.
    """

    runs: int
    mean: dict[str, Any]
    std: dict[str, Any]

    def to_json_dict(self) -> dict[str, Any]:
        return {"runs": self.runs, "mean": self.mean, "std": self.std}

    def to_text(self) -> str:
        """Mean +- std of the headline figures per simulation, for a terminal."""
        lines = [f"Monte Carlo over {self.runs} runs (mean +- sample std)"]
        for m, s in zip(self.mean["sims"], self.std["sims"]):
            path = m["path"] if isinstance(m["path"], str) else ",".join(m["path"])
            lines.append(f"{_label(path)}:")
            for key in (
                "total",
                "on",
                "off",
                "on_off_ratio",
                "total_rel_error",
                "distance",
                "max_bin_error_share",
            ):
                mv, sv = m.get(key), s.get(key)
                lines.append(f"  {key:22s} {_num(mv)} +- {_num(sv)}")
        return "\n".join(lines)


def _num(v: Any) -> str:
    return "n/a" if v is None else f"{v:.6g}"


def _is_num(v: Any) -> bool:
    return v is None or (isinstance(v, (int, float)) and not isinstance(v, bool))


def _mean_std(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Column mean and sample std of a (runs, n) float array, ignoring nan, without warnings."""
    ok = ~np.isnan(rows)
    n = ok.sum(axis=0)
    filled = np.where(ok, rows, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(n > 0, filled.sum(axis=0) / np.maximum(n, 1), np.nan)
        dev = np.where(ok, rows - mean, 0.0)
        var = np.where(n > 1, (dev**2).sum(axis=0) / np.maximum(n - 1, 1), np.nan)
    return mean, np.sqrt(var)


def _aggregate(values: list[Any], where: tuple[str, ...] = ()) -> tuple[Any, Any]:
    key = ".".join(where)
    if all(isinstance(v, dict) for v in values):
        keys = list(values[0].keys())
        if any(list(v.keys()) != keys for v in values):
            raise ValueError(f"runs differ in the layout of {key or 'the result'}")
        pairs = {k: _aggregate([v[k] for v in values], where + (str(k),)) for k in keys}
        return {k: p[0] for k, p in pairs.items()}, {k: p[1] for k, p in pairs.items()}
    if all(isinstance(v, list) for v in values):
        if all(all(_is_num(x) for x in v) for v in values):
            n = max(len(v) for v in values)
            if "edges" in where:
                longest = max(values, key=len)
                return longest, [0.0] * n
            rows = np.zeros((len(values), n))
            for i, v in enumerate(values):
                rows[i, : len(v)] = [np.nan if x is None else x for x in v]
            mean, std = _mean_std(rows)
            return _jsonable(mean), _jsonable(std)
        if all(len(v) == len(values[0]) for v in values):
            pairs_l = [_aggregate([v[i] for v in values], where + (str(i),)) for i in range(len(values[0]))]
            return [p[0] for p in pairs_l], [p[1] for p in pairs_l]
        if any(isinstance(x, (dict, list)) for v in values for x in v):
            raise ValueError(f"runs differ in the number of entries of {key!r}")
    if all(_is_num(v) for v in values):
        rows = np.array([[np.nan if v is None else float(v)] for v in values])
        mean, std = _mean_std(rows)
        return _jsonable(mean[0]), _jsonable(std[0])
    if all(v == values[0] for v in values):
        return values[0], None
    return list(values), None  # e.g. differing paths or adjustments: listed per run


def aggregate(comparisons: Sequence[Comparison]) -> MonteCarloSummary:
    """Mean and spread of every figure over N runs (e.g. N seeds of one scenario).

    Every comparison must have the same simulations in the same order (sim i of every run is
    one scenario) and the same histogram bin width. See :class:`MonteCarloSummary`.
    """
    if len(comparisons) == 0:
        raise ValueError("aggregate needs at least one comparison")
    widths = {c.bin_width for c in comparisons}
    if len(widths) != 1:
        raise ValueError(f"runs use different histogram bin widths {sorted(widths)}")
    units = {c.value_unit for c in comparisons}
    if len(units) != 1:
        raise ValueError(f"runs compare in different units {sorted(units)} (some by rate)")
    counts = {len(c.sims) for c in comparisons}
    if len(counts) != 1:
        raise ValueError(f"runs compare different numbers of simulations {sorted(counts)}")
    trees = [c.to_json_dict() for c in comparisons]
    for t in trees:
        t.pop("outputs", None)
    mean, std = _aggregate(trees)
    return MonteCarloSummary(runs=len(comparisons), mean=mean, std=std)
