// Shot noise as a continuous-time process, discretised exactly (the default noise model).
//
// The photodiode current is its mean plus shot noise: electrons arrive as a Poisson process
// of rate lambda, so in the log domain the relative fluctuation is white with intensity
// D = lambda_noisy / lambda^2 [1/s] (lambda_noisy: the part of the rate that is Poisson;
// D = 1/lambda when signal and dark are both shot-noise limited). The log is linearised about
// the mean, which holds while many electrons arrive per filter time constant: the
// photoreceptor pole's bandwidth is proportional to the current, so it always averages
// ~I_ref / (2 pi f_ref e) ~ 1000 electrons with the default pole.
//
// That white noise drives the photoreceptor pole (rate a = 2 pi f_pr, set by the *mean*
// current) and the source follower (rate b = 2 pi f_sf), two first-order low-passes in
// series: a linear stochastic system, an Ornstein-Uhlenbeck process in (n_z, n_y),
//
//   d n_z = -a n_z dt + a sqrt(D) dW,      d n_y = b (n_z - n_y) dt.
//
// Over an interval T its exact update is n(T) = Phi(T) n(0) + w, w ~ N(0, Q(T)), with Phi and
// Q in closed form below, so the statistics of the samples do not depend on the sampling.
// Between two samples the comparator could also be tripped by an excursion that the straight
// line between the samples does not show; the probability is that of a Brownian bridge with
// the same conditional variance at the interval's middle crossing the level (closed form,
// bridge_crossing_probability), and its time is drawn from the bridge's first-passage law.
// With one filter only (no pole, or no source follower) the system is the 1-D OU process of
// that filter.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>

#include "config.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

/// (1 - exp(-x)) / x, stable for small x, 1 at x = 0.
inline double one_minus_exp_over(double x) { return std::fabs(x) > 1e-12 ? -std::expm1(-x) / x : 1.0 - 0.5 * x; }

/// What one interval T of the noise process needs, for one (mean current, T).
struct NoiseCoeffs {
    // Transition Phi(T) of (n_z, n_y): n_z' = phi_zz n_z, n_y' = phi_yz n_z + phi_yy n_y.
    double phi_zz = 0, phi_yz = 0, phi_yy = 0;
    // Lower Cholesky factor of the innovation covariance Q(T): w_z = l_zz g1,
    // w_y = l_yz g1 + l_yy g2 with g1, g2 independent standard normals.
    double l_zz = 0, l_yz = 0, l_yy = 0;
    /// Variance of n_y at the interval's middle given the whole state at both ends.
    double bridge_var = 0;
    /// Q(T)'s yy entry, the innovation variance of n_y over T (two poles only; else 0): above
    /// bridge_var (bridge_var_bounded()), so a pixel can be found quiet before bridge_var is known.
    double q_yy = 0;
};

/// What noise_coeffs_interval() and noise_coeffs_bridge() compute from the source follower's rate b and the interval T alone:
/// the same for every pixel, so a NoiseCache keeps it per T and the coefficients of a new
/// photon rate cost the pole's terms only (with the default single low-pass, no exp at all).
/// Each value is the expression those and ou2_covariance() would evaluate: the same bits.
struct SfTerms {
    double b = -1.0, T = -1.0;
    double exp_bT = 0, exp_bh = 0;      ///< exp(-b T), exp(-b (T / 2))
    double ome_2bT = 0, ome_2bh = 0;    ///< one_minus_exp_over(2 b T), (2 b (T / 2))
    double ome_bT = 0, exp_half_bT = 0; ///< the single low-pass's: one_minus_exp_over(b T), exp(-0.5 b T)
};
inline SfTerms sf_terms(double b, double T) {
    SfTerms s;
    s.b = b;
    s.T = T;
    const double h = 0.5 * T;
    s.exp_bT = std::exp(-b * T);
    s.exp_bh = std::exp(-b * h);
    s.ome_2bT = one_minus_exp_over(2 * b * T);
    s.ome_2bh = one_minus_exp_over(2 * b * h);
    s.ome_bT = one_minus_exp_over(b * T);
    s.exp_half_bT = std::exp(-0.5 * b * T);
    return s;
}

