"""Defocused sources and lens ghosts: psf.defocus_psf, targets.MirroredTarget / with_psf, the
scenario's ``kind = "ghost"`` and ``defocus_radius_px``, and their rendering in simulate."""

from __future__ import annotations

import math

import numpy as np
import pytest

import evstwin
from evstwin import psf
from evstwin.scenario import ScenarioError, build
from evstwin.targets import LinearTarget, MirroredTarget, StaticTarget, drifting, shifted, with_psf

NOISE_FREE = {"photon_shot_noise": False, "dark_model": "none", "leak_rate_hz": 0.0, "shot_noise_rate_hz": 0.0,
              "refractory_s": 0.0, "pr_pole": False}


@pytest.mark.parametrize("eps", [0.0, 0.3])
def test_defocus_psf_is_the_pupil_disc_with_its_flux(eps: float) -> None:
    # Without blur or vanes the encircled energy of a uniform annulus of radii eps R and R is
    # (r^2 - eps^2 R^2) / (R^2 (1 - eps^2)) between them; pixelisation blurs it by ~1 px.
    radius = 20.0
    shape = psf.defocus_psf(radius, obstruction_ratio=eps)
    cx, cy = 60.3, 59.6
    img = psf.render_points(120, 120, np.array([cx]), np.array([cy]), np.array([1.0]), shape)
    assert img.sum() == pytest.approx(1.0, abs=1e-12)
    yy, xx = np.mgrid[0:120, 0:120]
    r = np.hypot(xx - cx, yy - cy)
    for rr in (10.0, 15.0, 19.0):
        want = max(0.0, rr * rr - (eps * radius) ** 2) / (radius**2 * (1 - eps**2))
        assert img[r < rr].sum() == pytest.approx(want, abs=2.5 / radius)
    assert img[r > radius + 1.5].sum() == 0.0
    if eps:
        assert img[r < eps * radius - 1.5].sum() == 0.0  # the obstruction's shadow is dark


def test_defocus_psf_vanes_shadow_their_share_and_blur_spreads_it() -> None:
    radius, width = 30.0, 0.05
    open_disc = psf.defocus_psf(radius).fine.sum()
    vanes = psf.defocus_psf(radius, spider_vanes=4, spider_width_ratio=width)
    # The fine table is normalised: compare the shadowed area through the peak value instead.
    shadow = 4 * (2 * width * radius) * radius / (math.pi * radius**2)  # 4 bars of width 2 w R, length R
    assert vanes.max_pixel_share == pytest.approx(psf.defocus_psf(radius).max_pixel_share / (1 - shadow), rel=0.05)
    assert open_disc == pytest.approx(1.0)
    blurred = psf.defocus_psf(radius, extra_blur_sigma_px=3.0)
    assert blurred.half_width_px > psf.defocus_psf(radius).half_width_px
    with pytest.raises(ValueError, match="defocus_radius_px must be in"):
        psf.defocus_psf(0.1)
    with pytest.raises(ValueError, match="obstruction_ratio must be in"):
        psf.defocus_psf(5.0, obstruction_ratio=1.0)


def test_a_mirrored_target_moves_against_its_source_with_its_share_of_the_light() -> None:
    star = drifting(StaticTarget(100.0, 50.0, 2e6, label="star"), -3.0, 4.0)
    ghost = MirroredTarget(star, 640.0, 360.0, magnification=0.75, flux_fraction=0.05)
    t = np.array([0.0, 2.0])
    x, y = ghost.position_px(t)
    np.testing.assert_allclose(x, 640.0 - 0.75 * (np.array([100.0, 94.0]) - 640.0))
    np.testing.assert_allclose(y, 360.0 - 0.75 * (np.array([50.0, 58.0]) - 360.0))
    np.testing.assert_allclose(ghost.velocity_px_s(1.0), (2.25, -3.0))
    assert ghost.max_speed_px_s(0.0, 1.0) == pytest.approx(0.75 * 5.0)
    np.testing.assert_allclose(ghost.flux_ph_s(t), 1e5)
    with pytest.raises(ValueError, match="flux_fraction must be in"):
        MirroredTarget(star, 0.0, 0.0, flux_fraction=0.0)


