// The batches of simd.hpp (Philox4x32-10, the ziggurat's common path) over one instruction
// set's vectors, written once for every set: simd.hpp includes this file once per set (so no
// #pragma once), inside namespace evstwin::detail, with EVSTWIN_LANES naming the set's lane
// class (its vector types, widths and intrinsics: LanesAvx2, LanesAvx512) and
// EVSTWIN_LANES_TARGET its target attribute. (A template over the lane class alone cannot be
// compiled for the set: its target attribute cannot depend on a template parameter, and the
// intrinsics cannot be inlined into a function without it. Nor can it handle the vectors
// through calls to the lane class: Clang refuses a call passing AVX vectors between functions
// of different targets.) Included elsewhere it defines nothing.
#if defined(EVSTWIN_LANES) && defined(EVSTWIN_LANES_TARGET)
template <>
struct LaneBatches<EVSTWIN_LANES> {
    using L = EVSTWIN_LANES;
    using V = L::V;
    static constexpr std::size_t w = L::width;

    /// Philox's rounds for the U vectors of counters from index i, side by side.
    template <std::size_t U>
    EVSTWIN_LANES_TARGET static EVSTWIN_ALWAYS_INLINE void philox_vectors(const std::uint32_t* c0,
                                                                          const std::uint32_t* c1,
                                                                          const std::uint32_t* c2, std::size_t i,
                                                                          const V* k0, const V* k1, const V& x3_0,
                                                                          std::uint32_t* r0, std::uint32_t* r1,
                                                                          std::uint32_t* r2, std::uint32_t* r3) {
        const V m0 = L::set1(0xD2511F53u), m1 = L::set1(0xCD9E8D57u);
        V x0[U], x1[U], x2[U], x3[U];
#if defined(__GNUC__)
#pragma GCC unroll 4
#endif
        for (std::size_t u = 0; u < U; ++u) {
            x0[u] = L::load(c0 + i + w * u);
            x1[u] = L::load(c1 + i + w * u);
            x2[u] = L::load(c2 + i + w * u);
            x3[u] = x3_0;
        }
#if defined(__GNUC__)
#pragma GCC unroll 10
#endif
        for (int round = 0; round < 10; ++round) {
#if defined(__GNUC__)
#pragma GCC unroll 4
#endif
            for (std::size_t u = 0; u < U; ++u) {
                const V p0 = L::mul(x0[u], m0), p1 = L::mul(x2[u], m1);
                x0[u] = L::high_xor(p1, x1[u], k0[round]);
                x1[u] = p1;
                x2[u] = L::high_xor(p0, x3[u], k1[round]);
                x3[u] = p0;
            }
        }
#if defined(__GNUC__)
#pragma GCC unroll 4
#endif
        for (std::size_t u = 0; u < U; ++u) {
            L::store(r0 + i + w * u, x0[u]);
            L::store(r1 + i + w * u, x1[u]);
            L::store(r2 + i + w * u, x2[u]);
            L::store(r3 + i + w * u, x3[u]);
        }
    }

    /// philox_batch_body's words: L::unroll vectors at a time, then one, then the scalar tail.
    EVSTWIN_LANES_TARGET static EVSTWIN_ALWAYS_INLINE void philox(const std::uint32_t* c0, const std::uint32_t* c1,
                                                                  const std::uint32_t* c2, std::uint32_t c3,
                                                                  Philox4x32Key key, std::size_t n, std::uint32_t* r0,
                                                                  std::uint32_t* r1, std::uint32_t* r2,
                                                                  std::uint32_t* r3) {
        constexpr std::uint32_t W0 = 0x9E3779B9u, W1 = 0xBB67AE85u;
        V k0[10], k1[10];
        for (int round = 0; round < 10; ++round) {
            k0[round] = L::set1(static_cast<std::uint32_t>(key[0] + static_cast<std::uint32_t>(round) * W0));
            k1[round] = L::set1(static_cast<std::uint32_t>(key[1] + static_cast<std::uint32_t>(round) * W1));
        }
        const V x3_0 = L::set1(c3);
        std::size_t i = 0;
        for (; i + L::unroll * w <= n; i += L::unroll * w)
            philox_vectors<L::unroll>(c0, c1, c2, i, k0, k1, x3_0, r0, r1, r2, r3);
        for (; i + w <= n; i += w) philox_vectors<1>(c0, c1, c2, i, k0, k1, x3_0, r0, r1, r2, r3);
        philox_batch_tail(i, c0, c1, c2, c3, key, n, r0, r1, r2, r3);
    }

    /// ziggurat_batch_body's normals and slow flags, L::words words at a time (the tables looked
    /// up by gathers; the normals half a vector of words at a time), then the plain loop.
    EVSTWIN_LANES_TARGET static EVSTWIN_ALWAYS_INLINE void ziggurat(const std::uint32_t* words, std::size_t n,
                                                                    double* g, std::uint8_t* slow) {
        using Words = L::Words;
        const double* tw = ZIGGURAT.w;
        const int* tk = reinterpret_cast<const int*>(ZIGGURAT.k);
        const Words m127 = L::set1_words(127), one = L::set1_words(1);
        std::size_t i = 0;
        for (; i + L::words <= n; i += L::words) {
            const Words wi = L::load_words(words + i);
            const Words layer = L::and_words(wi, m127), j = L::template shift_right<8>(wi);
            const Words sign = L::and_words(L::template shift_right<7>(wi), one);
            L::store_slow(slow + i, j, L::gather_words(tk, layer));
            for (int h = 0; h < 2; ++h)
                L::store_normals(g + i + L::words / 2 * h, L::half(j, h), L::half(layer, h), L::half(sign, h), tw);
        }
        ziggurat_batch_body(words + i, n - i, g + i, slow + i);
    }
};
#endif
