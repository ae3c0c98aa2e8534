// C++ tests of kernels/ and simd/block_passes.hpp: the block arrays, the batched passes at every SIMD level, and the block kernels against PixelModel::advance pixel by pixel.
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

TEST(block_arrays_are_laid_out_apart_and_keep_their_elements) {
    // BlockSoA's arrays: one allocation, each 64-byte aligned, none overlapping another, and
    // a block's equal arrays at different 64-byte offsets of a 4 KB page (the point of the
    // layout: no two of them alias in the CPU's 4 KB store-load check).
    BlockSoA soa;
    soa.resize(100);
    for (std::size_t j = 0; j < 100; ++j) {
        CHECK(soa.now().x[j] == 0.0 && soa.busy[j] == 0u && soa.spare_lo[j] == 0u);  // value-initialised
        soa.now().x[j] = 1.5 * static_cast<double>(j);
        soa.theta_on[j] = -static_cast<double>(j);
        soa.spare_lo[j] = static_cast<std::uint32_t>(7 * j);
    }
    soa.resize(50);  // no smaller layout: the same arrays
    CHECK(soa.busy.size() == 100);
    soa.resize(256);
    CHECK(soa.busy.size() == 256 && soa.now().x.size() == 256 && soa.spare_lo.size() == 256);
    bool kept = true;
    for (std::size_t j = 0; j < 100; ++j)
        kept &= soa.now().x[j] == 1.5 * static_cast<double>(j) && soa.theta_on[j] == -static_cast<double>(j) &&
                soa.spare_lo[j] == static_cast<std::uint32_t>(7 * j);
    for (std::size_t j = 100; j < 256; ++j) kept &= soa.now().x[j] == 0.0 && soa.spare_lo[j] == 0u;
    CHECK(kept);
    struct Span {
        std::uintptr_t begin, end;
    };
    std::vector<Span> spans;
    std::vector<std::uintptr_t> doubles_at;  // the 2 KB arrays' page offsets
    const auto add = [&](const void* p, std::size_t bytes, bool is_double) {
        const auto a = reinterpret_cast<std::uintptr_t>(p);
        CHECK(a % 64 == 0);
        spans.push_back({a, a + bytes});
        if (is_double) doubles_at.push_back(a % 4096 / 64);
    };
    for (const BlockSoA::Levels& l : soa.buf)
        for (const auto* v : {&l.x, &l.z, &l.y, &l.nz, &l.ny, &l.ref, &l.clock_on, &l.clock_off})
            add(v->data(), 256 * sizeof(double), true);
    for (const auto* v : {&soa.refr_until, &soa.next_hot_t, &soa.theta_on, &soa.theta_off, &soa.leak_spread,
                          &soa.bg_on_hz, &soa.bg_off_hz, &soa.leak_g, &soa.bg_on_rate, &soa.bg_off_rate})
        add(v->data(), 256 * sizeof(double), true);
    add(soa.spare_lo.data(), 256 * 4, false);
    add(soa.spare_hi.data(), 256 * 4, false);
    add(soa.spare_sample.data(), 256 * 8, false);
    add(soa.n_base.data(), 256 * 8, false);
    add(soa.busy.data(), 256 * 8, false);
    bool apart = true;
    for (std::size_t i = 0; i < spans.size(); ++i)
        for (std::size_t k = i + 1; k < spans.size(); ++k)
            apart &= spans[i].end <= spans[k].begin || spans[k].end <= spans[i].begin;
    CHECK(apart);
    std::vector<std::uintptr_t> sorted = doubles_at;
    std::sort(sorted.begin(), sorted.end());
    CHECK(std::adjacent_find(sorted.begin(), sorted.end()) == sorted.end());  // 28 different page offsets
}

/// int_0^T f(s) ds of a sum of decaying exponentials whose fastest rate is k_max, by Simpson's
/// rule in long double on panels that double in width from 1 / (20 k_max): independent of the
/// closed forms of noise.hpp.
template <class F>
static long double integrate_decays(F f, long double k_max, long double T) {
    long double sum = 0.0L, lo = 0.0L, width = 0.05L / k_max;
    while (lo < T) {
        const long double hi = std::min(T, lo + width);
        const int m = 512;  // even
        const long double h = (hi - lo) / m;
        long double panel = f(lo) + f(hi);
        for (int i = 1; i < m; ++i) panel += (i % 2 ? 4.0L : 2.0L) * f(lo + i * h);
        sum += panel * h / 3.0L;
        lo = hi;
        width *= 2.0L;
    }
    return sum;
}