def test_own_psf_survives_the_wrappers() -> None:
    shape = psf.defocus_psf(4.0)
    star = with_psf(StaticTarget(10.0, 10.0, 1e6), shape)
    assert star.psf is shape and StaticTarget(10.0, 10.0, 1e6).psf is None
    assert drifting(star, 1.0, 0.0).psf is shape and shifted(star, -2.0, 3.0).psf is shape
    assert shifted(drifting(with_psf(LinearTarget(0, 0, 1, 1, 1e6), shape), 1.0, 1.0), 1.0, 1.0).psf is shape


def ghost_scenario(sparse: bool = True, chunk: int = 50, noise: bool = False) -> dict:
    return {"name": "g", "duration_s": 0.4, "seed": 2, "sensor": {"preset": "davis346", "width": 96, "height": 64},
            "background": {"photon_rate_ph_s": 3.5e7}, "pixel": {} if noise else dict(NOISE_FREE),
            "optics": {"extra_blur_sigma_px": 0.8, "obstruction_ratio": 0.3},
            "sampling": {"rate_hz": 200.0, "sparse": sparse, "chunk_samples": chunk},
            "targets": [{"kind": "linear", "label": "star", "x0_px": 20.0, "y0_px": 20.0, "vx_px_s": 60.0,
                         "vy_px_s": 20.0, "flux_ph_s": 1e9},
                        {"kind": "ghost", "of": "star", "centre_x_px": 47.5, "centre_y_px": 31.5,
                         "magnification": 0.8, "flux_fraction": 0.5, "defocus_radius_px": 6.0,
                         "defocus_blur_sigma_px": 0.5}]}


def test_a_scenario_ghost_is_rendered_through_its_own_defocused_psf() -> None:
    scene = build(ghost_scenario())
    ghost = scene.targets[1]
    assert isinstance(ghost, MirroredTarget) and ghost.psf is not None and ghost.psf.kind == "defocus"
    assert scene.targets[0].psf is None
    sparse = evstwin.simulate(ghost_scenario(sparse=True))
    dense = evstwin.simulate(ghost_scenario(sparse=False))
    assert sparse.sub_sampled_chunks > 0
    assert sparse.events.tobytes() == dense.events.tobytes()  # noise-free: the same events either way
    # Its events come where its light changes: at the 6 px edge of the defocused disc, which
    # sweeps over the pixels (the inside is uniform), seen a source-follower lag behind it
    # (10 Hz: ~16 ms, 0.8 px at the ghost's 50 px/s); a point source would fire at its centre.
    focused = ghost_scenario()
    del focused["targets"][1]["defocus_radius_px"], focused["targets"][1]["defocus_blur_sigma_px"]
    for result, low, high in ((sparse, 5.0, 9.0), (evstwin.simulate(focused), 0.0, 2.5)):
        ev, truth = result.events, result.meta["truth"]
        t = ev["t"] / 1e6
        d_ghost = np.hypot(ev["x"] - np.interp(t, truth["ghost"]["t_s"], truth["ghost"]["x_px"]),
                           ev["y"] - np.interp(t, truth["ghost"]["t_s"], truth["ghost"]["y_px"]))
        d_star = np.hypot(ev["x"] - np.interp(t, truth["star"]["t_s"], truth["star"]["x_px"]),
                          ev["y"] - np.interp(t, truth["star"]["t_s"], truth["star"]["y_px"]))
        on_ghost = d_ghost < d_star
        assert np.sum(on_ghost) > 50
        assert low < np.median(d_ghost[on_ghost]) < high
    for chunk in (7, 1000):  # and the chunking changes nothing
        assert evstwin.simulate(ghost_scenario(chunk=chunk)).events.tobytes() == sparse.events.tobytes()


