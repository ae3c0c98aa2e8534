// The README's C++ snippet ("Using it from C++") as a whole program, built and run by ctest so
// that the snippet keeps compiling against the API: the lines between "README:" and "end of
// README" are the README's, the rest supplies what the snippet takes as given (photon_rate,
// t_s, n_samples).
#include <cstddef>
#include <cstdio>
#include <vector>

#include <evstwin/evstwin.hpp>

int main() {
    // The scene: 200 samples 1 ms apart of a dim 1e6 photons/s on every pixel of the DAVIS346
    // frame, rising to 1e8 photons/s halfway through (every pixel sees one step up).
    const std::size_t n_samples = 200, pixels = 346 * 260;
    std::vector<double> photon_rate(n_samples * pixels), t_s(n_samples);
    for (std::size_t k = 0; k < n_samples; ++k) {
        t_s[k] = 1e-3 * static_cast<double>(k);
        const double rate = k < n_samples / 2 ? 1e6 : 1e8;
        for (std::size_t i = 0; i < pixels; ++i) photon_rate[k * pixels + i] = rate;
    }

    // README:
    evstwin::PixelParams params;                    // the paper's DAVIS346 pixel
    evstwin::Sensor sensor(346, 260, params, /*seed=*/1);
    // photon_rate: n_samples x 260 x 346 photons/s, C order; t_s: n_samples increasing times
    std::vector<evstwin::Event> events = sensor.run(photon_rate.data(), t_s.data(), n_samples);
    // end of README

    std::size_t on = 0;
    for (const evstwin::Event& e : events) on += e.p ? 1 : 0;
    std::printf("events: %zu (ON %zu)\n", events.size(), on);
    return events.empty() ? 1 : 0;
}