TEST(noise_caches_filled_together_are_fill_noise_cache_bit_for_bit) {
    // step_block_soa makes the numbers of its pixels at rates of their own together
    // (PixelModel::fill_noise_caches: each stage over all the rates; then fill_noise_finish,
    // the lazy choice, one by one); each must be what fill_noise_cache() gives, field by field,
    // whatever the caches held before (another batch's rates, another interval's source
    // follower terms), lazy or eager, at any credit. Over two poles (eager and lazy bridge, and
    // a pole at the source follower's rate, which separated_pole_rate moves off it), the pole
    // alone, the source follower alone, and no noise. Both forms run the same stages, so the
    // two-pole coefficients are also checked against the transition and the covariance
    // integrated numerically (Q = D a^2 int_0^T v v^T, v(s) = Phi(s) e_z): a wrong stage fails.
    const auto bits = [](double x, double y) { return std::memcmp(&x, &y, sizeof x) == 0; };
    const auto same = [&](const NoiseCache& x, const NoiseCache& y) {
        return bits(x.photon_rate, y.photon_rate) && bits(x.dt, y.dt) && bits(x.current_a, y.current_a) &&
               bits(x.x, y.x) && bits(x.a, y.a) && bits(x.D, y.D) && bits(x.pole_decay, y.pole_decay) &&
               bits(x.pole_ramp, y.pole_ramp) && std::memcmp(&x.k, &y.k, sizeof(NoiseCoeffs)) == 0 &&
               std::memcmp(&x.sf, &y.sf, sizeof(SfTerms)) == 0 && bits(x.bridge_bound, y.bridge_bound) &&
               x.bridge_ready == y.bridge_ready && x.lazy_credit == y.lazy_credit && bits(x.bg_factor, y.bg_factor) &&
               bits(x.leak_hz, y.leak_hz);
    };
    // |x - want| within rel of scale (the size of the terms the closed form adds up).
    const auto near = [](double x, long double want, long double scale, long double rel) {
        return std::fabs(static_cast<long double>(x) - want) <= rel * scale;
    };
    std::vector<PixelParams> configs(5);
    configs[0].pr_pole = true;  // mcreynolds' chain
    configs[1].pr_pole = true;
    configs[1].cutoff_hz = 0.5 * configs[1].pr_cutoff_ref_hz;
    configs[2].pr_pole = true;
    configs[2].cutoff_hz.reset();  // the pole alone
    configs[4].photon_shot_noise = false;
    configs[4].dark_model = DarkModel::None;  // no noise: D = 0
    int checked = 0, eager = 0, lazy = 0, moved = 0, integrated = 0;
    for (const PixelParams& params : configs) {
        const BlockModel model(params);
        const double b = model.sf_rate();
        std::vector<double> rates;
        for (int e = 0; e <= 44; ++e) rates.push_back(std::pow(10.0, 0.25 * e));  // 1 to 1e11 photons/s
        rates.push_back(0.0);
        rates.push_back(rates[7]);  // a rate twice
        if (params.pr_pole && params.cutoff_hz) {
            // The rate whose pole is the source follower's (a = b): moved off it.
            const double current = params.pr_ref_current_a * (*params.cutoff_hz / params.pr_cutoff_ref_hz);
            rates.push_back((current / ELEMENTARY_CHARGE_C - model.dark_mean_e_per_s) / model.e_per_photon);
        }
        const std::size_t n = rates.size();
        std::vector<NoiseCache> fills(n);
        std::vector<NoiseIntervalStage> stages(n);
        for (double dt : {1e-5, 3.1e-4, 4e-3, 0.05})  // each batch's caches hold the last interval's
            for (bool reversed : {false, true}) {     // and the last batch's rates, in another order
                std::vector<double> batch(rates);
                if (reversed) batch.assign(rates.rbegin(), rates.rend());
                const SampleConstants c = model.constants(1.0, 1.0 + dt);
                model.fill_noise_caches(fills.data(), stages.data(), batch.data(), n, c, sf_terms(b, c.dt));
                for (std::size_t i = 0; i < n; ++i) {
                    for (int credit : {-6, -1, 0, 6})
                        for (bool lazy_bridge : {true, false}) {
                            NoiseCache got = fills[i], ref;
                            got.lazy_credit = ref.lazy_credit = credit;
                            model.fill_noise_finish(got, c, lazy_bridge);
                            model.fill_noise_cache(ref, batch[i], c, lazy_bridge);
                            CHECK(same(got, ref));
                            CHECK(got.lazy_credit == (lazy_bridge ? std::min(credit + 1, 6) : credit));
                            eager += ref.bridge_ready && ref.k.bridge_var > 0.0 && ref.a > 0.0 && model.has_filter;
                            lazy += !ref.bridge_ready;
                            // What the per-pixel path does with a lazy one: the same bits once completed.
                            model.complete_noise_cache(got, c);
                            model.complete_noise_cache(ref, c);
                            CHECK(same(got, ref));
                            ++checked;
                        }
                    const NoiseCache& k = fills[i];
                    if (!(k.D > 0.0 && k.a > 0.0 && b > 0.0)) continue;
                    // The two poles against the numbers integrated here.
                    const long double A = detail::separated_pole_rate(k.a, b), B = b, T = c.dt, D = k.D;
                    moved += A != k.a;
                    const auto vz = [&](long double s) { return std::exp(-A * s); };
                    const auto vy = [&](long double s) { return B * (std::exp(-A * s) - std::exp(-B * s)) / (B - A); };
                    const long double g = D * A * A, fastest = 2.0L * std::max(A, B);
                    const long double qzz = g * integrate_decays([&](long double s) { return vz(s) * vz(s); }, fastest, T);
                    const long double qzy = g * integrate_decays([&](long double s) { return vz(s) * vy(s); }, fastest, T);
                    const long double qyy = g * integrate_decays([&](long double s) { return vy(s) * vy(s); }, fastest, T);
                    // The scale of the closed form's cancelling terms, g c^2 (h2a + 2 hab + h2b) <= 4 g c^2 T.
                    const long double cc = B / std::fabs(B - A), scale = g * cc * cc * 4.0L * T + qzz;
                    CHECK(near(k.k.phi_zz, vz(T), 1.0L, 1e-12L));
                    CHECK(near(k.k.phi_yy, std::exp(-B * T), 1.0L, 1e-12L));
                    CHECK(near(k.k.phi_yz, vy(T), 1.0L, 1e-9L));
                    CHECK(near(k.k.l_zz * k.k.l_zz, qzz, qzz, 1e-9L));
                    CHECK(near(k.k.l_zz * k.k.l_yz, qzy, scale, 1e-9L));
                    CHECK(near(k.k.q_yy, qyy, scale, 1e-9L));
                    CHECK(near(k.k.l_yz * k.k.l_yz + k.k.l_yy * k.k.l_yy, qyy, scale, 1e-9L));
                    ++integrated;
                }
            }
    }
    CHECK(checked == 4 * 2 * 4 * 2 * (2 * 48 + 3 * 47));
    CHECK(integrated > 4 * 2 * 2 * 40);
    CHECK(eager > 0 && lazy > 0 && moved > 0);  // every branch of the stages was taken
}

