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
#include <limits>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>

#include "config.hpp"
#include "constants.hpp"
#include "event.hpp"
#include "rng.hpp"

namespace evstwin {

enum class DarkModel { Poisson, Paper, None };
enum class LowPass { Exact, Euler };

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
    double shot_noise_rate_hz = 0.05;  ///< R_n, eq. 12; paper: 0.05 Hz
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

/// What one pixel-sample update reports for a probe (diagnostic trace).
struct TraceSample {
    double current_a;    ///< photodiode current over the interval [A]
    double log_current;  ///< x = ln(I / 1 A)
    double filtered;     ///< y, the comparator input
    double reference;    ///< the comparator reference at the end of the interval
};

/// Parameters turned into the numbers the hot loop needs.
struct PixelModel {
    PixelParams p;
    double e_per_photon = 0;  ///< electrons per photon arriving on the pixel
    double dark_mean_e_per_s = 0;
    bool has_filter = false;
    bool euler = false;
    double shot_slope_per_a = 0;  ///< (F - 1) R_n / I_max: eq. 12's slope in the current

    explicit PixelModel(const PixelParams& params) : p(params) {
        validate(p);
        e_per_photon = p.electrons_per_photon();
        dark_mean_e_per_s = p.dark_model == DarkModel::None ? 0.0 : p.dark_rate_e_per_s;
        has_filter = p.cutoff_hz.has_value();
        euler = p.lowpass == LowPass::Euler;
        shot_slope_per_a = (p.shot_noise_factor - 1.0) * p.shot_noise_rate_hz / p.shot_noise_i_max_a;
    }

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

    /// Thresholds with this pixel's mismatch (a pure function of seed and pixel).
    void init_thresholds(PixelState& s, Philox4x32Key key, std::uint32_t pixel) const {
        s.theta_on = theta_with_sigma(p.theta_on, key, pixel, PURPOSE_MISMATCH_ON);
        s.theta_off = theta_with_sigma(p.theta_off, key, pixel, PURPOSE_MISMATCH_OFF);
    }

    /// The first sample of a run: everything starts at the steady state of the mean input
    /// and no event fires.
    void init_state(PixelState& s, double photon_rate, double t) const {
        s.x = std::log(ELEMENTARY_CHARGE_C * mean_electron_rate(photon_rate));
        s.z = s.y = s.ref = s.x;
        s.refr_until = -std::numeric_limits<double>::infinity();
        s.t = t;
        s.n = 1;
    }

