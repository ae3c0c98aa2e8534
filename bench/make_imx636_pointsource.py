"""Measure the IMX636 point-source recording and write the numbers the built-in scenario
``imx636-pointsource`` is made of: the star's track, the companions' offsets and the star's
scintillation light curve (``python bench/make_imx636_pointsource.py [RAW] [--toml OUT]``).

The recording (../shared/data/imx636_pointsource_evt3.raw, 10.77 s) is a bright star on a
dark field, drifting. What the script measures:

- **Track**: the event centroid per 20 ms in a 24 px box that follows the star from (481, 292),
  then a least-squares line (weighted by the events per bin) over the whole recording less its
  last 0.3 s, where the mount slews away: the field's drift ``drift_px_s`` and the star's
  position at t = 0.
- **Companions**: the event centroid per second in a 16 px box around each of the two next
  brightest sources, their offset from the star's line averaged over 2-9 s (both move with the
  star: they belong to the field).
- **Light curve**: the star's own flux is not constant: the pixels within 5 px of its track fire
  ~45 events/s each, both polarities, far more than a steady star drifting at 4.5 px/s gives.
  That is scintillation and seeing. Per 20 ms bin k the mean ON and OFF counts per core pixel,
  ``on_k`` and ``off_k``, give a zig-zag in ln I: up by ``gain * theta * on_k``, then down by
  ``gain * theta * off_k``; the zig-zag's running drift (a 1 s moving mean of its level) is
  taken out so that the flux stays about its mean, as scintillation does. ``gain`` (printed
  and written as an argument) absorbs what the pixel's bandwidth and refractory period hide.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

DT_S = 0.02
"""Light-curve and centroid bin [s]."""


def measure(path: str, gain: float, theta: float) -> dict[str, object]:
    from evstwin.io import read_events

    ev = read_events(path)[0]
    t = (ev["t"] - ev["t"][0]) / 1e6
    x = ev["x"].astype(float)
    y = ev["y"].astype(float)
    p = ev["p"]
    n_bins = int(np.ceil(t[-1] / DT_S))
    near = (np.abs(x - 470) < 40) & (np.abs(y - 305) < 40)
    tn, xn, yn = t[near], x[near], y[near]
    px, py = 481.0, 292.0
    rows = []
    for k in range(n_bins):
        m = (tn >= k * DT_S) & (tn < (k + 1) * DT_S)
        w = m & (np.abs(xn - px) < 12) & (np.abs(yn - py) < 12)
        if w.sum() >= 30:
            px, py = float(xn[w].mean()), float(yn[w].mean())
            rows.append((k * DT_S + DT_S / 2, px, py, float(w.sum())))
    tr = np.array(rows)
    fit = tr[:, 0] < t[-1] - 0.3
    wts = np.sqrt(tr[fit, 3])
    ax = np.polyfit(tr[fit, 0], tr[fit, 1], 1, w=wts)
    ay = np.polyfit(tr[fit, 0], tr[fit, 2], 1, w=wts)
    vx, x0 = float(ax[0]), float(ax[1])
    vy, y0 = float(ay[0]), float(ay[1])

    companions = []
    for cx, cy in ((561.0, 236.0), (389.0, 357.0)):
        offs = []
        for k in range(2, 9):
            sx, sy = x0 + vx * (k + 0.5), y0 + vy * (k + 0.5)
            qx, qy = cx + sx - x0, cy + sy - y0
            m = (t >= k) & (t < k + 1) & (np.abs(x - qx) < 16) & (np.abs(y - qy) < 16)
            for _ in range(4):
                w = m & (np.abs(x - qx) < 8) & (np.abs(y - qy) < 8)
                qx, qy = float(x[w].mean()), float(y[w].mean())
            offs.append((qx - sx, qy - sy))
        ox, oy = np.mean(offs, axis=0)
        companions.append((x0 + float(ox), y0 + float(oy)))

    r = np.hypot(x - (x0 + vx * t), y - (y0 + vy * t))
    core = r < 5.0
    b = np.minimum((t[core] / DT_S).astype(int), n_bins - 1)
    npx = np.pi * 25.0
    on = np.bincount(b[p[core] == 1], minlength=n_bins) / npx
    off = np.bincount(b[p[core] == 0], minlength=n_bins) / npx
    step = gain * theta
    level = np.zeros(2 * n_bins + 1)
    level[1::2] = step * on
    level[2::2] = -step * off
    level = np.cumsum(level)
    times = np.arange(2 * n_bins + 1) * DT_S / 2
    kernel = np.ones(int(round(1.0 / (DT_S / 2)))) / round(1.0 / (DT_S / 2))
    pad = len(kernel) // 2
    drift = np.convolve(np.pad(level, pad, mode="edge"), kernel, mode="same")[pad:pad + level.size]
    ln_rel = level - drift
    ln_rel -= np.log(np.mean(np.exp(ln_rel)))  # mean flux 1
    return {
        "drift_px_s": [round(vx, 3), round(vy, 3)],
        "star_t0_px": [round(x0, 2), round(y0, 2)],
        "companions_t0_px": [[round(a, 2), round(c, 2)] for a, c in companions],
        "light_curve_t_s": [round(float(v), 3) for v in times],
        "light_curve_rel": [round(float(v), 4) for v in np.exp(ln_rel)],
        "core_events_per_px": float((on + off).sum()),
    }


HEADER = """\
# The real recording ../shared/data/imx636_pointsource_evt3.raw (Prophesee EVK4, IMX636
# 1280 x 720, 10.77 s, 1,218,618 events: 553,295 ON, 665,323 OFF) as a scenario: a bright
# scintillating star with a seeing halo and diffraction spikes, two fainter field sources
# that move with it, the sensor's hot pixel at (187, 261) and the imx636 preset's calibrated
# dark background. Written by `python bench/make_imx636_pointsource.py --gain {gain} --toml
# OUT` (the numbers below were measured from the recording by that script; the README's
# "A real point-source recording" gives how close it gets and what it leaves out).
name = "imx636-pointsource"
description = "Bright scintillating star drifting (-3.0, +3.4) px/s on a dark IMX636 field (EVK4 recording)"
duration_s = 10.77
seed = 0