TEST(list_flagged_lists_the_flagged_indices_in_order_at_every_simd_level) {
    // Against the plain list, for 64-bit and byte flags, lengths around the 64-flag words, flag
    // densities from none to all (values other than 1 count as flagged too).
    const SimdLevel before = simd_level();
    std::uint64_t state = 12345u;
    const auto next = [&state] {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        return static_cast<std::uint32_t>(state >> 33);
    };
    for (SimdLevel l : {SimdLevel::Baseline, SimdLevel::AVX2, SimdLevel::AVX512}) {
        if (!simd_level_supported(l)) continue;
        set_simd_level(l);
        for (std::size_t n : {0u, 1u, 63u, 64u, 65u, 200u, 256u, 300u}) {
            for (std::uint32_t per_mille : {0u, 50u, 500u, 1000u}) {
                std::vector<std::uint64_t> f64(n);
                std::vector<std::uint8_t> f8(n);
                std::vector<std::uint32_t> expected;
                for (std::size_t i = 0; i < n; ++i) {
                    const bool on = next() % 1000u < per_mille;
                    f64[i] = on ? 1u + next() % 3u : 0u;
                    f8[i] = static_cast<std::uint8_t>(on ? 1u + next() % 3u : 0u);
                    if (on) expected.push_back(static_cast<std::uint32_t>(i));
                }
                std::vector<std::uint32_t> got64(n + 1, 9999u), got8(n + 1, 9999u);
                const std::size_t m64 = list_flagged(f64.data(), n, got64.data());
                const std::size_t m8 = list_flagged(f8.data(), n, got8.data());
                CHECK(m64 == expected.size() && m8 == expected.size());
                for (std::size_t k = 0; k < expected.size() && k < m64 && k < m8; ++k)
                    CHECK(got64[k] == expected[k] && got8[k] == expected[k]);
            }
        }
    }
    set_simd_level(before);
}

