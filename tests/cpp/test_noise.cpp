// C++ tests of noise.hpp: the noise's exact coefficients, the leak hazard, the Brownian bridge.
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
