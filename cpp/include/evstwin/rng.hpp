// Counter-based randomness: every random number is a pure function of
// (seed, pixel, sample index, purpose), so events do not depend on the thread count, on the
// order pixels are visited, or on how the input is cut into chunks.
//
// The generator is Philox4x32-10 (Salmon et al., "Parallel random numbers: as easy as 1, 2,
// 3", SC'11), the counter-based generator of Random123, cuRAND and NumPy. The transforms to
// uniform, normal and Poisson variates are written here rather than taken from <random>,
// whose distributions differ between standard libraries.
#pragma once

#include <array>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include "config.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

using Philox4x32Counter = std::array<std::uint32_t, 4>;
using Philox4x32Key = std::array<std::uint32_t, 2>;

/// Philox4x32-10: 128 random bits from a 128-bit counter and a 64-bit key.
EVSTWIN_ALWAYS_INLINE Philox4x32Counter philox4x32(Philox4x32Counter c, Philox4x32Key k) {
    constexpr std::uint32_t M0 = 0xD2511F53u, M1 = 0xCD9E8D57u;
    constexpr std::uint32_t W0 = 0x9E3779B9u, W1 = 0xBB67AE85u;
    // Unrolled: the ten rounds' loop control was ~10 % of the noise update's instructions.
#if defined(__GNUC__)
#pragma GCC unroll 10
#endif
    for (int round = 0; round < 10; ++round) {
        const std::uint64_t p0 = static_cast<std::uint64_t>(M0) * c[0];
        const std::uint64_t p1 = static_cast<std::uint64_t>(M1) * c[2];
        const std::uint32_t hi0 = static_cast<std::uint32_t>(p0 >> 32), lo0 = static_cast<std::uint32_t>(p0);
        const std::uint32_t hi1 = static_cast<std::uint32_t>(p1 >> 32), lo1 = static_cast<std::uint32_t>(p1);
        c = {hi1 ^ c[1] ^ k[0], lo1, hi0 ^ c[3] ^ k[1], lo0};
        k[0] += W0;
        k[1] += W1;
    }
    return c;
}

/// A uniform in the open interval (0, 1) from 32 random bits: (w + 1/2) / 2^32.
inline double uniform_open(std::uint32_t w) { return (static_cast<double>(w) + 0.5) * 0x1p-32; }

/// What a random number is for: the fourth counter word. Distinct purposes never share
/// a number, so switching one noise source on or off leaves the others' draws unchanged
/// (common random numbers across a sweep).
enum Purpose : std::uint32_t {
    PURPOSE_SAMPLE = 0,            ///< per pixel-sample block: photon/dark count, shot noise
    PURPOSE_POISSON_EXTRA = 1,     ///< further uniforms of the rejection sampler (+ iteration)
    PURPOSE_BACKGROUND = 0x10000000u,     ///< eq. 12's clocks: a fresh budget after an event (+ block)
    PURPOSE_BRIDGE = 0x18000000u,         ///< a bridge crossing: whether, and its time (+ block)
    PURPOSE_INIT = 0x20000000u,           ///< a pixel's first sample: stationary noise, leak phase, hot clock
    PURPOSE_PIXEL = 0x28000000u,          ///< a pixel's fixed properties: rate spreads, hot or not
    PURPOSE_HOT = 0x30000000u,            ///< a hot pixel's event clock (counter: its event index)
    PURPOSE_REFINE = 0x38000000u,         ///< the noise at the cuts of a refined interval (+ block)
    PURPOSE_HOT_SWITCH = 0x3C000000u,     ///< a hot pixel's telegraph (counter: its switch index)
    PURPOSE_NORMAL = 0x3E000000u,         ///< the ziggurat's further words (+ block)
    PURPOSE_PAPER_DARK = 0x40000000u,     ///< eq. 4 dark draw (+ iteration)
    PURPOSE_MISMATCH_ON = 0x80000000u,    ///< per pixel ON threshold mismatch (+ retry)
    PURPOSE_MISMATCH_OFF = 0xC0000000u,   ///< per pixel OFF threshold mismatch (+ retry)
};

/// The random numbers of one (seed, pixel, sample) with a given purpose base: a lazily
/// refilled sequence of 32-bit words, four per Philox call.
class CounterStream {
public:
    CounterStream(Philox4x32Key key, std::uint32_t pixel, std::uint64_t sample, std::uint32_t purpose)
        : key_(key), pixel_(pixel), sample_(sample), purpose_(purpose) {}