TEST(bracket_fires_decides_as_the_library_exps_next_to_the_boundary_at_every_simd_level) {
    // The bridge stage's decision (bracket_fires on bridge_bracket's q) against u < p_on +
    // p_off with the library's exps, for uniforms aimed at that sum: within a relative 1e-12
    // to 1e-5 of it on either side, and its own bits and their neighbours a few ulps away.
    // Those in the 1e-6 band must take the library's exps (the engine's runs almost never
    // land there), the rest are decided on q; every answer must be the exps'.
    XorshiftUniform next{0x2545F4914F6CDD1Dull};
    const std::size_t m = 4000;
    std::vector<double> e_on(m), e_off(m);
    for (std::size_t i = 0; i < m; ++i) {
        e_on[i] = 42.0 * next();
        e_off[i] = i % 3 == 0 ? 1e300 : 42.0 * next();
    }
    const SimdLevel before = simd_level();
    for (SimdLevel l : {SimdLevel::Baseline, SimdLevel::AVX2, SimdLevel::AVX512}) {
        if (!simd_level_supported(l)) continue;
        set_simd_level(l);
        std::vector<double> q(m);
        detail::bridge_bracket(e_on.data(), e_off.data(), m, q.data());
        int wrong = 0, in_band = 0, out_of_band = 0;
        for (std::size_t i = 0; i < m; ++i) {
            const double p = (e_on[i] > 40.0 ? 0.0 : std::exp(-e_on[i])) + (e_off[i] > 40.0 ? 0.0 : std::exp(-e_off[i]));
            if (!(p > 0.0)) continue;
            std::vector<double> us = {p, std::nextafter(p, 0.0), std::nextafter(p, 1.0),
                                      std::nextafter(std::nextafter(p, 0.0), 0.0), q[i]};
            for (int k = 0; k < 8; ++k) {
                const double delta = std::pow(10.0, -12.0 + 7.0 * next());
                us.push_back(p * (1.0 + delta));
                us.push_back(p * (1.0 - delta));
            }
            for (double u : us) {
                if (!(u > 0.0 && u < 1.0)) continue;
                const bool band = u >= q[i] * (1.0 - 1e-6) && u <= q[i] * (1.0 + 1e-6);
                in_band += band;
                out_of_band += !band;
                wrong += detail::bracket_fires(u, q[i], e_on[i], e_off[i]) != (u < p);
            }
        }
        CHECK(wrong == 0);
        CHECK(in_band > 10000);     // the library's exps decided these
        CHECK(out_of_band > 5000);  // and the bracket these, next to the boundary
    }
    set_simd_level(before);
}

TEST(bridge_bracket_is_within_1e_8_of_the_crossing_probabilities_at_every_simd_level) {
    // q = exp(-e_on) + exp(-e_off) with terms above 40 cut to 0 (bridge_crossing_probability's
    // cut), -1 where an exponent is negative or NaN; the same bits at every level.
    std::vector<double> e_on, e_off;
    for (int i = 0; i <= 200; ++i)
        for (double other : {0.0, 0.3, 7.0, 39.9, 40.0, 40.5, 1e300}) {
            e_on.push_back(45.0 * i / 200.0);
            e_off.push_back(other);
        }
    for (double bad : {-1e-300, -3.0, std::numeric_limits<double>::quiet_NaN()}) {
        e_on.push_back(bad);
        e_off.push_back(1.0);
        e_on.push_back(1.0);
        e_off.push_back(bad);
    }
    const std::size_t m = e_on.size();
    const SimdLevel before = simd_level();
    std::vector<double> first;
    for (SimdLevel l : {SimdLevel::Baseline, SimdLevel::AVX2, SimdLevel::AVX512}) {
        if (!simd_level_supported(l)) continue;
        set_simd_level(l);
        std::vector<double> q(m);
        detail::bridge_bracket(e_on.data(), e_off.data(), m, q.data());
        for (std::size_t i = 0; i < m; ++i) {
            if (!(e_on[i] >= 0.0) || !(e_off[i] >= 0.0)) {
                CHECK(q[i] == -1.0);
                continue;
            }
            const double p = (e_on[i] > 40.0 ? 0.0 : std::exp(-e_on[i])) + (e_off[i] > 40.0 ? 0.0 : std::exp(-e_off[i]));
            CHECK(p == 0.0 ? q[i] == 0.0 : std::fabs(q[i] / p - 1.0) < 1e-8);
        }
        if (first.empty()) first = q;
        for (std::size_t i = 0; i < m; ++i) CHECK(std::memcmp(&q[i], &first[i], sizeof(double)) == 0);
    }
    set_simd_level(before);
}

