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
- **Slew**: the field's offset from that line over the last 0.2 s (``measure_slew``).
- **Ghost**: a disc of events that moves against the star (``measure_ghost``): its mirror
  centre, magnification and radius; its share of the star's light is an argument.
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

GHOST_FRACTION = 0.3
"""The ghost's share of the star's mean flux: set by hand for the ghost window's event count."""
GHOST_BLUR_SIGMA_PX = 12.0
"""The ghost disc's edge blur [px], the best of those tried on its window (`evstwin compare RAW
SCENARIO --roi 660,320,260,280`, seed 0; blur, share and radius: distance, worst bin): 8 px,
0.25, 86: 0.711, 3.4 %; 12 px, 0.3, 84: 0.574, 3.3 %; 16 px, 0.3, 80: 0.651, 4.2 %; 20 px,
0.3, 76: 0.785, 5.6 %; 25 px, 0.35, 70: 0.990, 8.7 %. A sharper rim puts too many events on
too few pixels, a softer one too few on too many."""
GHOST_RIM_PX = 4.0
"""Taken off the measured radius (where the events per pixel halve) so the blurred disc's
half-light radius stays near it."""


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

    ghost = measure_ghost(t, x, y, (x0, y0), (vx, vy))
    slew = measure_slew(t, x, y, (x0, y0), (vx, vy))

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
        "ghost": ghost,
        "slew": slew,
    }


SLEW_S = 0.2
"""The last seconds of the recording measured for the slew (it starts ~0.13 s before the end)."""
SLEW_BIN_S = 0.01


def measure_slew(t: np.ndarray, x: np.ndarray, y: np.ndarray, star0: tuple[float, float],
                 star_v: tuple[float, float]) -> dict[str, list[float]]:
    """The field's offset from its steady drift over the last SLEW_S seconds: the star's event
    centroid per 10 ms within 60 px of its line, less the line and less the centroid's own
    offset over the 0.3 s before (the halo's events are not centred on the star); the table
    starts at 0 offset SLEW_S before the end. The centroid of events lags a fast move a little
    (events come where the light changes), so the path is the light's, not the mount's."""
    end = float(t[-1])
    line_x = star0[0] + star_v[0] * t
    line_y = star0[1] + star_v[1] * t
    near = np.hypot(x - line_x, y - line_y) < 60.0
    before = near & (t >= end - SLEW_S - 0.3) & (t < end - SLEW_S)
    bias = (float(np.mean(x[before] - line_x[before])), float(np.mean(y[before] - line_y[before])))
    rows = [(end - SLEW_S, 0.0, 0.0)]
    for a in np.arange(end - SLEW_S, end - 1e-9, SLEW_BIN_S):
        m = near & (t >= a) & (t < a + SLEW_BIN_S)
        if m.sum() < 30:
            continue
        rows.append((float(a + SLEW_BIN_S / 2), float(np.mean(x[m] - line_x[m]) - bias[0]),
                     float(np.mean(y[m] - line_y[m]) - bias[1])))
    tab = np.array(rows)
    # Before the move the centroid wanders ~1 px per 10 ms bin from its events' own scatter
    # (a 30 px halo over ~600 events), which as a path would shake the whole field at
    # ~100 px/s: hold 0 until the first offset beyond 3 px (less one bin), and smooth the rest
    # over 3 bins.
    moved = np.flatnonzero(np.hypot(tab[:, 1], tab[:, 2]) > 3.0)
    start = max(1, int(moved[0]) - 1) if moved.size else tab.shape[0]
    tab[:start, 1:] = 0.0
    for c in (1, 2):
        smooth = np.convolve(np.pad(tab[:, c], 1, mode="edge"), np.ones(3) / 3.0, mode="valid")
        tab[start:, c] = smooth[start:]
    tab = np.vstack([tab[:1], tab[start - 1:]]) if start > 1 else tab
    return {"t_s": [round(float(v), 4) for v in tab[:, 0]], "dx_px": [round(float(v), 2) for v in tab[:, 1]],
            "dy_px": [round(float(v), 2) for v in tab[:, 2]]}