[sensor]
preset = "imx636"

[optics]
# Assumed: a 0.2 m f/14 telescope (no header says what the EVK4 was on). lambda N = 2.0 px
# at 0.7 um, so diffraction (the obstruction's rings and the spider's spikes) is resolved.
focal_length_m = 2.8
f_number = 14.0
psf = "airy"
obstruction_ratio = 0.3
spider_vanes = 4
spider_width_ratio = 0.02       # 4 mm vanes on a 0.2 m pupil
# Seeing: the real event map is flat out to ~20 px from the star and falls by 10x between
# 30 and 55 px; sigma 8 px (39 um, ~2.9 arcsec at f = 2.8 m, poor seeing) fits that profile.
extra_blur_sigma_px = 8.0
psf_half_width_px = 128         # the halo's events reach ~100 px from the star

[pixel]
# The preset's photodiode constants are the DAVIS346's (0.24 % of photons collected); a BSI
# pixel collects far more. Silicon absorption near 700 nm and a 5 um collection depth give
# tau (1 - exp(-alpha W)) = 0.68 x 0.63 = 43 %, the range Prophesee quotes for the IMX636.
absorption_per_m = 2.0e5
depletion_width_m = 5.0e-6
# The preset's 10 Hz source follower is a DAVIS346 bias copied over; an IMX636 pixel lit by a
# bright star follows kHz flicker (Prophesee's datasheet latency is ~100 us at 1000 lux).
# 2 kHz lets the star's 50 Hz scintillation through; dark pixels stay slow through the
# photoreceptor pole (pr_pole, current-dependent), so the dark background is unchanged.
cutoff_hz = 2000.0
# Thresholds: the preset assumes ln(1.25) = 0.223 both ways. In a 200 x 200 window around the
# star the recording's ON/OFF ratio is 0.91 under a light curve that returns to its mean,
# so theta_off is lower than theta_on: 0.235 (a 26.5 % step) and 0.21 (23 %), same mean.
theta_on = 0.235
theta_off = 0.21