@pytest.mark.parametrize(("change", "message"), [
    ({"of": "nobody"}, "of='nobody' must name exactly one earlier target"),
    ({"of": 3}, "targets\\[1\\].of must be the label of an earlier target"),
    ({"flux_ph_s": 1e6}, "unknown scenario key 'targets\\[1\\].flux_ph_s' for kind 'ghost'"),
    ({"frame": "field"}, "unknown scenario key 'targets\\[1\\].frame' for kind 'ghost'"),
    ({"flux_fraction": 2.0}, "flux_fraction must be in \\(0, 1\\]"),
    ({"defocus_radius_px": 500.0}, "defocus_radius_px must be in \\[0.5, 120\\]"),
])
def test_bad_ghosts_get_one_clear_line(change: dict, message: str) -> None:
    s = ghost_scenario()
    s["targets"][1].update(change)
    with pytest.raises(ScenarioError, match=message):
        build(s)


def test_a_ghost_needs_its_source_and_share() -> None:
    s = ghost_scenario()
    del s["targets"][1]["flux_fraction"]
    with pytest.raises(ScenarioError, match="a ghost\\) needs flux_fraction"):
        build(s)
    s = ghost_scenario()
    s["targets"][0]["defocus_blur_sigma_px"] = 1.0
    with pytest.raises(ScenarioError, match="defocus_blur_sigma_px needs targets\\[0\\].defocus_radius_px"):
        build(s)


def test_a_ghost_keeps_its_share_of_a_light_curve_through_the_wrappers() -> None:
    from evstwin.targets import LightCurve

    star = StaticTarget(10.0, 10.0, LightCurve(np.array([0.0, 1.0]), np.array([1e6, 3e6])), label="star")
    ghost = MirroredTarget(star, 50.0, 50.0, flux_fraction=0.1)
    for t in (ghost, shifted(ghost, -5.0, 7.0), drifting(ghost, 1.0, 1.0)):
        np.testing.assert_allclose(t.flux_ph_s([0.0, 0.5, 1.0]), [1e5, 2e5, 3e5])


def test_a_steady_ghost_keeps_its_share_of_the_mean_flux() -> None:
    from evstwin.targets import LightCurve, mean_flux_ph_s

    # linear between points: (1 + 3) / 2 over the first second, 3 over the next two -> 8/3 e6
    curve = LightCurve(np.array([0.0, 1.0, 3.0]), np.array([1e6, 3e6, 3e6]))
    assert mean_flux_ph_s(curve) == pytest.approx(8e6 / 3.0)
    # linear in ln: the mean of 1e6 exp(t) over [0, 1] is (e - 1) 1e6
    assert mean_flux_ph_s(LightCurve(np.array([0.0, 1.0]), np.array([1e6, math.e * 1e6]), log_interp=True)) == \
        pytest.approx((math.e - 1.0) * 1e6)
    assert mean_flux_ph_s(LightCurve(np.array([2.0]), np.array([5e5]))) == 5e5 and mean_flux_ph_s(7.0) == 7.0
    star = StaticTarget(10.0, 10.0, curve, label="star")
    ghost = MirroredTarget(star, 50.0, 50.0, flux_fraction=0.1, steady=True)
    assert ghost.brightness == pytest.approx(8e5 / 3.0)
    for t in (ghost, shifted(ghost, -5.0, 7.0), drifting(ghost, 1.0, 1.0)):
        np.testing.assert_allclose(t.flux_ph_s([0.0, 0.5, 2.0, 9.0]), 8e5 / 3.0)
    with pytest.raises(ValueError, match="steady must be True or False; got steady=1"):
        MirroredTarget(star, 0.0, 0.0, steady=1)  # type: ignore[arg-type]


