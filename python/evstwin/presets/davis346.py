"""The iniVation DAVIS346 presets: the camera (``davis346``) and the paper's own
(``davis346_paper``), their readout, background and sources, and the paper's runs 1-3."""

from __future__ import annotations

import dataclasses
from typing import Any

from ..optics import DAVIS346_MEAN_WAVELENGTH_M
from ..pixel import PixelParams
from ..readout import ReadoutParams
from .biases import _PAPER, FAST_PR_SLOW_SF_BALANCED_TH, PAPER_RUN_1, PAPER_RUN_3
from .sensor_preset import READOUT_FIFO_ASSUMPTION, SensorPreset, _fsi_pixel, _fsi_qe

DAVIS346_READOUT = ReadoutParams(
    max_rate_hz=12e6,
    fifo_depth=4096,
    tick_s=1e-6,
    sources=(
        "iniVation, DAVIS346 datasheet (inivation.com/wp-content/uploads/2019/08/DAVIS346.pdf, now "
        "docs.inivation.com/_static/hardware_guides/davis346.pdf): 'Bandwidth 12 MEvents/second', "
        "min. latency ~20 us. Not reachable from the machine this was written on: the figure is as "
        "quoted from that datasheet by two independent public sources; check it against your copy",
        "iniVation libcaer, davis.h (DAVIS_CONFIG_MUX_TIMESTAMP_RUN: the timestamp generator gives "
        "'microsecond accurate timestamps'); iniVation AEDAT 2.0 docs: 'Timestamps tick is 1 us'",
    ),
    assumptions=(READOUT_FIFO_ASSUMPTION,),
)
"""DAVIS346 readout: 12 Mev/s (the camera's bandwidth), 1 us timestamps, FIFO assumed."""



DAVIS346_RECORDING = (
    "a public DAVIS346 recording (the test data of the aedat package 2.3.0 on PyPI, tests/data/test_data.aedat4: "
    "2.36 s of a road in daylight)"
)
"""The real DAVIS346 recording the preset's background was measured on."""
DAVIS346_BACKGROUND_SOURCE = (
    f"{DAVIS346_RECORDING}, its static upper half (y < 120, 41,520 pixels): 289 events, all ON, "
    "2.95e-3 +- 0.18e-3 Hz per pixel, log-normal spread sigma 1.51 +- 0.14, 0 OFF (an OFF rate "
    "below 3.1e-5 Hz at 95 %), no hot pixel (evstwin calibrate-noise davis346_road.aedat4 --roi 0,0,346,120)"
)
"""Where the DAVIS346 preset's leak and background figures come from."""

_DAVIS346_BASE = PixelParams(
    # photodiode, paper Table 3 and sec. 3.1
    fill_factor=0.22,
    internal_qe=1.0,
    transmission=0.68,
    absorption_per_m=3e4,
    depletion_width_m=1.1637e-7,
    # noise: dark current from the paper's sec. 2.1; the background measured on the real
    # DAVIS346 road's static half (DAVIS346_BACKGROUND_SOURCE): all of it ON, so a leak, spread
    # log-normally across pixels; no eq. 12 background (0 OFF events there). The paper's own
    # sec. 2.4 figures (leak 0.1 Hz, R_n 0.05 Hz) stay in its run scenarios and paper_run_params.
    dark_rate_e_per_s=18000.0,
    leak_rate_hz=2.95e-3,
    leak_rate_sigma=1.51,
    shot_noise_rate_hz=0.0,
    shot_noise_factor=0.25,
    shot_noise_i_max_a=3.16e-9,
)

_DAVIS346_SOURCES = (
    f"{_PAPER}, sec. 3.1: 346 x 260 pixels, 18.5 um pitch, 22 % fill factor",
    f"{_PAPER}, Table 1: bias set 'Fast PR, Slow SF, Balanced TH' (McReynolds et al.)",
    f"{_PAPER}, sec. 2.1: dark rate 18000 e-/s (iniVation, its ref. [11])",
    f"{_PAPER}, sec. 2.4: F 0.25, I_max 3.16 nA (its leak 0.1 Hz and R_n 0.05 Hz: the run scenarios)",
    DAVIS346_BACKGROUND_SOURCE,
    "Nozaki & Delbruck (2017), IEEE Trans. Electron Devices (the paper's ref. [15]): eq. 8-9",
    "k = 0.0659 reproduces every threshold of the paper's Tables 1-2 (K_THRESHOLD_DAVIS346)",
)
_DAVIS346_ASSUMPTIONS = (
    "refractory 1 ms from I_refr = 4.7 nA via the calibrated Q = 4.7 pC (REFRACTORY_CHARGE_C)",
    "cutoff 10 Hz from I_sf = 834.7 fA via the calibrated C = 360 fF (SF_LOAD_CAPACITANCE_F)",
    "mean wavelength 0.7 um: the middle of a silicon photodiode's ~0.4-1.0 um response",
    "background measured in daylight only: the leak is taken as independent of the light (the "
    "paper's eq. 10-11); in the dark the twin adds its own filtered shot noise of the 18000 e-/s "
    "dark current; no dark DAVIS346 recording was at hand to check that",
    "the real background comes on the camera's 40 ms frame cycle (APS readout coupling); the "
    "twin's leak is not locked to it, so its rate matches and its timing does not",
    "dark current, leak and background hold at 25 degC and double every 6.5 degC (DARK_DOUBLING_C); the "
    "paper does not give the temperature of its 18000 e-/s",
)



