"""``evstwin simulate`` and ``evstwin scenarios``."""

from __future__ import annotations

import argparse
from typing import Any

from ._common import add_force, add_sets, check_output_file


def register(sub: Any) -> None:
    p = sub.add_parser("simulate", help="simulate a scenario and write its events")
    p.add_argument("scenario", help="built-in name (see `evstwin scenarios`) or a TOML file")
    p.add_argument("-o", "--output", required=True, help="event file: .h5, .npz, .txt, .csv, .aedat4, .raw, .dat, .es")
    p.add_argument("--duration", type=float, help="sensor time [s] (default: the scenario's)")
    p.add_argument("--seed", type=int, help="random seed (default: the scenario's)")
    p.add_argument("--threads", type=int,
                   help="engine threads (default: the cores this process may use, less those other processes keep "
                        "busy as it starts; the events are the same for any count)")
    add_sets(p, "override one scenario value, e.g. pixel.theta_on=0.25 (repeatable)")
    p.add_argument("--labels", action="store_true",
                   help="also write why each event fired (0 signal, 1 shot_noise, 2 leak, 3 background, "
                        "4 hot_pixel) as a label column: .h5, .npz, .txt, .csv only")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_force(p)
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("scenarios", help="list the built-in scenarios")
    p.set_defaults(func=cmd_scenarios)


def cmd_simulate(args: argparse.Namespace) -> int:
    from ..simulate import simulate_to_file

    if args.threads is not None and args.threads < 1:
        raise ValueError(f"--threads must be >= 1; got {args.threads}")
    if args.duration is not None and not args.duration > 0:
        raise ValueError(f"--duration must be > 0 s; got {args.duration}")
    # Everything about the output is checked before a second of simulation is spent.
    check_output_file(args.output, args.force, "--output")
    result = simulate_to_file(
        args.scenario, args.output, duration_s=args.duration, seed=args.seed, num_threads=args.threads,
        sets=args.sets, progress=not args.no_progress, labels=args.labels,
    )
    print(f"wrote {args.output}")
    print(result.summary())
    return 0


def cmd_scenarios(args: argparse.Namespace) -> int:
    from ..scenario import builtin_names, load

    for name in builtin_names():
        s = load(name)
        print(f"{name:18s} {s.get('description', '')}")
    return 0
