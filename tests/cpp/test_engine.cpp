// C++ tests of the pixel engine: analytic cases, determinism, bad input.
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
#include "noise_reference.hpp"

using namespace evstwin;

/// Uniforms in (0, 1) from xorshift64 (Marsaglia 2003), 53 bits each: test inputs that do
/// not share the engine's Philox streams.
struct XorshiftUniform {
    std::uint64_t state;
    double operator()() {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        return (static_cast<double>(state >> 11) + 0.5) * 0x1p-53;
    }
};

static PixelParams ideal() {
    PixelParams p;
    p.photon_shot_noise = false;
    p.dark_model = DarkModel::None;
    p.leak_rate_hz = 0.0;
    p.shot_noise_rate_hz = 0.0;
    p.cutoff_hz.reset();
    p.refractory_s = 0.0;
    p.theta_on = p.theta_off = 0.2;
    return p;
}

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

TEST(noise_coefficients_compose_and_reach_the_stationary_law) {
    // Exact discretisation: two steps of T are one step of 2T (Phi(2T) = Phi(T)^2 and
    // Q(2T) = Phi Q Phi^T + Q), and a long step reaches the stationary covariance.
    const double a = 300.0, b = 62.8, D = 1e-4;
    for (double T : {1e-4, 4e-3, 0.05}) {
        const NoiseCoeffs k1 = noise_coeffs(a, b, D, T), k2 = noise_coeffs(a, b, D, 2 * T);
        const double qzz = k1.l_zz * k1.l_zz, qzy = k1.l_zz * k1.l_yz, qyy = k1.l_yz * k1.l_yz + k1.l_yy * k1.l_yy;
        const double Pzz = k1.phi_zz, Pyz = k1.phi_yz, Pyy = k1.phi_yy;
        CHECK_NEAR(k2.phi_zz, Pzz * Pzz, 1e-12);
        CHECK_NEAR(k2.phi_yy, Pyy * Pyy, 1e-12);
        CHECK_NEAR(k2.phi_yz, Pyz * Pzz + Pyy * Pyz, 1e-12);
        const double Azz = Pzz * qzz * Pzz + qzz;
        const double Azy = Pzz * (qzz * Pyz + qzy * Pyy) + qzy;
        const double Ayy = Pyz * (Pyz * qzz + Pyy * qzy) + Pyy * (Pyz * qzy + Pyy * qyy) + qyy;
        const double zz2 = k2.l_zz * k2.l_zz, zy2 = k2.l_zz * k2.l_yz, yy2 = k2.l_yz * k2.l_yz + k2.l_yy * k2.l_yy;
        CHECK_NEAR(zz2, Azz, 1e-9 * Azz);
        CHECK_NEAR(zy2, Azy, 1e-9 * std::fabs(Azy) + 1e-18);
        CHECK_NEAR(yy2, Ayy, 1e-9 * Ayy);
    }
    const NoiseCoeffs far = noise_coeffs(a, b, D, 10.0);
    double szz, szy, syy;
    noise_stationary(a, b, D, szz, szy, syy);
    CHECK_NEAR(far.l_zz * far.l_zz, szz, 1e-9 * szz);
    CHECK_NEAR(far.l_yz * far.l_yz + far.l_yy * far.l_yy, syy, 1e-9 * syy);
}

TEST(a_fast_pole_over_a_long_interval_keeps_finite_noise_coefficients) {
    // phi_yz = b (e^{-aT} - e^{-bT}) / (b - a), against that closed form in long double, on
    // both sides of a = b and where (a - b) T passes 709: a 4.3 pA pixel's 1 kHz/pA pole
    // (a = 26,830 /s) with a 2 kHz source follower over a 50 ms pre-roll sample gave
    // 0 x inf = NaN, and the pixel never fired again.
    const double D = 1e-4;
    const double cases[][3] = {{26830.0, 12566.0, 0.05}, {3000.0, 1000.0, 1e-3}, {1000.0, 3000.0, 1e-3},
                               {12566.0, 26830.0, 0.05}, {4.4e6, 12566.0, 1e-3}, {300.0, 62.8, 10.0}};
    for (const auto& c : cases) {
        const double a = c[0], b = c[1], T = c[2];
        const NoiseCoeffs k = noise_coeffs(a, b, D, T);
        const long double la = a, lb = b, lT = T;
        const long double expect = lb * (std::exp(-la * lT) - std::exp(-lb * lT)) / (lb - la);
        CHECK(std::isfinite(k.phi_yz) && std::isfinite(k.l_zz) && std::isfinite(k.l_yz) && std::isfinite(k.l_yy) &&
              std::isfinite(k.bridge_var));
        CHECK_NEAR(k.phi_yz, static_cast<double>(expect), 1e-12 * std::fabs(static_cast<double>(expect)) + 1e-300);
    }
    // Every coefficient finite over pole rates 0.1 /s to 1e9 /s (0: no pole), source
    // followers 0.1 /s to 1e8 /s and intervals 0.1 us to 30 s.
    int bad = 0;
    for (double la = -1; la <= 9; la += 0.5)
        for (double lb = -1; lb <= 8; lb += 0.5)
            for (double lT = -7; lT <= 1.5; lT += 0.5)
                for (double a : {0.0, std::pow(10.0, la)}) {
                    const NoiseCoeffs k = noise_coeffs(a, std::pow(10.0, lb), D, std::pow(10.0, lT));
                    for (double v : {k.phi_zz, k.phi_yz, k.phi_yy, k.l_zz, k.l_yz, k.l_yy, k.bridge_var})
                        bad += !std::isfinite(v);
                }
    CHECK(bad == 0);
}

TEST(noise_coeffs_with_kept_source_follower_terms_are_the_same_bits) {
    // NoiseCache keeps sf_terms(b, T) per interval; the coefficients must not change by a bit,
    // for two poles (near-equal rates included), the source follower alone, and the pole alone.
    const auto same = [](const NoiseCoeffs& x, const NoiseCoeffs& y) {
        return std::memcmp(&x, &y, sizeof(NoiseCoeffs)) == 0;
    };
    int checked = 0;
    for (double T : {1e-5, 3.1e-4, 1e-3, 4e-3, 0.5})
        for (double b : {0.0, 62.83, 1256.6})
            for (double a : {0.0, 3.7, 62.83 * (1 + 1e-6), 2e4})
                for (double D : {1e-3, 55.0}) {
                    if (!(a > 0) && !(b > 0)) continue;
                    const SfTerms sf = sf_terms(b, T);
                    CHECK(same(noise_coeffs(a, b, D, T, &sf), noise_coeffs(a, b, D, T)));
                    const SfTerms other = sf_terms(b, 2 * T);  // for another interval: not used
                    CHECK(same(noise_coeffs(a, b, D, T, &other), noise_coeffs(a, b, D, T)));
                    ++checked;
                }
    CHECK(checked == 5 * 2 * 4 * 2 + 5 * 1 * 3 * 2);
}

