// The physics of one event-sensor pixel (the paper's section 2; the documentation's "pixel model"
// and "decisions and measured dead ends" pages for the traps).
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
// once the thresholds are in those units (docs/development/decisions.md, "Log units throughout").
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
#include "params.hpp"
#include "physics.hpp"
#include "rng.hpp"
#include "state.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

/// Parameters turned into the numbers the hot loop needs.
struct PixelModel {
    /// The parameters, fixed at construction (checked by validate()): the numbers below are
    /// derived from them once, so a changed copy would leave those stale. A new PixelModel
    /// takes new parameters.
    const PixelParams p;
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
    /// (HotPixelState::chain = k).
    std::vector<HotChainTerms> hot_chains;
    bool leak_off = false;  ///< LeakPolarity::Off: the leak drifts d = y - ref down, to OFF
    /// The longest piece, in source-follower time constants (b h), that the continuous model
    /// takes where a crossing is plausible with the follower alone (refine_and_compare with a = 0).
    /// Unrefined, the DAVIS346 preset's dark pixel (10 Hz follower) counts +1.0-1.4 % more
    /// events at 1 kHz (b dt = 1/16) than at 16 kHz, +1.5-2 % at 250 Hz and +20-24 % at 50 Hz
    /// (bench/noise_convergence.py --preset davis346); refined to 1/8, the paper's pixel
    /// (leak and background off, 64 x 64 px, 3 s, 3 seeds) stays within +1.0 to +1.7 % of
    /// 4 kHz at 1 kHz, 250 and 50 Hz (seed spread 0.7 %). 1/8 leaves 1 kHz, the rate most
    /// scenes sample such a follower at, unrefined: the same events and cost as before.
    static constexpr double SF_REFINE_BH = 1.0 / 8.0;
    /// The most chances to cross that crossing_plausible() counts over one interval, e^10: its
    /// limit 2 (13.8 + 10) var then stays under the quiet test's 48 var (bridge_bound_for), so
    /// a pixel the block kernels settle as quiet is one continuous_finish() leaves alone.
    static constexpr double MAX_EXCURSIONS = 22026.0;
    /// The deepest cut of refine_and_compare: 2^20 pieces, enough for a h <= 1 over 4 s behind
    /// a 40 kHz pole. It cuts only where a crossing stays plausible, so depth costs little.
    static constexpr int MAX_REFINE_LEVELS = 20;
    /// The most halvings of one interval (then every piece left runs whole): 16 times the
    /// 1,024 pieces an interval was cut into evenly before the cuts were adaptive. A noisy
    /// pixel's long step takes far fewer; only a line that crosses a level in nearly every
    /// piece (a leak firing every few seconds over a sample a year long) reaches it.
    static constexpr int MAX_REFINE_SPLITS = 1 << 14;

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
                c.sf_ramp = detail::low_pass_ramp(u);
            }
        }
        return c;
    }

    /// Mean electron rate of a pixel receiving `photon_rate` photons/s.
    EVSTWIN_ALWAYS_INLINE double mean_electron_rate(double photon_rate) const { return e_per_photon * photon_rate + dark_mean_e_per_s; }

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
        double hot_hz = hot_rate_hz;
        if (hot_rate_hz < 0.0) {
            const bool hot = p.hot_pixel_fraction > 0.0 && uniform_open(b[2]) < p.hot_pixel_fraction;
            // Median hot_pixel_rate_hz: exp(sigma z) without the mean correction.
            hot_hz = hot ? p.hot_pixel_rate_hz * (p.hot_pixel_rate_sigma > 0.0
                                                      ? std::exp(p.hot_pixel_rate_sigma *
                                                                 normal_from_uniforms(uniform_open(b[3]), uniform_open(a[0] ^ b[2])))
                                                      : 1.0)
                         : 0.0;
        }
        s.next_hot_t = std::numeric_limits<double>::infinity();
        if (!(hot_hz > 0.0)) {
            s.hot.reset();
            return;
        }
        HotPixelState& h = s.hot.emplace();
        h.rate_hz = hot_hz;
        // The chain's stationary polarity (the low bit, as before, at an even share).
        h.chain = hot_chain;
        const double on_share = hot_chains[hot_chain].chain.on_share;
        h.pol = static_cast<std::uint8_t>(on_share == 0.5 ? (b[3] & 1u) : uniform_open(b[3]) < on_share);
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
        s.next_hot_t = std::numeric_limits<double>::infinity();
        if (s.hot) {
            // The telegraph's state and the clocks as they stand in the steady state: active
            // with probability duty, and (exponential waits being memoryless) fresh waits.
            HotPixelState& h = *s.hot;
            h.count = h.switches = 0;
            h.last_t = -std::numeric_limits<double>::infinity();
            h.event_t = h.switch_t = std::numeric_limits<double>::infinity();
            const Philox4x32Counter u = philox4x32({2u, 0u, pixel, PURPOSE_INIT}, key);
            const double duty = hot_chains[h.chain].chain.duty;
            const bool bursts = duty < 1.0;
            h.active = !bursts || uniform_open(u[0]) < duty;
            if (bursts) h.switch_t = t - std::log(uniform_open(u[1])) * hot_dwell_s(h);
            if (h.active) h.event_t = t - std::log(uniform_open(w[3])) / h.rate_hz;
            s.next_hot_t = std::min(h.event_t, h.switch_t);
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
    /// The longest piece, in pole time constants (a h), of an interval refine_and_compare() cuts:
    /// 1 behind a pole at least as fast as the follower (a bright pixel, as it always was), and
    /// SF_REFINE_BH behind a slower one, whose noise a Brownian bridge over a longer piece
    /// describes as rougher than it is (the dark DAVIS346 pixel with the pole, 128 x 128 px, 4 s,
    /// 3 seeds: 1,750 OFF events at 1 kHz, 2,063 at 5 Hz cut to a h <= 1, 1,715 cut to 1/8).
    double pole_refine_ah(double a) const { return a < sf_rate() ? SF_REFINE_BH : 1.0; }
    /// Stationary standard deviation of the noise on the level y at a constant photon rate [ln
    /// units]: white noise of intensity D (noise_intensity) through the pole (rate a) and the
    /// follower (rate b) has variance D a b / (2 (a + b)); through one of them, D r / 2.
    double stationary_noise_sigma(double photon_rate) const {
        const double mean_e = mean_electron_rate(photon_rate);
        const double D = noise_intensity(photon_rate, mean_e);
        const double a = pole_rate(ELEMENTARY_CHARGE_C * mean_e), b = sf_rate();
        const double r = a > 0.0 && b > 0.0 ? a * b / (a + b) : (a > 0.0 ? a : b);
        return r > 0.0 ? std::sqrt(0.5 * D * r) : 0.0;
    }
    /// Whether a long interval of a pixel at this photon rate, where refine_and_compare() cuts
    /// it, would be cut into pieces shorter than piece_s [s]: a crossing of a level theta away
    /// at both ends stays plausible over such a piece (crossing_plausible's limit, with the
    /// piece's chances to cross). The noise on the level is taken as one OU process of its
    /// stationary sigma at the slower of the pole and the follower, whose bridge is at least as
    /// wide as the two poles' (so the answer errs toward yes). A pixel whose long steps are cut
    /// that fine costs more than a dense run's samples (Sensor::run_sparse). Speed only.
    bool long_steps_cut_below(double photon_rate, double theta, double piece_s) const {
        if (!continuous || !has_filter || euler) return false;
        const double mean_e = mean_electron_rate(photon_rate);
        if (noise_intensity(photon_rate, mean_e) <= 0.0) return false;
        const double b = sf_rate(), a = p.pr_pole ? pole_rate(ELEMENTARY_CHARGE_C * mean_e) : 0.0;
        if (p.pr_pole && !(a > 0.0)) return false;  // no refinement: the line and the bridge
        // The rate refine_and_compare cuts by and its finest piece: no cut goes below that.
        const double cut_rate = p.pr_pole ? a : b, finest_s = (p.pr_pole ? pole_refine_ah(a) : SF_REFINE_BH) / cut_rate;
        if (piece_s <= finest_s) return false;
        const double sigma = stationary_noise_sigma(photon_rate);
        const double rho2 = std::exp(-(p.pr_pole ? std::min(a, b) : b) * piece_s);  // rho^2 at half the piece
        const double bridge_var = sigma * sigma * (1.0 - rho2) / (1.0 + rho2);
        // continuous_finish's chances: one behind a pole at least as fast as the follower.
        const double chances = p.pr_pole && a >= b ? 1.0 : std::max(1.0, cut_rate * piece_s);
        return theta * theta < plausible_limit(bridge_var, chances);
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
    double hot_dwell_s(const HotPixelState& h) const {
        const HotPixelChain& c = hot_chains[h.chain].chain;
        return h.active ? c.burst_s : c.burst_s * (1.0 - c.duty) / c.duty;
    }

    /// A hot pixel's events up to t1 (its own Poisson clock with dead time, polarities from
    /// its two-state chain, running only in the active periods of its telegraph), independent of the
    /// comparator and of the sampling.
    template <class Emit>
    EVSTWIN_ALWAYS_INLINE void hot_events(PixelState& s, double t1, Philox4x32Key key, std::uint32_t pixel,
                                          Emit& emit) const {
        // next_hot_t is finite only for a hot pixel (init_pixel, init_state).
        HotPixelState& h = *s.hot;
        while (s.next_hot_t <= t1) {
            if (h.event_t <= h.switch_t) {
                emit(h.event_t, static_cast<Polarity>(h.pol), LABEL_HOT_PIXEL);
                h.last_t = h.event_t;
                ++h.count;
                const Philox4x32Counter w = philox4x32(
                    {static_cast<std::uint32_t>(h.count), static_cast<std::uint32_t>(h.count >> 32), pixel, PURPOSE_HOT},
                    key);
                // The next polarity: the same draw's second word decides a switch.
                const HotChainTerms& chain = hot_chains[h.chain];
                if (chain.strict || uniform_open(w[1]) < chain.switch_p[h.pol]) h.pol ^= 1u;
                h.event_t += p.refractory_s - std::log(uniform_open(w[0])) / h.rate_hz;
            } else {
                ++h.switches;
                const Philox4x32Counter w = philox4x32({static_cast<std::uint32_t>(h.switches),
                                                        static_cast<std::uint32_t>(h.switches >> 32), pixel,
                                                        PURPOSE_HOT_SWITCH},
                                                       key);
                const double now = h.switch_t;
                h.active ^= 1u;
                h.switch_t = now - std::log(uniform_open(w[0])) * hot_dwell_s(h);
                h.event_t = h.active ? std::max(now, h.last_t + p.refractory_s) - std::log(uniform_open(w[1])) / h.rate_hz
                                     : std::numeric_limits<double>::infinity();
            }
            s.next_hot_t = std::min(h.event_t, h.switch_t);
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
    EVSTWIN_ALWAYS_INLINE void shot_noise(const PixelState& s, double u, double current_a, const SampleConstants& c,
                                          NoisePulses& pulses) const {
        const double f = background_factor(current_a) * c.dt;
        const double p_off = s.bg_off_hz * f, p_on = s.bg_on_hz * f;
        if (u < p_off) {
            pulses.add(c.t0 + c.dt * (u / p_off), OFF);
        } else if (u > 1.0 - p_on) {
            pulses.add(c.t0 + c.dt * ((1.0 - u) / p_on), ON);
        }
    }

    /// Eq. 12's background as continuous-time processes (continuous model): ON and OFF events
    /// are two Poisson processes whose rates follow the light, each run on its own clock: an
    /// exponential budget, drawn at each event, spent at the rate r dt per interval; the event
    /// fires where the budget runs out (exact for rates constant over an interval), so a
    /// sample costs two multiply-adds and no random number. Each clock fires as often as it runs
    /// out in the interval, so the events do not depend on the sampling (a long step keeps them).
    ///
    /// background_spend (each interval) then background_fire (where a clock ran out).
    ///
    /// The first half: spend one interval of both clocks' budgets, f being
    /// background_factor() of the current. Returns whether a clock ran out (then
    /// background_fire has an event to place).
    EVSTWIN_ALWAYS_INLINE bool background_spend(PixelState& s, double f, const SampleConstants& c) const {
        const double r_on = s.bg_on_hz * f, r_off = s.bg_off_hz * f;
        const double on = detail::clock_spent(s.bg_clock_on, r_on, c.dt);
        const double off = detail::clock_spent(s.bg_clock_off, r_off, c.dt);
        s.bg_clock_on = on;
        s.bg_clock_off = off;
        return detail::clock_ran_out(on, off);
    }

    /// The second half: after background_spend, the events of the clocks that ran out, into
    /// `pulses` in time order, each clock given a fresh budget counted from where it ran out
    /// (its budget left at t1 is negative by r (t1 - t)) until both are positive again. The
    /// uniforms come in rounds, ON's then OFF's: one clock running out once draws what it did
    /// when an interval held one event at most.
    EVSTWIN_ALWAYS_INLINE void background_fire(PixelState& s, double current_a, const SampleConstants& c,
                                               Philox4x32Key key, std::uint32_t pixel, NoisePulses& pulses) const {
        if (s.bg_clock_on > 0.0 && s.bg_clock_off > 0.0) return;
        const double f = background_factor(current_a);
        const double r_on = s.bg_on_hz * f, r_off = s.bg_off_hz * f;
        CounterStream more(key, pixel, s.n, PURPOSE_BACKGROUND);
        const auto renew = [&more](double& clock) {
            const double left = -std::log(more.uniform()) + clock;
            clock = left > 0.0 ? left + 1e-300 : left;
        };
        while (s.bg_clock_on <= 0.0 || s.bg_clock_off <= 0.0) {
            if (s.bg_clock_on <= 0.0) {
                pulses.add(std::min(c.t1, std::max(c.t0, c.t1 + s.bg_clock_on / r_on)), ON);
                renew(s.bg_clock_on);
            }
            if (s.bg_clock_off <= 0.0) {
                pulses.add(std::min(c.t1, std::max(c.t0, c.t1 + s.bg_clock_off / r_off)), OFF);
                renew(s.bg_clock_off);
            }
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
            z = first_order_exact(s.z, s.x, x, pole_rate(current_a) * c.dt);
        }
        const double y = detail::source_follower(has_filter, euler, s.y, s.z, z, c.sf_decay, c.sf_ramp);

        // Statistical shot noise, eq. 12-15.
        NoisePulses pulses;
        if (has_background()) shot_noise(s, uniform_open(w[1]), current_a, c, pulses);

        compare(s, y, 0.0, c, leak_slope(s, leak_rate_hz(photon_rate)), pulses, emit);
        if (trace) *trace = {current_a, x, y, s.ref};
        s.x = x;
        s.z = z;
        s.y = y;
    }

    /// y(t1) of tau y' = in - y for an input linear from in0 to in1 over u = dt / tau.
    static double first_order_exact(double y0, double in0, double in1, double u) {
        return detail::low_pass_exact(y0, in0, in1, std::exp(-u), detail::low_pass_ramp(u));
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
        z = pole ? detail::low_pass_exact(s.z, s.x, x, cache.pole_decay, cache.pole_ramp) : x;
        const double yd = detail::source_follower(filter, eul, s.y - s.ny, s.z, z, c.sf_decay, c.sf_ramp);
        nz = 0.0;
        ny = 0.0;
        if (D > 0.0) {
            // Without the pole z is x, with no noise of its own (as init_state starts it): nz
            // stays 0, the bits phi_zz * s.nz + l_zz * g1 gave (the one-pole coefficients leave
            // phi_zz and l_zz at 0, noise.hpp), without the two multiplies.
            nz = pole ? detail::noise_z_next(k.phi_zz, k.l_zz, s.nz, g1) : 0.0;
            // Without the pole its rate a is 0: the 1-D process of the source follower.
            ny = (pole && cache.a > 0.0 && filter)
                     ? detail::noise_y_next(k.phi_yz, k.phi_yy, k.l_yz, k.l_yy, s.nz, s.ny, g1, g2)
                     : detail::noise_y_next(k.phi_yy, k.l_yy, s.ny, g1);
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
        NoisePulses pulses;
        if (has_background()) background_fire(s, current_a, c, key, pixel, pulses);

        // With a photoreceptor pole faster than the sampling (a dt > 1), the noise is smooth
        // below 1 / a but rough at the sample's scale, which neither the straight line nor a
        // Brownian bridge describes well near a level: where a crossing is plausible, the
        // interval is refined exactly (below). Elsewhere the line and the bridge do.
        const double a = pole_rate(current_a);
        const bool two_poles = D > 0.0 && a > 0.0 && has_filter;
        // The source follower alone (no pole), over an interval longer than a sixteenth of its
        // time constant: the noise is a 1-D OU process, which forgets within 1 / b, so over a
        // long interval it makes ~b dt excursions where a Brownian bridge makes one, and a
        // line between two far samples says little of the path. Where a crossing is
        // plausible (with ~b dt chances), the interval is refined exactly to pieces of b h <=
        // SF_REFINE_BH (where the dense engine has converged: the docs' noise model page).
        // A static pixel can then take long steps with the statistics of short ones.
        const double b_sf = sf_rate();
        const bool sf_noise = D > 0.0 && !p.pr_pole && has_filter && !euler;
        // Behind a pole slower than the follower (a dim pixel) the same holds of the pole's own
        // time constant: its pieces are cut to a h <= SF_REFINE_BH too (the dark DAVIS346 pixel
        // with the pole counted +18 % OFF events at 5 Hz against 1 kHz when cut to a h <= 1).
        const double pole_piece = pole_refine_ah(a);
        // A background event due in such an interval is refined to as well: it resets the
        // reference to the level at its time, which the line puts at the interval's straight
        // path and not at the noise's; after it the pixel's crossings went missing (the dark
        // mcreynolds pixel in 0.1 s steps: OFF -2 %, bench/stepping_statistics.py). Refined,
        // the event falls in a piece the pole or the follower resolves.
        if (two_poles && a * c.dt > pole_piece) {
            const double chances = pole_piece < 1.0 ? std::min(a * c.dt, MAX_EXCURSIONS) : 1.0;
            if (pulses.due(c.t1) || crossing_plausible(s, y, c, leak_g, bridge_var, chances)) {
                refine_and_compare(s, x, z, y - ny, nz, ny, c, leak_g, a, b_sf, D, bridge_var, chances, pulses, key,
                                   pixel, emit);
            } else {
                compare_bridged(s, y, ny, c, leak_g, bridge_var, pulses, key, pixel, PURPOSE_BRIDGE, emit, pre);
            }
        } else if (sf_noise && b_sf * c.dt > SF_REFINE_BH &&
                   (pulses.due(c.t1) || crossing_plausible(s, y, c, leak_g, bridge_var, std::min(b_sf * c.dt, MAX_EXCURSIONS)))) {
            refine_and_compare(s, x, x, y - ny, 0.0, ny, c, leak_g, 0.0, b_sf, D, bridge_var,
                               std::min(b_sf * c.dt, MAX_EXCURSIONS), pulses, key, pixel, emit);
        } else {
            compare_bridged(s, y, ny, c, leak_g, bridge_var, pulses, key, pixel, PURPOSE_BRIDGE, emit, pre);
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
    /// probability above 1e-6 (exp(-13.8)), or above 1e-6 / excursions where the noise has
    /// that many independent chances in the interval (b dt of an OU process; 1: a bridge).
    /// leak_g: leak_slope() of the sample.
    EVSTWIN_ALWAYS_INLINE bool crossing_plausible(const PixelState& s, double y1, const SampleConstants& c,
                                                  double leak_g, double bridge_var, double excursions = 1.0) const {
        return crossing_within(s, y1, c, leak_g, plausible_limit(bridge_var, excursions));
    }
    /// crossing_plausible()'s limit on the product of the distances to a level at both ends.
    static double plausible_limit(double bridge_var, double excursions) {
        return 2.0 * (excursions > 1.0 ? 13.8 + std::log(excursions) : 13.8) * bridge_var;
    }
    /// crossing_plausible() with its limit (plausible_limit) known.
    EVSTWIN_ALWAYS_INLINE bool crossing_within(const PixelState& s, double y1, const SampleConstants& c, double leak_g,
                                               double lim) const {
        const double g = detail::comparator_slope(s.y, y1, leak_g, c.inv_dt);
        const double d0 = s.y - s.ref, d1 = detail::comparator_end(s.y, s.ref, g, c.dt);
        const double th_on = s.theta_on, th_off = s.theta_off;
        if (!detail::inside_levels(d0, d1, th_on, th_off)) return true;
        return (th_on - d0) * (th_on - d1) < lim || (th_off + d0) * (th_off + d1) < lim;
    }

    /// The comparator over (c.t0, c.t1] toward y1 (noise part ny1), with the crossings of a
    /// Brownian bridge of middle variance bridge_var that the line misses: only while the line
    /// itself crosses nothing after the refractory period (a crossing of the line fires
    /// anyway; the excursions around it are second order). `purpose` keys the bridge's draws;
    /// leak_g: leak_slope() of the sample.
    template <class Emit>
    EVSTWIN_ALWAYS_INLINE void compare_bridged(PixelState& s, double y, double ny, const SampleConstants& c,
                                               double leak_g, double bridge_var, NoisePulses& pulses, Philox4x32Key key,
                                               std::uint32_t pixel, std::uint32_t purpose, Emit& emit,
                                               const BridgePre* pre = nullptr) const;

    /// The interval (c.t0, c.t1], where a crossing in it is plausible (crossing_plausible
    /// with `excursions` chances and the interval's bridge_var), cut adaptively: the noise at
    /// its middle drawn exactly from its law given the states at both ends (a Levy bridge
    /// construction of the OU process: two poles behind the pole a > 0, the follower's one
    /// with a = 0), and each half cut again while a crossing in it stays plausible (its own
    /// bridge, its share of the chances), down to pieces of a h <= pole_refine_ah(a) (b h <=
    /// SF_REFINE_BH with the follower alone; at most 2^MAX_REFINE_LEVELS pieces). The
    /// noise-free chain is stepped exactly through the cuts for the input linear in the
    /// interval, and the comparator runs piece by piece with each piece's bridge. x1, z1, yd1,
    /// nz1, ny1: the sample's values at c.t1 (already drawn; z1 = x1 and nz1 = 0 with the
    /// follower alone); s still holds those at c.t0.
    template <class Emit>
    void refine_and_compare(PixelState& s, double x1, double z1, double yd1, double nz1, double ny1,
                            const SampleConstants& c, double leak_g, double a, double b, double D, double bridge_var,
                            double excursions, NoisePulses& pulses, Philox4x32Key key, std::uint32_t pixel,
                            Emit& emit) const;

    /// Why a threshold crossing of the line fired, at a point a share f into the interval:
    /// the largest of the changes since the last event in the crossing's direction, of the
    /// noise-free level (signal), of the noise and of the leak (which only ever moves d towards
    /// its own polarity's level, so it never wins for the other one).
    EVSTWIN_ALWAYS_INLINE std::uint8_t crossing_label(const PixelState& s, int pol, double d, double y_t,
                                                      double ny_t) const;

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
                                       NoisePulses& pulses, Emit& emit) const;
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

// The comparator (PixelModel::compare, compare_bridged, crossing_label).
#include "comparator.hpp"

// The refinement of an interval where a crossing is plausible (PixelModel::refine_*).
#include "refine.hpp"

// The block kernels (BlockModel) and their arrays, for those who included pixel.hpp for them.
#include "kernels/block_model.hpp"
