"""Where the IMX636 point-source recording's OFF events come from, against a twin's
(``python bench/imx636_ghost_polarity.py [RAW] [--twin EVENTS]``; issue 10).

The recording (../shared/data/imx636_pointsource_evt3.raw) has 665,323 OFF events to 553,295
ON. This prints, for the recording and (``--twin``) for a simulated event file of the same
scene (``evstwin simulate imx636-pointsource -o twin.npz``; an ROI run's offset is read from
its metadata):

- **ghost window** (660, 320, 260 x 280): ON and OFF per second, and per 100 ms over the first
  and last 0.5 s, where the star's light curve has its largest excursions (its first 0.2 s and
  the slew at 10.6 s);
- **ghost, per radius** from its track (the star's line mirrored through the scenario's
  centre), in events per pixel per second, and per sector: ``lead`` (within 60 degrees of
  the ghost's motion), ``side``, ``trail``;
- **star image motion**: per 20 ms over 0-0.3 s, the centroids of the ON and of the OFF
  events within 30 px of the star's line, relative to it (a flux change puts both on the star;
  a moving image puts ON where it arrives and OFF where it leaves);
- **OFF by region**: the ghost window, the 200 x 200 star window, the rest; and per radius
  from the star outside the ghost window; at 150-300 px, per 30 degree sector about the star.

``--image-motion-scenario OUT.toml`` writes imx636-pointsource with the star's light curve
replaced by a steady 6e9 photons/s and its image motion as the field's path: the centroid of
all events within 25 px of the star's line per 10 ms, less the line, smoothed over 3 bins,
less its mean over 0-10.4 s (the slew included). Compare it on the star window.

``--dimmed-ghost K OUT.npz`` also simulates the ghost window (seed 0, one thread) with the
ghost's steady flux times exp(-K t), rescaled to the same mean: an OFF drift of ln I in the
ghost's pixels, the scenario-level stand-in for an OFF leak; then ``--twin OUT.npz`` reads it.
"""

from __future__ import annotations

import argparse

import numpy as np

STAR_T0_PX = (483.08, 287.11)
"""The star at t = 0 and its drift [px/s]: the scenario's (bench/make_imx636_pointsource.py)."""
STAR_V_PX_S = (-2.954, 3.428)
GHOST_CENTRE_PX = (642.08, 387.03)
"""The ghost's mirror centre and magnification (the scenario's, measured by measure_ghost)."""
GHOST_MAGNIFICATION = 0.819
GHOST_WINDOW = (660, 320, 260, 280)
STAR_WINDOW = (367, 205, 200, 200)
STEADY_END_S = 10.47
"""Radial and sector tables stop here, before the slew (the last 0.3 s)."""


Events = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def load(path: str, twin: bool) -> Events:
    """(t [s] from the first event or from 0 for a twin, x, y [sensor px], p) of a file."""
    if twin and path.endswith(".npz"):
        d = np.load(path)
        ev = d["events"]
        # an ROI run's offset: evstwin's metadata, or the keys simulate_dimmed_ghost writes
        x0 = next((int(d[k]) for k in ("meta/roi_x0_px", "roi_x0_px") if k in d.files), 0)
        y0 = next((int(d[k]) for k in ("meta/roi_y0_px", "roi_y0_px") if k in d.files), 0)
        t = ev["t"] / 1e6
    else:
        from evstwin.io import read_events

        ev = read_events(path)[0]
        x0 = y0 = 0
        t = (ev["t"] - (0 if twin else ev["t"][0])) / 1e6
    return t, ev["x"].astype(float) + x0, ev["y"].astype(float) + y0, np.asarray(ev["p"])