def steady_ghost_scenario(steady: bool) -> dict:
    """A still star whose light triples at 0.2 s and its ghost, noise-free."""
    s = ghost_scenario()
    s["targets"][0] = {"kind": "static", "label": "star", "x_px": 20.0, "y_px": 20.0,
                       "light_curve": {"t_s": [0.0, 0.2, 0.21, 0.4], "flux_ph_s": [1e10, 1e10, 3e10, 3e10]}}
    s["targets"][1]["steady"] = steady
    return s


def test_a_steady_ghost_stays_dark_where_a_sharing_one_fires() -> None:
    # Nothing moves: with its light steady, no pixel of the ghost's disc may fire (noise-free).
    # Sharing the star's x3 step, each pixel of its inside goes from B + G to B + 3 G, with
    # G = 0.5 x 1e10 / (pi 6^2) = 4.4e7 and the background B = 3.5e7 photons/s: ln(1.68e8 /
    # 7.9e7) = 0.755 = 3.7 theta_on (0.206), so 3 ON events a pixel (2 to 4 allowed: the
    # blurred rim and the source follower's lag).
    gx, gy = 47.5 - 0.8 * (20.0 - 47.5), 31.5 - 0.8 * (20.0 - 31.5)
    yy, xx = np.mgrid[0:64, 0:96]
    n_inside = int(np.sum(np.hypot(xx - gx, yy - gy) < 4.0))
    counts = {}
    for steady in (False, True):
        ev = evstwin.simulate(steady_ghost_scenario(steady)).events
        inside = np.hypot(ev["x"] - gx, ev["y"] - gy) < 4.0
        counts[steady] = int(np.sum(inside))
        assert np.all(ev["p"][inside] == 1)  # only a rise, if anything
    assert counts[True] == 0
    assert 2 * n_inside <= counts[False] <= 4 * n_inside
    s = steady_ghost_scenario(True)
    s["targets"][1]["steady"] = 1
    with pytest.raises(ScenarioError, match="targets\\[1\\].steady must be true or false; got 1"):
        build(s)


def test_a_ghost_with_image_motion_or_scintillation_is_refused() -> None:
    s = ghost_scenario()
    s["atmosphere"] = {"jitter_rms_arcsec": 1.0, "jitter_tau_s": 0.05}
    with pytest.raises(ScenarioError, match="a ghost \\(kind='ghost'\\) with image motion or scintillation is not"):
        build(s)


def test_ghost_and_defocus_numbers_must_be_numbers() -> None:
    for key, value in (("centre_x_px", "a"), ("magnification", True), ("defocus_radius_px", "abc")):
        s = ghost_scenario()
        s["targets"][1][key] = value
        with pytest.raises(ScenarioError, match=f"targets\\[1\\].{key} must be a number; got {value!r}"):
            build(s)


def test_the_fit_groups_see_a_ghost_through_its_own_psf() -> None:
    # The chi-square's pixel groups come from each source's light through the PSF it is
    # rendered with: a 6 px defocused ghost lights a disc, not a point.
    from evstwin.tune.counts import source_flux_map

    s = ghost_scenario()
    s["targets"][0].update(vx_px_s=0.0, vy_px_s=0.0)  # both at rest: the map is one frame
    scene = build(s)
    flux = source_flux_map(scene)
    gx, gy = scene.targets[1].position_px(np.array([0.0]))
    yy, xx = np.mgrid[0:scene.height, 0:scene.width]
    ring = np.abs(np.hypot(xx - gx[0], yy - gy[0]) - 4.0) < 0.5  # inside the 6 px disc, past the shadow
    # The disc holds 0.5 x 1e9 / (pi 36) ~ 4e6 photons/s a pixel, 2 % of the star's peak; a
    # point-like ghost would leave the ring at its Gaussian tail, ~1e-6 of the peak.
    assert flux[ring].min() > 1e-3 * flux.max()
