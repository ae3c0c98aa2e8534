"""``sweep``: an objective over a grid of scenario values times seeds, resumable."""

from __future__ import annotations

import contextlib
import csv
import itertools
import math
import os
import sys
import time
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..scenario import build, load, parse_assignment, set_value
from ._types import PathLike, Recording
from .bounds import _check_not_shadowed, canonical_key
from .execution import JobFailure, _bar, _Context, _Job, announce, make_executor
from .objectives import MatchObjective, Objective, make_objective


def _fmt_value(v: Any) -> str:
    """A CSV cell: floats with repr (round-trip exact), bools as true/false."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (np.floating, np.integer)):
        return _fmt_value(v.item())
    return str(v)


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(obj) else None
    if isinstance(obj, np.integer):
        return int(obj)
    return obj


def _atomic_write_text(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


@dataclass
class SweepResult:
    """Result of :func:`sweep`: one row per finished (point, seed), sorted by point then
    seed, with ``point`` (index in the grid's product order), every grid value, ``seed`` and
    the objective's metrics; ``summary`` has one row per point (``runs``, ``mean_<metric>``,
    ``std_<metric>``: sample std, nan for one run). ``failed`` lists jobs that failed every
    attempt (not in ``rows``; rerun with ``resume=True``)."""

    grid: dict[str, list[Any]]
    objective: str
    metrics: tuple[str, ...]
    headline: tuple[str, ...]
    runs: int
    seeds: list[int]
    rows: list[dict[str, Any]]
    summary: list[dict[str, Any]]
    failed: list[JobFailure] = field(default_factory=list)
    resumed: int = 0
    csv_path: Path | None = None
    summary_path: Path | None = None
    figure_path: Path | None = None
    """Set by :func:`evstwin.tune.figures.draw_sweep` once it has drawn ``sweep.png``."""
    executor: str = ""
    elapsed_s: float = 0.0

    @property
    def complete(self) -> bool:
        return not self.failed and len(self.rows) == len(self.summary) * self.runs

    def to_text(self, max_rows: int = 50) -> str:
        """The summary (mean +- std of the headline metrics per point) as a table."""
        keys = list(self.grid)
        head = [*(_short(k) for k in keys), "runs", *self.headline]
        body = []
        for row in self.summary[:max_rows]:
            cells = [_fmt_short(row[k]) for k in keys] + [str(row["runs"])]
            for m in self.headline:
                mean, std = row[f"mean_{m}"], row[f"std_{m}"]
                cells.append(_fmt_num(mean) + ("" if not math.isfinite(std) else f" +- {_fmt_num(std)}"))
            body.append(cells)
        widths = [max(len(x) for x in col) for col in zip(head, *body)] if body else [len(h) for h in head]
        lines = ["  ".join(c.rjust(w) for c, w in zip(r, widths)) for r in [head] + body]
        lines.insert(1, "-" * len(lines[0]))
        if len(self.summary) > max_rows:
            lines.append(f"... {len(self.summary) - max_rows} more points in the summary CSV")
        lines.append(
            f"{len(self.rows)} rows ({self.resumed} resumed) over {len(self.summary)} points x "
            f"{self.runs} seed(s); objective {self.objective}; {self.elapsed_s:.1f} s on {self.executor}"
        )
        for f in self.failed:
            lines.append(f"FAILED point {f.key} seed {f.seed} after {f.attempts} attempts: {f.error}")
        return "\n".join(lines)


def _short(key: str) -> str:
    return key.split(".", 1)[1] if key.startswith(("pixel.", "biases.")) else key


def _fmt_num(v: float) -> str:
    return "nan" if isinstance(v, float) and math.isnan(v) else f"{v:.4g}"


def _fmt_short(v: Any) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _grid_points(grid: Mapping[str, Sequence[Any]]) -> tuple[dict[str, list[Any]], list[tuple[Any, ...]]]:
    if not grid:
        raise ValueError("grid: give at least one parameter with values (--grid name=v1,v2)")
    canon: dict[str, list[Any]] = {}
    for name, values in grid.items():
        key = canonical_key(name)
        if key in canon:
            raise ValueError(f"grid: parameter {key} given twice")
        vals = list(values) if not isinstance(values, (str, bytes)) else [values]
        if not vals:
            raise ValueError(f"grid: {name} has no values")
        if len({_fmt_value(v) for v in vals}) != len(vals):
            raise ValueError(f"grid: {name} has repeated values {vals}")
        canon[key] = vals
    return canon, list(itertools.product(*canon.values()))


def _summarise(
    grid: Mapping[str, list[Any]],
    points: Sequence[tuple[Any, ...]],
    rows: Sequence[Mapping[str, Any]],
    metrics: Sequence[str],
) -> list[dict[str, Any]]:
    keys = list(grid)
    by_point: dict[int, list[Mapping[str, Any]]] = {}
    for r in rows:
        by_point.setdefault(int(r["point"]), []).append(r)
    out = []
    for i, pt in enumerate(points):
        rs = by_point.get(i, [])
        row: dict[str, Any] = {"point": i, **dict(zip(keys, pt)), "runs": len(rs)}
        for m in metrics:
            v = np.array([float(r[m]) for r in rs], dtype=float)
            with warnings.catch_warnings(), np.errstate(invalid="ignore"):
                warnings.simplefilter("ignore", RuntimeWarning)  # mean of inf - inf, empty points
                row[f"mean_{m}"] = float(np.mean(v)) if v.size else math.nan
                row[f"std_{m}"] = float(np.std(v, ddof=1)) if v.size > 1 else math.nan
        out.append(row)
    return out


def _read_done(
    path: Path, header: list[str], keys: list[str], points: Sequence[tuple[Any, ...]], seeds: Sequence[int]
) -> list[dict[str, Any]]:
    """Rows of an existing sweep CSV that belong to this grid (same header)."""
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        try:
            found = next(reader)
        except StopIteration:
            return []
        if found != header:
            raise ValueError(
                f"--resume: {path} has columns {found}, this sweep writes {header}: "
                "a different grid or objective (use another --out)"
            )
        index = {tuple(_fmt_value(v) for v in pt): i for i, pt in enumerate(points)}
        metrics = header[len(keys) + 2 :]
        rows: dict[tuple[int, int], dict[str, Any]] = {}
        for line in reader:
            if len(line) != len(header):
                continue  # a row cut by a kill: its job reruns
            cells = dict(zip(header, line))
            i = index.get(tuple(cells[k] for k in keys))
            try:
                seed = int(cells["seed"])
                values = {m: float(cells[m]) for m in metrics}
            except ValueError:
                continue
            if i is None or seed not in seeds:
                continue
            rows[(i, seed)] = {"point": i, **dict(zip(keys, points[i])), "seed": seed, **values}
    return list(rows.values())


class FitMatchObjective(Objective):
    """``sweep``'s objective 'match': the distance ``fit`` minimises by default, so that a sweep
    and a fit rank the same points the same way. Metrics: ``distance``, the fit's chi-square
    of this seed alone (K = 1; :mod:`evstwin.tune.counts`' counts and
    :mod:`evstwin.tune.timing`'s statistics, the pixel groups of the sweep's scenario);
    ``compare_distance``, :func:`evstwin.validation.compare`'s (the paper's figure of merit);
    and compare's ``total_rel_error``, ``on_off_ratio_rel_error``, ``sim_events``. The region
    (ROI, masks) and the duration are ``match``'s."""

    name = "match"
    metrics: tuple[str, ...] = ("distance", "compare_distance", "total_rel_error", "on_off_ratio_rel_error",
                                "sim_events")
    headline = ("distance",)

    def __init__(self, match: MatchObjective, chi2: Any) -> None:
        self.match = match
        self.chi2 = chi2
        self.duration_s = match.duration_s

    def prepare(self, scenario: dict[str, Any]) -> dict[str, Any]:
        return self.match.prepare(scenario)

    def check(self, scene: Any) -> None:
        self.match.check(scene)

    def evaluate(self, result: Any) -> dict[str, float]:
        from .counts import chi2_distance

        m = self.match.evaluate(result)
        stats = self.chi2.statistics(result.events)
        return {
            "distance": chi2_distance(self.chi2.real_stats, [stats]),
            "compare_distance": m["distance"],
            "total_rel_error": m["total_rel_error"],
            "on_off_ratio_rel_error": m["on_off_ratio_rel_error"],
            "sim_events": m["sim_events"],
        }


