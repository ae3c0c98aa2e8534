// Sensor's event collection: every block's events of a call ordered by (time, pixel) with a
// stable counting sort per sample, the samples in parallel, into the caller's storage.
// Included by sensor.hpp.
#pragma once

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <exception>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "../config.hpp"
#include "../sensor.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

inline std::size_t Sensor::collect_prepare(CollectPlan& plan, bool pixel_ordered) {
    CallBuffers& calls = *plan.calls;
    const std::size_t nblocks = calls.blocks_in_call, n_samples = calls.samples_in_call;
    std::size_t total = 0;
    for (std::size_t b = 0; b < nblocks; ++b) total += calls.block_events[b].size();
    if (total > max_events_) {
        stopped_ = true;
        throw_max_events();
    }
    plan.pixel_ordered = pixel_ordered;
    plan.row = detail::PixelDivider(static_cast<std::uint32_t>(width_));
    calls.labels.resize(total);
    if (total == 0) return 0;
    plan.events = (*plan.storage)(total);
    plan.total = total;
    for (std::size_t b = 0; b < nblocks; ++b)
        if (!calls.block_events[b].empty()) plan.busy.push_back(static_cast<std::uint32_t>(b));
    plan.base.assign(n_samples + 1, 0);
    for (const std::uint32_t b : plan.busy) {
        const std::uint32_t* ends = calls.block_sample_ends[b].data();
        std::uint32_t prev = 0;
        for (std::size_t k = 0; k < n_samples; ++k) {
            plan.base[k + 1] += ends[k] - prev;
            prev = ends[k];
        }
    }
    for (std::size_t k = 0; k < n_samples; ++k) plan.base[k + 1] += plan.base[k];
    return n_samples;
}

template <class FromLow, class FromFull, class Fn>
inline bool Sensor::for_each_event_in_sample(const CallBuffers& calls, std::uint32_t b, std::size_t k, FromLow&& from_low,
                                            FromFull&& from_full, Fn&& fn) {
    const RawEvent* out = calls.block_events[b].data();
    const std::uint32_t first = k == 0 ? 0u : calls.block_sample_ends[b][k - 1], end = calls.block_sample_ends[b][k];
    const std::int64_t* full_t = calls.block_full_t[b].empty() ? nullptr : calls.block_full_t[b].data();
    if (!full_t) {
        for (std::uint32_t e = first; e < end; ++e)
            if (!fn(from_low(out[e].t_lo), out[e])) return false;
    } else {
        for (std::uint32_t e = first; e < end; ++e)
            if (!fn(from_full(full_t[e]), out[e])) return false;
    }
    return true;
}

template <class Fn>
inline bool Sensor::for_each_offset_in_sample(const CallBuffers& calls, std::uint32_t b, std::size_t k, std::int64_t lo,
                                             Fn&& fn) {
    const std::uint32_t lo_bits = static_cast<std::uint32_t>(lo);
    return for_each_event_in_sample(
        calls, b, k, [lo_bits](std::uint32_t t_lo) { return t_lo - lo_bits; },
        [lo](std::int64_t t_us) {
            const std::uint64_t d = static_cast<std::uint64_t>(t_us) - static_cast<std::uint64_t>(lo);
            return static_cast<std::uint32_t>(std::min<std::uint64_t>(d, 0xFFFFFFFFu));
        },
        fn);
}

template <class Fn>
inline bool Sensor::for_each_in_sample(const CallBuffers& calls, std::uint32_t b, std::size_t k, std::int64_t end_us,
                                      Fn&& fn) {
    return for_each_event_in_sample(
        calls, b, k, [end_us](std::uint32_t t_lo) { return event_time(end_us, t_lo); },
        [](std::int64_t t_us) { return t_us; }, fn);
}

