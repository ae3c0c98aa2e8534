// The physics of one event-sensor pixel (the paper's section 2; DESIGN.md for the traps).
//
// Signal chain, per sample interval (t0, t1]:
//   photons/s on the pixel -> photodiode current I = e (QE * ff * lambda + dark)   eq. 1-2, 4
//   -> log photoreceptor x = ln I                                                     eq. 5
//   -> optional photoreceptor pole whose cutoff scales with I (off by default)
//   -> source-follower low-pass y (exact first-order update by default)               eq. 6-7
//   -> comparator: ON when y - ref >= theta_on, OFF when ref - y >= theta_off, at
//      linearly interpolated times (eq. 16), several per interval, with a refractory
//      period, leak of the reference (eq. 10-11) and statistical shot noise (eq. 12-15).
//
// All levels are in natural-log units of current: the factors U_T/kappa and C1/C2 cancel
// once the thresholds are in those units (DESIGN.md point 3).
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
#include "event.hpp"
#include "noise.hpp"
#include "rng.hpp"
#include "simd.hpp"

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

/// std::floor(x), by truncation where x is in (0, 2^52) (elsewhere the library's): there the
/// truncation is the floor, and the default SSE2 target has no rounding instruction.
inline double floor_positive(double x) {
    return (x > 0.0) & (x < 4503599627370496.0) ? static_cast<double>(static_cast<std::int64_t>(x)) : std::floor(x);
}

/// u < std::exp(-e), the same answer for every u and e, with the exp only where bounds leave it
/// open: above e = 24, exp(-e) < 3.8e-11 lies below uniform_open()'s least value 2^-33, so a
/// uniform is never below it; on [0, 24], exp_neg_bracket (within a relative 1e-8) decides
/// where u lies farther than a relative 1e-6 from it. init_state's leak-phase acceptance: an
/// event-heavy pixel's noise rejects almost every attempt with e > 40.
inline bool below_exp_neg(double u, double e) {
    if ((e > 24.0) & (u >= 0x1p-33)) return false;
    if ((e >= 0.0) & (e <= 24.0)) {
        const double q = exp_neg_bracket(e);
        if (u < q * (1.0 - 1e-6)) return true;
        if (u > q * (1.0 + 1e-6)) return false;
    }
    return u < std::exp(-e);
}

/// Whether a uniform u in (0, 1) fires a Brownian bridge that crosses the ON level with
/// probability bridge_crossing_probability(on0, on1, mid) = p_on and the OFF one with p_off
/// (u < p_on + p_off), and at which (on: u < p_on): the decisions compare_bridged() takes,
/// the same for every u. Decided on exp_neg_bracket where u lies farther than a relative 1e-6
/// from both sums (their error is below 1e-8, the library exp's 1e-16), so the two exps are
/// computed only for the one uniform in ~10^5 that lies that close.
inline bool bridge_fires(double u, double on0, double on1, double off0, double off1, double mid, bool& on) {
    if (!(mid > 0.0)) {  // bridge_crossing_probability is 0 for both
        on = false;
        return false;
    }
    // The exponents as bridge_crossing_probability forms them; above 40 it gives 0.
    const double e_on = on0 * on1 / (2.0 * mid), e_off = off0 * off1 / (2.0 * mid);
    // (A negative or NaN exponent, which the comparator's callers never form, goes to the exps.)
    const bool in_range = (e_on >= 0.0) & (e_off >= 0.0);
    const double q_on = !in_range || e_on > 40.0 ? 0.0 : exp_neg_bracket(e_on);
    const double q_off = !in_range || e_off > 40.0 ? 0.0 : exp_neg_bracket(e_off);
    const double q = q_on + q_off;
    constexpr double lo = 1.0 - 1e-6, hi = 1.0 + 1e-6;
    const bool fire_known = (u < q * lo) | (u > q * hi);
    const bool on_known = (u < q_on * lo) | (u > q_on * hi);
    if (in_range & fire_known & on_known) {
        on = u < q_on;
        return u < q;
    }
    const double p_on = bridge_crossing_probability(on0, on1, mid);
    const double p_off = bridge_crossing_probability(off0, off1, mid);
    on = u < p_on;
    return u < p_on + p_off;
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

/// The state of one pixel between samples. Kept as one small record so a pixel's whole
/// state sits in one cache line.
struct PixelState {
    double x = 0.0;            ///< log-photoreceptor input at the last sample, ln(I / 1 A)
    double z = 0.0;            ///< input of the source follower (photoreceptor pole output)
    double y = 0.0;            ///< source-follower output: the level the comparator sees
    double ref = 0.0;          ///< comparator reference (level at the last event, leaking)
    double refr_until = -std::numeric_limits<double>::infinity();  ///< refractory end [s]
    double theta_on = 0.0;     ///< this pixel's thresholds, mismatch included
    double theta_off = 0.0;
    double t = -std::numeric_limits<double>::infinity();  ///< time of the last sample [s]
    std::uint64_t n = 0;                          ///< samples consumed: the RNG's sample counter
    std::uint64_t spare_words = 0;                ///< Philox words 2-3 of the last even sample
    std::uint64_t spare_sample = ~std::uint64_t{0};  ///< the odd sample they belong to
    // Continuous noise model: the noise parts of z and y (z holds the noise-free pole output,
    // y the whole level, so the noise-free source-follower output is y - ny).
    double nz = 0.0, ny = 0.0;
    // Where the last event left the pixel, to tell why the next one fires: the level set as
    // the reference then (before any leak) and the noise part of the signal then.
    double level_at_event = 0.0, noise_at_event = 0.0;
    // This pixel's background: its leak rate's log-normal factor (mean 1; the rate itself
    // follows the light, PixelModel::leak_rate_hz), eq. 12 rates with their spread, and a hot
    // pixel's exponential rate (0: not hot), next event time, polarity and event counter.
    double leak_spread = 1.0, bg_on_hz = 0.0, bg_off_hz = 0.0;
    double hot_hz = 0.0;
    double next_hot_t = std::numeric_limits<double>::infinity();  ///< min(next event, next switch)
    double hot_event_t = std::numeric_limits<double>::infinity();  ///< next event (inf while quiet)
    double hot_switch_t = std::numeric_limits<double>::infinity(); ///< next active <-> quiet switch
    double hot_last_t = -std::numeric_limits<double>::infinity();  ///< last event (for the dead time)
    std::uint64_t hot_count = 0, hot_switches = 0;
    std::uint8_t hot_pol = 0, hot_active = 1;
    std::uint16_t hot_chain = 0;  ///< PixelModel::hot_chains index: 0 the params', else the pixel's own
    /// Continuous model: what is left of the exponential budgets of eq. 12's ON and OFF clocks.
    double bg_clock_on = 0.0, bg_clock_off = 0.0;
};

/// CounterStream(key, pixel, sample, purpose) whose first block of four words a Philox batch
/// has already computed (`first`; nullptr: none, the stream computes it as usual). The same
/// words in the same order: the first four from `first`, the rest from the stream, which
/// recomputes its first block once to reach the second (only the ziggurat's rare slow path
/// asks for a fifth word).
class PrefilledStream {
public:
    PrefilledStream(Philox4x32Key key, std::uint32_t pixel, std::uint64_t sample, std::uint32_t purpose,
                    const Philox4x32Counter* first)
        : rest_(key, pixel, sample, purpose), used_(first ? 0 : 5) {
        if (first) first_ = *first;
    }
    std::uint32_t word() {
        if (used_ < 4) return first_[used_++];
        if (used_ == 4) {  // past the given block: the stream's first block is the same four words
            for (int i = 0; i < 4; ++i) (void)rest_.word();
            used_ = 5;
        }
        return rest_.word();
    }
    /// As CounterStream::uniform(): the next word in (0, 1).
    double uniform() { return uniform_open(word()); }

private:
    CounterStream rest_;
    Philox4x32Counter first_{};
    int used_;  ///< words taken from first_ (0-4); 5: the rest come from rest_
};

/// compare_bridged()'s draw for one pixel made ahead by the block kernel (bridge_decisions):
/// the first block of the bridge's random words and whether (and at which level) it fires.
struct BridgePre {
    Philox4x32Counter words{};
    /// compare_bridged()'s test of whether the bridge applies (a bridge variance, time left after
    /// the refractory period, the line inside both levels there and at the end), made ahead:
    /// false, no draw; true, `fires` and `on` are the draw's decision.
    bool known = false;
    bool fires = false, on = false;
    /// Where it fires and its normal took the ziggurat's common path (one word): the crossing
    /// time tc that compare_bridged() would draw from the same words, and 1 / (tc - c.t0),
    /// 1 / (c.t1 - tc), its two pieces' inverse lengths (the same expressions). Drawn in a
    /// batch, so these divisions and the square root overlap across pixels instead of standing
    /// in each event's chain.
    bool timed = false;
    double tc = 0.0, inv_first_dt = 0.0, inv_second_dt = 0.0;
};

/// Per-sample constants shared by every pixel: computed once per sample, not per pixel.
struct SampleConstants {
    double t0 = 0.0, t1 = 0.0, dt = 0.0;
    double inv_dt = 0.0;       ///< 1 / dt: a multiply in the hot loop instead of a divide
    double e_over_dt = 0;      ///< e / dt: the current of one electron per interval [A]
    double log_e_over_dt = 0;  ///< ln(e / dt)
    double sf_decay = 0;       ///< exact: exp(-2 pi fc dt); euler: 1 - 2 pi fc dt
    double sf_ramp = 0;        ///< exact: (1 - exp(-u)) / u, u = 2 pi fc dt; euler: 2 pi fc dt
};

/// What the continuous model computes for one (photon rate, interval): the same for every
/// pixel at the background's rate, so one per thread is kept and reused while they repeat.
struct NoiseCache {
    double photon_rate = -1.0, dt = -1.0;
    double current_a = 0, x = 0, a = 0, D = 0;
    double pole_decay = 0, pole_ramp = 0;
    NoiseCoeffs k;
    SfTerms sf;  ///< the source follower's part of k for this dt (sf_terms)
    double bg_factor = 0;  ///< eq. 12's illumination factor at current_a (background_factor)
    double leak_hz = 0;    ///< the leak rate at this photon rate before a pixel's spread (leak_rate_hz)
    /// For the block kernel's quiet test: a pixel whose line stays inside both thresholds over
    /// the whole interval cannot cross by the bridge when (theta - d0)(theta - d1) exceeds this
    /// for both levels. Then both exponents of bridge_crossing_probability exceed 24, so
    /// p_on + p_off < 2 exp(-24) = 7.6e-11, below the smallest uniform there is, 2^-33 =
    /// 1.16e-10: the draw could not fire. 48 (1 + 1e-8) times the middle variance over the
    /// interval (the margin covers the rounding of the exponent's division).
    /// While !bridge_ready: the same bound for twice k.q_yy, above it (bridge_var_bounded()).
    double bridge_bound = 0;
    /// false: k.bridge_var is not computed yet, and bridge_bound is the upper bound from
    /// k.q_yy (fill_noise_cache(..., lazy_bridge = true)); complete_noise_cache() computes it.
    /// A pixel found quiet with the upper bound is quiet with the exact one: the same
    /// decision, and the bridge's terms (an exp, two expm1 and five divisions) only for the
    /// pixels that might cross.
    bool bridge_ready = true;
    /// When lazy fills pay (fill_noise_cache): +1 for a lazy fill no pixel had to complete and
    /// for an eager one, -3 for a completion; lazy while >= 0. Over long intervals most pixels
    /// need the bridge anyway, and then the split costs more than it saves (the bridge's terms
    /// wait for the quiet test). Speed only: either way gives the same numbers.
    int lazy_credit = 0;
};

/// What one pixel-sample update reports for a probe (diagnostic trace).
struct TraceSample {
    double current_a;    ///< photodiode current over the interval [A]
    double log_current;  ///< x = ln(I / 1 A)
    double filtered;     ///< y, the comparator input
    double reference;    ///< the comparator reference at the end of the interval
};

namespace detail {
/// One array of a block's pixels inside a BlockArena: what the kernels use of a std::vector
/// (data(), operator[], size()), with the storage owned by the arena.
template <class T>
class BlockArray {
public:
    T* data() { return p_; }
    const T* data() const { return p_; }
    T& operator[](std::size_t i) { return p_[i]; }
    const T& operator[](std::size_t i) const { return p_[i]; }
    std::size_t size() const { return n_; }

private:
    friend class BlockArena;
    T* p_ = nullptr;
    std::size_t n_ = 0;
};

/// The per-pixel arrays of a block (BlockSoA, PixelModel::BlockScratch) in one allocation,
/// each starting one cache line after the previous one ends. Why: a block's arrays are all
/// 2 KB long (256 doubles), and as separate heap blocks (glibc puts them 2,064 bytes apart)
/// every other one started within 32 bytes of the same offset in a 4 KB page, so the quiet
/// pass's stores to one array and loads from another looked alike to the CPU's 4 KB store-load
/// aliasing check and the loads waited (the same events; up to ~12 % of the quiet pass's
/// time, and it came and went with where the heap placed them). Laid out here, n equal
/// arrays start at n different 64-byte offsets of a page (2,112 = 33 lines apart; 33 is
/// odd, so up to 64 of them).
class BlockArena {
public:
    BlockArena() = default;
    BlockArena(const BlockArena&) = delete;
    BlockArena& operator=(const BlockArena&) = delete;
    BlockArena(BlockArena&&) = default;  // the arrays' storage does not move with it
    BlockArena& operator=(BlockArena&&) = default;

    /// Lay out again every array that `each` names (each(put) calls put(array, size) for
    /// every one, in the same order each time): their elements kept up to the smaller size,
    /// new ones value-initialised (as std::vector::resize would).
    template <class Each>
    void lay_out(Each&& each) {
        std::size_t bytes = 0;
        each([&bytes](auto& a, std::size_t n) {
            using T = std::remove_reference_t<decltype(a[0])>;
            bytes = start_of(bytes) + n * sizeof(T);
        });
        std::unique_ptr<unsigned char[]> mem(new unsigned char[bytes + LINE]);
        unsigned char* base = mem.get() + (LINE - reinterpret_cast<std::uintptr_t>(mem.get()) % LINE) % LINE;
        std::size_t at = 0;
        each([&at, base](auto& a, std::size_t n) {
            using T = std::remove_reference_t<decltype(a[0])>;
            static_assert(std::is_trivially_copyable_v<T>, "BlockArena holds plain numbers");
            at = start_of(at);
            T* p = reinterpret_cast<T*>(base + at);
            const std::size_t kept = std::min(a.n_, n);
            if (kept) std::memcpy(static_cast<void*>(p), a.p_, kept * sizeof(T));
            for (std::size_t i = kept; i < n; ++i) new (p + i) T{};
            a.p_ = p;
            a.n_ = n;
            at += n * sizeof(T);
        });
        mem_ = std::move(mem);  // the old storage goes only now: its elements were copied above
    }

private:
    static constexpr std::size_t LINE = 64;
    /// Where the next array starts after one that ends at `end`: the next line, and one more.
    static std::size_t start_of(std::size_t end) { return (end + LINE - 1) / LINE * LINE + LINE; }
    std::unique_ptr<unsigned char[]> mem_;
};
}  // namespace detail

/// The fields of a block's pixel states that the continuous block kernel's common path reads
/// or writes, as a structure of arrays: a working copy of the block for the samples of one
/// run call (loaded before the first, stored after the last), so that path is one loop over
/// contiguous arrays that the compiler vectorises. The array-of-structures PixelState stays
/// the state between calls and for the rare pixels that need the whole comparator.
///
/// The fields a sample changes for every pixel are double-buffered (but the sample counter,
/// which grows by one for every pixel: n_base): a sample reads `now()`
/// and writes `next()` for every pixel (a quiet pixel's new values, or a busy one's after the
/// per-pixel path), then flip() makes them current. So the vector loop stores everything
/// unconditionally (a conditional store, "keep the old value unless quiet", is what stops a
/// compiler vectorising it) and the per-pixel path still starts from the old state.
struct BlockSoA {
    /// How many pixels ahead load() asks for their states' cache lines. Speed only.
    static constexpr std::size_t PREFETCH_AHEAD = 8;
    struct Levels {
        detail::BlockArray<double> x, z, y, nz, ny, ref, clock_on, clock_off;
    };
    Levels buf[2];
    int cur = 0;
    /// The sample counters (PixelState::n): pixel j's is n_base[j] + n_step (count()). Every
    /// pixel in the arrays advances one sample a step (flip() counts them), so no pass loads or
    /// stores a counter that only grows by one; take() and give() translate.
    detail::BlockArray<std::uint64_t> n_base;
    std::uint64_t n_step = 0;
    detail::BlockArray<double> refr_until, next_hot_t;  ///< changed only by the per-pixel path
    detail::BlockArray<double> theta_on, theta_off, leak_spread, bg_on_hz, bg_off_hz;  ///< constant in a run
    /// The quiet pass's per-pixel terms that hold while the block's common rate does (made by
    /// PixelModel::prepare_quiet_terms, with the operations the pass made them with): the leak's
    /// part of the slope, PixelModel::leak_slope(leak_spread, theta_on, theta_off, leak_hz), and
    /// the background clocks' rates bg_on_hz * bg_factor, bg_off_hz * bg_factor. One stream
    /// each in place of two or three, and their multiplies out of every sample's pass.
    detail::BlockArray<double> leak_g, bg_on_rate, bg_off_rate;
    /// The leak_hz and bg_factor those terms are for (NaN: none; load() forgets them).
    double terms_leak_hz = std::numeric_limits<double>::quiet_NaN();
    double terms_bg_factor = std::numeric_limits<double>::quiet_NaN();
    /// Whether the levels' x and nz are left unwritten by the quiet pass (QuietChain::SfOnly):
    /// with the source follower alone z is x (no pole between them) and nz is 0 (z carries no
    /// noise: PixelModel::continuous_levels), in every state at all times, so give() makes
    /// them and the pass saves a stream of loads and two of stores.
    bool sf_only = false;
    /// PixelState::spare_words as its two 32-bit halves (the Philox batch writes its third and
    /// fourth words straight into them, and the next odd sample reads them in place), and
    /// spare_sample: changed in place by the word batch.
    detail::BlockArray<std::uint32_t> spare_lo, spare_hi;
    detail::BlockArray<std::uint64_t> spare_sample;
    /// The quiet pass's verdict per pixel (0 quiet, 1 bridge, 2 per-pixel path), 64-bit like
    /// the levels: a byte array would make the vectoriser take 64 pixels an iteration (one
    /// byte vector), eight zmm registers per level, and spill them to the stack.
    detail::BlockArray<std::uint64_t> busy;
    detail::BlockArena arena;  ///< where the arrays above live

    Levels& now() { return buf[cur]; }
    const Levels& now() const { return buf[cur]; }
    Levels& next() { return buf[cur ^ 1]; }
    void flip() {
        cur ^= 1;
        ++n_step;
    }
    /// Pixel j's sample counter (PixelState::n) before the coming step.
    std::uint64_t count(std::size_t j) const { return n_base[j] + n_step; }

    void resize(std::size_t m) {
        if (busy.size() >= m) return;
        arena.lay_out([this, m](auto&& put) {
            for (Levels& l : buf) {
                for (auto* v : {&l.x, &l.z, &l.y, &l.nz, &l.ny, &l.ref, &l.clock_on, &l.clock_off}) put(*v, m);
            }
            for (auto* v : {&refr_until, &next_hot_t, &theta_on, &theta_off, &leak_spread, &bg_on_hz, &bg_off_hz,
                            &leak_g, &bg_on_rate, &bg_off_rate})
                put(*v, m);
            put(spare_lo, m);
            put(spare_hi, m);
            put(spare_sample, m);
            put(n_base, m);
            put(busy, m);
        });
    }
    /// Pixel j's fields from its state, its changing levels into `into`: now() for a state at
    /// the coming step's start, next() for one at its end (the per-pixel path's; its counter
    /// one ahead of count()).
    EVSTWIN_ALWAYS_INLINE void take(const PixelState& s, std::size_t j, Levels& into) {
        take_at(fields(into), s, j, s.n - n_step - static_cast<std::uint64_t>(&into != &now()));
    }
    /// Pixel j's fields back into its state, its changing levels from `from` (the constant
    /// ones are not written).
    EVSTWIN_ALWAYS_INLINE void give(PixelState& s, std::size_t j, const Levels& from) const {
        give_at(fields(from), sf_only, s, j, n_step);  // (fields() takes x from z with sf_only)
    }
    /// Every pixel's fields from its state: take() for each, and the constant ones.
    void load(const PixelState* __restrict st, std::size_t m) {
        resize(m);
        terms_leak_hz = terms_bg_factor = std::numeric_limits<double>::quiet_NaN();
        n_step = 0;
        sf_only = false;  // x and nz as loaded, until a step of the source follower alone
        const Fields f = fields(now());
        double* __restrict ton = theta_on.data();
        double* __restrict toff = theta_off.data();
        double* __restrict ls = leak_spread.data();
        double* __restrict bon = bg_on_hz.data();
        double* __restrict boff = bg_off_hz.data();
        for (std::size_t j = 0; j < m; ++j) {
#if defined(__GNUC__) || defined(__clang__)
            // run() loads a block's states straight from memory when it knows they all stand at
            // the sample's start (Sensor::block_synced_), at a stride the hardware prefetcher
            // follows only within a page: the fields' lines a few pixels ahead are asked for now.
            if (j + PREFETCH_AHEAD < m) {
                const char* ahead = reinterpret_cast<const char*>(st + j + PREFETCH_AHEAD);
                for (std::size_t line = 0; line < sizeof(PixelState); line += 64) __builtin_prefetch(ahead + line);
                __builtin_prefetch(ahead + sizeof(PixelState) - 1);  // where the record is not 64-byte aligned
            }
#endif
            const PixelState& s = st[j];
            take_at(f, s, j, s.n);  // take(s, j, now()) with n_step = 0
            ton[j] = s.theta_on; toff[j] = s.theta_off; ls[j] = s.leak_spread;
            bon[j] = s.bg_on_hz; boff[j] = s.bg_off_hz;
        }
    }
    /// Back into the states, which all stand at t_s now; but for the pixels flagged in held
    /// (nullptr: none), whose states are left as they are (step_block_soa's held pixels).
    void store(PixelState* __restrict st, std::size_t m, double t_s, const std::uint8_t* held = nullptr) const {
        const ConstFields f = fields(now());
        const bool sf = sf_only;
        const std::uint64_t step = n_step;
        for (std::size_t j = 0; j < m; ++j) {
            if (held && held[j]) continue;
            give_at(f, sf, st[j], j, step);
            st[j].t = t_s;
        }
    }

private:
    /// The arrays take() and give() touch, at one Levels, by address: fetched once for a whole
    /// block in load() and store(). (Through the vectors, every store might alias their
    /// pointers and the compiler reloads them for every field of every pixel: ~70 instructions
    /// a pixel in load() where this takes ~46.)
    template <class Real, class Word, class Count>
    struct FieldsOf {
        Real *x, *z, *y, *nz, *ny, *ref, *clock_on, *clock_off, *refr_until, *next_hot_t;
        Count *n_base, *spare_sample;
        Word *spare_lo, *spare_hi;
    };
    using Fields = FieldsOf<double, std::uint32_t, std::uint64_t>;
    using ConstFields = FieldsOf<const double, const std::uint32_t, const std::uint64_t>;
    Fields fields(Levels& l) {
        return {l.x.data(),          l.z.data(),          l.y.data(),        l.nz.data(),
                l.ny.data(),         l.ref.data(),        l.clock_on.data(), l.clock_off.data(),
                refr_until.data(),   next_hot_t.data(),   n_base.data(),     spare_sample.data(),
                spare_lo.data(),     spare_hi.data()};
    }
    /// With the source follower alone, x is read from z (sf_only; give()).
    ConstFields fields(const Levels& l) const {
        return {sf_only ? l.z.data() : l.x.data(), l.z.data(),          l.y.data(),        l.nz.data(),
                l.ny.data(),         l.ref.data(),        l.clock_on.data(), l.clock_off.data(),
                refr_until.data(),   next_hot_t.data(),   n_base.data(),     spare_sample.data(),
                spare_lo.data(),     spare_hi.data()};
    }
    /// take() and give() of one pixel, where n_base is its counter less the step's, and
    /// sf_only as BlockSoA's: nz is 0 with the source follower alone (and fields() points x at z).
    static EVSTWIN_ALWAYS_INLINE void take_at(const Fields& f, const PixelState& s, std::size_t j, std::uint64_t n_base) {
        f.x[j] = s.x; f.z[j] = s.z; f.y[j] = s.y; f.nz[j] = s.nz; f.ny[j] = s.ny;
        f.ref[j] = s.ref; f.clock_on[j] = s.bg_clock_on; f.clock_off[j] = s.bg_clock_off;
        f.n_base[j] = n_base;
        f.refr_until[j] = s.refr_until; f.next_hot_t[j] = s.next_hot_t;
        f.spare_lo[j] = static_cast<std::uint32_t>(s.spare_words);
        f.spare_hi[j] = static_cast<std::uint32_t>(s.spare_words >> 32);
        f.spare_sample[j] = s.spare_sample;
    }
    static EVSTWIN_ALWAYS_INLINE void give_at(const ConstFields& f, bool sf_only, PixelState& s, std::size_t j,
                                              std::uint64_t step) {
        s.x = f.x[j]; s.z = f.z[j]; s.y = f.y[j];
        s.nz = sf_only ? 0.0 : f.nz[j]; s.ny = f.ny[j];
        s.ref = f.ref[j]; s.bg_clock_on = f.clock_on[j]; s.bg_clock_off = f.clock_off[j]; s.n = f.n_base[j] + step;
        s.refr_until = f.refr_until[j]; s.next_hot_t = f.next_hot_t[j];
        s.spare_words = static_cast<std::uint64_t>(f.spare_lo[j]) | (static_cast<std::uint64_t>(f.spare_hi[j]) << 32);
        s.spare_sample = f.spare_sample[j];
    }
};

/// What the continuous block kernel's common path needs: the block's arrays and the numbers
/// of one photon rate (the block's common one) for one sample interval.
struct QuietPass {
    const BlockSoA::Levels* now;
    BlockSoA::Levels* next;
    const double *refr_until, *next_hot_t, *theta_on, *theta_off;
    /// BlockSoA's terms for this rate (PixelModel::prepare_quiet_terms): the leak's part of the slope, and the
    /// background clocks' rates (bg_on_hz * bg_factor, bg_off_hz * bg_factor).
    const double *leak_g, *bg_on_rate, *bg_off_rate;
    const double *g1, *g2;
    std::uint64_t* busy;
    std::size_t count;
    double rate;  ///< the common photon rate: the pixels at any other are left busy
    double cx, pole_decay, pole_ramp;                 ///< NoiseCache's x and pole numbers at that rate
    double phi_zz, phi_yz, phi_yy, l_zz, l_yz, l_yy;  ///< its noise transition and innovation
    double bridge_bound;
    double sf_decay, sf_ramp, dt, inv_dt, t0, t1;
    /// Whether a pixel that only the bridge keeps from quiet may be settled by the bridge stage
    /// (step_block_soa_impl): the bridge has a variance and continuous_finish() would not refine.
    bool bridge_stage;
};

namespace detail {
/// The index of the lowest set bit of b != 0.
EVSTWIN_ALWAYS_INLINE unsigned lowest_set_bit(std::uint64_t b) {
#if defined(__GNUC__) || defined(__clang__)
    return static_cast<unsigned>(__builtin_ctzll(b));
#else
    unsigned i = 0;
    for (; !(b & 1u); b >>= 1) ++i;
    return i;
#endif
}

/// list_flagged()'s loop: the flags of 64 pixels at a time gathered into the bits of one word
/// (a loop without branches that vectorises: a compare, a shift and an OR per lane), then the
/// word's set bits listed lowest first (one step per flagged pixel, and one branch a word
/// that is mispredicted at most once).
template <class Flag>
EVSTWIN_ALWAYS_INLINE std::size_t list_flagged_body(const Flag* __restrict flag, std::size_t n,
                                                    std::uint32_t* __restrict list) {
    std::size_t m = 0;
    for (std::size_t base = 0; base < n; base += 64) {
        const std::size_t len = n - base < 64 ? n - base : 64;
        const Flag* __restrict f = flag + base;
        std::uint64_t bits = 0;
        for (std::size_t i = 0; i < len; ++i) bits |= static_cast<std::uint64_t>(f[i] != 0) << i;
        while (bits) {
            list[m++] = static_cast<std::uint32_t>(base + lowest_set_bit(bits));
            bits &= bits - 1;
        }
    }
    return m;
}

/// The bridge stage's bracket of each candidate's crossing probability: q[i] =
/// exp_neg_bracket(e_on[i]) + exp_neg_bracket(e_off[i]), a term 0 where its exponent is above
/// 40 (as bridge_crossing_probability cuts), and -1 where an exponent is negative or NaN (the
/// caller then takes the exact probability). Without branches, so it vectorises.
EVSTWIN_ALWAYS_INLINE void bridge_bracket_body(const double* __restrict e_on, const double* __restrict e_off,
                                               std::size_t m, double* __restrict q) {
    for (std::size_t i = 0; i < m; ++i) {
        const double eo = e_on[i], ef = e_off[i];
        const bool in_range = (eo >= 0.0) & (ef >= 0.0);
        // Clamped so the bracket's arithmetic stays finite; the lanes clamped are cut below.
        const double bo = exp_neg_bracket(eo < 40.0 ? eo : 40.0);
        const double bf = exp_neg_bracket(ef < 40.0 ? ef : 40.0);
        const double sum = (eo > 40.0 ? 0.0 : bo) + (ef > 40.0 ? 0.0 : bf);
        q[i] = in_range ? sum : -1.0;
    }
}

/// The bridge stage's decision for a uniform u: whether u < p_on + p_off, p = exp(-e) of the
/// exponents (0 above 40, as bridge_crossing_probability), given q, their sum's bracket from
/// bridge_bracket_body (-1: exponents the bracket does not cover). Decided on q where u lies
/// farther than a relative 1e-6 from it (q is within 1e-8 of the sum), else on the library's
/// exps: the same answer as the exps for every u.
inline bool bracket_fires(double u, double q, double e_on, double e_off) {
    if ((q < 0.0) | ((u >= q * (1.0 - 1e-6)) & (u <= q * (1.0 + 1e-6)))) {
        const double p_on = e_on > 40.0 ? 0.0 : std::exp(-e_on);
        const double p_off = e_off > 40.0 ? 0.0 : std::exp(-e_off);
        return u < p_on + p_off;
    }
    return u < q;
}

#define EVSTWIN_LIST_FLAGGED_LEVEL(SUFFIX, TARGET)                                                              \
    TARGET inline std::size_t list_flagged_##SUFFIX(const std::uint64_t* flag, std::size_t n, std::uint32_t* list) { \
        return list_flagged_body(flag, n, list);                                                                \
    }                                                                                                           \
    TARGET inline std::size_t list_flagged_##SUFFIX(const std::uint8_t* flag, std::size_t n, std::uint32_t* list) {  \
        return list_flagged_body(flag, n, list);                                                                \
    }                                                                                                           \
    TARGET inline void bridge_bracket_##SUFFIX(const double* e_on, const double* e_off, std::size_t m, double* q) {   \
        bridge_bracket_body(e_on, e_off, m, q);                                                                 \
    }
