"""The Sony IMX636 (Prophesee EVK4) preset: geometry sourced, its background, refractory
period, thresholds' split and source follower measured on a real recording."""

from __future__ import annotations

import math

from ..optics import DAVIS346_MEAN_WAVELENGTH_M
from ..readout import ReadoutParams
from ..spectra import silicon_qe_curve
from .davis346 import _DAVIS346_BASE
from .prophesee_biases import IMX636_BIASES
from .sensor_preset import READOUT_FIFO_ASSUMPTION, SensorPreset

IMX636_READOUT = ReadoutParams(
    max_rate_hz=1.066e9,
    fifo_depth=4096,
    tick_s=1e-6,
    sources=(
        "Sony Semiconductor Solutions, event-based vision sensor page "
        "(sony-semicon.com/en/products/is/industry/evs.html) and Prophesee's IMX636 page: maximum "
        "event rate 1.066 Gevents/s (quoted as '1.06 Gevents/s' and '1066 Mev/s'). Not reachable "
        "from the machine this was written on: the figure is as quoted by public secondary sources",
        "Prophesee Metavision docs, EVT 2.0 / 3.0 formats and EventCD: timestamps in microseconds",
    ),
    assumptions=(
        READOUT_FIFO_ASSUMPTION,
        "1.066 Gev/s is the sensor's own readout. A camera delivers less: the EVK4's USB 3 link "
        "(1.6 Gbps in Prophesee's EVK docs) and the sensor's event-rate controller (ERC, which "
        "thins events in time windows instead of queueing them) set the rate you see; give "
        "[readout] max_rate_hz for your camera",
    ),
)
"""IMX636 readout: 1.066 Gev/s (the sensor's), 1 us timestamps, FIFO assumed."""



IMX636_RECORDING = (
    "a public Prophesee EVK4 recording (the test data of the faery package, tests/data/evt3.raw: 10.77 s of a "
    "point source on a dark field)"
)
"""The real IMX636 recording the preset's background figures were measured on."""
IMX636_THETA = math.log(1.25)
"""A 25 % contrast step [ln units]: the nominal contrast threshold quoted for Sony's 4.86 um
event sensors (a camera datasheet of the IMX646, the IMX636's sibling), the Gen3 preset's."""
IMX636_THETA_ON = 0.235
IMX636_THETA_OFF = 0.21
"""The IMX636 preset's thresholds [ln units]: a 25 % step on average, split by the EVK4
recording's ON/OFF ratio of 0.91 within 200 px of its star (``imx636-pointsource``)."""
IMX636_COLLECTION_DEPTH_M = 5e-6
"""Depth [m] from which the IMX636's back-illuminated photodiode collects (an assumption: a
few um of epitaxial silicon is typical of BSI pixels). With the paper's 0.68 surface
transmission it gives a QE of 68 % in the blue-green, 43 % at 690 nm, 24 % at 800 nm."""
IMX636_ABSORPTION_PER_M = 2.0e5
"""Silicon's absorption at 690 nm [1/m] (Green 2008: 2.04e5): the IMX636 preset's engine counts
690 nm photons, its yield 0.68 (1 - exp(-2e5 x 5 um)) = 43 %, the QE curve's there."""