TEST(noise_coeffs_with_kept_pole_terms_are_the_same_bits) {
    // PixelModel passes its noise-free chain's exp(-a T) and one_minus_exp_over(a T) on
    // (PoleTerms); noise_coeffs must give the bits it computes itself, and ignore terms of
    // another a or T (near-equal rates move a off b: the kept terms no longer apply).
    const auto same = [](const NoiseCoeffs& x, const NoiseCoeffs& y) {
        return std::memcmp(&x, &y, sizeof(NoiseCoeffs)) == 0;
    };
    int checked = 0;
    for (double T : {1e-5, 3.1e-4, 1e-3, 4e-3, 0.5})
        for (double b : {62.83, 12566.4})
            for (double a : {1e-3, 3.7, 62.83 * (1 + 1e-6), 2e4, 7.7e5})
                for (double D : {1e-3, 55.0}) {
                    const SfTerms sf = sf_terms(b, T);
                    const PoleTerms pole{a, T, std::exp(-(a * T)), one_minus_exp_over(a * T)};
                    CHECK(same(noise_coeffs(a, b, D, T, &sf, &pole), noise_coeffs(a, b, D, T)));
                    const PoleTerms wrong{a, T, 0.5, 0.25};  // deliberately not a's terms
                    const bool moved = detail::separated_pole_rate(a, b) != a;
                    CHECK(same(noise_coeffs(a, b, D, T, &sf, &wrong), noise_coeffs(a, b, D, T)) == moved);
                    NoiseCoeffs k = noise_coeffs_interval(a, b, D, T, &sf, &pole);
                    CHECK(k.bridge_var == 0.0);
                    noise_coeffs_bridge(k, a, b, D, T, &sf, &pole);
                    CHECK(same(k, noise_coeffs(a, b, D, T)));
                    ++checked;
                }
    CHECK(checked == 5 * 2 * 5 * 2);
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

TEST(bridge_var_is_below_twice_q_yy_wherever_bridge_var_bounded_says_so) {
    // The block kernels test a pixel at a rate of its own for quiet against twice q_yy before
    // computing bridge_var; that is exact only if the computed bridge_var never exceeds it.
    // In exact arithmetic bridge_var <= q_yy; over a, b from 1e-6 to 1e8 /s and T from 1e-9 to
    // 10 s, the computed ratio where bridge_var_bounded() holds, and that it fails where the
    // closed forms lose it (a == b, a T tiny), which is why the guard is there.
    double worst = 0.0;
    int bounded = 0, unbounded_bad = 0;
    for (int ia = 0; ia <= 56; ++ia)
        for (int ib = 0; ib <= 56; ++ib)
            for (int iT = 0; iT <= 40; ++iT) {
                const double a = std::pow(10.0, -6.0 + 0.25 * ia), b = std::pow(10.0, -6.0 + 0.25 * ib);
                const double T = std::pow(10.0, -9.0 + 0.25 * iT);
                const NoiseCoeffs k = noise_coeffs(a, b, 1.0, T);
                if (bridge_var_bounded(a, b, T)) {
                    ++bounded;
                    CHECK(k.q_yy > 0.0);
                    worst = std::max(worst, k.bridge_var / k.q_yy);
                } else if (!(k.bridge_var <= 2.0 * k.q_yy)) {
                    ++unbounded_bad;
                }
            }
    CHECK(bounded > 57 * 57 * 41 / 2);
    CHECK(worst > 0.2);           // the bound is not vacuous: bridge_var comes close to q_yy
    CHECK(worst <= 1.0 + 1e-6);   // and twice q_yy is never reached
    CHECK(unbounded_bad > 0);     // outside the guard the closed forms do break it
}

TEST(leak_noise_hazard_against_quadrature_of_its_rate) {
    // The closed forms (E1 by A&S 5.1.56, erfc) against a fine Simpson rule over the rate the
    // header documents, for one pole, two comparable poles and a << b, and additivity.
    const double pi = 3.14159265358979323846;
    auto phi = [&](double x) { return std::exp(-0.5 * x * x) / std::sqrt(2 * pi); };
    for (const auto& [a, b] : std::vector<std::pair<double, double>>{{0.0, 63.0}, {71.0, 63.0}, {1.0e4, 63.0}, {63.0, 4.0e3}}) {
        const double sd = 1.7e-3;
        const bool two = a > 0 && b > 0;
        const double c = two ? std::min(a, b) : (a > 0 ? a : b);
        const double k = two ? std::sqrt(a * b / (2 * pi)) : 1e300;
        auto rate = [&](double x) {
            if (x < 1.5) return std::min(k * phi(1.5), 0.2167 * c);
            return x < std::max(k / c, 1.5) ? c * x * phi(x) * x * x / (x * x + 1) : k * phi(x);
        };
        for (const auto& [x1, x0] : std::vector<std::pair<double, double>>{{-2.0, 0.5}, {0.0, 3.0}, {2.0, 6.0}, {-1.0, 40.0}}) {
            const int n = 200000;  // Simpson over [x1, min(x0, 12)]; beyond 12 the rate is < 1e-30 c
            const double hi = std::min(x0, 12.0), h = (hi - x1) / n;
            double sum = rate(x1) + rate(hi);
            for (int i = 1; i < n; ++i) sum += (i % 2 ? 4 : 2) * rate(x1 + i * h);
            const double want = sd * sum * h / 3;
            const double got = LeakNoiseHazard(sd, a, b)(x1 * sd, x0 * sd);
            CHECK_NEAR(got, want, 2e-4 * want + 1e-12);
            const double mid = 0.5 * (x0 + x1) * sd;
            CHECK_NEAR(LeakNoiseHazard(sd, a, b)(x1 * sd, mid) + LeakNoiseHazard(sd, a, b)(mid, x0 * sd),
                       got, 1e-9 * got + 1e-15);
        }
    }
    CHECK(LeakNoiseHazard(1e-3, 10.0, 10.0)(0.01, 0.01) == 0.0);
}

TEST(brownian_bridge_crossing_probability_and_time_against_simulated_paths) {
    // Bridges from u0 = 1 to u1 = 1 below a level at 0 (distances), sigma^2 T = 1: crossing
    // probability exp(-2 u0 u1 / (sigma^2 T)); paths watched at m steps cross as often as a
    // continuous bridge whose distances are larger by 0.5826 sigma sqrt(T / m) (Broadie,
    // Glasserman & Kou 1997). And the first-passage quantiles: a share q of the crossing
    // paths has crossed by bridge_first_passage(..., q).
    const int paths = 10000, m = 2000;
    const double u0 = 1.0, u1 = 1.0, T = 1.0, h = T / m, shift = 0.5826 * std::sqrt(h);
    std::vector<double> first;
    for (int pth = 0; pth < paths; ++pth) {
        CounterStream words({3u, 4u}, static_cast<std::uint32_t>(pth), 0, 11u);
        auto more = [&] { return words.word(); };
        // A Brownian path from u0, then the bridge B(t) + (u1 - u0 - B(T)) t / T.
        std::vector<double> w(m + 1, 0.0);
        for (int i = 1; i <= m; ++i) w[i] = w[i - 1] + std::sqrt(h) * normal_ziggurat(words.word(), more);
        for (int i = 1; i < m; ++i) {
            const double t = i * h;
            if (u0 + w[i] + (u1 - u0 - w[m]) * t / T <= 0.0) {
                first.push_back(t);
                break;
            }
        }
    }
    const double p_cont = bridge_crossing_probability(u0 + shift, u1 + shift, 0.25 * T);
    const double p_mc = double(first.size()) / paths;
    CHECK_NEAR(p_mc, p_cont, 5.0 * std::sqrt(p_cont * (1 - p_cont) / paths));
    CHECK(std::fabs(bridge_crossing_probability(u0, u1, 0.25 * T) - std::exp(-2.0)) < 1e-12);
    for (double q : {0.25, 0.5, 0.75}) {
        const double tq = bridge_first_passage(u0, u1, 1.0, T, q);
        std::size_t k = 0;
        for (double t : first) k += t <= tq;
        const double share = double(k) / first.size();
        CHECK_NEAR(share, q, 5.0 * std::sqrt(q * (1 - q) / first.size()) + 0.02);
    }
}

TEST(bridge_first_passage_sample_has_the_law_bridge_first_passage_inverts) {
    // The engine draws a crossing's time by the inverse-Gaussian construction; the bisection of
    // the closed-form CDF (checked against simulated paths above) is the independent reference:
    // a share q of the draws must lie below its q-quantile, for near and far levels, equal and
    // unequal ends, and an end almost on the level (u1 -> 0, the Levy limit).
    struct Case { double u0, u1, sigma2, T; };
    for (const Case& k : {Case{1.0, 1.0, 1.0, 1.0}, Case{0.3, 2.0, 4.0, 1e-3}, Case{2.0, 0.1, 1.0, 0.5},
                          Case{0.05, 1e-12, 0.01, 2.0}}) {
        const int n = 20000;
        std::vector<double> draws(n);
        for (int i = 0; i < n; ++i) {
            CounterStream more({5u, 6u}, static_cast<std::uint32_t>(i), 0, 21u);
            const double g = normal_ziggurat(more.word(), [&more] { return more.word(); });
            draws[i] = bridge_first_passage_sample(k.u0, k.u1, k.sigma2, k.T, g, more.uniform());
            CHECK(draws[i] >= 0.0 && draws[i] <= k.T);
        }
        for (double q : {0.05, 0.25, 0.5, 0.75, 0.95}) {
            const double tq = bridge_first_passage(k.u0, k.u1, k.sigma2, k.T, q);
            std::size_t below = 0;
            for (double t : draws) below += t <= tq;
            CHECK_NEAR(double(below) / n, q, 5.0 * std::sqrt(q * (1 - q) / n));
        }
    }
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
    const auto same = [](const PixelState& a, const PixelState& b, bool words) {
        const auto bits = [](const auto& u, const auto& v) { return std::memcmp(&u, &v, sizeof u) == 0; };
        return bits(a.x, b.x) && bits(a.z, b.z) && bits(a.y, b.y) && bits(a.ref, b.ref) &&
               bits(a.refr_until, b.refr_until) && bits(a.theta_on, b.theta_on) && bits(a.theta_off, b.theta_off) &&
               bits(a.t, b.t) && a.n == b.n &&
               (!words || (a.spare_words == b.spare_words && a.spare_sample == b.spare_sample)) &&
               bits(a.nz, b.nz) && bits(a.ny, b.ny) && bits(a.level_at_event, b.level_at_event) &&
               bits(a.noise_at_event, b.noise_at_event) && bits(a.leak_spread, b.leak_spread) &&
               bits(a.bg_on_hz, b.bg_on_hz) && bits(a.bg_off_hz, b.bg_off_hz) && bits(a.hot_hz, b.hot_hz) &&
               bits(a.next_hot_t, b.next_hot_t) && bits(a.hot_event_t, b.hot_event_t) &&
               bits(a.hot_switch_t, b.hot_switch_t) && bits(a.hot_last_t, b.hot_last_t) && a.hot_count == b.hot_count &&
               a.hot_switches == b.hot_switches && a.hot_pol == b.hot_pol && a.hot_active == b.hot_active &&
               a.hot_chain == b.hot_chain && bits(a.bg_clock_on, b.bg_clock_on) && bits(a.bg_clock_off, b.bg_clock_off);
    };
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
            differ += !same(block[j], per_pixel[j], model.draws_normals());
            off_invariant += !pole && !(per_pixel[j].z == per_pixel[j].x && per_pixel[j].nz == 0.0);
        }
        CHECK(differ == 0);
        CHECK(off_invariant == 0);
        std::printf("  %s%s: %zu events, %zu per-pixel steps, %zu states differ\n",
                    chain == 0 ? "source follower" : chain == 1 ? "pole" : "no filter",
                    repeats ? ", repeated own rates" : "", want.size(), n_busy, differ);
    }
}