inline void Sensor::collect_sample(CollectPlan& plan, std::size_t k, SortScratch& sort) {
    const std::size_t base = plan.base[k], n_k = plan.base[k + 1] - base;
    if (n_k == 0) return;
    Event* events = plan.events + base;
    const CallBuffers& calls = *plan.calls;
    std::uint8_t* labels = plan.calls->labels.data() + base;
    const detail::PixelDivider row = plan.row;
    const std::int64_t end_us = floor_us(plan.t_s[k]);
    // Captured by value: the records' byte stores may alias anything, so what the loops
    // read through a reference was loaded again for every event.
    const auto put = [events, labels, row](std::size_t j, std::int64_t t_us, RawEvent e) {
        const std::uint32_t pixel = e.pixel(), y = row.quotient(pixel);
        put_event(events + j, t_us, static_cast<std::uint16_t>(pixel - y * row.divisor()),
                  static_cast<std::uint16_t>(y), e.p());
        labels[j] = e.label();
    };
    if (plan.pixel_ordered && plan.intervals_known && counting_sort_in_interval(plan, k, end_us, sort, put)) return;
    std::int64_t lo = std::numeric_limits<std::int64_t>::max(), hi = std::numeric_limits<std::int64_t>::min();
    for (const std::uint32_t b : plan.busy)
        for_each_in_sample(calls, b, k, end_us, [&](std::int64_t t_us, RawEvent) {
            lo = std::min(lo, t_us);
            hi = std::max(hi, t_us);
            return true;
        });
    const std::uint64_t span = static_cast<std::uint64_t>(hi) - static_cast<std::uint64_t>(lo);
    if (plan.pixel_ordered && span <= 4 * n_k + 4096) {
        // Counting sort: slots[d] = where the events of microsecond lo + d start.
        std::vector<std::uint32_t>& slots = sort.slots;
        slots.assign(span + 2, 0);
        for (const std::uint32_t b : plan.busy)
            for_each_in_sample(calls, b, k, end_us, [&](std::int64_t t_us, RawEvent) {
                ++slots[static_cast<std::size_t>(t_us - lo) + 1];
                return true;
            });
        for (std::size_t d = 1; d < slots.size(); ++d) slots[d] += slots[d - 1];
        for (const std::uint32_t b : plan.busy)
            for_each_in_sample(calls, b, k, end_us, [&](std::int64_t t_us, RawEvent e) {
                put(slots[static_cast<std::size_t>(t_us - lo)]++, t_us, e);
                return true;
            });
    } else {
        std::vector<TimedEvent>& sample_events = sort.sample_events;
        sample_events.clear();
        for (const std::uint32_t b : plan.busy)
            for_each_in_sample(calls, b, k, end_us, [&](std::int64_t t_us, RawEvent e) {
                sample_events.push_back(TimedEvent{t_us, e});
                return true;
            });
        std::stable_sort(sample_events.begin(), sample_events.end(), [](const TimedEvent& a, const TimedEvent& b) {
            return a.t_us != b.t_us ? a.t_us < b.t_us : a.e.pixel() < b.e.pixel();
        });
        for (std::size_t e = 0; e < n_k; ++e) put(e, sample_events[e].t_us, sample_events[e].e);
    }
}

template <class Put>
inline bool Sensor::counting_sort_in_interval(const CollectPlan& plan, std::size_t k, std::int64_t end_us, SortScratch& sort,
                               Put put) const {
    const double t0 = k == 0 ? plan.t_before : plan.t_s[k - 1];
    if (!std::isfinite(t0)) return false;
    const std::size_t n_k = plan.base[k + 1] - plan.base[k];
    const std::int64_t lo = floor_us(t0), hi = end_us;
    const std::uint64_t span = static_cast<std::uint64_t>(hi) - static_cast<std::uint64_t>(lo);
    if (!(hi >= lo && span <= 4 * n_k + 4096 && span < 0x80000000u)) return false;
    // Offsets from lo on 32 bits (for_each_offset_in_sample: lo lies within 2^31 us of the
    // sample's end, since span is small); one outside [0, span] makes the general sort take over.
    sort.slots.assign(span + 2, 0);
    std::uint32_t* slots = sort.slots.data();  // a pointer of our own: put()'s stores cannot move it
    for (const std::uint32_t b : plan.busy) {
        const bool inside = for_each_offset_in_sample(*plan.calls, b, k, lo, [&](std::uint32_t d, RawEvent) {
            if (d > span) return false;
            ++slots[d + 1];
            return true;
        });
        if (!inside) return false;
    }
    for (std::size_t d = 1; d < span + 2; ++d) slots[d] += slots[d - 1];
    // A sample with many events goes through a coarse pass first (64 spans of 2^shift
    // microseconds or fewer), stable, into staged: then put()'s destinations fall in one
    // span's short stretch of the output at a time, in the cache, instead of anywhere in
    // the sample's part of it (37,800 records a 1 kHz sample of the event-heavy load, half
    // a megabyte). Stable passes on the same keys: the same order.
    if (n_k >= STAGED_MIN_EVENTS) {
        unsigned shift = 0;
        while ((span >> shift) >= 64) ++shift;
        const std::size_t n_coarse = (span >> shift) + 1;
        sort.coarse.resize(n_coarse);
        if (sort.staged.size() < n_k) sort.staged.resize(n_k);
        std::uint32_t* coarse = sort.coarse.data();
        RawEvent* staged = sort.staged.data();
        for (std::size_t c = 0; c < n_coarse; ++c) coarse[c] = slots[c << shift];  // where span c starts
        for (const std::uint32_t b : plan.busy)
            for_each_offset_in_sample(*plan.calls, b, k, lo, [&](std::uint32_t d, RawEvent e) {
                staged[coarse[d >> shift]++] = RawEvent(d, e.code);
                return true;
            });
        for (std::size_t i = 0; i < n_k; ++i) {
            const RawEvent e = staged[i];
            put(slots[e.t_lo]++, lo + static_cast<std::int64_t>(e.t_lo), e);
        }
        return true;
    }
    for (const std::uint32_t b : plan.busy)
        for_each_offset_in_sample(*plan.calls, b, k, lo, [&](std::uint32_t d, RawEvent e) {
            put(slots[d]++, lo + static_cast<std::int64_t>(d), e);
            return true;
        });
    return true;
}

inline void Sensor::collect_finish(CallBuffers& calls) {
    for (auto& b : calls.block_events)
        if (b.capacity() > (std::size_t{1} << 18)) std::vector<RawEvent>().swap(b);
    for (auto& b : calls.block_full_t)
        if (b.capacity() > (std::size_t{1} << 17)) std::vector<std::int64_t>().swap(b);
}

}  // namespace evstwin

EVSTWIN_FP_STRICT_END
