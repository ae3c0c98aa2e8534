// C++ tests of sensor.hpp: determinism over threads, chunking and kernels, event order, bad input, limits.
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
    p.leak_rate_hz = 0.0;  // the leak would fire 6.4 million events a pixel over the two years
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

TEST(run_pixels_with_static_rates_is_the_repeated_row) {
    // One row of rates for every sample (static_rates) against the same row written out at
    // each sample: the same events; a bad value in the one row is still refused.
    PixelParams p;
    p.threshold_sigma = 0.04;
    p.shot_noise_rate_hz = 1.0;
    p.cutoff_hz = 300.0;
    const int w = 20, h = 10, n = 30;
    const std::vector<std::uint32_t> pixels{3, 17, 40, 41, 42, 150, 199};
    std::vector<double> row(pixels.size()), t(n), full;
    for (std::size_t j = 0; j < row.size(); ++j) row[j] = 2e6 * (1.0 + static_cast<double>(j));
    for (int k = 0; k < n; ++k) {
        t[k] = 1e-3 * (k + 1);
        full.insert(full.end(), row.begin(), row.end());
    }
    std::vector<double> start(w * h, 5e5), t0{0.0};
    Sensor a(w, h, p, 2, 1), b(w, h, p, 2, 1);
    a.run(start.data(), t0.data(), 1, nullptr, nullptr, true);
    b.run(start.data(), t0.data(), 1, nullptr, nullptr, true);
    const auto ea = a.run_pixels(pixels.data(), pixels.size(), row.data(), t.data(), n, true);
    const auto eb = b.run_pixels(pixels.data(), pixels.size(), full.data(), t.data(), n);
    CHECK(ea.size() > 10);
    CHECK(ea.size() == eb.size() && std::memcmp(ea.data(), eb.data(), ea.size() * sizeof(Event)) == 0);
    std::vector<double> bad(row);
    bad[4] = -1.0;
    std::vector<double> later(t);
    for (double& v : later) v += 1.0;
    CHECK_THROWS(a.run_pixels(pixels.data(), pixels.size(), bad.data(), later.data(), n, true));
}

TEST(a_block_whose_pixels_stand_apart_gives_the_per_pixel_events) {
    // Every 7th pixel moved ahead to 0.4 s by run_pixels, the others at 0: run()'s first
    // sample (to 0.5 s) finds every block's pixels standing apart. The kernel takes those at
    // 0 and the per-pixel path the others, and the sample's events go back into pixel order:
    // the same events, in the same order, as the per-pixel path for all (Kernel::PerPixel).
    PixelParams p;
    p.threshold_sigma = 0.04;
    p.shot_noise_rate_hz = 20.0;
    p.leak_rate_hz = 5.0;
    p.cutoff_hz = 50.0;
    const int w = 64, h = 12;
    std::vector<double> rate(w * h), t0{0.0}, t{0.5, 0.501, 0.502};
    for (int i = 0; i < w * h; ++i) rate[i] = 3e5 * (1 + i % 4);
    std::vector<std::uint32_t> moved;
    for (std::uint32_t i = 0; i < static_cast<std::uint32_t>(w * h); i += 7) moved.push_back(i);
    std::vector<double> moved_rate(moved.size(), 4e5);
    const double t_moved = 0.4;
    std::vector<Event> runs[2];
    std::size_t apart_events = 0;
    for (int k = 0; k < 2; ++k) {
        Sensor s(w, h, p, 6, 1);
        if (k == 1) s.set_kernel(Kernel::PerPixel);
        s.run(rate.data(), t0.data(), 1, nullptr, nullptr, true);
        s.run_pixels(moved.data(), moved.size(), moved_rate.data(), &t_moved, 1, true);
        runs[k] = s.run(rate.data(), t.data(), 3, nullptr, nullptr, true);
        if (k == 0)
            for (const Event& e : runs[k]) apart_events += (e.y * w + e.x) % 7 == 0;
    }
    CHECK(runs[0].size() > 50);
    CHECK(apart_events > 5 && apart_events < runs[0].size());  // both paths made events
    CHECK(runs[0].size() == runs[1].size() &&
          std::memcmp(runs[0].data(), runs[1].data(), runs[0].size() * sizeof(Event)) == 0);
}
