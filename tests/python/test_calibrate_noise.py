"""evstwin calibrate-noise: a round trip through the engine. A dark scene is simulated with
hidden background parameters (rates per polarity, their log-normal spread, a map of bursting
hot pixels); the estimates must agree with them within tolerances the statistics give, and
simulating the TOML written must give the rates back."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from evstwin.cli import main
from evstwin.simulate import simulate_to_file
from evstwin.validation.noise import (
    NoiseCalibration,
    calibrate_noise,
    fit_poisson_lognormal,
    pln_logpmf,
    pln_logsf,
)

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

DATA = Path(__file__).resolve().parents[1] / "data"
ON_HZ, OFF_HZ, SIGMA = 0.02, 0.05, 0.8
DUTY, BURST_S, DURATION_S = 0.3, 0.1, 30.0
ON_SHARE, ALTERNATION = 0.59, 0.78  # the hot pixels' polarity chain (the real IMX636 pixel's)
HOT = [[10, 20, 300.0], [50, 60, 1000.0], [100, 90, 600.0], [30, 80, 400.0], [80, 10, 800.0], [5, 95, 500.0]]
DARK = {
    "name": "dark", "duration_s": DURATION_S, "seed": 1,
    "sensor": {"preset": "imx636", "width": 120, "height": 100},  # its 130 us refractory period
    "pixel": {"shot_noise_on_rate_hz": ON_HZ, "shot_noise_off_rate_hz": OFF_HZ, "background_rate_sigma": SIGMA,
              "hot_pixel_duty": DUTY, "hot_pixel_burst_s": BURST_S, "hot_pixel_on_share": ON_SHARE,
              "hot_pixel_alternation": ALTERNATION},
    "sampling": {"rate_hz": 100.0},  # eq. 12's clocks and the telegraph are exact at any sampling
    "hot_pixels": {"pixels": HOT},
}


@pytest.fixture(scope="module")
def dark(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("dark") / "dark.h5"
    simulate_to_file(DARK, path, num_threads=1)
    return path


@pytest.fixture(scope="module")
def cal(dark: Path) -> NoiseCalibration:
    return calibrate_noise(dark)


def test_background_rates_and_sigma_come_back(cal: NoiseCalibration) -> None:
    for b, rate in ((cal.on, ON_HZ), (cal.off, OFF_HZ)):
        # The standard error from the pixels' scatter is the one the draw of 12,000 pixels
        # has: Poisson plus the log-normal's m^2 (exp(s^2) - 1) per pixel.
        m = rate * DURATION_S
        expected_se = math.sqrt((m + m**2 * math.expm1(SIGMA**2)) / b.pixels) / DURATION_S
        assert b.rate_se_hz == pytest.approx(expected_se, rel=0.15)
        assert abs(b.rate_hz - rate) < 4 * expected_se, (b.polarity, b.rate_hz)
        assert b.sigma_se is not None and 0 < b.sigma_se < 0.05
        assert abs(b.sigma - SIGMA) < 4 * b.sigma_se, (b.polarity, b.sigma, b.sigma_se)
    assert abs(cal.sigma - SIGMA) < 0.05
    assert abs(cal.stationarity_z) < 4  # a stationary simulation


def test_hot_pixels_and_their_telegraph_come_back(cal: NoiseCalibration) -> None:
    # 12,000 pixels at a false-alarm rate of 1e-6: the map's six and no other.
    assert sorted((h.x, h.y) for h in cal.hot) == sorted((x, y) for x, y, _ in HOT)
    dead = 130e-6
    for h in cal.hot:
        r = next(rate for x, y, rate in HOT if (x, y) == (h.x, h.y))
        rho = r / (1 + r * dead)  # the engine's rate while active
        within = DURATION_S * DUTY * rho  # about the intervals rho rests on
        assert h.active_rate_hz == pytest.approx(rho, rel=4 / math.sqrt(within))
        assert h.engine_rate_hz == pytest.approx(r, rel=5 / math.sqrt(within))
        # The chain's switching share; its events are correlated, so 5 binomial se x 2.
        n = h.on + h.off
        assert h.alternation == pytest.approx(ALTERNATION, abs=10 * math.sqrt(ALTERNATION * (1 - ALTERNATION) / n))
    # Duty and burst length rest on the ~90 active periods of each pixel: each is a sum of
    # exponentials, so about sqrt(2 / 90) = 15 % per pixel; the median of six is within 4 se.
    cycles = DURATION_S * DUTY / BURST_S
    table = cal.pixel_table()
    assert table["hot_pixel_duty"] == pytest.approx(DUTY, rel=4 * math.sqrt(2 / cycles / len(HOT)) * 1.25)
    assert table["hot_pixel_burst_s"] == pytest.approx(BURST_S, rel=4 * math.sqrt(3 / cycles / len(HOT)) * 1.25)
    assert table["hot_pixel_fraction"] == pytest.approx(len(HOT) / 12000)
    n_all = sum(h.on + h.off for h in cal.hot)
    assert table["hot_pixel_on_share"] == pytest.approx(ON_SHARE, abs=10 * math.sqrt(ON_SHARE * (1 - ON_SHARE) / n_all))
    assert table["hot_pixel_alternation"] == pytest.approx(ALTERNATION, abs=0.02)
    # The refractory period: the engine's hot pixels fire 130 us after an event at the earliest.
    assert cal.refractory_s is not None and 130e-6 <= cal.refractory_s <= 135e-6
    assert cal.preset == "imx636" and cal.dead_time_s == pytest.approx(dead)


def test_the_written_toml_simulates_the_same_rates(cal: NoiseCalibration, dark: Path, tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "noise.toml"
    assert main(["calibrate-noise", str(dark), "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "hot pixels: 6 of 12000" in printed and f"wrote {out}" in printed
    text = out.read_text()
    assert text.startswith("# evstwin calibrate-noise") and "Rules" in text and "# refractory_s = " in text
    scenario = tomllib.loads(text)
    assert scenario["sensor"] == {"preset": "imx636", "width": 120, "height": 100}
    assert scenario["pixel"]["leak_rate_hz"] == 0.0
    assert len(scenario["hot_pixels"]["pixels"]) == 6
    # Each hot pixel with its own chain, as measured (4 significant digits).
    for entry in scenario["hot_pixels"]["pixels"]:
        h = next(h for h in cal.hot if (h.x, h.y) == (entry["x"], entry["y"]))
        assert entry["on_share"] == pytest.approx(h.on / (h.on + h.off), rel=1e-3)
        assert entry["alternation"] == pytest.approx(h.alternation, rel=1e-3)
        assert (entry["duty"], entry["burst_s"]) == pytest.approx((h.duty, h.burst_s), rel=1e-3)
    # Simulate it (another seed) and measure again: the rates agree within their errors.
    again = tmp_path / "again.h5"
    assert main(["simulate", str(out), "-o", str(again), "--seed", "7", "--set", "sampling.rate_hz=100",
                 "--no-progress", "--threads", "1"]) == 0
    cal2 = calibrate_noise(again)
    for a, b in ((cal.on, cal2.on), (cal.off, cal2.off)):
        assert abs(a.rate_hz - b.rate_hz) < 4 * math.hypot(a.rate_se_hz, b.rate_se_hz), (a, b)
    assert sorted((h.x, h.y) for h in cal2.hot) == sorted((h.x, h.y) for h in cal.hot)
    for h1 in cal.hot:
        h2 = next(h for h in cal2.hot if (h.x, h.y) == (h1.x, h1.y))
        assert h2.active_rate_hz == pytest.approx(h1.active_rate_hz, rel=0.1)
        # Its own ON share comes back (two draws of ~2000 correlated events: 10 binomial se).
        s1, s2 = h1.on / (h1.on + h1.off), h2.on / (h2.on + h2.off)
        assert abs(s2 - s1) < 10 * math.sqrt(s1 * (1 - s1) * (1 / (h1.on + h1.off) + 1 / (h2.on + h2.off)))
    # Refused without --force, written with it.
    assert main(["calibrate-noise", str(dark), "-o", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
    assert main(["calibrate-noise", str(dark), "-o", str(out), "--force"]) == 0


def test_a_window_cuts_the_sensor_and_shifts_the_map(dark: Path, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["calibrate-noise", str(dark), "--roi", "40,50,80,50"]) == 0
    captured = capsys.readouterr()
    scenario = tomllib.loads(captured.out)  # the TOML on stdout, the summary on stderr
    assert "window 80 x 50 at (40, 50)" in captured.err
    assert scenario["sensor"]["width"] == 80 and scenario["sensor"]["height"] == 50
    # (50, 60) and (100, 90) lie in x 40..119, y 50..99: at (10, 10) and (60, 40) of the window.
    assert sorted((h["x"], h["y"]) for h in scenario["hot_pixels"]["pixels"]) == [(10, 10), (60, 40)]


@pytest.mark.parametrize("roi", ["100,90,40,20", "-1,0,5,5", "0,0,0,5"])
def test_a_window_off_the_sensor_is_one_error_and_nothing_written(
        dark: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], roi: str) -> None:
    out = tmp_path / "n.toml"
    assert main(["calibrate-noise", str(dark), f"--roi={roi}", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("evstwin: error: ") and err.count("\n") == 1
    assert "not inside the 120x100 sensor" in err and not out.exists()


def test_a_window_that_is_not_four_numbers_is_a_usage_error(dark: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["calibrate-noise", str(dark), "--roi", "1,2,3"])
    assert exc.value.code == 2 and "X0,Y0,W,H" in capsys.readouterr().err


def test_a_window_without_events_is_one_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "few.h5"
    simulate_to_file(dict(DARK, duration_s=0.5, hot_pixels={"pixels": []},
                          pixel=dict(DARK["pixel"], shot_noise_on_rate_hz=0.0, shot_noise_off_rate_hz=0.01)),
                     path, num_threads=1)
    from evstwin import read_events

    ev, _ = read_events(path)
    x, y = int(ev["x"][0]), int(ev["y"][0])
    empty = next((i, j) for j in range(100) for i in range(120)
                 if not np.any((ev["x"] == i) & (ev["y"] == j)))
    out = tmp_path / "n.toml"
    assert main(["calibrate-noise", str(path), "--roi", f"{empty[0]},{empty[1]},1,1", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("evstwin: error: ") and "no events in the window" in err and not out.exists()
    assert main(["calibrate-noise", str(path), "--roi", f"{x},{y},1,1", "--preset", "none"]) == 0
    text = capsys.readouterr().out
    assert "add [sensor] preset" in text and "pixels = []" in text
    assert "sensor" not in tomllib.loads(text)  # --preset none: the user adds it


def test_a_real_recording_cut_runs_and_names_its_preset(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["calibrate-noise", str(DATA / "davis346_road_cut.aedat4"), "--roi", "0,0,346,120"]) == 0
    scenario = tomllib.loads(capsys.readouterr().out)
    assert scenario["sensor"]["preset"] == "davis346"  # 346 x 260: the preset of that size


def test_the_mixture_is_a_distribution_and_its_fit_finds_sigma() -> None:
    k = np.arange(400)
    for mean, sigma in ((0.01, 3.0), (0.5, 1.0), (20.0, 0.3), (3.0, 0.0)):
        pmf = np.exp(pln_logpmf(k, mean, sigma))
        assert pmf.sum() == pytest.approx(1.0, abs=1e-6)
        if sigma < 2:  # (at sigma 3 a share of the mean lies beyond k = 400)
            assert (k * pmf).sum() == pytest.approx(mean, rel=1e-3)  # the factor has mean 1
        sf = np.exp(pln_logsf(k[:50], mean, sigma))
        assert sf == pytest.approx(1 - np.concatenate([[0], np.cumsum(pmf)[:49]]), abs=1e-9)
    rng = np.random.default_rng(5)
    counts = rng.poisson(0.8 * np.exp(1.2 * rng.standard_normal(30000) - 0.72))
    sigma, se, moment = fit_poisson_lognormal(counts)
    assert se is not None and abs(sigma - 1.2) < 4 * se and se < 0.05
    assert moment is not None and abs(moment - 1.2) < 0.2
