// C++ tests of detail/sensor_sparse.hpp (Sensor::run_sparse): the steps it takes per pixel
// counted by hand, the dense run it must equal where every pixel is lit, determinism over
// threads, bad input refused before any pixel moves.
#include <evstwin/evstwin.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <map>
#include <memory>
#include <vector>

#include "check.hpp"

using namespace evstwin;

namespace {

/// Continuous noise, exact low-pass, every noise source on, the source follower alone at
/// cutoff_hz, whose noise's standard deviation on the level grows as sqrt(cutoff_hz). At 1 Hz
/// it stays far below the thresholds (run_sparse gives long steps); at 100 Hz it stays within
/// reach of them over any piece of a long step longer than 1 / (8 x 2 pi cutoff_hz), so
/// refine_and_compare would cut a long step into pieces shorter than the base samples' (the
/// base samples throughout: PixelModel::long_steps_cut_below). A pixel a source left relaxes
/// for 5 / (2 pi cutoff_hz) (0.796 s at 1 Hz).
PixelParams sparse_params(double cutoff_hz = 1.0) {
    PixelParams p;
    p.threshold_sigma = 0.04;
    p.leak_rate_hz = 2.0;
    p.shot_noise_rate_hz = 1.0;
    p.cutoff_hz = cutoff_hz;
    return p;
}

bool same_events(const std::vector<Event>& a, const std::vector<Event>& b) {
    return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(Event)) == 0;
}

/// A Gaussian spot of 2e7 photons/s crossing a w x h sensor at 400 px/s, as light entries
/// over its 7 x 7 window at the step's sample times.
struct Spot {
    std::vector<std::uint32_t> sample, pixel;
    std::vector<double> rate;
    Spot(int w, int h, const std::vector<double>& t) {
        for (std::size_t k = 0; k < t.size(); ++k) {
            const double cx = -5.0 + 400.0 * t[k], cy = h / 2.0;
            for (int y = static_cast<int>(cy) - 3; y <= static_cast<int>(cy) + 3; ++y)
                for (int x = static_cast<int>(std::floor(cx)) - 3; x <= static_cast<int>(std::floor(cx)) + 3; ++x) {
                    if (x < 0 || x >= w || y < 0 || y >= h) continue;
                    const double r2 = (x - cx) * (x - cx) + (y - cy) * (y - cy);
                    sample.push_back(static_cast<std::uint32_t>(k));
                    pixel.push_back(static_cast<std::uint32_t>(y * w + x));
                    rate.push_back(2e7 * std::exp(-r2 / 2.0) / (2.0 * 3.141592653589793));
                }
        }
    }
    SparseStep step(const std::vector<double>& background, const std::vector<double>& t, std::size_t base_every,
                    std::size_t group) const {
        SparseStep s;
        s.static_rate = background.data();
        s.t_s = t.data();
        s.n_samples = t.size();
        s.base_every = base_every;
        s.group_base_samples = group;
        s.light_sample = sample.data();
        s.light_pixel = pixel.data();
        s.light_rate = rate.data();
        s.n_light = rate.size();
        return s;
    }
};

}  // namespace