EVSTWIN_LIST_FLAGGED_LEVEL(baseline, )
#if EVSTWIN_MULTIVERSION
EVSTWIN_LIST_FLAGGED_LEVEL(avx2, EVSTWIN_TARGET_AVX2)
#endif
#undef EVSTWIN_LIST_FLAGGED_LEVEL

#if EVSTWIN_MULTIVERSION
// AVX-512: 16 flags at a time become a 16-bit mask (vptestm), their indices are compressed to
// the front of a vector (vpcompressd) and stored under a mask of the count's length, so no
// branch depends on the flags (list_flagged_body's loop over a word's bits ends at a branch
// mispredicted about once a word: perf had the two listings at ~9 % of continuous 260).
// The last n % 16 (n % 64 for bytes) flags as in the plain list. Same list.
/// The indices base + b of the set bits b of the 16-bit mask k, compressed into out in order
/// (their count returned): vpcompressd and a store under a mask of the count's length.
EVSTWIN_TARGET_AVX512 inline unsigned list_sixteen(unsigned k, std::size_t base, std::uint32_t* out) {
    const __m512i idx = _mm512_add_epi32(_mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15),
                                         _mm512_set1_epi32(static_cast<int>(base)));
    const unsigned count = static_cast<unsigned>(__builtin_popcount(k));
    _mm512_mask_storeu_epi32(out, static_cast<__mmask16>((1u << count) - 1u),
                             _mm512_maskz_compress_epi32(static_cast<__mmask16>(k), idx));
    return count;
}
EVSTWIN_TARGET_AVX512 inline std::size_t list_flagged_avx512(const std::uint64_t* flag, std::size_t n, std::uint32_t* list) {
    std::size_t m = 0, i = 0;
    for (; i + 16 <= n; i += 16) {
        const __m512i a = _mm512_loadu_si512(flag + i), b = _mm512_loadu_si512(flag + i + 8);
        const unsigned k = static_cast<unsigned>(_mm512_test_epi64_mask(a, a)) |
                           (static_cast<unsigned>(_mm512_test_epi64_mask(b, b)) << 8);
        m += list_sixteen(k, i, list + m);
    }
    for (; i < n; ++i)
        if (flag[i]) list[m++] = static_cast<std::uint32_t>(i);
    return m;
}
EVSTWIN_TARGET_AVX512 inline std::size_t list_flagged_avx512(const std::uint8_t* flag, std::size_t n, std::uint32_t* list) {
    std::size_t m = 0, i = 0;
    for (; i + 64 <= n; i += 64) {
        const __m512i a = _mm512_loadu_si512(flag + i);
        const std::uint64_t k64 = _mm512_test_epi8_mask(a, a);
        for (unsigned part = 0; part < 4; ++part) {
            const unsigned k = static_cast<unsigned>(k64 >> (16u * part)) & 0xFFFFu;
            m += list_sixteen(k, i + 16u * part, list + m);
        }
    }
    for (; i < n; ++i)
        if (flag[i]) list[m++] = static_cast<std::uint32_t>(i);
    return m;
}
EVSTWIN_TARGET_AVX512 inline void bridge_bracket_avx512(const double* e_on, const double* e_off, std::size_t m, double* q) {
    bridge_bracket_body(e_on, e_off, m, q);
}
#endif

/// bridge_bracket_body() at the current SIMD level (simd.hpp).
inline void bridge_bracket(const double* e_on, const double* e_off, std::size_t m, double* q) {
    EVSTWIN_AT_LEVEL(bridge_bracket, e_on, e_off, m, q)
}
}  // namespace detail

namespace detail {
/// soa_sample_words' passes over a block's counters, compiled per SIMD level (the block
/// kernel itself is compiled for the baseline, where these loops take two counters a step).
/// A pixel's counter is sample[j] + step (BlockSoA::count):
/// sample_words_off: nonzero unless every pixel's words are kept for its (odd) sample;
/// even_counters: the counters of an even sample's Philox batch, and the OR of the samples
/// (odd bit set: some pixel's sample is odd); keep_for_next: every pixel's words now belong
/// to its sample | 1.
EVSTWIN_ALWAYS_INLINE std::uint64_t sample_words_off_body(const std::uint64_t* __restrict kept_for,
                                                         const std::uint64_t* __restrict sample, std::uint64_t step,
                                                         std::size_t n) {
    std::uint64_t off = 0;
    for (std::size_t j = 0; j < n; ++j) {
        const std::uint64_t now = sample[j] + step;
        off |= (kept_for[j] ^ now) | (~now & 1u);
    }
    return off;
}
EVSTWIN_ALWAYS_INLINE std::uint64_t even_counters_body(const std::uint64_t* __restrict sample, std::uint64_t step,
                                                      const std::uint32_t* __restrict ids, std::size_t n,
                                                      std::uint32_t* __restrict c0, std::uint32_t* __restrict c1,
                                                      std::uint32_t* __restrict c2) {
    std::uint64_t any = 0;
    for (std::size_t j = 0; j < n; ++j) {
        const std::uint64_t now = sample[j] + step, pair = now >> 1;
        c0[j] = static_cast<std::uint32_t>(pair);
        c1[j] = static_cast<std::uint32_t>(pair >> 32);
        c2[j] = ids[j];
        any |= now;
    }
    return any;
}
EVSTWIN_ALWAYS_INLINE void keep_for_next_body(const std::uint64_t* __restrict sample, std::uint64_t step, std::size_t n,
                                              std::uint64_t* __restrict kept_for) {
    for (std::size_t j = 0; j < n; ++j) kept_for[j] = (sample[j] + step) | 1u;
}
#define EVSTWIN_WORD_BOOKS_LEVEL(SUFFIX, TARGET)                                                               \
    TARGET inline std::uint64_t sample_words_off_##SUFFIX(const std::uint64_t* k, const std::uint64_t* s,      \
                                                          std::uint64_t step, std::size_t n) {                 \
        return sample_words_off_body(k, s, step, n);                                                           \
    }                                                                                                          \
    TARGET inline std::uint64_t even_counters_##SUFFIX(const std::uint64_t* s, std::uint64_t step,             \
                                                       const std::uint32_t* ids, std::size_t n,                \
                                                       std::uint32_t* c0, std::uint32_t* c1, std::uint32_t* c2) { \
        return even_counters_body(s, step, ids, n, c0, c1, c2);                                                \
    }                                                                                                          \
    TARGET inline void keep_for_next_##SUFFIX(const std::uint64_t* s, std::uint64_t step, std::size_t n,       \
                                              std::uint64_t* k) {                                              \
        keep_for_next_body(s, step, n, k);                                                                     \
    }
EVSTWIN_WORD_BOOKS_LEVEL(baseline, )
#if EVSTWIN_MULTIVERSION
EVSTWIN_WORD_BOOKS_LEVEL(avx2, EVSTWIN_TARGET_AVX2)
EVSTWIN_WORD_BOOKS_LEVEL(avx512, EVSTWIN_TARGET_AVX512)
#endif
#undef EVSTWIN_WORD_BOOKS_LEVEL
inline std::uint64_t sample_words_off(const std::uint64_t* kept_for, const std::uint64_t* sample, std::uint64_t step,
                                      std::size_t n) {
    EVSTWIN_AT_LEVEL(sample_words_off, kept_for, sample, step, n)
}
inline std::uint64_t even_counters(const std::uint64_t* sample, std::uint64_t step, const std::uint32_t* ids,
                                   std::size_t n, std::uint32_t* c0, std::uint32_t* c1, std::uint32_t* c2) {
    EVSTWIN_AT_LEVEL(even_counters, sample, step, ids, n, c0, c1, c2)
}
inline void keep_for_next(const std::uint64_t* sample, std::uint64_t step, std::size_t n, std::uint64_t* kept_for) {
    EVSTWIN_AT_LEVEL(keep_for_next, sample, step, n, kept_for)
}
}  // namespace detail

/// The indices i in [0, n) with flag[i] != 0 into list, in order; returns how many: a pass
/// over the flags without branches, then one step per flagged pixel (list_flagged_body), at
/// the current SIMD level (simd.hpp). Flag: std::uint64_t (the quiet pass's verdicts) or
/// std::uint8_t (the ziggurat batch's slow flags).
template <class Flag>
inline std::size_t list_flagged(const Flag* flag, std::size_t n, std::uint32_t* list) {
    EVSTWIN_AT_LEVEL(detail::list_flagged, flag, n, list)
}

/// The configurations the quiet pass is compiled for: the exact source follower alone (the
/// default) or behind the photoreceptor pole (DAVIS346-like presets). Others (Euler, no
/// source follower) keep the array-of-structures kernel.
enum class QuietChain { SfOnly, PoleSf };

