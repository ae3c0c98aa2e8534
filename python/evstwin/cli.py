"""The ``evstwin`` command (also ``python -m evstwin``).

    evstwin simulate SCENARIO -o OUT [--duration S] [--seed N] [--threads N] [--set key=value ...]
    evstwin scenarios
    evstwin info FILE
    evstwin show FILE --out DIR
    evstwin compare REAL SIM [SIM ...] --out DIR [--bin-width 2] [--runs N]
    evstwin timing FILE --out DIR [--radius-px 1]
    evstwin fit REAL --scenario S [--params ...] [--budget N] [--runs-per-trial K] [--out DIR]
    evstwin sweep --scenario S --grid name=v1,v2 [...] --objective OBJ [--runs K] [--out DIR] [--resume]
    evstwin limiting-magnitude --scenario S --rates-arcsec-s ... --magnitudes ... [--out DIR]

Errors are one line on stderr (``evstwin: error: ...``) and exit status 2; nothing is
written then.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any, Optional, Sequence

from ._core import __version__


def _parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="evstwin", description="Physics-based digital twin of event cameras (DAVIS346, IMX636) for SSA.")
    ap.add_argument("--version", action="version", version=f"evstwin {__version__}")
    sub = ap.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("simulate", help="simulate a scenario and write its events")
    p.add_argument("scenario", help="built-in name (see `evstwin scenarios`) or a TOML file")
    p.add_argument("-o", "--output", required=True, help="event file: .h5, .npz, .txt, .csv, .aedat4, .raw, .dat, .es")
    p.add_argument("--duration", type=float, help="sensor time [s] (default: the scenario's)")
    p.add_argument("--seed", type=int, help="random seed (default: the scenario's)")
    p.add_argument("--threads", type=int, help="engine threads (default: all cores)")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                   help="override one scenario value, e.g. pixel.theta_on=0.25 (repeatable)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")

    sub.add_parser("scenarios", help="list the built-in scenarios")

    p = sub.add_parser("info", help="print a recording's summary")
    p.add_argument("file")

    p = sub.add_parser("show", help="draw one recording's figures")
    p.add_argument("file")
    p.add_argument("--out", required=True, help="output folder for the PNGs")

    p = sub.add_parser("compare", help="compare a real recording with simulations (paper sec. 3)")
    p.add_argument("real", help="real recording (AEDAT4, RAW, ... any format read_events takes)")
    p.add_argument("sims", nargs="+", help="simulated recordings, or scenarios to simulate")
    p.add_argument("--out", required=True)
    p.add_argument("--bin-width", type=float, default=2.0, help="histogram bin width [events] (paper: 2)")
    p.add_argument("--runs", type=int, default=1, help="seeds per scenario SIM (Monte Carlo; paper: 20)")
    p.add_argument("--duration", type=float, help="sensor time of scenario SIMs [s]")
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE")

    p = sub.add_parser("timing", help="event-timing bias against the ground truth of simulated .h5/.npz files")
    p.add_argument("files", nargs="+", help="one file, or several (one per bias setting) to compare")
    p.add_argument("--out", required=True)
    p.add_argument("--radius-px", type=float, default=1.0, help="attribute events within this distance of the track [px]")
    p.add_argument("--max-delay-s", type=float, default=0.3,
                   help="longest delay attributed to a crossing [s]; keep it below the time between two passes")

    from . import tune

    tune.add_commands(sub)
    return ap


def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = _parser()
    args = ap.parse_args(argv)
    try:
        return int(_run(args) or 0)
    except KeyboardInterrupt:
        print("evstwin: interrupted", file=sys.stderr)
        return 130
    except (ValueError, TypeError, FileNotFoundError, FileExistsError, NotADirectoryError, PermissionError) as exc:
        print(f"evstwin: error: {exc}", file=sys.stderr)
        return 2


def _run(args: argparse.Namespace) -> int:
    if args.command == "simulate":
        return _simulate(args)
    if args.command == "scenarios":
        from .scenario import builtin_names, load

        for name in builtin_names():
            s = load(name)
            print(f"{name:18s} {s.get('description', '')}")
        return 0
    if args.command == "info":
        from .validation import info

        print(info(args.file))
        return 0
    if args.command == "show":
        from .validation import show

        for name, path in show(args.file, args.out).items():
            print(f"{name}: {path}")
        return 0
    if args.command == "compare":
        return _compare(args)
    if args.command == "timing":
        return _timing(args)
    from . import tune

    return tune.run_command(args)


def _simulate(args: argparse.Namespace) -> int:
    from .simulate import simulate_to_file

    if args.threads is not None and args.threads < 1:
        raise ValueError(f"--threads must be >= 1; got {args.threads}")
    result = simulate_to_file(
        args.scenario, args.output, duration_s=args.duration, seed=args.seed, num_threads=args.threads,
        sets=args.sets, progress=not args.no_progress,
    )
    print(f"wrote {args.output}")
    print(result.summary())
    return 0


def _is_event_file(text: str) -> bool:
    from .io import supported_read_suffixes

    return Path(text).suffix.lower() in supported_read_suffixes() and Path(text).is_file()


def _compare(args: argparse.Namespace) -> int:
    from . import plots
    from .io import read_events, write_events
    from .simulate import run_many
    from .validation import aggregate, compare, compare_files

    if args.runs < 1:
        raise ValueError(f"--runs must be >= 1; got {args.runs}")
    if args.bin_width <= 0:
        raise ValueError(f"--bin-width must be > 0; got {args.bin_width}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    real_events, real_meta = read_events(args.real)
    # Scenario SIMs are simulated (--runs seeds each, in parallel processes) and written
    # beside the figures, so every number in compare.json points at a file.
    runs: list[list[Path]] = [[] for _ in range(args.runs)]
    labels: list[str] = []  # what each SIM is called in the Monte Carlo summary
    for sim in args.sims:
        labels.append(sim if _is_event_file(sim) else f"{sim} ({args.runs} seeds)")
        if _is_event_file(sim):
            for r in runs:
                r.append(Path(sim))
            continue
        start = time.perf_counter()
        results = run_many(sim, seeds=range(args.runs), duration_s=args.duration, sets=args.sets)
        stem = Path(sim).stem if sim.endswith(".toml") else sim
        for seed, res in enumerate(results):
            path = out / f"{stem}_seed{seed}.h5"
            write_events(path, res.events, res.meta)
            runs[seed].append(path)
        print(f"simulated {sim}: {args.runs} run(s) in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    comparison = compare_files(args.real, runs[0], out, bin_width=args.bin_width)
    report = comparison.to_json_dict()
    print(comparison.to_text())
    if args.runs > 1:
        comparisons = [compare(real_events, dict(real_meta, path=args.real),
                               [_with_path(read_events(p), label) for p, label in zip(paths, labels)],
                               bin_width=args.bin_width)
                       for paths in runs]
        summary = aggregate(comparisons)
        report["monte_carlo"] = summary.to_json_dict()
        plots.plot_monte_carlo(summary, out)
        print(summary.to_text())
    with open(out / "compare.json", "w", encoding="utf-8") as fh:
        json.dump(report, fh, indent=1, allow_nan=False)
    print(f"wrote {out / 'compare.json'} and the figures in {out}")
    return 0


def _with_path(pair: Any, label: str) -> Any:
    events, meta = pair
    return events, dict(meta, path=label)


def _timing(args: argparse.Namespace) -> int:
    from . import plots
    from .io import read_events
    from .validation import format_timing_bias_summary, timing_bias, timing_bias_summary

    out = Path(args.out)
    tables: list[tuple[str, Any]] = []
    for path in args.files:
        events, meta = read_events(path)
        truth = meta.get("truth") or {}
        if not truth:
            raise ValueError(f"{path} holds no ground truth (/truth): simulate to .h5 or .npz first")
        tables.append((_setting_label(path, meta), timing_bias(events, truth, radius_px=args.radius_px,
                                                                max_abs_delay_s=args.max_delay_s)))
    out.mkdir(parents=True, exist_ok=True)
    report: dict[str, Any] = {}
    for label, table in tables:
        rows = {by: timing_bias_summary(table, by=by) for by in ("target", "polarity", "flux", "speed")}
        report[label] = rows
        print(f"== {label}: {len(table)} events attributed to a crossing")
        for by, r in rows.items():
            print(format_timing_bias_summary(r, by=by))
            print()
    if len(tables) == 1:
        png = plots.plot_timing_bias(tables[0][1], out / "timing_bias.png")
        report = report[tables[0][0]]
    else:
        png = plots.plot_timing_by_setting(tables, out / "timing_by_setting.png")
    with open(out / "timing_bias.json", "w", encoding="utf-8") as fh:
        json.dump(report, fh, indent=1, default=float)
    print(f"wrote {png} and {out / 'timing_bias.json'}")
    return 0


def _setting_label(path: str, meta: dict) -> str:
    """A file's name and the thresholds it was simulated with, when its scenario says."""
    scenario = meta.get("scenario")
    name = Path(path).name
    if isinstance(scenario, dict):
        try:
            from .scenario import build

            p = build(scenario).params
            return f"{name}\ntheta {p.theta_on:.3g}/{p.theta_off:.3g}"
        except ValueError:
            return name
    return name


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