/// The photoreceptor pole's own terms at (a, T), when the caller has computed them already
/// (PixelModel's noise-free chain: exp(-a T) and one_minus_exp_over(a T)). noise_coeffs_interval()
/// needs the same two values: exp(-a T) is Phi's phi_zz, and one_minus_exp_over(2 a (T / 2))
/// is one_minus_exp_over(a T) bit for bit (2 a and T / 2 are exact, so is their product's
/// rounding the same as a T's). Used only where a is the caller's a (not moved off b).
struct PoleTerms {
    double a = -1.0, T = -1.0;
    double exp_aT = 0, ome_aT = 0;  ///< exp(-a T), one_minus_exp_over(a T)
};

/// ou2_covariance()'s integrals over T: int_0^T e^{-2as}, e^{-(a+b)s} and e^{-2bs} ds, its
/// libm calls (ou2_covariance_of() makes Q of them). ome_2bT, ome_2aT as in ou2_covariance().
struct Ou2Integrals {
    double h2a = 0, hab = 0, h2b = 0;
};
inline Ou2Integrals ou2_integrals(double a, double b, double T,
                                  double ome_2bT = std::numeric_limits<double>::quiet_NaN(),
                                  double ome_2aT = std::numeric_limits<double>::quiet_NaN()) {
    Ou2Integrals h;
    h.h2a = T * (ome_2aT == ome_2aT ? ome_2aT : one_minus_exp_over(2 * a * T));  // int e^{-2as}
    h.hab = T * one_minus_exp_over((a + b) * T);    // int e^{-(a+b)s}
    h.h2b = T * (ome_2bT == ome_2bT ? ome_2bT : one_minus_exp_over(2 * b * T));  // int e^{-2bs}
    return h;
}
/// The innovation covariance (zz, zy, yy) of the two-pole system from its integrals h over T.
inline void ou2_covariance_of(const Ou2Integrals& h, double a, double b, double D, double& qzz, double& qzy,
                              double& qyy) {
    // v(s) = Phi(s) e_z = (e^{-as}, b (e^{-as} - e^{-bs}) / (b - a)); Q = D a^2 int_0^T v v^T.
    const double c = b / (b - a);
    const double g = D * a * a;
    qzz = g * h.h2a;
    qzy = g * c * (h.h2a - h.hab);
    qyy = g * c * c * (h.h2a - 2 * h.hab + h.h2b);
}
/// The innovation covariance of the two-pole system over T: (zz, zy, yy). a, b > 0.
/// ome_2bT: one_minus_exp_over(2 b T) if the caller has it (SfTerms), else NaN; ome_2aT the same
/// for one_minus_exp_over(2 a T).
inline void ou2_covariance(double a, double b, double D, double T, double& qzz, double& qzy, double& qyy,
                           double ome_2bT = std::numeric_limits<double>::quiet_NaN(),
                           double ome_2aT = std::numeric_limits<double>::quiet_NaN()) {
    ou2_covariance_of(ou2_integrals(a, b, T, ome_2bT, ome_2aT), a, b, D, qzz, qzy, qyy);
}

/// How much of n_z reaches n_y over T: b (e^{-aT} - e^{-bT}) / (b - a), exp_aT = e^{-aT}.
/// Written from the slower rate's decay, so that no factor overflows: with a faster pole
/// (a > b) the other form, b T e^{-aT} (e^{(a-b)T} - 1) / ((a-b)T), is 0 x inf = NaN once
/// (a - b) T passes 709 (a bright pixel's pole at 20 Hz pre-roll sampling: every pixel over
/// ~4 pA, for good).
inline double cross_gain(double a, double b, double T, double exp_aT) {
    if (a <= b) return b * T * exp_aT * one_minus_exp_over((b - a) * T);
    return b * T * std::exp(-b * T) * one_minus_exp_over((a - b) * T);
}