TEST(batched_normals_are_sample_normals_bit_for_bit_at_every_simd_level) {
    // BlockModel::batch_sample_normals (the block kernels' normals: a batch for the common
    // path, the slow ones alone in their stream finished without branches where their first
    // wedge test decides, either accepted or rejected with the stream's next word common, the
    // rest by normal_ziggurat_slow) against sample_normals, pixel by pixel, with one and with
    // two normals a pixel. 256 pixels x 300 samples: ~4,200 slow normals with two, each kind
    // that the batch finishes its own way counted, so the comparison reaches them all.
    const Philox4x32Key key{21u, 22u};
    const std::size_t n = 256;
    BlockModel::BlockScratch scratch;
    scratch.resize(n);
    std::vector<std::uint32_t> w0(n), w1(n), ids(n);
    std::vector<double> g1(n), g2(n);
    for (std::size_t j = 0; j < n; ++j) ids[j] = static_cast<std::uint32_t>(7919u * j + 3u);
    const ZigguratTables& z = ZIGGURAT;
    // The batch on this sample's words against sample_normals, pixel by pixel: how many normals
    // differ in any bit. One normal: the first takes the further words first in either, so it
    // is the same; g2 is left as it was (-7).
    const auto batch_differs = [&](std::uint64_t sample, bool second) {
        for (std::size_t j = 0; j < n; ++j) g2[j] = -7.0;
        BlockModel::batch_sample_normals(
            n, [sample](std::size_t) { return sample; }, [&ids](std::size_t j) { return ids[j]; }, key, scratch,
            w0.data(), w1.data(), g1.data(), g2.data(), second);
        std::size_t differ = 0;
        for (std::size_t j = 0; j < n; ++j) {
            double want1 = 0.0, want2 = 0.0;
            PixelModel::sample_normals(w0[j], w1[j], key, ids[j], sample, want1, want2);
            if (!second) want2 = -7.0;
            differ += std::memcmp(&g1[j], &want1, sizeof want1) != 0;
            differ += std::memcmp(&g2[j], &want2, sizeof want2) != 0;
        }
        return differ;
    };
    const auto level_name = [](SimdLevel l) {
        return l == SimdLevel::Baseline ? "baseline" : l == SimdLevel::AVX2 ? "AVX2" : "AVX-512";
    };
    const SimdLevel before = simd_level();
    for (SimdLevel l : {SimdLevel::Baseline, SimdLevel::AVX2, SimdLevel::AVX512}) {
        if (!simd_level_supported(l)) continue;
        set_simd_level(l);
        for (bool second : {false, true}) {
            std::size_t differ = 0, accepted = 0, retried = 0, rest = 0, both = 0;
            for (std::uint64_t sample = 1; sample <= 300; ++sample) {
                for (std::size_t j = 0; j < n; ++j) {
                    const Philox4x32Counter w = philox4x32(
                        {static_cast<std::uint32_t>(sample), 0u, ids[j], PURPOSE_SAMPLE}, key);
                    w0[j] = w[0];
                    w1[j] = w[1];
                }
                differ += batch_differs(sample, second);
                for (std::size_t j = 0; j < n; ++j) {
                    // Which way the batch went for a slow normal (the test's own reckoning).
                    const bool slow_a = (w0[j] >> 8) >= z.k[w0[j] & 127u];
                    const bool slow_b = second && (w1[j] >> 8) >= z.k[w1[j] & 127u];
                    if (!slow_a && !slow_b) continue;
                    if (slow_a && slow_b) {
                        ++both;
                        continue;
                    }
                    const std::uint32_t ws = slow_a ? w0[j] : w1[j], layer = ws & 127u;
                    CounterStream stream(key, ids[j], sample, PURPOSE_NORMAL);
                    const std::uint32_t r0 = stream.word(), r1 = stream.word();
                    const double x = static_cast<double>(ws >> 8) * z.w[layer];
                    const double lhs = layer ? z.f[layer] + uniform_open(r0) * (z.f[layer - 1] - z.f[layer]) : 0.0;
                    const double q = std::exp(-0.5 * x * x);
                    if (layer && lhs < q * (1.0 - 1e-6)) {
                        ++accepted;
                    } else if (layer && lhs > q * (1.0 + 1e-6) && (r1 >> 8) < z.k[r1 & 127u]) {
                        ++retried;
                    } else {
                        ++rest;
                    }
                }
            }
            std::printf("  %s, %s: %zu accepted, %zu retried, %zu by the slow path, %zu pixels with two slow\n",
                        level_name(l), second ? "two normals" : "one normal", accepted, retried, rest, both);
            CHECK(differ == 0);
            CHECK(accepted > 100 && retried > 100 && rest > 5);
            CHECK(!second || both > 0);
        }
        // Words made to fall in the undecided band: for each pixel, a wedge layer and the
        // magnitude whose bracketed exp(-x^2/2) lies within a relative 1e-6 of the first wedge
        // test's lhs (from the stream's first word), searched by bisection; of the two
        // magnitudes around the crossing, one where lhs lies between the bracket and the
        // library's exp where there is one (the bracket then decides the other way: only the
        // exact test, the one the batch must leave to normal_ziggurat_slow, gets it right; the
        // bracket lies below the exp, its Taylor remainder being positive, so lhs falls between
        // them only from below). Random words reach the band rarely. With two normals, half the
        // pixels carry the word as their first normal, half as their second (the other one common).
        for (bool second : {false, true}) {
            std::size_t differ = 0, banded = 0, split = 0;
            for (std::uint64_t sample = 1; sample <= 20; ++sample) {
                for (std::size_t j = 0; j < n; ++j) {
                    const std::uint32_t common = 5u;  // magnitude 0 in layer 5: the common path
                    w0[j] = w1[j] = common;
                    const std::uint32_t layer = 1u + static_cast<std::uint32_t>((37u * j + 11u * sample) % 127u);
                    CounterStream stream(key, ids[j], sample, PURPOSE_NORMAL);
                    const double lhs = z.f[layer] + uniform_open(stream.word()) * (z.f[layer - 1] - z.f[layer]);
                    const auto x_of = [&](std::uint32_t m) { return static_cast<double>(m) * z.w[layer]; };
                    const auto bracket = [&](std::uint32_t m) { return detail::exp_neg_bracket(0.5 * x_of(m) * x_of(m)); };
                    const auto exact = [&](std::uint32_t m) { return std::exp(-0.5 * x_of(m) * x_of(m)); };
                    std::uint32_t lo = z.k[layer], hi = (1u << 24) - 1u;  // the bracket falls with the magnitude
                    if (!(bracket(lo) >= lhs && bracket(hi) <= lhs)) continue;
                    while (hi - lo > 1) {
                        const std::uint32_t mid = lo + (hi - lo) / 2;
                        (bracket(mid) >= lhs ? lo : hi) = mid;
                    }
                    const auto splits = [&](std::uint32_t m) { return (lhs < bracket(m)) != (lhs < exact(m)); };
                    const std::uint32_t m = splits(lo)   ? lo
                                            : splits(hi) ? hi
                                            : std::fabs(bracket(lo) - lhs) < std::fabs(bracket(hi) - lhs) ? lo
                                                                                                          : hi;
                    if (std::fabs(bracket(m) - lhs) > 0.9e-6 * bracket(m)) continue;
                    split += splits(m);
                    const std::uint32_t w = (m << 8) | (static_cast<std::uint32_t>(j & 1u) << 7) | layer;
                    (second && (j & 2u) ? w1[j] : w0[j]) = w;
                    ++banded;
                }
                differ += batch_differs(sample, second);
            }
            std::printf("  %s, %s: %zu words in the undecided band, %zu with lhs between the bracket and the exp\n",
                        level_name(l), second ? "two normals" : "one normal", banded, split);
            CHECK(differ == 0);
            CHECK(banded > 2500 && split > 10);
        }
    }
    set_simd_level(before);
}

