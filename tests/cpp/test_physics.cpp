// C++ tests of physics.hpp: the decisions every path shares, against the library's exact forms.
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
