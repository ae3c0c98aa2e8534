"""What :func:`evstwin.tune.fit` returns: its trials and result, and the files it writes."""

from __future__ import annotations

import csv
import dataclasses
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ._types import PathLike
from .bounds import ParamBound
from .execution import JobFailure
from .sweep import _atomic_write_text, _fmt_value, _jsonable

if TYPE_CHECKING:
    from .identify import Identifiability
    from .options import FitOptions


@dataclass
class TrialRecord:
    """One trial of a fit: its number, parameter values, mean distance over the runs (nan
    if failed), each run's distance, and the error of a failed trial."""

    trial: int
    params: dict[str, float]
    distance: float
    run_distances: list[float]
    error: str = ""
    phase: str = ""
    """Which search proposed the trial: tpe, random, cmaes, nm or ls."""


@dataclass
class FitResult:
    """Result of :func:`fit`. ``best_scenario`` is the input scenario with the best values
    set (and the real recording's duration, the first fit seed): what ``best.toml`` holds."""

    best_params: dict[str, float]
    best_distance: float
    history: list[TrialRecord]
    params: list[str]
    bounds: dict[str, ParamBound]
    scenario: dict[str, Any]
    best_scenario: dict[str, Any]
    budget: int
    runs_per_trial: int
    seed: int
    sim_seeds: list[int]
    sampler: str
    batch_size: int
    duration_s: float
    real_events: np.ndarray = field(repr=False)
    real_meta: dict[str, Any] = field(repr=False)
    executor: str = ""
    elapsed_s: float = 0.0
    failed: list[JobFailure] = field(default_factory=list)
    roi: tuple[int, int, int, int] | None = None
    """The compared rectangle (x0, y0, w, h) of the sensor; None: the whole sensor."""
    mask: np.ndarray | None = field(default=None, repr=False)
    """The (h, w) pixels of the compared region left out (listed and hot); None: none."""
    distance: str = "compare"
    """The distance minimised: 'compare' (:func:`evstwin.validation.compare`'s, mean over the
    seeds) or 'chi2' (:mod:`evstwin.tune.counts`, from the mean of the seeds' statistics)."""
    intervals: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Each parameter's interval (``intervals=True``; see :func:`fit`): with the chi-square, the
    best +- one standard error of the least-squares estimate; with compare's distance, the
    values that raise the mean distance by its own seed-to-seed standard error. Empty when not
    asked for."""
    options: FitOptions | None = field(default=None, repr=False)
    """The options the fit ran with."""
    stop_reason: str = ""
    """Why the search ended: one of :data:`evstwin.tune.search.STOP_REASONS` ('budget',
    'converged', 'stalled')."""
    stop_detail: str = ""
    """The same in words, with the trials used."""
    identifiability: Identifiability | None = field(default=None, repr=False)
    """What the statistics can and cannot separate (:mod:`evstwin.tune.identify`), from the
    least squares' Jacobian; None for the other searches."""
    interval_kind: str = ""
    """Where ``intervals`` come from: 'calibrated' (``FitOptions.intervals``:
    :mod:`evstwin.tune.intervals`), 'report' (+- the identifiability report's standard error,
    the default with the least squares) or '' (none)."""

    @property
    def best_trial(self) -> int:
        finite = [r for r in self.history if math.isfinite(r.distance)]
        return min(finite, key=lambda r: (r.distance, r.trial)).trial if finite else -1

    def to_text(self) -> str:
        """The best parameters and distance as a table, for a terminal."""
        rows = [("parameter", "best", "interval", "low", "high", "scale")]
        for p in self.params:
            b = self.bounds[p]
            iv = self.intervals.get(p)
            rows.append(
                (p, f"{self.best_params[p]:.6g}", f"{iv[0]:.4g}..{iv[1]:.4g}" if iv else "-", f"{b.low:g}",
                 f"{b.high:g}", "log" if b.log else "lin")
            )
        widths = [max(len(r[i]) for r in rows) for i in range(6)]
        lines = [
            "  ".join(c.ljust(w) if i == 0 else c.rjust(w) for i, (c, w) in enumerate(zip(r, widths)))
            for r in rows
        ]
        lines.insert(1, "-" * len(lines[0]))
        n_ok = sum(math.isfinite(r.distance) for r in self.history)
        lines.append(
            f"best distance {self.best_distance:.6g} ({self.distance}; trial {self.best_trial} of {len(self.history)}, "
            f"{n_ok} finished; {self.runs_per_trial} run(s) per trial, seeds {self.sim_seeds}; "
            f"{self.elapsed_s:.1f} s on {self.executor})"
        )
        if self.stop_reason:
            lines.append(f"stopped: {self.stop_reason} ({self.stop_detail})")
        if self.interval_kind:
            lines.append("intervals: " + ("+- one standard error (calibrated: probes and fresh seeds at the best)"
                                          if self.interval_kind == "calibrated" else
                                          "+- one standard error from the search's Jacobian (uncalibrated; "
                                          "--intervals for the calibrated ones)"))
        if self.identifiability is not None:
            lines.append(self.identifiability.to_text())
        return "\n".join(lines)

    def to_json_dict(self) -> dict[str, Any]:
        from ..validation import DISTANCE_FORMULA
        from .counts import CHI2_FORMULA
        from .timing import TIMING_FORMULA

        statistics = None if self.options is None or self.distance != "chi2" else self.options.statistics

        return _jsonable(
            {
                "best_params": self.best_params,
                "best_distance": self.best_distance,
                "intervals": {k: list(v) for k, v in self.intervals.items()},
                "best_trial": self.best_trial,
                "params": self.params,
                "bounds": {
                    k: {"low": b.low, "high": b.high, "log": b.log, "why": b.why}
                    for k, b in self.bounds.items()
                },
                "budget": self.budget,
                "trials": len(self.history),
                "runs_per_trial": self.runs_per_trial,
                "seed": self.seed,
                "sim_seeds": self.sim_seeds,
                "sampler": self.sampler,
                "batch_size": self.batch_size,
                "duration_s": self.duration_s,
                "real": str(self.real_meta.get("path", "")),
                "executor": self.executor,
                "elapsed_s": self.elapsed_s,
                "distance": self.distance,
                "stop": {"reason": self.stop_reason, "detail": self.stop_detail},
                "interval_kind": self.interval_kind,
                "identifiability": None if self.identifiability is None else self.identifiability.to_json_dict(),
                "statistics": statistics,
                "distance_formula": (DISTANCE_FORMULA if self.distance != "chi2" else CHI2_FORMULA if statistics != "timing"
                                     else f"{CHI2_FORMULA}; {TIMING_FORMULA}"),
                "roi": list(self.roi) if self.roi is not None else None,
                "masked_pixels": (
                    [] if self.mask is None
                    else [[int(x) + (self.roi[0] if self.roi else 0), int(y) + (self.roi[1] if self.roi else 0)]
                          for y, x in np.argwhere(self.mask)]
                ),
                "failed": [dataclasses.asdict(f) for f in self.failed],
            }
        )

    def write(self, out_dir: PathLike) -> dict[str, Path]:
        """Write the data of the fit: ``best.toml`` (runnable by ``evstwin simulate``),
        ``history.csv`` and ``fit.json``. Returns {name: path}. The figures (convergence and
        the comparison of the best fit) are :func:`evstwin.tune.figures.draw_fit`'s."""
        from ..scenario import to_toml

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        paths: dict[str, Path] = {}
        paths["best_toml"] = out / "best.toml"
        _atomic_write_text(paths["best_toml"], to_toml(self.best_scenario))
        paths["history"] = out / "history.csv"
        with open(paths["history"], "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(
                [
                    "trial",
                    "phase",
                    "distance",
                    *self.params,
                    *[f"distance_seed{s}" for s in self.sim_seeds],
                    "error",
                ]
            )
            for r in self.history:
                run_d = r.run_distances + [math.nan] * (len(self.sim_seeds) - len(r.run_distances))
                w.writerow(
                    [
                        r.trial,
                        r.phase,
                        _fmt_value(r.distance),
                        *[_fmt_value(r.params[p]) for p in self.params],
                        *[_fmt_value(d) for d in run_d],
                        r.error,
                    ]
                )
        report = self.to_json_dict()
        report["outputs"] = {k: str(v) for k, v in paths.items()}
        paths["json"] = out / "fit.json"
        _atomic_write_text(paths["json"], json.dumps(report, indent=1, allow_nan=False))
        return paths
