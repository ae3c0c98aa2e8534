"""``limiting_magnitude``: the faintest magnitude detected against angular rate."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..scenario import ARCSEC_RAD, build, load, parse_assignment, set_value
from ._types import PathLike
from .objectives import DetectObjective
from .sweep import SweepResult, _atomic_write_text, _csv_text, _fmt_num, sweep

DEFAULT_RATES_ARCSEC_S: tuple[float, ...] = (5.0, 15.04, 50.0, 150.0, 500.0)


"""Angular rates [arcsec/s]: slow drifts, GEO at the sidereal rate, MEO to LEO."""


DEFAULT_MAGNITUDES: tuple[float, ...] = (6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0)


"""Visual magnitudes (V zero point of :mod:`evstwin.optics`)."""


def limiting_magnitude_scenario() -> dict[str, Any]:
    """The default scenario of :func:`limiting_magnitude`: ``geo-stare`` (0.5 m f/4 telescope,
    1.9 arcsec/px, silicon-like photodiode, 20 mag/arcsec^2 sky, its bias set) without the star
    field, on a 128 x 64 px window for 4 s, the satellite starting 4 px from the left edge."""
    s = load("geo-stare")
    s.pop("star_field", None)
    s["name"] = "limiting-magnitude"
    s["description"] = "geo-stare without stars, 128 x 64 px window: a linear mover across it"
    s["duration_s"] = 4.0
    s["sensor"] = dict(s["sensor"], width=128, height=64)
    s["targets"] = [
        {
            "kind": "linear",
            "label": "target",
            "x0_px": 4.0,
            "y0_px": 31.5,
            "wx_arcsec_s": 15.04,
            "wy_arcsec_s": 0.0,
            "magnitude": 8.0,
        }
    ]
    return load(s)


def _as_linear_mover(scenario: dict[str, Any]) -> dict[str, Any]:
    """The scenario with its first target made a linear mover (rate and magnitude set later),
    keeping its start position if it has one, else 4 px from the left edge, mid-height."""
    s = dict(scenario)
    sc = build(s)
    targets = list(s.get("targets", []))
    old = dict(targets[0]) if targets else {}
    new = {
        "kind": "linear",
        "label": str(old.get("label", "target")),
        "x0_px": float(old.get("x0_px", 4.0)),
        "y0_px": float(old.get("y0_px", (sc.height - 1) / 2)),
        "wx_arcsec_s": 15.04,
        "wy_arcsec_s": 0.0,
        "magnitude": float(old.get("magnitude", 8.0)),
    }
    s["targets"] = [new] + targets[1:]
    return load(s)


@dataclass
class LimitingMagnitudeResult:
    """The faintest magnitude meeting the criterion at each angular rate.

    ``table``: one row per rate: rate_arcsec_s, rate_px_s, limiting_magnitude (nan when even
    the brightest magnitude fails), and the criterion metric's mean at the limit. The limit is
    the faintest magnitude reached going from bright to faint before the first that fails
    (a noise-dependent miss does not let a fainter success count)."""

    criterion: tuple[str, float]
    table: list[dict[str, float]]
    sweep: SweepResult
    table_path: Path | None = None
    figure_path: Path | None = None

    def to_text(self) -> str:
        metric, threshold = self.criterion
        lines = [
            f"{'rate [arcsec/s]':>16}  {'rate [px/s]':>11}  {'limiting mag':>12}  {metric + ' at limit':>24}",
            "-" * 69,
        ]
        for r in self.table:
            lines.append(
                f"{r['rate_arcsec_s']:16.4g}  {r['rate_px_s']:11.4g}  {_fmt_num(r['limiting_magnitude']):>12}"
                f"  {_fmt_num(r['metric_at_limit']):>24}"
            )
        lines.append(f"criterion: mean {metric} >= {threshold:g} over {self.sweep.runs} seed(s)")
        return "\n".join(lines)


def limiting_magnitude(
    scenario: str | Path | dict | None = None,
    rates_arcsec_s: Sequence[float] = DEFAULT_RATES_ARCSEC_S,
    magnitudes: Sequence[float] = DEFAULT_MAGNITUDES,
    runs: int = 1,
    criterion: tuple[str, float] = ("excess_fraction", 0.5),
    out_dir: PathLike | None = None,
    resume: bool = False,
    scheduler: Any = None,
    workers: int | None = None,
    seed: int = 0,
    sets: Sequence[str] = (),
    duration_s: float | None = None,
    progress: bool = False,
) -> LimitingMagnitudeResult:
    """Limiting magnitude against angular rate for the scenario's bias configuration.

    The scenario's first target becomes a linear mover along +x (``targets.0.wx_arcsec_s``)
    and a ``detect`` sweep runs over (rate, magnitude) x runs seeds; the criterion is
    ``mean(metric) >= threshold`` with a :class:`DetectObjective` metric. Default criterion:
    ``excess_fraction >= 0.5`` -- half the track's pixels fire, after correcting for those
    noise alone would fire (``track_fraction`` counts noise as detection, which makes a
    noisy bias look sensitive). scenario None: :func:`limiting_magnitude_scenario`.
    out_dir: the sweep's files plus ``limiting_magnitude.csv`` and ``limiting_magnitude.png``.
    """
    metric, threshold = criterion
    if metric not in DetectObjective.metrics:
        raise ValueError(
            f"criterion metric must be one of {', '.join(DetectObjective.metrics)}; got {metric!r}"
        )
    rates = [float(r) for r in rates_arcsec_s]
    mags = sorted(float(m) for m in magnitudes)
    if not rates or not mags:
        raise ValueError("limiting magnitude needs at least one rate and one magnitude")
    bad = [r for r in rates if not (math.isfinite(r) and r > 0)]
    if bad:
        raise ValueError(f"rates-arcsec-s must be finite and > 0; got {bad}")
    base = load(limiting_magnitude_scenario() if scenario is None else scenario)
    for text in sets:
        k, v = parse_assignment(text)
        base = set_value(base, k, v)
    base = _as_linear_mover(base)
    label = base["targets"][0]["label"]
    names = [t.get("label") for t in base["targets"]]
    if names.count(label) > 1:
        raise ValueError(f"target label {label!r} is not unique: give the targets distinct labels")
    grid = {"targets.0.wx_arcsec_s": rates, "targets.0.magnitude": mags}
    result = sweep(
        base,
        grid,
        objective=DetectObjective(target=label),
        runs=runs,
        out_dir=out_dir,
        resume=resume,
        scheduler=scheduler,
        workers=workers,
        duration_s=duration_s,
        seed=seed,
        progress=progress,
    )
    plate_arcsec = build(base).optics.plate_scale_rad_per_px / ARCSEC_RAD
    table = []
    for rate in rates:
        rows = {
            float(r["targets.0.magnitude"]): r for r in result.summary if r["targets.0.wx_arcsec_s"] == rate
        }
        limit, at_limit = math.nan, math.nan
        for m in mags:
            value = rows[m][f"mean_{metric}"]
            if not (rows[m]["runs"] > 0 and value >= threshold):
                break
            limit, at_limit = m, value
        table.append(
            {
                "rate_arcsec_s": rate,
                "rate_px_s": rate / plate_arcsec,
                "limiting_magnitude": limit,
                "metric_at_limit": at_limit,
            }
        )
    out = LimitingMagnitudeResult(criterion=(metric, float(threshold)), table=table, sweep=result)
    if out_dir is not None:
        o = Path(out_dir)
        out.table_path = o / "limiting_magnitude.csv"
        _atomic_write_text(
            out.table_path,
            _csv_text(["rate_arcsec_s", "rate_px_s", "limiting_magnitude", "metric_at_limit"], table),
        )
    return out


def parse_float_list(text: str, what: str) -> list[float]:
    """'1,2,3' or 'lo:hi:step' (inclusive) -> floats; ValueError naming the argument."""
    text = text.strip()
    try:
        if ":" in text and "," not in text:
            parts = [float(p) for p in text.split(":")]
            if len(parts) != 3 or not parts[2] > 0 or parts[1] < parts[0]:
                raise ValueError
            n = math.floor((parts[1] - parts[0]) / parts[2] + 1e-9) + 1
            return [round(parts[0] + k * parts[2], 10) for k in range(n)]
        values = [float(p) for p in text.split(",") if p.strip()]
    except ValueError:
        raise ValueError(f"{what} takes numbers v1,v2,... or lo:hi:step; got {text!r}") from None
    if not values or not all(math.isfinite(v) for v in values):
        raise ValueError(f"{what} takes finite numbers v1,v2,... or lo:hi:step; got {text!r}")
    return values
