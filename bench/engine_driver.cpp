// The C++ engine alone, for instruction counts (valgrind --tool=callgrind), perf profiles and
// wall time: a 346-pixel-wide DAVIS346 window, 2e6 photons/s on every pixel, every noise
// source on, 400 samples at 1 kHz in 4 calls. CUTOFF_HZ (default 10, the reference load)
// sets the source follower's cutoff: 200 Hz makes the event-heavy load (the 18,000 e-/s dark
// current's shot noise then crosses the thresholds ~900 times a pixel a second, and, b dt = 1.26
// being above SF_REFINE_BH, an interval where a crossing is plausible is refined:
// refine_and_compare). THREADS (default 1) is the engine's thread count. "pole" is "continuous"
// with the photoreceptor pole (pr_pole, as the IMX636 and Gen3 VGA presets and mcreynolds have
// it; the DAVIS346 preset does not).
//
//   g++ -std=c++17 -O3 -DNDEBUG -fopenmp -Icpp/include bench/engine_driver.cpp -o /tmp/engine_driver
//   valgrind --tool=callgrind /tmp/engine_driver continuous 64          # or: sampled 64
//   valgrind --tool=callgrind /tmp/engine_driver continuous 4 200       # event-heavy (~4,300 instructions an event)
//   time /tmp/engine_driver continuous 260 [CUTOFF_HZ [THREADS]]
#include <evstwin/evstwin.hpp>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <vector>

int main(int argc, char** argv) {
    const bool pole = argc >= 2 && std::strcmp(argv[1], "pole") == 0;
    if (argc < 3 || argc > 5 ||
        (std::strcmp(argv[1], "continuous") != 0 && std::strcmp(argv[1], "sampled") != 0 && !pole)) {
        std::fprintf(stderr, "usage: %s continuous|pole|sampled HEIGHT [CUTOFF_HZ [THREADS]]\n", argv[0]);
        return 2;
    }
    evstwin::PixelParams p;
    p.threshold_sigma = 0.03;
    p.noise_model = std::strcmp(argv[1], "sampled") == 0 ? evstwin::NoiseModel::Sampled : evstwin::NoiseModel::Continuous;
    p.pr_pole = pole;
    const int width = 346, height = std::atoi(argv[2]), samples = 100;
    if (height < 1 || height > 260) {
        std::fprintf(stderr, "HEIGHT must be in [1, 260]; got %s\n", argv[2]);
        return 2;
    }
    if (argc >= 4) p.cutoff_hz = std::atof(argv[3]);
    const int threads = argc >= 5 ? std::atoi(argv[4]) : 1;
    evstwin::Sensor sensor(width, height, p, 1, threads);
    std::vector<float> rate(static_cast<std::size_t>(width) * height, 2e6f);
    std::vector<double> t(samples);
    std::size_t n = 0;
    std::uint64_t digest = 1469598103934665603ull;  // FNV-1a over the events' time, pixel, polarity
    const auto mix = [&digest](std::uint64_t v) {
        for (int b = 0; b < 8; ++b) digest = (digest ^ ((v >> (8 * b)) & 0xFFu)) * 1099511628211ull;
    };
    for (int call = 0; call < 4; ++call) {
        for (int i = 0; i < samples; ++i) t[i] = (call * samples + i) / 1000.0;
        const auto events = sensor.run(rate.data(), t.data(), samples, nullptr, nullptr, true);
        for (const auto& e : events) {
            mix(static_cast<std::uint64_t>(e.t));
            mix((static_cast<std::uint64_t>(e.y) << 32) | (static_cast<std::uint64_t>(e.x) << 8) | e.p);
        }
        n += events.size();
    }
    // The digest tells builds apart that should give the same events (e.g. -march=native).
    std::printf("%zu events, digest %016llx\n", n, static_cast<unsigned long long>(digest));
    return 0;
}
