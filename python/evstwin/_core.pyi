"""Type stubs of the compiled engine (cpp/bindings). Private: use the evstwin package."""

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

__version__: str
EVENT_DTYPE: np.dtype
TRACE_DTYPE: np.dtype
ELEMENTARY_CHARGE_C: float
EVENT_LABELS: dict[int, str]

def validate_hot_pixel_chain(duty: float, burst_s: float, on_share: float, alternation: float, prefix: str) -> None: ...

def has_openmp() -> bool: ...
def default_num_threads() -> int: ...
def simd_levels() -> list[str]: ...
def simd_level() -> str: ...
def set_simd_level(level: str) -> None: ...
def bilinear_phase_mix(table: npt.NDArray[np.float64], q: npt.NDArray[np.intp], p: npt.NDArray[np.intp],
                       a: npt.NDArray[np.float64], b: npt.NDArray[np.float64],
                       flux: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]: ...
def add_scaled_terms(image: npt.NDArray[np.float64], terms: Sequence[npt.NDArray[np.float64]],
                     coef: Sequence[float]) -> None: ...

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
    shot_noise_on_rate_hz: float | None
    shot_noise_off_rate_hz: float | None
    background_rate_sigma: float
    leak_rate_sigma: float
    leak_random_phase: bool
    leak_photocurrent_hz_per_a: float
    leak_polarity: str
    hot_pixel_fraction: float
    hot_pixel_rate_hz: float
    hot_pixel_rate_sigma: float
    hot_pixel_duty: float
    hot_pixel_burst_s: float
    hot_pixel_on_share: float
    hot_pixel_alternation: float
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
    kernel: str  # 'auto', 'per_pixel', 'blocks' or 'vector': the same events whichever
    DEFAULT_MAX_EVENTS: int
    MAX_THREADS: int
    MAX_PIXELS: int
    STATE_BYTES_PER_PIXEL: int
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
    def run_sparse(
        self, static_rate: np.ndarray, t_s: np.ndarray, base_every: int, group_base_samples: int,
        light_sample: np.ndarray, light_pixel: np.ndarray, light_rate: np.ndarray,
        reach_pixel: np.ndarray | None = None
    ) -> np.ndarray: ...
    @property
    def last_pixel_updates(self) -> int: ...
    def settle_time_s(self, photon_rate: float) -> float: ...
    def reset(self) -> None: ...
    def last_labels(self) -> np.ndarray: ...
    def set_hot_pixel_rates(self, rates_hz: npt.ArrayLike) -> None: ...
    MAX_HOT_PIXEL_CHAINS: int
    def set_hot_pixel_chains(self, pixels: Sequence[int], duty: Sequence[float], burst_s: Sequence[float],
                             on_share: Sequence[float], alternation: Sequence[float]) -> None: ...
    def hot_pixel_rates(self) -> np.ndarray: ...
    def thresholds(self, on: bool) -> np.ndarray: ...

class Readout:
    max_rate_hz: float
    fifo_depth: int
    tick_s: float
    tick_units: int
    last_t_us: int
    n_in: int
    n_out: int
    n_dropped: int
    n_dropped_on: int
    n_delayed: int
    max_delay_s: float
    peak_waiting: int
    TIME_UNIT_S: float
    MAX_QUEUE_DELAY_S: float
    MAX_RATE_HZ: float
    MIN_TICK_S: float
    MAX_TICK_S: float
    MAX_ABS_T_US: int
    def __init__(self, max_rate_hz: float, fifo_depth: int, tick_s: float) -> None: ...
    def process(self, events: np.ndarray) -> np.ndarray: ...
    def process_with_index(self, events: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...
    def process_with_delays(self, events: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...
    def reset(self) -> None: ...