DAVIS346 = SensorPreset(
    name="davis346",
    description="iniVation DAVIS346 (2nd generation, front-illuminated), the sensor of the paper",
    width=346,
    height=260,
    pixel_pitch_m=18.5e-6,
    fill_factor=0.22,
    back_illuminated=False,
    mean_wavelength_m=DAVIS346_MEAN_WAVELENGTH_M,
    pixel=FAST_PR_SLOW_SF_BALANCED_TH.pixel_params(_fsi_pixel(_DAVIS346_BASE, 0.22)),
    biases=FAST_PR_SLOW_SF_BALANCED_TH,
    qe_notes=(
        "Front-illuminated, 22 % fill factor, no microlens gain assumed; QE from silicon's absorption "
        "spectrum over a 2 um collection depth through the paper's 0.68 transmission: 10 % at 550 nm (the "
        "engine's reference photon), 15 % peak, 4.6 % at 700 nm. davis346_paper keeps the paper's 0.35 %."
    ),
    sources=_DAVIS346_SOURCES + ("Green (2008), Sol. Energy Mater. Sol. Cells 92, 1305: silicon's absorption",),
    assumptions=_DAVIS346_ASSUMPTIONS + (
        "collection depth 2 um (FSI_COLLECTION_DEPTH_M) and the paper's transmission 0.68: they set the QE curve",
    ),
    readout=DAVIS346_READOUT,
    qe=_fsi_qe(0.22, "DAVIS346"),
)
"""The DAVIS346 as a camera: the paper's geometry, biases and dark current, the measured
background, and a silicon QE curve (about 15 % at its peak) in place of the paper's 0.35 %."""

DAVIS346_PAPER = dataclasses.replace(
    DAVIS346,
    name="davis346_paper",
    description="the paper's DAVIS346: its Table 3 photodiode (0.35 % of photons absorbed), kept to reproduce it",
    pixel=FAST_PR_SLOW_SF_BALANCED_TH.pixel_params(_DAVIS346_BASE),
    qe=None,
    qe_notes=(
        "Front-illuminated, 22 % fill factor, no microlens gain assumed. Photon-to-electron "
        "efficiency by eq. 2 with Table 3: tau (1 - exp(-alpha W)) = 0.68 x 0.0035 = 0.24 % of the "
        "photons on the photodiode (x 0.22 fill factor): the paper's constants, kept as given. No "
        "spectrum: a magnitude counts the V band's photons (the paper's scenes are lab LEDs given in photons/s)."
    ),
    sources=_DAVIS346_SOURCES + (f"{_PAPER}, Table 3: alpha, eta_i, tau, W",),
    assumptions=_DAVIS346_ASSUMPTIONS,
)
"""The paper's DAVIS346 with its Table 1 biases (theta 0.2060 / 0.0930, 1 ms, 10 Hz) and its
Table 3 photodiode: what the paper's tables and its section 3 were computed with. Everything
else is the DAVIS346 preset's."""



def paper_run_params(run: int, base: PixelParams | None = None, **overrides: Any) -> PixelParams:
    """Pixel parameters of the paper's simulation runs 1-3 (Table 2, sec. 3.3).

    1: Table 2 run-1 biases, shot and leak noise on, 18000 e-/s dark;
    2: same biases, no shot or leak noise, 18000 e-/s;
    3: run-3 biases, no shot or leak noise, 290 e-/s.
    Everything else from ``base`` (default: the davis346_paper preset, so 1 ms and 10 Hz). The paper
    used eq. 4 literally for the dark current: pass ``dark_model='paper'`` to do the same.
    """
    base = DAVIS346_PAPER.pixel if base is None else base
    if run == 1:
        changes: dict[str, Any] = dict(
            PAPER_RUN_1.derived(), dark_rate_e_per_s=18000.0, shot_noise_rate_hz=0.05, leak_rate_hz=0.1
        )
    elif run == 2:
        changes = dict(
            PAPER_RUN_1.derived(), dark_rate_e_per_s=18000.0, shot_noise_rate_hz=0.0, leak_rate_hz=0.0
        )
    elif run == 3:
        changes = dict(
            PAPER_RUN_3.derived(), dark_rate_e_per_s=290.0, shot_noise_rate_hz=0.0, leak_rate_hz=0.0
        )
    else:
        raise ValueError(f"run must be 1, 2 or 3 (the paper's Table 2); got run={run!r}")
    changes.update(overrides)
    return base.replace(**changes)