def measure_ghost(t: np.ndarray, x: np.ndarray, y: np.ndarray, star0: tuple[float, float],
                  star_v: tuple[float, float]) -> dict[str, object]:
    """The ghost near (780, 460): its event centroid per second (iterated within 110 px), a
    line through them (the last 0.3 s left out), the mirror that maps the star's line onto it
    (magnification m from the velocities, v_ghost = -m v_star; centre c from the positions,
    g0 = c - m (s0 - c)), and its radius: where the events per pixel about its line fall to
    half their mean inside 60 px (a blurred disc's edge)."""
    box = (x > 660) & (x < 920) & (y > 320) & (y < 600) & (t < t[-1] - 0.3)
    rows = []
    for k in range(int(t[-1] - 0.3)):
        m = box & (t >= k) & (t < k + 1)
        cx, cy = float(x[m].mean()), float(y[m].mean())
        for _ in range(5):
            w = m & (np.hypot(x - cx, y - cy) < 110)
            cx, cy = float(x[w].mean()), float(y[w].mean())
        rows.append((k + 0.5, cx, cy))
    g = np.array(rows)
    ax, ay = np.polyfit(g[:, 0], g[:, 1], 1), np.polyfit(g[:, 0], g[:, 2], 1)
    vs, s0 = np.array(star_v), np.array(star0)
    vg, g0 = np.array([ax[0], ay[0]]), np.array([ax[1], ay[1]])
    mag = float(-(vg @ vs) / (vs @ vs))
    centre = (g0 + mag * s0) / (1.0 + mag)
    keep = t < t[-1] - 0.3
    r = np.hypot(x[keep] - (ax[1] + ax[0] * t[keep]), y[keep] - (ay[1] + ay[0] * t[keep]))
    edges = np.arange(0.0, 150.0, 2.0)
    density = np.histogram(r, edges)[0] / (np.pi * np.diff(edges**2))
    inner = density[edges[1:] <= 60.0].mean()
    radius = float(edges[1:][np.argmax((edges[1:] > 60.0) & (density < 0.5 * inner))])
    return {"centre_px": [round(float(centre[0]), 2), round(float(centre[1]), 2)], "magnification": round(mag, 3),
            "radius_px": radius, "events_within_110_px": int(np.sum(r < 110.0))}


PIXEL_TABLES = """\
[pixel]
# The preset's photodiode constants are the DAVIS346's (0.24 % of photons collected); a BSI
# pixel collects far more. Silicon absorption near 700 nm and a 5 um collection depth give
# tau (1 - exp(-alpha W)) = 0.68 x 0.63 = 43 %, the range Prophesee quotes for the IMX636.
absorption_per_m = 2.0e5
depletion_width_m = 5.0e-6
# The preset's 10 Hz source follower is a DAVIS346 bias copied over; an IMX636 pixel lit by a
# bright star follows kHz changes (Prophesee's datasheet latency is ~100 us at 1000 lux).
# Dark pixels stay slow through the photoreceptor pole (pr_pole, current-dependent).
cutoff_hz = 2000.0
# Thresholds: the preset assumes ln(1.25) = 0.223 both ways; in a 200 x 200 window around the
# star the recording's ON/OFF ratio is 0.91, so theta_off is lower: 0.235 and 0.21, same mean.
theta_on = 0.235
theta_off = 0.21

[hot_pixels]
# The recording's hot pixel, 1170 Hz while active (the preset's telegraph duty 0.13 and
# 46 ms bursts apply): 1447 events in 10.77 s, measured by evstwin calibrate-noise. And its
# leaky pixel in the dark corner: 113 events, 111 ON, all but 6 of them in one second (5.2 to
# 6.3 s), with its own chain as `evstwin calibrate-noise RAW --roi 980,520,300,200` wrote it
# (engine rate 104.5 Hz, 103.1 Hz while active after the 130 us dead time; duty 0.10, bursts
# of 0.10 s: the rule splits that second at its longest intervals; ON 0.98 of its events, 4 %
# alternating).
pixels = [
    [187, 261, 1170.0],
    { x = 1224, y = 658, rate_hz = 104.5, duty = 0.1018, burst_s = 0.09983, on_share = 0.9823, alternation = 0.0354 },
]

"""
"""The scenario's [pixel] and [hot_pixels] tables, shared with bench/imx636_halo_trial.py."""


HEADER = """\
# The real recording ../shared/data/imx636_pointsource_evt3.raw (Prophesee EVK4, IMX636
# 1280 x 720, 10.77 s, 1,218,618 events: 553,295 ON, 665,323 OFF) as a scenario: a bright
# scintillating star with a seeing halo and diffraction spikes, two fainter field sources
# that move with it, the sensor's hot and leaky pixels and the imx636 preset's calibrated
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

""" + PIXEL_TABLES + """\
[sampling]
rate_hz = 200.0                 # the light curve has a point every 10 ms
"""


STAR_NOTE = """\
# The field drifts at the star's measured rate (a line through its event centroid per 20 ms,
# the last 0.3 s left out: the mount slews away there, given apart as star_field.path).
# The star: mean flux 6e9 photons/s at the pupil (1.7 nW at 0.7 um; V = -3.4 on this 0.2 m
# aperture: planet-bright, or a nanowatt artificial source), its light curve the recording's
# own scintillation: per 20 ms, ln I rises by 1.3 theta per ON event and falls by 1.3 theta per
# OFF event of the average pixel within 5 px of the star, less its 1 s running mean (the 1.3
# makes up for what the pixel's bandwidth and dead time hide; fitted on the 200 x 200 window).
# Part of it is image motion, not flux: per 20 ms the star's ON and OFF events lie 13-21 px
# apart on opposite sides of it (README, "Where the OFF events come from"); a flux flicker
# stands for it here, which is why the ghost does not share this curve.
# The companions: the two next brightest sources, (80, -54) and (-91, +66) px from the star
# all along the run (both move with it), 3e8 photons/s each (V = -0.2), steady.
"""


