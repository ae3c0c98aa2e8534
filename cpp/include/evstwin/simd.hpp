// Batched random numbers over the pixels of a block, compiled for several instruction sets
// and chosen at run time, so a portable build (SSE2 on x86-64) still uses AVX2 or AVX-512
// where the processor has them, without -march=native.
//
// What is batched: Philox4x32-10 for a list of counters (integer arithmetic: every
// instruction set gives the same bits) and the ziggurat's common path (a table look-up, a
// conversion of a 24-bit integer and one multiplication: exact or correctly rounded the same
// way on every instruction set, and nothing a compiler could contract into a fused
// multiply-add). The rare rest (a ziggurat wedge or tail) is flagged and finished by the
// scalar code. So the random numbers, and the events, are the same bit for bit at every level;
// set_simd_level() forces a level so tests can check that.
//
// Dispatch: GCC and Clang on x86-64 compile the batch loops three times (baseline, AVX2,
// AVX-512: target attributes, so the rest of the program keeps the baseline) and pick one by
// __builtin_cpu_supports; other compilers and processors get the baseline loop, which the
// compiler vectorises for whatever the build targets. One mechanism does it for every batched
// loop of the engine: at_simd_level<Kernel>(args...) below.
#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <utility>

#include "config.hpp"
#include "rng.hpp"

// x86-64 only: on 32-bit x86 the scalar code may use the x87 unit's 80-bit intermediates
// while the dispatched loops use SSE doubles, and the two would round differently.
#if (defined(__GNUC__) || defined(__clang__)) && defined(__x86_64__) && !defined(EVSTWIN_NO_MULTIVERSION)
#define EVSTWIN_MULTIVERSION 1
#define EVSTWIN_TARGET_AVX2 __attribute__((target("avx2")))
#define EVSTWIN_TARGET_AVX512 __attribute__((target("avx512f,avx512vl,avx512bw,avx512dq")))
#include <immintrin.h>
#else
#define EVSTWIN_MULTIVERSION 0
#endif

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

/// The instruction sets the batched loops are compiled for. Baseline: whatever the build
/// targets (SSE2 on a default x86-64 build).
enum class SimdLevel : int { Baseline = 0, AVX2 = 1, AVX512 = 2 };

inline const char* simd_level_name(SimdLevel l) {
    switch (l) {
        case SimdLevel::AVX2: return "avx2";
        case SimdLevel::AVX512: return "avx512";
        default: return "baseline";
    }
}

/// Whether this processor (and this build) can run the loops compiled for `l`.
inline bool simd_level_supported(SimdLevel l) {
    if (l == SimdLevel::Baseline) return true;
#if EVSTWIN_MULTIVERSION
    __builtin_cpu_init();
    if (l == SimdLevel::AVX2) return __builtin_cpu_supports("avx2");
    return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
           __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512dq");
#else
    return false;
#endif
}

/// The best level this processor supports.
inline SimdLevel best_simd_level() {
    if (simd_level_supported(SimdLevel::AVX512)) return SimdLevel::AVX512;
    if (simd_level_supported(SimdLevel::AVX2)) return SimdLevel::AVX2;
    return SimdLevel::Baseline;
}

namespace detail {
inline std::atomic<int>& simd_level_slot() {
    static std::atomic<int> level{static_cast<int>(best_simd_level())};
    return level;
}
}  // namespace detail

/// The level the batched loops use now (process-wide; the best supported one by default).
inline SimdLevel simd_level() { return static_cast<SimdLevel>(detail::simd_level_slot().load(std::memory_order_relaxed)); }

/// A SIMD level as a type, for overloading a kernel's code by level (see at_simd_level).
template <SimdLevel L>
struct SimdAt {
    static constexpr SimdLevel level = L;
};
using SimdBaseline = SimdAt<SimdLevel::Baseline>;
using SimdAvx2 = SimdAt<SimdLevel::AVX2>;
using SimdAvx512 = SimdAt<SimdLevel::AVX512>;

