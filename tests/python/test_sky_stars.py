"""evstwin.sky.stars: the all-sky star counts, magnitudes drawn from them, and a star field whose
size follows from the optics (star_field.distribution = 'all-sky')."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from evstwin.optics import Optics
from evstwin.scenario import ScenarioError, build
from evstwin.sky import stars
from evstwin.targets import random_star_field

SPHERE_DEG2 = 41252.96


def test_counts_at_the_table_magnitudes_and_between() -> None:
    # Tycho-2 + UCAC4: 382,925 stars brighter than V = 10 and 1,048,084 than V = 11, whole sky.
    assert stars.cumulative_density_per_deg2(10.0) == pytest.approx(382925 / SPHERE_DEG2, rel=1e-5)
    assert stars.cumulative_density_per_deg2(11.0) == pytest.approx(1048084 / SPHERE_DEG2, rel=1e-5)
    # Half way, log10 N half way (geometric mean).
    assert stars.cumulative_density_per_deg2(10.5) == pytest.approx(math.sqrt(382925 * 1048084) / SPHERE_DEG2,
                                                                     rel=1e-5)
    assert stars.density_per_deg2(10.0, 11.0, 2.0) == pytest.approx(2 * (1048084 - 382925) / SPHERE_DEG2, rel=1e-5)
    slope = np.diff(np.log10(stars.ALL_SKY_COUNT))
    assert np.all((slope > 0.3) & (slope < 0.7))  # star counts, not a Euclidean 0.6 everywhere
    with pytest.raises(ValueError, match=r"mag must be in \[0, 16\].*17"):
        stars.cumulative_density_per_deg2(17.0)
    with pytest.raises(ValueError, match="mag_min <= mag_max"):
        stars.density_per_deg2(12.0, 8.0)
    with pytest.raises(ValueError, match="density_scale"):
        stars.density_per_deg2(8.0, 12.0, -1.0)


def test_drawn_magnitudes_follow_the_counts() -> None:
    rng = np.random.default_rng(5)
    n = 200_000
    mag = stars.draw_magnitudes(rng.uniform(0.0, 1.0, n), 6.0, 14.0)
    assert mag.min() >= 6.0 and mag.max() <= 14.0
    edges = np.arange(6.0, 14.5, 0.5)
    counts, _ = np.histogram(mag, edges)
    cum = np.array([stars.cumulative_density_per_deg2(m) for m in edges])
    expected = n * np.diff(cum) / (cum[-1] - cum[0])
    # Poisson-like tolerance per bin (multinomial: at most sqrt(e)); 5 sigma.
    assert np.all(np.abs(counts - expected) < 5 * np.sqrt(expected))


def test_all_sky_field_count_follows_the_optics() -> None:
    # 135 mm f/2 on 4.86 um pixels: 7.43 arcsec/px; 640 x 480 px = 1.32 x 0.99 deg.
    optics = Optics(focal_length_m=0.135, f_number=2.0, pixel_pitch_m=4.86e-6, width_px=640, height_px=480)
    px_deg = 4.86e-6 / 0.135 * 180.0 / math.pi
    area_deg2 = 640 * 480 * px_deg**2
    expected = (stars.cumulative_density_per_deg2(13.0) - stars.cumulative_density_per_deg2(5.0)) * area_deg2
    assert 200 < expected < 300
    n = [len(random_star_field(640, 480, optics, mag_min=5.0, mag_max=13.0, seed=s, distribution="all-sky"))
         for s in range(20)]
    # 20 Poisson counts: their mean within 5 sigma of the law, their spread Poisson-like.
    assert np.mean(n) == pytest.approx(expected, abs=5 * math.sqrt(expected / 20))
    # 19 s^2 / lambda is chi-square with 19 degrees of freedom for Poisson counts: within its
    # 0.005 % and 99.995 % points (4.9 and 45.0); a fixed count (variance 0) fails.
    assert 4.9 / 19 < np.var(n, ddof=1) / expected < 45.0 / 19
    field = random_star_field(640, 480, optics, mag_min=5.0, mag_max=13.0, seed=3, distribution="all-sky",
                              density_scale=3.0)
    assert len(field) > 2 * expected
    again = random_star_field(640, 480, optics, mag_min=5.0, mag_max=13.0, seed=3, distribution="all-sky",
                              density_scale=3.0)
    assert [t.label for t in again] == [t.label for t in field]


def test_uniform_stays_the_default_and_bad_combinations_are_refused() -> None:
    optics = Optics()
    old = random_star_field(100, 80, optics, n_stars=30, seed=2)
    new = random_star_field(100, 80, optics, n_stars=30, seed=2, distribution="uniform")
    assert [t.label for t in old] == [t.label for t in new]
    with pytest.raises(ValueError, match="give neither n_stars nor density_per_deg2.*n_stars=30"):
        random_star_field(100, 80, optics, n_stars=30, distribution="all-sky")
    with pytest.raises(ValueError, match="distribution must be 'uniform' or 'all-sky'.*'galaxy'"):
        random_star_field(100, 80, optics, n_stars=30, distribution="galaxy")
    with pytest.raises(ValueError, match="density_scale applies to distribution='all-sky'"):
        random_star_field(100, 80, optics, n_stars=30, density_scale=2.0)


def _scenario(**star_field) -> dict:
    return {"sensor": {"preset": "imx636", "width": 320, "height": 240}, "duration_s": 0.1,
            "optics": {"focal_length_m": 0.05, "f_number": 1.4}, "background": {"sky_mag_per_arcsec2": 21.0},
            "star_field": star_field}


def test_all_sky_star_field_in_a_scenario() -> None:
    scene = build(_scenario(distribution="all-sky", mag_min=4.0, mag_max=12.0, seed=1))
    px_deg = 4.86e-6 / 0.05 * 180.0 / math.pi
    expected = stars.density_per_deg2(4.0, 12.0) * 320 * 240 * px_deg**2
    assert scene.field_stars == len(scene.targets)
    assert abs(scene.field_stars - expected) < 5 * math.sqrt(expected)
    mags = [float(t.label.split("mag=")[1]) for t in scene.targets]
    assert min(mags) >= 4.0 and max(mags) <= 12.0


@pytest.mark.parametrize("table, words", [
    ({"distribution": "galactic", "mag_max": 12.0}, ["distribution", "'galactic'"]),
    ({"distribution": "all-sky", "mag_max": 18.0}, ["mag_max", "18"]),
    ({"distribution": "all-sky", "n_stars": 10}, ["n_stars=10"]),
    ({"distribution": "all-sky", "density_scale": -2.0}, ["density_scale", "-2"]),
])
def test_bad_star_field_values_get_one_line(table: dict, words: list[str]) -> None:
    with pytest.raises(ScenarioError) as err:
        build(_scenario(**table))
    text = str(err.value)
    assert "\n" not in text
    for w in words:
        assert w in text


def test_leo_pass_says_how_fast_its_stars_drift() -> None:
    # The scenario's text gives the stars' drift across its field; 0.1 px/s was the rate at
    # the equator, not at this field's declination.
    import re

    from evstwin.scenario import build

    text = (Path(__file__).resolve().parents[2] / "python" / "evstwin" / "scenarios" / "leo-pass.toml").read_text()
    lo, hi, median = (float(v) for v in re.search(r"(\d\.\d+)-(\d\.\d+) px/s across this field, median (\d\.\d+)",
                                                   text).groups())
    scene = build("leo-pass", duration_s=40.0)
    speeds = np.array([t.max_speed_px_s(0.0, 40.0) for t in scene.targets[1:]])
    assert speeds.min() == pytest.approx(lo, abs=6e-4) and speeds.max() == pytest.approx(hi, abs=6e-4)
    assert np.median(speeds) == pytest.approx(median, abs=6e-4)