[hot_pixels]
# The recording's hot pixel, 1170 Hz while active (the preset's telegraph duty 0.13 and
# 46 ms bursts apply): 1447 events in 10.77 s, measured by evstwin calibrate-noise.
pixels = [[187, 261, 1170.0]]

[sampling]
rate_hz = 200.0                 # the light curve has a point every 10 ms
"""


STAR_NOTE = """\
# The field drifts at the star's measured rate (a line through its event centroid per 20 ms,
# the last 0.3 s left out: the mount slews away there and the scene does not model it).
# The star: mean flux 6e9 photons/s at the pupil (1.7 nW at 0.7 um; V = -3.4 on this 0.2 m
# aperture: planet-bright, or a nanowatt artificial source), its light curve the recording's
# own scintillation: per 20 ms, ln I rises by 1.3 theta per ON event and falls by 1.3 theta per
# OFF event of the average pixel within 5 px of the star, less its 1 s running mean (the 1.3
# makes up for what the pixel's bandwidth and dead time hide; fitted on the 200 x 200 window).
# The companions: the two next brightest sources, (80, -54) and (-91, +66) px from the star
# all along the run (both move with it), 3e8 photons/s each (V = -0.2), steady.
"""


def to_toml(res: dict[str, object], flux_ph_s: float, companions_ph_s: tuple[float, float],
            header: str = "", body: str = "") -> str:
    """The scenario: ``header`` (comments and tables before the targets) then the measured
    drift, the star with its light curve and the two companions (field frame)."""
    t = res["light_curve_t_s"]
    rel = res["light_curve_rel"]
    assert isinstance(t, list) and isinstance(rel, list)
    flux = ", ".join(f"{flux_ph_s * float(v):.4g}" for v in rel)
    times = ", ".join(f"{float(v):.3f}" for v in t)
    (sx, sy) = res["star_t0_px"]  # type: ignore[misc]
    comp = res["companions_t0_px"]
    assert isinstance(comp, list)
    out = [header, body]
    out.append(f"[star_field]\ndrift_px_s = {res['drift_px_s']!r}\n")
    out.append("[[targets]]\nkind = \"static\"\nlabel = \"star\"\nframe = \"field\"\n"
               f"x_px = {sx}\ny_px = {sy}\n"
               f"light_curve = {{ t_s = [{times}], flux_ph_s = [{flux}] }}\n")
    for k, ((cx, cy), f) in enumerate(zip(comp, companions_ph_s)):
        out.append(f"[[targets]]\nkind = \"static\"\nlabel = \"companion{k + 1}\"\nframe = \"field\"\n"
                   f"x_px = {cx}\ny_px = {cy}\nflux_ph_s = {f:.4g}\n")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("raw", nargs="?", default="../shared/data/imx636_pointsource_evt3.raw")
    ap.add_argument("--gain", type=float, default=1.0)
    ap.add_argument("--theta", type=float, default=float(np.log(1.25)))
    ap.add_argument("-o", "--out", default="-", help="JSON output (default stdout)")
    ap.add_argument("--toml", help="write the scenario here")
    ap.add_argument("--flux", type=float, default=6e9, help="the star's mean flux [photons/s]")
    ap.add_argument("--companion-flux", type=float, nargs=2, default=(3e8, 3e8))
    a = ap.parse_args()
    res = measure(a.raw, a.gain, a.theta)
    text = json.dumps(res)
    if a.out == "-":
        print(text)
    else:
        with open(a.out, "w") as f:
            f.write(text)
    print({k: v for k, v in res.items() if not k.startswith("light_curve")}, flush=True)
    if a.toml:
        with open(a.toml, "w") as f:
            f.write(to_toml(res, a.flux, tuple(a.companion_flux), HEADER.replace("{gain}", f"{a.gain:g}"), STAR_NOTE))


if __name__ == "__main__":
    main()