TEST(a_leak_grows_with_the_photocurrent_and_fires_its_own_polarity) {
    // A noise-free static pixel: the reference drifts one threshold per leak period, so it
    // fires floor(f T) events in T, f = leak_rate_hz + k e electrons_per_photon rate (the
    // photocurrent part 6x the dark part here), ON or OFF as leak_polarity says.
    for (LeakPolarity pol : {LeakPolarity::On, LeakPolarity::Off})
        for (NoiseModel model : {NoiseModel::Continuous, NoiseModel::Sampled}) {
            PixelParams p = ideal();
            p.leak_random_phase = false;
            p.leak_rate_hz = 0.5;
            p.leak_photocurrent_hz_per_a = 1e15;
            p.leak_polarity = pol;
            p.noise_model = model;
            const double rate = 3.6e7;
            const double f = 0.5 + 1e15 * ELEMENTARY_CHARGE_C * p.electrons_per_photon() * rate;
            CHECK(f > 3.0 && f < 4.0);
            Sensor s(2, 1, p);
            std::vector<double> rates, t;
            for (int k = 0; k <= 1015; ++k) {
                t.push_back(k * 0.01);
                rates.push_back(rate);
                rates.push_back(rate);
            }
            const auto ev = s.run(rates.data(), t.data(), t.size());
            CHECK(ev.size() == 2 * static_cast<std::size_t>(std::floor(f * 10.15)));
            for (const auto& e : ev) CHECK(e.p == (pol == LeakPolarity::On ? ON : OFF));
        }
}