def to_toml(res: dict[str, object], flux_ph_s: float, companions_ph_s: tuple[float, float],
            header: str = "", body: str = "", ghost_fraction: float = GHOST_FRACTION) -> str:
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
    slew = res["slew"]
    assert isinstance(slew, dict)
    out.append(SLEW_NOTE)
    out.append(f"[star_field]\ndrift_px_s = {res['drift_px_s']!r}\n"
               f"path = {{ t_s = {slew['t_s']!r}, dx_px = {slew['dx_px']!r}, dy_px = {slew['dy_px']!r} }}\n")
    out.append("[[targets]]\nkind = \"static\"\nlabel = \"star\"\nframe = \"field\"\n"
               f"x_px = {sx}\ny_px = {sy}\n"
               f"light_curve = {{ t_s = [{times}], flux_ph_s = [{flux}] }}\n")
    for k, ((cx, cy), f) in enumerate(zip(comp, companions_ph_s)):
        out.append(f"[[targets]]\nkind = \"static\"\nlabel = \"companion{k + 1}\"\nframe = \"field\"\n"
                   f"x_px = {cx}\ny_px = {cy}\nflux_ph_s = {f:.4g}\n")
    g = res["ghost"]
    assert isinstance(g, dict)
    out.append(GHOST_NOTE.format(fraction=ghost_fraction, blur=GHOST_BLUR_SIGMA_PX, **g))
    out.append("[[targets]]\nkind = \"ghost\"\nlabel = \"ghost\"\nof = \"star\"\n"
               f"centre_x_px = {g['centre_px'][0]}\ncentre_y_px = {g['centre_px'][1]}\n"
               f"magnification = {g['magnification']}\nflux_fraction = {ghost_fraction:g}\nsteady = true\n"
               f"defocus_radius_px = {g['radius_px'] - GHOST_RIM_PX:g}\n"
               f"defocus_blur_sigma_px = {GHOST_BLUR_SIGMA_PX:g}\n"
               "defocus_obstruction_ratio = 0.0\ndefocus_spider_vanes = 0\n")
    return "\n".join(out)


SLEW_NOTE = """\
# The slew: in the last ~0.13 s the mount moves the field ~19 px up in ~50 ms (~38,000 events in
# 0.1 s). star_field.path is the field's offset from its drift over the last 0.2 s, the star's
# event centroid per 10 ms less the line, 0 until it moves, smoothed over 3 bins (measure_slew);
# every field target follows it, and the ghost mirrors it.
"""


GHOST_NOTE = """\
# The ghost: a disc of events about (780, 460) that moves against the star, a reflection of it
# focused far from the sensor. Measured (measure_ghost): mirrored through ({centre_px[0]}, {centre_px[1]})
# with magnification {magnification}, radius {radius_px:g} px (half its inner events per pixel),
# no obstruction or vane shadows, {events_within_110_px} events within 110 px of it.
# steady: its events come at a steady ~6,000/s all through the run, ON ahead of its motion and
# OFF behind it (python bench/imx636_ghost_polarity.py), with no trace of the star's light-curve
# excursions (x17 at 0.07 s, the slew's rise at 10.6 s). Those excursions are mostly the star's
# image moving (its ON and OFF events lie 10-35 px apart, on opposite sides), which a wide, dim
# (slow) ghost does not follow; sharing the curve, the ghost fired 64,000 of its 65,800 events
# in those two bursts. So the ghost keeps {fraction:g} of the star's mean flux, steady; its
# events then come from its drift over the pixels. The share is set by hand for the window's
# count (evstwin compare RAW imx636-pointsource --roi 660,320,260,280: 66,444 against 65,662,
# seed 0); it is not a reflectance: with the preset's assumed dark current (18,000 e-/s, the
# DAVIS346's) a disc this wide must bring ~2x the dark current per pixel for its edge to fire.
# A flat disc (blur {blur:g} px) fires at its rim, where the real ghost also fires inside.
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("raw", nargs="?", default="../shared/data/imx636_pointsource_evt3.raw")
    ap.add_argument("--gain", type=float, default=1.0)
    ap.add_argument("--theta", type=float, default=float(np.log(1.25)))
    ap.add_argument("-o", "--out", default="-", help="JSON output (default stdout)")
    ap.add_argument("--toml", help="write the scenario here")
    ap.add_argument("--flux", type=float, default=6e9, help="the star's mean flux [photons/s]")
    ap.add_argument("--companion-flux", type=float, nargs=2, default=(3e8, 3e8))
    ap.add_argument("--ghost-fraction", type=float, default=GHOST_FRACTION,
                    help="the ghost's share of the star's mean light")
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
            f.write(to_toml(res, a.flux, tuple(a.companion_flux), HEADER.replace("{gain}", f"{a.gain:g}"), STAR_NOTE,
                            a.ghost_fraction))


if __name__ == "__main__":
    main()