def sweep(
    scenario: str | Path | dict,
    grid: Mapping[str, Sequence[Any]],
    objective: str | Objective = "detect",
    runs: int = 1,
    out_dir: PathLike | None = None,
    resume: bool = False,
    scheduler: Any = None,
    workers: int | None = None,
    real: Recording | PathLike | None = None,
    target: str | None = None,
    duration_s: float | None = None,
    seed: int = 0,
    sets: Sequence[str] = (),
    progress: bool = False,
    roi: Any = None,
    mask_pixels: Sequence[tuple[int, int]] = (),
    mask_hot: bool = False,
    job_seconds: float | None = None,
) -> SweepResult:
    """Evaluate every combination of ``grid`` over ``runs`` seeds (``seed .. seed+runs-1``).

    grid: {scenario key: [values]} (keys as in ``--set``; bare PixelParams fields mean
        ``pixel.<name>``, bare bias currents ``biases.<name>``); points in product order,
        the first key varying slowest.
    objective: 'match' (needs ``real``: events and meta, or a file; scored by
        :class:`FitMatchObjective`: the fit's default distance, and compare's), 'detect'
        (``target``: a moving target's label, default the first), 'noise', or an
        :class:`Objective`.
    duration_s: simulated duration [s] (default the scenario's; for 'match' the real one).
    sets: extra ``key=value`` overrides of the scenario.
    roi, mask_pixels, mask_hot: for 'match', the region compared (see :class:`MatchObjective`):
        ``(x0, y0, w, h)`` of the sensor, simulated alone; pixels left out.
    out_dir: where ``sweep.csv`` (rows, appended and flushed as each job finishes, rewritten
        sorted at the end), ``sweep_summary.csv`` and ``sweep.png`` go; an existing
        ``sweep.csv`` is an error unless ``resume``, which keeps its rows for this grid and runs
        only the missing (point, seed) jobs. None: nothing written.
    job_seconds: one job's wall time measured by the caller, for the estimate printed with
        ``progress`` (None: the rough pixel-update figure).
    """
    t0 = time.perf_counter()
    if isinstance(runs, bool) or not isinstance(runs, int) or runs < 1:
        raise ValueError(f"runs must be an integer >= 1; got {runs!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed must be an integer >= 0; got {seed!r}")
    obj = make_objective(objective, real=real, target=target, roi=roi, mask_pixels=mask_pixels, mask_hot=mask_hot)
    base = load(scenario)
    for text in sets:
        k, v = parse_assignment(text)
        base = set_value(base, k, v)
    if duration_s is not None:
        if isinstance(obj, MatchObjective):
            raise ValueError("duration: objective 'match' simulates the real recording's duration")
        base = set_value(base, "duration_s", float(duration_s))
    canon, points = _grid_points(grid)
    keys = list(canon)
    _check_not_shadowed(base, keys, "grid parameter")
    for pt in points:  # every point must be a valid scenario (fail now, not in a worker)
        s = base
        for k, v in zip(keys, pt):
            s = set_value(s, k, v)
        obj.check(build(obj.prepare(s)))
    if isinstance(obj, MatchObjective):
        w, h = build(base).width, build(base).height
        if (w, h) != (obj.sensor_width, obj.sensor_height):
            raise ValueError(
                f"scenario sensor is {w}x{h} px but the real recording is {obj.sensor_width}x{obj.sensor_height}: "
                "set sensor.width / sensor.height"
            )
        if objective == "match" and real is not None:  # by name: the fit's distance beside compare's
            from .objectives import _read_real
            from .timing import TimingObjective

            events, meta = _read_real(real)
            obj = FitMatchObjective(obj, TimingObjective(events, meta, base, roi=roi, mask_pixels=mask_pixels,
                                                         mask_hot=mask_hot))
    seeds = [seed + k for k in range(runs)]
    header = ["point", *keys, "seed", *obj.metrics]
    csv_path = summary_path = None
    done: list[dict[str, Any]] = []
    out: Path | None = None
    if out_dir is not None:
        out = Path(out_dir)
        csv_path = out / "sweep.csv"
        summary_path = out / "sweep_summary.csv"
        if csv_path.exists():
            if not resume:
                raise FileExistsError(
                    f"{csv_path} exists: pass --resume to continue it, or choose another --out"
                )
            done = _read_done(csv_path, header, keys, points, seeds)
        out.mkdir(parents=True, exist_ok=True)
    finished = {(int(r["point"]), int(r["seed"])) for r in done}
    jobs = [
        _Job(i, dict(zip(keys, pt)), s)
        for i, pt in enumerate(points)
        for s in seeds
        if (i, s) not in finished
    ]
    rows = list(done)
    failed: list[JobFailure] = []
    ctx = _Context(scenario=base, objective=obj)
    executor = make_executor(scheduler, workers) if jobs else None
    if progress and jobs:
        print(announce(f"sweep ({obj.name})", len(jobs), build(obj.prepare(base), duration_s=obj.duration_s), executor,
                       job_seconds),
              file=sys.stderr)
    bar = _bar(len(points) * runs, f"sweep ({obj.name})", progress, initial=len(done))
    try:
        with contextlib.ExitStack() as stack:
            writer = None
            if csv_path is not None:
                # A clean start: the header and the kept rows (drops a row cut by a kill).
                _atomic_write_text(csv_path, _csv_text(header, sorted(done, key=_row_order)))
                fh = stack.enter_context(open(csv_path, "a", newline="", encoding="utf-8"))
                writer = csv.writer(fh, lineterminator="\n")
            for job, res in executor.run(ctx, jobs) if executor is not None else iter(()):
                if isinstance(res, JobFailure):
                    failed.append(res)
                else:
                    i = int(job.key)  # type: ignore[call-overload]
                    row = {"point": i, **dict(zip(keys, points[i])), "seed": job.seed, **res}
                    rows.append(row)
                    if writer is not None:
                        writer.writerow([_fmt_value(row[c]) for c in header])
                        fh.flush()  # a finished job survives Ctrl-C or a kill
                if bar is not None:
                    bar.update(1)
        description = executor.description if executor is not None else "nothing to run"
    finally:
        if bar is not None:
            bar.close()
        if executor is not None:
            executor.close()
    rows.sort(key=_row_order)
    summary = _summarise(canon, points, rows, obj.metrics)
    result = SweepResult(
        grid=canon,
        objective=obj.name,
        metrics=tuple(obj.metrics),
        headline=tuple(obj.headline),
        runs=runs,
        seeds=seeds,
        rows=rows,
        summary=summary,
        failed=failed,
        resumed=len(done),
        executor=description,
    )
    if out is not None and csv_path is not None and summary_path is not None:
        _atomic_write_text(csv_path, _csv_text(header, rows))
        sum_header = ["point", *keys, "runs"] + [f"{s}_{m}" for m in obj.metrics for s in ("mean", "std")]
        _atomic_write_text(summary_path, _csv_text(sum_header, summary))
        result.csv_path, result.summary_path = csv_path, summary_path
    result.elapsed_s = time.perf_counter() - t0
    return result


def _row_order(row: Mapping[str, Any]) -> tuple[int, int]:
    return int(row["point"]), int(row["seed"])


def _csv_text(header: Sequence[str], rows: Sequence[Mapping[str, Any]]) -> str:
    import io

    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    for r in rows:
        w.writerow([_fmt_value(r[c]) for c in header])
    return buf.getvalue()


def parse_grid(items: Sequence[str]) -> dict[str, list[Any]]:
    """``['pixel.theta_on=0.15,0.3', ...]`` -> {key: values}; values read as TOML (numbers,
    booleans, quoted strings) else bare strings, like ``--set``."""
    grid: dict[str, list[Any]] = {}
    for item in items:
        if "=" not in item:
            raise ValueError(f"--grid takes name=v1,v2,... (e.g. pixel.theta_on=0.15,0.3); got {item!r}")
        name, _, values = item.partition("=")
        key = canonical_key(name)
        if key in grid:
            raise ValueError(f"--grid {key} given twice")
        vals = [parse_assignment(f"{key}={v}")[1] for v in values.split(",") if v.strip()]
        if not vals:
            raise ValueError(f"--grid {item!r}: no values")
        grid[key] = vals
    return grid