TEST(run_sparse_takes_the_steps_counted_by_hand) {
    // 4 x 4 px, steps of 8 samples 10 ms apart in groups of 2; pixel 5 lit at sample 2 only
    // (group 1). The follower at 1 Hz: quiet pixels, none sampled throughout; pixel 5 relaxes
    // for 0.796 s once lit.
    // Step 1. Group 1: pixel 5's long step to t[1] (1), its 2 fine samples; groups 2 and 3:
    // its 2 + 2 base samples; then the 15 others' long step to t[7]: 1 + 2 + 4 + 15 = 22.
    // Step 2 (nothing lit): pixel 5 still relaxes, 8 base samples, and the 15 others: 23.
    // Every pixel noisy instead (the follower at 100 Hz): the steps run densely, all 16
    // pixels at the 8 base samples (pixel 5 its 2 fine ones in place of 2 of them): 128.
    const int w = 4, h = 4;
    for (const double cutoff_hz : {1.0, 100.0}) {
        Sensor s(w, h, sparse_params(cutoff_hz), 3, 1);
        std::vector<double> background(w * h, 1e6), t0{0.0};
        s.run(background.data(), t0.data(), 1, nullptr, nullptr, true);
        std::vector<double> t(8);
        for (int k = 0; k < 8; ++k) t[k] = 0.01 * (k + 1);
        const std::uint32_t sample = 2, pixel = 5;
        const double rate = 0.0;  // the edge of a stamp: lit all the same
        SparseStep step;
        step.static_rate = background.data();
        step.t_s = t.data();
        step.n_samples = 8;
        step.group_base_samples = 2;
        step.light_sample = &sample;
        step.light_pixel = &pixel;
        step.light_rate = &rate;
        step.n_light = 1;
        s.run_sparse(step);
        const bool sampled = cutoff_hz > 50.0;
        CHECK(s.last_pixel_updates() == (sampled ? 128u : 22u));
        CHECK_NEAR(s.settle_time_s(1e6), 5.0 / (2.0 * 3.141592653589793 * cutoff_hz), 1e-15);
        step.n_light = 0;
        for (double& v : t) v += 0.08;
        s.run_sparse(step);
        CHECK(s.last_pixel_updates() == (sampled ? 128u : 23u));
    }
}

TEST(run_sparse_with_every_pixel_lit_is_the_dense_run) {
    // Every pixel listed at every sample (rate 0 added): each group is one run_pixels of the
    // whole array on the dense grid, so the events are the dense run's, bit for bit.
    const int w = 24, h = 12, n = 40;
    std::vector<double> background(w * h), t(n), t0{0.0};
    for (int i = 0; i < w * h; ++i) background[i] = 1e5 * (1 + i % 5);
    for (int k = 0; k < n; ++k) t[k] = 1e-3 * (k + 1);
    std::vector<std::uint32_t> sample, pixel;
    std::vector<double> rate;
    std::vector<double> frames(static_cast<std::size_t>(n) * w * h);
    for (int k = 0; k < n; ++k)
        for (int i = 0; i < w * h; ++i) {
            const double extra = (i % 7 == k % 7) ? 3e6 : 0.0;
            sample.push_back(k);
            pixel.push_back(i);
            rate.push_back(extra);
            frames[static_cast<std::size_t>(k) * w * h + i] = background[i] + extra;
        }
    Sensor dense(w, h, sparse_params(100.0), 9, 2), sparse(w, h, sparse_params(100.0), 9, 2);
    dense.run(background.data(), t0.data(), 1, nullptr, nullptr, true);
    sparse.run(background.data(), t0.data(), 1, nullptr, nullptr, true);
    const auto expected = dense.run(frames.data(), t.data(), n);
    SparseStep step;
    step.static_rate = background.data();
    step.t_s = t.data();
    step.n_samples = n;
    step.group_base_samples = 8;
    step.light_sample = sample.data();
    step.light_pixel = pixel.data();
    step.light_rate = rate.data();
    step.n_light = rate.size();
    const auto got = sparse.run_sparse(step);
    CHECK(expected.size() > 100);
    CHECK(same_events(got, expected));
    CHECK(sparse.last_pixel_updates() == static_cast<std::uint64_t>(n) * w * h);
    CHECK(sparse.last_labels() == dense.last_labels());
}