IMX636 = SensorPreset(
    name="imx636",
    description="Sony IMX636 (Prophesee Gen4.1 HD), as in the Prophesee EVK4 HD",
    width=1280,
    height=720,
    pixel_pitch_m=4.86e-6,
    fill_factor=1.0,
    back_illuminated=True,
    mean_wavelength_m=DAVIS346_MEAN_WAVELENGTH_M,
    pixel=_DAVIS346_BASE.replace(
        fill_factor=1.0,
        absorption_per_m=IMX636_ABSORPTION_PER_M,
        depletion_width_m=IMX636_COLLECTION_DEPTH_M,
        theta_on=IMX636_THETA_ON,
        theta_off=IMX636_THETA_OFF,
        refractory_s=1.3e-4,
        cutoff_hz=2000.0,
        pr_pole=True,
        leak_rate_hz=0.0,
        shot_noise_on_rate_hz=2.2e-4,
        shot_noise_off_rate_hz=1.69e-3,
        shot_noise_factor=1.0,
        background_rate_sigma=1.41,
        hot_pixel_fraction=1.0 / (1280 * 720),
        hot_pixel_rate_hz=1170.0,
        hot_pixel_duty=0.13,
        hot_pixel_burst_s=0.046,
        hot_pixel_on_share=0.59,
        hot_pixel_alternation=0.78,
    ),
    biases=None,
    qe_notes=(
        "Back-illuminated stacked sensor with microlenses: fill_factor 1.0 stands for an effective "
        "optical fill factor near 1 (Prophesee measures QE over the whole 4.86 um pixel). QE from silicon's "
        "absorption spectrum over a 5 um collection depth through the paper's 0.68 transmission: 68 % peak, "
        "43 % at 690 nm (the engine's reference photon). No measured curve was found (Prophesee publishes it "
        "as a figure only)."
    ),
    sources=(
        (
            "Finateu et al., 'A 1280x720 back-illuminated stacked temporal contrast event-based vision "
            "sensor with 4.86 um pixels, ...', ISSCC 2020: 1280 x 720, 4.86 um, BSI stacked"
        ),
        (
            f"{IMX636_RECORDING} (10.77 s, dark field): refractory 130 us, the shortest interval between two "
            "events of its hot pixel (131 us)"
        ),
        (
            f"{IMX636_RECORDING}, dark corner x >= 980, y >= 520 (60,000 pixels; `evstwin calibrate-noise "
            "... --roi 980,520,300,200`): background 2.20e-4 Hz ON and 1.69e-3 Hz OFF per pixel, log-normal "
            "spread sigma 2.58 (ON) and 1.26 (OFF), 1.41 event-weighted; one ON-leaky pixel (1224, 658) apart "
            "(113 events, 111 ON); no leak beyond the ON background"
        ),
        (
            f"{IMX636_RECORDING}: one hot pixel in 921,600 at (187, 261), 1447 events (134 Hz, 78 % of "
            "successive events alternate polarity) in bursts (`calibrate-noise ... --roi 0,0,240,720`): "
            "1015 Hz while active, i.e. r = 1170 Hz with 130 us dead time, duty 0.13, mean burst 46 ms; "
            "854 of its events ON (0.59), switching polarity after 66 % of its ON events and 95 % of its OFF "
            "events: the two-state chain of hot_pixel_on_share 0.59 and hot_pixel_alternation 0.78"
        ),
    ),
    assumptions=(
        "fill factor 1.0 (BSI + microlens, effective)",
        (
            "thresholds ln(1.25) = 0.223 both ways (a 25 % contrast step), far enough above the filtered "
            "shot noise that the dark background comes from eq. 12 as measured; Prophesee biases are DAC "
            "settings, not the currents of eq. 8-9, so measure theta with S-curves (McReynolds et al. 2024, "
            "arXiv:2404.07656) for a given camera; vendor_biases maps the biases onto these values by trends "
            "(its own assumptions)"
        ),
        (
            "QE: collection depth 5 um and transmission 0.68 (IMX636_COLLECTION_DEPTH_M); a simulator's 0.6 "
            "(dvs_performance_metrics, Gen4 config) is the only other figure found"
        ),
        (
            "dark rate 18000 e-/s at 25 degC, the DAVIS346's: no primary IMX636 figure was found (a simulator "
            "uses 5.5 fA = 34,000 e-/s, dvs_performance_metrics); the recording's fluxes are set against it"
        ),
        (
            "source follower 2 kHz: the EVK4 recording's star core follows ms-scale image motion (the 10 Hz of "
            "the DAVIS346's Table 1 bias would smear it); Prophesee quotes a pixel latency under 100 us at "
            "1000 lux (IMX636 product brief 2024, as quoted by public notes)"
        ),
        "mean wavelength 0.7 um as for the DAVIS346",
        "eq. 12's illumination factor F = 1 (the recording is dark: it says nothing about F)",
    ),
    readout=IMX636_READOUT,
    qe=silicon_qe_curve(
        0.68, IMX636_COLLECTION_DEPTH_M,
        "IMX636: eq. 2 with silicon's absorption spectrum (Green 2008), transmission 0.68 x (1 - exp(-alpha(lambda) x "
        "5 um)), fill factor 1 (BSI with microlenses); an assumption, no measured curve was found"),
    vendor_biases=IMX636_BIASES,
)
"""Sony IMX636 / Prophesee EVK4: geometry sourced; refractory period, background (rates per
polarity, their spread, hot pixels), thresholds' ON/OFF split and the source follower from a
real recording; QE curve and dark current assumed."""
