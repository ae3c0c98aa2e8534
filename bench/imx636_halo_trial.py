"""The IMX636 point-source recording against a twin with a scattered-light halo, image motion
and a pre-roll (issue 10): ``python bench/imx636_halo_trial.py --write OUT.toml`` writes the
trial scenario, ``python bench/imx636_halo_trial.py --radial TWIN [TWIN ...]`` prints the
per-radius table below for the recording and for simulated files.

The trial scenario is ``imx636-pointsource`` with:

- ``[optics]``: the seeing as a Moffat (``--seeing-fwhm``, ``--seeing-beta``) in place of the
  Airy pattern blurred by 8 px, and a halo (``--halo-fraction``, ``--halo-fwhm``,
  ``--halo-beta``, on a 512 px window);
- the star steady at ``--flux`` photons/s, moved by its image motion (the event centroid per
  10 ms within 25 px of its track, ``imx636_ghost_polarity.write_image_motion_scenario``) in
  place of its flux flicker; the companions at ``--companion-flux``; the ghost at the same
  absolute flux as in the built-in scenario;
- ``[sampling] pre_roll_s`` (``--pre-roll``, at 20 Hz): the halo's pixels 200 px out drift by a
  threshold in ~10 s, and without a pre-roll they start silent.

The table: for rings about the star's mid-run position (outside the ghost's window, before the
slew at 10.47 s), the ON and OFF events per pixel per second and the share of pixels with 0, 1,
2-3, 4-7 and 8+ events (the bins the issue's goal counts are 0-1, 2-3, ... events).
"""

from __future__ import annotations

import argparse
import re
import tempfile

import numpy as np
from imx636_ghost_polarity import (
    GHOST_WINDOW,
    STAR_T0_PX,
    STAR_V_PX_S,
    in_window,
    load,
    write_image_motion_scenario,
)

RAW = "../shared/data/imx636_pointsource_evt3.raw"
WIDTH, HEIGHT = 1280, 720
STEADY_END_S = 10.47
RING_EDGES_PX = (0, 5, 10, 20, 30, 45, 60, 80, 100, 130, 160, 200, 250, 300, 400, 500, 700, 2000)
BUILTIN_GHOST_PH_S = 1.8e9
"""The built-in scenario's ghost: 0.3 of the star's 6e9 photons/s mean; kept in the trial."""


def write_trial(out: str, a: argparse.Namespace) -> None:
    real = load(a.raw, twin=False)
    with tempfile.NamedTemporaryFile("w", suffix=".toml") as tmp:
        write_image_motion_scenario(real, tmp.name, a.flux)
        text = open(tmp.name).read()
    optics = (f'psf = "moffat"\nmoffat_fwhm_px = {a.seeing_fwhm:g}\nmoffat_beta = {a.seeing_beta:g}\n'
              f"psf_half_width_px = 128\nhalo_fraction = {a.halo_fraction:g}\nhalo_fwhm_px = {a.halo_fwhm:g}\n"
              f"halo_beta = {a.halo_beta:g}\nhalo_half_width_px = 512\n")
    text, n = re.subn(r'^psf = "airy"\n(?:.*\n)*?psf_half_width_px = 128[^\n]*\n', optics, text, count=1, flags=re.M)
    assert n == 1, "the built-in scenario's [optics] changed: update this script"
    if a.motion_scale != 1.0:
        text = re.sub(r"^path = \{.*\}$", lambda m: scaled_path(m.group(0), a.motion_scale), text, count=1, flags=re.M)
    text = re.sub(r"^flux_ph_s = 3e\+08$", f"flux_ph_s = {a.companion_flux:g}", text, flags=re.M)
    text = re.sub(r"^flux_fraction = .*$", f"flux_fraction = {BUILTIN_GHOST_PH_S / a.flux:.4g}", text, flags=re.M)
    text = text.replace("[sampling]\n", f"[sampling]\npre_roll_s = {a.pre_roll:g}\npre_roll_rate_hz = 20.0\n", 1)
    text = text.replace('name = "imx636-pointsource-image-motion"', 'name = "imx636-pointsource-halo-trial"')
    with open(out, "w") as f:
        f.write(text)
    print(f"wrote {out}")


