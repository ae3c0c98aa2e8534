// C++ tests of pixel.hpp: PixelModel, the scalar reference, on analytic cases.
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

TEST(a_hot_pixels_clocks_copy_with_its_state) {
    // A hot pixel's clocks live outside PixelState's record (HotBox): a copy of the state
    // carries a copy of them (stepping one leaves the other's alone), a plain pixel's box
    // stays empty, and assigning one hot state to another keeps the target's storage (copies
    // between run_pixels' buffers allocate nothing once both hold one).
    const PixelModel model(ideal());
    const Philox4x32Key key{1u, 2u};
    PixelState hot, plain;
    model.init_pixel(hot, key, 0, 300.0);
    model.init_pixel(plain, key, 1, 0.0);
    CHECK(hot.hot && !plain.hot);
    CHECK(hot.hot->rate_hz == 300.0);
    model.init_state(hot, 1e6, 0.0, key, 0);
    CHECK(std::isfinite(hot.next_hot_t) && !std::isfinite(plain.next_hot_t));
    PixelState copy = hot;
    CHECK(copy.hot && &*copy.hot != &*hot.hot && same_state(copy, hot));
    std::size_t fired = 0;
    auto emit = [&fired](double, auto, auto) { ++fired; };
    model.hot_events(hot, 1.0, key, 0, emit);
    CHECK(fired > 200 && fired < 400);  // 300 Hz over 1 s
    CHECK(hot.hot->count == fired && copy.hot->count == 0 && !same_state(copy, hot));
    const HotPixelState* kept = &*copy.hot;
    copy = hot;
    CHECK(&*copy.hot == kept && same_state(copy, hot));
    copy = plain;
    CHECK(!copy.hot && same_state(copy, plain));
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

TEST(stationary_noise_sigma_is_the_levels_spread_across_pixels) {
    // 4,096 pixels under the same light, settled for 2 s (many time constants of pole and
    // follower), with no mismatch in the level: their levels at one instant are independent
    // draws of the stationary noise, whose variance D a b / (2 (a + b)) stationary_noise_sigma
    // gives (the sample variance of 4,096 draws is within 10 % of it with 4 sd to spare).
    // With the pole and without it.
    for (const bool pole : {true, false}) {
        PixelParams p;
        p.pr_pole = pole;
        p.cutoff_hz = 200.0;
        p.leak_rate_hz = 0.0;
        p.shot_noise_rate_hz = 0.0;
        p.theta_on = p.theta_off = 5.0;  // no events: the reference stays put (y does anyway)
        const int side = 64, n = side * side;
        const double rate = 2e5;
        Sensor s(side, side, p, 17, 1);
        std::vector<double> frame(n, rate), t0{0.0}, t1{2.0};
        std::vector<std::uint32_t> all(n);
        for (int i = 0; i < n; ++i) all[i] = static_cast<std::uint32_t>(i);
        std::vector<TraceSample> trace;
        s.run(frame.data(), t0.data(), 1, nullptr, nullptr, true);
        s.run(frame.data(), t1.data(), 1, &all, &trace, true);
        double mean = 0.0, var = 0.0;
        for (const TraceSample& tr : trace) mean += tr.filtered / n;
        for (const TraceSample& tr : trace) var += (tr.filtered - mean) * (tr.filtered - mean) / (n - 1);
        const double sigma = PixelModel(p).stationary_noise_sigma(rate);
        CHECK(sigma > 0.0);
        CHECK_NEAR(var / (sigma * sigma), 1.0, 0.1);
    }
}
