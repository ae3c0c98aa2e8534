"""How a slow leak under noise starts: leak events in the first seconds against f_leak.

Each pixel starts at its steady-state leak phase (PixelModel::init, weighted by the cycle's
survival against the noise). This prints, for the full DAVIS346 preset under a static scene,
the leak-labelled events of the first DURATION seconds and of the first 0.5 s as a ratio to
f_leak x pixels x time (1.0 = stationary from t = 0), over several seeds.

    python bench/leak_start.py                      # 2.95e-3 and 0.01 Hz, daylight and dim
    python bench/leak_start.py --leak 0.003 --photon-rate 1e9 --seeds 8
"""

from __future__ import annotations

import argparse

import numpy as np

import evstwin

LEAK_LABEL = next(code for code, name in evstwin.EVENT_LABELS.items() if name == "leak")


def leak_ratio(leak_hz: float, photon_rate: float, duration_s: float, seeds: int) -> tuple[float, float, float]:
    """(ratio over duration_s, its Poisson sd, ratio over the first 0.5 s) for the DAVIS346 preset."""
    w, h = evstwin.presets.DAVIS346.width, evstwin.presets.DAVIS346.height
    n_all = n_early = 0
    for seed in range(seeds):
        scenario = {"name": "leak-start", "duration_s": duration_s, "seed": seed,
                    "sensor": {"preset": "davis346"}, "background": {"photon_rate_ph_s": photon_rate},
                    "pixel": {"leak_rate_hz": leak_hz, "leak_rate_sigma": 0.0}, "sampling": {"rate_hz": 200.0}}
        result = evstwin.simulate(scenario, labels=True)
        leak = result.labels == LEAK_LABEL
        n_all += int(np.count_nonzero(leak))
        n_early += int(np.count_nonzero(leak & (result.events["t"] < 500_000)))
    expected = seeds * w * h * duration_s * leak_hz
    return n_all / expected, np.sqrt(n_all) / expected, n_early / (expected * 0.5 / duration_s)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--leak", type=float, nargs="*", default=[2.95e-3, 0.01], help="leak rates [Hz]")
    ap.add_argument("--photon-rate", type=float, nargs="*", default=[2e10, 1e8], help="photons/s per pixel")
    ap.add_argument("--duration", type=float, default=2.0, help="sensor seconds per run")
    ap.add_argument("--seeds", type=int, default=4)
    args = ap.parse_args()
    print(f"DAVIS346 preset, {args.seeds} seeds x {args.duration} s; ratio = leak events / (f_leak px t)")
    for leak_hz in args.leak:
        for photon_rate in args.photon_rate:
            r, sd, early = leak_ratio(leak_hz, photon_rate, args.duration, args.seeds)
            print(f"f_leak {leak_hz:g} Hz, {photon_rate:g} ph/s: first {args.duration:g} s {r:.3f} +- {sd:.3f}, "
                  f"first 0.5 s {early:.3f}")


if __name__ == "__main__":
    main()
