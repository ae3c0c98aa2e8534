// A pixel's parameters (PixelParams, with each default's source), the enums that choose its
// models, hot-pixel chains, and their checks (validate): what an embedder sets.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <new>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "config.hpp"
#include "constants.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

enum class DarkModel { Poisson, Paper, None };
enum class LowPass { Exact, Euler };
/// How shot noise reaches the comparator. Continuous (default): the current's shot noise as a
/// white process through the photoreceptor pole and the source follower, advanced exactly
/// between samples (noise.hpp), so its statistics do not depend on the sampling. Sampled: the
/// paper's model, a Poisson electron count per sample interval (eq. 4), whose noise grows as
/// the samples get shorter; kept to reproduce the paper.
enum class NoiseModel { Continuous, Sampled };
/// Which way the comparator's reference drifts (eq. 10-11's leak): On, the paper's, lowers the
/// reference so d = y - ref climbs to theta_on and the leak fires ON events; Off raises it, so d
/// falls to -theta_off and the leak fires OFF events (Nozaki & Delbruck 2017: the direction is a
/// property of the pixel design; the IMX636's leak fires OFF).
enum class LeakPolarity { On, Off };

/// Why an event fired (the optional label column of the output).
enum EventLabel : std::uint8_t {
    LABEL_SIGNAL = 0,      ///< the mean photocurrent changed (the scene)
    LABEL_SHOT_NOISE = 1,  ///< photon and dark-current shot noise crossed a threshold
    LABEL_LEAK = 2,        ///< the reference leaked to a threshold (eq. 10-11; ON or OFF, leak_polarity)
    LABEL_BACKGROUND = 3,  ///< a background-activity event of eq. 12 (statistical shot noise)
    LABEL_HOT_PIXEL = 4,   ///< a hot or flickering pixel
};

