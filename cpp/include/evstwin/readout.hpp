// The sensor's readout: the arbiter and serialiser (or event-rate controller) between the pixels
// and the timestamped event stream. A streaming queue model applied to the engine's sorted events.
#pragma once

#include "config.hpp"
#include "event.hpp"

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

/// A readout of limited rate: one server, a FIFO, a timestamp counter.
///
/// * Service. Events leave one at a time, at least 1 / max_rate_hz apart: event i leaves at
///   d_i = max(a_i, d_{i-1} + 1/rate), a_i its arrival (the engine's timestamp). An event that
///   finds the readout idle leaves at once (zero delay).
/// * FIFO. An accepted event counts as waiting from its arrival until it leaves (one leaving at
///   the very instant another arrives no longer waits). An arriving event that finds
///   fifo_depth events waiting is dropped and counted; a dropped event takes no service time.
/// * Timestamp. The output time is the departure time floored to the tick (a free-running
///   counter latches the count when the event leaves the readout), then floored to the
///   record's integer microsecond. Below saturation, with a 1 us tick and the engine's
///   microsecond times, an event keeps its time exactly.
///
/// Events with equal times are served in input order. The output stays sorted by time and
/// each event's fate is settled when it arrives, so the state carried between calls is a few
/// integers and any chunking of a stream gives the same output bytes as one call.
///
/// Arithmetic is exact where it matters: times are integers in units of 10 ps (TIME_UNIT_S;
/// int64, so arrivals within +-MAX_ABS_T_US of 0, 231 days), the tick is rounded to a whole
/// unit, and the k-th departure of a busy period is its start plus round(k / rate) in units
/// (rounded once, never accumulated, so the long-run throughput is max_rate_hz to double
/// precision). fifo_depth / max_rate_hz, the longest delay a kept event can suffer, is at most
/// MAX_QUEUE_DELAY_S, so no departure can leave that range.
class Readout {
public:
    static constexpr double TIME_UNIT_S = 1e-11;     ///< the model's clock: 10 ps
    static constexpr double MAX_RATE_HZ = 1e11;      ///< service time >= one unit
    static constexpr double MIN_TICK_S = 1e-11;      ///< one unit
    static constexpr double MAX_TICK_S = 1.0;        ///< no timestamp clock is slower
    static constexpr double MAX_QUEUE_DELAY_S = 1e6;  ///< most fifo_depth / max_rate_hz
    static constexpr std::int64_t MAX_ABS_T_US = 20'000'000'000'000LL;  ///< 2e13 us, 231 days
    static constexpr double UNITS_PER_S = 1e11;      ///< 1 / TIME_UNIT_S, exact in a double

    Readout(double max_rate_hz, std::int64_t fifo_depth, double tick_s)
        : rate_hz_(max_rate_hz), depth_(fifo_depth), tick_s_(tick_s) {
        if (!(max_rate_hz > 0.0) || !(max_rate_hz <= MAX_RATE_HZ))  // also NaN
            throw std::invalid_argument("max_rate_hz must be > 0 and <= 1e11 Hz (a service time of at least 10 ps); "
                                        "got max_rate_hz=" + num(max_rate_hz));
        if (fifo_depth < 1)
            throw std::invalid_argument("fifo_depth must be >= 1 event; got fifo_depth=" + std::to_string(fifo_depth));
        if (!(static_cast<double>(fifo_depth) / max_rate_hz <= MAX_QUEUE_DELAY_S))
            throw std::invalid_argument("fifo_depth / max_rate_hz (the longest delay a kept event can suffer) must be "
                                        "<= 1e6 s; got fifo_depth=" + std::to_string(fifo_depth) + ", max_rate_hz=" +
                                        num(max_rate_hz));
        if (!(tick_s >= MIN_TICK_S) || !(tick_s <= MAX_TICK_S))
            throw std::invalid_argument("tick_s must be in [1e-11, 1] s; got tick_s=" + num(tick_s));
        service_u_ = UNITS_PER_S / max_rate_hz;  // 1e11 / 1e6 is exactly 1e5: whole services stay whole
        tick_u_ = std::llround(tick_s * UNITS_PER_S);
    }

    /// Counters since construction or the last reset().
    struct Counts {
        std::uint64_t n_in = 0;        ///< events offered
        std::uint64_t n_out = 0;       ///< events kept
        std::uint64_t n_dropped = 0;   ///< events lost to a full FIFO
        std::uint64_t n_dropped_on = 0;  ///< of which ON (p = 1)
        std::uint64_t n_delayed = 0;   ///< kept events that left after they arrived
        std::int64_t max_delay_u = 0;  ///< worst queueing delay of a kept event (departure - arrival) [10 ps]
        std::int64_t peak_waiting = 0;  ///< most events waiting at once (<= fifo_depth)
    };