TEST(run_sparse_is_the_same_whatever_the_threads) {
    // The follower at 1 Hz (long steps for the pixels the spot leaves alone) and at 100 Hz
    // (every pixel noisy: the steps run densely, SPARSE_DENSE_SHARE).
    const int w = 48, h = 16;
    std::vector<double> background(w * h, 3e5), t0{0.0};
    for (const double cutoff_hz : {1.0, 100.0}) {
        // Three blocks of pixels: with 2 threads run_sparse's parts are blocks {0, 2} and {1},
        // with 3 one block each.
        std::vector<Event> runs[3];
        for (int threads : {1, 2, 3}) {
            Sensor s(w, h, sparse_params(cutoff_hz), 5, threads);
            s.run(background.data(), t0.data(), 1, nullptr, nullptr, true);
            for (int unit = 0; unit < 3; ++unit) {
                // 0.1 s steps of 4 fine samples per 1 ms base sample, groups of 5 base samples.
                std::vector<double> t(400);
                for (int k = 0; k < 400; ++k) t[k] = 0.1 * unit + 2.5e-4 * (k + 1);
                const Spot spot(w, h, t);
                const auto ev = s.run_sparse(spot.step(background, t, 4, 5));
                // The spot's pixels finely, its trail's at the base rate while they relax (0.8 s);
                // densely, every pixel at the 100 base samples but those the spot lights (at
                // most its 49 a sample) at the fine ones.
                if (cutoff_hz < 50.0)
                    CHECK(s.last_pixel_updates() < 400u * w * h / 4);
                else
                    CHECK(s.last_pixel_updates() > 90u * w * h && s.last_pixel_updates() <= 100u * w * h + 49u * 400u);
                for (std::size_t i = 1; i < ev.size(); ++i)
                    CHECK(ev[i - 1].t < ev[i].t ||
                          (ev[i - 1].t == ev[i].t && ev[i - 1].y * w + ev[i - 1].x <= ev[i].y * w + ev[i].x));
                runs[threads - 1].insert(runs[threads - 1].end(), ev.begin(), ev.end());
            }
        }
        CHECK(runs[0].size() > 50);
        CHECK(same_events(runs[0], runs[1]));
        CHECK(same_events(runs[0], runs[2]));
    }
}

