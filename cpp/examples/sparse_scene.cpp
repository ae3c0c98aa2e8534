// A tracking pipeline feeding the engine a sparse scene (Sensor::run_sparse): a constant sky
// plus a moving satellite given as its PSF stamp at each fine sample, never as full frames.
// The engine samples finely only the pixels the satellite lights, at the base rate those it
// has just left (while their levels relax), and moves every other pixel in one long exact
// step per step of the scene.
//
// A 640 x 480 sensor behind a dim sky (2,000 photons/s a pixel), a satellite of 2e7 photons/s
// crossing at 300 px/s, 4 fine samples per 1 ms base sample, 0.25 s steps.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <vector>

#include <evstwin/evstwin.hpp>

int main() {
    evstwin::PixelParams params;  // the paper's DAVIS346 pixel, its noise on
    params.cutoff_hz = 1.0;       // a slow follower: quiet long steps (long_steps_cut_below)
    const int width = 640, height = 480;
    evstwin::Sensor sensor(width, height, params, /*seed=*/1);

    const std::vector<double> sky(static_cast<std::size_t>(width) * height, 2e3);
    const double t0 = 0.0;
    sensor.run(sky.data(), &t0, 1, nullptr, nullptr, /*static_frame=*/true);  // the steady state

    const std::size_t fine_per_base = 4, base_per_step = 250;
    const std::size_t n = fine_per_base * base_per_step;
    std::vector<double> t_s(n);
    std::vector<std::uint32_t> light_sample, light_pixel;
    std::vector<double> light_rate;
    std::size_t total = 0;
    std::uint64_t updates = 0;
    for (int step = 0; step < 4; ++step) {
        light_sample.clear();
        light_pixel.clear();
        light_rate.clear();
        for (std::size_t k = 0; k < n; ++k) {
            const double t = 0.25 * step + 2.5e-4 * static_cast<double>(k + 1);
            t_s[k] = t;
            // The satellite's stamp: a Gaussian of 1 px sigma over its 7 x 7 window.
            const double xc = 20.0 + 300.0 * t, yc = 200.0 + 40.0 * t;
            for (int y = static_cast<int>(yc) - 3; y <= static_cast<int>(yc) + 3; ++y)
                for (int x = static_cast<int>(xc) - 3; x <= static_cast<int>(xc) + 3; ++x) {
                    const double r2 = (x - xc) * (x - xc) + (y - yc) * (y - yc);
                    light_sample.push_back(static_cast<std::uint32_t>(k));
                    light_pixel.push_back(static_cast<std::uint32_t>(y * width + x));
                    light_rate.push_back(2e7 * std::exp(-0.5 * r2) / (2.0 * 3.141592653589793));
                }
        }
        evstwin::SparseStep scene;
        scene.static_rate = sky.data();
        scene.t_s = t_s.data();
        scene.n_samples = n;
        scene.base_every = fine_per_base;
        scene.group_base_samples = 25;  // the per-pixel choice, every 25 ms
        scene.light_sample = light_sample.data();
        scene.light_pixel = light_pixel.data();
        scene.light_rate = light_rate.data();
        scene.n_light = light_rate.size();
        const std::vector<evstwin::Event> events = sensor.run_sparse(scene);
        total += events.size();
        updates += sensor.last_pixel_updates();
    }
    const double dense = 4.0 * static_cast<double>(n) * width * height;
    std::printf("events: %zu; pixel-updates: %llu, %.0fx fewer than every pixel at the fine rate\n", total,
                static_cast<unsigned long long>(updates), dense / static_cast<double>(updates));
    return total > 0 ? 0 : 1;
}