namespace detail {
/// The pole's rate as the two-pole closed form uses it: equal rates make it 0/0, so a pole
/// within 1e-4 of b is moved by 1e-4 (far below what the bias currents are known to), which
/// keeps every cancellation above 1e-8 relative.
inline double separated_pole_rate(double a, double b) { return std::fabs(b - a) < 1e-4 * (a + b) ? b * (1.0 - 2e-4) : a; }
}  // namespace detail

/// Whether, for two poles at rates a, b > 0 over T, the computed bridge_var is known to lie
/// below twice the computed q_yy. In exact arithmetic bridge_var <= q_yy always: conditioning
/// on the far end only lowers a variance, so bridge_var <= Q(T / 2)_yy, and Q(t) = Sigma -
/// Phi(t) Sigma Phi(t)^T grows with t (its derivative is Phi G G^T Phi^T >= 0). In floating
/// point the closed forms cancel where a T or b T is tiny or a is near b; on a grid of a, b
/// from 1e-6 to 1e8 /s and T from 1e-9 to 10 s (tests/cpp), the computed ratio stays <= 1
/// wherever this holds, and reaches 1.2, or q_yy <= 0 < bridge_var, outside it.
inline bool bridge_var_bounded(double a, double b, double T) {
    return a > 0.0 && b > 0.0 && std::min(a, b) * T >= 1e-6 && std::fabs(b - a) >= 1e-3 * (a + b);
}

/// noise_coeffs_interval() in two stages, for a caller that makes the coefficients of many
/// rates at once (PixelModel::fill_noise_caches): noise_interval_begin(), the libm calls (and
/// the whole of the one low-pass), then noise_interval_end(), the two-pole covariance's
/// arithmetic and its Cholesky factor, a chain of two square roots and three divisions that
/// waits on the calls. Over many rates, the first stage of all and then the second of all let
/// successive rates' chains overlap. What the first stage leaves to the second:
struct NoiseIntervalStage {
    Ou2Integrals h;          ///< ou2_covariance()'s integrals over T
    double a = 0;            ///< the pole's rate as the closed form takes it (separated_pole_rate)
    bool two_poles = false;  ///< false: nothing left to do
};
inline void noise_interval_begin(NoiseCoeffs& k, NoiseIntervalStage& stage, double a, double b, double D, double T,
                                 const SfTerms* sf = nullptr, const PoleTerms* pole = nullptr) {
    k = NoiseCoeffs{};
    const bool kept = sf != nullptr && sf->b == b && sf->T == T;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    stage.two_poles = a > 0 && b > 0;
    if (stage.two_poles) {
        a = detail::separated_pole_rate(a, b);
        const bool pole_kept = pole != nullptr && pole->a == a && pole->T == T;
        k.phi_zz = pole_kept ? pole->exp_aT : std::exp(-a * T);
        k.phi_yy = kept ? sf->exp_bT : std::exp(-b * T);
        k.phi_yz = cross_gain(a, b, T, k.phi_zz);
        stage.h = ou2_integrals(a, b, T, kept ? sf->ome_2bT : nan);
        stage.a = a;
    } else {
        const double r = a > 0 ? a : b;  // one low-pass: a 1-D OU process of rate r
        const bool sf_only = kept && !(a > 0);  // r is b: its terms are kept
        k.phi_yy = sf_only ? sf->exp_bT : std::exp(-r * T);
        k.l_yy = std::sqrt(D * r * r * T * (sf_only ? sf->ome_2bT : one_minus_exp_over(2 * r * T)));
        const double qh = D * r * r * 0.5 * T * (sf_only ? sf->ome_bT : one_minus_exp_over(r * T));
        const double ph = sf_only ? sf->exp_half_bT : std::exp(-0.5 * r * T);
        k.bridge_var = qh / (1.0 + ph * ph);
    }
}
/// The two-pole system's innovation covariance Q(T) (zz, zy, yy), as noise_interval_end() makes it.
struct Ou2Covariance {
    double zz = 0, zy = 0, yy = 0;
};
/// noise_coeffs_interval()'s second stage (noise_interval_begin()'s k and stage; b, D as there).
/// q: where to keep Q(T) itself (two poles only), for a caller that needs it beside its factor.
inline void noise_interval_end(NoiseCoeffs& k, const NoiseIntervalStage& stage, double b, double D,
                               Ou2Covariance* q = nullptr) {
    if (!stage.two_poles) return;
    double qzz, qzy, qyy;
    ou2_covariance_of(stage.h, stage.a, b, D, qzz, qzy, qyy);
    if (q) *q = {qzz, qzy, qyy};
    if (qzz > 0) {
        k.l_zz = std::sqrt(qzz);
        k.l_yz = qzy / k.l_zz;
        k.l_yy = std::sqrt(std::max(0.0, qyy - k.l_yz * k.l_yz));
    }
    k.q_yy = qyy;
}

