// The pixel's equations and decisions, each one inline function that every path (the scalar
// PixelModel, the block kernels, the vector passes) calls, so they agree bit for bit by
// construction.
#pragma once

#include <algorithm>
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
#include "noise.hpp"
#include "rng.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

namespace detail {

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

/// Whether bridge_fires() is false for every uniform uniform_open() gives (u >= 2^-33): no
/// variance, or both exponents above 24 (two e^-24 sum to 7.6e-11, below 2^-33). compare_bridged()
/// then draws no uniform: a counter-based draw changes nothing else, so the events are the
/// same, and a long step's refined pieces that cannot fire cost no Philox call.
inline bool bridge_cannot_fire(double on0, double on1, double off0, double off1, double mid) {
    if (!(mid > 0.0)) return true;
    const double e_on = bridge_exponent(on0, on1, mid), e_off = bridge_exponent(off0, off1, mid);
    return (e_on > 24.0) & (e_off > 24.0);
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
    const double e_on = bridge_exponent(on0, on1, mid), e_off = bridge_exponent(off0, off1, mid);
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
// ---- The photoreceptor pole and the source follower: first-order low-passes (eq. 6-7) ----

/// (1 - e^-u) / u for u = dt / tau >= 0: the share of an input's ramp over the interval that
/// an exact first-order low-pass passes (SampleConstants::sf_ramp, the sampled model's pole).
/// Below u = 1e-12 (and at 0, where the expression is 0 / 0) it is 1. noise.hpp's
/// one_minus_exp_over() is the same expression above 1e-12 with 1 - u / 2 below (and takes
/// negative arguments); the continuous model's pole uses that one. One fallback for both
/// would change the bits of u in (1.1e-16, 1e-12] on one of the two paths (intervals near
/// Sensor::MIN_DT_S), so both stay.
EVSTWIN_ALWAYS_INLINE double low_pass_ramp(double u) { return u > 1e-12 ? -std::expm1(-u) / u : 1.0; }

/// y(t1) of tau y' = in - y over an interval u = dt / tau, exactly, for an input linear from
/// in0 to in1: decay = e^-u, ramp = low_pass_ramp(u) (or the same numbers kept: NoiseCache,
/// SampleConstants). The photoreceptor pole (input x, output z) and the exact source follower
/// (input z, output y) of every path.
EVSTWIN_ALWAYS_INLINE double low_pass_exact(double y0, double in0, double in1, double decay, double ramp) {
    return in1 + (y0 - in0) * decay - (in1 - in0) * ramp;
}

/// Eq. 7, the paper's forward Euler step on the previous input: decay = 1 - u, ramp = u.
EVSTWIN_ALWAYS_INLINE double low_pass_euler(double y0, double in0, double decay, double ramp) {
    return ramp * in0 + decay * y0;
}

/// The source follower's output at t1 from its output y0 and input z0 at t0 and input z1 at
/// t1: z1 itself without a filter, else eq. 7 (euler) or the exact low-pass, with the
/// sample's decay and ramp (SampleConstants::sf_decay, sf_ramp).
EVSTWIN_ALWAYS_INLINE double source_follower(bool filter, bool euler, double y0, double z0, double z1, double decay,
                                             double ramp) {
    if (!filter) return z1;
    if (euler) return low_pass_euler(y0, z0, decay, ramp);
    return low_pass_exact(y0, z0, z1, decay, ramp);
}

// ---- The shot noise's exact transition (noise.hpp's NoiseCoeffs) ----

/// n_z at t1 behind the photoreceptor pole: phi_zz n_z + l_zz g1.
EVSTWIN_ALWAYS_INLINE double noise_z_next(double phi_zz, double l_zz, double nz0, double g1) {
    return phi_zz * nz0 + l_zz * g1;
}
/// n_y at t1 of the two-pole system (pole and source follower), from (n_z, n_y) at t0 and the
/// sample's two normals.
EVSTWIN_ALWAYS_INLINE double noise_y_next(double phi_yz, double phi_yy, double l_yz, double l_yy, double nz0, double ny0,
                                          double g1, double g2) {
    return phi_yz * nz0 + phi_yy * ny0 + l_yz * g1 + l_yy * g2;
}
/// n_y at t1 of one low-pass (the source follower alone, or the pole alone): phi_yy n_y + l_yy g1.
EVSTWIN_ALWAYS_INLINE double noise_y_next(double phi_yy, double l_yy, double ny0, double g1) {
    return phi_yy * ny0 + l_yy * g1;
}

// ---- Eq. 12's background as two clocks (continuous model) ----

/// A background clock's budget after an interval dt at the rate r_hz (bg_*_hz times
/// background_factor()).
EVSTWIN_ALWAYS_INLINE double clock_spent(double clock, double r_hz, double dt) { return clock - r_hz * dt; }
/// Whether either clock ran out (then it places an event: PixelModel::background_fire).
EVSTWIN_ALWAYS_INLINE bool clock_ran_out(double on, double off) { return !((on > 0.0) & (off > 0.0)); }

// ---- The comparator (eq. 10-11, 16) ----

/// The slope of d = y - ref over an interval: the level's straight line from y0 to y1 plus
/// the leak's drift leak_g (PixelModel::leak_slope).
EVSTWIN_ALWAYS_INLINE double comparator_slope(double y0, double y1, double leak_g, double inv_dt) {
    return (y1 - y0) * inv_dt + leak_g;
}
/// d at t1 on that line: (y0 - ref) + g dt.
EVSTWIN_ALWAYS_INLINE double comparator_end(double y0, double ref, double g, double dt) { return (y0 - ref) + g * dt; }

/// Whether the line stays strictly inside both levels at both ends (d0 = d at t0, d1 at t1:
/// -theta_off < d < theta_on): no crossing of the line in the interval. Written with the
/// differences (a - b > 0 exactly when a > b, for every pair of doubles: gradual underflow
/// never rounds a difference of two different doubles to 0, and a NaN or inf - inf fails
/// both; the thresholds are finite) so the vector quiet pass shares them (std::min of two).
EVSTWIN_ALWAYS_INLINE bool inside_levels(double d0, double d1, double th_on, double th_off) {
    return (std::min(th_on - d0, th_off + d0) > 0.0) & (std::min(th_on - d1, th_off + d1) > 0.0);
}

/// The continuous model's quiet test on that line: inside both levels at t0, and far enough
/// from both at both ends that a Brownian bridge of the interval's middle variance would
/// cross one with a probability below 1e-6: (theta_on - d0)(theta_on - d1) and
/// (theta_off + d0)(theta_off + d1) above bound (NoiseCache::bridge_bound). Then the pixel
/// fires nothing in the interval (clocks, hot events and refractory aside).
EVSTWIN_ALWAYS_INLINE bool bridge_quiet(double d0, double d1, double th_on, double th_off, double bound) {
    const double on0 = th_on - d0, off0 = th_off + d0;
    return (std::min(on0, off0) > 0.0) & (std::min(on0 * (th_on - d1), off0 * (th_off + d1)) > bound);
}

}  // namespace detail

}  // namespace evstwin

EVSTWIN_FP_STRICT_END
