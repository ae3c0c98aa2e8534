// How a C++ tracking pipeline embeds evstwin: build a sensor, feed it photon rates chunk by
// chunk as the scene renders them, and consume the events of each chunk.
//
// Here the "scene" is one pixel-sized spot sweeping along row 4 of a 32 x 8 sensor, at
// 1 kHz sampling, noise-free so the output is easy to read.
#include <cmath>
#include <cstdio>
#include <vector>

#include <evstwin/evstwin.hpp>

int main() {
    evstwin::PixelParams params;            // DAVIS346 pixel of the paper
    params.photon_shot_noise = false;       // noise-free for a readable demo
    params.dark_model = evstwin::DarkModel::None;
    params.leak_rate_hz = 0.0;
    params.shot_noise_rate_hz = 0.0;
    params.cutoff_hz.reset();               // no source-follower filter
    params.refractory_s = 0.0;

    const int width = 32, height = 8;
    evstwin::Sensor sensor(width, height, params, /*seed=*/1);

    const double background = 1e7, spot = 1e9;  // photons/s on a pixel
    const double speed_px_s = 1000.0;           // the spot moves 1 px per ms
    const std::size_t chunk = 8;                // samples per call, as a renderer would stream
    std::vector<double> rate(chunk * width * height), t_s(chunk);
    std::size_t total = 0;
    for (std::size_t k0 = 0; k0 < 32; k0 += chunk) {
        for (std::size_t j = 0; j < chunk; ++j) {
            const double t = static_cast<double>(k0 + j) * 1e-3;
            t_s[j] = t;
            const double xc = 2.0 + speed_px_s * t;
            for (int y = 0; y < height; ++y)
                for (int x = 0; x < width; ++x) {
                    const double dx = x - xc;
                    const double on_spot = (y == 4) ? std::exp(-0.5 * dx * dx) : 0.0;
                    rate[(j * height + y) * width + x] = background + spot * on_spot;
                }
        }
        const std::vector<evstwin::Event> events = sensor.run(rate.data(), t_s.data(), chunk);
        for (const evstwin::Event& e : events)
            if (total++ < 12)
                std::printf("t=%8lld us  x=%2u y=%u %s\n", static_cast<long long>(e.t), e.x, e.y, e.p ? "ON" : "OFF");
    }
    std::printf("events: %zu (threads: %d, OpenMP: %s)\n", total, sensor.num_threads(),
                evstwin::has_openmp() ? "yes" : "no");
    return total > 0 ? 0 : 1;
}