/// Exact coefficients of the noise over an interval T, all but the two-pole system's
/// bridge_var (noise_coeffs_bridge() adds it).
///   pole_rate_per_s: a = 2 pi f_pr (0 = no photoreceptor pole)
///   sf_rate_per_s:   b = 2 pi f_sf (0 = no source follower)
///   D: white-noise intensity of ln I [1/s]. At least one of a, b must be > 0.
///   sf: sf_terms(b, T), if the caller keeps them (the same coefficients, faster).
///   pole: PoleTerms at (a, T), if the caller has them (the same coefficients, faster).
inline NoiseCoeffs noise_coeffs_interval(double a, double b, double D, double T, const SfTerms* sf = nullptr,
                                         const PoleTerms* pole = nullptr) {
    NoiseCoeffs k;
    NoiseIntervalStage stage;
    noise_interval_begin(k, stage, a, b, D, T, sf, pole);
    noise_interval_end(k, stage, b, D);
    return k;
}

namespace detail {
/// The two-pole system's variance of n_y at an interval's middle given the whole state at both
/// ends, from the half interval's transition (pzz, pyz, pyy) and innovation covariance (hzz,
/// hzy, hyy): Cov(mid | ends) = Qh - Qh Ph^T (Ph Qh Ph^T + Qh)^-1 Ph Qh. Into `out` where that
/// system is not singular (returns whether it was not).
inline bool bridge_var_from_halves(double pzz, double pyz, double pyy, double hzz, double hzy, double hyy,
                                   double& out) {
    // P = Ph Qh (rows of Ph times Qh): [[pzz, 0], [pyz, pyy]] [[hzz, hzy], [hzy, hyy]]
    const double Pzz = pzz * hzz, Pzy = pzz * hzy;
    const double Pyz = pyz * hzz + pyy * hzy, Pyy = pyz * hzy + pyy * hyy;
    // M = P Ph^T + Qh (symmetric)
    const double Mzz = Pzz * pzz + hzz;
    const double Mzy = Pzz * pyz + Pzy * pyy + hzy;
    const double Myy = Pyz * pyz + Pyy * pyy + hyy;
    const double det = Mzz * Myy - Mzy * Mzy;
    if (!(det > 0)) return false;
    // Cov_yy = hyy - (Qh Ph^T)_y. M^-1 (Ph Qh)_.y, and (Qh Ph^T)_y. = (P_.y)^T.
    const double iz = (Myy * Pzy - Mzy * Pyy) / det;  // (M^-1 P)_{z,y}
    const double iy = (Mzz * Pyy - Mzy * Pzy) / det;  // (M^-1 P)_{y,y}
    out = std::max(0.0, hyy - (Pzy * iz + Pyy * iy));
    return true;
}
}  // namespace detail