namespace detail {

/// The continuous block kernel's common path for every pixel of a block: continuous_levels(),
/// background_spend() and the quiet test of step_block_continuous(), one loop over the arrays
/// without branches or conditional stores, so it vectorises. Every pixel's new levels (but x
/// and nz with the source follower alone, which are z and 0: BlockSoA::sf_only) go to
/// q.next (a quiet pixel's are final: what continuous_finish() would leave); q.busy says 0 for
/// quiet, 1 where only the bridge's draw could fire (the bridge stage), 2 for the per-pixel
/// path, which starts over from q.now. The same operations in
/// the same order as the scalar code and no contraction (EVSTWIN_FP_STRICT): the same bits at
/// every instruction set. Noise: the rate's noise intensity is > 0; Background: eq. 12's
/// background is on (both compile-time, so no operation sits behind a branch).
template <QuietChain Chain, bool Noise, bool Background, class Real>
EVSTWIN_ALWAYS_INLINE void quiet_pass_body(const QuietPass& q, const Real* __restrict rate) {
    const double* __restrict sx = q.now->x.data();
    const double* __restrict sz = q.now->z.data();
    const double* __restrict sy = q.now->y.data();
    const double* __restrict snz = q.now->nz.data();
    const double* __restrict sny = q.now->ny.data();
    const double* __restrict sref = q.now->ref.data();
    const double* __restrict son = q.now->clock_on.data();
    const double* __restrict soff = q.now->clock_off.data();
    double* __restrict ox = q.next->x.data();
    double* __restrict oz = q.next->z.data();
    double* __restrict oy = q.next->y.data();
    double* __restrict onz = q.next->nz.data();
    double* __restrict ony = q.next->ny.data();
    double* __restrict oref = q.next->ref.data();
    double* __restrict oon = q.next->clock_on.data();
    double* __restrict ooff = q.next->clock_off.data();
    const double* __restrict refr = q.refr_until;
    const double* __restrict hot = q.next_hot_t;
    const double* __restrict th_on_a = q.theta_on;
    const double* __restrict th_off_a = q.theta_off;
    const double* __restrict leak_g = q.leak_g;
    const double* __restrict bon = q.bg_on_rate;
    const double* __restrict boff = q.bg_off_rate;
    const double* __restrict g1 = q.g1;
    const double* __restrict g2 = q.g2;
    std::uint64_t* __restrict busy = q.busy;
    constexpr bool pole = Chain == QuietChain::PoleSf;
    const double x = q.cx, common = q.rate;
    const double pole_decay = q.pole_decay, pole_ramp = q.pole_ramp, sf_decay = q.sf_decay, sf_ramp = q.sf_ramp;
    const double phi_zz = q.phi_zz, phi_yz = q.phi_yz, phi_yy = q.phi_yy, l_zz = q.l_zz, l_yz = q.l_yz, l_yy = q.l_yy;
    const double bridge_bound = q.bridge_bound, dt = q.dt, inv_dt = q.inv_dt;
    const double t0 = q.t0, t1 = q.t1;
    const bool bridge_stage = q.bridge_stage;
    const std::size_t count = q.count;
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC ivdep
#endif
    for (std::size_t j = 0; j < count; ++j) {
        const double s_z = sz[j], s_y = sy[j], s_ny = sny[j];
        // continuous_levels(): the pole (if any), the exact source follower, the noise.
        double z = x;
        if constexpr (pole) z = x + (s_z - sx[j]) * pole_decay - (x - sx[j]) * pole_ramp;
        const double yd0 = s_y - s_ny;
        const double yd = z + (yd0 - s_z) * sf_decay - (z - s_z) * sf_ramp;
        double nz = 0.0, ny = 0.0;
        if constexpr (Noise) {
            // With the pole its rate is > 0 wherever there is noise: the two-pole system.
            // Without it z carries no noise (continuous_levels): nz stays 0, unwritten.
            if constexpr (pole) {
                nz = phi_zz * snz[j] + l_zz * g1[j];
                ny = phi_yz * snz[j] + phi_yy * s_ny + l_yz * g1[j] + l_yy * g2[j];
            } else {
                ny = phi_yy * s_ny + l_yy * g1[j];
            }
        }
        const double y = yd + ny;
        // background_spend().
        double on = son[j], off = soff[j];
        bool ran_out = false;
        if constexpr (Background) {
            // background_spend()'s (bg_on_hz bg_factor) dt, the product in brackets made once.
            on = son[j] - bon[j] * dt;
            off = soff[j] - boff[j] * dt;
            ran_out = !((on > 0.0) & (off > 0.0));
        }
        // The quiet test (step_block_continuous()).
        const double th_on = th_on_a[j], th_off = th_off_a[j];
        const double g = (y - s_y) * inv_dt + leak_g[j];
        const double db = s_y - sref[j];
        const double d1 = db + g * dt;
        const double on0 = th_on - db, off0 = th_off + db;
        const bool plain = (static_cast<double>(rate[j]) == common) & !ran_out & (hot[j] > t1) & (refr[j] <= t0);
        const double on1 = th_on - d1, off1 = th_off + d1;
        const bool between0 = std::min(on0, off0) > 0.0;
        const bool quiet = plain & between0 & (std::min(on0 * on1, off0 * off1) > bridge_bound);
        // Not quiet, but the line stays between the levels (compare_bridged()'s test, db and d1
        // inside (-theta_off, theta_on)): only the bridge's draw can make it fire. Written with
        // the differences above (a - b > 0 exactly when a > b; on0, off0 are NaN together, as
        // on1, off1 are), so the same verdicts with fewer comparisons.
        const bool bridge = bridge_stage & plain & between0 & (std::min(on1, off1) > 0.0);
        oref[j] = y - d1;
        if constexpr (pole) ox[j] = x;  // else z is x (BlockSoA::sf_only)
        oz[j] = z;
        oy[j] = y;
        if constexpr (pole) onz[j] = nz;
        ony[j] = ny;
        oon[j] = on;
        ooff[j] = off;
        // 0, 1 or 2 as arithmetic: a nested select here becomes a branch and stops the vectoriser.
        const std::uint64_t not_quiet = !quiet;
        busy[j] = 2u * not_quiet - (not_quiet & static_cast<std::uint64_t>(bridge));
    }
}

#define EVSTWIN_QUIET_PASS_LEVEL(NAME, TARGET)                                                        \
    template <QuietChain Chain, bool Noise, bool Background, class Real>                              \
    TARGET inline void NAME(const QuietPass& q, const Real* rate) {                                   \
        quiet_pass_body<Chain, Noise, Background>(q, rate);                                           \
    }
EVSTWIN_QUIET_PASS_LEVEL(quiet_pass_baseline, )
#if EVSTWIN_MULTIVERSION
EVSTWIN_QUIET_PASS_LEVEL(quiet_pass_avx2, EVSTWIN_TARGET_AVX2)
EVSTWIN_QUIET_PASS_LEVEL(quiet_pass_avx512, EVSTWIN_TARGET_AVX512)
#endif
#undef EVSTWIN_QUIET_PASS_LEVEL

/// quiet_pass_body() at the current SIMD level (simd.hpp).
template <QuietChain Chain, bool Noise, bool Background, class Real>
inline void quiet_pass_at_level(const QuietPass& q, const Real* rate) {
#if EVSTWIN_MULTIVERSION
    switch (simd_level()) {
        case SimdLevel::AVX512: return quiet_pass_avx512<Chain, Noise, Background>(q, rate);
        case SimdLevel::AVX2: return quiet_pass_avx2<Chain, Noise, Background>(q, rate);
        default: break;
    }
#endif
    quiet_pass_baseline<Chain, Noise, Background>(q, rate);
}

/// quiet_pass_body() for the run-time noise and background switches.
template <QuietChain Chain, class Real>
inline void quiet_pass(const QuietPass& q, const Real* rate, bool noise, bool background) {
    if (noise) {
        if (background) return quiet_pass_at_level<Chain, true, true>(q, rate);
        return quiet_pass_at_level<Chain, true, false>(q, rate);
    }
    if (background) return quiet_pass_at_level<Chain, false, true>(q, rate);
    quiet_pass_at_level<Chain, false, false>(q, rate);
}

}  // namespace detail

/// Parameters turned into the numbers the hot loop needs.
struct PixelModel {
    PixelParams p;
    double e_per_photon = 0;  ///< electrons per photon arriving on the pixel
    double dark_mean_e_per_s = 0;
    bool has_filter = false;
    bool euler = false;
    bool continuous = false;      ///< NoiseModel::Continuous
    double bg_on_hz = 0, bg_off_hz = 0;  ///< eq. 12's R_n per polarity
    double inv_i_max = 0;                ///< 1 / I_max of eq. 12
    /// A hot pixel's chain, as the comparator uses it: its telegraph's duty and mean burst, and
    /// its chance to switch polarity after an event, from OFF [0] and from ON [1] (strict
    /// alternation, both 1, takes no random number).
    struct HotChainTerms {
        HotPixelChain chain;
        double switch_p[2] = {1.0, 1.0};
        bool strict = true;
        explicit HotChainTerms(const HotPixelChain& c) : chain(c) {
            switch_p[1] = std::min(1.0, c.alternation / (2.0 * c.on_share));
            switch_p[0] = std::min(1.0, c.alternation / (2.0 * (1.0 - c.on_share)));
            strict = switch_p[0] >= 1.0 && switch_p[1] >= 1.0;
        }
    };
    /// [0]: PixelParams' chain; [k]: the chains a sensor gave pixels of their own
    /// (PixelState::hot_chain = k).
    std::vector<HotChainTerms> hot_chains;
    bool leak_off = false;  ///< LeakPolarity::Off: the leak drifts d = y - ref down, to OFF

    explicit PixelModel(const PixelParams& params) : p(params) {
        validate(p);
        e_per_photon = p.electrons_per_photon();
        dark_mean_e_per_s = p.dark_model == DarkModel::None ? 0.0 : p.dark_rate_e_per_s;
        has_filter = p.cutoff_hz.has_value();
        euler = p.lowpass == LowPass::Euler;
        continuous = p.noise_model == NoiseModel::Continuous;
        bg_on_hz = p.shot_noise_on_rate_hz.value_or(p.shot_noise_rate_hz);
        bg_off_hz = p.shot_noise_off_rate_hz.value_or(p.shot_noise_rate_hz);
        inv_i_max = 1.0 / p.shot_noise_i_max_a;
        hot_chains.assign(1, HotChainTerms(hot_chain_of(p)));
        leak_off = p.leak_polarity == LeakPolarity::Off;
    }

    /// The mean photocurrent of a pixel at a photon rate without the dark current [A]: what
    /// the leak's parasitic part follows (leak_photocurrent_hz_per_a).
    EVSTWIN_ALWAYS_INLINE double photo_current_a(double photon_rate) const {
        return ELEMENTARY_CHARGE_C * (e_per_photon * photon_rate);
    }
    /// The leak rate at a photon rate before the pixel's log-normal factor [Hz].
    EVSTWIN_ALWAYS_INLINE double leak_rate_hz(double photon_rate) const {
        return p.leak_rate_hz + p.leak_photocurrent_hz_per_a * photo_current_a(photon_rate);
    }
    /// The level the leak drifts d = y - ref to: theta_on (ON leak) or -theta_off (OFF leak).
    EVSTWIN_ALWAYS_INLINE double leak_theta(const PixelState& s) const { return leak_off ? -s.theta_off : s.theta_on; }
    /// The leak's part of the slope of d = y - ref [1/s] for a leak rate leak_hz (leak_rate_hz()):
    /// the reference drifts one threshold per leak period. detail::quiet_pass_body() computes
    /// it with the same operations in the same order.
    EVSTWIN_ALWAYS_INLINE double leak_slope(const PixelState& s, double leak_hz) const {
        return leak_slope(s.leak_spread, s.theta_on, s.theta_off, leak_hz);
    }
    /// leak_slope() from a pixel's fields (as the structure-of-arrays kernel holds them).
    EVSTWIN_ALWAYS_INLINE double leak_slope(double leak_spread, double theta_on, double theta_off,
                                            double leak_hz) const {
        return (leak_hz * leak_spread) * (leak_off ? -theta_off : theta_on);
    }

    /// Whether the continuous model's noise can be on at any photon rate (shot noise of the
    /// photons or of a Poisson dark current): the block kernels draw the sample's normals then.
    bool draws_normals() const {
        return p.photon_shot_noise || (p.dark_model == DarkModel::Poisson && dark_mean_e_per_s > 0.0);
    }

    /// Whether eq. 12's background is on for any pixel.
    bool has_background() const { return bg_on_hz > 0.0 || bg_off_hz > 0.0; }

    /// The numbers of one sample interval (t0, t1] that do not depend on the pixel.
    SampleConstants constants(double t0, double t1) const {
        SampleConstants c;
        c.t0 = t0;
        c.t1 = t1;
        c.dt = t1 - t0;
        c.inv_dt = 1.0 / c.dt;
        c.e_over_dt = ELEMENTARY_CHARGE_C / c.dt;
        c.log_e_over_dt = std::log(c.e_over_dt);
        if (has_filter) {
            const double u = 2.0 * PI * *p.cutoff_hz * c.dt;
            if (euler) {
                c.sf_ramp = u;
                c.sf_decay = 1.0 - u;
            } else {
                c.sf_decay = std::exp(-u);
                c.sf_ramp = u > 1e-12 ? -std::expm1(-u) / u : 1.0;
            }
        }
        return c;
    }

    /// Mean electron rate of a pixel receiving `photon_rate` photons/s.
    double mean_electron_rate(double photon_rate) const { return e_per_photon * photon_rate + dark_mean_e_per_s; }

    /// The properties of one pixel that do not change in a run (a pure function of seed and
    /// pixel): thresholds with their mismatch, leak and background rates with their spread,
    /// and whether it is hot. hot_rate_hz >= 0 replaces the drawn hot rate (an explicit map);
    /// hot_chain picks the pixel's chain in hot_chains.
    void init_pixel(PixelState& s, Philox4x32Key key, std::uint32_t pixel, double hot_rate_hz = -1.0,
                    std::uint16_t hot_chain = 0) const {
        s.theta_on = theta_with_sigma(p.theta_on, key, pixel, PURPOSE_MISMATCH_ON);
        s.theta_off = theta_with_sigma(p.theta_off, key, pixel, PURPOSE_MISMATCH_OFF);
        const Philox4x32Counter a = philox4x32({0u, 0u, pixel, PURPOSE_PIXEL}, key);
        const Philox4x32Counter b = philox4x32({1u, 0u, pixel, PURPOSE_PIXEL}, key);
        // Log-normal factors of mean 1: exp(sigma z - sigma^2 / 2).
        const auto spread = [](double sigma, std::uint32_t w0, std::uint32_t w1) {
            if (sigma <= 0.0) return 1.0;
            return std::exp(sigma * normal_from_uniforms(uniform_open(w0), uniform_open(w1)) - 0.5 * sigma * sigma);
        };
        s.bg_on_hz = bg_on_hz * spread(p.background_rate_sigma, a[0], a[1]);
        s.bg_off_hz = bg_off_hz * spread(p.background_rate_sigma, a[2], a[3]);
        s.leak_spread = spread(p.leak_rate_sigma, b[0], b[1]);
        if (hot_rate_hz >= 0.0) {
            s.hot_hz = hot_rate_hz;
        } else {
            const bool hot = p.hot_pixel_fraction > 0.0 && uniform_open(b[2]) < p.hot_pixel_fraction;
            // Median hot_pixel_rate_hz: exp(sigma z) without the mean correction.
            s.hot_hz = hot ? p.hot_pixel_rate_hz * (p.hot_pixel_rate_sigma > 0.0
                                                        ? std::exp(p.hot_pixel_rate_sigma *
                                                                   normal_from_uniforms(uniform_open(b[3]), uniform_open(a[0] ^ b[2])))
                                                        : 1.0)
                           : 0.0;
        }
        // The chain's stationary polarity (the low bit, as before, at an even share).
        s.hot_chain = hot_chain;
        const double on_share = hot_chains[hot_chain].chain.on_share;
        s.hot_pol = static_cast<std::uint8_t>(on_share == 0.5 ? (b[3] & 1u) : uniform_open(b[3]) < on_share);
    }

    /// The first sample of a run: the noise-free state starts at the steady state of the mean
    /// input; the continuous model's noise at its stationary distribution (the pixel has been
    /// on long before t = 0), the leak at a random phase of its cycle and a hot pixel's next
    /// event after an exponential wait. No event fires.
    void init_state(PixelState& s, double photon_rate, double t, Philox4x32Key key, std::uint32_t pixel) const {
        const double mean_e = mean_electron_rate(photon_rate);
        s.x = std::log(ELEMENTARY_CHARGE_C * mean_e);
        s.z = s.y = s.ref = s.x;
        s.nz = s.ny = 0.0;
        s.refr_until = -std::numeric_limits<double>::infinity();
        s.t = t;
        s.n = 1;
        const Philox4x32Counter w = philox4x32({0u, 0u, pixel, PURPOSE_INIT}, key);
        double noise_var_y = 0.0;
        double pole_a = 0.0, pole_b = 0.0;
        if (continuous) {
            const double D = noise_intensity(photon_rate, mean_e);
            if (D > 0.0) {
                const double a = pole_rate(ELEMENTARY_CHARGE_C * mean_e), b = sf_rate();
                pole_a = a;
                pole_b = b;
                double szz, szy, syy;
                noise_stationary(a, b, D, szz, szy, syy);
                noise_var_y = syy;
                double g1, g2;
                normal_pair(w[0], w[1], g1, g2);
                if (a > 0.0 && b > 0.0) {
                    const double lzz = std::sqrt(szz), lyz = szy / lzz;
                    s.nz = lzz * g1;
                    s.ny = lyz * g1 + std::sqrt(std::max(0.0, syy - lyz * lyz)) * g2;
                } else {
                    s.ny = std::sqrt(syy) * g1;
                }
                s.y += s.ny;
                s.ref = s.y;
            }
        }
        s.level_at_event = s.ref;
        s.noise_at_event = s.ny;
        const double leak0_hz = leak_rate_hz(photon_rate) * s.leak_spread;
        if (p.leak_random_phase && leak0_hz > 0.0) {
            // The leak's phase as it stands in the steady state: the difference d = y - ref
            // drifts towards the leak's level (theta_on for an ON leak, -theta_off for an OFF
            // one) at f_leak theta and restarts from 0 at every event; its distance d0 from 0
            // is what follows (an OFF leak mirrors an ON one). With eq. 12's background
            // resetting it at rate rho, the density of d0 is exp(-lambda d0) on [0, theta),
            // lambda = rho / (f_leak theta) (uniform without a background).
            // With shot noise, the reference was set at the last event's noise, not at the
            // current one: an independent stationary draw, kept where the whole difference lies
            // between the levels (so nothing fires at once). The noise also ends a leak cycle
            // early: once the leak has brought the level L = theta +- n_then - d0 that the
            // noise must reach (up for ON, down for OFF; the noise is symmetric) down to a few
            // sigma, the noise crosses it. A cycle survives to d0 with probability
            // exp(-int h(L) dL / (f_leak theta)), h the noise's rate of reaching L
            // (leak_noise_hazard); the phase is drawn with that weight too, so a pixel does not
            // start where, in the steady state, the noise would already have fired it (without
            // it a 3e-3 Hz leak fired 4x its rate in the first second).
            const double theta = leak_off ? s.theta_off : s.theta_on;
            const double rho = (s.bg_on_hz + s.bg_off_hz) * background_factor(ELEMENTARY_CHARGE_C * mean_e);
            const double lambda = rho / (leak0_hz * theta);
            const double sd = std::sqrt(noise_var_y);
            const LeakNoiseHazard hazard(sd, pole_a, pole_b);
            CounterStream more(key, pixel, 0, PURPOSE_INIT + 1u);
            // The truncated exponential's normaliser, once: the loop's attempts are mostly
            // rejected where the noise is strong, and libm calls are not hoisted for us.
            const bool truncated_exp = lambda * theta > 1e-9;
            const double exp_span = truncated_exp ? std::expm1(-lambda * theta) : 0.0;
            for (int attempt = 0; attempt < 64; ++attempt) {
                const double u = attempt == 0 ? uniform_open(w[2]) : more.uniform();
                const double d0 = truncated_exp ? -std::log1p(u * exp_span) / lambda : u * theta;
                const double n_then = sd > 0.0 ? sd * normal_from_uniforms(more.uniform(), more.uniform()) : s.ny;
                const double d = (leak_off ? -d0 : d0) + s.ny - n_then;
                if (sd > 0.0) {
                    const double level0 = leak_off ? theta - n_then : theta + n_then;
                    const double reach = hazard(level0 - d0, level0);
                    // u < exp(-reach / (f_leak theta)) (-r / x is -(r / x)), mostly without the exp.
                    if (!detail::below_exp_neg(more.uniform(), reach / (leak0_hz * theta))) continue;
                }
                if (d < s.theta_on && d > -s.theta_off) {
                    s.ref = s.y - d;
                    s.noise_at_event = n_then;
                    s.level_at_event = s.y - s.ny + n_then;
                    break;
                }
            }
        }
        s.hot_count = s.hot_switches = 0;
        s.hot_last_t = -std::numeric_limits<double>::infinity();
        s.hot_event_t = s.hot_switch_t = s.next_hot_t = std::numeric_limits<double>::infinity();
        if (s.hot_hz > 0.0) {
            // The telegraph's state and the clocks as they stand in the steady state: active
            // with probability duty, and (exponential waits being memoryless) fresh waits.
            const Philox4x32Counter h = philox4x32({2u, 0u, pixel, PURPOSE_INIT}, key);
            const double duty = hot_chains[s.hot_chain].chain.duty;
            const bool bursts = duty < 1.0;
            s.hot_active = !bursts || uniform_open(h[0]) < duty;
            if (bursts) s.hot_switch_t = t - std::log(uniform_open(h[1])) * hot_dwell_s(s);
            if (s.hot_active) s.hot_event_t = t - std::log(uniform_open(w[3])) / s.hot_hz;
            s.next_hot_t = std::min(s.hot_event_t, s.hot_switch_t);
        }
        // The background clocks start with fresh budgets: a Poisson process is memoryless, so
        // it is stationary from t = 0.
        const Philox4x32Counter v = philox4x32({1u, 0u, pixel, PURPOSE_INIT}, key);
        s.bg_clock_on = -std::log(uniform_open(v[0]));
        s.bg_clock_off = -std::log(uniform_open(v[1]));
    }

    /// White-noise intensity D [1/s] of ln I at a photon rate: the Poisson part of the electron
    /// rate over the square of the whole (1 / lambda when everything is shot-noise limited).
    double noise_intensity(double photon_rate, double mean_e_per_s) const {
        const double noisy = (p.photon_shot_noise ? e_per_photon * photon_rate : 0.0) +
                             (p.dark_model == DarkModel::Poisson ? dark_mean_e_per_s : 0.0);
        return noisy > 0.0 ? noisy / (mean_e_per_s * mean_e_per_s) : 0.0;
    }
    /// Photoreceptor pole rate 2 pi f_pr [1/s] at a current (0 without the pole).
    double pole_rate(double current_a) const {
        return p.pr_pole ? 2.0 * PI * p.pr_cutoff_ref_hz * (current_a / p.pr_ref_current_a) : 0.0;
    }
    /// Source-follower rate 2 pi f_sf [1/s] (0 without the filter).
    double sf_rate() const { return has_filter ? 2.0 * PI * *p.cutoff_hz : 0.0; }

