// C++ tests of rng.hpp and simd.hpp: Philox, the ziggurat, their batches at every SIMD level, exp_neg_bracket.
#include <evstwin/evstwin.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <initializer_list>
#include <limits>
#include <utility>
#include <vector>

#include "check.hpp"
#include "helpers.hpp"
#include "noise_reference.hpp"

using namespace evstwin;

TEST(philox_known_answer) {
    // Random123's published known-answer vectors for Philox4x32-10.
    auto r = philox4x32({0, 0, 0, 0}, {0, 0});
    CHECK(r[0] == 0x6627e8d5u && r[1] == 0xe169c58du && r[2] == 0xbc57ac4cu && r[3] == 0x9b00dbd8u);
    r = philox4x32({0xffffffffu, 0xffffffffu, 0xffffffffu, 0xffffffffu}, {0xffffffffu, 0xffffffffu});
    CHECK(r[0] == 0x408f276du && r[1] == 0x41c83b0eu && r[2] == 0xa20bc7c6u && r[3] == 0x6d5451fdu);
}

/// n standard normals from the ziggurat, fed by Philox words keyed by their index.
static std::vector<double> ziggurat_normals(std::size_t n, std::uint32_t purpose) {
    std::vector<double> out(n);
    for (std::size_t i = 0; i < n; ++i) {
        CounterStream words({1u, 2u}, static_cast<std::uint32_t>(i), 0, purpose);
        auto more = [&] { return words.word(); };
        out[i] = normal_ziggurat(words.word(), more);
    }
    return out;
}

TEST(ziggurat_is_a_standard_normal_tails_included) {
    // Bin counts of 2e6 variates against the normal CDF, each within 5 binomial sigmas, out to
    // |x| = 5 (the tail beyond r = 3.44 and the wedges take the slow path).
    const std::size_t n = 2000000;
    const auto x = ziggurat_normals(n, 7u);
    double sum = 0, sum2 = 0;
    for (double v : x) { sum += v; sum2 += v * v; }
    CHECK_NEAR(sum / n, 0.0, 5.0 / std::sqrt(double(n)));
    CHECK_NEAR(sum2 / n, 1.0, 5.0 * std::sqrt(2.0 / n));
    const auto cdf = [](double v) { return 0.5 * std::erfc(-v / std::sqrt(2.0)); };
    for (double lo = -5.0; lo < 5.0; lo += 0.5) {
        const double hi = lo + 0.5;
        std::size_t k = 0;
        for (double v : x) k += (v >= lo && v < hi);
        const double p = cdf(hi) - cdf(lo);
        CHECK_NEAR(double(k), n * p, 5.0 * std::sqrt(n * p * (1 - p)) + 1.0);
    }
    std::size_t far = 0;
    for (double v : x) far += std::fabs(v) > 4.0;
    const double p4 = std::erfc(4.0 / std::sqrt(2.0));
    CHECK_NEAR(double(far), n * p4, 5.0 * std::sqrt(n * p4) + 1.0);
}

namespace {
/// A kernel of at_simd_level whose code at each level returns that level and counts its calls
/// in the caller's variable (so the argument must reach it by reference, not copied).
struct WhichLevel {
    template <class Level>
    static SimdLevel run(Level, int& calls) {
        ++calls;
        return Level::level;
    }
};
}  // namespace

TEST(at_simd_level_runs_the_code_of_the_current_level_once) {
    const SimdLevel before = simd_level();
    for (SimdLevel l : {SimdLevel::Baseline, SimdLevel::AVX2, SimdLevel::AVX512}) {
        if (!simd_level_supported(l)) {
            CHECK_THROWS(set_simd_level(l));
            continue;
        }
        set_simd_level(l);
        int calls = 0;
        CHECK(at_simd_level<WhichLevel>(calls) == l);
        CHECK(calls == 1);
    }
    set_simd_level(before);
}