/// Parameters of every pixel of a sensor. Defaults are the paper's DAVIS346 pixel: Table 3
/// photodiode constants, section 2 noise figures, thresholds of the Table 1 bias set.
struct PixelParams {
    // Comparator (eq. 8-9), natural-log units of photocurrent; both positive.
    double theta_on = 0.2061;   ///< ON threshold; paper sec. 3.1 (Table 1 biases)
    double theta_off = 0.0930;  ///< OFF threshold; paper sec. 3.1 (Table 1 biases)
    /// Dead time after each event [s]. The paper gives no value; 1 ms lies in the
    /// 0.33-10 ms range McReynolds et al. measured on the DAVIS346.
    double refractory_s = 1e-3;
    /// Source-follower low-pass cutoff [Hz]; empty = no filter. Paper sec. 2.2: 10 Hz.
    std::optional<double> cutoff_hz = 10.0;
    LowPass lowpass = LowPass::Exact;  ///< Exact first-order update, or eq. 7 (forward Euler)
    double leak_rate_hz = 0.1;         ///< f_leak, eq. 11; paper: 0.1 Hz
    double shot_noise_rate_hz = 0.05;  ///< R_n, eq. 12, of each polarity; paper: 0.05 Hz
    /// Eq. 12's R_n of ON and OFF events separately (empty: shot_noise_rate_hz). Real sensors'
    /// background is far from symmetric (17 % ON on an IMX636 dark sky, ~100 % ON on a
    /// DAVIS346 static scene), whatever the thresholds.
    std::optional<double> shot_noise_on_rate_hz;
    std::optional<double> shot_noise_off_rate_hz;
    /// Spread of eq. 12's rates across pixels: each pixel's ON and OFF rates are R exp(s z - s^2/2)
    /// with independent z ~ N(0, 1) fixed per pixel for a seed (log-normal, mean R). 0 = none.
    double background_rate_sigma = 0.0;
    /// Spread of the leak rate across pixels, log-normal as above. 0 = every pixel at f_leak.
    double leak_rate_sigma = 0.0;
    /// Start each pixel at a random phase of its leak cycle (the reference a uniform share of
    /// theta_on below the signal), so leak events are stationary from t = 0 instead of all
    /// pixels firing together at 1 / f_leak. Off reproduces the paper's lockstep.
    bool leak_random_phase = true;
    /// The leak's rise with light [Hz/A]: parasitic photocurrent in the reset switch's junction
    /// adds to its dark leakage, so the leak rate grows linearly with the photocurrent (Nozaki &
    /// Delbruck 2017, IEEE TED 64(8)). A pixel's leak rate over a sample is
    ///   (leak_rate_hz + leak_photocurrent_hz_per_a * I_photo) * s,
    /// I_photo = e * electrons_per_photon * photon rate the mean photocurrent of the sample
    /// (the dark current is not in it: its leak is leak_rate_hz), s the pixel's log-normal
    /// factor (leak_rate_sigma). s multiplies both parts: they flow through the same junction
    /// into the same capacitor, so a pixel whose junction or capacitor makes it leak faster in
    /// the dark does so in the light too. 0 = a leak independent of the light (the paper's).
    double leak_photocurrent_hz_per_a = 0.0;
    LeakPolarity leak_polarity = LeakPolarity::On;  ///< direction of the leak's drift
    /// Hot (flickering) pixels: a share of the pixels, chosen per seed, fires alternating ON and
    /// OFF events whatever the light: after each event the pixel is dead for refractory_s, then
    /// fires after an exponential wait of rate r, so it fires r / (1 + r refractory_s) times a
    /// second. r is log-normal about hot_pixel_rate_hz (its median) with hot_pixel_rate_sigma.
    /// A sensor can also be given an explicit map of hot-pixel rates instead.
    double hot_pixel_fraction = 0.0;
    double hot_pixel_rate_hz = 100.0;
    double hot_pixel_rate_sigma = 0.0;
    /// Hot pixels flicker in bursts (random telegraph noise, the usual cause of a flickering
    /// pixel): each is active a share hot_pixel_duty of the time, in active periods of mean
    /// hot_pixel_burst_s (exponential), and fires only then. 1 = always active.
    double hot_pixel_duty = 1.0;
    double hot_pixel_burst_s = 0.1;
    /// A hot pixel's polarities as a two-state Markov chain: its long-run share of ON events
    /// and the share of successive events of opposite polarity (the chain switches from ON
    /// with probability alternation / (2 on_share), from OFF alternation / (2 (1 - on_share)),
    /// so alternation <= 2 min(on_share, 1 - on_share)). 0.5 and 1: strict alternation. The
    /// real IMX636 hot pixel: 0.59 and 0.78 (switching 66 % from ON, 95 % from OFF).
    double hot_pixel_on_share = 0.5;
    double hot_pixel_alternation = 1.0;
    NoiseModel noise_model = NoiseModel::Continuous;
    double shot_noise_factor = 0.25;   ///< F, eq. 12; paper: 0.25
    double shot_noise_i_max_a = 3.16e-9;  ///< I_max, eq. 12 [A]; paper: 3.16 nA
    // Dark current (eq. 1, 4): mean rate of thermally generated electrons.
    double dark_rate_e_per_s = 18000.0;  ///< iniVation's figure quoted in sec. 2.1
    DarkModel dark_model = DarkModel::Poisson;
    bool photon_shot_noise = true;  ///< Poisson photon (electron) counts on the signal
    /// Per-pixel threshold mismatch: each pixel's thresholds are theta * (1 + sigma z),
    /// z ~ N(0, 1) fixed per pixel for a seed, redrawn where theta would fall below 1 % of
    /// its nominal value. 0 = identical pixels (the paper's model).
    double threshold_sigma = 0.0;
    // Photodiode (eq. 2) and pixel geometry; Table 3 and sec. 3.1.
    double fill_factor = 0.22;             ///< photodiode share of the pixel area (DAVIS346)
    double internal_qe = 1.0;              ///< eta_i
    double transmission = 0.68;            ///< tau
    double absorption_per_m = 3e4;         ///< alpha [1/m]
    double depletion_width_m = 1.1637e-7;  ///< W [m]
    // Optional photoreceptor pole in series before the source follower. Its cutoff scales
    // with the pixel's own photocurrent, f_pr = pr_cutoff_ref_hz * I / pr_ref_current_a:
    // the real photoreceptor is slow in the dark. The defaults (1 kHz at 1 pA) are an
    // order-of-magnitude estimate, f = kappa I / (2 pi C U_T) with C ~ 20 fF and a loop
    // gain ~5; calibrate them against a recording before trusting latencies.
    bool pr_pole = false;
    double pr_cutoff_ref_hz = 1000.0;
    double pr_ref_current_a = 1e-12;