    /// Two independent standard normals from two random words (Box-Muller, both outputs), for
    /// a pixel's first sample (its stationary noise). The angle's cosine and sine come from
    /// Taylor polynomials on a quarter turn (error < 1e-9), reflected into the quadrant that
    /// the top two bits of w1 pick.
    static void normal_pair(std::uint32_t w0, std::uint32_t w1, double& g1, double& g2) {
        const double r = std::sqrt(-2.0 * std::log(uniform_open(w0)));
        const double t = (static_cast<double>(w1 & 0x3FFFFFFFu) + 0.5) * (0.5 * PI * 0x1p-30);  // [0, pi/2)
        const double t2 = t * t;
        const double sn = t * (1 + t2 * (-1.0 / 6 + t2 * (1.0 / 120 + t2 * (-1.0 / 5040 + t2 * (1.0 / 362880 +
                              t2 * (-1.0 / 39916800 + t2 * (1.0 / 6227020800.0)))))));
        const double cs = 1 + t2 * (-0.5 + t2 * (1.0 / 24 + t2 * (-1.0 / 720 + t2 * (1.0 / 40320 + t2 * (-1.0 / 3628800 +
                              t2 * (1.0 / 479001600.0 + t2 * (-1.0 / 87178291200.0)))))));
        static constexpr double SIGN[2] = {1.0, -1.0};
        g1 = r * cs * SIGN[(w1 >> 30) & 1u];
        g2 = r * sn * SIGN[w1 >> 31];
    }
    /// The continuous model's two normals of a sample from its two random words, by the
    /// ziggurat (rng.hpp): a table look-up for ~99 % of them instead of Box-Muller's log and
    /// square root (~70 instructions an update). The rare rest draw further words keyed by
    /// (pixel, sample), so both are pure functions of the counter.
    EVSTWIN_ALWAYS_INLINE static void sample_normals(std::uint32_t w0, std::uint32_t w1, Philox4x32Key key,
                                                     std::uint32_t pixel, std::uint64_t sample, double& g1, double& g2) {
        std::optional<CounterStream> extra;
        auto more = [&] {
            if (!extra) extra.emplace(key, pixel, sample, PURPOSE_NORMAL);
            return extra->word();
        };
        g1 = normal_ziggurat(w0, more);
        g2 = normal_ziggurat(w1, more);
    }

    /// Mean time a hot pixel stays in its present state, active or quiet [s].
    double hot_dwell_s(const PixelState& s) const {
        const HotPixelChain& c = hot_chains[s.hot_chain].chain;
        return s.hot_active ? c.burst_s : c.burst_s * (1.0 - c.duty) / c.duty;
    }

    /// A hot pixel's events up to t1 (its own Poisson clock with dead time, polarities from
    /// its two-state chain, running only in the active periods of its telegraph), independent of the
    /// comparator and of the sampling.
    template <class Emit>
    EVSTWIN_ALWAYS_INLINE void hot_events(PixelState& s, double t1, Philox4x32Key key, std::uint32_t pixel,
                                          Emit& emit) const {
        while (s.next_hot_t <= t1) {
            if (s.hot_event_t <= s.hot_switch_t) {
                emit(s.hot_event_t, static_cast<Polarity>(s.hot_pol), LABEL_HOT_PIXEL);
                s.hot_last_t = s.hot_event_t;
                ++s.hot_count;
                const Philox4x32Counter w = philox4x32({static_cast<std::uint32_t>(s.hot_count),
                                                        static_cast<std::uint32_t>(s.hot_count >> 32), pixel, PURPOSE_HOT},
                                                       key);
                // The next polarity: the same draw's second word decides a switch.
                const HotChainTerms& chain = hot_chains[s.hot_chain];
                if (chain.strict || uniform_open(w[1]) < chain.switch_p[s.hot_pol]) s.hot_pol ^= 1u;
                s.hot_event_t += p.refractory_s - std::log(uniform_open(w[0])) / s.hot_hz;
            } else {
                ++s.hot_switches;
                const Philox4x32Counter w = philox4x32({static_cast<std::uint32_t>(s.hot_switches),
                                                        static_cast<std::uint32_t>(s.hot_switches >> 32), pixel,
                                                        PURPOSE_HOT_SWITCH},
                                                       key);
                const double now = s.hot_switch_t;
                s.hot_active ^= 1u;
                s.hot_switch_t = now - std::log(uniform_open(w[0])) * hot_dwell_s(s);
                s.hot_event_t = s.hot_active ? std::max(now, s.hot_last_t + p.refractory_s) -
                                                   std::log(uniform_open(w[1])) / s.hot_hz
                                             : std::numeric_limits<double>::infinity();
            }
            s.next_hot_t = std::min(s.hot_event_t, s.hot_switch_t);
        }
    }

    /// Advance a pixel to the sample (t1, photon_rate), whatever its last sample time: the
    /// first sample initialises it; a sample at or before its last one is skipped (the
    /// pixel was already advanced further by a finer, pixel-local sampling).
    template <class Emit>
    EVSTWIN_ALWAYS_INLINE void advance(PixelState& s, double photon_rate, const SampleConstants& c, Philox4x32Key key,
                                       std::uint32_t pixel, PoissonSampler& poisson, NoiseCache& cache, Emit&& emit,
                                       TraceSample* trace = nullptr) const {
        if (s.n == 0) {
            init_state(s, photon_rate, c.t1, key, pixel);
            if (trace) *trace = {std::exp(s.x), s.x, s.y, s.ref};
            return;
        }
        if (c.t1 <= s.t) return;
        SampleConstants own;
        const SampleConstants* cs = &c;
        if (s.t != c.t0) {
            own = constants(s.t, c.t1);
            cs = &own;
        }
        if (continuous)
            step_continuous(s, photon_rate, *cs, key, pixel, cache, emit, trace);
        else
            step(s, photon_rate, *cs, key, pixel, poisson, emit, trace);
        if (s.next_hot_t <= c.t1) hot_events(s, c.t1, key, pixel, emit);
        s.t = c.t1;
        ++s.n;
    }

    /// The two 32-bit random words of the pixel's current sample (s.n): one Philox call
    /// serves two consecutive samples (words 0-1 for the even one, 2-3 for the odd one); the
    /// odd sample's pair is kept in the state, and recomputed when the even sample was not
    /// seen (a fresh start), so the draws stay a pure function of (seed, pixel, sample).
    EVSTWIN_ALWAYS_INLINE static void sample_words(PixelState& s, Philox4x32Key key, std::uint32_t pixel,
                                                   std::uint32_t* w) {
        if ((s.n & 1u) && s.spare_sample == s.n) {
            w[0] = static_cast<std::uint32_t>(s.spare_words);
            w[1] = static_cast<std::uint32_t>(s.spare_words >> 32);
        } else {
            const std::uint64_t pair = s.n >> 1;
            const Philox4x32Counter r = philox4x32(
                {static_cast<std::uint32_t>(pair), static_cast<std::uint32_t>(pair >> 32), pixel, PURPOSE_SAMPLE}, key);
            const int off = (s.n & 1u) ? 2 : 0;
            w[0] = r[off];
            w[1] = r[off + 1];
            s.spare_words = static_cast<std::uint64_t>(r[2]) | (static_cast<std::uint64_t>(r[3]) << 32);
            s.spare_sample = s.n | 1u;
        }
    }

    /// Eq. 12's illumination factor (F - 1) min(I / I_max, 1) + 1, with I / I_max saturating
    /// at the top of the dynamic range (beyond it eq. 12 would turn negative).
    EVSTWIN_ALWAYS_INLINE double background_factor(double current_a) const {
        return (p.shot_noise_factor - 1.0) * (std::min(current_a, p.shot_noise_i_max_a) * inv_i_max) + 1.0;
    }

    /// Eq. 12-15 as the paper draws them (sampled model): one uniform u decides OFF
    /// (u < p_off), ON (u > 1 - p_on) or nothing, p = r dt, and, given an event, its time
    /// inside the interval (u / p is uniform). Returns the polarity or -1.
    EVSTWIN_ALWAYS_INLINE int shot_noise(const PixelState& s, double u, double current_a, const SampleConstants& c,
                                         double& t_noise) const {
        const double f = background_factor(current_a) * c.dt;
        const double p_off = s.bg_off_hz * f, p_on = s.bg_on_hz * f;
        if (u < p_off) {
            t_noise = c.t0 + c.dt * (u / p_off);
            return OFF;
        }
        if (u > 1.0 - p_on) {
            t_noise = c.t0 + c.dt * ((1.0 - u) / p_on);
            return ON;
        }
        return -1;
    }

    /// Eq. 12's background as continuous-time processes (continuous model): ON and OFF events
    /// are two Poisson processes whose rates follow the light, each run on its own clock: an
    /// exponential budget, drawn at each event, spent at the rate r dt per interval; the event
    /// fires where the budget runs out (exact for rates constant over an interval), so a
    /// sample costs two multiply-adds and no random number. If both fire in one interval, the
    /// earlier reaches the comparator and the later is dropped (rare: r dt is small).
    ///
    /// background_spend (each interval) then background_fire (where a clock ran out).
    ///
    /// The first half: spend one interval of both clocks' budgets, f being
    /// background_factor() of the current. Returns whether a clock ran out (then
    /// background_fire has an event to place).
    EVSTWIN_ALWAYS_INLINE bool background_spend(PixelState& s, double f, const SampleConstants& c) const {
        const double r_on = s.bg_on_hz * f, r_off = s.bg_off_hz * f;
        const double on = s.bg_clock_on - r_on * c.dt, off = s.bg_clock_off - r_off * c.dt;
        s.bg_clock_on = on;
        s.bg_clock_off = off;
        return !((on > 0.0) & (off > 0.0));
    }

    /// The second half: after background_spend, the event of a clock that ran out (its polarity,
    /// its time in t_noise, fresh budgets) or -1.
    EVSTWIN_ALWAYS_INLINE int background_fire(PixelState& s, double current_a, const SampleConstants& c,
                                              Philox4x32Key key, std::uint32_t pixel, double& t_noise) const {
        if (s.bg_clock_on > 0.0 && s.bg_clock_off > 0.0) return -1;
        const double f = background_factor(current_a);
        const double r_on = s.bg_on_hz * f, r_off = s.bg_off_hz * f;
        // The time each clock ran out: its budget left at t1 is negative by r (t1 - t).
        const double t_on = s.bg_clock_on > 0.0 ? std::numeric_limits<double>::infinity()
                                                : c.t1 + s.bg_clock_on / r_on;
        const double t_off = s.bg_clock_off > 0.0 ? std::numeric_limits<double>::infinity()
                                                  : c.t1 + s.bg_clock_off / r_off;
        CounterStream more(key, pixel, s.n, PURPOSE_BACKGROUND);
        // A fresh budget for each clock that ran out, counted from where it ran out (the time
        // left in the interval is spent at once; a second event in it is dropped).
        if (s.bg_clock_on <= 0.0) s.bg_clock_on = std::max(0.0, -std::log(more.uniform()) + s.bg_clock_on) + 1e-300;
        if (s.bg_clock_off <= 0.0) s.bg_clock_off = std::max(0.0, -std::log(more.uniform()) + s.bg_clock_off) + 1e-300;
        const bool on = t_on < t_off;
        t_noise = std::min(c.t1, std::max(c.t0, on ? t_on : t_off));
        return on ? ON : OFF;
    }

    /// Whether the block kernels below handle this configuration: every continuous one
    /// (step_block_continuous), the common sampled ones (step_block_impl).
    bool has_block_kernel() const {
        if (continuous) return true;
        const bool pooled = p.photon_shot_noise && p.dark_model != DarkModel::Paper;
        const bool deterministic = !p.photon_shot_noise && p.dark_model == DarkModel::None;
        return pooled || deterministic;
    }

    /// Room for pad_batch's padding (at least the Philox batches' widest vector body, 8 counters).
    static constexpr std::size_t PHILOX_BATCH_PAD = 16;
    /// Scratch space of the block kernel (one per thread).
    struct BlockScratch {
        detail::BlockArray<double> u_noise, x, current, y;
        detail::BlockArray<std::uint8_t> busy;
        detail::BlockArray<std::uint32_t> count_word;
        detail::BlockArray<double> z, count;
        // The continuous model's: the sample's second word, the noise, the bridge's variance.
        detail::BlockArray<std::uint32_t> word1, busy_at;
        detail::BlockArray<double> nz, ny, bridge_var, noise_d;
        detail::BlockArray<double> leak;  ///< the busy pixels' leak rates (continuous), or slopes (sampled)
        // block_sample_words' Philox batch: counters, the pixels that need a call, the words;
        // and the ziggurat batch's flags of the normals left to the slow path.
        detail::BlockArray<std::uint32_t> ctr0, ctr1, ctr2, need_at, r0, r1, r2, r3;
        detail::BlockArray<std::uint8_t> slow1, slow2;
        detail::BlockArray<BridgePre> bridge_pre;  ///< step_block_continuous' bridge decisions of the busy pixels
        std::vector<double> bridge_args;    ///< bridge_decisions' numbers, ARGS a pixel
        detail::BlockArray<std::uint32_t> fired;   ///< bridge_decisions' pixels whose draw fires
        double cached_rate = -1.0, cached_x = 0.0;
        // The photoreceptor pole's decay and ramp depend on the current only through the
        // electron count of the interval: kept per count for the current dt.
        std::vector<double> pr_decay, pr_ramp;
        std::vector<std::uint8_t> pr_known;
        double pr_dt = -1.0;
        NoiseCache noise;  ///< the continuous model's per-rate numbers (advance())
        NoiseCache noise_other;  ///< step_block_soa's: the last own-rate pixel's numbers, carried to the next sample and call
        // step_block_soa's fills for those pixels, made together (fill_noise_caches): their
        // rates, numbers and stages; grown to the most a call has needed.
        std::vector<double> fill_rates;
        std::vector<NoiseCache> fills;
        std::vector<NoiseIntervalStage> fill_stages;
        BlockSoA soa;  ///< step_block_soa's working copy of a block's state
        detail::BlockArena arena;  ///< where the BlockArray members above live
        void resize(std::size_t n) {
            if (x.size() >= n) return;
            const std::size_t padded = n + PHILOX_BATCH_PAD;  // room for a short batch's padding (pad_batch)
            arena.lay_out([this, n, padded](auto&& put) {
                for (auto* v : {&u_noise, &x, &current, &y, &z, &count, &nz, &ny, &bridge_var, &noise_d, &leak}) put(*v, n);
                for (auto* v : {&count_word, &word1, &busy_at, &need_at, &fired}) put(*v, n);
                for (auto* v : {&ctr0, &ctr1, &ctr2, &r0, &r1, &r2, &r3}) put(*v, padded);
                for (auto* v : {&busy, &slow1, &slow2}) put(*v, n);
                put(bridge_pre, n);
            });
        }
    };

    /// A Philox batch of m counters (ctr0..ctr2 from index 0) padded with zero counters up to a
    /// multiple of the batch loop's vector body at the current SIMD level (4 counters on SSE2
    /// and AVX2, 8 with AVX-512: simd.hpp), which does the rest one by one: a batch of a few (a
    /// block's slow normals or bridge draws, ~10) would be mostly scalar. The padding's words
    /// are not used.
    static std::size_t pad_batch(BlockScratch& scratch, std::size_t m) {
        const std::size_t width = simd_level() == SimdLevel::AVX512 ? 8 : 4;
        const std::size_t padded = (m + width - 1) / width * width;
        for (std::size_t i = m; i < padded; ++i) scratch.ctr0[i] = scratch.ctr1[i] = scratch.ctr2[i] = 0;
        return padded;
    }

    /// Which pixels of a block the kernel advances now: `active` lists their positions
    /// (local indices into the block's state, rates and ids).
    struct BlockView {
        PixelState* state;           ///< the block's pixel states
        const std::uint32_t* ids;    ///< global pixel index of each local index
        const std::uint32_t* active; ///< local indices to advance, in increasing order; nullptr: all
        std::size_t n_active;
    };

    /// sample_words() for n pixels of a block: the pixels whose words are not kept from the
    /// previous sample are listed, their Philox calls made in one batch (simd.hpp: vectorised,
    /// the same bits at every instruction set), and the words handed out and kept as
    /// sample_words() does. count(j): the j-th pixel's sample counter; id(j): its global index;
    /// spare(j, words, sample): its kept words and the sample they belong to (references).
    template <class Count, class Id, class Spare>
    EVSTWIN_ALWAYS_INLINE static void batch_sample_words(std::size_t n, Count count, Id id, Spare spare,
                                                         Philox4x32Key key, BlockScratch& scratch, std::uint32_t* w0,
                                                         std::uint32_t* w1) {
        std::uint32_t *c0 = scratch.ctr0.data(), *c1 = scratch.ctr1.data(), *c2 = scratch.ctr2.data();
        std::uint32_t* need = scratch.need_at.data();
        std::size_t m = 0;
        for (std::size_t j = 0; j < n; ++j) {
            const std::uint64_t sample = count(j);
            spare(j, [&](std::uint64_t& words, std::uint64_t& kept_for) {
                if ((sample & 1u) && kept_for == sample) {
                    w0[j] = static_cast<std::uint32_t>(words);
                    w1[j] = static_cast<std::uint32_t>(words >> 32);
                } else {
                    const std::uint64_t pair = sample >> 1;
                    c0[m] = static_cast<std::uint32_t>(pair);
                    c1[m] = static_cast<std::uint32_t>(pair >> 32);
                    c2[m] = id(j);
                    need[m] = static_cast<std::uint32_t>(j);
                    ++m;
                }
            });
        }
        if (m == 0) return;
        std::uint32_t *r0 = scratch.r0.data(), *r1 = scratch.r1.data(), *r2 = scratch.r2.data(), *r3 = scratch.r3.data();
        philox4x32_batch(c0, c1, c2, PURPOSE_SAMPLE, key, m, r0, r1, r2, r3);
        for (std::size_t q = 0; q < m; ++q) {
            const std::size_t j = need[q];
            const std::uint64_t sample = count(j);
            const bool odd = (sample & 1u) != 0;
            w0[j] = odd ? r2[q] : r0[q];
            w1[j] = odd ? r3[q] : r1[q];
            spare(j, [&](std::uint64_t& words, std::uint64_t& kept_for) {
                words = static_cast<std::uint64_t>(r2[q]) | (static_cast<std::uint64_t>(r3[q]) << 32);
                kept_for = sample | 1u;
            });
        }
    }

    /// batch_sample_words() for a block held as arrays, with the two cases of a block whose
    /// pixels all share the sample's parity as loops without branches: an odd sample whose
    /// words every pixel kept (no Philox call: w0, w1 point at the kept words in h), and an
    /// even one where every pixel needs one (the batch writes the kept words straight into h).
    /// Anything else (pixels sub-sampled apart) goes through batch_sample_words() into the
    /// scratch arrays. The same words. Each case is tested by one pass over the block without
    /// an early exit (an OR of the parities or mismatches), which vectorises, fused with the
    /// counters the even case needs; a block of pixels sub-sampled apart wastes one such pass.
    EVSTWIN_ALWAYS_INLINE static void soa_sample_words(BlockSoA& h, const std::uint32_t* ids, std::size_t n,
                                                       Philox4x32Key key, BlockScratch& scratch,
                                                       const std::uint32_t*& w0, const std::uint32_t*& w1) {
        // The counters as BlockSoA keeps them: sample[j] + step (BlockSoA::count).
        const std::uint64_t* __restrict sample = h.n_base.data();
        const std::uint64_t step = h.n_step;
        std::uint32_t* __restrict lo = h.spare_lo.data();
        std::uint32_t* __restrict hi = h.spare_hi.data();
        std::uint64_t* __restrict kept_for = h.spare_sample.data();
        std::uint32_t* __restrict s0 = scratch.count_word.data();
        std::uint32_t* __restrict s1 = scratch.word1.data();
        const bool first_odd = n > 0 && ((sample[0] + step) & 1u);
        if (first_odd) {
            if (detail::sample_words_off(kept_for, sample, step, n) == 0) {
                w0 = lo;
                w1 = hi;
                return;
            }
        } else {
            std::uint32_t *__restrict c0 = scratch.ctr0.data(), *__restrict c1 = scratch.ctr1.data(),
                          *__restrict c2 = scratch.ctr2.data();
            if (!(detail::even_counters(sample, step, ids, n, c0, c1, c2) & 1u)) {
                philox4x32_batch(c0, c1, c2, PURPOSE_SAMPLE, key, n, s0, s1, lo, hi);
                detail::keep_for_next(sample, step, n, kept_for);
                w0 = s0;
                w1 = s1;
                return;
            }
        }
        batch_sample_words(
            n, [sample, step](std::size_t j) { return sample[j] + step; }, [ids](std::size_t j) { return ids[j]; },
            [&](std::size_t j, auto&& use) {
                std::uint64_t words = static_cast<std::uint64_t>(lo[j]) | (static_cast<std::uint64_t>(hi[j]) << 32);
                use(words, kept_for[j]);
                lo[j] = static_cast<std::uint32_t>(words);
                hi[j] = static_cast<std::uint32_t>(words >> 32);
            },
            key, scratch, s0, s1);
        w0 = s0;
        w1 = s1;
    }