TEST(run_sparse_is_the_calls_its_rule_makes_by_hand) {
    // The rule the header states, followed with public calls on a sensor of its own: in each
    // group the lit pixels take one long step at the static light to the group's start (those
    // behind it, one call per time they stand at) and then the group's fine samples; the
    // pixels still settling (within settle_time_s of the end of a group they were lit in) take
    // the group's base samples, after the same long step; at the step's end one run() of the
    // static map. run_sparse makes other calls (a settling pixel's base samples ahead of the
    // groups, in one call; the pixels in parts, one a thread) but must give the same events,
    // bit for bit, on 1, 2 and 3 threads, over three steps (the settling carried from step to
    // step), at settling times beyond the three steps (1 Hz) and within them (5 Hz).
    const int w = 48, h = 16;
    const std::size_t n = 400, base_every = 4, group_base = 5, group = base_every * group_base;
    const double light = 3e5;
    for (const double cutoff_hz : {1.0, 5.0}) {
        const std::vector<double> background(w * h, light), t0{0.0};
        Sensor ref(w, h, sparse_params(cutoff_hz), 5, 1);
        ref.run(background.data(), t0.data(), 1, nullptr, nullptr, true);
        const double settle_s = ref.settle_time_s(light);
        std::vector<double> at(w * h, 0.0), settle_until(w * h, -std::numeric_limits<double>::infinity());
        std::vector<std::unique_ptr<Sensor>> sparse;
        for (int threads : {1, 2, 3}) {
            sparse.push_back(std::make_unique<Sensor>(w, h, sparse_params(cutoff_hz), 5, threads));
            sparse.back()->run(background.data(), t0.data(), 1, nullptr, nullptr, true);
        }
        std::size_t settled_within = 0;  // pixels whose settling ended inside a step
        double step_start = 0.0;
        for (int unit = 0; unit < 3; ++unit) {
            std::vector<double> t(n);
            for (std::size_t k = 0; k < n; ++k) t[k] = 0.1 * unit + 2.5e-4 * static_cast<double>(k + 1);
            const Spot spot(w, h, t);
            std::vector<Event> expected;
            const auto take = [&](const std::vector<Event>& ev) { expected.insert(expected.end(), ev.begin(), ev.end()); };
            const auto long_step = [&](const std::vector<std::uint32_t>& pixels, double to) {
                std::map<double, std::vector<std::uint32_t>> by_start;
                for (const std::uint32_t px : pixels)
                    if (at[px] < to) by_start[at[px]].push_back(px);
                for (const auto& [from, list] : by_start) {
                    const std::vector<double> rate(list.size(), light);
                    take(ref.run_pixels(list.data(), list.size(), rate.data(), &to, 1, true));
                    for (const std::uint32_t px : list) at[px] = to;
                }
            };
            for (std::size_t k0 = 0; k0 < n; k0 += group) {
                const double t_start = k0 == 0 ? step_start : t[k0 - 1], t_end = t[k0 + group - 1];
                std::vector<std::uint32_t> lit;
                for (std::size_t i = 0; i < spot.rate.size(); ++i)
                    if (spot.sample[i] >= k0 && spot.sample[i] < k0 + group) lit.push_back(spot.pixel[i]);
                std::sort(lit.begin(), lit.end());
                lit.erase(std::unique(lit.begin(), lit.end()), lit.end());
                std::vector<double> rate(group * lit.size(), light);
                for (std::size_t i = 0; i < spot.rate.size(); ++i)
                    if (spot.sample[i] >= k0 && spot.sample[i] < k0 + group) {
                        const std::size_t j = static_cast<std::size_t>(
                            std::lower_bound(lit.begin(), lit.end(), spot.pixel[i]) - lit.begin());
                        rate[(spot.sample[i] - k0) * lit.size() + j] += spot.rate[i];
                    }
                long_step(lit, t_start);
                if (!lit.empty()) take(ref.run_pixels(lit.data(), lit.size(), rate.data(), t.data() + k0, group));
                std::vector<std::uint32_t> settling;
                for (std::uint32_t px = 0; px < static_cast<std::uint32_t>(w * h); ++px)
                    if (settle_until[px] > t_start && !std::binary_search(lit.begin(), lit.end(), px)) {
                        settling.push_back(px);
                        if (!(settle_until[px] > t_end)) ++settled_within;
                    }
                long_step(settling, t_start);
                std::vector<double> base;
                for (std::size_t k = k0 + base_every - 1; k < k0 + group; k += base_every) base.push_back(t[k]);
                const std::vector<double> settle_rate(settling.size(), light);
                if (!settling.empty())
                    take(ref.run_pixels(settling.data(), settling.size(), settle_rate.data(), base.data(), base.size(), true));
                for (const std::uint32_t px : lit) settle_until[px] = t_end + settle_s;
                for (const std::uint32_t px : lit) at[px] = t_end;
                for (const std::uint32_t px : settling) at[px] = t_end;
            }
            take(ref.run(background.data(), &t[n - 1], 1, nullptr, nullptr, true));
            std::fill(at.begin(), at.end(), t[n - 1]);
            step_start = t[n - 1];
            std::stable_sort(expected.begin(), expected.end(), [&](const Event& a, const Event& b) {
                if (a.t != b.t) return a.t < b.t;
                return a.y * w + a.x < b.y * w + b.x;
            });
            CHECK(expected.size() > 20);
            for (const auto& s : sparse)
                CHECK(same_events(s->run_sparse(spot.step(background, t, base_every, group_base)), expected));
        }
        if (cutoff_hz > 2.0) CHECK(settled_within > 10);  // the 5 Hz pixels settle 0.16 s after they were lit
    }
}

