"""``evstwin characterize PRESET``: the twin through the vendors' datasheet tests."""

from __future__ import annotations

import argparse
import json
from typing import Any

from ._common import add_force, check_output_dir, staged_folder


def register(sub: Any) -> None:
    p = sub.add_parser("characterize",
                       help="run a preset's twin through the datasheet tests (latency, background, low-light cutoff, "
                            "contrast threshold) beside the published figures")
    p.add_argument("preset", help="sensor preset (davis346, imx636, prophesee_gen3_vga, davis346_paper)")
    p.add_argument("--out", default="characterize", help="output folder (default ./characterize): characterize.txt, "
                                                         "characterize.json and characterize.png")
    p.add_argument("--lux", help="illuminances at the focal plane [lux], v1,v2,... (default 0.01 to 10000)")
    p.add_argument("--size-px", type=int, default=32, help="pixels a side of the simulated array (default 32)")
    p.add_argument("--seed", type=int, default=0, help="first seed (default 0)")
    p.add_argument("--bias", dest="biases", action="append", default=[], metavar="NAME=VALUE",
                   help="a Prophesee preset's bias in the vendor's name and unit, e.g. bias_diff_on=+40 (IMX636: "
                        "code offset from the factory default; Gen3 VGA: mV); repeatable")
    p.add_argument("--threads", type=int, help="engine threads (default: the engine's choice)")
    p.add_argument("--no-figure", action="store_true", help="skip characterize.png (no matplotlib needed)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_force(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from ..characterize import DEFAULT_LUX, characterize, plot_characterization
    from ..presets import get_preset
    from ..tune.limits import parse_float_list

    preset = get_preset(args.preset)
    biases: dict[str, float] = {}
    for item in args.biases:
        name, _, value = item.partition("=")
        try:  # a missing '=' leaves value empty: float('') fails too
            if not name.strip():
                raise ValueError
            biases[name.strip()] = float(value)
        except ValueError:
            raise ValueError(f"--bias takes NAME=VALUE with a number (e.g. bias_diff_on=+40); got {item!r}") from None
    lux = DEFAULT_LUX if args.lux is None else tuple(parse_float_list(args.lux, "--lux"))
    if args.threads is not None and args.threads < 1:
        raise ValueError(f"--threads must be >= 1; got {args.threads}")
    out = check_output_dir(args.out, args.force)
    if not args.no_figure:
        from .._extras import require

        require("matplotlib", "characterize.png (or pass --no-figure)")
    bar: Any = None
    if not args.no_progress:
        from tqdm import tqdm

        bar = tqdm(total=1, desc=f"characterize {preset.name}", unit="run", leave=False)

    def progress(done: int, total: int) -> None:
        if bar is not None:
            bar.total = total
            bar.n = done
            bar.refresh()

    try:
        result = characterize(preset, lux=lux, size_px=args.size_px, seed=args.seed, num_threads=args.threads,
                              progress=progress, biases=biases)
    finally:
        if bar is not None:
            bar.close()
    text = result.to_text()
    with staged_folder(out) as stage:  # written whole or not at all
        (stage.path / "characterize.txt").write_text(text + "\n")
        (stage.path / "characterize.json").write_text(json.dumps(result.to_dict(), indent=1, allow_nan=True) + "\n")
        if not args.no_figure:
            plot_characterization(result, stage.path / "characterize.png")
    print(text)
    print(f"wrote {out}/characterize.txt, characterize.json" + ("" if args.no_figure else " and characterize.png"))
    return 0