    /// batch_sample_words() for the active pixels of a block view (array-of-structures state).
    template <bool AllActive>
    EVSTWIN_ALWAYS_INLINE static void block_sample_words(const BlockView& v, Philox4x32Key key, BlockScratch& scratch,
                                                         std::uint32_t* w0, std::uint32_t* w1) {
        PixelState* st = v.state;
        const auto at = [&v](std::size_t j) -> std::size_t { return AllActive ? j : v.active[j]; };
        batch_sample_words(
            v.n_active, [&](std::size_t j) { return st[at(j)].n; }, [&](std::size_t j) { return v.ids[at(j)]; },
            [&](std::size_t j, auto&& use) { use(st[at(j)].spare_words, st[at(j)].spare_sample); }, key, scratch, w0,
            w1);
    }

    /// sample_normals() for n pixels of a block: the ziggurat's common path as one batch for
    /// each word (simd.hpp), then the few normals in a wedge or the tail finished as
    /// sample_normals() would (both sharing the pixel's further words, the first one first).
    /// Without `second` only g1 is made (g2 is left as it was): with one low-pass the noise is
    /// a 1-D process that uses g1 alone (continuous_levels), and skipping g2 cannot change g1,
    /// which takes the further words first. count(j), id(j) as in batch_sample_words.
    template <class Count, class Id>
    EVSTWIN_ALWAYS_INLINE static void batch_sample_normals(std::size_t n, Count count, Id id, Philox4x32Key key,
                                                           BlockScratch& scratch, const std::uint32_t* w0,
                                                           const std::uint32_t* w1, double* g1, double* g2,
                                                           bool second) {
        std::uint8_t *slow1 = scratch.slow1.data(), *slow2 = scratch.slow2.data();
        ziggurat_batch(w0, n, g1, slow1);
        if (second) ziggurat_batch(w1, n, g2, slow2);
        // The flags of both words in one array, so one scan finds the few to finish.
        if (second)
            for (std::size_t j = 0; j < n; ++j) slow1[j] |= static_cast<std::uint8_t>(slow2[j] << 1);
        // The few to finish, listed; their further words' first blocks in one Philox batch (a
        // scalar call each was most of the slow path's instructions), and the bracket of each
        // one's first wedge test in one pass without branches (its polynomial's latency then
        // overlaps across normals); then each finished from a stream that starts with that block.
        std::uint32_t* at = scratch.need_at.data();
        std::size_t m = list_flagged(slow1, n, at);
        if (m == 0) return;
        std::uint32_t *c0 = scratch.ctr0.data(), *c1 = scratch.ctr1.data(), *c2 = scratch.ctr2.data();
        double* q_first = scratch.noise_d.data();
        const ZigguratTables& z = ZIGGURAT;
        for (std::size_t q = 0; q < m; ++q) {
            const std::size_t j = at[q];
            const std::uint64_t sample = count(j);
            c0[q] = static_cast<std::uint32_t>(sample);
            c1[q] = static_cast<std::uint32_t>(sample >> 32);
            c2[q] = id(j);
            const std::uint32_t w = (slow1[j] & 1u) ? w0[j] : w1[j];
            const double x = static_cast<double>(w >> 8) * z.w[w & 127u];
            q_first[q] = detail::exp_neg_bracket(0.5 * x * x);
        }
        std::uint32_t *r0 = scratch.r0.data(), *r1 = scratch.r1.data(), *r2 = scratch.r2.data(), *r3 = scratch.r3.data();
        philox4x32_batch(c0, c1, c2, PURPOSE_NORMAL, key, pad_batch(scratch, m), r0, r1, r2, r3);
        // A slow normal alone in its stream (the pixel's other normal is not slow) that falls
        // in a wedge is finished here, as normal_ziggurat_slow would finish it, in a loop
        // without branches, where its first wedge test decides clearly (lhs against
        // q (1 -+ 1e-6), with the stream's first word, r0): accepted, it is that word's x;
        // rejected, the stream's second word (r1) starts over, and where that word's common
        // test accepts it, it is the second word's x. That accept-or-reject branch, taken
        // about as often as not, was most of the slow path's time (mispredicted). Either
        // normal: the first (flag 1) and the second (flag 2) each take the stream from its
        // first word when alone, and q_first is the bracket of that one's word. The others
        // (undecided first tests, a second word that is slow too, the tail, two slow normals
        // sharing a stream) are kept, in order, for the loop below.
        std::size_t d = 0;
        for (std::size_t q = 0; q < m; ++q) {
            const std::size_t j = at[q];
            const std::uint8_t flags = slow1[j];
            const bool first = flags & 1u;
            const std::uint32_t w = first ? w0[j] : w1[j], layer = w & 127u, wedge = layer != 0 ? layer : 1u;
            const double x = static_cast<double>(w >> 8) * z.w[layer];
            const double lhs = z.f[wedge] + uniform_open(r0[q]) * (z.f[wedge - 1] - z.f[wedge]);
            const bool wedge_alone = (flags != 3u) & (layer != 0);
            const bool accepted = wedge_alone & (lhs < q_first[q] * (1.0 - 1e-6));
            const std::uint32_t w_next = r1[q], layer_next = w_next & 127u;
            const bool next_common = (w_next >> 8) < z.k[layer_next];
            const bool retried = wedge_alone & (lhs > q_first[q] * (1.0 + 1e-6)) & next_common;
            const double x_next = static_cast<double>(w_next >> 8) * z.w[layer_next];
            // sign * x, sign = +-1 from bit 7, of the accepted word
            const double g_first = (1.0 - 2.0 * static_cast<double>((w >> 7) & 1u)) * x;
            const double g_next = (1.0 - 2.0 * static_cast<double>((w_next >> 7) & 1u)) * x_next;
            // *out = accepted ? g_first : retried ? g_next : *out by bit masks: a select here
            // became a mispredicted branch.
            double* out = first ? g1 + j : g2 + j;
            std::uint64_t first_bits, next_bits, old_bits;
            std::memcpy(&first_bits, &g_first, sizeof first_bits);
            std::memcpy(&next_bits, &g_next, sizeof next_bits);
            std::memcpy(&old_bits, out, sizeof old_bits);
            const std::uint64_t take_first = 0u - static_cast<std::uint64_t>(accepted);
            const std::uint64_t take_next = 0u - static_cast<std::uint64_t>(retried);
            const std::uint64_t bits =
                (first_bits & take_first) | (next_bits & take_next) | (old_bits & ~(take_first | take_next));
            std::memcpy(out, &bits, sizeof bits);
            const bool done = accepted | retried;
            at[d] = static_cast<std::uint32_t>(j);
            r0[d] = r0[q]; r1[d] = r1[q]; r2[d] = r2[q]; r3[d] = r3[q];
            q_first[d] = q_first[q];
            d += !done;
        }
        m = d;
        for (std::size_t q = 0; q < m; ++q) {
            const std::size_t j = at[q];
            const bool first_slow = slow1[j] & 1u, second_slow = slow1[j] >> 1;
            const Philox4x32Counter first{r0[q], r1[q], r2[q], r3[q]};
            PrefilledStream extra(key, id(j), count(j), PURPOSE_NORMAL, &first);
            auto more = [&extra] { return extra.word(); };
            if (first_slow) g1[j] = normal_ziggurat_slow(w0[j], more, q_first[q]);
            if (second_slow) g2[j] = normal_ziggurat_slow(w1[j], more, first_slow ? -1.0 : q_first[q]);
        }
    }

    /// batch_sample_normals() for the active pixels of a block view.
    template <bool AllActive>
    EVSTWIN_ALWAYS_INLINE static void block_sample_normals(const BlockView& v, Philox4x32Key key, BlockScratch& scratch,
                                                           const std::uint32_t* w0, const std::uint32_t* w1, double* g1,
                                                           double* g2, bool second) {
        const auto at = [&v](std::size_t j) -> std::size_t { return AllActive ? j : v.active[j]; };
        batch_sample_normals(
            v.n_active, [&](std::size_t j) { return v.state[at(j)].n; }, [&](std::size_t j) { return v.ids[at(j)]; },
            key, scratch, w0, w1, g1, g2, second);
    }

    /// advance() for pixels that all stand at c.t0 with n > 0, as separate passes (random
    /// words; currents; filter, noise and the quiet test; the comparator for the few busy
    /// pixels; the commit), so each pass is a short loop the processor can overlap across
    /// pixels. Same arithmetic in the same order as step(): the same events.
    template <class Real, class Emit>
    void step_block(const BlockView& v, const Real* rate, const SampleConstants& c, Philox4x32Key key,
                    PoissonSampler& poisson, BlockScratch& scratch, Emit&& emit, std::uint32_t& pixel) const {
        // All pixels active (the common case): index them directly, without the indirection.
        if (continuous) {
            const bool sf_only = has_filter && !euler && !p.pr_pole;  // the default configuration
            if (v.active == nullptr) {
                if (sf_only)
                    step_block_continuous<true, true>(v, rate, c, key, scratch, emit, pixel);
                else
                    step_block_continuous<true, false>(v, rate, c, key, scratch, emit, pixel);
            } else {
                if (sf_only)
                    step_block_continuous<false, true>(v, rate, c, key, scratch, emit, pixel);
                else
                    step_block_continuous<false, false>(v, rate, c, key, scratch, emit, pixel);
            }
        } else if (v.active == nullptr) {
            step_block_impl<true>(v, rate, c, key, poisson, scratch, emit, pixel);
        } else {
            step_block_impl<false>(v, rate, c, key, poisson, scratch, emit, pixel);
        }
    }

    /// The block kernels' quiet test for a pixel whose new level is y1 (its state still at c.t0,
    /// its clocks spent): the line (compare()'s fast path) and, around it, the bridge's
    /// exponents. The difference d inside both thresholds at both ends, and (th_on - d0)(th_on -
    /// d1) and (th_off + d0)(th_off + d1) above the bound (a product above a bound >= 0 with
    /// its first factor positive also says that the second one is; std::min returns its first
    /// argument where a NaN is involved, and a NaN in the second one makes the first NaN). d1:
    /// the difference at c.t1 (a quiet pixel's reference becomes y1 - d1). detail::quiet_pass_body
    /// is the same test, vectorised.
    EVSTWIN_ALWAYS_INLINE bool quiet_in_interval(const PixelState& s, double y1, const NoiseCache& cache,
                                                 const SampleConstants& c, bool clock_ran_out, double& d1) const {
        const double th_on = s.theta_on, th_off = s.theta_off;
        const double g = (y1 - s.y) * c.inv_dt + leak_slope(s, cache.leak_hz);
        const double db = s.y - s.ref;
        d1 = db + g * c.dt;
        const double on0 = th_on - db, off0 = th_off + db;
        return !clock_ran_out & (s.next_hot_t > c.t1) & (s.refr_until <= c.t0) & (std::min(on0, off0) > 0.0) &
               (std::min(on0 * (th_on - d1), off0 * (th_off + d1)) > cache.bridge_bound);
    }

    /// What continuous_finish() leaves of a pixel that quiet_in_interval() found quiet: the new
    /// levels, and the reference leaked to y1 - d1 (the time and counter are the caller's).
    EVSTWIN_ALWAYS_INLINE static void settle_quiet(PixelState& s, const NoiseCache& cache, double z1, double y1,
                                                   double nz1, double ny1, double d1) {
        s.ref = y1 - d1;
        s.x = cache.x;
        s.z = z1;
        s.y = y1;
        s.nz = nz1;
        s.ny = ny1;
    }

    /// step_continuous() for a block, as passes: the random words; the levels, the background
    /// clocks' spending and a branch-free test of whether anything can happen in the interval
    /// (a clock ran out, a hot pixel's event is due, refractory, the line reaches a threshold,
    /// or the bridge could cross); continuous_finish() for the few pixels where it can; the
    /// commit. The quiet pixels do what continuous_finish() would do for them (nothing but
    /// the reference's leak): the same arithmetic in the same order, so the same events.
    template <bool AllActive, bool SfOnly, class Real, class Emit>
    EVSTWIN_ALWAYS_INLINE void step_block_continuous(const BlockView& v, const Real* rate, const SampleConstants& c,
                                                     Philox4x32Key key, BlockScratch& scratch, Emit&& emit,
                                                     std::uint32_t& pixel) const {
        const std::size_t n = v.n_active;
        scratch.resize(n);
        std::uint32_t* w0 = scratch.count_word.data();
        std::uint32_t* w1 = scratch.word1.data();
        // The busy pixels' local indices and new levels, packed.
        std::uint32_t* busy_at = scratch.busy_at.data();
        double* x = scratch.x.data();
        double* z = scratch.z.data();
        double* y = scratch.y.data();
        double* nz = scratch.nz.data();
        double* ny = scratch.ny.data();
        double* cur = scratch.current.data();
        double* bvar = scratch.bridge_var.data();
        double* noise_d = scratch.noise_d.data();
        double* leak = scratch.leak.data();
        PixelState* st = v.state;
        const auto at = [&v](std::size_t j) -> std::size_t { return AllActive ? j : v.active[j]; };
        // The normals in a pass of their own (their rare slow path is a call, which would make
        // the main pass save and restore its registers around it). Not needed without shot
        // noise (the per-pixel path draws them only where the noise intensity is > 0, and so
        // must this: a pixel's rate enters only through the cache, below), and then neither
        // are the sample's words, which only they use: a noiseless pixel (an ideal one) spent
        // a fifth of its time on a Philox call per two samples. The words are counter-based
        // and the kept ones are tagged with their sample, so not drawing them changes nothing.
        double* g1s = scratch.u_noise.data();
        double* g2s = scratch.count.data();
        const bool noisy = draws_normals();
        if (noisy) {
            block_sample_words<AllActive>(v, key, scratch, w0, w1);
            // The second normal only drives the two-pole system (continuous_levels).
            const bool two_poles = !SfOnly && p.pr_pole && has_filter;
            block_sample_normals<AllActive>(v, key, scratch, w0, w1, g1s, g2s, two_poles);
        } else {
            for (std::size_t j = 0; j < n; ++j) g1s[j] = g2s[j] = 0.0;
        }
        const bool background = has_background();
        NoiseCache& cache = scratch.noise;
        if (cache.dt != c.dt) cache.photon_rate = std::numeric_limits<double>::quiet_NaN();  // refill below
        std::size_t n_busy = 0;
        BridgeBatch bridge = bridge_batch(scratch, SfOnly ? n : 0);
        for (std::size_t j = 0; j < n; ++j) {
            PixelState& s = st[at(j)];
            const double r = static_cast<double>(rate[at(j)]);
            // A new rate's numbers without the bridge's until a pixel needs them (NoiseCache::bridge_ready).
            if (r != cache.photon_rate) fill_noise_cache(cache, r, c, true);  // cache.dt is c.dt
            double zj, yj, nzj, nyj;
            continuous_levels<SfOnly>(s, cache, c, g1s[j], g2s[j], zj, yj, nzj, nyj);
            const bool clock_ran_out = background && background_spend(s, cache.bg_factor, c);
            double d1;
            bool quiet = quiet_in_interval(s, yj, cache, c, clock_ran_out, d1);
            if (!quiet && !cache.bridge_ready) {
                complete_noise_cache(cache, c);
                quiet = quiet_in_interval(s, yj, cache, c, clock_ran_out, d1);
            }
            if (quiet) {
                settle_quiet(s, cache, zj, yj, nzj, nyj, d1);
                s.t = c.t1;
                ++s.n;
            } else {
                busy_at[n_busy] = static_cast<std::uint32_t>(at(j));
                x[n_busy] = cache.x;
                cur[n_busy] = cache.current_a;
                bvar[n_busy] = cache.k.bridge_var;
                noise_d[n_busy] = cache.D;
                leak[n_busy] = cache.leak_hz;
                z[n_busy] = zj;
                y[n_busy] = yj;
                nz[n_busy] = nzj;
                ny[n_busy] = nyj;
                if (SfOnly)
                    bridge_prepare(s, v.ids[at(j)], static_cast<std::uint32_t>(n_busy), yj, cache.leak_hz,
                                   cache.k.bridge_var, c, bridge);
                ++n_busy;
            }
        }
        // Without the pole (continuous_finish never refines), the busy pixels' bridge draws are
        // decided ahead, in passes without unpredictable branches (bridge_decisions).
        BridgePre* pre = nullptr;
        if (SfOnly && n_busy > 0) {
            pre = scratch.bridge_pre.data();
            bridge_decisions(bridge, n_busy, c, key, scratch, pre);
        }
        BufferedEmit<std::remove_reference_t<Emit>> buffered{emit, pixel};
        for (std::size_t b = 0; b < n_busy; ++b) {
            PixelState& s = st[busy_at[b]];
            pixel = v.ids[busy_at[b]];
            continuous_finish(s, x[b], z[b], y[b], nz[b], ny[b], cur[b], leak[b], bvar[b], noise_d[b], c, key, pixel,
                              buffered, nullptr, pre ? pre + b : nullptr);
            if (s.next_hot_t <= c.t1) hot_events(s, c.t1, key, pixel, buffered);
            s.t = c.t1;
            ++s.n;
        }
        buffered.flush();
    }

    /// The comparator's emit(t, polarity, label) for step_block_continuous' busy pixels: the
    /// events kept in a short buffer, with the pixel they belong to, and handed to `emit` in
    /// the same order when it fills and at the end of the pass (with `pixel` set to each one's,
    /// as emit reads it). The comparator's loop then makes no call an event, so its doubles
    /// are not saved and restored around one.
    template <class Emit>
    struct BufferedEmit {
        static constexpr std::size_t N = 64;
        Emit& emit;
        std::uint32_t& pixel;
        std::size_t n = 0;
        double t[N];
        std::uint32_t px[N];
        std::uint8_t pol[N], label[N];
        EVSTWIN_ALWAYS_INLINE void operator()(double t_event, Polarity p, std::uint8_t l) {
            t[n] = t_event;
            px[n] = pixel;
            pol[n] = static_cast<std::uint8_t>(p);
            label[n] = l;
            if (++n == N) flush();
        }
        EVSTWIN_NOINLINE void flush() {
            const std::uint32_t now = pixel;
            for (std::size_t i = 0; i < n; ++i) {
                pixel = px[i];
                emit(t[i], static_cast<Polarity>(pol[i]), label[i]);
            }
            pixel = now;
            n = 0;
        }
    };

    /// bridge_decisions' inputs, filled by bridge_prepare() for each busy pixel in the pass that
    /// finds it busy (its state is at hand there): the draws' counters and arguments (ARGS
    /// numbers a pixel) of the m pixels whose line stays inside both levels, and their places
    /// among the busy ones.
    struct BridgeBatch {
        double* args;
        std::uint32_t *c0, *c1, *c2, *at;
        std::size_t m = 0;
    };
    static BridgeBatch bridge_batch(BlockScratch& scratch, std::size_t n) {
        if (scratch.bridge_args.size() < ARGS * n) scratch.bridge_args.resize(ARGS * n);
        return {scratch.bridge_args.data(), scratch.ctr0.data(), scratch.ctr1.data(), scratch.ctr2.data(),
                scratch.need_at.data(), 0};
    }
    /// bridge_decisions' test and arguments for the b-th busy pixel (global index id, new level
    /// y1, leak rate leak_hz, bridge variance bvar; the state still at c.t0): compare_bridged()'s
    /// expressions on the same values.
    EVSTWIN_ALWAYS_INLINE void bridge_prepare(const PixelState& s, std::uint32_t id, std::uint32_t b, double y1,
                                              double leak_hz, double bvar, const SampleConstants& c,
                                              BridgeBatch& bb) const {
        const double t_start = std::max(c.t0, s.refr_until);
        const double g = (y1 - s.y) * c.inv_dt + leak_slope(s, leak_hz);
        const double d_start = (s.y - s.ref) + g * (t_start - c.t0);
        const double d_end = (s.y - s.ref) + g * c.dt;
        const double th_on = s.theta_on, th_off = s.theta_off;
        const bool inside = (bvar > 0.0) & (t_start < c.t1) & (d_start < th_on) & (d_start > -th_off) &
                            (d_end < th_on) & (d_end > -th_off);
        const double sigma2 = 4.0 * bvar * c.inv_dt;
        const double span = c.t1 - t_start;
        const std::size_t m = bb.m;
        double* a = bb.args + ARGS * m;
        a[0] = th_on - d_start;
        a[1] = th_on - d_end;
        a[2] = th_off + d_start;
        a[3] = th_off + d_end;
        a[4] = 0.25 * sigma2 * span;
        a[5] = sigma2;
        a[6] = span;
        a[7] = t_start;
        bb.c0[m] = static_cast<std::uint32_t>(s.n);
        bb.c1[m] = static_cast<std::uint32_t>(s.n >> 32);
        bb.c2[m] = id;
        bb.at[m] = b;
        bb.m = m + inside;
    }

