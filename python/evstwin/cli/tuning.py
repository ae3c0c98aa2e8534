"""``evstwin fit``, ``sweep`` and ``limiting-magnitude``: thin commands over :mod:`evstwin.tune`."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Any

from ..scenario import load, parse_assignment, set_value
from ..tune import (
    DEFAULT_FIT_PARAMS,
    DEFAULT_MAGNITUDES,
    DEFAULT_RATES_ARCSEC_S,
    OBJECTIVES,
    SAMPLERS,
    STATISTICS,
    FitOptions,
    draw_fit,
    draw_limiting_magnitude,
    draw_sweep,
    fit,
    limiting_magnitude,
    parse_bound,
    parse_float_list,
    parse_grid,
    sweep,
)
from ..tune.limits import Setup
from ._common import (
    add_force,
    add_region,
    add_sets,
    add_size,
    check_output_dir,
    region_args,
    resumable,
    staged_folder,
)


def register(subparsers: Any) -> None:
    """Add ``fit``, ``sweep`` and ``limiting-magnitude`` to the ``evstwin`` command."""

    def execution(p: argparse.ArgumentParser, dask_workers_default: str) -> None:
        p.add_argument(
            "--scheduler",
            help="Dask scheduler address (tcp://host:8786, or tls://host:8786 with Dask's TLS settings "
            "from its config or DASK_DISTRIBUTED__COMM__TLS__* variables), or 'local' for an in-process "
            "cluster; default: local worker processes. A scheduler and its workers run the pickled jobs "
            "they are sent: use only a cluster you trust, and tls:// across untrusted networks",
        )
        p.add_argument("--workers", type=int, help=f"worker processes (default: {dask_workers_default})")
        p.add_argument("--no-progress", action="store_true", help="no progress bar")
        add_force(p)

    p = subparsers.add_parser("fit", help="fit twin parameters to a real recording (least squares by default; Nelder-Mead, CMA-ES, Optuna)")
    p.add_argument("real", help="real recording (any format read_events takes)")
    p.add_argument(
        "--scenario", required=True, help="scenario to fit (built-in name or TOML), of the sensor's size"
    )
    p.add_argument(
        "--params",
        default=",".join(DEFAULT_FIT_PARAMS),
        help="comma list of parameters (pixel fields or scenario keys); default: "
        + ",".join(p.split(".", 1)[1] for p in DEFAULT_FIT_PARAMS),
    )
    p.add_argument(
        "--bounds",
        action="append",
        nargs="+",
        default=[],
        metavar="NAME=LO:HI",
        help="search bounds replacing the documented defaults (repeatable)",
    )
    p.add_argument("--budget", type=int, default=40, help="number of trials (default 40)")
    p.add_argument("--runs-per-trial", type=int, default=1, help="seeds averaged per trial (default 1)")
    p.add_argument("--intervals", action="store_true",
                   help="also give each parameter an interval: with the chi-square (--sampler ls), +- one "
                        "standard error of the least-squares estimate (2 more trials a parameter and 8 more runs "
                        "at the best); with compare's distance, from its curvature at the best (2 more trials a "
                        "parameter; needs --runs-per-trial >= 2). Default: off")
    p.add_argument("--seed", type=int, default=0, help="sampler seed and first simulation seed (default 0)")
    p.add_argument(
        "--sampler",
        default="ls",
        choices=SAMPLERS,
        help="ls: least squares on the chi-square of per-pixel counts and event timing (--statistics) from the "
        "scenario's values, each step's derivatives one parallel batch (default); nm: "
        "Nelder-Mead on compare's distance; tpe: Optuna TPE, global; tpe+nm: TPE then Nelder-Mead; "
        "cmaes: CMA-ES (cmaes package), a generation a batch; random",
    )
    p.add_argument(
        "--batch-size", type=int, default=4, help="Optuna trials run in parallel per round (default 4)"
    )
    p.add_argument(
        "--statistics", default=FitOptions.statistics, choices=STATISTICS,
        help="the chi-square's statistics (--sampler ls): timing: the per-pixel counts and the statistics that "
        "carry timing (delays after a source's passage, intervals between a pixel's events, ON/OFF "
        "alternation); counts: the per-pixel counts alone (default %(default)s)",
    )
    add_sets(p, "override a scenario value before fitting (repeatable)")
    p.add_argument("--out", help="output folder (default: <REAL stem>_fit)")
    add_size(p)
    add_region(p)
    execution(p, "all cores; 2 with --scheduler local")
    p.set_defaults(func=_cmd_fit)

    p = subparsers.add_parser("sweep", help="evaluate an objective over a grid of scenario values x seeds")
    p.add_argument("--scenario", required=True, help="built-in name or TOML")
    p.add_argument(
        "--grid",
        action="append",
        default=[],
        required=True,
        metavar="NAME=V1,V2,...",
        help="a parameter and its values, named as in --set (repeatable)",
    )
    p.add_argument("--objective", default="detect", help=f"one of {', '.join(OBJECTIVES)} (default detect)")
    p.add_argument("--real", help="real recording for --objective match")
    p.add_argument("--target", help="label of the detect objective's target (default: the first moving one)")
    p.add_argument("--runs", type=int, default=1, help="seeds per point (default 1)")
    p.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    p.add_argument("--duration", type=float, help="sensor time per run [s] (default: the scenario's)")
    add_sets(p, "override a scenario value at every point, e.g. sensor.bias_set=paper_run_3 (repeatable)")
    p.add_argument("--out", default="sweep", help="output folder (default ./sweep)")
    p.add_argument(
        "--resume", action="store_true", help="keep the finished rows of OUT/sweep.csv, run the rest"
    )
    add_region(p)
    execution(p, "all cores; 2 with --scheduler local")
    p.set_defaults(func=_cmd_sweep)

    p = subparsers.add_parser(
        "limiting-magnitude",
        help="faintest magnitude detected against angular rate, for a scenario or a real setup (--preset and a lens)",
    )
    p.add_argument(
        "--scenario", help="built-in name or TOML (default: geo-stare without stars, 128x64 px, 4 s); or give a "
                           "real setup with --preset and --focal-length-mm"
    )
    setup = p.add_argument_group("a real setup (instead of --scenario)")
    setup.add_argument("--preset", help="sensor preset (davis346, imx636, ...): the setup's sensor")
    setup.add_argument("--bias-set", help="bias set of the preset (default: the preset's own)")
    setup.add_argument("--focal-length-mm", type=float, help="lens focal length [mm]")
    setup.add_argument("--f-number", type=float, help="lens f-number (or --aperture-mm)")
    setup.add_argument("--aperture-mm", type=float, help="entrance pupil diameter [mm] (or --f-number)")
    setup.add_argument("--transmission", type=float, default=0.8, help="optics throughput (default 0.8)")
    setup.add_argument("--sky-mag", type=float, default=21.0,
                       help="sky surface brightness [V mag/arcsec^2] (default 21; ~21.9 dark site, ~18 city)")
    setup.add_argument("--seeing-arcsec", type=float, default=2.0, help="seeing FWHM [arcsec] (default 2; 0: none)")
    setup.add_argument("--declination-deg", type=float, default=0.0,
                       help="field declination [deg]: the stars' drift when staring (default 0)")
    setup.add_argument("--window", default="128x64", help="simulated window of the sensor, WxH px (default 128x64)")
    setup.add_argument("--rate-hz", type=float, default=100.0, help="sampling floor [Hz] (default 100)")
    setup.add_argument("--no-stars", action="store_true", help="no star field (default: the sky's star counts)")
    setup.add_argument("--stars-mag-max", type=float, default=14.0, help="faintest field star [V] (default 14)")
    setup.add_argument("--jitter-rms-arcsec", type=float, default=0.0,
                       help="image motion per axis [arcsec rms] (default 0: none)")
    setup.add_argument("--jitter-tau-s", type=float, default=0.05, help="image motion correlation time [s] (default 0.05)")
    setup.add_argument("--scintillation", action="store_true", help="scintillation of every point source")
    setup.add_argument("--site-altitude-m", type=float, default=0.0, help="observatory altitude [m] (scintillation)")
    setup.add_argument("--airmass", type=float, default=1.0, help="airmass (scintillation; default 1)")
    p.add_argument("--pointing", default="sidereal", choices=("sidereal", "staring", "target"),
                   help="sidereal: stars at rest, the target moves at the rate; staring: the stars drift at the "
                        "sidereal rate, the target at its rate less that; target: the target at rest, the stars "
                        "drift at the rate (default sidereal). Rates are relative to the stars")
    p.add_argument(
        "--rates-arcsec-s",
        default=",".join(f"{r:g}" for r in DEFAULT_RATES_ARCSEC_S),
        help="angular rates [arcsec/s], v1,v2,... or lo:hi:step (default %(default)s)",
    )
    p.add_argument(
        "--magnitudes",
        default=",".join(f"{m:g}" for m in DEFAULT_MAGNITUDES),
        help="magnitudes, v1,v2,... or lo:hi:step (default %(default)s)",
    )
    p.add_argument(
        "--criterion",
        default="excess_fraction>=0.5",
        help="METRIC>=VALUE of the detect objective (default excess_fraction>=0.5)",
    )
    p.add_argument("--runs", type=int, default=1, help="seeds per (rate, magnitude) (default 1)")
    p.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    p.add_argument("--duration", type=float, help="sensor time per run [s] (default: the scenario's)")
    add_sets(p, "bias configuration etc., e.g. sensor.bias_set=paper_run_3 (repeatable)")
    p.add_argument("--out", default="limiting_magnitude", help="output folder (default ./limiting_magnitude)")
    p.add_argument("--resume", action="store_true",
                   help="keep the finished rows of OUT/sweep.csv and run only the rest")
    execution(p, "all cores; 2 with --scheduler local")
    p.set_defaults(func=_cmd_limiting)


def _check_workers(args: argparse.Namespace) -> None:
    if args.workers is not None and args.workers < (1 if args.scheduler else 0):
        raise ValueError(f"--workers must be >= {1 if args.scheduler else 0}; got {args.workers}")


def _check_at_least(args: argparse.Namespace, **lowest: int) -> None:
    """ValueError naming the first integer option (``runs_per_trial`` is --runs-per-trial) below its lowest value."""
    for name, low in lowest.items():
        value = getattr(args, name)
        if value < low:
            raise ValueError(f"--{name.replace('_', '-')} must be >= {low}; got {value}")


def _check_duration(args: argparse.Namespace) -> None:
    if args.duration is not None and not args.duration > 0:
        raise ValueError(f"--duration must be > 0; got {args.duration}")


def _cmd_fit(args: argparse.Namespace) -> int:
    _check_workers(args)
    from ..io import read_events

    _check_at_least(args, budget=1, runs_per_trial=1, seed=0, batch_size=1)
    params = [p for p in args.params.split(",") if p.strip()]
    bounds = dict(parse_bound(b) for group in args.bounds for b in group)
    scenario = load(args.scenario)
    for text in args.sets:
        k, v = parse_assignment(text)
        scenario = set_value(scenario, k, v)
    roi, pixels, mask_hot = region_args(args)
    out = check_output_dir(args.out if args.out else f"{Path(args.real).stem}_fit", args.force)
    events, meta = read_events(args.real, size=args.size)
    options = FitOptions(
        params=params,
        budget=args.budget,
        runs_per_trial=args.runs_per_trial,
        seed=args.seed,
        bounds=bounds,
        sampler=args.sampler,
        batch_size=args.batch_size,
        roi=roi,
        mask_pixels=pixels,
        mask_hot=mask_hot,
        intervals=args.intervals,
        statistics=args.statistics,
    )
    result = fit(events, meta, scenario, options, scheduler=args.scheduler, workers=args.workers,
                 progress=not args.no_progress)
    with staged_folder(out) as stage:  # whole or not at all: Ctrl-C leaves no folder
        paths = result.write(stage.path)
        paths.update(draw_fit(result, stage.path))
    paths = {k: stage.final_of(v) for k, v in paths.items()}
    print(result.to_text())
    figures = ", ".join(str(paths[k]) for k in ("convergence", "correlation") if k in paths)
    print(
        f"wrote {paths['best_toml']} (evstwin simulate {paths['best_toml']} -o OUT), {paths['history']}, "
        f"{paths['json']}, {figures} and the comparison in {out / 'compare'}"
    )
    for f in result.failed:
        print(f"failed trial {f.key}: {f.error}", file=sys.stderr)
    return 0


def _prepare_sweep_dir(args: argparse.Namespace) -> None:
    """Check --out for a new sweep (nothing to do with --resume); with --force drop its old
    ``sweep.csv``, which would otherwise be taken for one to resume."""
    if not args.resume:
        check_output_dir(args.out, args.force)
        if args.force:
            (Path(args.out) / "sweep.csv").unlink(missing_ok=True)


def _sweep_options(args: argparse.Namespace) -> dict[str, Any]:
    """The keyword arguments ``sweep`` and ``limiting_magnitude`` both take from the command
    line: runs, output folder, resuming, execution, seed, overrides, duration, progress."""
    return {
        "runs": args.runs,
        "out_dir": args.out,
        "resume": args.resume,
        "scheduler": args.scheduler,
        "workers": args.workers,
        "seed": args.seed,
        "sets": args.sets,
        "duration_s": args.duration,
        "progress": not args.no_progress,
    }


def _cmd_sweep(args: argparse.Namespace) -> int:
    _check_workers(args)
    _check_at_least(args, runs=1, seed=0)
    if args.objective not in OBJECTIVES:
        raise ValueError(f"--objective must be one of {', '.join(OBJECTIVES)}; got {args.objective!r}")
    if args.real is not None and args.objective != "match":
        raise ValueError(f"--real is for --objective match; got --objective {args.objective}")
    _check_duration(args)
    roi, pixels, mask_hot = region_args(args)
    if args.objective != "match" and (roi is not None or pixels or mask_hot):
        raise ValueError(f"--roi and the --mask options are for --objective match; got --objective {args.objective}")
    grid = parse_grid(args.grid)
    _prepare_sweep_dir(args)
    with resumable(args.out, math.prod(len(v) for v in grid.values()) * args.runs):
        result = sweep(
            args.scenario,
            grid,
            objective=args.objective,
            real=args.real,
            target=args.target,
            **_sweep_options(args),
            roi=roi,
            mask_pixels=pixels,
            mask_hot=mask_hot,
        )
        if result.csv_path is not None:
            draw_sweep(result)
    print(result.to_text())
    print(f"wrote {result.csv_path}, {result.summary_path} and {result.figure_path}")
    return 1 if result.failed else 0


def _cmd_limiting(args: argparse.Namespace) -> int:
    _check_workers(args)
    _check_at_least(args, runs=1)
    _check_duration(args)
    if ">=" not in args.criterion:
        raise ValueError(
            f"--criterion takes METRIC>=VALUE (e.g. excess_fraction>=0.5); got {args.criterion!r}"
        )
    metric, _, value = args.criterion.partition(">=")
    try:
        threshold = float(value)
    except ValueError:
        raise ValueError(f"--criterion {args.criterion!r}: the value must be a number") from None
    rates = parse_float_list(args.rates_arcsec_s, "--rates-arcsec-s")
    mags = parse_float_list(args.magnitudes, "--magnitudes")
    setup = _setup(args)
    _prepare_sweep_dir(args)
    with resumable(args.out, len(rates) * len(mags) * args.runs):
        result = limiting_magnitude(
            args.scenario,
            rates,
            mags,
            criterion=(metric.strip(), threshold),
            **_sweep_options(args),
            setup=setup,
            pointing=args.pointing,
            declination_deg=args.declination_deg,
        )
        draw_limiting_magnitude(result, args.out)
        if result.sweep.csv_path is not None:
            draw_sweep(result.sweep)
    print(result.to_text())
    print(f"wrote {result.table_path}, {result.figure_path} and the sweep in {args.out}")
    return 1 if result.sweep.failed else 0


def _setup(args: argparse.Namespace) -> Setup | None:
    """The real setup the limiting-magnitude arguments describe (None: --scenario), each bad
    value refused in one line naming its option."""
    lens = {"--preset": args.preset, "--focal-length-mm": args.focal_length_mm}
    given = [k for k, v in lens.items() if v is not None]
    if not given:
        for name in ("bias_set", "f_number", "aperture_mm"):
            if getattr(args, name) is not None:
                raise ValueError(f"--{name.replace('_', '-')} describes a real setup: give --preset and --focal-length-mm")
        return None
    if args.scenario is not None:
        raise ValueError(f"give --scenario or a real setup ({', '.join(given)}), not both")
    missing = [k for k, v in lens.items() if v is None]
    if missing:
        raise ValueError(f"a real setup needs {' and '.join(missing)}; got only {', '.join(given)}")
    if args.f_number is None and args.aperture_mm is None:
        raise ValueError("a real setup needs --f-number or --aperture-mm (the lens)")
    for option, value, lo, hi in (("--focal-length-mm", args.focal_length_mm, 0.0, 1e7),
                                  ("--f-number", args.f_number, 0.0, 1e4), ("--aperture-mm", args.aperture_mm, 0.0, 1e5),
                                  ("--transmission", args.transmission, 0.0, 1.0),
                                  ("--seeing-arcsec", args.seeing_arcsec, -1e-300, 3600.0),
                                  ("--rate-hz", args.rate_hz, 0.0, 1e7), ("--jitter-tau-s", args.jitter_tau_s, 0.0, 3600.0),
                                  ("--jitter-rms-arcsec", args.jitter_rms_arcsec, -1e-300, 3600.0),
                                  ("--airmass", args.airmass, 1.0 - 1e-12, 40.0)):
        if value is not None and not (math.isfinite(value) and lo < value <= hi):
            raise ValueError(f"{option} must be in ({lo:g}, {hi:g}]; got {option} {value!r}")
    if not (math.isfinite(args.stars_mag_max) and 4.0 <= args.stars_mag_max <= 16.0):
        raise ValueError(f"--stars-mag-max must be in [4, 16] (the star-count table); got --stars-mag-max {args.stars_mag_max!r}")
    if not (math.isfinite(args.sky_mag) and 10.0 <= args.sky_mag <= 30.0):
        raise ValueError(f"--sky-mag must be in [10, 30] mag/arcsec^2; got --sky-mag {args.sky_mag!r}")
    if not (math.isfinite(args.declination_deg) and -90.0 < args.declination_deg < 90.0):
        raise ValueError(f"--declination-deg must be in (-90, 90); got --declination-deg {args.declination_deg!r}")
    if not (math.isfinite(args.site_altitude_m) and -500.0 <= args.site_altitude_m <= 9000.0):
        raise ValueError(f"--site-altitude-m must be in [-500, 9000]; got --site-altitude-m {args.site_altitude_m!r}")
    width, sep, height = args.window.lower().partition("x")
    if not (sep and width.isdigit() and height.isdigit() and 16 <= int(width) <= 4096 and 16 <= int(height) <= 4096):
        raise ValueError(f"--window takes WxH pixels, each in [16, 4096] (e.g. 128x64); got --window {args.window!r}")
    from ..presets import get_preset

    try:
        preset = get_preset(args.preset)
    except ValueError as exc:
        raise ValueError(f"--preset: {exc}") from None
    if int(width) > preset.width or int(height) > preset.height:
        raise ValueError(f"--window {args.window} is larger than the {preset.name} sensor ({preset.width}x{preset.height})")
    if args.bias_set is not None:
        from ..presets import get_bias_set

        try:
            get_bias_set(args.bias_set)
        except ValueError as exc:
            raise ValueError(f"--bias-set: {exc}") from None
        if preset.vendor_biases is not None:
            raise ValueError(f"--bias-set {args.bias_set}: the DAVIS bias sets do not apply to --preset {preset.name}, "
                             "whose biases are Prophesee's; leave --bias-set out for its own")
    if args.scintillation:
        from ..sky.atmosphere import MIN_SAMPLES_PER_SCINTILLATION_TAU, Scintillation

        d_m = args.aperture_mm * 1e-3 if args.aperture_mm is not None else args.focal_length_mm * 1e-3 / args.f_number
        tau = Scintillation().correlation_time_s(d_m)
        if args.rate_hz * tau < MIN_SAMPLES_PER_SCINTILLATION_TAU:
            raise ValueError(f"--scintillation: its correlation time is {tau * 1e3:.3g} ms with this aperture, and "
                             f"--rate-hz {args.rate_hz:g} samples it {args.rate_hz * tau:.2g} times: give --rate-hz "
                             f"{math.ceil(MIN_SAMPLES_PER_SCINTILLATION_TAU / tau)} or more "
                             f"({MIN_SAMPLES_PER_SCINTILLATION_TAU} samples per correlation time)")
    return Setup(
        preset=args.preset, bias_set=args.bias_set, focal_length_m=args.focal_length_mm * 1e-3,
        f_number=args.f_number, aperture_diameter_m=None if args.aperture_mm is None else args.aperture_mm * 1e-3,
        transmission=args.transmission, sky_mag_per_arcsec2=args.sky_mag,
        seeing_fwhm_arcsec=args.seeing_arcsec if args.seeing_arcsec > 0 else None, pointing=args.pointing,
        declination_deg=args.declination_deg, width_px=int(width), height_px=int(height),
        duration_s=4.0 if args.duration is None else args.duration, rate_hz=args.rate_hz, stars=not args.no_stars,
        stars_mag_max=args.stars_mag_max, jitter_rms_arcsec=args.jitter_rms_arcsec, jitter_tau_s=args.jitter_tau_s,
        scintillation=args.scintillation, site_altitude_m=args.site_altitude_m, airmass=args.airmass,
    )