    /// Pass n events (sorted by t, and not before the previous call's last) through the
    /// readout; append the kept ones to `out` with their output times and, if `delay_u` is
    /// given, each one's queueing delay (departure - arrival, before the tick) in TIME_UNIT_S;
    /// if `kept` is given, each kept event's index in `in` (the FIFO keeps their order), so a
    /// caller can carry per-event data (labels) along.
    /// Atomic: on an error (unsorted or out-of-range times) nothing is appended and the state
    /// is unchanged.
    void process(const Event* in, std::size_t n, std::vector<Event>& out,
                 std::vector<std::int64_t>* delay_u = nullptr, std::vector<std::uint64_t>* kept = nullptr) {
        check(in, n);
        State s = state_;
        const std::size_t out0 = out.size();
        const std::size_t delay0 = delay_u ? delay_u->size() : 0;
        const std::size_t kept0 = kept ? kept->size() : 0;
        try {
            for (std::size_t i = 0; i < n; ++i) {
                const Event& e = in[i];
                const std::int64_t a = e.t * UNITS_PER_US;
                ++s.counts.n_in;
                std::int64_t d;
                if (s.k_last < 0 || a >= departure(s, s.k_last + 1)) {
                    // The readout is idle by now: a new busy period starts with this event.
                    s.anchor_u = a;
                    s.k_last = 0;
                    s.k_wait = 0;
                    d = a;
                } else {
                    while (s.k_wait <= s.k_last && departure(s, s.k_wait) <= a) ++s.k_wait;
                    const std::int64_t waiting = s.k_last - s.k_wait + 1;
                    if (waiting >= depth_) {
                        ++s.counts.n_dropped;
                        if (e.p == ON) ++s.counts.n_dropped_on;
                        continue;
                    }
                    ++s.k_last;
                    d = departure(s, s.k_last);
                    if (waiting + 1 > s.counts.peak_waiting) s.counts.peak_waiting = waiting + 1;
                }
                const std::int64_t delay = d - a;
                if (delay > 0) ++s.counts.n_delayed;
                if (delay > s.counts.max_delay_u) s.counts.max_delay_u = delay;
                ++s.counts.n_out;
                out.push_back({floor_div(floor_div(d, tick_u_) * tick_u_, UNITS_PER_US), e.x, e.y, e.p});
                if (delay_u) delay_u->push_back(delay);
                if (kept) kept->push_back(i);
            }
        } catch (...) {
            out.resize(out0);
            if (delay_u) delay_u->resize(delay0);
            if (kept) kept->resize(kept0);
            throw;
        }
        if (n) s.last_t_us = in[n - 1].t;
        state_ = s;
    }

    std::vector<Event> process(const Event* in, std::size_t n, std::vector<std::int64_t>* delay_u = nullptr,
                               std::vector<std::uint64_t>* kept = nullptr) {
        std::vector<Event> out;
        out.reserve(n);
        if (delay_u) delay_u->reserve(delay_u->size() + n);
        if (kept) kept->reserve(kept->size() + n);
        process(in, n, out, delay_u, kept);
        return out;
    }

    /// Forget every event seen: an empty, idle readout with zeroed counters.
    void reset() { state_ = State{}; }

    double max_rate_hz() const { return rate_hz_; }
    std::int64_t fifo_depth() const { return depth_; }
    double tick_s() const { return tick_s_; }
    /// The tick actually used [TIME_UNIT_S] (tick_s rounded to a whole 10 ps).
    std::int64_t tick_units() const { return tick_u_; }
    const Counts& counts() const { return state_.counts; }
    /// Time of the last event offered [us] (std::numeric_limits<std::int64_t>::min() before the first).
    std::int64_t last_t_us() const { return state_.last_t_us; }

private:
    static constexpr std::int64_t UNITS_PER_US = 100'000;
    /// Departures stay below this (int64 holds 9.2e18): arrivals reach 2e18 units, a queue adds
    /// at most 1e17 (MAX_QUEUE_DELAY_S); the check is a safety net that never fires.
    static constexpr double MAX_DEPARTURE_U = 8e18;

    struct State {
        std::int64_t anchor_u = 0;  ///< arrival of the event that opened the current busy period
        std::int64_t k_last = -1;    ///< service index (in the busy period) of the last kept event; -1: none
        std::int64_t k_wait = 0;     ///< first index not yet departed at the last arrival
        std::int64_t last_t_us = std::numeric_limits<std::int64_t>::min();
        Counts counts;
    };

    /// Departure of the k-th kept event of the busy period [units]: its start plus k services,
    /// rounded once (never accumulated).
    std::int64_t departure(const State& s, std::int64_t k) const {
        const double wait = std::nearbyint(static_cast<double>(k) * service_u_);
        if (!(static_cast<double>(s.anchor_u) + wait < MAX_DEPARTURE_U))
            throw std::overflow_error("readout departure time beyond 8e7 s (the model clock's range)");
        return s.anchor_u + static_cast<std::int64_t>(wait);
    }

    static std::int64_t floor_div(std::int64_t a, std::int64_t b) {
        const std::int64_t q = a / b;
        return (a % b != 0 && a < 0) ? q - 1 : q;
    }

    /// Times sorted and in range, checked before any state changes.
    void check(const Event* in, std::size_t n) const {
        std::int64_t prev = state_.last_t_us;
        for (std::size_t i = 0; i < n; ++i) {
            const std::int64_t t = in[i].t;
            if (t > MAX_ABS_T_US || t < -MAX_ABS_T_US)
                throw std::invalid_argument("event " + std::to_string(i) + " has t=" + std::to_string(t) +
                                            " us, outside the readout's +-2e13 us (231 days)");
            if (t < prev)
                throw std::invalid_argument(
                    "events must be sorted by t: event " + std::to_string(i) + " has t=" + std::to_string(t) +
                    " us, before " + (i ? "the event before it" : "the previous call's last event") + " at t=" +
                    std::to_string(prev) + " us");
            prev = t;
        }
    }

    static std::string num(double v) {
        char buf[32];
        std::snprintf(buf, sizeof buf, "%.17g", v);
        return buf;
    }

    double rate_hz_;
    std::int64_t depth_;
    double tick_s_;
    double service_u_ = 0.0;  ///< 1 / max_rate_hz [units]
    std::int64_t tick_u_ = 1;
    State state_;
};

}  // namespace evstwin
EVSTWIN_FP_STRICT_END