TEST(step_gives_floor_ln_r_over_theta_events) {
    for (double R : {1.5, 3.0, 10.0, 0.1}) {
        Sensor s(1, 1, ideal());
        const double rate[2] = {1e8, 1e8 * R};
        const double t[2] = {0.0, 1e-3};
        auto ev = s.run(rate, t, 2);
        const std::size_t expect = static_cast<std::size_t>(std::floor(std::fabs(std::log(R)) / 0.2));
        CHECK(ev.size() == expect);
        for (auto& e : ev) CHECK(e.p == (R > 1 ? ON : OFF));
    }
}

TEST(exponential_ramp_crossings_at_analytic_times) {
    // ln(rate) rises by g per second: crossing n at n theta / g.
    const double g = 50.0, theta = 0.2;
    Sensor s(1, 1, ideal());
    std::vector<double> rate, t;
    for (int k = 0; k <= 100; ++k) {
        t.push_back(k * 1e-3);
        rate.push_back(1e8 * std::exp(g * t.back()));
    }
    auto ev = s.run(rate.data(), t.data(), t.size());
    CHECK(ev.size() == static_cast<std::size_t>(std::floor(g * 0.1 / theta + 1e-9)));
    for (std::size_t n = 0; n < ev.size(); ++n) CHECK_NEAR(double(ev[n].t), (n + 1) * theta / g * 1e6, 0.5);
}

TEST(build_without_openmp_or_one_thread_matches_two_threads) {
    PixelParams p;  // all noise on
    p.threshold_sigma = 0.05;
    p.leak_rate_hz = 5.0;
    p.shot_noise_rate_hz = 2.0;
    const int w = 40, h = 30;
    std::vector<double> rate(20 * w * h), t(20);
    for (int k = 0; k < 20; ++k) {
        t[k] = k * 1e-3;
        for (int i = 0; i < w * h; ++i) rate[k * w * h + i] = 1e6 * (1.0 + (i % 7) * (k % 3));
    }
    Sensor a(w, h, p, 7, 1), b(w, h, p, 7, 2);
    auto ea = a.run(rate.data(), t.data(), 20);
    auto eb = b.run(rate.data(), t.data(), 10);
    auto eb2 = b.run(rate.data() + 10 * w * h, t.data() + 10, 10);
    eb.insert(eb.end(), eb2.begin(), eb2.end());
    CHECK(!ea.empty());
    CHECK(ea.size() == eb.size());
    CHECK(ea.size() == eb.size() && std::memcmp(ea.data(), eb.data(), ea.size() * sizeof(Event)) == 0);
}

TEST(every_kernel_gives_the_same_events) {
    // Kernel::Auto, PerPixel, Blocks and Vector on the same calls (run, then run_pixels on a
    // patch, then run again, where the patch's pixels stand apart), for the sampled model, the
    // continuous one and the continuous one with the pole (the last call's events follow from
    // the state the others left): the same events.
    for (int config = 0; config < 3; ++config) {
        PixelParams p;  // all noise on
        p.threshold_sigma = 0.04;
        p.leak_rate_hz = 2.0;
        p.shot_noise_rate_hz = 1.0;
        p.noise_model = config == 0 ? NoiseModel::Sampled : NoiseModel::Continuous;
        p.pr_pole = config == 2;
        p.cutoff_hz = 2000.0;
        const int w = 64, h = 16, n = 12;
        std::vector<float> rate(static_cast<std::size_t>(n) * w * h);
        // A fifth of the pixels blink (x3 every other sample: events at every sample), the rest
        // sit at the common rate (the vector kernel's quiet pass).
        for (std::size_t i = 0; i < rate.size(); ++i)
            rate[i] = (i % 5 == 0 && (i / (w * h)) % 2 == 1) ? 6e6f : 2e6f;
        if (p.pr_pole)  // 100 x the light: a pole of a few kHz, not ~30 Hz
            for (float& r : rate) r *= 100.0f;
        std::vector<double> t(n), tp(3);
        for (int k = 0; k < n; ++k) t[k] = (k + 1) * 1e-3;
        std::vector<std::uint32_t> patch;
        for (std::uint32_t i = 100; i < 400; i += 3) patch.push_back(i);
        std::vector<float> prate(3 * patch.size(), 3e6f);
        for (int k = 0; k < 3; ++k) tp[k] = t[n - 1] + (k + 1) * 3e-4;
        std::vector<double> t2(n);
        for (int k = 0; k < n; ++k) t2[k] = t[n - 1] + (k + 1) * 1e-3;
        std::vector<std::vector<Event>> got;
        for (Kernel k : {Kernel::Auto, Kernel::PerPixel, Kernel::Blocks, Kernel::Vector}) {
            Sensor s(w, h, p, 11, 1);
            s.set_kernel(k);
            CHECK(s.kernel() == k);
            auto e = s.run(rate.data(), t.data(), n);
            const auto e2 = s.run_pixels(patch.data(), patch.size(), prate.data(), tp.data(), 3);
            const auto e3 = s.run(rate.data(), t2.data(), n);
            e.insert(e.end(), e2.begin(), e2.end());
            e.insert(e.end(), e3.begin(), e3.end());
            got.push_back(e);
        }
        CHECK(got[0].size() > 500);
        for (std::size_t k = 1; k < got.size(); ++k)
            CHECK(got[k].size() == got[0].size() &&
                  std::memcmp(got[k].data(), got[0].data(), got[0].size() * sizeof(Event)) == 0);
    }
    Sensor s(4, 4, PixelParams{}, 1, 1);
    CHECK_THROWS(s.set_kernel(static_cast<Kernel>(7)));
    CHECK(s.kernel() == Kernel::Auto);
}