    /// compare_bridged()'s decision, made ahead for the n busy pixels of a block whose tests
    /// and arguments bridge_prepare() put in bb (the state still at c.t0): where the line stays
    /// inside both levels, the bridge's first Philox block (one vectorised batch), its uniform
    /// and whether it fires, and at which level (detail::bridge_fires). compare_bridged then
    /// reads them instead of drawing: the long chain of a scalar Philox call, two divisions and
    /// two exps no longer stands between a pixel's state and its comparator's first
    /// unpredictable branch. The same expressions on the same state (continuous_finish's
    /// background_fire changes only the clocks), so the same decisions.
    void bridge_decisions(const BridgeBatch& bb, std::size_t n, const SampleConstants& c, Philox4x32Key key,
                          BlockScratch& scratch, BridgePre* pre) const {
        for (std::size_t b = 0; b < n; ++b) pre[b].known = false;
        const std::size_t m = bb.m;
        const std::uint32_t *c0 = bb.c0, *c1 = bb.c1, *c2 = bb.c2, *at = bb.at;
        const double* q = bb.args;
        if (m == 0) return;
        std::uint32_t *r0 = scratch.r0.data(), *r1 = scratch.r1.data(), *r2 = scratch.r2.data(), *r3 = scratch.r3.data();
        philox4x32_batch(c0, c1, c2, PURPOSE_BRIDGE, key, m, r0, r1, r2, r3);
        std::uint32_t* fired = scratch.fired.data();
        std::size_t n_fired = 0;
        for (std::size_t k = 0; k < m; ++k) {
            BridgePre& r = pre[at[k]];
            const double* a = q + ARGS * k;
            bool on = false;
            r.fires = detail::bridge_fires(uniform_open(r0[k]), a[0], a[1], a[2], a[3], a[4], on);
            r.on = on;
            r.words = {r0[k], r1[k], r2[k], r3[k]};
            r.known = true;
            r.timed = false;
            fired[n_fired] = static_cast<std::uint32_t>(k);
            n_fired += r.fires;
        }
        // The crossing times of those that fire, as compare_bridged() draws them: the normal
        // from the second word (where the ziggurat's common path takes it; else compare_bridged
        // draws as usual), the uniform from the third, the same arithmetic on the same values.
        for (std::size_t f = 0; f < n_fired; ++f) {
            const std::size_t k = fired[f];
            BridgePre& r = pre[at[k]];
            double g_time;
            if (!normal_ziggurat_common(r1[k], g_time)) continue;
            const double* a = q + ARGS * k;
            const double u0 = r.on ? a[0] : a[2];
            const double u1 = r.on ? a[1] : a[3];
            r.tc = a[7] + bridge_first_passage_sample(u0, u1, a[5], a[6], g_time, uniform_open(r2[k]));
            r.inv_first_dt = 1.0 / (r.tc - c.t0);
            r.inv_second_dt = 1.0 / (c.t1 - r.tc);
            r.timed = true;
        }
    }
    /// bridge_decisions' numbers a pixel (BlockScratch::bridge_args).
    static constexpr std::size_t ARGS = 8;

    /// Whether step_block_soa() handles this configuration: the continuous model with the exact
    /// source follower, behind the photoreceptor pole or not; or with neither (the ideal
    /// pixel, noiseless: continuous noise needs a low-pass). That one takes the SfOnly chain
    /// as it is: without a filter the sample's sf_decay and sf_ramp are 0, so its
    /// z + (y - z_before) * 0 - (z - z_before) * 0 is z, bit for bit, for every finite level
    /// (x is a log, never -0), which is what the per-pixel path's y = z gives; a level of
    /// -inf gives NaN there, which the quiet test sends to the per-pixel path. With the pole
    /// and no filter the noise is the pole's 1-D process, which the PoleSf chain does not do.
    bool has_soa_kernel() const { return continuous && !euler && (has_filter || !p.pr_pole); }

    /// step_block_continuous() for every pixel of a block held as a structure of arrays (h,
    /// loaded from st; all pixels stand at c.t0 with n > 0): the random words and normals in
    /// batches; then one vectorised pass (detail::quiet_pass) over the pixels at the block's
    /// most common photon rate, which settles the quiet ones; then, for the few left busy (a
    /// crossing is possible, a clock ran out, a hot pixel is due, refractory, or another
    /// rate), the per-pixel path on the array-of-structures state from the start of the
    /// interval (levels, clocks, continuous_finish, hot events). The same events as
    /// step_block_continuous(). Needs has_soa_kernel().
    ///
    /// held (n_held local indices, nullptr if none): pixels that sit in the arrays but are not
    /// advanced (they stand past this sample: run_pixels sampled them finely). The passes run
    /// over them too, on their stale arrays, and their results are dropped: they never take the
    /// per-pixel path, their states in st are not touched, and the arrays' copy of them is
    /// garbage until the caller takes them in again (BlockSoA::take) or stores the block
    /// without them (BlockSoA::store's held). Their random words are counter-based (a function
    /// of the pixel, the sample and the purpose), so drawing some that are dropped changes no
    /// other pixel's. Returns how many pixels took the per-pixel path.
    template <class Real, class Emit>
    std::size_t step_block_soa(BlockSoA& h, PixelState* st, const std::uint32_t* ids, std::size_t n, const Real* rate,
                               const SampleConstants& c, Philox4x32Key key, BlockScratch& scratch, Emit&& emit,
                               std::uint32_t& pixel, const std::uint32_t* held = nullptr, std::size_t n_held = 0) const {
        if (p.pr_pole)
            return step_block_soa_impl<QuietChain::PoleSf>(h, st, ids, n, rate, c, key, scratch, emit, pixel, held, n_held);
        return step_block_soa_impl<QuietChain::SfOnly>(h, st, ids, n, rate, c, key, scratch, emit, pixel, held, n_held);
    }

    template <QuietChain Chain, class Real, class Emit>
    EVSTWIN_ALWAYS_INLINE std::size_t step_block_soa_impl(BlockSoA& h, PixelState* st, const std::uint32_t* ids, std::size_t n,
                                                   const Real* rate, const SampleConstants& c, Philox4x32Key key,
                                                   BlockScratch& scratch, Emit&& emit, std::uint32_t& pixel,
                                                   const std::uint32_t* held, std::size_t n_held) const {
        constexpr bool sf_only = Chain == QuietChain::SfOnly;
        scratch.resize(n);
        BlockSoA::Levels& now = h.now();
        BlockSoA::Levels& next = h.next();
        const std::uint32_t* w0 = nullptr;
        const std::uint32_t* w1 = nullptr;
        const auto count = [&h](std::size_t j) { return h.count(j); };
        const auto id = [ids](std::size_t j) { return ids[j]; };
        double* g1s = scratch.u_noise.data();
        double* g2s = scratch.count.data();
        const bool noisy = draws_normals();
        if (noisy) {
            // The words only for the normals (as step_block_continuous): a noiseless pixel has
            // no use for them, and the kept ones are tagged with their sample.
            soa_sample_words(h, ids, n, key, scratch, w0, w1);
            // The second normal only drives the two-pole system (continuous_levels).
            batch_sample_normals(n, count, id, key, scratch, w0, w1, g1s, g2s, !sf_only);
        } else {
            for (std::size_t j = 0; j < n; ++j) g1s[j] = g2s[j] = 0.0;
        }
        // The block's common rate: the cache's if a probe has it (no refill), else the most
        // common of three probes. Any choice gives the same events; a good one leaves the
        // per-pixel path to the pixels that need it.
        NoiseCache& common = scratch.noise;
        if (common.dt != c.dt) common.photon_rate = std::numeric_limits<double>::quiet_NaN();
        const double probe[3] = {static_cast<double>(rate[0]), static_cast<double>(rate[n / 2]),
                                 static_cast<double>(rate[n - 1])};
        double pick = probe[1] == probe[2] ? probe[1] : probe[0];
        for (double r : probe)
            if (r == common.photon_rate) pick = r;
        noise_cache_for(common, pick, c);  // complete (bridge_var) even when another path filled it lazily
        const bool background = has_background(), noise = common.D > 0.0;
        QuietPass q;
        q.now = &now;
        q.next = &next;
        q.refr_until = h.refr_until.data(); q.next_hot_t = h.next_hot_t.data();
        q.theta_on = h.theta_on.data(); q.theta_off = h.theta_off.data();
        prepare_quiet_terms(h, n, common, background);
        q.leak_g = h.leak_g.data(); q.bg_on_rate = h.bg_on_rate.data(); q.bg_off_rate = h.bg_off_rate.data();
        q.g1 = g1s; q.g2 = g2s; q.busy = h.busy.data(); q.count = n;
        // The pass takes the two-pole noise wherever there is noise behind the pole, which holds
        // when the pole's rate is > 0; were it not (a current that underflows), no pixel is
        // taken as quiet and the per-pixel path does them all.
        q.rate = (!sf_only && noise && !(common.a > 0.0)) ? std::numeric_limits<double>::quiet_NaN() : common.photon_rate;
        q.cx = common.x; q.pole_decay = common.pole_decay; q.pole_ramp = common.pole_ramp;
        q.phi_zz = common.k.phi_zz; q.phi_yz = common.k.phi_yz; q.phi_yy = common.k.phi_yy;
        q.l_zz = common.k.l_zz; q.l_yz = common.k.l_yz; q.l_yy = common.k.l_yy;
        q.bridge_bound = common.bridge_bound;
        q.sf_decay = c.sf_decay; q.sf_ramp = c.sf_ramp; q.dt = c.dt; q.inv_dt = c.inv_dt; q.t0 = c.t0; q.t1 = c.t1;
        // continuous_finish() refines (rather than bridges) behind a pole faster than the sampling.
        q.bridge_stage = common.k.bridge_var > 0.0 && (sf_only || !(noise && common.a > 0.0 && common.a * c.dt > 1.0));
        h.sf_only = sf_only;
        detail::quiet_pass<Chain>(q, rate, noise, background);
        std::uint64_t* busy = h.busy.data();
        for (std::size_t i = 0; i < n_held; ++i) busy[held[i]] = 0;  // dropped, whatever the pass found
        // The pixels the pass did not settle, listed once for the two stages below.
        std::uint32_t* flagged = scratch.busy_at.data();
        const std::size_t n_flagged = list_flagged(busy, n, flagged);
        if (q.bridge_stage) bridge_stage(h, ids, flagged, n_flagged, common, c, key, scratch);
        // The busy pixels at rates of their own: the numbers of each rate that the loop below
        // meets (one fill_noise_cache() each, as it did, but for a pixel at the rate of the
        // previous busy pixel at a rate of its own, which takes the same numbers; the first
        // such takes noise_other's, the rate the last sample ended on, only if their dt is
        // c.dt). Their fills' first two stages are made here, over all of them
        // (fill_noise_caches), the last (the lazy choice, NoiseCache::lazy_credit) in the loop,
        // in order, as one fill after another: the same numbers and choices.
        NoiseCache& other = scratch.noise_other;
        std::size_t n_fills = 0;
        {
            double last = other.photon_rate;
            bool last_holds = other.dt == c.dt;
            for (std::size_t f = 0; f < n_flagged; ++f) {
                const std::size_t j = flagged[f];
                const double r = static_cast<double>(rate[j]);
                if (!busy[j] || r == common.photon_rate || (last_holds && r == last)) continue;
                if (n_fills == scratch.fill_rates.size()) scratch.fill_rates.resize(2 * n_fills + 16);
                scratch.fill_rates[n_fills++] = r;
                last = r;
                last_holds = true;
            }
        }
        if (n_fills > 0) {
            if (scratch.fills.size() < n_fills) {
                scratch.fills.resize(scratch.fill_rates.size());
                scratch.fill_stages.resize(scratch.fill_rates.size());
            }
            if (other.sf.T != c.dt || other.sf.b != sf_rate()) other.sf = sf_terms(sf_rate(), c.dt);
            fill_noise_caches(scratch.fills.data(), scratch.fill_stages.data(), scratch.fill_rates.data(), n_fills, c,
                              other.sf);
        }
        NoiseCache* own = &other;  // the numbers of the last pixel at a rate of its own
        std::size_t n_filled = 0;
        // The busy pixels, from their state at c.t0 (now), as step_continuous() does; their new
        // state goes to next, beside the quiet ones'.
        std::size_t n_busy = 0;
        for (std::size_t f = 0; f < n_flagged; ++f) {
            const std::size_t j = flagged[f];
            if (!busy[j]) continue;  // settled by the bridge stage
            ++n_busy;
            PixelState& s = st[j];
            h.give(s, j, now);
            const double r = static_cast<double>(rate[j]);
            const bool own_rate = r != common.photon_rate;  // common is complete, for c.dt
            // Another rate's numbers without the bridge's until a pixel needs them (NoiseCache::bridge_ready).
            if (own_rate && (r != own->photon_rate || own->dt != c.dt)) {
                NoiseCache& next_own = scratch.fills[n_filled++];
                next_own.lazy_credit = own->lazy_credit;
                fill_noise_finish(next_own, c, true);
                own = &next_own;
            }
            NoiseCache& cache = own_rate ? *own : common;
            double zj, yj, nzj, nyj;
            continuous_levels<sf_only>(s, cache, c, g1s[j], g2s[j], zj, yj, nzj, nyj);
            const bool clock_ran_out = background && background_spend(s, cache.bg_factor, c);
            // A pixel at another rate was not tested by the pass: it may be quiet at its own (as
            // step_block_continuous() settles it), which saves continuous_finish()'s bridge.
            double d1;
            bool quiet = own_rate && quiet_in_interval(s, yj, cache, c, clock_ran_out, d1);
            if (own_rate && !quiet && !cache.bridge_ready) {
                complete_noise_cache(cache, c);
                quiet = quiet_in_interval(s, yj, cache, c, clock_ran_out, d1);
            }
            if (quiet) {
                settle_quiet(s, cache, zj, yj, nzj, nyj, d1);
            } else {
                pixel = ids[j];
                continuous_finish(s, cache.x, zj, yj, nzj, nyj, cache.current_a, cache.leak_hz, cache.k.bridge_var,
                                  cache.D, c, key, pixel, emit, nullptr);
                if (s.next_hot_t <= c.t1) hot_events(s, c.t1, key, pixel, emit);
            }
            ++s.n;
            h.take(s, j, next);
        }
        if (own != &other) other = *own;  // for the next call, whose first pixels may share its rate
        h.flip();
        return n_busy;
    }

    /// The quiet pass's per-pixel terms at the common rate's numbers (BlockSoA::leak_g,
    /// bg_on_rate, bg_off_rate), unless the arrays hold them already: they change only with
    /// the common rate (its leak_hz and bg_factor), so most calls make them once per block.
    void prepare_quiet_terms(BlockSoA& h, std::size_t n, const NoiseCache& common, bool background) const {
        if (!(h.terms_leak_hz == common.leak_hz)) {
            for (std::size_t j = 0; j < n; ++j)
                h.leak_g[j] = leak_slope(h.leak_spread[j], h.theta_on[j], h.theta_off[j], common.leak_hz);
            h.terms_leak_hz = common.leak_hz;
        }
        if (background && !(h.terms_bg_factor == common.bg_factor)) {
            for (std::size_t j = 0; j < n; ++j) {
                h.bg_on_rate[j] = h.bg_on_hz[j] * common.bg_factor;
                h.bg_off_rate[j] = h.bg_off_hz[j] * common.bg_factor;
            }
            h.terms_bg_factor = common.bg_factor;
        }
    }

    /// The pixels the quiet pass left to the bridge alone (h.busy 1): their levels in h.next()
    /// are final unless the bridge's draw fires. As compare_bridged() (the interval starts at
    /// c.t0: not refractory), whether its uniform u falls below the crossing probability
    /// p = bridge_crossing_probability(on) + bridge_crossing_probability(off); a pixel whose
    /// draw fires is handed to the per-pixel path (h.busy 2), which draws the same uniform again
    /// and places the event; the others are settled (h.busy 0). The uniforms of all the pixels
    /// that might fire come from one Philox batch; p's two exps are bracketed by
    /// exp_neg_bracket (within 1e-8), which decides wherever u lies farther than a relative 1e-6
    /// from the bracketed sum, and the library's exps are taken only for the rare pixel whose
    /// u lies that close (or whose exponents are out of the bracket's range): the same
    /// decision as u < p for every u (as detail::bridge_fires decides).
    void bridge_stage(BlockSoA& h, const std::uint32_t* ids, const std::uint32_t* flagged, std::size_t n_flagged,
                      const NoiseCache& common,
                      const SampleConstants& c, Philox4x32Key key, BlockScratch& scratch) const {
        const BlockSoA::Levels& now = h.now();
        const BlockSoA::Levels& next = h.next();
        std::uint64_t* busy = h.busy.data();
        const double t_start = c.t0;
        const double sigma2 = 4.0 * common.k.bridge_var * c.inv_dt;
        const double span = c.t1 - t_start;
        const double mid = 0.25 * sigma2 * span;
        std::uint32_t *c0 = scratch.ctr0.data(), *c1 = scratch.ctr1.data(), *c2 = scratch.ctr2.data();
        std::uint32_t* at = scratch.need_at.data();
        double* q_fire = scratch.noise_d.data();       // the bracketed p (-1: take the exact p)
        double* e_on = scratch.x.data();               // bridge_crossing_probability's exponents
        double* e_off = scratch.y.data();
        // bridge_crossing_probability is 0 for both levels without a middle variance.
        const bool has_mid = mid > 0.0;
        // The candidates and their exponents, as bridge_crossing_probability forms them.
        std::size_t m = 0;
        for (std::size_t f = 0; f < n_flagged; ++f) {
            const std::size_t j = flagged[f];
            if (busy[j] != 1) continue;
            busy[j] = 0;
            if (!has_mid) continue;
            const double s_y = now.y[j], ref = now.ref[j], th_on = h.theta_on[j], th_off = h.theta_off[j];
            const double g = (next.y[j] - s_y) * c.inv_dt + leak_slope(h.leak_spread[j], th_on, th_off, common.leak_hz);
            const double d_start = (s_y - ref) + g * (t_start - c.t0);
            const double d_end = (s_y - ref) + g * c.dt;
            e_on[m] = (th_on - d_start) * (th_on - d_end) / (2.0 * mid);
            e_off[m] = (th_off + d_start) * (th_off + d_end) / (2.0 * mid);
            at[m] = static_cast<std::uint32_t>(j);
            ++m;
        }
        if (m == 0) return;
        // Their brackets in one vectorised pass: the exps' latency chains overlap.
        detail::bridge_bracket(e_on, e_off, m, q_fire);
        // Those whose p may exceed 2^-33 (a uniform can fall below it; wherever q (1 + 1e-6)
        // does), kept in place without branches, with their counters.
        std::size_t d = 0;
        for (std::size_t k = 0; k < m; ++k) {
            const std::size_t j = at[k];
            const double q = q_fire[k];
            const std::uint64_t sample = h.count(j);
            c0[d] = static_cast<std::uint32_t>(sample);
            c1[d] = static_cast<std::uint32_t>(sample >> 32);
            c2[d] = ids[j];
            at[d] = static_cast<std::uint32_t>(j);
            q_fire[d] = q;
            e_on[d] = e_on[k];
            e_off[d] = e_off[k];
            d += static_cast<std::size_t>((q < 0.0) | (q * (1.0 + 1e-6) > 0x1p-33));
        }
        if (d == 0) return;
        // CounterStream(key, pixel, sample, PURPOSE_BRIDGE)'s first word.
        std::uint32_t *r0 = scratch.r0.data(), *r1 = scratch.r1.data(), *r2 = scratch.r2.data(), *r3 = scratch.r3.data();
        philox4x32_batch(c0, c1, c2, PURPOSE_BRIDGE, key, pad_batch(scratch, d), r0, r1, r2, r3);
        for (std::size_t k = 0; k < d; ++k) {
            const bool fires = detail::bracket_fires(uniform_open(r0[k]), q_fire[k], e_on[k], e_off[k]);
            busy[at[k]] = 2u * static_cast<std::uint64_t>(fires);
        }
    }

