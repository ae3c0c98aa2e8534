// A consumer of evstwin: a 4 x 4 sensor sees a 10x brightening and must report ON events.
#include <evstwin/evstwin.hpp>

#include <cstdio>
#include <vector>

int main() {
    evstwin::PixelParams p;
    p.photon_shot_noise = false;
    p.dark_model = evstwin::DarkModel::None;
    p.shot_noise_rate_hz = 0.0;
    p.leak_rate_hz = 0.0;
    p.cutoff_hz.reset();
    p.refractory_s = 0.0;
    evstwin::Sensor sensor(4, 4, p);
    std::vector<double> rate(2 * 16, 1e8), t = {0.0, 1e-3};
    for (int i = 16; i < 32; ++i) rate[i] = 1e9;
    const auto events = sensor.run(rate.data(), t.data(), 2);
    std::printf("evstwin %s consumer: %zu events\n", EVSTWIN_VERSION, events.size());
    return events.size() == 16 * 11 ? 0 : 1;  // floor(ln 10 / 0.2061) = 11 per pixel
}