TEST(samples_with_thousands_of_events_come_out_as_the_comparison_sort_orders_them) {
    // The event-heavy load's samples (thousands of events each, so the counting sort stages
    // them by coarse spans of time first) against run_pixels over every pixel in order, whose
    // events are sorted by (microsecond, pixel) with std::stable_sort: the same bytes, on one
    // thread and on two, and time then pixel order within every interval. And against
    // Kernel::PerPixel, which takes the per-pixel path (advance) for every pixel, without the
    // block kernel's buffered emit (BufferedEmit: dozens of events a pass, each with its pixel).
    PixelParams p;  // all noise on
    p.threshold_sigma = 0.03;
    p.cutoff_hz = 200.0;
    const int w = 128, h = 64, n = 12;
    std::vector<float> rate(static_cast<std::size_t>(n) * w * h, 2e6f);
    std::vector<double> t(n);
    for (int k = 0; k < n; ++k) t[k] = (k + 1) * 1e-3;
    std::vector<std::uint32_t> all(static_cast<std::size_t>(w) * h);
    for (std::size_t i = 0; i < all.size(); ++i) all[i] = static_cast<std::uint32_t>(i);
    Sensor a(w, h, p, 5, 1), b(w, h, p, 5, 2), c(w, h, p, 5, 1), d(w, h, p, 5, 1);
    const auto ea = a.run(rate.data(), t.data(), n);
    const auto eb = b.run(rate.data(), t.data(), n);
    const auto ec = c.run_pixels(all.data(), all.size(), rate.data(), t.data(), n);
    d.set_kernel(Kernel::PerPixel);
    const auto ed = d.run(rate.data(), t.data(), n);
    CHECK(ea.size() == ed.size() && std::memcmp(ea.data(), ed.data(), ea.size() * sizeof(Event)) == 0);
    CHECK(ea.size() > 2 * 2048 * (n - 1));  // samples far above STAGED_MIN_EVENTS (2048)
    CHECK(ea.size() == eb.size() && std::memcmp(ea.data(), eb.data(), ea.size() * sizeof(Event)) == 0);
    CHECK(ea.size() == ec.size() && std::memcmp(ea.data(), ec.data(), ea.size() * sizeof(Event)) == 0);
    int out_of_order = 0;
    for (std::size_t e = 1; e < ea.size(); ++e) {
        const std::int64_t pix0 = std::int64_t{ea[e - 1].y} * w + ea[e - 1].x, pix1 = std::int64_t{ea[e].y} * w + ea[e].x;
        const bool at_sample_time = ea[e].t % 1000 == 0;
        out_of_order += ea[e].t < ea[e - 1].t || (ea[e].t == ea[e - 1].t && pix1 < pix0 && !at_sample_time);
    }
    CHECK(out_of_order == 0);
}

TEST(leak_events_keep_their_times_far_from_zero_after_sample_intervals_of_hours) {
    // The working records keep an event's microsecond modulo 2^32 and take the rest from its
    // sample's end; an event more than 2^31 us before that end makes its block keep full
    // times. Leak events every 900 s over a 5000 s interval, with the times based near -2^62 us
    // (where a sentinel of -2^62 once aliased a real time) and at +5e12 s (where the
    // difference from it overflowed): every event at its analytic time (ulp of t ~1 ms there).
    PixelParams p = ideal();
    p.leak_rate_hz = 1.0 / 900.0;
    p.leak_random_phase = false;
    for (const double t0 : {-4611686018427.387904 - 6000.0, 0.0, 5e12, -5e12}) {
        Sensor s(1, 1, p, 1, 1);
        const double t[4] = {t0, t0 + 1000.0, t0 + 6000.0, t0 + 6400.0};
        const float rate[4] = {1e9f, 1e9f, 1e9f, 1e9f};
        const auto ev = s.run(rate, t, 4);
        CHECK(ev.size() == 7);  // 900 s ... 6300 s
        for (std::size_t k = 0; k < ev.size(); ++k) CHECK_NEAR(double(ev[k].t) * 1e-6, t0 + (k + 1) * 900.0, 0.01);
    }
}

TEST(run_into_writes_the_events_of_run_into_the_callers_memory) {
    PixelParams p;  // all noise on
    p.threshold_sigma = 0.05;
    p.leak_rate_hz = 5.0;
    const int w = 24, h = 16, n = 12;
    std::vector<double> rate(n * w * h), t(n);
    for (int k = 0; k < n; ++k) {
        t[k] = k * 1e-3;
        for (int i = 0; i < w * h; ++i) rate[k * w * h + i] = 1e6 * (1.0 + (i % 5) * (k % 4));
    }
    Sensor a(w, h, p, 11, 2), b(w, h, p, 11, 2);
    const auto want = a.run(rate.data(), t.data(), n);
    // Room with a guard word after it: the engine writes exactly the count it asked for.
    std::vector<Event> room;
    int calls = 0;
    const std::size_t got = b.run_into(
        [&](std::size_t m) {
            ++calls;
            room.assign(m + 1, Event{-7, 7, 7, 7});
            return room.data();
        },
        rate.data(), t.data(), n);
    CHECK(!want.empty());
    CHECK(calls == 1 && got == want.size() && room.size() == want.size() + 1);
    CHECK(got == want.size() && std::memcmp(room.data(), want.data(), got * sizeof(Event)) == 0);
    CHECK(room.back().t == -7 && room.back().x == 7);
    // A call without events does not ask for room.
    Sensor quiet(w, h, ideal(), 11);
    std::vector<double> flat(2 * w * h, 1e6), t2{0.0, 1e-3};
    calls = 0;
    CHECK(quiet.run_into([&](std::size_t) { ++calls; return room.data(); }, flat.data(), t2.data(), 2) == 0);
    CHECK(calls == 0);
}

