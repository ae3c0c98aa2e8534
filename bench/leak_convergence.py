"""The light-dependent OFF leak's event rate at two samplings, 4x apart (issue 10's convergence
check): ``python bench/leak_convergence.py [--rate-hz 200] [--seconds 10]``.

The scene is the IMX636 ghost's case: the imx636 preset's pixel (photoreceptor pole, shot
noise, its dark background) with ``leak_polarity = "off"`` and a leak that grows with the
photocurrent, under a disc of light ~2x the dark current drifting at 3.7 px/s over a
160 x 120 patch (its rim fires signal events, its inside leaks). Printed per sampling rate:
the events of each polarity and the leak-labelled ones, with their Poisson errors, and how
many sigma apart the two samplings are. A model whose statistics depend on the sampling
would show it here.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from evstwin import Sensor
from evstwin.presets import IMX636
from evstwin.sensor import EVENT_LABELS

E_C = 1.602176634e-19
LEAK_PHOTOCURRENT_HZ_PER_A = 4.7e13
"""The ghost-calibrated slope (README, "Where the OFF events come from")."""


def run(rate_hz: float, seconds: float, seed: int) -> dict[str, int]:
    params = IMX636.pixel.replace(leak_polarity="off", leak_photocurrent_hz_per_a=LEAK_PHOTOCURRENT_HZ_PER_A,
                                  absorption_per_m=2.0e5, depletion_width_m=5.0e-6)
    w, h = 160, 120
    # A disc bringing 2x the dark current's electrons, 40 px in radius, blurred by 6 px.
    photo_e_s = 2.0 * params.dark_rate_e_per_s
    ph_s = photo_e_s / params.electrons_per_photon
    yy, xx = np.mgrid[0:h, 0:w]
    n = round(seconds * rate_hz)
    t = np.arange(n + 1) / rate_hz
    sensor = Sensor(w, h, params, seed=seed, num_threads=1)
    leak = next(code for code, name in EVENT_LABELS.items() if name == "leak")
    counts = {"on": 0, "off": 0, "leak": 0}
    chunk = max(1, round(0.25 * rate_hz))
    for a in range(0, n + 1, chunk):
        tt = t[a : a + chunk]
        cx = 60.0 + 3.0 * tt
        cy = 60.0 + 2.2 * tt
        r = np.hypot(xx[None] - cx[:, None, None], yy[None] - cy[:, None, None])
        disc = 0.5 * (1.0 - np.tanh((r - 40.0) / 6.0))
        ev = sensor.run(ph_s * disc + 1e-3, tt)
        labels = sensor.last_labels()
        counts["on"] += int(np.count_nonzero(ev["p"] == 1))
        counts["off"] += int(np.count_nonzero(ev["p"] == 0))
        counts["leak"] += int(np.count_nonzero(labels == leak))
    return counts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rate-hz", type=float, default=200.0, help="the coarse sampling rate [Hz]; the fine one is 4x")
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    results = {}
    for rate in (args.rate_hz, 4.0 * args.rate_hz):
        t0 = time.perf_counter()
        results[rate] = run(rate, args.seconds, args.seed)
        c = results[rate]
        print(f"{rate:7.0f} Hz sampling: ON {c['on']} +- {math.sqrt(c['on']):.0f}, OFF {c['off']} +- "
              f"{math.sqrt(c['off']):.0f}, leak-labelled {c['leak']} +- {math.sqrt(c['leak']):.0f} "
              f"({time.perf_counter() - t0:.1f} s)")
    a, b = results[args.rate_hz], results[4.0 * args.rate_hz]
    for k in ("on", "off", "leak"):
        z = (b[k] - a[k]) / math.sqrt(max(1, a[k] + b[k]))
        print(f"{k}: fine / coarse {b[k] / max(1, a[k]):.4f}, {z:+.2f} sigma (independent draws' Poisson error)")


if __name__ == "__main__":
    main()