TEST(batched_philox_and_ziggurat_match_the_scalar_ones_at_every_simd_level) {
    // 1000 counters (odd length: the vector loops' remainders too), words through both paths.
    const std::size_t n = 1001;
    std::vector<std::uint32_t> c0(n), c1(n), c2(n), r0(n), r1(n), r2(n), r3(n);
    for (std::size_t i = 0; i < n; ++i) {
        c0[i] = static_cast<std::uint32_t>(i * 2654435761u);
        c1[i] = static_cast<std::uint32_t>(i >> 3);
        c2[i] = static_cast<std::uint32_t>(1000003u * i + 7u);
    }
    std::vector<double> g(n);
    std::vector<std::uint8_t> slow(n);
    const SimdLevel before = simd_level();
    int levels = 0;
    for (SimdLevel l : {SimdLevel::Baseline, SimdLevel::AVX2, SimdLevel::AVX512}) {
        if (!simd_level_supported(l)) continue;
        ++levels;
        set_simd_level(l);
        philox4x32_batch(c0.data(), c1.data(), c2.data(), PURPOSE_SAMPLE, {9u, 10u}, n, r0.data(), r1.data(), r2.data(),
                         r3.data());
        ziggurat_batch(r0.data(), n, g.data(), slow.data());
        std::size_t n_slow = 0;
        for (std::size_t i = 0; i < n; ++i) {
            const Philox4x32Counter w = philox4x32({c0[i], c1[i], c2[i], PURPOSE_SAMPLE}, {9u, 10u});
            CHECK(r0[i] == w[0] && r1[i] == w[1] && r2[i] == w[2] && r3[i] == w[3]);
            // The scalar ziggurat's common case: the magnitude below its layer's k (no more() call).
            const bool scalar_slow = (w[0] >> 8) >= ZIGGURAT.k[w[0] & 127u];
            CHECK(static_cast<bool>(slow[i]) == scalar_slow);
            if (!scalar_slow) CHECK(g[i] == normal_ziggurat(w[0], [] { return 0u; }));
            n_slow += slow[i];
        }
        CHECK(n_slow < n / 20);  // ~1 % of words leave the common path
    }
    CHECK(levels >= 1);
    // Every layer and sign, with magnitudes at the edges of its rectangle (0, k - 1, k, the
    // largest): the batches read the tables right (the AVX2 and AVX-512 ones by gathers) and
    // give the scalar common path's bits (a zero's sign too) and the same slow flags.
    std::vector<std::uint32_t> words;
    for (std::uint32_t layer = 0; layer < 128; ++layer)
        for (std::uint32_t sign = 0; sign < 2; ++sign)
            for (std::uint32_t j : {0u, ZIGGURAT.k[layer] - 1u, ZIGGURAT.k[layer], (1u << 24) - 1u})
                if (j < (1u << 24)) words.push_back((j << 8) | (sign << 7) | layer);
    const std::size_t m = words.size();
    std::vector<double> gw(m);
    std::vector<std::uint8_t> slow_w(m);
    for (SimdLevel l : {SimdLevel::Baseline, SimdLevel::AVX2, SimdLevel::AVX512}) {
        if (!simd_level_supported(l)) continue;
        set_simd_level(l);
        ziggurat_batch(words.data(), m, gw.data(), slow_w.data());
        std::size_t wrong = 0, n_slow = 0;
        for (std::size_t i = 0; i < m; ++i) {
            double want = 0.0;
            const bool common = normal_ziggurat_common(words[i], want);
            wrong += static_cast<bool>(slow_w[i]) == common;
            if (common) wrong += std::memcmp(&gw[i], &want, sizeof want) != 0;
            n_slow += slow_w[i];
        }
        CHECK(wrong == 0);
        CHECK(n_slow > 0 && n_slow < m);
    }
    set_simd_level(before);
}

TEST(ziggurat_slow_path_decides_its_wedges_as_the_library_exp_does) {
    // normal_ziggurat_slow (its wedge test decided on exp_neg_bracket, the library exp only
    // near the boundary; with or without the caller's bracket of the first wedge) against the
    // same algorithm written with std::exp, for 20,000 words that leave the common path.
    const auto reference = [](std::uint32_t w, CounterStream& more) {
        const ZigguratTables& z = ZIGGURAT;
        for (;;) {
            const std::uint32_t i = w & 127u, j = w >> 8;
            const double sign = (w & 128u) ? -1.0 : 1.0;
            const double x = static_cast<double>(j) * z.w[i];
            if (j < z.k[i]) return sign * x;
            if (i == 0) {
                double xt, yt;
                do {
                    xt = -std::log(uniform_open(more.word())) / ZigguratTables::R;
                    yt = -std::log(uniform_open(more.word()));
                } while (yt + yt < xt * xt);
                return sign * (ZigguratTables::R + xt);
            }
            if (z.f[i] + uniform_open(more.word()) * (z.f[i - 1] - z.f[i]) < std::exp(-0.5 * x * x)) return sign * x;
            w = more.word();
        }
    };
    int slow = 0, differ = 0;
    for (std::uint32_t s = 0; slow < 20000; ++s) {
        const std::uint32_t w = philox4x32({s, 0u, 77u, PURPOSE_SAMPLE}, {3u, 4u})[0];
        if ((w >> 8) < ZIGGURAT.k[w & 127u]) continue;
        ++slow;
        CounterStream a({3u, 4u}, 77u, s, PURPOSE_NORMAL), b = a, c = a;
        auto more_b = [&b] { return b.word(); };
        auto more_c = [&c] { return c.word(); };
        const double x = static_cast<double>(w >> 8) * ZIGGURAT.w[w & 127u];
        const double want = reference(w, a);
        const double plain = normal_ziggurat_slow(w, more_b);
        const double given = normal_ziggurat_slow(w, more_c, detail::exp_neg_bracket(0.5 * x * x));
        differ += !(plain == want && given == want);
    }
    CHECK(differ == 0);
}

TEST(exp_neg_bracket_is_within_1e_8_of_exp) {
    // The bracket bridge_fires decides on: its stated error against the library's exp, on a
    // fine grid of [0, 40] and at the ends.
    double worst = 0.0;
    for (int i = 0; i <= 400000; ++i) {
        const double e = 40.0 * i / 400000.0;
        worst = std::max(worst, std::fabs(detail::exp_neg_bracket(e) / std::exp(-e) - 1.0));
    }
    CHECK(worst < 1e-8);
    CHECK(detail::exp_neg_bracket(0.0) == 1.0);
}