TEST(quiet_pass_gives_the_same_bits_at_every_simd_level) {
    // The block kernel's vectorised pass on random levels (around both thresholds, so every
    // class occurs), every chain and switch, against the baseline build's scalar loop: the
    // same bits in every output array. A compiler that contracted a multiply-add into an FMA
    // at AVX2 / AVX-512 (what EVSTWIN_FP_STRICT_BEGIN forbids) would fail this.
    const std::size_t n = 203;  // not a multiple of a vector: the loops' remainders too
    std::uint64_t state = 0x9E3779B97F4A7C15ull;
    const auto unit = [&state] {  // splitmix64 -> [0, 1)
        std::uint64_t z = (state += 0x9E3779B97F4A7C15ull);
        z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
        z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
        return static_cast<double>((z ^ (z >> 31)) >> 11) * 0x1p-53;
    };
    BlockSoA h;
    h.resize(n);
    std::vector<float> rate(n);
    std::vector<double> g1(n), g2(n);
    for (std::size_t j = 0; j < n; ++j) {
        BlockSoA::Levels& l = h.now();
        l.x[j] = -30.0 + unit(); l.z[j] = -30.0 + unit(); l.ny[j] = 0.1 * (unit() - 0.5);
        l.nz[j] = 0.1 * (unit() - 0.5); l.ref[j] = -30.0 + unit();
        h.theta_on[j] = 0.15 + 0.1 * unit(); h.theta_off[j] = 0.1 + 0.1 * unit();
        l.y[j] = l.ref[j] + (unit() - 0.4) * 0.5;  // some past a threshold, most between
        l.clock_on[j] = 3.0 * unit(); l.clock_off[j] = 0.002 * unit();
        h.leak_spread[j] = 0.5 + unit(); h.bg_on_hz[j] = 5.0 * unit(); h.bg_off_hz[j] = 5.0 * unit();
        h.refr_until[j] = unit() < 0.1 ? 0.0105 : 0.0;
        h.next_hot_t[j] = unit() < 0.05 ? 0.0101 : 1e300;
        rate[j] = unit() < 0.9 ? 2e6f : 3e6f;
        g1[j] = 2.0 * (unit() - 0.5); g2[j] = 2.0 * (unit() - 0.5);
    }
    QuietPass q{};
    q.now = &h.now(); q.refr_until = h.refr_until.data(); q.next_hot_t = h.next_hot_t.data();
    q.theta_on = h.theta_on.data(); q.theta_off = h.theta_off.data(); q.g1 = g1.data(); q.g2 = g2.data();
    q.count = n; q.rate = 2e6; q.cx = -29.7; q.pole_decay = 0.93; q.pole_ramp = 0.97;
    q.phi_zz = 0.91; q.phi_yz = 0.05; q.phi_yy = 0.94; q.l_zz = 0.013; q.l_yz = 0.004; q.l_yy = 0.011;
    q.bridge_bound = 2e-3; q.sf_decay = 0.939; q.sf_ramp = 0.969; q.dt = 1e-3; q.inv_dt = 1e3;
    q.t0 = 0.010; q.t1 = 0.011; q.bridge_stage = true;
    const double leak_hz = 0.07;  // a fast leak (70 thresholds a second x spread) moves d by up to 0.1 per sample
    const double bg_factor = 0.77;
    std::vector<double> bg_on_rate(n), bg_off_rate(n);
    for (std::size_t j = 0; j < n; ++j) {
        bg_on_rate[j] = h.bg_on_hz[j] * bg_factor;
        bg_off_rate[j] = h.bg_off_hz[j] * bg_factor;
    }
    q.bg_on_rate = bg_on_rate.data(); q.bg_off_rate = bg_off_rate.data();
    const auto pass = [&](SimdLevel l, QuietChain chain, bool noise, bool background, bool leak_off) {
        BlockSoA::Levels out = h.buf[1];
        std::vector<std::uint64_t> busy(n, 7);
        QuietPass qq = q;
        std::vector<double> leak_g(n);  // PixelModel::leak_slope's term
        for (std::size_t j = 0; j < n; ++j)
            leak_g[j] = (leak_hz * h.leak_spread[j]) * (leak_off ? -h.theta_off[j] : h.theta_on[j]);
        qq.leak_g = leak_g.data();
        qq.next = &out;
        qq.busy = busy.data();
        set_simd_level(l);
        if (chain == QuietChain::SfOnly)
            detail::quiet_pass<QuietChain::SfOnly>(qq, rate.data(), noise, background);
        else
            detail::quiet_pass<QuietChain::PoleSf>(qq, rate.data(), noise, background);
        std::vector<unsigned char> bytes;
        const auto add = [&bytes](const void* p, std::size_t size) {
            const auto* b = static_cast<const unsigned char*>(p);
            bytes.insert(bytes.end(), b, b + size);
        };
        for (const auto* v : {&out.x, &out.z, &out.y, &out.nz, &out.ny, &out.ref, &out.clock_on, &out.clock_off})
            add(v->data(), n * sizeof(double));
        add(busy.data(), n * sizeof(std::uint64_t));
        std::size_t classes[3] = {0, 0, 0};
        for (std::uint64_t b : busy) classes[b < 3 ? b : 0] += b < 3;
        return std::make_pair(bytes, classes[0] > 0 && classes[1] > 0 && classes[2] > 0);
    };
    const SimdLevel before = simd_level();
    int compared = 0;
    for (QuietChain chain : {QuietChain::SfOnly, QuietChain::PoleSf})
        for (bool noise : {false, true})
            for (bool background : {false, true})
                for (bool leak_off : {false, true}) {
                    const auto ref = pass(SimdLevel::Baseline, chain, noise, background, leak_off);
                    CHECK(ref.second);  // quiet, bridge and busy pixels all occur
                    // The leak's direction reaches the levels: the references differ.
                    if (!leak_off) CHECK(pass(SimdLevel::Baseline, chain, noise, background, true).first != ref.first);
                    for (SimdLevel l : {SimdLevel::AVX2, SimdLevel::AVX512}) {
                        if (!simd_level_supported(l)) continue;
                        CHECK(pass(l, chain, noise, background, leak_off).first == ref.first);
                        ++compared;
                    }
                }
    set_simd_level(before);
    std::printf("  quiet pass: %d level comparisons\n", compared);
}

