// The block kernels' small vectorised passes, compiled per SIMD level and chosen at run time
// (at_simd_level, simd.hpp): listing flagged pixels, the bridge's bracketed
// probabilities and decisions, and the bookkeeping of a block's random words.
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

#include "../config.hpp"
#include "../noise.hpp"
#include "../rng.hpp"
#include "../simd.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

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
/// caller then takes the exact probability). Without branches, so it vectorises: one body at
/// every level (at_simd_level, simd.hpp).
struct BridgeBracket {
    template <class Level>
    static EVSTWIN_ALWAYS_INLINE void run(Level, const double* __restrict e_on, const double* __restrict e_off,
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
};

/// The bridge stage's decision for a uniform u: whether u < p_on + p_off, p = exp(-e) of the
/// exponents (0 above 40, as bridge_crossing_probability), given q, their sum's bracket from
/// BridgeBracket (-1: exponents the bracket does not cover). Decided on q where u lies
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

/// list_flagged()'s kernel: list_flagged_body at the baseline and AVX2, at AVX-512 16 flags at
/// a time become a 16-bit mask (vptestm), their indices are compressed to the front of a
/// vector (vpcompressd) and stored under a mask of the count's length, so no branch depends on
/// the flags (list_flagged_body's loop over a word's bits ends at a branch mispredicted about
/// once a word: perf had the two listings at ~9 % of continuous 260). The last n % 16 (n % 64
/// for bytes) flags as in the plain list. Same list. (The intrinsics: LanesAvx512, simd.hpp.)
struct ListFlagged {
    template <class Level, class Flag>
    static EVSTWIN_ALWAYS_INLINE std::size_t run(Level, const Flag* flag, std::size_t n, std::uint32_t* list) {
        return list_flagged_body(flag, n, list);
    }
#if EVSTWIN_MULTIVERSION
    template <class Flag>
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE std::size_t run(SimdAvx512, const Flag* flag, std::size_t n,
                                                                       std::uint32_t* list) {
        constexpr std::size_t chunk = sizeof(Flag) == 1 ? 64 : 16;  // LanesAvx512::nonzero's flags
        std::size_t m = 0, i = 0;
        for (; i + chunk <= n; i += chunk) {
            const std::uint64_t k = LanesAvx512::nonzero(flag + i);
            for (unsigned part = 0; part < chunk / 16; ++part) {
                const unsigned k16 = static_cast<unsigned>(k >> (16u * part)) & 0xFFFFu;
                m += LanesAvx512::list_sixteen(k16, i + 16u * part, list + m);
            }
        }
        for (; i < n; ++i)
            if (flag[i]) list[m++] = static_cast<std::uint32_t>(i);
        return m;
    }
#endif
};

/// BridgeBracket at the current SIMD level.
inline void bridge_bracket(const double* e_on, const double* e_off, std::size_t m, double* q) {
    at_simd_level<BridgeBracket>(e_on, e_off, m, q);
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
struct SampleWordsOff {
    template <class Level>
    static EVSTWIN_ALWAYS_INLINE std::uint64_t run(Level, const std::uint64_t* __restrict kept_for,
                                                   const std::uint64_t* __restrict sample, std::uint64_t step,
                                                   std::size_t n) {
        std::uint64_t off = 0;
        for (std::size_t j = 0; j < n; ++j) {
            const std::uint64_t now = sample[j] + step;
            off |= (kept_for[j] ^ now) | (~now & 1u);
        }
        return off;
    }
};
struct EvenCounters {
    template <class Level>
    static EVSTWIN_ALWAYS_INLINE std::uint64_t run(Level, const std::uint64_t* __restrict sample, std::uint64_t step,
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
};
struct KeepForNext {
    template <class Level>
    static EVSTWIN_ALWAYS_INLINE void run(Level, const std::uint64_t* __restrict sample, std::uint64_t step,
                                          std::size_t n, std::uint64_t* __restrict kept_for) {
        for (std::size_t j = 0; j < n; ++j) kept_for[j] = (sample[j] + step) | 1u;
    }
};
inline std::uint64_t sample_words_off(const std::uint64_t* kept_for, const std::uint64_t* sample, std::uint64_t step,
                                      std::size_t n) {
    return at_simd_level<SampleWordsOff>(kept_for, sample, step, n);
}
inline std::uint64_t even_counters(const std::uint64_t* sample, std::uint64_t step, const std::uint32_t* ids,
                                   std::size_t n, std::uint32_t* c0, std::uint32_t* c1, std::uint32_t* c2) {
    return at_simd_level<EvenCounters>(sample, step, ids, n, c0, c1, c2);
}
inline void keep_for_next(const std::uint64_t* sample, std::uint64_t step, std::size_t n, std::uint64_t* kept_for) {
    at_simd_level<KeepForNext>(sample, step, n, kept_for);
}
}  // namespace detail

/// The indices i in [0, n) with flag[i] != 0 into list, in order; returns how many: a pass
/// over the flags without branches, then one step per flagged pixel (list_flagged_body), at
/// the current SIMD level (simd.hpp). Flag: std::uint64_t (the quiet pass's verdicts) or
/// std::uint8_t (the ziggurat batch's slow flags).
template <class Flag>
inline std::size_t list_flagged(const Flag* flag, std::size_t n, std::uint32_t* list) {
    return at_simd_level<detail::ListFlagged>(flag, n, list);
}

}  // namespace evstwin

EVSTWIN_FP_STRICT_END
