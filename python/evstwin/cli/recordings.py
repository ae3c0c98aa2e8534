"""``evstwin info``, ``show``, ``compare``, ``timing`` and ``calibrate-noise``: commands on recordings."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from ._common import (
    add_force,
    add_region,
    add_sets,
    add_size,
    check_output_dir,
    check_output_file,
    parse_roi,
    region_args,
    staged_folder,
)


def register(sub: Any) -> None:
    p = sub.add_parser("info", help="print a recording's summary (read in chunks: any size)")
    p.add_argument("file", help="event file in any format read_events takes (.h5, .aedat4, .raw, ...)")
    add_size(p)
    p.set_defaults(func=cmd_info)

    p = sub.add_parser("show", help="draw one recording's figures")
    p.add_argument("file", help="event file in any format read_events takes")
    p.add_argument("--out", required=True, help="output folder for the PNGs (created; must be empty or new)")
    p.add_argument("--t0", type=float, default=0.0,
                   help="start of the frames and x-y-t figures after the recording's first event [s] (default 0)")
    p.add_argument("--window", type=float,
                   help="length of each of the three frames [s] (default: from the recording, so that a frame "
                        "holds about 0.02 events per pixel, at most a third of what follows --t0; the paper's "
                        "Fig. 5 used 0.033)")
    add_size(p)
    add_force(p)
    p.set_defaults(func=cmd_show)

    p = sub.add_parser("movie", help="render a recording as a movie (.mp4 or .gif, through faery)",
                       description="Render any readable recording, real or simulated, as a movie: frames of "
                                   "--speed/--frame-rate seconds of recording, each pixel coloured by its latest "
                                   "event (ON/OFF colours) faded by --decay; a simulated file's ground truth "
                                   "(each target's true place) is drawn as coloured squares.")
    p.add_argument("file", help="event file in any format read_events takes")
    p.add_argument("--out", required=True, help="the movie: a .mp4 (H.264) or .gif file (must not exist, or --force)")
    p.add_argument("--t0", type=float, default=0.0, help="start after the recording's first event [s] (default 0)")
    p.add_argument("--duration", type=float, help="recording time shown [s] (default: to the last event)")
    p.add_argument("--frame-rate", type=float, default=30.0, help="video frames per second (default 30)")
    p.add_argument("--speed", type=float, default=1.0,
                   help="recording seconds per video second (default 1; 0.1 plays ten times slower)")
    p.add_argument("--decay", default="exponential", choices=("exponential", "linear", "window", "cumulative"),
                   help="how a pixel's colour fades with its latest event's age (faery's render; default exponential)")
    p.add_argument("--tau", type=float, help="the decay's time constant [s] (default: one frame's span)")
    p.add_argument("--on-color", default="#F4C20D", help="colour of ON events, #RRGGBB (default #F4C20D)")
    p.add_argument("--off-color", default="#1E88E5", help="colour of OFF events, #RRGGBB (default #1E88E5)")
    p.add_argument("--background", default="#000000", help="colour of pixels without events, #RRGGBB (default black)")
    p.add_argument("--scale", type=int, default=1, help="video pixels per sensor pixel, each way (default 1)")
    p.add_argument("--no-truth", action="store_true", help="do not draw the ground truth of a simulated file")
    p.add_argument("--color-by", choices=("polarity", "label"), default="polarity",
                   help="'label': why each event fired, from a file's label column (simulate --labels): the "
                        "signal in the ON/OFF colours, each kind of noise in its own (default: polarity)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_size(p)
    add_force(p)
    p.set_defaults(func=cmd_movie)

    p = sub.add_parser("compare", help="compare a real recording with simulations (paper sec. 3)")
    p.add_argument("real", help="real recording (AEDAT4, RAW, ... any format read_events takes)")
    p.add_argument("sims", nargs="+", help="simulated recordings, or scenarios (built-in names or TOML) to simulate")
    p.add_argument("--out", required=True,
                   help="output folder for compare.json, the figures and the simulated runs (must be empty or new)")
    p.add_argument("--bin-width", type=float, default=2.0,
                   help="per-pixel count histogram bin width [events] (default 2, the paper's)")
    p.add_argument("--runs", type=int, default=1,
                   help="seeds per scenario SIM, a Monte Carlo run in parallel processes (default 1; paper: 20)")
    p.add_argument("--duration", type=float,
                   help="sensor time simulated per scenario SIM [s] (default: the real recording's span)")
    add_sets(p, "override a value of every scenario SIM, e.g. pixel.theta_on=0.25 (repeatable)")
    add_size(p)
    add_region(p)
    add_force(p)
    p.set_defaults(func=cmd_compare)

    p = sub.add_parser("timing", help="event-timing bias against the ground truth of simulated .h5/.npz files")
    p.add_argument("files", nargs="+", help="one file, or several (one per bias setting) to compare")
    p.add_argument("--out", required=True, help="output folder for timing_bias.json and the figure (must be empty or new)")
    p.add_argument("--radius-px", type=float, default=1.0,
                   help="attribute events within this distance of the track [px] (default 1)")
    p.add_argument("--max-delay-s", type=float, default=0.3,
                   help="longest delay after a crossing attributed to it [s] (default 0.3): an event goes to its "
                        "pixel's latest crossing whose source had come within --radius-px; later events, and "
                        "events before any crossing, are counted as unexplained. The result stops changing once "
                        "this covers the slowest response")
    add_force(p)
    p.set_defaults(func=cmd_timing)

    p = sub.add_parser("calibrate-noise",
                       help="measure the background activity of a static or dark recording as scenario TOML")
    p.add_argument("file", help="event file in any format read_events takes (a static or dark scene)")
    p.add_argument("--roi", type=parse_roi, metavar="X0,Y0,W,H",
                   help="window measured [px]: corner x0, y0 and size (default: the whole sensor)")
    p.add_argument("-o", "--output",
                   help="scenario TOML to write (default: none; the TOML goes to stdout, the summary to stderr)")
    p.add_argument("--preset", default="auto",
                   help="[sensor] preset written: a preset name, 'none', or 'auto' (default: a simulated file's own "
                        "preset, else the built-in preset of the recording's size, none if there is none)")
    p.add_argument("--alpha", type=float, default=1e-6,
                   help="false-alarm probability per pixel of the hot-pixel test (default 1e-6)")
    add_size(p)
    add_force(p)
    p.set_defaults(func=cmd_calibrate_noise)


def cmd_info(args: argparse.Namespace) -> int:
    from ..validation import info

    print(info(args.file, size=args.size))
    return 0


def cmd_show(args: argparse.Namespace) -> int:
    from ..validation import show

    if args.window is not None and not args.window > 0:
        raise ValueError(f"--window must be > 0 s; got {args.window}")
    if not args.t0 >= 0:
        raise ValueError(f"--t0 must be >= 0 s; got {args.t0}")
    check_output_dir(args.out, args.force)
    notes: list[str] = []
    with staged_folder(args.out) as stage:
        outputs = show(args.file, stage.path, window_s=args.window, t_offset_s=args.t0, size=args.size, notes=notes)
    for note in notes:
        print(note, file=sys.stderr)
    for name, path in outputs.items():
        print(f"{name}: {stage.final_of(path)}")
    return 0


def cmd_movie(args: argparse.Namespace) -> int:
    from ..movie import MovieOptions, render_movie

    options = MovieOptions(
        t0_s=args.t0, duration_s=args.duration, frame_rate_hz=args.frame_rate, speed=args.speed, decay=args.decay,
        tau_s=args.tau, on_color=args.on_color, off_color=args.off_color, background=args.background,
        scale=args.scale, truth=not args.no_truth, color_by=args.color_by,
    )
    options.check()
    out = check_output_file(args.out, args.force, "--out")
    bar: Any = None

    def progress(done: int, total: int) -> None:
        nonlocal bar
        if args.no_progress:
            return
        if bar is None:
            from tqdm import tqdm

            bar = tqdm(total=total, unit="frame", desc="rendering", file=sys.stderr, leave=False)
        bar.update(done - bar.n)

    try:
        movie = render_movie(args.file, out, options, size=args.size, progress=progress)
    finally:
        if bar is not None:
            bar.close()
    t0, t1 = movie.window_us
    print(f"wrote {movie.path}: {movie.frames} frames of {movie.size_px[0]} x {movie.size_px[1]} px at "
          f"{options.frame_rate_hz:g} frames/s, {movie.events} events from {t0} to {t1} us "
          f"({options.frame_span_s:.6g} s of recording a frame)")
    for name, colors in movie.legend.items():
        print(f"  {name}: {colors}")
    return 0


def _is_event_file(text: str) -> bool:
    from ..io import supported_read_suffixes

    return Path(text).suffix.lower() in supported_read_suffixes() and Path(text).is_file()


def cmd_compare(args: argparse.Namespace) -> int:
    from ..io import write_events
    from ..scenario import build
    from ..simulate import resolve_scenario, run_many
    from ..validation import compare_files, compare_runs
    from ..validation.region import Roi, describe
    from ..validation.report import region_mask, scan_recording

    if args.runs < 1:
        raise ValueError(f"--runs must be >= 1; got {args.runs}")
    if not args.bin_width > 0:
        raise ValueError(f"--bin-width must be > 0; got {args.bin_width}")
    if args.duration is not None and not args.duration > 0:
        raise ValueError(f"--duration must be > 0 s; got {args.duration}")
    roi, pixels, mask_hot = region_args(args)
    out = check_output_dir(args.out, args.force)
    # Everything is read and checked before a folder is made or a second simulated; the real
    # recording is read in chunks (its per-pixel counts are all the comparison keeps), cut to
    # the ROI as it is read.
    real_rec, real_meta, _ = scan_recording(args.real, args.size, 0.0, 0.0, roi=roi)
    width, height = int(real_meta.get("sensor_width", real_rec.width)), int(real_meta.get("sensor_height", real_rec.height))
    the_roi = None if roi is None else Roi.of(roi)
    mask = region_mask(real_rec, real_meta, the_roi, pixels, mask_hot, sensor_size=(width, height))
    duration_s = args.duration if args.duration is not None else _span_s(real_rec, real_meta)
    sets = list(args.sets)
    if the_roi is not None:  # scenarios simulate the ROI alone: the cost follows its pixels
        sets.append(f"sensor.roi=[{the_roi}]")
    for sim in args.sims:
        if _is_event_file(sim):
            scan_recording(sim, None, 0.0, 0.0, roi=roi)  # readable, before anything is simulated
            continue
        scenario = resolve_scenario(sim, args.sets)
        full = build(scenario, duration_s=duration_s)
        if (full.width, full.height) != (width, height):
            raise ValueError(
                f"scenario {sim!r} simulates a {full.width}x{full.height} sensor but {args.real} is "
                f"{width}x{height}: set sensor.width/height (--set) or compare another scenario"
            )
        if the_roi is not None:
            build(resolve_scenario(sim, sets), duration_s=duration_s)
    if the_roi is not None or mask is not None:
        print(f"comparing {describe(the_roi, mask)}", file=sys.stderr)
    if not all(_is_event_file(sim) for sim in args.sims):
        source = "--duration" if args.duration is not None else "the real recording's span; --duration to change"
        print(f"simulating {duration_s:.6g} s per run ({source})", file=sys.stderr)
    with staged_folder(out) as stage:  # whole or not at all: Ctrl-C leaves no folder
        # Scenario SIMs are simulated (--runs seeds each, in parallel processes, a progress bar
        # counting finished runs) and written beside the figures, so every number in
        # compare.json points at a file.
        runs: list[list[Path]] = [[] for _ in range(args.runs)]
        labels: list[str] = []  # what each SIM is called in the Monte Carlo summary
        for sim in args.sims:
            labels.append(sim if _is_event_file(sim) else f"{sim} ({args.runs} seeds)")
            if _is_event_file(sim):
                for r in runs:
                    r.append(Path(sim))
                continue
            start = time.perf_counter()
            results = run_many(sim, seeds=range(args.runs), duration_s=duration_s, sets=sets, progress=True)
            stem = Path(sim).stem if sim.endswith(".toml") else sim
            for seed, res in enumerate(results):
                path = stage.path / f"{stem}_seed{seed}.h5"
                write_events(path, res.events, res.meta)
                runs[seed].append(path)
            print(f"simulated {sim}: {args.runs} run(s) of {duration_s:.6g} s in {time.perf_counter() - start:.1f} s",
                  file=sys.stderr)
        comparison = compare_files(args.real, runs[0], stage.path, bin_width=args.bin_width, size=args.size, roi=roi, mask=mask)
        report = comparison.to_json_dict()
        report["simulated_duration_s"] = duration_s
        texts = [comparison.to_text()]
        if args.runs > 1:
            summary = compare_runs((real_rec, dict(real_meta, path=args.real)), runs, labels, stage.path,
                                   bin_width=args.bin_width, roi=roi, mask=mask)
            report["monte_carlo"] = summary.to_json_dict()
            texts.append(summary.to_text())
        with open(stage.path / "compare.json", "w", encoding="utf-8") as fh:
            json.dump(report, fh, indent=1, allow_nan=False)
    for text in texts:
        print(stage.relocated(text))
    print(f"wrote {out / 'compare.json'} and the figures in {out}")
    return 0


def _span_s(rec: Any, meta: dict) -> float:
    """The recording's duration [s]: its meta's, else first to last event (at least 1 ms)."""
    if meta.get("duration_s"):
        return float(meta["duration_s"])
    if rec.t_start_us is None:
        return 1e-3
    return max(1e-3, (rec.t_end_us - rec.t_start_us) * 1e-6)


def cmd_timing(args: argparse.Namespace) -> int:
    from ..validation import timing_report

    if not args.radius_px > 0:
        raise ValueError(f"--radius-px must be > 0 px; got {args.radius_px}")
    if not args.max_delay_s > 0:
        raise ValueError(f"--max-delay-s must be > 0 s; got {args.max_delay_s}")
    out = check_output_dir(args.out, args.force)
    with staged_folder(out) as stage:
        _, text, png = timing_report(args.files, stage.path, radius_px=args.radius_px, max_delay_s=args.max_delay_s)
    print(text)
    print(f"wrote {stage.final_of(png)} and {out / 'timing_bias.json'}")
    return 0


def cmd_calibrate_noise(args: argparse.Namespace) -> int:
    from ..validation.noise import calibrate_noise

    out = check_output_file(args.output, args.force, "--output") if args.output is not None else None
    cal = calibrate_noise(args.file, args.roi, size=args.size, preset=args.preset, alpha=args.alpha)
    if out is None:
        print(cal.summary(), file=sys.stderr)
        print(cal.to_toml(), end="")
        return 0
    cal.write(out)
    print(cal.summary())
    print(f"wrote {out}")
    return 0
