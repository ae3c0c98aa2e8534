"""Does a leak explain the IMX636 recording's OFF excess? (issue 10; ``python
bench/imx636_leak_check.py [--twin FILE X0 Y0] [--currents] [--dark]``).

Prints, for ../shared/data/imx636_pointsource_evt3.raw (and, with ``--twin FILE X0 Y0``, for a
simulated file whose pixel (0, 0) is the sensor's (X0, Y0), as ``evstwin compare --roi``
writes them):

- ON and OFF per pixel per second in rings about the star's line and the ghost's track
  (0-10.47 s, before the slew);
- ``--currents``: the twin's mean photocurrent there (imx636-pointsource rendered at t = 5 s,
  e-/s without the dark current), what a leak proportional to the photocurrent follows;
- ``--dark``: whether the dark background's OFF events are a leak or Poisson: the per-pixel
  OFF count histogram of the dark corner (980, 520, 300 x 200) and of the empty left strip
  (0, 0, 240 x 720), fitted by maximum likelihood with a log-normal rate spread (sigma free,
  mean the observed) under two models: Poisson counts (eq. 12) or a leak, which fires
  floor(r T + U) times (U the uniform random phase); and the intervals' CV of the pixels
  with >= 3 OFF events.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from scipy import optimize, stats

sys.path.insert(0, str(Path(__file__).parent))
import imx636_ghost_polarity as ghost  # noqa: E402

RAW = "../shared/data/imx636_pointsource_evt3.raw"
STAR_RINGS_PX = [(0, 3), (3, 10), (10, 20), (20, 40), (40, 80), (80, 130)]
GHOST_RINGS_PX = [(0, 24), (24, 50), (50, 70), (70, 84), (84, 100)]
DARK_WINDOWS = {"dark corner": (980, 520, 300, 200), "left strip": (0, 0, 240, 720)}
DURATION_S = 10.77


def tracks(t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    sx, sy = ghost.star_track(t)
    cx, cy = ghost.GHOST_CENTRE_PX
    m = ghost.GHOST_MAGNIFICATION
    return sx, sy, cx - m * (sx - cx), cy - m * (sy - cy)


def rings(name: str, path: str, offset: tuple[float, float]) -> None:
    t, x, y, p = ghost.load(path, twin=not path.endswith(".raw"))
    x, y = x + offset[0], y + offset[1]
    keep = t < ghost.STEADY_END_S
    t, x, y, p = t[keep], x[keep], y[keep], p[keep]
    sx, sy, gx, gy = tracks(t)
    print(f"=== {name}: ON / OFF per pixel per second, 0-{ghost.STEADY_END_S} s")
    for label, (ox, oy), table in (("star", (sx, sy), STAR_RINGS_PX), ("ghost", (gx, gy), GHOST_RINGS_PX)):
        r = np.hypot(x - ox, y - oy)
        for r0, r1 in table:
            s = (r >= r0) & (r < r1)
            area = np.pi * (r1 * r1 - r0 * r0) * ghost.STEADY_END_S
            on, off = int(np.sum(s & (p == 1))), int(np.sum(s & (p == 0)))
            print(f"  {label:5s} r {r0:3d}-{r1:3d} px: ON {on / area:8.4f}  OFF {off / area:8.4f}  "
                  f"ON/OFF {on / max(off, 1):.3f}")


def currents() -> None:
    """The twin's photo-electron rate per pixel at t = 5 s in the same rings."""
    from evstwin import scenario
    from evstwin.presets import ELEMENTARY_CHARGE_C
    from evstwin.simulate import _Runner

    sc = scenario.build("imx636-pointsource")
    run = _Runner(sc, 1, lambda *a: None)
    t = np.array([5.0])
    frame = run.frames(t)
    photo = frame[0] * sc.params.electrons_per_photon
    sx, sy, gx, gy = tracks(t)
    yy, xx = np.mgrid[0 : sc.height, 0 : sc.width]
    print(f"=== twin photocurrent at t = 5 s [e-/s; dark current {sc.params.dark_rate_e_per_s:g} e-/s, "
          f"1 e-/s = {ELEMENTARY_CHARGE_C:.4g} A]")
    for label, (ox, oy), table in (("star", (sx[0], sy[0]), STAR_RINGS_PX), ("ghost", (gx[0], gy[0]), GHOST_RINGS_PX)):
        r = np.hypot(xx - ox, yy - oy)
        for r0, r1 in table:
            v = photo[(r >= r0) & (r < r1)]
            print(f"  {label:5s} r {r0:3d}-{r1:3d} px: median {np.median(v):10.4g}  mean {v.mean():10.4g}")


