// Small loads of the C++ engine behind figures in the README's "Speed" section, for
// callgrind instruction counts or `/usr/bin/time` CPU seconds (one thread):
//
//   short-calls N   mcreynolds' pixel (photoreceptor pole, the paper's leak and background,
//                   run-1 thresholds) on a dark 346 x 260 array at 250 Hz: 1000 samples in
//                   run() calls of N samples (what a call's fixed cost does: N = 3 was
//                   mcreynolds' call length before SUB_SAMPLED_UNIT_SAMPLES = 150)
//   run-pixels      run_pixels() on 4096 pixels, 39 fine samples a call, 20 calls, 15 % of them
//                   at photon rates of their own (a moving source's window): the per-pixel cost
//                   of rates no other pixel shares
//   sub-sampled     what `evstwin simulate mcreynolds` does in a sub-sampled unit: run_pixels()
//                   on 4096 pixels (every 7th of the first 28,672; 15 % of them at rates of
//                   their own) over 143 fine samples ending exactly on the unit's last base
//                   sample, then run() on the whole dark 346 x 260 array over the unit's 11
//                   base samples at 250 Hz, where those pixels stand ahead (held); 20 units.
//                   Prints the events' count and an FNV-1a digest.
//   fill            PixelModel::fill_noise_cache() for 200,000 distinct photon rates with the
//                   pole: the noise coefficients of one new rate
//   own-rates       what `evstwin simulate imx636-pointsource` does with a star and its halo:
//                   every pixel of a 256 x 64 array at a photon rate of its own that changes
//                   every sample (a smooth, moving glow over the dark current), the pole and a
//                   2 kHz source follower; 20 units of one run_pixels() call (a 64 x 16 patch,
//                   13 fine samples a base interval) and one run() call of 11 samples at 200 Hz
//                   (the sub-sampled path). Prints the events' count and an FNV-1a digest.
//   own-rates-pre-roll  the same array at 20 Hz in run() calls of 11 samples only, as the
//                   scenario's 12 s pre-roll: intervals long enough for most pixels to need
//                   the bridge's terms after all, and bright ones the refinement
//
//   g++ -std=c++17 -O3 -DNDEBUG -Icpp/include bench/kernel_micro.cpp -o /tmp/kernel_micro
//   valgrind --tool=callgrind /tmp/kernel_micro fill      # or: run-pixels, own-rates
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

std::uint64_t digest_of(const std::vector<evstwin::Event>& events, std::uint64_t digest) {
    const auto mix = [&digest](std::uint64_t v) {
        for (int b = 0; b < 8; ++b) digest = (digest ^ ((v >> (8 * b)) & 0xFFu)) * 1099511628211ull;
    };
    for (const auto& e : events) {
        mix(static_cast<std::uint64_t>(e.t));
        mix((static_cast<std::uint64_t>(e.y) << 32) | (static_cast<std::uint64_t>(e.x) << 8) | e.p);
    }
    return digest;
}