    double uniform() {
        if (used_ == 4) refill();
        return uniform_open(buf_[used_++]);
    }
    /// The next 32 random bits.
    std::uint32_t word() {
        if (used_ == 4) refill();
        return buf_[used_++];
    }

private:
    void refill() {
        buf_ = philox4x32({static_cast<std::uint32_t>(sample_), static_cast<std::uint32_t>(sample_ >> 32),
                           pixel_, purpose_ + block_++},
                          key_);
        used_ = 0;
    }
    Philox4x32Key key_;
    std::uint32_t pixel_;
    std::uint64_t sample_;
    std::uint32_t purpose_;
    std::uint32_t block_ = 0;
    Philox4x32Counter buf_{};
    int used_ = 4;
};

inline Philox4x32Key key_from_seed(std::uint64_t seed) {
    return {static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32)};
}

/// Standard normal from two uniforms in (0, 1) (Box-Muller, first output).
inline double normal_from_uniforms(double u1, double u2) {
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * 3.14159265358979323846 * u2);
}

namespace detail {
/// exp(-e) for 0 <= e <= 40 within a relative 1e-8 (tests/cpp checks it against std::exp):
/// 2^k e^r with k the nearest integer to -e log2(e) and |r| <= ln(2) / 2, e^r by its Taylor
/// series to r^7 (remainder below e^0.35 0.35^8 / 8! = 7.3e-9), 2^k put in the exponent bits.
/// No library call, no table, no branch: k is rounded by adding and subtracting 1.5 * 2^52
/// (the sum's low bits then hold k), so a loop of these vectorises at every instruction set
/// (a std::floor would be a library call on SSE2). Only a bracket for decisions (the
/// ziggurat's wedge test, pixel.hpp's bridge stage and bridge_fires), never a value of the
/// model. The shift needs the sum rounded to a double: -ffast-math folds (t + R) - R to t and
/// x87 arithmetic keeps the sum in 80 bits, either of which puts the bracket up to 41 % off,
/// past the decisions' 1e-6 band; those builds round with std::floor instead.
EVSTWIN_ALWAYS_INLINE double exp_neg_bracket(double e) {
    const double t = -e * 1.4426950408889634;  // log2(e); |t| < 58
#if defined(__FAST_MATH__) || (defined(FLT_EVAL_METHOD) && FLT_EVAL_METHOD != 0)
    const double k = std::floor(t + 0.5);
    std::uint64_t bits = static_cast<std::uint64_t>(static_cast<std::int64_t>(k) + 1023) << 52;
#else
    constexpr double ROUND = 6755399441055744.0;  // 1.5 * 2^52: t + ROUND rounds t to an integer
    const double shifted = t + ROUND;
    const double k = shifted - ROUND;
    std::uint64_t bits;
    std::memcpy(&bits, &shifted, sizeof bits);  // ROUND's bits + k (two's complement)
    bits = (bits - 0x4338000000000000ull + 1023u) << 52;
#endif
    const double r = (t - k) * 0.6931471805599453;
    double p = 1.0 / 5040.0;
    p = p * r + 1.0 / 720.0;
    p = p * r + 1.0 / 120.0;
    p = p * r + 1.0 / 24.0;
    p = p * r + 1.0 / 6.0;
    p = p * r + 0.5;
    p = p * r + 1.0;
    p = p * r + 1.0;
    double two_k;
    std::memcpy(&two_k, &bits, sizeof two_k);
    return p * two_k;
}
}  // namespace detail