/// The two-pole system's bridge_var into k (noise_coeffs_interval()'s, the same a, b, D, T, sf
/// and pole); nothing to do with one low-pass. Its half interval's terms are
/// noise_coeffs_interval(a, b, D, T / 2)'s, the same expressions on the same values: a caller
/// that makes those anyway (refine_level) takes bridge_var_from_halves() from them.
inline void noise_coeffs_bridge(NoiseCoeffs& k, double a, double b, double D, double T, const SfTerms* sf = nullptr,
                                const PoleTerms* pole = nullptr) {
    if (!(a > 0 && b > 0)) return;
    a = detail::separated_pole_rate(a, b);
    const bool kept = sf != nullptr && sf->b == b && sf->T == T;
    const bool pole_kept = pole != nullptr && pole->a == a && pole->T == T;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double h = 0.5 * T;
    double hzz, hzy, hyy;
    ou2_covariance(a, b, D, h, hzz, hzy, hyy, kept ? sf->ome_2bh : nan, pole_kept ? pole->ome_aT : nan);
    const double pzz = std::exp(-a * h), pyy = kept ? sf->exp_bh : std::exp(-b * h);
    const double pyz = cross_gain(a, b, h, pzz);
    detail::bridge_var_from_halves(pzz, pyz, pyy, hzz, hzy, hyy, k.bridge_var);
}

/// Stationary covariance of (n_z, n_y): the noise a pixel has carried since long before t = 0.
inline void noise_stationary(double a, double b, double D, double& szz, double& szy, double& syy) {
    if (a > 0 && b > 0) {
        szz = 0.5 * D * a;
        szy = syy = 0.5 * D * a * b / (a + b);
    } else {
        szz = szy = 0.0;
        syy = 0.5 * D * (a > 0 ? a : b);
    }
}