namespace detail {
/// Kernel::run(tag, args...) compiled for the tag's level: called from a function that carries
/// the level's target attribute, into which a run() written once (a template over the tag,
/// EVSTWIN_ALWAYS_INLINE, no attribute of its own) is inlined and so compiled for that level.
/// Where a level's vector form differs, Kernel has an overload of run() for that tag alone,
/// with the level's EVSTWIN_TARGET_* (and its intrinsics).
template <class Kernel, class... Args>
inline decltype(auto) run_at_level(SimdBaseline tag, Args&&... args) {
    return Kernel::run(tag, std::forward<Args>(args)...);
}
#if EVSTWIN_MULTIVERSION
template <class Kernel, class... Args>
EVSTWIN_TARGET_AVX2 inline decltype(auto) run_at_level(SimdAvx2 tag, Args&&... args) {
    return Kernel::run(tag, std::forward<Args>(args)...);
}
template <class Kernel, class... Args>
EVSTWIN_TARGET_AVX512 inline decltype(auto) run_at_level(SimdAvx512 tag, Args&&... args) {
    return Kernel::run(tag, std::forward<Args>(args)...);
}
#endif
}  // namespace detail

/// The one dispatch of every batched loop (here, simd/block_passes.hpp, kernels/quiet_pass.hpp):
/// Kernel::run(tag, args...) at the current level, compiled for it (detail::run_at_level).
/// A kernel is a class with a static run() whose first parameter is the level's tag, e.g.
///
///     struct Twice {
///         template <class Level>
///         static EVSTWIN_ALWAYS_INLINE void run(Level, const double* a, std::size_t n, double* b) {
///             for (std::size_t i = 0; i < n; ++i) b[i] = 2.0 * a[i];  // one body, every level
///         }
///     };
///     at_simd_level<Twice>(a, n, b);
template <class Kernel, class... Args>
inline decltype(auto) at_simd_level(Args&&... args) {
#if EVSTWIN_MULTIVERSION
    switch (simd_level()) {
        case SimdLevel::AVX512: return detail::run_at_level<Kernel>(SimdAvx512{}, std::forward<Args>(args)...);
        case SimdLevel::AVX2: return detail::run_at_level<Kernel>(SimdAvx2{}, std::forward<Args>(args)...);
        default: break;
    }
#endif
    return detail::run_at_level<Kernel>(SimdBaseline{}, std::forward<Args>(args)...);
}

/// Force a level (for tests and benchmarks: the results are the same at every level). Throws
/// std::invalid_argument for a level this processor or build cannot run.
inline void set_simd_level(SimdLevel l) {
    if (static_cast<int>(l) < 0 || static_cast<int>(l) > 2)
        throw std::invalid_argument("simd level must be baseline, avx2 or avx512; got " + std::to_string(static_cast<int>(l)));
    if (!simd_level_supported(l))
        throw std::invalid_argument(std::string("simd level ") + simd_level_name(l) +
                                    " is not supported by this processor or build");
    detail::simd_level_slot().store(static_cast<int>(l), std::memory_order_relaxed);
}