/// The ziggurat's tables (Marsaglia & Tsang, "The ziggurat method for generating random
/// variables", J. Stat. Softw. 5(8), 2000: 128 layers, tail at r = 3.442619855899), for a
/// magnitude of 24 bits. Built once with std::exp / std::log; a pure function of nothing.
struct ZigguratTables {
    static constexpr double R = 3.442619855899;
    double w[128];         ///< layer i's right edge / 2^24
    std::uint32_t k[128];  ///< magnitudes below k[i] lie inside layer i's rectangle: accepted at once
    double f[128];         ///< the density exp(-x^2 / 2) at layer i's right edge
};
inline ZigguratTables make_ziggurat_tables() {
    ZigguratTables z{};
    const double m = 16777216.0;  // 2^24
    const double v = 9.91256303526217e-3;  // the area of each layer
    double dn = ZigguratTables::R, tn = dn;
    const double q = v / std::exp(-0.5 * dn * dn);
    z.k[0] = static_cast<std::uint32_t>((dn / q) * m);
    z.k[1] = 0;
    z.w[0] = q / m;
    z.w[127] = dn / m;
    z.f[0] = 1.0;
    z.f[127] = std::exp(-0.5 * dn * dn);
    for (int i = 126; i >= 1; --i) {
        dn = std::sqrt(-2.0 * std::log(v / dn + std::exp(-0.5 * dn * dn)));
        z.k[i + 1] = static_cast<std::uint32_t>((dn / tn) * m);
        tn = dn;
        z.f[i] = std::exp(-0.5 * dn * dn);
        z.w[i] = dn / m;
    }
    return z;
}
/// Built at start-up (a namespace-scope variable: no guard on every read, as a function's
/// static would have).
inline const ZigguratTables ZIGGURAT = make_ziggurat_tables();

/// normal_ziggurat's rare path: a wedge, or the tail beyond r (Marsaglia's exponential method);
/// further words from more(). Kept out of line so the common path stays a few instructions.
/// q_first: exp_neg_bracket(0.5 x^2) for w's magnitude x (the first wedge test's bracket) if
/// the caller computed it (batch_sample_normals does, for many normals at once), else < 0.
template <class More>
EVSTWIN_NOINLINE double normal_ziggurat_slow(std::uint32_t w, More& more, double q_first = -1.0) {
    const ZigguratTables& z = ZIGGURAT;
    for (;;) {
        const std::uint32_t i = w & 127u, j = w >> 8;
        const double sign = (w & 128u) ? -1.0 : 1.0;
        const double x = static_cast<double>(j) * z.w[i];
        if (j < z.k[i]) return sign * x;
        if (i == 0) {
            double xt, yt;
            do {
                xt = -std::log(uniform_open(more())) / ZigguratTables::R;
                yt = -std::log(uniform_open(more()));
            } while (yt + yt < xt * xt);
            return sign * (ZigguratTables::R + xt);
        }
        // The wedge: accept below the density. Decided on exp_neg_bracket (x < r here, so its
        // argument is below 6) where the two sides lie farther apart than a relative 1e-6 (its
        // error is below 1e-8): the library exp only for the rare word that lies that close, and
        // the same decision as `lhs < std::exp(-0.5 * x * x)` for every word.
        const double lhs = z.f[i] + uniform_open(more()) * (z.f[i - 1] - z.f[i]);
        const double q = q_first >= 0.0 ? q_first : detail::exp_neg_bracket(0.5 * x * x);
        q_first = -1.0;  // a further word's x is another
        const bool accept = lhs < q * (1.0 - 1e-6) ? true
                            : lhs > q * (1.0 + 1e-6) ? false
                                                     : lhs < std::exp(-0.5 * x * x);
        if (accept) return sign * x;
        w = more();
    }
}

/// normal_ziggurat's common path: whether word w is accepted at once, and then its normal in g
/// (else normal_ziggurat_slow() finishes it, with further words).
EVSTWIN_ALWAYS_INLINE bool normal_ziggurat_common(std::uint32_t w, double& g) {
    const std::uint32_t i = w & 127u, j = w >> 8;
    const double x = static_cast<double>(j) * ZIGGURAT.w[i];
    // The sign from bit 7 by arithmetic: a branch on it would be mispredicted half the time.
    g = x * (1.0 - 2.0 * static_cast<double>((w >> 7) & 1u));
    return j < ZIGGURAT.k[i];
}

/// One standard normal from a 32-bit word by the ziggurat: bits 0-6 pick the layer, bit 7 the
/// sign, bits 8-31 the magnitude; ~99 % of words are accepted with a table look-up and a
/// multiply (no log, no square root). The rest (a wedge, or the tail beyond r) draw further
/// words from `more()`, so the variate stays a pure function of its counter. Exact, tails
/// included (threshold crossings of the noise live in its tails).
template <class More>
EVSTWIN_ALWAYS_INLINE double normal_ziggurat(std::uint32_t w, More&& more) {
    double g;
    if (normal_ziggurat_common(w, g)) return g;
    return normal_ziggurat_slow(w, more);
}

