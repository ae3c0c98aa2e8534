// The pixel's equations and decisions, each one inline function that every path (the scalar
// PixelModel, the block kernels, the vector passes) calls, so they agree bit for bit by
// construction.
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

}  // namespace evstwin

EVSTWIN_FP_STRICT_END