def scaled_path(line: str, scale: float) -> str:
    """The path's offsets before the slew times ``scale``: the event centroid moves less than the
    image (ON and OFF events fall on both sides of it), as the flicker's gain made up for."""
    m = re.match(r"path = \{ t_s = \[(.*)\], dx_px = \[(.*)\], dy_px = \[(.*)\] \}", line)
    assert m is not None
    t, dx, dy = (np.array([float(v) for v in g.split(",")]) for g in m.groups())
    before = t < STEADY_END_S
    dx[before] *= scale
    dy[before] *= scale
    return "path = {{ t_s = [{}], dx_px = [{}], dy_px = [{}] }}".format(
        ", ".join(f"{v:.3f}" for v in t), ", ".join(f"{v:.2f}" for v in dx), ", ".join(f"{v:.2f}" for v in dy))


def rings(path: str, twin: bool) -> None:
    t, x, y, p = load(path, twin)
    keep = t < STEADY_END_S
    xi, yi, p = x[keep].astype(np.int64), y[keep].astype(np.int64), p[keep]
    on = np.bincount(yi[p == 1] * WIDTH + xi[p == 1], minlength=WIDTH * HEIGHT)
    off = np.bincount(yi[p == 0] * WIDTH + xi[p == 0], minlength=WIDTH * HEIGHT)
    total = on + off
    xs, ys = np.meshgrid(np.arange(WIDTH), np.arange(HEIGHT))
    mid = STEADY_END_S / 2
    r = np.hypot(xs - (STAR_T0_PX[0] + STAR_V_PX_S[0] * mid), ys - (STAR_T0_PX[1] + STAR_V_PX_S[1] * mid)).ravel()
    outside = ~in_window(xs, ys, GHOST_WINDOW).ravel()
    print(f"=== {path}: rings about the star's mid-run position, outside the ghost window, t < {STEADY_END_S} s")
    print(f"{'r [px]':>9s} {'pixels':>7s} {'ON/px/s':>8s} {'OFF/px/s':>8s}   0     1    2-3   4-7   8+")
    for lo, hi in zip(RING_EDGES_PX[:-1], RING_EDGES_PX[1:]):
        m = outside & (r >= lo) & (r < hi)
        c = total[m]
        shares = [np.mean(c == 0), np.mean(c == 1), np.mean((c >= 2) & (c < 4)), np.mean((c >= 4) & (c < 8)),
                  np.mean(c >= 8)]
        print(f"{lo:4d}-{hi:<4d} {int(m.sum()):7d} {on[m].mean() / STEADY_END_S:8.4f} {off[m].mean() / STEADY_END_S:8.4f}  "
              + " ".join(f"{v:.3f}" for v in shares))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--raw", default=RAW)
    ap.add_argument("--write", metavar="OUT", help="write the trial scenario (TOML)")
    ap.add_argument("--radial", nargs="*", metavar="TWIN", help="print the rings for the recording and these files")
    ap.add_argument("--flux", type=float, default=3.6e10, help="the star [photons/s]")
    ap.add_argument("--companion-flux", type=float, default=1.5e8)
    ap.add_argument("--seeing-fwhm", type=float, default=14.0)
    ap.add_argument("--seeing-beta", type=float, default=2.5)
    ap.add_argument("--halo-fraction", type=float, default=0.417)
    ap.add_argument("--halo-fwhm", type=float, default=100.0)
    ap.add_argument("--halo-beta", type=float, default=1.5)
    ap.add_argument("--pre-roll", type=float, default=12.0)
    ap.add_argument("--motion-scale", type=float, default=1.0,
                    help="the image motion before the slew times this (the centroid understates it)")
    a = ap.parse_args()
    if a.write:
        write_trial(a.write, a)
    if a.radial is not None:
        rings(a.raw, twin=False)
        for path in a.radial:
            rings(path, twin=True)


if __name__ == "__main__":
    main()
