"""The Prophesee Gen3 VGA (PPS3MVCD) preset: geometry and readout as published, pixel figures
assumed from the DAVIS346's and the IMX636's."""

from __future__ import annotations

from ..optics import DAVIS346_MEAN_WAVELENGTH_M
from ..readout import ReadoutParams
from .davis346 import _DAVIS346_BASE
from .imx636 import IMX636_THETA
from .prophesee_biases import GEN3_BIASES
from .sensor_preset import READOUT_FIFO_ASSUMPTION, SensorPreset, _fsi_pixel, _fsi_qe

GEN3_VGA_DARK_RATE_E_PER_S = 18000.0 * (15.0**2 * 0.25) / (18.5**2 * 0.22)
"""The Gen3 VGA preset's dark current [e-/s]: the DAVIS346's 18,000 e-/s scaled by photodiode
area (15 um x 15 um x 0.25 against 18.5 um x 18.5 um x 0.22): 13,450 e-/s. Both are 0.18 um
CMOS front-illuminated pixels; a dark current grows with the junction's area (assumption)."""
GEN3_VGA_CUTOFF_HZ = 150.0
"""The Gen3 VGA preset's source-follower cutoff [Hz], calibrated on one published figure: the
PPS3MVCD's typical latency of 200 us (CenturyArks SilkyEvCam-USB specification, Table 1; taken
at 1000 lux, as Prophesee states its latencies): ``evstwin characterize prophesee_gen3_vga``
gives a median of 202 us at 1000 lux with 150 Hz (130 Hz: 233 us, 300 Hz: 93 us)."""
GEN3_VGA_THETA = IMX636_THETA  # the same assumed 25 % contrast step (no Gen3 figure at hand)
"""The Gen3 VGA preset's ON and OFF thresholds [ln units]: a 25 % contrast step, as assumed for
the IMX636 (Prophesee's biases are DAC settings, not currents; ``vendor_biases`` scales these
values with the vendor's bias_diff_on and bias_diff_off)."""

PROPHESEE_GEN3_VGA = SensorPreset(
    name="prophesee_gen3_vga",
    description="Prophesee Gen3 VGA (PPS3MVCD, 3rd generation), as in the Gen3 EVK and the SSA studies of 2019-2020",
    width=640,
    height=480,
    pixel_pitch_m=15e-6,
    fill_factor=0.25,
    back_illuminated=False,
    mean_wavelength_m=DAVIS346_MEAN_WAVELENGTH_M,
    pixel=_fsi_pixel(_DAVIS346_BASE, 0.25).replace(
        dark_rate_e_per_s=GEN3_VGA_DARK_RATE_E_PER_S,
        theta_on=GEN3_VGA_THETA,
        theta_off=GEN3_VGA_THETA,
        refractory_s=1e-3,
        cutoff_hz=GEN3_VGA_CUTOFF_HZ,
        pr_pole=True,
    ),
    biases=None,
    qe_notes=(
        "Front-illuminated 0.18 um CMOS pixel (Gen3 predates the stacked BSI Gen4 of Finateu et al. 2020), "
        "fill factor 25 % (assumed, see assumptions); QE from silicon's absorption spectrum over a 2 um "
        "collection depth through 0.68 transmission, as for the DAVIS346: 17 % peak, 12 % at 550 nm."
    ),
    sources=(
        "Prophesee, Gen3 VGA CD sensor (PPS3MVCD) and its evaluation kit: 640 x 480 pixels, 15 um pitch "
        "(as quoted by Prophesee's product pages and in the Metavision docs' list of sensor generations: Gen3 "
        "sensors use EVT 2.0). Not reachable from the machine this was written on: the figures are as quoted "
        "by secondary sources; check them against your datasheet",
        "Afshar, Nicholson, van Schaik & Cohen (2020), 'Event-based object detection and tracking for space "
        "situational awareness', IEEE Sensors J. 20(24), 15117; Cohen, Afshar, Morreale, Bessell, Wabnitz, "
        "Rutten & van Schaik (2019), 'Event-based sensing for space situational awareness', J. Astronaut. "
        "Sci. 66, 125: the Prophesee VGA-class sensor in the field's published SSA observations, beside "
        "the DAVIS240/346 and, later, the IMX636",
    ),
    assumptions=(
        "fill factor 0.25: the order of the figure quoted for Gen3 pixels (secondary sources; not verified)",
        "thresholds ln(1.25) = 0.223 both ways, a 25 % contrast step, as for the IMX636 preset",
        "refractory 1 ms as the DAVIS346 preset's; the photoreceptor pole on",
        "source follower 150 Hz, calibrated on the typical latency of 200 us (GEN3_VGA_CUTOFF_HZ), taken at 1000 lux",
        "dark rate 13,450 e-/s at 25 degC (GEN3_VGA_DARK_RATE_E_PER_S: the DAVIS346's per photodiode area) and "
        "the DAVIS346's background (a 2.95e-3 Hz leak, sigma 1.51, no eq. 12 rate; no Gen3 background figures "
        "at hand: measure them with `evstwin calibrate-noise` on a Gen3 recording)",
        "QE: collection depth 2 um and transmission 0.68, as for the DAVIS346 (FSI_COLLECTION_DEPTH_M)",
        "mean wavelength 0.7 um as for the DAVIS346",
        "readout FIFO depth assumed (READOUT_FIFO_ASSUMPTION)",
    ),
    readout=ReadoutParams(
        max_rate_hz=50e6,
        fifo_depth=4096,
        tick_s=1e-6,
        sources=(
            "CenturyArks SilkyEvCam-USB specification Rev 1.02 (PPS3MVCD sensor), Table 1: 'Maximum readout "
            "throughput 50Mevents/s', 'Typical Latency 200us' (as quoted by public notes)",
        ),
        assumptions=(READOUT_FIFO_ASSUMPTION,),
    ),
    qe=_fsi_qe(0.25, "Prophesee Gen3 VGA"),
    vendor_biases=GEN3_BIASES,
)
"""Prophesee Gen3 VGA: geometry and readout as published (640 x 480, 15 um, 50 Mev/s); pixel figures assumed."""