/// ln(k!) for integer k >= 0: a table below 256, Stirling's series above (relative error
/// < 1e-15 there). std::lgamma is avoided because glibc's writes the global `signgam`,
/// a data race under OpenMP.
inline double log_factorial(double k) {
    static const std::vector<double> table = [] {
        std::vector<double> t(256, 0.0);
        for (int i = 2; i < 256; ++i) t[i] = t[i - 1] + std::log(static_cast<double>(i));
        return t;
    }();
    if (k < 256.0) return table[static_cast<std::size_t>(k)];
    const double n = k + 1.0, inv = 1.0 / n, inv2 = inv * inv;
    return (n - 0.5) * std::log(n) - n + 0.91893853320467274178 +
           inv * (1.0 / 12.0 - inv2 * (1.0 / 360.0 - inv2 * (1.0 / 1260.0)));
}

/// Poisson variates.
///
/// Small means (mu < POISSON_TABLE_MAX_MEAN) use inversion of the cumulative distribution;
/// the table for the last mean is kept, because on a sensor most pixels in a sample share
/// one mean (the dark or sky background), so the table is built once and searched many
/// times. The result is a pure function of (mu, u): the table is rebuilt with the same
/// arithmetic whenever mu changes. Larger means use Hormann's PTRS transformed rejection
/// ("The transformed rejection method for generating Poisson random variables", 1993),
/// the algorithm NumPy uses, with further uniforms drawn from a CounterStream.
class PoissonSampler {
public:
    static constexpr double POISSON_TABLE_MAX_MEAN = 256.0;  // 18000 e-/s over 10 ms: still a table

    /// The mean rounded to 32 significant bits (relative change below 2.4e-10). Sample
    /// times k * dt give intervals that differ in their last bits, so the background's mean
    /// would change from sample to sample and every block would rebuild its table each
    /// sample; rounded, it stays put. The rounding is part of the model (a pure function of
    /// mu), so results do not depend on which tables happen to be cached.
    static double quantised_mean(double mu) {
        std::uint64_t bits;
        std::memcpy(&bits, &mu, sizeof bits);
        bits = (bits + (std::uint64_t{1} << 20)) & ~((std::uint64_t{1} << 21) - 1);
        std::memcpy(&mu, &bits, sizeof bits);
        return mu;
    }

    /// One variate of mean mu >= 0. u is a uniform in (0, 1) used by inversion; the
    /// rejection sampler draws further uniforms from `more`, a CounterStream it builds only
    /// when needed (building one per call would cost the hot loop for nothing).
    ///
    /// The count is returned as a double: every caller turns it into a current at once, and a
    /// mean above 2^64 (1e20 photons/s over a long sample) has no integer type to hold it.
    /// Below 2^53 the double is the exact count; above, its rounding is far below the
    /// variate's spread (sqrt(mu) > 9e7).
    template <class MakeStream>
    inline double operator()(double mu, double u, MakeStream&& more) {
        if (mu <= 0.0) return 0.0;
        mu = quantised_mean(mu);
        if (mu < POISSON_TABLE_MAX_MEAN) return static_cast<double>(invert(mu, u));
        auto stream = more();
        return ptrs(mu, stream);
    }

    std::uint64_t invert(double mu, double u) {
        if (mu != table_mean_) build(mu);
        // First k with u <= F(k). The guide table (Chen and Asau's indexed search) gives the
        // first candidate for u's bucket, so the linear search takes about one step; the
        // answer is the same as a search from k = 0.
        std::size_t k = guide_[static_cast<std::size_t>(u * static_cast<double>(guide_.size()))];
        const std::size_t n = cdf_.size();
        while (k < n && cdf_[k] < u) ++k;
        return k;  // == cdf_.size() only in the tail beyond 1 - 2^-33, where F was cut.
    }

