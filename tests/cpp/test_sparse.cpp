// C++ tests of detail/sensor_sparse.hpp (Sensor::run_sparse): the steps it takes per pixel
// counted by hand, the dense run it must equal where every pixel is lit, determinism over
// threads, bad input refused before any pixel moves.
#include <evstwin/evstwin.hpp>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include "check.hpp"

using namespace evstwin;

namespace {

PixelParams sparse_params() {
    PixelParams p;  // continuous noise, exact low-pass, every noise source on
    p.threshold_sigma = 0.04;
    p.leak_rate_hz = 2.0;
    p.shot_noise_rate_hz = 1.0;
    p.cutoff_hz = 100.0;  // settle_time_s: 5 / (2 pi 100 Hz) = 7.96 ms
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
    // 4 x 4 px, 8 samples 10 ms apart in groups of 2; pixel 5 lit at sample 2 only (group 1).
    // Group 1: pixel 5 steps to t[1] (1), then its 2 fine samples; group 2: it still relaxes
    // (7.96 ms after t[3]), so its 2 base samples; group 3: settled, nothing; then the 16
    // pixels' long step to t[7] (pixel 5 from t[5]). 1 + 2 + 2 + 16 = 21.
    const int w = 4, h = 4;
    Sensor s(w, h, sparse_params(), 3, 1);
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
    CHECK(s.last_pixel_updates() == 21u);
    CHECK_NEAR(s.settle_time_s(1e6), 5.0 / (2.0 * 3.141592653589793 * 100.0), 1e-15);
    // Nothing lit: one long step for each pixel, and no pixel is left relaxing.
    step.n_light = 0;
    for (double& v : t) v += 0.08;
    s.run_sparse(step);
    CHECK(s.last_pixel_updates() == 16u);
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
    Sensor dense(w, h, sparse_params(), 9, 2), sparse(w, h, sparse_params(), 9, 2);
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
    const int w = 48, h = 16;
    std::vector<double> background(w * h, 3e5), t0{0.0};
    std::vector<Event> runs[2];
    for (int threads : {1, 2}) {
        Sensor s(w, h, sparse_params(), 5, threads);
        s.run(background.data(), t0.data(), 1, nullptr, nullptr, true);
        for (int unit = 0; unit < 3; ++unit) {
            // 0.1 s steps of 4 fine samples per 1 ms base sample, groups of 5 base samples.
            std::vector<double> t(400);
            for (int k = 0; k < 400; ++k) t[k] = 0.1 * unit + 2.5e-4 * (k + 1);
            const Spot spot(w, h, t);
            const auto ev = s.run_sparse(spot.step(background, t, 4, 5));
            CHECK(s.last_pixel_updates() < 400u * w * h / 10);  // the spot's pixels only, finely
            for (std::size_t i = 1; i < ev.size(); ++i)
                CHECK(ev[i - 1].t < ev[i].t || (ev[i - 1].t == ev[i].t && ev[i - 1].y * w + ev[i - 1].x <= ev[i].y * w + ev[i].x));
            runs[threads - 1].insert(runs[threads - 1].end(), ev.begin(), ev.end());
        }
    }
    CHECK(runs[0].size() > 50);
    CHECK(same_events(runs[0], runs[1]));
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
