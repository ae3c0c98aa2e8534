"""The characterisation bench (issue 29): lux to photons, the bench's measures against what the
preset's parameters say by hand, and the command's all-or-nothing output."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from evstwin import characterize, presets, spectra
from evstwin.cli import main


def test_a_lumen_of_555_nm_light_is_the_si_definition_in_photons() -> None:
    # 1 lm at 555 nm (540 THz) is 1/683 W: 1 / (683 h c / 555 nm) = 4.09e15 photons/s.
    line = spectra.led(555e-9, 2e-9)
    assert spectra.photons_per_lumen(line) == pytest.approx(555e-9 / (683 * 6.62607015e-34 * 299792458.0), rel=2e-3)


def test_lux_become_the_engines_photons_through_the_qe_curve() -> None:
    paper, imx = presets.get_preset("davis346_paper"), presets.get_preset("imx636")
    per_lumen = spectra.photons_per_lumen(spectra.blackbody(3000.0))
    # No QE curve: every photon between 300 and 1100 nm, over the pixel's area.
    assert characterize.photons_per_px_s(paper, 10.0) == pytest.approx(10.0 * per_lumen * 18.5e-6**2, rel=1e-12)
    # With a curve: the engine's photons times the pixel's yield are the curve's electrons.
    s = spectra.blackbody(3000.0)
    assert imx.qe is not None
    electrons = 10.0 * per_lumen * 4.86e-6**2 * float(np.sum(s.photon_flux * imx.qe.on_grid()) / np.sum(s.photon_flux))
    assert characterize.photons_per_px_s(imx, 10.0) * imx.pixel.electrons_per_photon == pytest.approx(electrons, rel=1e-9)
    with pytest.raises(ValueError, match="lux must be finite and >= 0; got -1"):
        characterize.photons_per_px_s(imx, -1.0)


def test_bench_on_the_imx636_meets_its_own_parameters() -> None:
    r = characterize.characterize("imx636", lux=[0.003, 0.03, 1.0, 1000.0], contrasts=[0.2, 0.3, 0.6], size_px=8,
                                  num_threads=1)
    # Latency falls as the light rises (the photoreceptor's bandwidth follows its current), and
    # at 1000 lux it is below the 100 us Prophesee publishes (validation: not used to set it).
    assert r.latency_median_s[1] > r.latency_median_s[2] > r.latency_median_s[3]
    assert r.latency_median_s[3] < 100e-6
    # Doubling the light fires every pixel at 1000 lux; at 0.003 lux (a thirtieth of the dark
    # current's electrons) few respond within 0.5 s.
    assert r.response_fraction[3] == 1.0 and r.response_fraction[0] < 0.5
    assert 0.003 < r.low_light_cutoff_lux < 1.0
    # The contrast threshold brackets the ON threshold: exp(0.235) - 1 = 26.5 %.
    assert 0.2 < r.contrast_threshold < 0.3 and r.contrast_response[-1] == 1.0
    roles = {p["quantity"]: p["role"] for p in r.published}
    assert roles == {"latency_s": "validation", "low_light_cutoff_lux": "validation",
                     "contrast_threshold": "calibration"}


def test_characterize_command_writes_all_or_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "bench"
    assert main(["characterize", "imx636", "--out", str(out), "--lux", "1,1000", "--size-px", "4",
                 "--no-progress", "--no-figure"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["characterize.json", "characterize.txt"]
    data = json.loads((out / "characterize.json").read_text())
    assert data["preset"] == "imx636" and data["lux"] == [1.0, 1000.0] and math.isfinite(data["latency_median_s"][1])
    capsys.readouterr()
    assert main(["characterize", "imx636", "--out", str(out), "--no-progress"]) == 2
    assert "is not empty; pass --force" in capsys.readouterr().err
    assert main(["characterize", "davis240", "--out", str(tmp_path / "x"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown sensor preset 'davis240'" in err and not (tmp_path / "x").exists()
    assert main(["characterize", "imx636", "--out", str(tmp_path / "y"), "--size-px", "2", "--no-progress"]) == 2
    assert "size_px must be an integer in [4, 128]" in capsys.readouterr().err and not (tmp_path / "y").exists()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary folder left


def test_vendor_biases_move_the_bench_as_their_laws_say(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    # IMX636 bias_diff_on +140 codes from the assumed factory 115: theta_on = 0.235 + 0.0659 ln(255 / 115)
    # = 0.2875, an ON step of exp(0.2875) - 1 = 33 % against exp(0.235) - 1 = 26.5 % at the default.
    steps = [0.2, 0.24, 0.28, 0.32, 0.36, 0.4, 0.6]
    base = characterize.characterize("imx636", lux=[1000.0], contrasts=steps, size_px=8, num_threads=1)
    raised = characterize.characterize("imx636", lux=[1000.0], contrasts=steps, size_px=8, num_threads=1,
                                       biases={"bias_diff_on": 140})
    assert 0.22 < base.contrast_threshold < 0.30 < raised.contrast_threshold < 0.37
    assert raised.biases == {"bias_diff_on": 140.0} and "biases bias_diff_on=140" in raised.to_text()
    assert "at its default biases" in raised.to_text() and base.biases == {}
    for argv, words in ((["davis346", "--bias", "bias_diff_on=10"], "preset 'davis346' has no Prophesee biases"),
                        (["imx636", "--bias", "bias_diff_on"], "--bias takes NAME=VALUE"),
                        (["imx636", "--bias", "bias_fo=+999"], "biases.bias_fo")):
        assert main(["characterize", *argv, "--out", str(tmp_path / "z"), "--no-progress", "--no-figure"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and words in err and not (tmp_path / "z").exists()
