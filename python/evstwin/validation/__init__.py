"""Validation of a simulation against a real recording: the method of the paper's section 3.

* :func:`compare` -- totals and ON/OFF ratio (Table 4), per-pixel count histograms (Fig. 7),
  their per-bin error and percent error (Fig. 8), the error as a share of the sensor's pixels
  (Fig. 9), and one summary ``distance`` a tuner can minimise.
* :func:`aggregate` -- mean and spread of every number over N Monte Carlo runs (the paper's 20).
* :func:`compare_files`, :func:`compare_runs`, :func:`info`, :func:`show`, :func:`timing_report`
  -- the file-level entry points the CLI uses (:mod:`.report`, the one module here that draws);
  they read recordings in chunks and return values or text, printing nothing.
* :func:`calibrate_noise` -- the background activity of a static or dark recording as the
  engine's eq. 12 model and hot-pixel map, written as scenario TOML (:mod:`.noise`).
* :func:`timing_bias`, :func:`timing_bias_summary` -- delay of each event after the true
  crossing of a source over its pixel, against brightness and speed (the astrometry obstacle
  the paper names).

* :mod:`.region` -- a region of interest (:class:`~.region.Roi`), pixel masks and the
  hot-pixel rule (:func:`~.region.hot_pixels`): which pixels a comparison looks at.

The summary distance (0 for identical recordings, finite for any two; see :func:`compare`)::

    distance = (W1_total + W1_on + W1_off) / (m_real + 1/N)
               + |ln((n_sim + 1/2) / (n_real + 1/2))| + |ln(O_sim / O_real)|

where W1_k is the 1-Wasserstein distance between the real and simulated distributions over
the N compared pixels of the per-pixel count of kind k (mean |sorted(real) - sorted(sim)|,
the unbinned limit of the Fig. 7 histograms), m_real the real recording's mean per-pixel
total, n the totals and O = (ON + 1/2) / (OFF + 1/2), the simulation's counts scaled to the
real duration when the durations differ."""

from __future__ import annotations

from ..analysis import nice_bin_s
from .comparison import DISTANCE_FORMULA, Comparison, PathLike, Recording, SimComparison, compare
from .montecarlo import MonteCarloSummary, aggregate
from .noise import NoiseCalibration, calibrate_noise
from .report import compare_files, compare_runs, format_info, info, show, timing_report
from .timing import (
    TruthTrack,
    format_timing_bias_summary,
    timing_attribution,
    timing_bias,
    timing_bias_summary,
)

__all__ = [
    "Comparison",
    "DISTANCE_FORMULA",
    "MonteCarloSummary",
    "NoiseCalibration",
    "PathLike",
    "Recording",
    "SimComparison",
    "TruthTrack",
    "aggregate",
    "calibrate_noise",
    "compare",
    "compare_files",
    "compare_runs",
    "format_info",
    "format_timing_bias_summary",
    "info",
    "nice_bin_s",
    "show",
    "timing_attribution",
    "timing_bias",
    "timing_bias_summary",
    "timing_report",
]