namespace detail {

/// Philox4x32-10 (rng.hpp's philox4x32) of the counters (c0[i], c1[i], c2[i], c3) for
/// i < n, into r0..r3. Scalar locals rather than std::array, so the loop vectorises.
EVSTWIN_ALWAYS_INLINE void philox_batch_body(const std::uint32_t* __restrict c0, const std::uint32_t* __restrict c1,
                                             const std::uint32_t* __restrict c2, std::uint32_t c3, Philox4x32Key key,
                                             std::size_t n, std::uint32_t* __restrict r0, std::uint32_t* __restrict r1,
                                             std::uint32_t* __restrict r2, std::uint32_t* __restrict r3) {
    constexpr std::uint32_t M0 = 0xD2511F53u, M1 = 0xCD9E8D57u;
    constexpr std::uint32_t W0 = 0x9E3779B9u, W1 = 0xBB67AE85u;
    for (std::size_t i = 0; i < n; ++i) {
        std::uint32_t x0 = c0[i], x1 = c1[i], x2 = c2[i], x3 = c3;
        std::uint32_t k0 = key[0], k1 = key[1];
#if defined(__GNUC__)
#pragma GCC unroll 10
#endif
        for (int round = 0; round < 10; ++round) {
            const std::uint64_t p0 = static_cast<std::uint64_t>(M0) * x0;
            const std::uint64_t p1 = static_cast<std::uint64_t>(M1) * x2;
            const std::uint32_t hi0 = static_cast<std::uint32_t>(p0 >> 32), lo0 = static_cast<std::uint32_t>(p0);
            const std::uint32_t hi1 = static_cast<std::uint32_t>(p1 >> 32), lo1 = static_cast<std::uint32_t>(p1);
            x0 = hi1 ^ x1 ^ k0;
            x1 = lo1;
            x2 = hi0 ^ x3 ^ k1;
            x3 = lo0;
            k0 += W0;
            k1 += W1;
        }
        r0[i] = x0;
        r1[i] = x1;
        r2[i] = x2;
        r3[i] = x3;
    }
}

/// normal_ziggurat's common path for words w[i]: g[i] the normal, slow[i] = 1 where the word
/// falls in a wedge or the tail (then g[i] is meaningless and the caller finishes it).
EVSTWIN_ALWAYS_INLINE void ziggurat_batch_body(const std::uint32_t* __restrict w, std::size_t n, double* __restrict g,
                                               std::uint8_t* __restrict slow) {
    const double* __restrict tw = ZIGGURAT.w;
    const std::uint32_t* __restrict tk = ZIGGURAT.k;
    for (std::size_t i = 0; i < n; ++i) {
        const std::uint32_t wi = w[i], layer = wi & 127u, j = wi >> 8;
        const double x = static_cast<double>(static_cast<std::int32_t>(j)) * tw[layer];  // j < 2^24: exact either way
        g[i] = x * (1.0 - 2.0 * static_cast<double>(static_cast<std::int32_t>((wi >> 7) & 1u)));
        slow[i] = static_cast<std::uint8_t>(j >= tk[layer]);
    }
}

#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
// GCC 12's AVX-512 and gather intrinsics leave an undefined vector that -Wmaybe-uninitialized
// reports (GCC bug 105593, fixed in 13).
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
#if EVSTWIN_MULTIVERSION
/// The intrinsic batches' last counters, from `from` to n (fewer than a vector), one by one.
inline void philox_batch_tail(std::size_t from, const std::uint32_t* c0, const std::uint32_t* c1,
                              const std::uint32_t* c2, std::uint32_t c3, Philox4x32Key key, std::size_t n,
                              std::uint32_t* r0, std::uint32_t* r1, std::uint32_t* r2, std::uint32_t* r3) {
    for (std::size_t i = from; i < n; ++i) {
        const Philox4x32Counter r = philox4x32({c0[i], c1[i], c2[i], c3}, key);
        r0[i] = r[0]; r1[i] = r[1]; r2[i] = r[2]; r3[i] = r[3];
    }
}
// The AVX2 and AVX-512 batches are written once (simd/lane_batches.hpp, Stim's way: the
// algorithms once, the intrinsics in a small class per instruction set, LanesAvx2 and
// LanesAvx512).
//
// Philox: each 32-bit word rides in a 64-bit lane (its upper half ignored: the multiplication
// reads the low 32 bits, the stores truncate), so each product is one 32 x 32 -> 64-bit
// multiplication (vpmuludq) and the three words of an XOR one or two instructions, with no
// permutes. From the plain loop GCC made 32-bit lanes and split even from odd ones with
// permutes for every product (AVX-512), or emulated a 64-bit multiplication with shifts and
// adds (the loop over 64-bit lanes, AVX2). Integer arithmetic: the same words as philox4x32 at
// every level. Each batch takes several vectors of counters through the ten rounds side by
// side, so one vector's multiplications fill another's latency: four at AVX2 (some of them
// spill: 16 registers, which costs instructions but not time here), two at AVX-512 (more
// gained nothing), then the rest one vector at a time; the last n % width counters are done by
// the scalar philox4x32. Figures: bench/philox_batch.cpp (the documentation's performance page).
//
// The ziggurat: gathers. From the plain loop GCC 12 looked the tables up lane by lane (an
// extract and an insert a lane), most of the batch's time (found by bench/precision_study.cpp;
// bench/draw_floor.cpp at AVX-512, before and after: 3.2-3.3 -> 2.2-2.3 ns a pixel-update, at
// the change; git history). The same operations as ziggurat_batch_body: the 24-bit magnitude
// converted exactly, one multiplication by the layer's width, the sign set by an XOR of the
// sign bit (x * (1 - 2 s) only flips it, zeros included), the slow flag from j >= k (both below
// 2^31, so a signed comparison is the unsigned one). So the same normals and flags, bit for
// bit. (Processors whose microcode slows gathers, the Gather Data Sampling mitigation, may gain
// less or lose; not measured here. The bits are the same either way.)
/// The intrinsics of the AVX2 batches. Philox: its words in the 64-bit lanes of a vector (V),
/// four counters a vector, four vectors side by side. The ziggurat: eight words a vector
/// (Words), four of them (Half) for a vector of four doubles.
struct LanesAvx2 {
    using V = __m256i;
    static constexpr std::size_t width = 4, unroll = 4;
    EVSTWIN_TARGET_AVX2 static EVSTWIN_ALWAYS_INLINE V set1(std::uint32_t v) { return _mm256_set1_epi64x(v); }
    EVSTWIN_TARGET_AVX2 static EVSTWIN_ALWAYS_INLINE V load(const std::uint32_t* p) {
        return _mm256_cvtepu32_epi64(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p)));
    }
    EVSTWIN_TARGET_AVX2 static EVSTWIN_ALWAYS_INLINE void store(std::uint32_t* p, V v) {
        _mm_storeu_si128(reinterpret_cast<__m128i*>(p),
                         _mm256_castsi256_si128(_mm256_permutevar8x32_epi32(v, _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7))));
    }
    EVSTWIN_TARGET_AVX2 static EVSTWIN_ALWAYS_INLINE V mul(V a, V b) { return _mm256_mul_epu32(a, b); }
    /// The high half of each lane of p (in the low 32 bits) ^ x ^ k.
    EVSTWIN_TARGET_AVX2 static EVSTWIN_ALWAYS_INLINE V high_xor(V p, V x, V k) {
        return _mm256_xor_si256(_mm256_xor_si256(_mm256_srli_epi64(p, 32), x), k);
    }

    using Words = __m256i;
    using Half = __m128i;
    static constexpr std::size_t words = 8;
    EVSTWIN_TARGET_AVX2 static EVSTWIN_ALWAYS_INLINE Words load_words(const std::uint32_t* p) {
        return _mm256_loadu_si256(reinterpret_cast<const __m256i*>(p));
    }
    EVSTWIN_TARGET_AVX2 static EVSTWIN_ALWAYS_INLINE Words set1_words(int v) { return _mm256_set1_epi32(v); }
    EVSTWIN_TARGET_AVX2 static EVSTWIN_ALWAYS_INLINE Words and_words(Words a, Words b) { return _mm256_and_si256(a, b); }
    template <int S>
    EVSTWIN_TARGET_AVX2 static EVSTWIN_ALWAYS_INLINE Words shift_right(Words a) { return _mm256_srli_epi32(a, S); }
    EVSTWIN_TARGET_AVX2 static EVSTWIN_ALWAYS_INLINE Words gather_words(const int* t, Words i) {
        return _mm256_i32gather_epi32(t, i, 4);
    }
    /// slow = j >= k as bytes: 1 - (k > j), eight 32-bit lanes packed to bytes.
    EVSTWIN_TARGET_AVX2 static EVSTWIN_ALWAYS_INLINE void store_slow(std::uint8_t* slow, Words j, Words k) {
        const __m256i slow32 = _mm256_add_epi32(_mm256_cmpgt_epi32(k, j), _mm256_set1_epi32(1));
        const __m128i slow16 = _mm_packus_epi32(_mm256_castsi256_si128(slow32), _mm256_extracti128_si256(slow32, 1));
        _mm_storel_epi64(reinterpret_cast<__m128i*>(slow), _mm_packus_epi16(slow16, slow16));
    }
    EVSTWIN_TARGET_AVX2 static EVSTWIN_ALWAYS_INLINE Half half(Words v, int h) {
        return h ? _mm256_extracti128_si256(v, 1) : _mm256_castsi256_si128(v);
    }
    /// g = j * tw[layer], its sign bit flipped where s = 1.
    EVSTWIN_TARGET_AVX2 static EVSTWIN_ALWAYS_INLINE void store_normals(double* g, Half j, Half layer, Half s,
                                                                        const double* tw) {
        const __m256d x = _mm256_mul_pd(_mm256_cvtepi32_pd(j), _mm256_i32gather_pd(tw, layer, 8));
        const __m256i bits = _mm256_slli_epi64(_mm256_cvtepu32_epi64(s), 63);
        _mm256_storeu_pd(g, _mm256_castsi256_pd(_mm256_xor_si256(_mm256_castpd_si256(x), bits)));
    }
};
/// The same for AVX-512: eight counters a vector, two vectors side by side; sixteen words a
/// vector. high_xor swaps the halves of each lane (vpshufd, a shuffle port) rather than
/// shifting, which shares its port with the multiplications; the upper halves then hold the low
/// halves, ignored as above. (At AVX2, with four vectors, the swap lost.) The three-way XOR is
/// one vpternlogq; the slow flags a mask. With list_flagged's, every AVX-512 intrinsic of the
/// engine is here.
struct LanesAvx512 {
    using V = __m512i;
    static constexpr std::size_t width = 8, unroll = 2;
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE V set1(std::uint32_t v) { return _mm512_set1_epi64(v); }
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE V load(const std::uint32_t* p) {
        return _mm512_cvtepu32_epi64(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(p)));
    }
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE void store(std::uint32_t* p, V v) {
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(p), _mm512_cvtepi64_epi32(v));
    }
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE V mul(V a, V b) { return _mm512_mul_epu32(a, b); }
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE V high_xor(V p, V x, V k) {
        return _mm512_ternarylogic_epi64(_mm512_shuffle_epi32(p, _MM_PERM_CDAB), x, k, 0x96);  // a ^ b ^ c
    }

    using Words = __m512i;
    using Half = __m256i;
    static constexpr std::size_t words = 16;
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE Words load_words(const std::uint32_t* p) {
        return _mm512_loadu_si512(p);
    }
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE Words set1_words(int v) { return _mm512_set1_epi32(v); }
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE Words and_words(Words a, Words b) {
        return _mm512_and_si512(a, b);
    }
    template <int S>
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE Words shift_right(Words a) { return _mm512_srli_epi32(a, S); }
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE Words gather_words(const int* t, Words i) {
        return _mm512_i32gather_epi32(i, t, 4);
    }
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE void store_slow(std::uint8_t* slow, Words j, Words k) {
        const __mmask16 s = _mm512_cmpge_epu32_mask(j, k);
        _mm_storeu_si128(reinterpret_cast<__m128i*>(slow), _mm_maskz_mov_epi8(s, _mm_set1_epi8(1)));
    }
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE Half half(Words v, int h) {
        return h ? _mm512_extracti64x4_epi64(v, 1) : _mm512_castsi512_si256(v);
    }
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE void store_normals(double* g, Half j, Half layer, Half s,
                                                                          const double* tw) {
        const __m512d x = _mm512_mul_pd(_mm512_cvtepi32_pd(j), _mm512_i32gather_pd(layer, tw, 8));
        const __m512i bits = _mm512_slli_epi64(_mm512_cvtepu32_epi64(s), 63);
        _mm512_storeu_pd(g, _mm512_castsi512_pd(_mm512_xor_si512(_mm512_castpd_si512(x), bits)));
    }

    // list_flagged's (simd/block_passes.hpp, ListFlagged).
    /// Which of the 16 flags from f are nonzero, as the bits of a mask (two vptestmq).
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE std::uint64_t nonzero(const std::uint64_t* f) {
        const __m512i a = _mm512_loadu_si512(f), b = _mm512_loadu_si512(f + 8);
        return static_cast<unsigned>(_mm512_test_epi64_mask(a, a)) |
               (static_cast<unsigned>(_mm512_test_epi64_mask(b, b)) << 8);
    }
    /// The same for the 64 flags from f (one vptestmb).
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE std::uint64_t nonzero(const std::uint8_t* f) {
        const __m512i a = _mm512_loadu_si512(f);
        return _mm512_test_epi8_mask(a, a);
    }
    /// The indices base + b of the set bits b of the 16-bit mask k, compressed into out in order
    /// (their count returned): vpcompressd and a store under a mask of the count's length.
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE unsigned list_sixteen(unsigned k, std::size_t base,
                                                                             std::uint32_t* out) {
        const __m512i idx = _mm512_add_epi32(_mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15),
                                             _mm512_set1_epi32(static_cast<int>(base)));
        const unsigned count = static_cast<unsigned>(__builtin_popcount(k));
        _mm512_mask_storeu_epi32(out, static_cast<__mmask16>((1u << count) - 1u),
                                 _mm512_maskz_compress_epi32(static_cast<__mmask16>(k), idx));
        return count;
    }
};
/// The batches over the vectors of Lanes (philox, ziggurat), defined in simd/lane_batches.hpp
/// once for each lane class.
template <class Lanes>
struct LaneBatches;
#define EVSTWIN_LANES LanesAvx2
#define EVSTWIN_LANES_TARGET EVSTWIN_TARGET_AVX2
#include "simd/lane_batches.hpp"
#undef EVSTWIN_LANES
#undef EVSTWIN_LANES_TARGET
#define EVSTWIN_LANES LanesAvx512
#define EVSTWIN_LANES_TARGET EVSTWIN_TARGET_AVX512
#include "simd/lane_batches.hpp"
#undef EVSTWIN_LANES
#undef EVSTWIN_LANES_TARGET
#endif