    /// Advance a pixel to the sample (t1, photon_rate), whatever its last sample time: the
    /// first sample initialises it; a sample at or before its last one is skipped (the
    /// pixel was already advanced further by a finer, pixel-local sampling).
    template <class Emit>
    EVSTWIN_ALWAYS_INLINE void advance(PixelState& s, double photon_rate, const SampleConstants& c, Philox4x32Key key,
                                       std::uint32_t pixel, PoissonSampler& poisson, Emit&& emit,
                                       TraceSample* trace = nullptr) const {
        if (s.n == 0) {
            init_state(s, photon_rate, c.t1);
            if (trace) *trace = {std::exp(s.x), s.x, s.y, s.ref};
            return;
        }
        if (c.t1 <= s.t) return;
        if (s.t == c.t0) {
            step(s, photon_rate, c, key, pixel, poisson, emit, trace);
        } else {
            step(s, photon_rate, constants(s.t, c.t1), key, pixel, poisson, emit, trace);
        }
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

    /// Eq. 12-15: one uniform u decides OFF (u < p), ON (u > 1 - p) or nothing, and, given
    /// an event, its time inside the interval (u / p is uniform). Returns the polarity or -1.
    EVSTWIN_ALWAYS_INLINE int shot_noise(double u, double current_a, const SampleConstants& c, double& t_noise) const {
        // r = ((F - 1) min(I / I_max, 1) + 1) R_n, with I / I_max saturating at the top of
        // the dynamic range (beyond it eq. 12 would turn negative).
        const double prob = (shot_slope_per_a * std::min(current_a, p.shot_noise_i_max_a) + p.shot_noise_rate_hz) * c.dt;
        if (u < prob) {
            t_noise = c.t0 + c.dt * (u / prob);
            return OFF;
        }
        if (u > 1.0 - prob) {
            t_noise = c.t0 + c.dt * ((1.0 - u) / prob);
            return ON;
        }
        return -1;
    }

    /// Whether the block kernel below handles this configuration (the common ones).
    bool has_block_kernel() const {
        const bool pooled = p.photon_shot_noise && p.dark_model != DarkModel::Paper;
        const bool deterministic = !p.photon_shot_noise && p.dark_model == DarkModel::None;
        return pooled || deterministic;
    }

    /// Scratch space of the block kernel (one per thread).
    struct BlockScratch {
        std::vector<double> u_noise, x, current, y;
        std::vector<std::uint8_t> busy;
        std::vector<std::uint32_t> count_word;
        std::vector<double> z, count;
        double cached_rate = -1.0, cached_x = 0.0;
        // The photoreceptor pole's decay and ramp depend on the current only through the
        // electron count of the interval: kept per count for the current dt.
        std::vector<double> pr_decay, pr_ramp;
        std::vector<std::uint8_t> pr_known;
        double pr_dt = -1.0;
        void resize(std::size_t n) {
            if (x.size() < n) {
                u_noise.resize(n); x.resize(n); current.resize(n); y.resize(n); busy.resize(n); count_word.resize(n);
                z.resize(n); count.resize(n);
            }
        }
    };

    /// Which pixels of a block the kernel advances now: `active` lists their positions
    /// (local indices into the block's state, rates and ids).
    struct BlockView {
        PixelState* state;           ///< the block's pixel states
        const std::uint32_t* ids;    ///< global pixel index of each local index
        const std::uint32_t* active; ///< local indices to advance, in increasing order; nullptr: all
        std::size_t n_active;
    };

    /// advance() for pixels that all stand at c.t0 with n > 0, as separate passes (random
    /// words; currents; filter, noise and the quiet test; the comparator for the few busy
    /// pixels; the commit), so each pass is a short loop the processor can overlap across
    /// pixels. Same arithmetic in the same order as step(): the same events.
    template <class Real, class Emit>
    void step_block(const BlockView& v, const Real* rate, const SampleConstants& c, Philox4x32Key key,
                    PoissonSampler& poisson, BlockScratch& scratch, Emit&& emit, std::uint32_t& pixel) const {
        // All pixels active (the common case): index them directly, without the indirection.
        if (v.active == nullptr)
            step_block_impl<true>(v, rate, c, key, poisson, scratch, emit, pixel);
        else
            step_block_impl<false>(v, rate, c, key, poisson, scratch, emit, pixel);
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
        std::uint8_t* busy = scratch.busy.data();
        PixelState* st = v.state;
        // at(j): the local index of the j-th active pixel.
        const auto at = [&v](std::size_t j) -> std::size_t { return AllActive ? j : v.active[j]; };
        const bool shot = p.shot_noise_rate_hz > 0.0;
        if (p.photon_shot_noise) {
            std::uint32_t* count_word = scratch.count_word.data();
            for (std::size_t j = 0; j < n; ++j) {
                std::uint32_t w[2];
                sample_words(st[at(j)], key, v.ids[at(j)], w);
                u_noise[j] = uniform_open(w[1]);
                count_word[j] = w[0];
            }
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
            for (std::size_t j = 0; j < n; ++j) {
                if (shot) {
                    std::uint32_t w[2];
                    sample_words(st[at(j)], key, v.ids[at(j)], w);
                    u_noise[j] = uniform_open(w[1]);
                }
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
                const double prob =
                    (shot_slope_per_a * std::min(cur[j], p.shot_noise_i_max_a) + p.shot_noise_rate_hz) * c.dt;
                noise = (u_noise[j] < prob) | (u_noise[j] > 1.0 - prob);
            }
            const double th_on = si.theta_on, th_off = si.theta_off;
            const double g = (yi - si.y) * c.inv_dt + p.leak_rate_hz * th_on;
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
                const int pol = shot ? shot_noise(u_noise[j], cur[j], c, t_noise) : -1;
                compare(si, y[j], c, pol, t_noise, emit);
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
        if (p.photon_shot_noise || p.dark_model != DarkModel::None || p.shot_noise_rate_hz > 0.0)
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
        const int noise_pol = p.shot_noise_rate_hz > 0.0 ? shot_noise(uniform_open(w[1]), current_a, c, t_noise) : -1;

        compare(s, y, c, noise_pol, t_noise, emit);
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

    /// The comparator over (t0, t1]: the level difference d(t) = y(t) - ref(t) is linear in
    /// t, since y is interpolated linearly (eq. 16) and the leak lowers ref at a constant
    /// rate f_leak theta_on (eq. 10-11). Each crossing fires at its interpolated time and
    /// sets ref to the level there; during the refractory period nothing fires and ref keeps
    /// the last event's level (it still leaks). If, when the refractory period ends, the
    /// difference has passed n >= 1 thresholds, one event fires then and ref moves by n
    /// whole thresholds: the levels crossed while the pixel was dead are merged into that
    /// single event, as a real pixel cannot report them separately.
    template <class Emit>
    EVSTWIN_ALWAYS_INLINE void compare(PixelState& s, double y1, const SampleConstants& c, int noise_pol, double t_noise, Emit& emit) const {
        const double th_on = s.theta_on, th_off = s.theta_off, refr = p.refractory_s;
        const double g = (y1 - s.y) * c.inv_dt + p.leak_rate_hz * th_on;  // d(d)/dt
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
        for (;;) {
            if (s.refr_until > tb) {
                if (noise_pol >= 0 && t_noise < s.refr_until) noise_pol = -1;  // dead pixel
                if (s.refr_until >= c.t1) break;
                db += g * (s.refr_until - tb);
                tb = s.refr_until;
            }
            if (db >= th_on) {
                const double n = std::floor(db / th_on);
                emit(tb, ON);
                db -= n * th_on;
                s.refr_until = tb + refr;
                continue;
            }
            if (db <= -th_off) {
                const double n = std::floor(-db / th_off);
                emit(tb, OFF);
                db += n * th_off;
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
                emit(tb, static_cast<Polarity>(noise_pol));
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
                emit(tb, static_cast<Polarity>(pol));
                db = pol == ON ? d_end - std::floor(d_end / th_on) * th_on : d_end + std::floor(-d_end / th_off) * th_off;
                tb = c.t1;
                s.refr_until = tb + refr;
                break;
            }
            emit(tc, static_cast<Polarity>(pol));
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