    /// Electrons per photon arriving on the pixel: fill factor x eq. 2 without e.
    double electrons_per_photon() const {
        return fill_factor * internal_qe * transmission * (1.0 - std::exp(-absorption_per_m * depletion_width_m));
    }
};

namespace detail {
inline std::string fmt(double v) {
    std::ostringstream s;
    s.precision(17);
    s << v;
    return s.str();
}
inline void require_range(const char* name, double v, double lo, double hi, const char* unit) {
    if (!(v >= lo && v <= hi)) {
        throw std::invalid_argument(std::string(name) + " must be in [" + fmt(lo) + ", " + fmt(hi) + "]" + unit +
                                    "; got " + name + "=" + fmt(v));
    }
}

}  // namespace detail

/// A hot pixel's telegraph and polarity chain: what PixelParams' hot_pixel_duty,
/// hot_pixel_burst_s, hot_pixel_on_share and hot_pixel_alternation give every hot pixel, and
/// what a sensor may give one pixel of its own (Sensor::set_hot_pixel_chains): real hot
/// pixels differ (the IMX636 recording's flickering pixel is ON 0.59 of the time, its leaky
/// one 0.98, in one burst of a second).
struct HotPixelChain {
    double duty = 1.0;        ///< share of the time the pixel is active (fires)
    double burst_s = 0.1;     ///< mean active period [s] (exponential)
    double on_share = 0.5;    ///< long-run share of ON events
    double alternation = 1.0; ///< share of successive events of opposite polarity
};

/// The chain PixelParams gives every hot pixel without a chain of its own.
inline HotPixelChain hot_chain_of(const PixelParams& p) {
    return {p.hot_pixel_duty, p.hot_pixel_burst_s, p.hot_pixel_on_share, p.hot_pixel_alternation};
}

/// Throws std::invalid_argument naming the first field out of range and its value; the
/// fields are named prefix + "duty", ... ("hot_pixel_" for PixelParams' own).
inline void validate_hot_chain(const HotPixelChain& c, const std::string& prefix) {
    using detail::require_range;
    const auto name = [&](const char* field) { return prefix + field; };
    require_range(name("duty").c_str(), c.duty, 1e-6, 1.0, " (share of the time)");
    require_range(name("burst_s").c_str(), c.burst_s, 1e-6, 1e6, " s");
    require_range(name("on_share").c_str(), c.on_share, 1e-6, 1.0 - 1e-6, " (share of a hot pixel's events)");
    require_range(name("alternation").c_str(), c.alternation, 0.0, 1.0, " (share of successive events)");
    if (c.alternation > 2.0 * std::min(c.on_share, 1.0 - c.on_share) * (1.0 + 1e-12))
        throw std::invalid_argument(name("alternation") + " must be at most 2 min(" + name("on_share") + ", 1 - " +
                                    name("on_share") + ") (a chain that is ON a share s of the time switches at most "
                                    "2 min(s, 1 - s) of its events); got " + name("alternation") + "=" +
                                    detail::fmt(c.alternation) + " with " + name("on_share") + "=" +
                                    detail::fmt(c.on_share));
}