/// Philox4x32-10 of a list of counters (philox4x32_batch): the plain loop at the baseline,
/// LaneBatches' at AVX2 and AVX-512.
struct PhiloxBatch {
    template <class Level>
    static EVSTWIN_ALWAYS_INLINE void run(Level, const std::uint32_t* c0, const std::uint32_t* c1,
                                          const std::uint32_t* c2, std::uint32_t c3, Philox4x32Key key, std::size_t n,
                                          std::uint32_t* r0, std::uint32_t* r1, std::uint32_t* r2, std::uint32_t* r3) {
        philox_batch_body(c0, c1, c2, c3, key, n, r0, r1, r2, r3);
    }
#if EVSTWIN_MULTIVERSION
    EVSTWIN_TARGET_AVX2 static EVSTWIN_ALWAYS_INLINE void run(SimdAvx2, const std::uint32_t* c0, const std::uint32_t* c1,
                                                              const std::uint32_t* c2, std::uint32_t c3,
                                                              Philox4x32Key key, std::size_t n, std::uint32_t* r0,
                                                              std::uint32_t* r1, std::uint32_t* r2, std::uint32_t* r3) {
        LaneBatches<LanesAvx2>::philox(c0, c1, c2, c3, key, n, r0, r1, r2, r3);
    }
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE void run(SimdAvx512, const std::uint32_t* c0,
                                                                const std::uint32_t* c1, const std::uint32_t* c2,
                                                                std::uint32_t c3, Philox4x32Key key, std::size_t n,
                                                                std::uint32_t* r0, std::uint32_t* r1, std::uint32_t* r2,
                                                                std::uint32_t* r3) {
        LaneBatches<LanesAvx512>::philox(c0, c1, c2, c3, key, n, r0, r1, r2, r3);
    }
#endif
};

