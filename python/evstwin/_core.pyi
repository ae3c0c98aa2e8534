"""Type stubs of the compiled engine (cpp/bindings). Private: use the evstwin package."""

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

__version__: str
EVENT_DTYPE: np.dtype
TRACE_DTYPE: np.dtype
ELEMENTARY_CHARGE_C: float
EVENT_LABELS: dict[int, str]

def has_openmp() -> bool: ...
def default_num_threads() -> int: ...

class PixelParams:
    theta_on: float
    theta_off: float
    refractory_s: float
    cutoff_hz: float | None
    lowpass: str
    leak_rate_hz: float
    shot_noise_rate_hz: float
    shot_noise_factor: float
    shot_noise_i_max_a: float
    dark_rate_e_per_s: float
    dark_model: str
    photon_shot_noise: bool
    threshold_sigma: float
    fill_factor: float
    internal_qe: float
    transmission: float
    absorption_per_m: float
    depletion_width_m: float
    pr_pole: bool
    pr_cutoff_ref_hz: float
    pr_ref_current_a: float
    shot_noise_on_rate_hz: float
    shot_noise_off_rate_hz: float
    background_rate_sigma: float
    leak_rate_sigma: float
    leak_random_phase: bool
    hot_pixel_fraction: float
    hot_pixel_rate_hz: float
    hot_pixel_rate_sigma: float
    noise_model: str
    def __init__(self) -> None: ...
    def validate(self) -> None: ...
    def electrons_per_photon(self) -> float: ...

class Sensor:
    width: int
    height: int
    seed: int
    samples_seen: int
    last_time_s: float
    num_threads: int
    max_events: int
    DEFAULT_MAX_EVENTS: int
    MAX_THREADS: int
    MAX_PIXELS: int
    def __init__(
        self, width: int, height: int, params: PixelParams, seed: int = 0, num_threads: int | None = None
    ) -> None: ...
    def run(self, photon_rate: npt.NDArray[np.floating], t_s: npt.ArrayLike) -> np.ndarray: ...
    def run_probe(
        self, photon_rate: npt.NDArray[np.floating], t_s: npt.ArrayLike, pixels: Sequence[int]
    ) -> tuple[np.ndarray, np.ndarray]: ...
    def run_pixels(
        self, pixels: npt.ArrayLike, photon_rate: npt.NDArray[np.floating], t_s: npt.ArrayLike
    ) -> np.ndarray: ...
    def reset(self) -> None: ...
    def last_labels(self) -> np.ndarray: ...
    def set_hot_pixel_rates(self, rates_hz: npt.ArrayLike) -> None: ...
    def hot_pixel_rates(self) -> np.ndarray: ...
    def thresholds(self, on: bool) -> np.ndarray: ...
