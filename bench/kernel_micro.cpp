// Three small loads of the C++ engine behind figures in the README's "Speed" section, for
// callgrind instruction counts or `/usr/bin/time` CPU seconds (one thread):
//
//   short-calls N   mcreynolds' pixel (photoreceptor pole, the paper's leak and background,
//                   run-1 thresholds) on a dark 346 x 260 array at 250 Hz: 1000 samples in
//                   run() calls of N samples (what a call's fixed cost does: N = 3 was
//                   mcreynolds' call length before SUB_SAMPLED_UNIT_SAMPLES = 150)
//   run-pixels      run_pixels() on 4096 pixels, 39 fine samples a call, 20 calls, 15 % of them
//                   at photon rates of their own (a moving source's window): the per-pixel cost
//                   of rates no other pixel shares
//   fill            PixelModel::fill_noise_cache() for 200,000 distinct photon rates with the
//                   pole: the noise coefficients of one new rate
//
//   g++ -std=c++17 -O3 -DNDEBUG -Icpp/include bench/kernel_micro.cpp -o /tmp/kernel_micro
//   valgrind --tool=callgrind /tmp/kernel_micro fill      # or: run-pixels
//   /usr/bin/time -f "%U s" /tmp/kernel_micro short-calls 3
#include <evstwin/evstwin.hpp>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

namespace {

evstwin::PixelParams mcreynolds_pixel() {
    evstwin::PixelParams p;
    p.pr_pole = true;
    p.leak_rate_hz = 0.1;
    p.shot_noise_rate_hz = 0.05;
    p.theta_on = 0.206;
    p.theta_off = 0.093;
    return p;
}

int short_calls(int samples_per_call) {
    if (samples_per_call < 1 || samples_per_call > 1000) {
        std::fprintf(stderr, "short-calls N: N must be in [1, 1000]; got %d\n", samples_per_call);
        return 2;
    }
    const int width = 346, height = 260, calls = 1000 / samples_per_call;
    evstwin::Sensor sensor(width, height, mcreynolds_pixel(), 1, 1);
    std::vector<float> rate(static_cast<std::size_t>(width) * height, 0.0f);
    std::vector<double> t(static_cast<std::size_t>(samples_per_call));
    std::size_t n = 0;
    for (int call = 0; call < calls; ++call) {
        for (int i = 0; i < samples_per_call; ++i) t[static_cast<std::size_t>(i)] = (call * samples_per_call + i) / 250.0;
        n += sensor.run(rate.data(), t.data(), t.size(), nullptr, nullptr, true).size();
    }
    std::printf("%zu events in %d calls of %d samples\n", n, calls, samples_per_call);
    return 0;
}

int run_pixels() {
    evstwin::Sensor sensor(346, 260, mcreynolds_pixel(), 1, 1);
    const std::size_t m = 4096, ns = 39;
    std::vector<std::uint32_t> px(m);
    for (std::size_t j = 0; j < m; ++j) px[j] = static_cast<std::uint32_t>(j * 7);
    std::vector<float> dark(346 * 260, 0.0f);
    const double t0 = 0.0;
    sensor.run(dark.data(), &t0, 1, nullptr, nullptr, true);
    std::vector<double> rate(ns * m), t(ns);
    std::size_t n = 0;
    for (std::size_t call = 0; call < 20; ++call) {
        for (std::size_t k = 0; k < ns; ++k) {
            t[k] = static_cast<double>(call * ns + k + 1) / 3250.0;
            for (std::size_t j = 0; j < m; ++j)
                rate[k * m + j] = (j % 100 < 85) ? 0.0 : 1e6 * (1.0 + std::sin(0.01 * j + 0.1 * (call * ns + k)));
        }
        n += sensor.run_pixels(px.data(), m, rate.data(), t.data(), ns).size();
    }
    std::printf("%zu events\n", n);
    return 0;
}

int fill() {
    const evstwin::PixelModel model(mcreynolds_pixel());
    const evstwin::SampleConstants c = model.constants(0.0, 1.0 / 3250.0);
    evstwin::NoiseCache cache;
    double sum = 0.0;  // printed, so the fills are not optimised away
    for (int i = 0; i < 200000; ++i) {
        model.fill_noise_cache(cache, 1e5 + i * 37.0, c);
        sum += cache.k.l_yy + cache.bridge_bound;
    }
    std::printf("200000 fills, checksum %.10g\n", sum);
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc == 3 && std::strcmp(argv[1], "short-calls") == 0) return short_calls(std::atoi(argv[2]));
    if (argc == 2 && std::strcmp(argv[1], "run-pixels") == 0) return run_pixels();
    if (argc == 2 && std::strcmp(argv[1], "fill") == 0) return fill();
    std::fprintf(stderr, "usage: %s short-calls N | run-pixels | fill\n", argv[0]);
    return 2;
}