/// normal_ziggurat's common path for a list of words (ziggurat_batch): the plain loop at the
/// baseline, LaneBatches' (gathers) at AVX2 and AVX-512.
struct ZigguratBatch {
    template <class Level>
    static EVSTWIN_ALWAYS_INLINE void run(Level, const std::uint32_t* w, std::size_t n, double* g, std::uint8_t* slow) {
        ziggurat_batch_body(w, n, g, slow);
    }
#if EVSTWIN_MULTIVERSION
    EVSTWIN_TARGET_AVX2 static EVSTWIN_ALWAYS_INLINE void run(SimdAvx2, const std::uint32_t* w, std::size_t n, double* g,
                                                              std::uint8_t* slow) {
        LaneBatches<LanesAvx2>::ziggurat(w, n, g, slow);
    }
    EVSTWIN_TARGET_AVX512 static EVSTWIN_ALWAYS_INLINE void run(SimdAvx512, const std::uint32_t* w, std::size_t n,
                                                                double* g, std::uint8_t* slow) {
        LaneBatches<LanesAvx512>::ziggurat(w, n, g, slow);
    }
#endif
};
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif
}  // namespace detail

/// Philox4x32-10 of n counters (c0[i], c1[i], c2[i], c3) under `key`, at the current level.
inline void philox4x32_batch(const std::uint32_t* c0, const std::uint32_t* c1, const std::uint32_t* c2,
                             std::uint32_t c3, Philox4x32Key key, std::size_t n, std::uint32_t* r0, std::uint32_t* r1,
                             std::uint32_t* r2, std::uint32_t* r3) {
    at_simd_level<detail::PhiloxBatch>(c0, c1, c2, c3, key, n, r0, r1, r2, r3);
}

/// normal_ziggurat's common path for n words, at the current level (see ziggurat_batch_body).
inline void ziggurat_batch(const std::uint32_t* w, std::size_t n, double* g, std::uint8_t* slow) {
    at_simd_level<detail::ZigguratBatch>(w, n, g, slow);
}

}  // namespace evstwin
EVSTWIN_FP_STRICT_END