TEST(block_arrays_leave_every_pixel_as_the_per_pixel_path_does) {
    // step_block_soa on a block held as arrays against advance() pixel by pixel over the same
    // samples (every noise source on, 10 Hz source follower, alone and behind the pole, and the
    // noiseless pixel without either; a
    // quarter of the pixels at photon rates of their own that change every sample): the same
    // events in the same order and, once the arrays are stored back, every field of every
    // pixel's state the same bits. x and nz among them, which the arrays leave unwritten with
    // the source follower alone (BlockSoA::sf_only: z is x there, and nz 0, on every path);
    // and the terms the pass takes ready-made
    // (BlockSoA::leak_g, bg_on_rate, bg_off_rate) reach the clocks and references.
    // Twice: own rates all different at a steady 1 ms; and own rates from a set of three, the
    // same for runs of pixels and of samples, with every fifth interval 0.5 ms, so a pixel's
    // rate is often the previous own-rate pixel's, or the rate the last sample ended on under
    // a new dt (step_block_soa's fills listed ahead of its loop: which numbers each reuses).
    struct Ev {
        double t;
        std::uint32_t pixel;
        int pol;
        bool operator==(const Ev& o) const { return t == o.t && pixel == o.pixel && pol == o.pol; }
    };
    // words: whether the kept random words count. A noiseless pixel's block kernels draw none
    // (they would only feed its normals), where advance() keeps its sample's words anyway:
    // words tagged with their sample, so either way every later draw is the same.
    // Three chains: the source follower alone, behind the pole, and neither (noiseless: the
    // ideal pixel, which takes the source follower's arrays with its decay and ramp at 0).
    for (int chain : {0, 1, 2})
    for (bool repeats : {false, true}) {
        const bool pole = chain == 1;
        PixelParams p;
        p.threshold_sigma = 0.03;
        p.cutoff_hz = 10.0;
        p.pr_pole = pole;
        if (chain == 2) {
            p.cutoff_hz.reset();
            p.photon_shot_noise = false;
            p.dark_model = DarkModel::None;
        }
        const BlockModel model(p);
        CHECK(model.has_soa_kernel());
        const Philox4x32Key key{11u, 12u};
        const std::size_t n = 203;  // not a multiple of a vector
        const int samples = 400;
        std::vector<PixelState> per_pixel(n), block;
        std::vector<std::uint32_t> ids(n);
        std::vector<float> rate(n);
        const float own_set[3] = {3e6f, 1.5e6f, 5e6f};
        const auto rates_at = [&](int k) {
            for (std::size_t j = 0; j < n; ++j)
                rate[j] = j % 4 != 3 ? 2e6f
                          : repeats  ? own_set[(static_cast<std::size_t>(k / 7) + j / 64) % 3]
                                     : static_cast<float>(2e6 * (1.0 + 0.5 * std::sin(0.05 * k + static_cast<double>(j))));
        };
        std::vector<double> t_at(samples, 0.0);  // the samples' end times
        for (int k = 1; k < samples; ++k) t_at[k] = t_at[k - 1] + (repeats && k % 5 == 0 ? 0.5e-3 : 1e-3);
        std::vector<Ev> want, got;
        std::uint32_t pixel = 0;
        auto emit_want = [&](double t, Polarity pol, std::uint8_t) { want.push_back({t, pixel, static_cast<int>(pol)}); };
        auto emit_got = [&](double t, Polarity pol, std::uint8_t) { got.push_back({t, pixel, static_cast<int>(pol)}); };
        PoissonSampler poisson;
        NoiseCache cache;
        BlockModel::BlockScratch scratch;
        BlockSoA h;
        // The first sample starts every pixel (as Sensor::run's does); then both paths.
        rates_at(0);
        for (std::size_t j = 0; j < n; ++j) {
            ids[j] = static_cast<std::uint32_t>(j);
            model.init_pixel(per_pixel[j], key, ids[j]);
            pixel = ids[j];
            model.advance(per_pixel[j], rate[j], model.constants(-1e-3, 0.0), key, ids[j], poisson, cache, emit_want);
        }
        block = per_pixel;
        h.load(block.data(), n);
        std::size_t n_busy = 0;
        for (int k = 1; k < samples; ++k) {
            rates_at(k);
            const SampleConstants c = model.constants(t_at[k - 1], t_at[k]);
            for (std::size_t j = 0; j < n; ++j) {
                pixel = ids[j];
                model.advance(per_pixel[j], rate[j], c, key, ids[j], poisson, cache, emit_want);
            }
            n_busy += model.step_block_soa(h, block.data(), ids.data(), n, rate.data(), c, key, scratch, emit_got, pixel);
        }
        h.store(block.data(), n, t_at[samples - 1]);
        CHECK(n_busy > 0 && !want.empty());  // the per-pixel path and the comparator were reached
        CHECK(got == want);
        std::size_t differ = 0;
        std::size_t off_invariant = 0;  // the source follower alone: z is x, nz is 0
        for (std::size_t j = 0; j < n; ++j) {
            differ += !same_state(block[j], per_pixel[j], model.draws_normals());
            off_invariant += !pole && !(per_pixel[j].z == per_pixel[j].x && per_pixel[j].nz == 0.0);
        }
        CHECK(differ == 0);
        CHECK(off_invariant == 0);
        std::printf("  %s%s: %zu events, %zu per-pixel steps, %zu states differ\n",
                    chain == 0 ? "source follower" : chain == 1 ? "pole" : "no filter",
                    repeats ? ", repeated own rates" : "", want.size(), n_busy, differ);
    }
}