int sub_sampled() {
    const int width = 346, height = 260;
    evstwin::Sensor sensor(width, height, mcreynolds_pixel(), 1, 1);
    const std::size_t m = 4096, base = 11, fine = 13, units = 20;
    std::vector<std::uint32_t> px(m);
    for (std::size_t j = 0; j < m; ++j) px[j] = static_cast<std::uint32_t>(j * 7);
    std::vector<float> dark(static_cast<std::size_t>(width) * height, 0.0f);
    const double t0 = 0.0;
    std::uint64_t digest = 1469598103934665603ull;
    std::size_t n = 0;
    const auto take = [&](const std::vector<evstwin::Event>& events) {
        digest = digest_of(events, digest);
        n += events.size();
    };
    take(sensor.run(dark.data(), &t0, 1, nullptr, nullptr, true));
    std::vector<double> rate(base * fine * m), t_fine(base * fine), t_base(base);
    for (std::size_t u = 0; u < units; ++u) {
        for (std::size_t k = 0; k < base; ++k) {
            t_base[k] = static_cast<double>(u * base + k + 1) / 250.0;
            for (std::size_t f = 0; f < fine; ++f) {
                const std::size_t i = k * fine + f;
                t_fine[i] = f + 1 == fine ? t_base[k] : (static_cast<double>(u * base + k) + (f + 1.0) / fine) / 250.0;
                for (std::size_t j = 0; j < m; ++j)
                    rate[i * m + j] = (j % 100 < 85) ? 0.0 : 1e6 * (1.0 + std::sin(0.01 * j + 0.1 * (u * base * fine + i)));
            }
        }
        take(sensor.run_pixels(px.data(), m, rate.data(), t_fine.data(), t_fine.size()));
        take(sensor.run(dark.data(), t_base.data(), base, nullptr, nullptr, true));
    }
    std::printf("%zu events, digest %016llx\n", n, static_cast<unsigned long long>(digest));
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

int own_rates(bool pre_roll) {
    evstwin::PixelParams p = mcreynolds_pixel();
    p.cutoff_hz = 2000.0;
    const std::size_t width = 256, height = 64, npix = width * height, base = 11, fine = 13, units = 20;
    evstwin::Sensor sensor(static_cast<int>(width), static_cast<int>(height), p, 1, 1);
    // A patch of 64 x 16 pixels is sampled finely (the star's core), the rest at the base rate.
    std::vector<std::uint32_t> patch;
    for (std::size_t y = 24; y < 40; ++y)
        for (std::size_t x = 96; x < 160; ++x) patch.push_back(static_cast<std::uint32_t>(y * width + x));
    const double dt = pre_roll ? 1.0 / 20.0 : 1.0 / 200.0;
    // The glow on pixel (x, y) at time t: a wide bump moving 30 px/s across the array.
    const auto glow = [&](std::size_t pixel, double t) {
        const double x = static_cast<double>(pixel % width) - 60.0 - 30.0 * t, y = static_cast<double>(pixel / width) - 32.0;
        return 3e4 + 5e5 / (1.0 + (x * x + y * y) / 900.0);
    };
    std::vector<double> frames(base * npix), t_base(base), rate(base * fine * patch.size()), t_fine(base * fine);
    std::uint64_t digest = 1469598103934665603ull;
    const auto mix = [&digest](std::uint64_t v) {
        for (int b = 0; b < 8; ++b) digest = (digest ^ ((v >> (8 * b)) & 0xFFu)) * 1099511628211ull;
    };
    std::size_t n = 0;
    const auto take = [&](const std::vector<evstwin::Event>& events) {
        for (const auto& e : events) {
            mix(static_cast<std::uint64_t>(e.t));
            mix((static_cast<std::uint64_t>(e.y) << 32) | (static_cast<std::uint64_t>(e.x) << 8) | e.p);
        }
        n += events.size();
    };
    for (std::size_t i = 0; i < npix; ++i) frames[i] = glow(i, 0.0);
    const double t0 = 0.0;
    take(sensor.run(frames.data(), &t0, 1, nullptr, nullptr, true));
    for (std::size_t u = 0; u < units; ++u) {
        for (std::size_t k = 0; k < base; ++k) {
            t_base[k] = static_cast<double>(u * base + k + 1) * dt;
            for (std::size_t i = 0; i < npix; ++i) frames[k * npix + i] = glow(i, t_base[k]);
            for (std::size_t f = 0; f < fine; ++f) {
                const std::size_t j = k * fine + f;
                t_fine[j] = f + 1 == fine ? t_base[k] : (static_cast<double>(u * base + k) + (f + 1.0) / fine) * dt;
                for (std::size_t q = 0; q < patch.size(); ++q) rate[j * patch.size() + q] = glow(patch[q], t_fine[j]);
            }
        }
        if (!pre_roll) take(sensor.run_pixels(patch.data(), patch.size(), rate.data(), t_fine.data(), t_fine.size()));
        take(sensor.run(frames.data(), t_base.data(), base, nullptr, nullptr, true));
    }
    std::printf("%zu events, digest %016llx\n", n, static_cast<unsigned long long>(digest));
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc == 3 && std::strcmp(argv[1], "short-calls") == 0) return short_calls(std::atoi(argv[2]));
    if (argc == 2 && std::strcmp(argv[1], "run-pixels") == 0) return run_pixels();
    if (argc == 2 && std::strcmp(argv[1], "sub-sampled") == 0) return sub_sampled();
    if (argc == 2 && std::strcmp(argv[1], "fill") == 0) return fill();
    if (argc == 2 && std::strcmp(argv[1], "own-rates") == 0) return own_rates(false);
    if (argc == 2 && std::strcmp(argv[1], "own-rates-pre-roll") == 0) return own_rates(true);
    std::fprintf(stderr, "usage: %s short-calls N | run-pixels | sub-sampled | fill | own-rates | own-rates-pre-roll\n", argv[0]);
    return 2;
}