    /// invert(mu, uniform_open(w)) without leaving the integers: u = (w + 1/2) / 2^32 <= F(k)
    /// exactly when w <= floor(F(k) 2^32 - 1/2), and floor(w m / 2^32) never exceeds the
    /// bucket of u, so the guide's start is still at or below the answer. Same results.
    EVSTWIN_ALWAYS_INLINE std::uint64_t invert_word(double mu, std::uint32_t w) {
        if (mu != table_mean_) {
            // A mean seen once (a pixel in a source's PSF) is searched from k = 0 without a
            // table; a mean seen twice in a row (the background) gets one. Both walk the same
            // partial sums, so they return the same k.
            if (mu != last_miss_) {
                last_miss_ = mu;
                return invert_sequential(mu, w);
            }
            build(mu);
        }
        std::size_t k = guide_[static_cast<std::size_t>((static_cast<std::uint64_t>(w) * guide_.size()) >> 32)];
        const std::size_t n = word_cdf_.size();
        const std::int64_t wi = w;
        while (k < n && word_cdf_[k] < wi) ++k;
        return k;
    }

    /// As operator(), from a 32-bit word instead of its uniform.
    template <class MakeStream>
    EVSTWIN_ALWAYS_INLINE double from_word(double mu, std::uint32_t w, MakeStream&& more) {
        if (mu <= 0.0) return 0.0;
        mu = quantised_mean(mu);
        if (mu < POISSON_TABLE_MAX_MEAN) return static_cast<double>(invert_word(mu, w));
        auto stream = more();
        return ptrs(mu, stream);
    }

private:
    std::uint64_t invert_sequential(double mu, std::uint32_t w) const {
        const std::int64_t wi = w;
        double p = std::exp(-mu), c = p;
        std::uint64_t idx = 0;
        if (static_cast<std::int64_t>(std::floor(c * 0x1p32 - 0.5)) >= wi) return 0;
        const double cap = mu + 40.0 * std::sqrt(mu) + 40.0;
        for (double k = 1.0; c < 1.0 - 0x1p-33 && k < cap; k += 1.0) {
            p *= mu / k;
            c += p;
            ++idx;
            if (static_cast<std::int64_t>(std::floor(c * 0x1p32 - 0.5)) >= wi) return idx;
        }
        return idx + 1;
    }

    void build(double mu) {
        cdf_.clear();
        double p = std::exp(-mu), c = p;
        cdf_.push_back(c);
        const double cap = mu + 40.0 * std::sqrt(mu) + 40.0;
        for (double k = 1.0; c < 1.0 - 0x1p-33 && k < cap; k += 1.0) {
            p *= mu / k;
            c += p;
            cdf_.push_back(c);
        }
        // word_cdf_[k] = floor(F(k) 2^32 - 1/2), exact in double; -1 when no word qualifies.
        word_cdf_.resize(cdf_.size());
        for (std::size_t i = 0; i < cdf_.size(); ++i)
            word_cdf_[i] = static_cast<std::int64_t>(std::floor(cdf_[i] * 0x1p32 - 0.5));
        // guide_[j] = first k with F(k) >= j / m: no k below it can be the answer for a u in
        // bucket j, since u >= j / m there.
        const std::size_t m = cdf_.size();
        guide_.assign(m, 0);
        std::size_t k = 0;
        for (std::size_t j = 0; j < m; ++j) {
            const double level = static_cast<double>(j) / static_cast<double>(m);
            while (k < m && cdf_[k] < level) ++k;
            guide_[j] = k;
        }
        table_mean_ = mu;
    }

    template <class Stream>
    static double ptrs(double lam, Stream& more) {
        const double slam = std::sqrt(lam), loglam = std::log(lam);
        const double b = 0.931 + 2.53 * slam;
        const double a = -0.059 + 0.02483 * b;
        const double invalpha = 1.1239 + 1.1328 / (b - 3.4);
        const double vr = 0.9277 - 3.6224 / (b - 2.0);
        for (;;) {
            const double U = more.uniform() - 0.5;
            const double V = more.uniform();
            const double us = 0.5 - std::fabs(U);
            const double kd = std::floor((2.0 * a / us + b) * U + lam + 0.43);
            if (us >= 0.07 && V <= vr) return kd;
            if (kd < 0.0 || (us < 0.013 && V > us)) continue;
            if (std::log(V) + std::log(invalpha) - std::log(a / (us * us) + b) <=
                -lam + kd * loglam - log_factorial(kd))
                return kd;
        }
    }

    double table_mean_ = -1.0;
    double last_miss_ = -1.0;
    std::vector<double> cdf_;
    std::vector<std::int64_t> word_cdf_;
    std::vector<std::size_t> guide_;
};

}  // namespace evstwin
EVSTWIN_FP_STRICT_END