/// int_{l1}^{l0} h(l) dl [ln units / s]: the stationary noise n_y's rate h(l) of first reaching
/// a level l (its standard deviation sd > 0), integrated over the levels a slowly moving
/// threshold sweeps, for a leak cycle's survival (l1 <= l0). With x = l / sd:
/// - the slower pole, rate c = min(a, b), sets an escape rate over a high level: the inverse
///   of an OU process's mean first-passage time, sqrt(2 pi) / (c x) exp(x^2 / 2) (1 + 1 / x^2)
///   asymptotically, so h = c x phi(x) x^2 / (x^2 + 1); against the inverse of the exact mean
///   first-passage time from the mean, +4 % at x = 2.7 to 3, -10 % at x = 2 (checked by
///   quadrature); its integral is closed-form with E1 (A&S 5.1.56);
/// - with two poles n_y is differentiable and Rice's up-crossing rate
///   sqrt(a b) / (2 pi) exp(-x^2 / 2) = k phi(x), k = sqrt(a b / (2 pi)), bounds the first
///   crossings; where it is the smaller (x > k / c) it is used;
/// - below x = 1.5 the asymptotic forms fail; h is held at c / T(1.5) = 0.2167 c (T the
///   exact mean first-passage time from the mean): there the crossing comes within a few
///   1 / c, far shorter than a leak cycle, either way.
/// Used only to start a pixel at its steady-state leak phase (PixelModel::init_state).
///
/// LeakNoiseHazard(sd, a, b)(l1, l0) is the integral; the object keeps what depends on the
/// noise alone (the rates c and k, the held rate, the crossover), worked out once for
/// init_state's rejection loop, which asks for up to 64 pairs of levels a pixel: the same
/// expressions on the same values as when they were worked out per call, so the same bits.
/// Where both levels lie in the held part (l0 <= 1.5 sd: most of an event-heavy pixel's
/// attempts) no libm call is left.
class LeakNoiseHazard {
public:
    LeakNoiseHazard(double sd, double a, double b) : sd_(sd) {
        const bool two = a > 0.0 && b > 0.0;
        c_ = two ? std::min(a, b) : (a > 0.0 ? a : b);
        k_ = two ? std::sqrt(a * b) * INV_SQRT_2PI : std::numeric_limits<double>::infinity();
        held_ = std::min(k_ * phi(X_HELD), H_HELD * c_);
        cross_ = std::max(k_ / c_, X_HELD);
    }
    double operator()(double l1, double l0) const {
        const double sd = sd_, c = c_, k = k_;
        if (!(l0 > l1) || !(sd > 0.0)) return 0.0;
        const double x0 = l0 / sd, x1 = l1 / sd;
        double integral = 0.0;  // int h dx
        if (x1 < X_HELD) integral += (std::min(x0, X_HELD) - x1) * held_;
        const double lo = std::max(x1, X_HELD), hi = x0, cross = cross_;
        if (hi > lo) {
            const double esc_hi = std::min(hi, cross);  // escape-rate part, [lo, min(hi, k / c)]
            if (esc_hi > lo) integral += c * (escape(esc_hi) - escape(lo));
            const double rice_lo = std::max(lo, cross);  // Rice part, [max(lo, k / c), hi]
            if (hi > rice_lo) integral += k * (Phi(hi) - Phi(rice_lo));
        }
        return sd * integral;
    }

private:
    static constexpr double INV_SQRT2 = 0.70710678118654752440, INV_SQRT_2PI = 0.39894228040143267794;
    static constexpr double X_HELD = 1.5, H_HELD = 0.2167;  // c / T(1.5) in units of c
    static double phi(double x) { return INV_SQRT_2PI * std::exp(-0.5 * x * x); }
    static double Phi(double x) { return 0.5 * std::erfc(-x * INV_SQRT2); }
    // Antiderivative of x phi(x) x^2 / (x^2 + 1): -phi(x) (1 - R(w) / (x^2 + 1)), w = (x^2 + 1) / 2,
    // R(w) = w e^w E1(w) by Abramowitz & Stegun 5.1.56 (w >= 1, error < 5e-5).
    static double escape(double x) {
        const double w = 0.5 * (x * x + 1.0);
        const double r = (w * w + 2.334733 * w + 0.250621) / (w * w + 3.330657 * w + 1.681534);
        return -phi(x) * (1.0 - r / (x * x + 1.0));
    }
    double sd_, c_, k_, held_, cross_;
};

/// The exponent e of bridge_crossing_probability() = exp(-e): 2 u0 u1 / (sigma^2 T) with
/// sigma^2 T = 4 mid_var.
EVSTWIN_ALWAYS_INLINE double bridge_exponent(double u0, double u1, double mid_var) {
    return u0 * u1 / (2.0 * mid_var);
}

/// Probability that a Brownian bridge whose distance to a level is u0 > 0 and u1 > 0 at the
/// ends of an interval, with variance `mid_var` at the middle, touches the level in between:
/// exp(-bridge_exponent).
inline double bridge_crossing_probability(double u0, double u1, double mid_var) {
    if (!(mid_var > 0.0)) return 0.0;
    const double e = bridge_exponent(u0, u1, mid_var);
    // Below exp(-40) = 4e-18 a crossing would not happen once in 1e17 pixel-samples (a year of
    // a megapixel sensor at 1 kHz): 0 saves the exp for the pixels far from both levels.
    return e > 40.0 ? 0.0 : std::exp(-e);
}

namespace detail {
/// `take ? a : b` by a mask on the bits, without a branch (which the compiler emits for a
/// plain conditional where one side has a division it can sink into it).
inline double select(bool take, double a, double b) {
    std::uint64_t ia, ib;
    std::memcpy(&ia, &a, sizeof ia);
    std::memcpy(&ib, &b, sizeof ib);
    const std::uint64_t mask = std::uint64_t{0} - static_cast<std::uint64_t>(take);
    const std::uint64_t r = (ia & mask) | (ib & ~mask);
    double out;
    std::memcpy(&out, &r, sizeof out);
    return out;
}

/// ln Phi(x) of the standard normal CDF, accurate in the far lower tail.
inline double log_normal_cdf(double x) {
    if (x > -8.0) return std::log(0.5 * std::erfc(-x / std::sqrt(2.0)));
    const double x2 = x * x;  // Mills ratio series
    return -0.5 * x2 - std::log(-x) - 0.91893853320467274178 + std::log1p(-1.0 / x2 + 3.0 / (x2 * x2));
}
}  // namespace detail

