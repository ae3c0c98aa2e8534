"""Cost of the PSF shapes: building a tabulated PSF, and ``render_frames`` per source and sample.

    python bench/bench_psf.py

50 samples of 10 sources at random positions on a 346 x 260 DAVIS346 frame (the call also
fills each frame with the background: that is most of the Gaussian's time). Best of 3. Then a
halo added to a 1280 x 720 frame as ``simulate`` does it (one slice) and through the general
path (flat indices and a bincount).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from evstwin import psf
from evstwin.psf import halo
from evstwin.scenario import build


def main() -> None:
    rng = np.random.default_rng(0)
    n_t, n_s, width, height = 50, 10, 346, 260
    x = rng.uniform(40, 300, (n_t, n_s))
    y = rng.uniform(40, 220, (n_t, n_s))
    flux = np.full((n_t, n_s), 1e5)
    geo = build("geo-stare").optics
    cases: dict[str, Callable[[], psf.PSFShape]] = {
        "gaussian, geo-stare (sigma 0.70 px)": lambda: psf.from_optics(geo),
        "airy, geo-stare + 4 vanes (lambda N 0.15 px, blur 0.7 px)": lambda: psf.from_optics(
            geo.replace(psf="airy", spider_vanes=4)),
        "moffat, geo-stare, FWHM 2 arcsec, beta 4.765": lambda: psf.from_optics(
            geo.replace(psf="moffat", moffat_fwhm_arcsec=2.0)),
        "moffat, FWHM 3 px, beta 2.5": lambda: psf.moffat_psf(3.0, 2.5),
        "airy, lambda N 1.5 px": lambda: psf.airy_psf(1.5),
        "airy, lambda N 4 px": lambda: psf.airy_psf(4.0),
        "gaussian + halo (FWHM 15 px, beta 1.5), h 128": lambda: psf.from_optics(
            geo.replace(halo_fraction=0.5, halo_fwhm_px=15.0, halo_half_width_px=128)),
        "gaussian + halo (FWHM 15 px, beta 1.5), h 256": lambda: psf.from_optics(
            geo.replace(halo_fraction=0.5, halo_fwhm_px=15.0, halo_half_width_px=256)),
    }
    print(f"{'shape':58s} {'h':>4s} {'build s':>8s} {'us per source-sample':>21s}")
    for name, make in cases.items():
        for cached in (halo._from_optics, halo.halo_psf, halo._composite):
            cached.cache_clear()  # time each build
        t0 = time.perf_counter()
        shape = make()
        built = time.perf_counter() - t0
        best = np.inf
        for _ in range(3):
            t0 = time.perf_counter()
            psf.render_frames(width, height, x, y, flux, shape)
            best = min(best, time.perf_counter() - t0)
        print(f"{name:58s} {shape.half_width_px:4d} {built:8.3f} {best / (n_t * n_s) * 1e6:21.1f}")


def halos_in_frames() -> None:
    """A halo the way ``simulate`` adds one (``KernelPSF.add_dense``, one slice of the frame)
    against the general path (flat indices and a bincount), one source on a 1280 x 720 frame."""
    from evstwin.psf.render import _accumulate

    width, height = 1280, 720
    print(f"\n{'halo on a 1280 x 720 frame, one source':58s} {'h':>4s} {'slice ms':>9s} {'indices ms':>11s}")
    for h in (128, 256, 512):
        shape = psf.halo_psf(60.0, 1.5, h)
        frame = np.zeros((height, width))
        n = 20
        t0 = time.perf_counter()
        for i in range(n):
            shape.add_dense(frame, 640.3 + 0.01 * i, 360.6, 1e10)
        dense = (time.perf_counter() - t0) / n
        t0 = time.perf_counter()
        for i in range(n):
            for idx, w in shape.contributions(width, height, np.array([640.3 + 0.01 * i]), np.array([360.6]),
                                              np.array([1e10])):
                _accumulate(frame.reshape(-1), idx, w)
        general = (time.perf_counter() - t0) / n
        print(f"{'FWHM 60 px, beta 1.5':58s} {h:4d} {dense * 1e3:9.2f} {general * 1e3:11.2f}")


if __name__ == "__main__":
    main()
    halos_in_frames()
