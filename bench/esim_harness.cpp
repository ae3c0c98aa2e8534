// Times ESIM's C++ core (uzh-rpg/rpg_vid2e, esim_py: EventSimulator::imageCallback) on
// in-memory log frames, for bench/bench_esim.py. No ESIM code lives here: this file is
// compiled together with ESIM's own src/esim.cpp from a checkout given at build time, e.g.
//
//   ESIM=/tmp/esim-src/esim_py
//   g++ -std=c++17 -O3 -DNDEBUG -I"$ESIM/include" -I/usr/include/eigen3 -I/usr/include/opencv4
//       bench/esim_harness.cpp "$ESIM/src/esim.cpp" -lopencv_videoio -lopencv_imgcodecs
//       -lopencv_imgproc -lopencv_core -lboost_filesystem -o build/bench-esim/esim_harness
//   (one line)
//
// (bench_esim.py runs that command itself). ESIM is GPL-3.0: the binary built this way is a
// local benchmark tool, not part of evstwin, and is not distributed.
//
// Usage: esim_harness WIDTH HEIGHT N_FRAMES C_POS C_NEG REPEATS < input
//   input: N_FRAMES float64 timestamps [s], then N_FRAMES x HEIGHT x WIDTH float32 log
//   intensities (row-major, frame after frame), native byte order.
// Output (stdout), one line: wall seconds of each repetition, its process CPU seconds, then
//   the events of the last one: "times_s <t1> ... cpu_s <c1> ... events <n> on <n_on> off <n_off>".
//
// Each repetition is a fresh EventSimulator (refractory period 0, as the ideal pixel) fed every
// frame through imageCallback, 1 thread; only that loop is timed (the frames are already in
// memory). imageCallback keeps cv::Mat headers on the frames it is given (no copy), and writes
// its reference levels into the first frame's buffer, as it does when ESIM reads files itself:
// the first frame is restored before each repetition, outside the timing.

#include <chrono>
#include <ctime>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <iostream>
#include <string>
#include <vector>

#include <esim.h>

namespace {

// imageCallback is private in esim.h. An explicit template instantiation may name a private
// member (the access rules do not apply there: [temp.explicit]), which gives a pointer to it without editing ESIM's header.
using Callback = void (EventSimulator::*)(const cv::Mat&, double, std::vector<Event>&);
struct CallbackTag {
    friend Callback image_callback(CallbackTag);
};
template <Callback M>
struct Expose {
    friend Callback image_callback(CallbackTag) { return M; }
};
template struct Expose<&EventSimulator::imageCallback>;

long parse_long(const char* name, const char* text, long lo, long hi) {
    char* end = nullptr;
    const long v = std::strtol(text, &end, 10);
    if (end == text || *end != '\0' || v < lo || v > hi) {
        std::fprintf(stderr, "esim_harness: %s must be an integer in [%ld, %ld]; got %s=%s\n", name, lo, hi, name, text);
        std::exit(2);
    }
    return v;
}

float parse_threshold(const char* name, const char* text) {
    char* end = nullptr;
    const float v = std::strtof(text, &end);
    if (end == text || *end != '\0' || !(v > 0.0f) || !(v < 100.0f)) {
        std::fprintf(stderr, "esim_harness: %s must be a number in (0, 100); got %s=%s\n", name, name, text);
        std::exit(2);
    }
    return v;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 7) {
        std::fprintf(stderr, "usage: esim_harness WIDTH HEIGHT N_FRAMES C_POS C_NEG REPEATS < timestamps+frames\n");
        return 2;
    }
    const long width = parse_long("WIDTH", argv[1], 1, 65535);
    const long height = parse_long("HEIGHT", argv[2], 1, 65535);
    const long n_frames = parse_long("N_FRAMES", argv[3], 2, 1000000);
    const float c_pos = parse_threshold("C_POS", argv[4]);
    const float c_neg = parse_threshold("C_NEG", argv[5]);
    const long repeats = parse_long("REPEATS", argv[6], 1, 1000);

    const std::size_t pixels = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
    std::vector<double> t_s(static_cast<std::size_t>(n_frames));
    std::vector<float> data(pixels * static_cast<std::size_t>(n_frames));
    if (std::fread(t_s.data(), sizeof(double), t_s.size(), stdin) != t_s.size() ||
        std::fread(data.data(), sizeof(float), data.size(), stdin) != data.size()) {
        std::fprintf(stderr, "esim_harness: stdin ended before %ld timestamps and %ld frames of %ld x %ld float32\n",
                     n_frames, n_frames, width, height);
        return 2;
    }
    const std::vector<float> first(data.begin(), data.begin() + static_cast<std::ptrdiff_t>(pixels));
    std::vector<cv::Mat> frames;
    frames.reserve(static_cast<std::size_t>(n_frames));
    for (long k = 0; k < n_frames; ++k)
        frames.emplace_back(static_cast<int>(height), static_cast<int>(width), CV_32F,
                            data.data() + static_cast<std::size_t>(k) * pixels);

    const Callback callback = image_callback(CallbackTag{});
    std::vector<double> times_s, cpu_s;
    std::vector<Event> events;
    for (long r = 0; r < repeats; ++r) {
        std::memcpy(data.data(), first.data(), pixels * sizeof(float));
        EventSimulator sim(c_pos, c_neg, /*refractory_period=*/0.0f, /*log_eps=*/0.001f, /*use_log_img=*/true);
        events.clear();
        events.reserve(1 << 20);
        const std::clock_t start_cpu = std::clock();
        const auto start = std::chrono::steady_clock::now();
        for (long k = 0; k < n_frames; ++k)
            (sim.*callback)(frames[static_cast<std::size_t>(k)], t_s[static_cast<std::size_t>(k)], events);
        const auto stop = std::chrono::steady_clock::now();
        const std::clock_t stop_cpu = std::clock();
        times_s.push_back(std::chrono::duration<double>(stop - start).count());
        cpu_s.push_back(static_cast<double>(stop_cpu - start_cpu) / CLOCKS_PER_SEC);
    }
    std::size_t n_on = 0;
    for (const Event& e : events) n_on += e.polarity_ > 0 ? 1 : 0;
    std::printf("times_s");
    for (double t : times_s) std::printf(" %.9f", t);
    std::printf(" cpu_s");
    for (double t : cpu_s) std::printf(" %.9f", t);
    std::printf(" events %zu on %zu off %zu\n", events.size(), n_on, events.size() - n_on);
    return 0;
}