/// The time, in [0, T], at which a Brownian bridge from distance u0 to u1 (both > 0) over T
/// with variance rate sigma2 first touches the level, given that it does; q in (0, 1) picks
/// the quantile of that conditional first-passage law. P(hit by s) is
///   Phi(-m/sqrt v) + exp(-k m + k^2 v / 2) Phi((m - k v)/sqrt v),
/// with m, v the bridge's mean and variance at s and k = 2 u0 / (sigma2 s); it is inverted by
/// bisection (resolution T / 2^32: 1 fs at 4 ms samples).
inline double bridge_first_passage(double u0, double u1, double sigma2, double T, double q) {
    auto cdf = [&](double s) {
        if (s <= 0.0) return 0.0;
        if (s >= T) return std::exp(-2.0 * u0 * u1 / (sigma2 * T));
        const double m = u0 + (u1 - u0) * s / T;
        const double v = sigma2 * s * (T - s) / T;
        const double sd = std::sqrt(v);
        const double k = 2.0 * u0 / (sigma2 * s);
        const double first = 0.5 * std::erfc(m / (sd * std::sqrt(2.0)));
        const double second = std::exp(-k * m + 0.5 * k * k * v + detail::log_normal_cdf((m - k * v) / sd));
        return first + second;
    };
    const double target = q * cdf(T);
    double lo = 0.0, hi = T;
    for (int i = 0; i < 32; ++i) {
        const double mid = 0.5 * (lo + hi);
        if (cdf(mid) < target)
            lo = mid;
        else
            hi = mid;
    }
    return 0.5 * (lo + hi);
}

/// A draw from the law bridge_first_passage inverts, from a standard normal g and a uniform u
/// in (0, 1): no search, a square root and a few divisions (the event path's cost).
/// Exact: given that it touches the level, the bridge from u0 to u1 touches it first at the
/// time the bridge from u0 to -u1 does (reflect the path after the touch: same density). The
/// time change r = s T / (T - s) turns that bridge into a Brownian motion of variance rate
/// sigma2 with drift -u1 / T started at u0, whose first touch of 0 is inverse Gaussian with
/// mean mu = u0 T / u1 and shape lambda = u0^2 / sigma2; it is drawn by Michael, Schucany and
/// Haas's method ("Generating random variates using transformations with multiple roots",
/// Am. Stat. 30, 1976) and mapped back by s = r T / (T + r).
inline double bridge_first_passage_sample(double u0, double u1, double sigma2, double T, double g, double u) {
    const double m = u1 / (u0 * T);                     // 1 / mu (0 when u1 = 0: a Levy law)
    const double c = g * g * sigma2 / (2.0 * u0 * u0);  // g^2 / (2 lambda)
    // MSH's smaller root mu (1 + w - sqrt(w (2 + w))), w = mu g^2 / (2 lambda), written as
    // 1 / (1/mu + c + sqrt(c (2/mu + c))): no cancellation, and finite as mu -> infinity.
    const double x = 1.0 / (m + c + std::sqrt(c * (2.0 * m + c)));
    // The root x with probability mu / (mu + x), else the other one, mu^2 / x: both computed
    // and one picked, as a coin toss makes a branch on it mispredict often.
    const double other = 1.0 / (m * m * x);
    const double r = detail::select(u * (1.0 + x * m) <= 1.0, x, other);
    return T / (1.0 + T / r);  // r T / (T + r), and T when r is infinite
}

}  // namespace evstwin
EVSTWIN_FP_STRICT_END