    template <bool AllActive, class Real, class Emit>
    EVSTWIN_ALWAYS_INLINE void step_block_impl(const BlockView& v, const Real* rate, const SampleConstants& c,
                                               Philox4x32Key key, PoissonSampler& poisson, BlockScratch& scratch,
                                               Emit&& emit, std::uint32_t& pixel) const {
        const std::size_t n = v.n_active;
        scratch.resize(n);
        double* u_noise = scratch.u_noise.data();
        double* x = scratch.x.data();
        double* cur = scratch.current.data();
        double* y = scratch.y.data();
        double* leak = scratch.leak.data();
        std::uint8_t* busy = scratch.busy.data();
        PixelState* st = v.state;
        // at(j): the local index of the j-th active pixel.
        const auto at = [&v](std::size_t j) -> std::size_t { return AllActive ? j : v.active[j]; };
        const bool shot = has_background();
        if (p.photon_shot_noise) {
            std::uint32_t* count_word = scratch.count_word.data();
            std::uint32_t* w1 = scratch.word1.data();
            block_sample_words<AllActive>(v, key, scratch, count_word, w1);
            for (std::size_t j = 0; j < n; ++j) u_noise[j] = uniform_open(w1[j]);
            for (std::size_t j = 0; j < n; ++j) {
                const std::uint32_t px = v.ids[at(j)];
                const std::uint64_t sample = st[at(j)].n;
                const auto more = [&] { return CounterStream(key, px, sample, PURPOSE_POISSON_EXTRA); };
                const double mu = (e_per_photon * static_cast<double>(rate[at(j)]) + dark_mean_e_per_s) * c.dt;
                const double k = static_cast<double>(poisson.from_word(mu, count_word[j], more));
                x[j] = log_count(k) + c.log_e_over_dt;
                cur[j] = k * c.e_over_dt;
                scratch.count[j] = k;
            }
        } else {
            if (shot) {
                std::uint32_t* w0 = scratch.count_word.data();
                std::uint32_t* w1 = scratch.word1.data();
                block_sample_words<AllActive>(v, key, scratch, w0, w1);
                for (std::size_t j = 0; j < n; ++j) u_noise[j] = uniform_open(w1[j]);
            }
            for (std::size_t j = 0; j < n; ++j) {
                const double r = static_cast<double>(rate[at(j)]);
                cur[j] = ELEMENTARY_CHARGE_C * (e_per_photon * r);
                if (r != scratch.cached_rate) {  // most pixels share the background's rate
                    scratch.cached_rate = r;
                    scratch.cached_x = std::log(cur[j]);
                }
                x[j] = scratch.cached_x;
            }
        }
        double* z = scratch.z.data();
        if (p.pr_pole) {
            // The photoreceptor pole, cutoff proportional to the pixel's current (step()).
            if (scratch.pr_dt != c.dt) {
                scratch.pr_decay.assign(LOG_TABLE_SIZE, 0.0);
                scratch.pr_ramp.assign(LOG_TABLE_SIZE, 0.0);
                scratch.pr_known.assign(LOG_TABLE_SIZE, 0);
                scratch.pr_dt = c.dt;
            }
            for (std::size_t j = 0; j < n; ++j) {
                const PixelState& si = st[at(j)];
                double decay, ramp;
                const double k = p.photon_shot_noise ? scratch.count[j] : -1.0;
                const bool tabled = k >= 0.0 && k < static_cast<double>(LOG_TABLE_SIZE);
                const std::size_t slot = tabled ? static_cast<std::size_t>(k) : 0;
                if (tabled && scratch.pr_known[slot]) {
                    decay = scratch.pr_decay[slot];
                    ramp = scratch.pr_ramp[slot];
                } else {
                    const double u = 2.0 * PI * p.pr_cutoff_ref_hz * (cur[j] / p.pr_ref_current_a) * c.dt;
                    decay = std::exp(-u);
                    ramp = u > 1e-12 ? -std::expm1(-u) / u : 1.0;
                    if (tabled) {
                        scratch.pr_decay[slot] = decay;
                        scratch.pr_ramp[slot] = ramp;
                        scratch.pr_known[slot] = 1;
                    }
                }
                z[j] = x[j] + (si.z - si.x) * decay - (x[j] - si.x) * ramp;
            }
        } else {
            z = x;  // no pole: the source follower's input is the log itself
        }
        // Filter, noise decision and the quiet test: branch-free arithmetic.
        for (std::size_t j = 0; j < n; ++j) {
            PixelState& si = st[at(j)];
            double yi;
            if (!has_filter) {
                yi = z[j];
            } else if (euler) {
                yi = c.sf_ramp * si.z + c.sf_decay * si.y;
            } else {
                yi = z[j] + (si.y - si.z) * c.sf_decay - (z[j] - si.z) * c.sf_ramp;
            }
            y[j] = yi;
            bool noise = false;
            if (shot) {
                const double f = background_factor(cur[j]) * c.dt;
                noise = (u_noise[j] < si.bg_off_hz * f) | (u_noise[j] > 1.0 - si.bg_on_hz * f);
            }
            noise |= si.next_hot_t <= c.t1;
            const double th_on = si.theta_on, th_off = si.theta_off;
            const double lg = leak_slope(si, leak_rate_hz(static_cast<double>(rate[at(j)])));
            leak[j] = lg;
            const double g = (yi - si.y) * c.inv_dt + lg;
            const double db = si.y - si.ref;
            const double d1 = db + g * c.dt;
            const bool quiet = !noise & (si.refr_until <= c.t0) & (db < th_on) & (db > -th_off) & (d1 < th_on) &
                               (d1 > -th_off);
            busy[j] = !quiet;
            if (quiet) si.ref = yi - d1;
        }
        for (std::size_t j = 0; j < n; ++j) {
            PixelState& si = st[at(j)];
            if (busy[j]) {
                pixel = v.ids[at(j)];
                double t_noise = 0.0;
                const int pol = shot ? shot_noise(si, u_noise[j], cur[j], c, t_noise) : -1;
                compare(si, y[j], 0.0, c, leak[j], pol, t_noise, emit);
                if (si.next_hot_t <= c.t1) hot_events(si, c.t1, key, pixel, emit);
            }
            si.x = x[j];
            si.z = z[j];
            si.y = y[j];
            si.t = c.t1;
            ++si.n;
        }
    }

    /// Advance one pixel over (c.t0, c.t1] to the sample `photon_rate` and emit its events
    /// through emit(t_s, polarity), in time order. Its random numbers are keyed by the
    /// pixel's own sample counter s.n. (advance() also keeps s.t and s.n.)
    template <class Emit>
    EVSTWIN_ALWAYS_INLINE void step(PixelState& s, double photon_rate, const SampleConstants& c, Philox4x32Key key, std::uint32_t pixel,
              PoissonSampler& poisson, Emit&& emit, TraceSample* trace = nullptr) const {
        std::uint32_t w[2] = {0, 0};
        if (p.photon_shot_noise || p.dark_model != DarkModel::None || has_background())
            sample_words(s, key, pixel, w);

        // Photodiode current over the interval, eq. 1-2 and 4. Poisson counts are pooled into
        // one draw where signal and dark are both Poisson over dt (their sum is Poisson).
        const double signal_e_per_s = e_per_photon * photon_rate;
        double x;          // ln(I / 1 A)
        double current_a;  // I
        // The log photoreceptor sees ln(N + 1/2) of an electron count N, not ln N: the log of
        // a Poisson count is biased by -1/(2 mu) and undefined at zero, so the baseline would
        // sink as the samples get shorter; ln(N + 1/2) is unbiased to O(1/mu^2) and finite.
        // The current reported (and used by eq. 12 and the photoreceptor pole) is N e / dt.
        if (p.photon_shot_noise && p.dark_model != DarkModel::Paper) {
            const auto more = [&] { return CounterStream(key, pixel, s.n, PURPOSE_POISSON_EXTRA); };
            const double n = static_cast<double>(poisson.from_word((signal_e_per_s + dark_mean_e_per_s) * c.dt, w[0], more));
            x = log_count(n) + c.log_e_over_dt;
            current_a = n * c.e_over_dt;
        } else {
            double e_per_s = p.photon_shot_noise ? 0.0 : signal_e_per_s;  // what flows [e-/s]
            double seen = e_per_s;  // what the log sees: counts with their half electron
            if (p.photon_shot_noise) {
                const auto more = [&] { return CounterStream(key, pixel, s.n, PURPOSE_POISSON_EXTRA); };
                const double n = static_cast<double>(poisson(signal_e_per_s * c.dt, uniform_open(w[0]), more));
                e_per_s += n * c.inv_dt;
                seen += (n + 0.5) * c.inv_dt;
            }
            if (p.dark_model == DarkModel::Poisson) {
                const auto more = [&] { return CounterStream(key, pixel, s.n, PURPOSE_POISSON_EXTRA); };
                const double n = static_cast<double>(poisson(dark_mean_e_per_s * c.dt, uniform_open(w[0]), more));
                e_per_s += n * c.inv_dt;
                seen += (n + 0.5) * c.inv_dt;
            } else if (p.dark_model == DarkModel::Paper) {
                // eq. 4 literally: Poisson(lambda_dark) electrons "per sample", read as e/s,
                // so the fluctuation does not shrink with longer samples.
                const auto paper = [&] { return CounterStream(key, pixel, s.n, PURPOSE_PAPER_DARK); };
                const double n = static_cast<double>(poisson(dark_mean_e_per_s, paper().uniform(), paper));
                e_per_s += n;
                seen += n;
            }
            current_a = ELEMENTARY_CHARGE_C * e_per_s;
            x = std::log(ELEMENTARY_CHARGE_C * seen);
        }

        // Photoreceptor pole (optional) and source follower, both exact for an input that is
        // linear between samples; eq. 7 (forward Euler on the previous input) on request.
        double z = x;
        if (p.pr_pole) {
            const double u = 2.0 * PI * p.pr_cutoff_ref_hz * (current_a / p.pr_ref_current_a) * c.dt;
            z = first_order_exact(s.z, s.x, x, u);
        }
        double y;
        if (!has_filter) {
            y = z;
        } else if (euler) {
            y = c.sf_ramp * s.z + c.sf_decay * s.y;
        } else {
            y = z + (s.y - s.z) * c.sf_decay - (z - s.z) * c.sf_ramp;
        }

        // Statistical shot noise, eq. 12-15.
        double t_noise = 0.0;
        const int noise_pol = has_background() ? shot_noise(s, uniform_open(w[1]), current_a, c, t_noise) : -1;

        compare(s, y, 0.0, c, leak_slope(s, leak_rate_hz(photon_rate)), noise_pol, t_noise, emit);
        if (trace) *trace = {current_a, x, y, s.ref};
        s.x = x;
        s.z = z;
        s.y = y;
    }

    /// y(t1) of tau y' = in - y for an input linear from in0 to in1 over u = dt / tau.
    static double first_order_exact(double y0, double in0, double in1, double u) {
        const double decay = std::exp(-u);
        const double ramp = u > 1e-12 ? -std::expm1(-u) / u : 1.0;
        return in1 + (y0 - in0) * decay - (in1 - in0) * ramp;
    }

    /// ln(n + 1/2) of an electron count n (see step()); a table for the small counts of the
    /// hot loop.
    EVSTWIN_ALWAYS_INLINE double log_count(double n) const {
        return n < static_cast<double>(LOG_TABLE_SIZE) ? log_table_[static_cast<std::size_t>(n)] : std::log(n + 0.5);
    }
    static constexpr std::size_t LOG_TABLE_SIZE = 1024;
    std::vector<double> log_table_ = [] {
        std::vector<double> t(LOG_TABLE_SIZE);
        for (std::size_t i = 0; i < LOG_TABLE_SIZE; ++i) t[i] = std::log(static_cast<double>(i) + 0.5);
        return t;
    }();

    /// theta (1 + sigma z), redrawn below 1 % of nominal; once per pixel, not in the hot loop.
    double theta_with_sigma(double theta, Philox4x32Key key, std::uint32_t pixel, std::uint32_t purpose) const;

    /// The continuous model's numbers for (photon_rate, c.dt) into `cache`, unless it holds
    /// them already (most pixels share the background's rate); complete (bridge_ready).
    EVSTWIN_ALWAYS_INLINE void noise_cache_for(NoiseCache& cache, double photon_rate, const SampleConstants& c) const {
        if (photon_rate != cache.photon_rate || c.dt != cache.dt)
            fill_noise_cache(cache, photon_rate, c);
        else if (!cache.bridge_ready)
            complete_noise_cache(cache, c);
    }
    /// The numbers for (photon_rate, c.dt). lazy_bridge: leave the two-pole system's bridge_var
    /// for later where bridge_var_bounded() allows (bridge_ready false, bridge_bound from
    /// q_yy): for the callers that test quiet_in_interval() and call complete_noise_cache()
    /// before anything else reads the bridge. Every value computed is the same as eagerly.
    /// Its three stages: fill_noise_begin, fill_noise_end (both also made over many rates at
    /// once: fill_noise_caches) and fill_noise_finish (per pixel, in order: the lazy choice).
    void fill_noise_cache(NoiseCache& cache, double photon_rate, const SampleConstants& c, bool lazy_bridge = false) const {
        NoiseIntervalStage stage;
        fill_noise_begin(cache, stage, photon_rate, c);
        fill_noise_end(cache, stage);
        fill_noise_finish(cache, c, lazy_bridge);
    }
    /// fill_noise_cache()'s first stage: the rate's current, its libm calls (the log, the
    /// pole's exp, the expm1 of the noise's terms: noise_interval_begin) and the fields that
    /// depend on the rate alone; what the second stage needs goes to `stage`.
    EVSTWIN_ALWAYS_INLINE void fill_noise_begin(NoiseCache& cache, NoiseIntervalStage& stage, double photon_rate,
                                                const SampleConstants& c) const {
        const double b = sf_rate();  // once: the stores below could alias p's doubles
        const double mean_e = mean_electron_rate(photon_rate);
        cache.photon_rate = photon_rate;
        cache.dt = c.dt;
        cache.current_a = ELEMENTARY_CHARGE_C * mean_e;
        cache.x = std::log(cache.current_a);
        cache.a = pole_rate(cache.current_a);
        cache.D = noise_intensity(photon_rate, mean_e);
        const double u = cache.a * c.dt;
        cache.pole_decay = std::exp(-u);
        cache.pole_ramp = one_minus_exp_over(u);
        if (cache.sf.T != c.dt || cache.sf.b != b) cache.sf = sf_terms(b, c.dt);
        cache.k = NoiseCoeffs{};
        stage.two_poles = false;
        if (cache.D > 0.0) {
            const PoleTerms pole{cache.a, c.dt, cache.pole_decay, cache.pole_ramp};
            noise_interval_begin(cache.k, stage, cache.a, b, cache.D, c.dt, &cache.sf, &pole);
        }
        cache.bg_factor = background_factor(cache.current_a);
        cache.leak_hz = leak_rate_hz(photon_rate);
    }
    /// fill_noise_cache()'s second stage: the two-pole covariance and its Cholesky factor
    /// (noise_interval_end), from the first's `stage`.
    EVSTWIN_ALWAYS_INLINE void fill_noise_end(NoiseCache& cache, const NoiseIntervalStage& stage) const {
        noise_interval_end(cache.k, stage, sf_rate(), cache.D);
    }
    /// fill_noise_cache()'s last stage: whether the bridge's terms are left for later (the
    /// lazy fills' credit, NoiseCache::lazy_credit), those terms if not, and the quiet test's bound.
    EVSTWIN_ALWAYS_INLINE void fill_noise_finish(NoiseCache& cache, const SampleConstants& c, bool lazy_bridge) const {
        const double b = sf_rate();
        if (lazy_bridge) cache.lazy_credit = std::min(cache.lazy_credit + 1, 6);  // the last fill needed no completion, or was eager
        cache.bridge_ready = true;
        if (cache.D > 0.0) {
            // Twice q_yy bounds bridge_var (bridge_var_bounded): the bound's quiet test is safe.
            cache.bridge_ready = !(lazy_bridge && cache.lazy_credit >= 0 && bridge_var_bounded(cache.a, b, c.dt) &&
                                   cache.k.q_yy > 0.0);
            if (cache.bridge_ready) {
                const PoleTerms pole{cache.a, c.dt, cache.pole_decay, cache.pole_ramp};
                noise_coeffs_bridge(cache.k, cache.a, b, cache.D, c.dt, &cache.sf, &pole);
            }
        }
        cache.bridge_bound = bridge_bound_for(cache.bridge_ready ? cache.k.bridge_var : 2.0 * cache.k.q_yy, c);
    }
    /// fill_noise_cache()'s first two stages for m rates into caches[0, m) (stages: room for
    /// m): the first stage of all, then the second of all, so that one rate's chain of
    /// divisions and square roots overlaps the next rates' libm calls. (Fill after fill, each
    /// chain waited for its own libm calls and the next fill's calls for the chain: one fill
    /// is longer than the processor's out-of-order window.) fill_noise_finish() then completes each, in the caller's
    /// order: the same numbers as fill_noise_cache(). sf: sf_terms(sf_rate(), c.dt), given to
    /// the caches that hold another interval's.
    void fill_noise_caches(NoiseCache* caches, NoiseIntervalStage* stages, const double* rates, std::size_t m,
                           const SampleConstants& c, const SfTerms& sf) const {
        for (std::size_t i = 0; i < m; ++i) {
            NoiseCache& k = caches[i];
            if (k.sf.T != sf.T || k.sf.b != sf.b) k.sf = sf;
            fill_noise_begin(k, stages[i], rates[i], c);
        }
        for (std::size_t i = 0; i < m; ++i) fill_noise_end(caches[i], stages[i]);
    }
    /// What fill_noise_cache(..., lazy_bridge = true) left: bridge_var and its exact bound.
    void complete_noise_cache(NoiseCache& cache, const SampleConstants& c) const {
        if (cache.bridge_ready) return;
        const PoleTerms pole{cache.a, c.dt, cache.pole_decay, cache.pole_ramp};
        noise_coeffs_bridge(cache.k, cache.a, sf_rate(), cache.D, c.dt, &cache.sf, &pole);
        cache.bridge_bound = bridge_bound_for(cache.k.bridge_var, c);
        cache.bridge_ready = true;
        cache.lazy_credit = std::max(cache.lazy_credit - 4, -6);  // -3 net: the next fill adds 1
    }
    /// The quiet test's bound for a middle variance bridge_var (NoiseCache::bridge_bound), as
    /// step_continuous computes the bridge's variance over the whole interval; non-decreasing in it.
    static double bridge_bound_for(double bridge_var, const SampleConstants& c) {
        return 48.0 * (1.0 + 1e-8) * (0.25 * (4.0 * bridge_var * c.inv_dt) * c.dt);
    }

    /// Advance one pixel over (c.t0, c.t1] with the continuous noise model (noise.hpp): the
    /// noise-free chain follows the mean photocurrent exactly as in step() without noise; the
    /// shot noise (n_z, n_y) is advanced with its exact transition and innovation; eq. 12's
    /// background is a continuous-time process; and an excursion of the noise between the
    /// samples that the straight line misses trips the comparator with the probability of a
    /// Brownian bridge of the same conditional variance. One Philox call per sample: two
    /// normals, the bridge's uniform and the background's.
    template <class Emit>
    EVSTWIN_ALWAYS_INLINE void step_continuous(PixelState& s, double photon_rate, const SampleConstants& c,
                                               Philox4x32Key key, std::uint32_t pixel, NoiseCache& cache, Emit&& emit,
                                               TraceSample* trace = nullptr) const {
        noise_cache_for(cache, photon_rate, c);
        std::uint32_t w[2];  // two words a sample, one Philox call for two samples
        sample_words(s, key, pixel, w);
        double z, y, nz, ny;
        double g1 = 0.0, g2 = 0.0;
        if (cache.D > 0.0) sample_normals(w[0], w[1], key, pixel, s.n, g1, g2);
        continuous_levels(s, cache, c, g1, g2, z, y, nz, ny);
        if (has_background()) background_spend(s, cache.bg_factor, c);
        continuous_finish(s, cache.x, z, y, nz, ny, cache.current_a, cache.leak_hz, cache.k.bridge_var, cache.D, c, key,
                          pixel, emit, trace);
    }

    /// The continuous model's new levels over (c.t0, c.t1] from the sample's two normals
    /// (sample_normals, needed only where cache.D > 0): the noise-free chain (pole
    /// at the rate the mean current sets, source follower) and the noise (n_z, n_y) with its
    /// exact transition and innovation; y = noise-free + n_y.
    /// SfOnly: the caller knows the configuration is the default one (the exact source follower,
    /// no pole), so the branches on it are taken at compile time; the same arithmetic.
    template <bool SfOnly = false>
    EVSTWIN_ALWAYS_INLINE void continuous_levels(const PixelState& s, const NoiseCache& cache, const SampleConstants& c,
                                                 double g1, double g2, double& z, double& y, double& nz,
                                                 double& ny) const {
        const bool pole = !SfOnly && p.pr_pole, filter = SfOnly || has_filter, eul = !SfOnly && euler;
        const double x = cache.x, D = cache.D;
        const NoiseCoeffs& k = cache.k;
        // Noise-free chain: pole (rate set by the mean current) and source follower.
        z = pole ? x + (s.z - s.x) * cache.pole_decay - (x - s.x) * cache.pole_ramp : x;
        const double yd0 = s.y - s.ny;
        double yd;
        if (!filter)
            yd = z;
        else if (eul)
            yd = c.sf_ramp * s.z + c.sf_decay * yd0;
        else
            yd = z + (yd0 - s.z) * c.sf_decay - (z - s.z) * c.sf_ramp;
        nz = 0.0;
        ny = 0.0;
        if (D > 0.0) {
            // Without the pole z is x, with no noise of its own (as init_state starts it): nz
            // stays 0, the bits phi_zz * s.nz + l_zz * g1 gave (the one-pole coefficients leave
            // phi_zz and l_zz at 0, noise.hpp), without the two multiplies.
            nz = pole ? k.phi_zz * s.nz + k.l_zz * g1 : 0.0;
            // Without the pole its rate a is 0: the 1-D process of the source follower.
            ny = (pole && cache.a > 0.0 && filter) ? k.phi_yz * s.nz + k.phi_yy * s.ny + k.l_yz * g1 + k.l_yy * g2
                                                   : k.phi_yy * s.ny + k.l_yy * g1;
        }
        y = yd + ny;
    }