TEST(bad_input_throws_before_changing_state) {
    Sensor s(2, 1, ideal());
    const double rate[2] = {1e6, -1.0};
    const double t[1] = {0.0};
    CHECK_THROWS(s.run(rate, t, 1));
    CHECK(s.samples_seen() == 0);
    const double t2[2] = {0.0, 0.0};
    const double rate2[4] = {1, 1, 1, 1};
    CHECK_THROWS(s.run(rate2, t2, 2));
    PixelParams p = ideal();
    p.theta_on = 0.0;
    CHECK_THROWS(Sensor(1, 1, p));
    p = ideal();
    p.refractory_s = -1e-3;
    CHECK_THROWS(Sensor(1, 1, p));
    CHECK_THROWS(Sensor(0, 1, ideal()));
}

TEST(huge_mean_counts_stay_defined) {
    // 1e20 photons/s over samples a year long: a Poisson mean far above 2^64 electrons. The
    // count must saturate, not overflow (undefined behaviour, caught by the sanitizer build).
    PixelParams p;  // photon shot noise and dark current on; eq. 12-15 noise off (it bounds dt)
    p.shot_noise_rate_hz = 0.0;
    Sensor s(2, 1, p, 3, 1);
    const double rate[6] = {1e20, 1e20, 1e6, 1e20, 1e20, 1e20};
    const double t[3] = {0.0, 3.2e7, 6.4e7};
    auto ev = s.run(rate, t, 3);
    for (auto& e : ev) CHECK(e.x < 2 && e.y == 0);
}

TEST(limits_are_refused_up_front) {
    // Issue 11: the OpenMP runtime crashes or exits at thousands of threads; a 30000 x 30000
    // sensor failed in the allocation after minutes.
    CHECK_THROWS(Sensor(4, 4, ideal(), 0, Sensor::MAX_THREADS + 1));
    CHECK_THROWS(Sensor(4, 4, ideal(), 0, 100000));
    Sensor ok(4, 4, ideal(), 0, Sensor::MAX_THREADS);
    CHECK(ok.num_threads() == Sensor::MAX_THREADS);
    CHECK_THROWS(Sensor(30000, 30000, ideal()));
    CHECK_THROWS(ok.set_max_events(0));
    CHECK_THROWS(ok.set_max_events(std::size_t{1} << 32));
    // Times beyond int64 microseconds are refused by run_pixels as by run.
    const std::uint32_t px[1] = {0};
    const double rate[1] = {1e6}, t[1] = {1e13};
    CHECK_THROWS(ok.run_pixels(px, 1, rate, t, 1));
    CHECK_THROWS(ok.run(rate, t, 1));
    // float(1e20) rounds up to 1.00000002e20: above the limit, as the double is.
    const float big[16] = {1e20f, 1e20f, 1e20f, 1e20f, 1e20f, 1e20f, 1e20f, 1e20f,
                           1e20f, 1e20f, 1e20f, 1e20f, 1e20f, 1e20f, 1e20f, 1e20f};
    const double t1[1] = {1e-3};
    CHECK_THROWS(ok.run(big, t1, 1));
    // A probe pixel listed twice would leave one trace column empty.
    std::vector<std::uint32_t> probe{1, 1};
    std::vector<TraceSample> trace;
    const double r16[16] = {1e6, 1e6, 1e6, 1e6, 1e6, 1e6, 1e6, 1e6, 1e6, 1e6, 1e6, 1e6, 1e6, 1e6, 1e6, 1e6};
    CHECK_THROWS(ok.run(r16, t1, 1, &probe, &trace));
    CHECK(ok.samples_seen() == 0);
}

/// Rates that jump between lo and hi every sample (the first sample only sets the state).
static std::vector<Event> jumps(Sensor& s, int n_samples, double lo, double hi) {
    const std::size_t npix = s.num_pixels();
    std::vector<double> rate(n_samples * npix), t(n_samples);
    for (int k = 0; k < n_samples; ++k) {
        t[k] = (k + 1) * 1e-3;
        for (std::size_t i = 0; i < npix; ++i) rate[k * npix + i] = k % 2 ? hi : lo;
    }
    return s.run(rate.data(), t.data(), t.size());
}

TEST(max_events_stops_a_flood_the_same_way_on_any_thread_count) {
    // Issue 11's flood: theta 1e-3, no refractory period, rates jumping 1e-30 <-> 1e20: about
    // 3.5e4 events per pixel and jump, 1e8 for these 1024 pixels and 3 jumps without the cap.
    PixelParams p = ideal();
    p.theta_on = p.theta_off = 1e-3;
    for (int threads : {1, 2, 4}) {
        Sensor s(32, 32, p, 0, threads);
        s.set_max_events(100000);
        bool thrown = false;
        try {
            jumps(s, 4, 1e-30, 1e20);
        } catch (const std::length_error& e) {
            thrown = std::string(e.what()).find("max_events=100000") != std::string::npos;
        }
        CHECK(thrown);
        // The pixels are half advanced: the sensor refuses to go on until reset.
        bool refused = false;
        try {
            jumps(s, 2, 1e6, 1e8);
        } catch (const std::logic_error& e) {
            refused = std::string(e.what()).find("reset()") != std::string::npos;
        }
        CHECK(refused);
        s.reset();
        s.set_max_events(1000000);
        p.theta_on = p.theta_off = 1e-2;  // ln 100 / 0.01: 460 events a pixel, 4.7e5 in all
        Sensor after(32, 32, p, 0, threads), fresh(32, 32, p, 0, 1);
        after.set_max_events(1000000);
        auto a = jumps(after, 2, 1e6, 1e8), b = jumps(fresh, 2, 1e6, 1e8);
        CHECK(a.size() > 400000 && a.size() == b.size() &&
              std::memcmp(a.data(), b.data(), a.size() * sizeof(Event)) == 0);
        jumps(s, 2, 1e6, 1e6);  // usable again after reset
        CHECK(s.samples_seen() == 2);
    }
}

