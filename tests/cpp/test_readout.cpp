// The readout model (readout.hpp) from C++: bursts, drops, chunking, refusals. The Python
// suite (tests/python/test_readout.py) checks it against an exact-rational reference.
#include <evstwin/readout.hpp>

#include "check.hpp"

#include <cstdint>
#include <stdexcept>
#include <vector>

using evstwin::Event;
using evstwin::Readout;

namespace {

std::vector<Event> burst(std::int64_t t_us, int n, std::uint8_t p = 1) {
    std::vector<Event> ev;
    for (int i = 0; i < n; ++i) ev.push_back({t_us, static_cast<std::uint16_t>(i), 0, p});
    return ev;
}

template <class F>
bool throws_invalid(F&& f) {
    try {
        f();
    } catch (const std::invalid_argument&) {
        return true;
    }
    return false;
}

}  // namespace

TEST(burst_leaves_one_service_apart_and_a_full_fifo_drops) {
    Readout r(1e6, 3, 1e-6);
    std::vector<std::int64_t> delay;
    const auto ev = burst(0, 10);
    const auto out = r.process(ev.data(), ev.size(), &delay);
    CHECK(out.size() == 4);
    for (std::size_t i = 0; i < out.size(); ++i) {
        CHECK(out[i].t == static_cast<std::int64_t>(i));
        CHECK(out[i].x == i);
        CHECK(delay[i] == static_cast<std::int64_t>(i) * 100'000);  // i us in 10 ps units
    }
    CHECK(r.counts().n_dropped == 6 && r.counts().n_dropped_on == 6 && r.counts().peak_waiting == 3);
}

TEST(any_chunking_gives_the_same_events) {
    std::vector<Event> ev;
    std::uint32_t state = 12345;
    std::int64_t t = 0;
    for (int i = 0; i < 20000; ++i) {
        state = state * 1664525u + 1013904223u;
        if ((state >> 28) < 6) t += (state >> 20) % 7;  // bursts of equal times
        ev.push_back({t, static_cast<std::uint16_t>(i % 346), static_cast<std::uint16_t>(i % 260),
                      static_cast<std::uint8_t>((state >> 8) & 1)});
    }
    Readout one(5e5, 32, 1e-6);  // 0.5 events/us against ~0.9 arriving: saturated
    const auto whole = one.process(ev.data(), ev.size());
    CHECK(one.counts().n_dropped > 0);
    for (std::size_t step : {1u, 7u, 1000u, 19999u}) {
        Readout r(5e5, 32, 1e-6);
        std::vector<Event> out;
        for (std::size_t a = 0; a < ev.size(); a += step) r.process(ev.data() + a, std::min(step, ev.size() - a), out);
        CHECK(out.size() == whole.size());
        bool same = out.size() == whole.size();
        for (std::size_t i = 0; same && i < out.size(); ++i)
            same = out[i].t == whole[i].t && out[i].x == whole[i].x && out[i].y == whole[i].y && out[i].p == whole[i].p;
        CHECK(same);
        CHECK(r.counts().n_dropped == one.counts().n_dropped && r.counts().max_delay_u == one.counts().max_delay_u);
    }
}

TEST(bad_parameters_and_unsorted_events_are_refused) {
    CHECK(throws_invalid([] { Readout(0.0, 1, 1e-6); }));
    CHECK(throws_invalid([] { Readout(-1.0, 1, 1e-6); }));
    CHECK(throws_invalid([] { Readout(std::nan(""), 1, 1e-6); }));
    CHECK(throws_invalid([] { Readout(1e6, 0, 1e-6); }));
    CHECK(throws_invalid([] { Readout(1e6, 1, 0.0); }));
    CHECK(throws_invalid([] { Readout(1e-7, 1, 1e-6); }));  // 1e7 s of queue
    Readout r(1e6, 2, 1e-6);
    std::vector<Event> ev = {{5, 0, 0, 1}, {3, 0, 0, 1}};
    std::vector<Event> out;
    CHECK(throws_invalid([&] { r.process(ev.data(), ev.size(), out); }));
    CHECK(out.empty() && r.counts().n_in == 0);
    ev = {{Readout::MAX_ABS_T_US + 1, 0, 0, 1}};
    CHECK(throws_invalid([&] { r.process(ev.data(), ev.size(), out); }));
    // The far end of the range works, and a queue there stays in range.
    ev = burst(Readout::MAX_ABS_T_US, 3);
    Readout slow(1e-6 * 2, 2, 1.0);  // 2 events per 1e6 s: a 1e6 s queue at the end of time
    out = slow.process(ev.data(), ev.size());
    CHECK(out.size() == 3 && out[2].t == Readout::MAX_ABS_T_US + 1'000'000'000'000);
}

TEST_MAIN()