    /// The rest of step_continuous once the levels are known and the background clocks spent
    /// (background_spend): eq. 12's event, the bridge, the comparator and the new state
    /// (x, z, y, nz, ny; advance() keeps s.t and s.n). leak_hz: leak_rate_hz() of the sample.
    template <class Emit>
    EVSTWIN_ALWAYS_INLINE void continuous_finish(PixelState& s, double x, double z, double y, double nz, double ny,
                                                 double current_a, double leak_hz, double bridge_var, double D,
                                                 const SampleConstants& c, Philox4x32Key key, std::uint32_t pixel,
                                                 Emit& emit, TraceSample* trace, const BridgePre* pre = nullptr) const {
        const double leak_g = leak_slope(s, leak_hz);
        double t_noise = 0.0;
        const int noise_pol = has_background() ? background_fire(s, current_a, c, key, pixel, t_noise) : -1;

        // With a photoreceptor pole faster than the sampling (a dt > 1), the noise is smooth
        // below 1 / a but rough at the sample's scale, which neither the straight line nor a
        // Brownian bridge describes well near a level: where a crossing is plausible, the
        // interval is refined exactly (below). Elsewhere the line and the bridge do.
        const double a = pole_rate(current_a);
        const bool two_poles = D > 0.0 && a > 0.0 && has_filter;
        if (two_poles && a * c.dt > 1.0 && crossing_plausible(s, y, c, leak_g, bridge_var)) {
            refine_and_compare(s, x, z, y - ny, nz, ny, c, leak_g, a, D, noise_pol, t_noise, key, pixel, emit);
        } else {
            compare_bridged(s, y, ny, c, leak_g, bridge_var, noise_pol, t_noise, key, pixel, PURPOSE_BRIDGE, emit, pre);
        }
        if (trace) *trace = {current_a, x, y, s.ref};
        s.x = x;
        s.z = z;
        s.y = y;
        s.nz = nz;
        s.ny = ny;
    }

    /// Whether the comparator could fire in (c.t0, c.t1] toward y1: the line crosses a level,
    /// or a Brownian bridge of the interval's middle variance would cross one with a
    /// probability above 1e-6 (exp(-13.8)). leak_g: leak_slope() of the sample.
    EVSTWIN_ALWAYS_INLINE bool crossing_plausible(const PixelState& s, double y1, const SampleConstants& c,
                                                  double leak_g, double bridge_var) const {
        const double g = (y1 - s.y) * c.inv_dt + leak_g;
        const double d0 = s.y - s.ref, d1 = d0 + g * c.dt;
        const double th_on = s.theta_on, th_off = s.theta_off;
        if (!(d0 < th_on && d0 > -th_off && d1 < th_on && d1 > -th_off)) return true;
        const double lim = 2.0 * 13.8 * bridge_var;
        return (th_on - d0) * (th_on - d1) < lim || (th_off + d0) * (th_off + d1) < lim;
    }

    /// The comparator over (c.t0, c.t1] toward y1 (noise part ny1), with the crossings of a
    /// Brownian bridge of middle variance bridge_var that the line misses: only while the line
    /// itself crosses nothing after the refractory period (a crossing of the line fires
    /// anyway; the excursions around it are second order). `purpose` keys the bridge's draws;
    /// leak_g: leak_slope() of the sample.
    template <class Emit>
    EVSTWIN_ALWAYS_INLINE void compare_bridged(PixelState& s, double y, double ny, const SampleConstants& c,
                                               double leak_g, double bridge_var, int noise_pol, double t_noise, Philox4x32Key key,
                                               std::uint32_t pixel, std::uint32_t purpose, Emit& emit,
                                               const BridgePre* pre = nullptr) const {
        // `pre` (bridge_decisions): its `known` is the tests below (a variance, an interval left
        // after the refractory period, the line inside both levels), made on the same state
        // and values, and `fires` the draw's decision; the branches test its bytes, which are
        // at hand long before the levels' arithmetic is done (a mispredicted branch costs less).
        const bool decided = pre != nullptr;
        if (decided ? (pre->known & pre->fires) : bridge_var > 0.0) {
            const double t_start = std::max(c.t0, s.refr_until);
            if (decided || t_start < c.t1) {
                const double g = (y - s.y) * c.inv_dt + leak_g;
                const double d_start = (s.y - s.ref) + g * (t_start - c.t0);
                const double d_end = (s.y - s.ref) + g * c.dt;
                const double th_on = s.theta_on, th_off = s.theta_off;
                if (decided || ((d_start < th_on) & (d_start > -th_off) & (d_end < th_on) & (d_end > -th_off))) {
                    // The variance rate of the bridge that has this middle variance over dt.
                    const double sigma2 = 4.0 * bridge_var * c.inv_dt;
                    const double span = c.t1 - t_start;
                    const double mid = 0.25 * sigma2 * span;
                    // The crossing's probabilities p_on, p_off (bridge_crossing_probability) and
                    // its uniform u: it fires where u < p_on + p_off, at the ON level where u <
                    // p_on (detail::bridge_fires, which needs the exps only near a tie). u is
                    // drawn whatever p is: a counter-based draw changes nothing else, and where
                    // p_on + p_off <= 2^-33 no uniform (uniform_open) lies below it.
                    // `pre`: the same words and decision, made ahead in a batch (bridge_decisions).
                    bool on = decided && pre->on;
                    bool fires = decided;
                    double tc = 0.0;
                    if (decided && pre->timed) {
                        tc = pre->tc;  // bridge_decisions drew it, from the same words
                    } else {
                        PrefilledStream more(key, pixel, s.n, purpose, decided ? &pre->words : nullptr);
                        const double u = more.uniform();
                        if (!decided)
                            fires = detail::bridge_fires(u, th_on - d_start, th_on - d_end, th_off + d_start, th_off + d_end,
                                                         mid, on);
                        if (fires) {
                            const double u0 = on ? th_on - d_start : th_off + d_start;
                            const double u1 = on ? th_on - d_end : th_off + d_end;
                            const double g_time = normal_ziggurat(more.word(), [&more] { return more.word(); });
                            tc = t_start + bridge_first_passage_sample(u0, u1, sigma2, span, g_time, more.uniform());
                        }
                    }
                    if (fires) {
                        if (tc > c.t0 && tc < c.t1) {
                            // Split the interval at the crossing: a virtual sample there, just
                            // past the level, so the comparator fires at tc; then on to y.
                            const double f = (tc - c.t0) * c.inv_dt;
                            const double d_line = (s.y - s.ref) + g * (tc - c.t0);
                            const double level = on ? th_on * (1.0 + 1e-9) : -th_off * (1.0 + 1e-9);
                            const double excursion = level - d_line;
                            const double y_c = s.y + f * (y - s.y) + excursion;
                            const double ny_c = s.ny + f * (ny - s.ny) + excursion;
                            SampleConstants first = c, second = c;
                            first.t1 = second.t0 = tc;
                            first.dt = tc - c.t0;
                            second.dt = c.t1 - tc;
                            const bool timed = decided && pre->timed;
                            first.inv_dt = timed ? pre->inv_first_dt : 1.0 / first.dt;
                            second.inv_dt = timed ? pre->inv_second_dt : 1.0 / second.dt;
                            const bool noise_first = noise_pol >= 0 && t_noise <= tc;
                            compare(s, y_c, ny_c, first, leak_g, noise_first ? noise_pol : -1, t_noise, emit);
                            s.y = y_c;
                            s.ny = ny_c;
                            compare(s, y, ny, second, leak_g, noise_first ? -1 : noise_pol, t_noise, emit);
                            return;
                        }
                    }
                }
            }
        }
        compare(s, y, ny, c, leak_g, noise_pol, t_noise, emit);
    }

    /// The interval (c.t0, c.t1] cut into m = 2^L pieces with a h <= 1 (h = dt / m), the noise
    /// state at each cut drawn exactly from its law given the states at both ends (a Levy
    /// bridge construction of the two-pole OU process: midpoints first, then quarter points,
    /// ...), the noise-free chain stepped through the cuts, and the comparator (with its
    /// bridge, now over pieces the pole resolves) run piece by piece. x1, z1, yd1, nz1, ny1:
    /// the sample's values at c.t1 (already drawn); s still holds those at c.t0.
    template <class Emit>
    void refine_and_compare(PixelState& s, double x1, double z1, double yd1, double nz1, double ny1,
                            const SampleConstants& c, double leak_g, double a, double D, int noise_pol, double t_noise,
                            Philox4x32Key key, std::uint32_t pixel, Emit& emit) const {
        constexpr int MAX_LEVELS = 10;
        int levels = 1;
        while (levels < MAX_LEVELS && a * c.dt > static_cast<double>(1 << levels)) ++levels;
        const int m = 1 << levels;
        const double h = c.dt / m;
        const double b = sf_rate();
        double nzs[(1 << MAX_LEVELS) + 1], nys[(1 << MAX_LEVELS) + 1];
        nzs[0] = s.nz;
        nys[0] = s.ny;
        nzs[m] = nz1;
        nys[m] = ny1;
        CounterStream normals(key, pixel, s.n, PURPOSE_REFINE);
        double piece_bridge = 0.0;  // the pieces' bridge variance: noise_coeffs_bridge's at (a, b, D, h), from step 1
        for (int step = m / 2; step >= 1; step /= 2) {
            // X_mid | X_0, X_1 for two halves of length T = step h: mean Phi X_0 + K (X_1 -
            // Phi^2 X_0), covariance Q - K Phi Q, with K = Q Phi^T (Phi Q Phi^T + Q)^-1.
            const double T = step * h;
            // Only the last level (T = h, the pieces' length) needs the bridge's variance.
            NoiseCoeffs q = noise_coeffs_interval(a, b, D, T);
            if (step == 1) {
                noise_coeffs_bridge(q, a, b, D, T);
                piece_bridge = q.bridge_var;
            }
            const double Qzz = q.l_zz * q.l_zz, Qzy = q.l_zz * q.l_yz, Qyy = q.l_yz * q.l_yz + q.l_yy * q.l_yy;
            const double Pzz = q.phi_zz, Pyz = q.phi_yz, Pyy = q.phi_yy;  // Phi = [[Pzz, 0], [Pyz, Pyy]]
            // A = Q Phi^T
            const double Azz = Qzz * Pzz, Azy = Qzz * Pyz + Qzy * Pyy;
            const double Ayz = Qzy * Pzz, Ayy = Qzy * Pyz + Qyy * Pyy;
            // M = Phi A + Q (symmetric)
            const double Mzz = Pzz * Azz + Qzz, Mzy = Pzz * Azy + Qzy, Myy = Pyz * Azy + Pyy * Ayy + Qyy;
            const double det = Mzz * Myy - Mzy * Mzy;
            // K = A M^-1
            const double Kzz = (Azz * Myy - Azy * Mzy) / det, Kzy = (Azy * Mzz - Azz * Mzy) / det;
            const double Kyz = (Ayz * Myy - Ayy * Mzy) / det, Kyy = (Ayy * Mzz - Ayz * Mzy) / det;
            // C = Q - K A^T (A^T = Phi Q), and its Cholesky factor.
            const double Czz = Qzz - (Kzz * Azz + Kzy * Azy);
            const double Czy = Qzy - (Kzz * Ayz + Kzy * Ayy);
            const double Cyy = Qyy - (Kyz * Ayz + Kyy * Ayy);
            const double lzz = Czz > 0.0 ? std::sqrt(Czz) : 0.0;
            const double lyz = lzz > 0.0 ? Czy / lzz : 0.0;
            const double lyy = std::sqrt(std::max(0.0, Cyy - lyz * lyz));
            for (int i = step; i < m; i += 2 * step) {
                const double z0 = nzs[i - step], y0 = nys[i - step];
                const double mz = Pzz * z0, my = Pyz * z0 + Pyy * y0;  // Phi X_0
                const double ez = nzs[i + step] - Pzz * mz, ey = nys[i + step] - (Pyz * mz + Pyy * my);
                const double g1 = normal_from_uniforms(normals.uniform(), normals.uniform());
                const double g2 = normal_from_uniforms(normals.uniform(), normals.uniform());
                nzs[i] = mz + Kzz * ez + Kzy * ey + lzz * g1;
                nys[i] = my + Kyz * ez + Kyy * ey + lyz * g1 + lyy * g2;
            }
        }
        // The pieces: the noise-free chain stepped exactly for the input linear in each piece
        // (its end forced to the sample's own value), the comparator with the piece's bridge.
        const double pole_decay = std::exp(-a * h), pole_ramp = one_minus_exp_over(a * h);
        const double sf_decay = std::exp(-b * h), sf_ramp = one_minus_exp_over(b * h);
        double x_prev = s.x, z_prev = s.z, yd_prev = s.y - s.ny;
        for (int i = 1; i <= m; ++i) {
            double xi, zi, ydi;
            if (i == m) {
                xi = x1;
                zi = z1;
                ydi = yd1;
            } else {
                xi = s.x + (x1 - s.x) * (static_cast<double>(i) / m);
                zi = xi + (z_prev - x_prev) * pole_decay - (xi - x_prev) * pole_ramp;
                ydi = zi + (yd_prev - z_prev) * sf_decay - (zi - z_prev) * sf_ramp;
            }
            SampleConstants piece = c;
            piece.t0 = i == 1 ? c.t0 : c.t0 + (i - 1) * h;
            piece.t1 = i == m ? c.t1 : c.t0 + i * h;
            piece.dt = piece.t1 - piece.t0;
            piece.inv_dt = 1.0 / piece.dt;
            const bool here = noise_pol >= 0 && t_noise > piece.t0 - (i == 1 ? 1.0 : 0.0) && t_noise <= piece.t1;
            compare_bridged(s, ydi + nys[i], nys[i], piece, leak_g, piece_bridge, here ? noise_pol : -1, t_noise, key, pixel,
                            PURPOSE_BRIDGE + 16u * static_cast<std::uint32_t>(i), emit);
            s.y = ydi + nys[i];
            s.ny = nys[i];
            x_prev = xi;
            z_prev = zi;
            yd_prev = ydi;
        }
    }

    /// Why a threshold crossing of the line fired, at a point a share f into the interval:
    /// the largest of the changes since the last event in the crossing's direction, of the
    /// noise-free level (signal), of the noise and of the leak (which only ever moves d towards
    /// its own polarity's level, so it never wins for the other one).
    EVSTWIN_ALWAYS_INLINE std::uint8_t crossing_label(const PixelState& s, int pol, double d, double y_t,
                                                      double ny_t) const {
        const double dn = ny_t - s.noise_at_event;
        const double dl = s.level_at_event - (y_t - d);  // how far the reference has leaked
        const double ds = d - dn - dl;
        // The changes' signs turned to the crossing's direction (a negation is exact), and the
        // label picked by arithmetic on the comparisons: these are the event path's least
        // predictable branches.
        const double sign = pol == ON ? 1.0 : -1.0;
        const double sl = sign * dl, ss = sign * ds, sn = sign * dn;
        const unsigned leak = static_cast<unsigned>(sl >= ss) & static_cast<unsigned>(sl >= sn);
        const unsigned shot = static_cast<unsigned>(sn > ss);
        return static_cast<std::uint8_t>(leak * LABEL_LEAK + (1u - leak) * (shot * LABEL_SHOT_NOISE + (1u - shot) * LABEL_SIGNAL));
    }

    /// The comparator over (t0, t1]: the level difference d(t) = y(t) - ref(t) is linear in
    /// t, since y is interpolated linearly (eq. 16) and the leak moves ref at a constant
    /// rate, leak_g = f_leak theta_on down (ON leak) or f_leak theta_off up (OFF; eq. 10-11). Each crossing fires at its interpolated time and
    /// sets ref to the level there; during the refractory period nothing fires and ref keeps
    /// the last event's level (it still leaks). If, when the refractory period ends, the
    /// difference has passed n >= 1 thresholds, one event fires then and ref moves by n
    /// whole thresholds: the levels crossed while the pixel was dead are merged into that
    /// single event, as a real pixel cannot report them separately. ny1 is the noise part of
    /// y1 (0 in the sampled model), for the events' labels.
    template <class Emit>
    EVSTWIN_ALWAYS_INLINE void compare(PixelState& s, double y1, double ny1, const SampleConstants& c, double leak_g,
                                       int noise_pol, double t_noise, Emit& emit) const {
        const double th_on = s.theta_on, th_off = s.theta_off, refr = p.refractory_s;
        const double g = (y1 - s.y) * c.inv_dt + leak_g;  // d(d)/dt
        double tb = c.t0;
        double db = s.y - s.ref;  // d(tb)
        // Fast path: no noise event, not refractory, and the line stays inside both thresholds.
        const double d1 = db + g * c.dt;
        // Evaluated without short-circuits: one well-predicted branch instead of six.
        const bool quiet = (noise_pol < 0) & (s.refr_until <= tb) & (db < th_on) & (db > -th_off) & (d1 < th_on) &
                           (d1 > -th_off);
        if (quiet) {
            s.ref = y1 - d1;
            return;
        }
        const double y0 = s.y, ny0 = s.ny;
        // An event at t with the difference d there, leaving the difference d_after: emit it
        // and remember where it left the pixel.
        // Inlined at each of its four calls (GCC's attribute; elsewhere a plain lambda): left to
        // the compiler, whether it was depended on the code around it, and an out-of-line copy
        // cost an event more.
        auto fire = [&](double t, int pol, double d, double d_after, int label) EVSTWIN_LAMBDA_ALWAYS_INLINE {
            const double f = (t - c.t0) * c.inv_dt;
            const double y_t = y0 + f * (y1 - y0), ny_t = ny0 + f * (ny1 - ny0);
            if (label < 0) label = crossing_label(s, pol, d, y_t, ny_t);
            emit(t, static_cast<Polarity>(pol), static_cast<std::uint8_t>(label));
            s.level_at_event = y_t - d_after;
            s.noise_at_event = ny_t;
        };
        for (;;) {
            if (s.refr_until > tb) {
                if (noise_pol >= 0 && t_noise < s.refr_until) noise_pol = -1;  // dead pixel
                if (s.refr_until >= c.t1) break;
                db += g * (s.refr_until - tb);
                tb = s.refr_until;
            }
            if (db >= th_on) {
                const double n = detail::floor_positive(db / th_on);
                const double d = db;
                db -= n * th_on;
                fire(tb, ON, d, db, -1);
                s.refr_until = tb + refr;
                continue;
            }
            if (db <= -th_off) {
                const double n = detail::floor_positive(-db / th_off);
                const double d = db;
                db += n * th_off;
                fire(tb, OFF, d, db, -1);
                s.refr_until = tb + refr;
                continue;
            }
            double tc = std::numeric_limits<double>::infinity();
            int pol = -1;
            if (g > 0.0) {
                tc = tb + (th_on - db) / g;
                pol = ON;
            } else if (g < 0.0) {
                tc = tb + (-th_off - db) / g;
                pol = OFF;
            }
            if (noise_pol >= 0 && t_noise < tc) {
                // The noise pulse trips the comparator first; ref resets to the level there.
                db += g * (t_noise - tb);
                tb = t_noise;
                fire(tb, noise_pol, db, 0.0, LABEL_BACKGROUND);
                noise_pol = -1;
                db = 0.0;
                s.refr_until = tb + refr;
                continue;
            }
            if (!(tc <= c.t1)) break;  // also stops on a NaN rather than looping
            if (!(tc > tb)) {
                // The next level lies closer than t can resolve (a huge slope with no
                // refractory period): the rest of this interval's levels fire as one event
                // now, merged as at a wake-up, instead of looping at one instant.
                const double d_end = db + g * (c.t1 - tb);
                const double d = db;
                db = pol == ON ? d_end - std::floor(d_end / th_on) * th_on : d_end + std::floor(-d_end / th_off) * th_off;
                fire(tb, pol, d, db - g * (c.t1 - tb), -1);
                tb = c.t1;
                s.refr_until = tb + refr;
                break;
            }
            fire(tc, pol, pol == ON ? th_on : -th_off, 0.0, -1);
            tb = tc;
            db = 0.0;
            s.refr_until = tb + refr;
        }
        s.ref = y1 - (db + g * (c.t1 - tb));
    }
};

inline double PixelModel::theta_with_sigma(double theta, Philox4x32Key key, std::uint32_t pixel,
                                           std::uint32_t purpose) const {
    if (p.threshold_sigma <= 0.0) return theta;
    for (std::uint32_t attempt = 0;; ++attempt) {
        const Philox4x32Counter w = philox4x32({0u, 0u, pixel, purpose + attempt}, key);
        const double z = normal_from_uniforms(uniform_open(w[0]), uniform_open(w[1]));
        const double th = theta * (1.0 + p.threshold_sigma * z);
        if (th >= 0.01 * theta) return th;
    }
}

}  // namespace evstwin
EVSTWIN_FP_STRICT_END