/// Throws std::invalid_argument naming the first parameter out of range and its value.
inline void validate(const PixelParams& p) {
    using detail::require_range;
    constexpr double inf = std::numeric_limits<double>::max();
    require_range("theta_on", p.theta_on, 1e-3, 10.0, " (natural-log units)");
    require_range("theta_off", p.theta_off, 1e-3, 10.0, " (natural-log units)");
    require_range("refractory_s", p.refractory_s, 0.0, 1.0, " s");
    if (p.cutoff_hz) require_range("cutoff_hz", *p.cutoff_hz, 1e-6, 1e9, " Hz (or None for no filter)");
    require_range("leak_rate_hz", p.leak_rate_hz, 0.0, 1e6, " Hz");
    require_range("shot_noise_rate_hz", p.shot_noise_rate_hz, 0.0, 1e6, " Hz");
    if (p.shot_noise_on_rate_hz) require_range("shot_noise_on_rate_hz", *p.shot_noise_on_rate_hz, 0.0, 1e6, " Hz (or None)");
    if (p.shot_noise_off_rate_hz)
        require_range("shot_noise_off_rate_hz", *p.shot_noise_off_rate_hz, 0.0, 1e6, " Hz (or None)");
    require_range("background_rate_sigma", p.background_rate_sigma, 0.0, 3.0, " (natural-log units)");
    require_range("leak_rate_sigma", p.leak_rate_sigma, 0.0, 3.0, " (natural-log units)");
    require_range("leak_photocurrent_hz_per_a", p.leak_photocurrent_hz_per_a, 0.0, 1e30, " Hz/A");
    require_range("hot_pixel_fraction", p.hot_pixel_fraction, 0.0, 1.0, "");
    require_range("hot_pixel_rate_hz", p.hot_pixel_rate_hz, 0.0, 1e6, " Hz");
    require_range("hot_pixel_rate_sigma", p.hot_pixel_rate_sigma, 0.0, 3.0, " (natural-log units)");
    validate_hot_chain(hot_chain_of(p), "hot_pixel_");
    if (p.noise_model == NoiseModel::Continuous && p.dark_model == DarkModel::Paper)
        throw std::invalid_argument("dark_model='paper' (eq. 4: Poisson(rate) electrons per sample, whatever dt) is a "
                                    "per-sample model; use it with noise_model='sampled'");
    if (p.noise_model == NoiseModel::Continuous && !p.cutoff_hz && !p.pr_pole &&
        (p.photon_shot_noise || p.dark_model == DarkModel::Poisson))
        throw std::invalid_argument("noise_model='continuous' needs a low-pass to band-limit the shot noise (cutoff_hz "
                                    "or pr_pole=True); got cutoff_hz=None and pr_pole=False (or use noise_model='sampled')");
    require_range("shot_noise_factor", p.shot_noise_factor, 0.0, 1e6, "");
    require_range("shot_noise_i_max_a", p.shot_noise_i_max_a, 1e-30, 1.0, " A");
    require_range("dark_rate_e_per_s", p.dark_rate_e_per_s, 0.0, 1e15, " e-/s");
    require_range("threshold_sigma", p.threshold_sigma, 0.0, 1.0, " (fraction of the threshold)");
    require_range("fill_factor", p.fill_factor, 1e-6, 1.0, "");
    require_range("internal_qe", p.internal_qe, 1e-6, 1.0, "");
    require_range("transmission", p.transmission, 1e-6, 1.0, "");
    require_range("absorption_per_m", p.absorption_per_m, 1e-6, inf, " 1/m");
    require_range("depletion_width_m", p.depletion_width_m, 1e-15, 1.0, " m");
    require_range("pr_cutoff_ref_hz", p.pr_cutoff_ref_hz, 1e-6, 1e12, " Hz");
    require_range("pr_ref_current_a", p.pr_ref_current_a, 1e-30, 1.0, " A");
}

}  // namespace evstwin

EVSTWIN_FP_STRICT_END
