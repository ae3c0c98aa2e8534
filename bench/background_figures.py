"""The README's background figures (issue 9): the leak's transient at t = 0 where shot noise
fires as often as the leak, and the IMX636 preset's dark background.

    python bench/background_figures.py
"""

from __future__ import annotations

import numpy as np

from evstwin import PixelParams, Sensor, simulate

LEAK = 2  # evstwin._core.EVENT_LABELS: 2 = leak


def leak_transient(theta_on: float, theta_off: float) -> tuple[int, float]:
    """Leak events in the first 2 s of a dark 32 x 32 scene, and their mean per later 2 s."""
    params = PixelParams(pr_pole=True, theta_on=theta_on, theta_off=theta_off, leak_rate_hz=0.5,
                         shot_noise_rate_hz=0.2)
    sensor = Sensor(32, 32, params, seed=1, num_threads=1)
    counts = np.zeros(10, np.int64)
    for k in range(20):  # 20 s in 1 s chunks at 250 Hz
        t = np.arange(k * 250, (k + 1) * 250 + (k == 19)) / 250.0
        ev = sensor.run(np.zeros((len(t), 32, 32)), t)
        leak = ev["t"][sensor.last_labels() == LEAK]
        counts += np.histogram(leak / 1e6, bins=10, range=(0.0, 20.0))[0]
    return int(counts[0]), float(counts[1:].mean())


def main() -> None:
    for on, off in ((0.2, 0.15), (0.1, 0.07)):
        first, later = leak_transient(on, off)
        print(f"theta {on} / {off}: leak events in the first 2 s {first}, later 2 s on average {later:.0f} "
              f"({(first / later - 1) * 100:+.0f} %)")
    scenario = {"name": "dark", "duration_s": 10.77, "sensor": {"preset": "imx636", "width": 300, "height": 200},
                "sampling": {"rate_hz": 250.0}}
    r = simulate(scenario, num_threads=2)
    on = int(np.sum(r.events["p"] == 1))
    n = 300 * 200 * 10.77
    print(f"imx636 preset, dark 300 x 200 window, 10.77 s: ON {on / n:.3g} Hz, OFF {(len(r.events) - on) / n:.3g} Hz "
          "per pixel")


if __name__ == "__main__":
    main()