def star_track(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return STAR_T0_PX[0] + STAR_V_PX_S[0] * t, STAR_T0_PX[1] + STAR_V_PX_S[1] * t


def in_window(x: np.ndarray, y: np.ndarray, w: tuple[int, int, int, int]) -> np.ndarray:
    return (x >= w[0]) & (x < w[0] + w[2]) & (y >= w[1]) & (y < w[1] + w[3])


def report(name: str, ev: Events) -> None:
    t, x, y, p = ev
    on, off = p == 1, p == 0
    print(f"=== {name}: {on.sum()} ON, {off.sum()} OFF")
    g = in_window(x, y, GHOST_WINDOW)
    print(f"ghost window: ON {np.sum(g & on)}, OFF {np.sum(g & off)}, ON/OFF {np.sum(g & on) / max(np.sum(g & off), 1):.3f}")
    sec = np.minimum(t, 10.999).astype(int)
    print("  per second ON: ", np.bincount(sec[g & on], minlength=11).tolist())
    print("  per second OFF:", np.bincount(sec[g & off], minlength=11).tolist())
    for a in (0.0, 10.3):
        b = ((t - a) / 0.1).astype(int)
        m = g & (t >= a) & (t < a + 0.5)
        print(f"  per 100 ms from {a:.1f} s, ON {np.bincount(b[m & on], minlength=5)[:5].tolist()}"
              f" OFF {np.bincount(b[m & off], minlength=5)[:5].tolist()}")

    sx, sy = star_track(t)
    cx, cy = GHOST_CENTRE_PX
    gx, gy = cx - GHOST_MAGNIFICATION * (sx - cx), cy - GHOST_MAGNIFICATION * (sy - cy)
    dx, dy = x - gx, y - gy
    rg = np.hypot(dx, dy)
    keep = t < STEADY_END_S
    print("ghost per radius [px]: ON and OFF per pixel per second, ON/OFF")
    for r0 in range(0, 120, 8):
        m = keep & (rg >= r0) & (rg < r0 + 8)
        area = np.pi * ((r0 + 8) ** 2 - r0**2) * STEADY_END_S
        a, b = np.sum(m & on) / area, np.sum(m & off) / area
        print(f"  {r0:3d}-{r0 + 8:3d}  {a:.4f}  {b:.4f}  {a / b if b else float('nan'):.2f}")
    v = -GHOST_MAGNIFICATION * np.array(STAR_V_PX_S)
    cos = (dx * v[0] + dy * v[1]) / np.maximum(rg, 1e-9) / np.hypot(*v)
    print("ghost per sector (lead: within 60 deg of its motion), ON / OFF")
    for r0, r1 in ((0, 24), (24, 56), (56, 88), (88, 104)):
        row = []
        for label, s in (("lead", cos > 0.5), ("side", np.abs(cos) <= 0.5), ("trail", cos < -0.5)):
            m = keep & (rg >= r0) & (rg < r1) & s
            row.append(f"{label} {np.sum(m & on)}/{np.sum(m & off)}")
        print(f"  r {r0}-{r1}: " + ", ".join(row))

    centre = keep & (rg < 20.0) & off
    key = np.round(x[centre]).astype(np.int64) * 4096 + np.round(y[centre]).astype(np.int64)
    order = np.lexsort((t[centre], key))
    k_sorted, t_sorted = key[order], t[centre][order]
    _, first, count = np.unique(k_sorted, return_index=True, return_counts=True)
    cvs, gaps = [], []
    for i, n in zip(first, count):
        if n >= 4:
            dt = np.diff(t_sorted[i:i + n])
            cvs.append(dt.std() / dt.mean())
            gaps.extend(dt.tolist())
    if cvs:
        q = np.percentile(gaps, [1, 50])
        print(f"ghost centre (< 20 px), OFF intervals in the {len(cvs)} pixels with >= 4 OFF: median "
              f"{q[1]:.2f} s, 1st percentile {q[0]:.2f} s, median CV {np.median(cvs):.2f} (Poisson: 1)")

    rs = np.hypot(x - sx, y - sy)
    near = rs < 30.0
    print("star image, per 20 ms: ON and OFF counts within 30 px, their centroids less the star's line [px]")
    for k in range(15):
        m = near & (t >= 0.02 * k) & (t < 0.02 * (k + 1))
        cen = []
        for pol in (on, off):
            w = m & pol
            cen.append(f"({np.mean(x[w] - sx[w]):6.1f}, {np.mean(y[w] - sy[w]):6.1f})" if w.any() else "(  -  ,   -  )")
        print(f"  {0.02 * k:4.2f} s  ON {np.sum(m & on):5d} at {cen[0]}   OFF {np.sum(m & off):5d} at {cen[1]}")

    print("star image, per second: RMS distance between the ON and the OFF centroid of each 20 ms [px]")
    row = []
    for k in range(10):
        d2 = []
        for j in range(50):
            m = near & (t >= k + 0.02 * j) & (t < k + 0.02 * (j + 1))
            if np.sum(m & on) >= 20 and np.sum(m & off) >= 20:
                d2.append((np.mean(x[m & on]) - np.mean(x[m & off])) ** 2 + (np.mean(y[m & on]) - np.mean(y[m & off])) ** 2)
        row.append(f"{np.sqrt(np.mean(d2)):.1f}" if d2 else "-")
    print("  ", row)

    s = in_window(x, y, STAR_WINDOW) & ~g
    rest = ~g & ~s
    print("by region: ON / OFF")
    for label, m in (("ghost window", g), ("star window", s), ("rest", rest)):
        print(f"  {label:12s} {np.sum(m & on):8d} {np.sum(m & off):8d}")
    print("by radius from the star, ghost window left out: ON / OFF")
    edges = (0, 10, 20, 30, 40, 60, 80, 100, 120, 150, 200, 300, 500, 2000)
    for r0, r1 in zip(edges[:-1], edges[1:]):
        m = ~g & (rs >= r0) & (rs < r1)
        print(f"  {r0:4d}-{r1:4d} {np.sum(m & on):8d} {np.sum(m & off):8d}")
    m = ~g & (rs >= 150.0) & (rs < 300.0)
    motion_deg = np.degrees(np.arctan2(STAR_V_PX_S[1], STAR_V_PX_S[0]))
    rel = (np.degrees(np.arctan2(y - sy, x - sx)) - motion_deg + 180.0) % 360.0 - 180.0
    sector = ((rel[m] + 180.0) // 30.0).astype(int)
    print(f"150-300 px, per 30 deg sector from -180 (behind) to +180 about the star's motion ({motion_deg:.0f} deg): ON / OFF")
    print("   ON ", np.bincount(sector[on[m]], minlength=12)[:12].tolist())
    print("   OFF", np.bincount(sector[off[m]], minlength=12)[:12].tolist())


IMAGE_MOTION_BIN_S = 0.01
IMAGE_MOTION_SMOOTH_BINS = 3
IMAGE_MOTION_RADIUS_PX = 25.0


def write_image_motion_scenario(ev: Events, out: str, flux_ph_s: float = 6e9) -> None:
    """``image_motion_scenario`` of the built-in imx636-pointsource, written to ``out``."""
    from importlib.resources import files

    base = files("evstwin").joinpath("scenarios/imx636-pointsource.toml").read_text()
    with open(out, "w") as f:
        f.write(image_motion_scenario(ev, base, flux_ph_s))
    print(f"wrote {out}")


def image_motion_scenario(ev: Events, base: str, flux_ph_s: float) -> str:
    """The scenario text ``base`` with a steady star (its light curve replaced by
    ``flux_ph_s``) moved by the measured image motion as the field's path (docstring)."""
    import re

    t, x, y, _ = ev
    sx, sy = star_track(t)
    near = np.hypot(x - sx, y - sy) < IMAGE_MOTION_RADIUS_PX
    n = int(np.ceil(t[-1] / IMAGE_MOTION_BIN_S))
    b = np.minimum((t[near] / IMAGE_MOTION_BIN_S).astype(int), n - 1)
    count = np.maximum(np.bincount(b, minlength=n), 1)
    kernel = np.ones(IMAGE_MOTION_SMOOTH_BINS) / IMAGE_MOTION_SMOOTH_BINS
    pad = IMAGE_MOTION_SMOOTH_BINS // 2
    offsets = []
    for d in ((x - sx)[near], (y - sy)[near]):
        c = np.bincount(b, weights=d, minlength=n) / count
        c = np.convolve(np.pad(c, pad, mode="edge"), kernel, mode="valid")[:n]
        offsets.append(c - c[: int(STEADY_END_S / IMAGE_MOTION_BIN_S)].mean())
    t_mid = (np.arange(n) + 0.5) * IMAGE_MOTION_BIN_S
    print(f"image motion: RMS {offsets[0].std():.2f} px in x, {offsets[1].std():.2f} px in y")
    path = "path = {{ t_s = [{}], dx_px = [{}], dy_px = [{}] }}".format(
        ", ".join(f"{v:.3f}" for v in t_mid), ", ".join(f"{v:.2f}" for v in offsets[0]),
        ", ".join(f"{v:.2f}" for v in offsets[1]))
    text = re.sub(r"^path = \{.*\}$", lambda _: path, base, flags=re.M)
    text = re.sub(r"^light_curve = \{.*\}$", f"flux_ph_s = {flux_ph_s:g}", text, count=1, flags=re.M)
    return text.replace('name = "imx636-pointsource"', 'name = "imx636-pointsource-image-motion"')


def simulate_dimmed_ghost(k_per_s: float, out: str) -> None:
    """The ghost window of imx636-pointsource with the ghost's flux times exp(-k t) (same
    mean), seed 0, one thread, written as an .npz that ``--twin`` reads."""
    import dataclasses
    from importlib.resources import files

    import tomllib

    from evstwin.scenario import build
    from evstwin.simulate import _Runner
    from evstwin.targets import LightCurve, Target, with_psf

    @dataclasses.dataclass(frozen=True, eq=False)
    class Dimmed(Target):
        inner: Target
        curve: LightCurve
        label: str = "ghost"

        def __post_init__(self) -> None:
            object.__setattr__(self, "brightness", self.curve)

        def position_px(self, t_s: np.typing.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
            return self.inner.position_px(t_s)

        def velocity_px_s(self, t_s: np.typing.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
            return self.inner.velocity_px_s(t_s)

        def max_speed_px_s(self, t0_s: float, t1_s: float) -> float:
            return self.inner.max_speed_px_s(t0_s, t1_s)

        def flux_ph_s(self, t_s: np.typing.ArrayLike) -> np.ndarray:
            return self.curve(t_s)

    text = files("evstwin").joinpath("scenarios/imx636-pointsource.toml").read_text()
    table = tomllib.loads(text)
    table["sensor"]["roi"] = list(GHOST_WINDOW)
    scene = build(table)
    labels = [tg.label for tg in scene.targets]
    ghost = scene.targets[labels.index("ghost")]
    t = np.linspace(0.0, scene.duration_s, 1001)
    shape = np.exp(-k_per_s * t)
    mean = float(ghost.flux_ph_s(np.array([0.0]))[0])
    curve = LightCurve(t, mean * shape / (np.trapezoid(shape, t) / (t[-1] - t[0])))
    targets = list(scene.targets)
    targets[labels.index("ghost")] = with_psf(Dimmed(ghost, curve), ghost.psf)
    runner = _Runner(dataclasses.replace(scene, targets=targets), 1, truth_sink=lambda name, rows: None)
    ev = np.concatenate([e for e, _ in runner.chunks()])
    np.savez(out, events=ev, roi_x0_px=np.array(GHOST_WINDOW[0]), roi_y0_px=np.array(GHOST_WINDOW[1]))
    print(f"wrote {out}: {len(ev)} events, {int(np.sum(ev['p'] == 1))} ON, {int(np.sum(ev['p'] == 0))} OFF")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("raw", nargs="?", default="../shared/data/imx636_pointsource_evt3.raw")
    ap.add_argument("--twin", help="a simulated event file of imx636-pointsource (times from 0)")
    ap.add_argument("--dimmed-ghost", nargs=2, metavar=("K", "OUT"),
                    help="first simulate the ghost window with the ghost dimming as exp(-K t) into OUT (.npz)")
    ap.add_argument("--image-motion-scenario", metavar="OUT",
                    help="write the scenario with the star's image motion in place of its light curve (TOML)")
    a = ap.parse_args()
    if a.dimmed_ghost:
        simulate_dimmed_ghost(float(a.dimmed_ghost[0]), a.dimmed_ghost[1])
    real = load(a.raw, twin=False)
    if a.image_motion_scenario:
        write_image_motion_scenario(real, a.image_motion_scenario)
    report("real " + a.raw, real)
    if a.twin:
        report("twin " + a.twin, load(a.twin, twin=True))


if __name__ == "__main__":
    main()
