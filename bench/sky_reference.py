"""How far evstwin.sky's frames are from published values (the figures in the README's "The
sky" section): the ISS from Bluffton against Skyfield's documented example, satellite 00005
against Vallado et al. (2006), and the two built-in sky scenarios' passes.

    python bench/sky_reference.py
"""

from __future__ import annotations

import math
from datetime import datetime, timezone

import numpy as np

from evstwin import scenario
from evstwin.sky import earth, iers, orbit
from evstwin.sky import scene as sky_scene


def main() -> None:
    iss = orbit.Elements("1 25544U 98067A   14020.93268519  .00009878  00000-0  18200-3 0  5082",
                         "2 25544  51.6498 109.4756 0003572  55.9686 274.8005 15.49815350868473")
    when = datetime(2014, 1, 23, 11, 18, 7, tzinfo=timezone.utc)
    o = orbit.observe(iss, earth.Site(40.8939, -83.8917, 0.0), when, [0.0], iers.ut1_utc_s(when))
    print(f"UT1 - UTC then: {iers.ut1_utc_s(when):+.4f} s ({iers.source()})")
    ref = {"el": 16 + 16 / 60 + 32.6 / 3600, "az": 350 + 15 / 60 + 20.4 / 3600, "range": 1168.7,
           "ra_h": 3 + 20 / 60 + 22.42 / 3600, "dec": 63 + 58 / 60 + 45.2 / 3600}
    print("ISS from Bluffton, 2014-01-23 11:18:07 UTC, against Skyfield's documentation:")
    print(f"  elevation {o.el_deg[0]:.6f} deg, ref {ref['el']:.6f}: {3600 * (o.el_deg[0] - ref['el']):+.2f} arcsec")
    print(f"  azimuth   {o.az_deg[0]:.6f} deg, ref {ref['az']:.6f}: {3600 * (o.az_deg[0] - ref['az']):+.2f} arcsec")
    print(f"  range     {o.range_km[0]:.3f} km, ref {ref['range']} (printed to 0.1 km)")
    print(f"  RA        {o.ra_deg[0] / 15:.6f} h, ref (true equinox of date) {ref['ra_h']:.6f}: "
          f"{3600 * (o.ra_deg[0] / 15 - ref['ra_h']):+.2f} s of time (TEME's mean equinox: minus the "
          "equation of the equinoxes)")
    print(f"  Dec       {o.dec_deg[0]:.6f} deg, ref {ref['dec']:.6f}: {3600 * (o.dec_deg[0] - ref['dec']):+.2f} arcsec")
    e5 = orbit.Elements("1 00005U 58002B   00179.78495062  .00000023  00000-0  28098-4 0  4753",
                        "2 00005  34.2682 348.7242 1859667 331.7664  19.3264 10.82419157413667")
    jd = e5.epoch_jd
    r, _ = orbit.propagate_teme(e5, [math.floor(jd)], [jd - math.floor(jd) + 0.25])
    ref5 = np.array([-7154.03120202, -3783.17682504, -3536.19412294])
    print(f"00005 at 360 min (Vallado et al. 2006): |r - ref| = {1e3 * np.linalg.norm(r[0] - ref5):.3f} m")
    for name in ("leo-pass", "geo-belt"):
        s = scenario.load(name)
        scene = scenario.build(s)
        sky = sky_scene.build_sky(s, scene.optics, scene.width, scene.height, scene.duration_s,
                                  scene.psf.half_width_px + 2.0)
        sat = sky.info["satellites"][0]
        fov = [math.degrees(v) for v in scene.optics.field_of_view_rad]
        print(f"{name}: {scene.optics.plate_scale_arcsec_per_px:.2f} arcsec/px, field {fov[0]:.2f} x {fov[1]:.2f} deg; "
              f"{sat['label']}: highest elevation {sat['max_el_deg']:.1f} deg, nearest {sat['min_range_km']:.0f} km, "
              f"V {sat['mag_min']:.2f} to {sat['mag_max']:.2f} (with extinction), up to {sat['max_rate_deg_s']:.3f} deg/s, "
              f"on the sensor {100 * sat['on_sensor_fraction']:.0f} % of the run; Sun at {sky.info['sun_el_deg']:.1f} deg; "
              f"{sky.info['stars_kept']} stars; position table every {sky.info['table_step_s']:g} s "
              f"(interpolation error {sky.info['table_error_px']:.2g} px)")


if __name__ == "__main__":
    main()