TEST(pixel_divider_is_the_exact_division_for_every_row_width) {
    // collect_sample's (x, y) of an event: the multiply-shift quotient against / and % for
    // every width the sensor accepts, at the ends of the index range, around multiples of the
    // width (where a rounding error would show first) and at pseudo-random indices.
    constexpr std::uint32_t top = (std::uint32_t{1} << detail::PixelDivider::INDEX_BITS) - 1;
    std::uint64_t state = 88172645463325252ull;
    int wrong = 0;
    for (std::uint32_t d = 1; d <= 65535; ++d) {
        const detail::PixelDivider div(d);
        const std::uint32_t last_multiple = top / d * d;
        const std::uint32_t ns[] = {0, 1, d - 1, d, d + 1, top, top - 1, last_multiple, last_multiple - 1,
                                    last_multiple - d, last_multiple - d + 1};
        for (std::uint32_t n : ns)
            if (n <= top && div.quotient(n) != n / d) ++wrong;
        for (int r = 0; r < 8; ++r) {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            const std::uint32_t n = static_cast<std::uint32_t>(state) & top;
            if (div.quotient(n) != n / d) ++wrong;
        }
    }
    CHECK(wrong == 0);
    CHECK_THROWS(detail::PixelDivider(0));
    CHECK_THROWS(detail::PixelDivider(65536));
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

TEST(below_exp_neg_decides_as_the_library_exp) {
    // init_state's leak-phase acceptance, u < exp(-e), decided on bounds where it can be (above
    // e = 24 against uniform_open's least value, on [0, 24] against exp_neg_bracket), against
    // the library's exp: random exponents over [0, 60] and far beyond with random uniforms;
    // uniforms placed within a relative 1e-12 to 1e-6 of exp(-e) (where only the exp can
    // decide); exponents next to 24; uniform_open's least and greatest values; uniforms below
    // 2^-33 (not uniform_open's, still decided as the exp); negative, infinite and NaN exponents
    // and a NaN uniform.
    XorshiftUniform next{0x2545F4914F6CDD1Dull};
    const auto exact = [](double u, double e) { return u < std::exp(-e); };
    const double inf = std::numeric_limits<double>::infinity(), nan = std::numeric_limits<double>::quiet_NaN();
    int wrong = 0, near_ties = 0, cases = 0;
    const auto check = [&](double u, double e) {
        wrong += detail::below_exp_neg(u, e) != exact(u, e);
        ++cases;
    };
    for (int i = 0; i < 400000; ++i) {
        const double e = i % 8 == 7 ? std::exp(20.0 * next()) : 60.0 * next();
        double u = uniform_open(static_cast<std::uint32_t>(next() * 4294967296.0));
        if (i % 4 == 1) {
            u = std::exp(-e) * (1.0 + (next() - 0.5) * std::pow(10.0, -6.0 - 6.0 * next()));
            near_ties += e <= 24.0;
        }
        check(u, e);
    }
    const double u_min = uniform_open(0u), u_max = uniform_open(0xFFFFFFFFu);
    CHECK(u_min == 0x1p-33);
    for (double e = 23.9; e < 24.1; e = std::nextafter(e + 1e-4, inf)) {
        for (const double u : {u_min, std::nextafter(u_min, 1.0), u_max, std::exp(-e), std::nextafter(std::exp(-e), 0.0),
                               std::nextafter(std::exp(-e), 1.0), 1e-12, 0.0, -1.0})
            check(u, e);
        for (const double d : {0.0, -1.0, 1.0}) check(u_min, std::nextafter(24.0, 24.0 + d));
    }
    for (const double e : {0.0, -0.0, -1e-300, -0.5, -40.0, 40.0, 1e300, inf, -inf, nan})
        for (const double u : {u_min, 0.5, u_max, 1.0, 1e-20, 0.0, nan}) check(u, e);
    CHECK(wrong == 0);
    CHECK(near_ties > 30000);
    CHECK(cases > 400000);
}

TEST(floor_positive_and_select_give_the_library_floor_and_the_chosen_bits) {
    // floor_positive (the comparator's merged-levels count) against std::floor, bit for bit: on
    // integers and their neighbours, halves, a random spread of magnitudes, and where it hands
    // over to the library (0, -0, negatives, 2^52 and above, infinities, NaN).
    const auto same_bits = [](double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; };
    std::vector<double> xs = {0.0, -0.0, 0.5, 1.0, 1.5, 2.0, 1e-300, 4503599627370495.5, 4503599627370496.0,
                              4503599627370497.0, 1e300, -0.5, -1.0, -2.5,
                              std::numeric_limits<double>::infinity(), -std::numeric_limits<double>::infinity()};
    for (double k = 1.0; k < 1e15; k *= 3.7) {
        xs.push_back(k);
        xs.push_back(std::nextafter(k, 0.0));
        xs.push_back(std::nextafter(k, 1e300));
    }
    std::uint64_t state = 12345;
    for (int i = 0; i < 100000; ++i) {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        xs.push_back(std::ldexp(static_cast<double>(state >> 11), -53) * std::pow(10.0, static_cast<double>(i % 20) - 4.0));
    }
    int wrong = 0;
    for (const double x : xs) wrong += !same_bits(detail::floor_positive(x), std::floor(x));
    CHECK(wrong == 0);
    CHECK(std::isnan(detail::floor_positive(std::numeric_limits<double>::quiet_NaN())));
    // select: the chosen value's bits, whatever they are (signed zeros, infinities, NaN).
    const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
    CHECK(same_bits(detail::select(true, -0.0, 0.0), -0.0));
    CHECK(same_bits(detail::select(false, -0.0, 0.0), 0.0));
    CHECK(same_bits(detail::select(true, inf, nan), inf));
    CHECK(std::isnan(detail::select(false, inf, nan)));
    CHECK(same_bits(detail::select(false, 1.0, -3.25), -3.25));
}

TEST(bridge_fires_decides_as_the_exact_probabilities) {
    // Whether the bridge fires and at which level, against u < p_on + p_off and u < p_on with
    // bridge_crossing_probability, for random bridges and uniforms, and for uniforms placed
    // within a relative 1e-12 to 1e-6 of the sums (where the bracket cannot decide and the
    // exps must), distances beyond exp(-40) and a zero variance.
    XorshiftUniform next{0x9E3779B97F4A7C15ull};
    int wrong = 0, near_ties = 0;
    for (int i = 0; i < 200000; ++i) {
        const double mid = i % 1000 == 0 ? 0.0 : 1e-4 * next();
        const double on0 = 0.05 * next(), on1 = 0.05 * next(), off0 = 0.05 * next(), off1 = 0.05 * next();
        const double p_on = bridge_crossing_probability(on0, on1, mid);
        const double p_off = bridge_crossing_probability(off0, off1, mid);
        double u = uniform_open(static_cast<std::uint32_t>(next() * 4294967296.0));
        if (i % 4 == 1) u = (p_on + p_off) * (1.0 + (next() - 0.5) * std::pow(10.0, -6.0 - 6.0 * next()));
        if (i % 4 == 2) u = p_on * (1.0 + (next() - 0.5) * std::pow(10.0, -6.0 - 6.0 * next()));
        if (!(u > 0.0 && u < 1.0)) continue;
        near_ties += i % 4 == 1 || i % 4 == 2;
        bool on = false;
        const bool fires = detail::bridge_fires(u, on0, on1, off0, off1, mid, on);
        wrong += fires != (u < p_on + p_off) || (fires && on != (u < p_on));
    }
    CHECK(wrong == 0);
    CHECK(near_ties > 50000);
    // A NaN distance (never formed by the comparator) decides as the exact formula: no crossing.
    bool on = true;
    CHECK(!detail::bridge_fires(0.5, std::nan(""), 0.01, 0.01, 0.01, 1e-4, on) && !on);
}

TEST(hot_pixel_chains_of_their_own_leave_every_other_draw_alone) {
    // Every pixel hot at 300 Hz; pixel 5 gets an ON-only-ish chain of its own and pixel 9 the
    // params' own chain: pixel 9 and every pixel without a chain fire as without chains, bit
    // for bit, and pixel 5 fires ON a share ~0.95 (each polarity drawn afresh).
    PixelParams p = ideal();
    p.refractory_s = 1e-4;
    // The params' own chain is not the default one: its ON share, switches and telegraph are
    // drawn, so the pixels without a chain of their own exercise all of it.
    p.hot_pixel_duty = 0.3;
    p.hot_pixel_burst_s = 0.05;
    p.hot_pixel_on_share = 0.7;
    p.hot_pixel_alternation = 0.4;
    const std::vector<double> hot(16, 300.0);
    std::vector<double> t(1001), rate(16 * t.size(), 1e9);
    for (std::size_t i = 0; i < t.size(); ++i) t[i] = 0.01 * static_cast<double>(i);
    Sensor plain(4, 4, p, 3, 1), own(4, 4, p, 3, 2);
    plain.set_hot_pixel_rates(hot);
    own.set_hot_pixel_rates(hot);
    own.set_hot_pixel_chains({5, 9}, {HotPixelChain{1.0, 0.1, 0.95, 2 * 0.95 * 0.05}, hot_chain_of(p)});
    const auto a = plain.run(rate.data(), t.data(), t.size());
    const auto b = own.run(rate.data(), t.data(), t.size());
    std::vector<Event> a_rest, b_rest;
    double on = 0, n5 = 0;
    for (const Event& e : a) if (e.y * 4 + e.x != 5) a_rest.push_back(e);
    for (const Event& e : b) {
        if (e.y * 4 + e.x != 5) b_rest.push_back(e);
        else { n5 += 1; on += e.p; }
    }
    CHECK(a_rest.size() == b_rest.size() && !a_rest.empty());
    CHECK(std::memcmp(a_rest.data(), b_rest.data(), a_rest.size() * sizeof(Event)) == 0);
    CHECK(n5 > 1500);
    CHECK_NEAR(on / n5, 0.95, 5 * std::sqrt(0.95 * 0.05 / n5));
    // Bad chains are refused by name, before anything changes.
    CHECK_THROWS(own.set_hot_pixel_chains({16}, {hot_chain_of(p)}));
    CHECK_THROWS(own.set_hot_pixel_chains({3, 3}, {hot_chain_of(p), hot_chain_of(p)}));
    CHECK_THROWS(own.set_hot_pixel_chains({3}, {}));
    CHECK_THROWS(own.set_hot_pixel_chains({3}, {HotPixelChain{1.0, 0.1, 0.95, 0.5}}));
    std::string message;
    try {
        own.set_hot_pixel_chains({2, 3}, {hot_chain_of(p), HotPixelChain{0.0, 0.1, 0.5, 1.0}});
    } catch (const std::invalid_argument& e) {
        message = e.what();
    }
    CHECK(message.rfind("hot_pixel_chains[1].duty must be in", 0) == 0);
    // ... and refused before anything changed: the sensor run again from its start fires as before.
    own.reset();
    const auto again = own.run(rate.data(), t.data(), t.size());
    CHECK(again.size() == b.size() && std::memcmp(again.data(), b.data(), b.size() * sizeof(Event)) == 0);
}

// stamp.hpp: the PSF renderer's two loops, on values a hand can check (each sum and product
// exact in binary), and a term with a zero coefficient is not read at all (0 x NaN would be NaN).
TEST(psf_stamp_loops_by_hand) {
    // Table (3, 3, 1, 1): T[q, p] = 3 q + p.
    std::vector<double> table(3 * 3);
    for (std::size_t i = 0; i < table.size(); ++i) table[i] = static_cast<double>(i);
    const std::ptrdiff_t q[2] = {0, 1}, p[2] = {1, 0};
    const double a[2] = {0.5, 0.0}, b[2] = {0.25, 1.0}, flux[2] = {4.0, 2.0};
    std::vector<double> out(2);
    evstwin::bilinear_phase_mix(table.data(), 3, 1, q, p, a, b, flux, 2, out.data());
    // Source 0: (0.75 (0.5 * 1 + 0.5 * 2) + 0.25 (0.5 * 4 + 0.5 * 5)) * 4 = (1.125 + 1.125) * 4.
    CHECK(out[0] == 9.0);
    // Source 1: b = 1, a = 0: T[2, 0] * 2.
    CHECK(out[1] == 12.0);

    double image[2][3] = {{1, 1, 1}, {1, 1, 1}};
    const double t0[2][4] = {{1, 2, 3, 99}, {4, 5, 6, 99}};  // a row stride of 4
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double t1[2][3] = {{nan, nan, nan}, {nan, nan, nan}};
    const double t2[2][3] = {{0.5, 0.5, 0.5}, {1, 1, 1}};
    const double* terms[3] = {&t0[0][0], &t1[0][0], &t2[0][0]};
    const std::ptrdiff_t strides[3] = {4, 3, 3};
    const double coef[3] = {2.0, 0.0, 4.0};
    evstwin::add_scaled_terms(&image[0][0], 3, terms, strides, coef, 3, 2, 3);
    CHECK(image[0][0] == 5.0 && image[0][1] == 7.0 && image[0][2] == 9.0);     // 1 + 2 t0 + 4 * 0.5
    CHECK(image[1][0] == 13.0 && image[1][1] == 15.0 && image[1][2] == 17.0);  // 1 + 2 t0 + 4
}

TEST_MAIN()