TEST(run_sparse_refuses_bad_input_before_any_pixel_moves) {
    const int w = 16, h = 8;
    std::vector<double> background(w * h, 3e5), t0{0.0}, t(20);
    for (int k = 0; k < 20; ++k) t[k] = 1e-3 * (k + 1);
    const Spot spot(w, h, t);
    Sensor s(w, h, sparse_params(), 4, 1), fresh(w, h, sparse_params(), 4, 1);
    s.run(background.data(), t0.data(), 1, nullptr, nullptr, true);
    fresh.run(background.data(), t0.data(), 1, nullptr, nullptr, true);
    SparseStep bad = spot.step(background, t, 3, 2);  // 3 does not divide 20
    CHECK_THROWS(s.run_sparse(bad));
    bad = spot.step(background, t, 1, 0);
    CHECK_THROWS(s.run_sparse(bad));
    std::vector<std::uint32_t> far(spot.pixel);
    far.back() = w * h;
    bad = spot.step(background, t, 1, 2);
    bad.light_pixel = far.data();
    CHECK_THROWS(s.run_sparse(bad));
    std::vector<double> negative(spot.rate);
    negative.back() = -1.0;
    bad = spot.step(background, t, 1, 2);
    bad.light_rate = negative.data();
    CHECK_THROWS(s.run_sparse(bad));
    std::vector<double> nan_background(background);
    nan_background[w * h - 1] = std::nan("");
    bad = spot.step(nan_background, t, 1, 2);
    CHECK_THROWS(s.run_sparse(bad));
    // None of them moved a pixel: the next step's events are a fresh sensor's.
    CHECK(same_events(s.run_sparse(spot.step(background, t, 1, 2)), fresh.run_sparse(spot.step(background, t, 1, 2))));
    PixelParams sampled = sparse_params();
    sampled.noise_model = NoiseModel::Sampled;
    Sensor other(w, h, sampled, 4, 1);
    CHECK_THROWS(other.run_sparse(spot.step(background, t, 1, 2)));
}

TEST(run_sparse_lets_unlisted_pixels_wait_for_one_long_step) {
    // Three steps where nothing is lit and only pixels 3 and 7 must reach the first step's
    // end, then a step that takes every pixel to its end: each other pixel crosses the whole
    // 0.3 s in one exact step, which is what one run() sample at 0.3 s gives it, bit for bit
    // (the same interval, light and sample counter).
    const int w = 8, h = 6;
    std::vector<double> background(w * h), t0{0.0};
    for (int i = 0; i < w * h; ++i) background[i] = 2e5 * (1 + i % 3);
    // One sample a step, 0.1 s apart: the follower at 0.1 Hz (5 pieces a second) steps long.
    Sensor waits(w, h, sparse_params(0.1), 8, 1), once(w, h, sparse_params(0.1), 8, 1);
    waits.run(background.data(), t0.data(), 1, nullptr, nullptr, true);
    once.run(background.data(), t0.data(), 1, nullptr, nullptr, true);
    const std::uint32_t reach[2] = {3, 7};
    std::vector<Event> got;
    for (int k = 1; k <= 3; ++k) {
        const double t = 0.1 * k;
        SparseStep step;
        step.static_rate = background.data();
        step.t_s = &t;
        step.n_samples = 1;
        step.reach_all = k == 3;
        step.reach_pixel = reach;
        step.n_reach = k == 1 ? 2 : 0;
        const auto ev = waits.run_sparse(step);
        got.insert(got.end(), ev.begin(), ev.end());
        CHECK(waits.last_pixel_updates() == (k == 1 ? 2u : k == 2 ? 0u : static_cast<std::uint64_t>(w * h)));
    }
    const double t_end = 0.3;
    auto expected = once.run(background.data(), &t_end, 1, nullptr, nullptr, true);
    // Pixels 3 and 7 took two steps (0.1 s, then 0.2 s) in place of one: leave them out.
    const auto other = [](const Event& e) { return !(e.y == 0 && (e.x == 3 || e.x == 7)); };
    std::vector<Event> a, b;
    for (const Event& e : got)
        if (other(e)) a.push_back(e);
    for (const Event& e : expected)
        if (other(e)) b.push_back(e);
    CHECK(b.size() > 5);
    CHECK(same_events(a, b));
    // A step must start after the last one's end, waiting pixels or not.
    const double early = 0.25;
    SparseStep step;
    step.static_rate = background.data();
    step.t_s = &early;
    step.n_samples = 1;
    CHECK_THROWS(waits.run_sparse(step));
}