def dark() -> None:
    t, x, y, p = ghost.load(RAW, twin=False)
    z, wz = np.polynomial.hermite_e.hermegauss(80)
    wz = wz / wz.sum()
    for name, (x0, y0, w, h) in DARK_WINDOWS.items():
        s = (x >= x0) & (x < x0 + w) & (y >= y0) & (y < y0 + h) & (p == 0)
        idx = ((y[s] - y0) * w + (x[s] - x0)).astype(np.int64)
        counts = np.bincount(idx, minlength=w * h)
        hot = counts > 20  # the few hot pixels (calibrate-noise flags them) apart
        c = counts[~hot]
        hist = np.bincount(c)
        mean = c.mean()
        print(f"=== {name} {x0},{y0},{w},{h}: OFF counts per pixel {hist.tolist()} "
              f"({int(hot.sum())} hot pixels left out), mean {mean / DURATION_S:.3e} Hz")

        def pmf(sigma: float, model: str, mean: float = mean, kmax: int = int(c.max())) -> np.ndarray:
            lam = mean * np.exp(sigma * z - 0.5 * sigma * sigma)
            k = np.arange(kmax + 1)[:, None]
            if model == "poisson":
                prob = stats.poisson.pmf(k, lam[None, :])
            else:
                whole = np.floor(lam)
                frac = lam - whole
                prob = (k == whole[None, :]) * (1 - frac)[None, :] + (k == whole[None, :] + 1) * frac[None, :]
            return np.asarray((prob * wz[None, :]).sum(1))

        for model in ("poisson", "leak"):
            def nll(sigma: float, model: str = model) -> float:
                return float(-(hist * np.log(np.maximum(pmf(sigma, model)[: hist.size], 1e-300))).sum())

            best = optimize.minimize_scalar(nll, bounds=(0.01, 4.0), method="bounded")
            expect = (pmf(best.x, model)[:5] * c.size).round(1).tolist()
            print(f"  {model:7s}: sigma {best.x:.2f}, -ln L {best.fun:9.1f}, expected pixels with 0-4 events {expect}")
        tt, order = t[s], np.lexsort((t[s], idx))
        ii, ts = idx[order], tt[order]
        cvs = [np.diff(ts[ii == k]).std() / np.diff(ts[ii == k]).mean() for k in np.nonzero((counts >= 3) & ~hot)[0]]
        if cvs:
            print(f"  {len(cvs)} pixels with >= 3 OFF: interval CV median {np.median(cvs):.2f} (two exponential "
                  "intervals give 0.5, a leak's ~0)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--twin", nargs=3, metavar=("FILE", "X0", "Y0"), help="a simulated file and its ROI corner")
    ap.add_argument("--currents", action="store_true", help="the twin's photocurrent in the same rings")
    ap.add_argument("--dark", action="store_true", help="the dark background's OFF counts: leak or Poisson")
    args = ap.parse_args()
    rings("real", RAW, (0.0, 0.0))
    if args.twin:
        rings(f"twin {args.twin[0]}", args.twin[0], (float(args.twin[1]), float(args.twin[2])))
    if args.currents:
        currents()
    if args.dark:
        dark()


if __name__ == "__main__":
    main()
