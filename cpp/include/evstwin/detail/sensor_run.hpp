// Sensor's calls and block scheduler: run_into() and run_pixels_into() (checks, the parallel
// loop over blocks, the call's event count), for_each_block() (the OpenMP region), and
// run_block() / run_pixel_block(), which choose the kernel for each block and sample
// (Kernel) and hand its events to the block's list. Included by sensor.hpp.
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

template <class Real>
inline std::size_t Sensor::run_into(const EventStorage& storage, const Real* photon_rate, const double* t_s,
                     std::size_t n_samples, const std::vector<std::uint32_t>* probe_pixels,
                     std::vector<TraceSample>* trace, bool static_frame) {
    const std::size_t npix = state_.size();
    check_usable();
    if (n_samples == 0) {
        calls_.labels.clear();
        return 0;
    }
    check_times(t_s, n_samples);
    // The rates are checked at the start of the call's parallel region (RateCheck), before
    // any pixel moves.
    RateCheck<Real> rate_check(*this, photon_rate, (static_frame ? 1 : n_samples) * npix);
    const std::size_t sample_stride = static_frame ? 0 : npix;
    const std::vector<SampleConstants> consts = sample_constants(t_s, n_samples);

    std::vector<std::int32_t> probe_slot;
    std::size_t n_probe = 0;
    if (probe_pixels && trace && !probe_pixels->empty()) {
        probe_slot.assign(npix, -1);
        n_probe = probe_pixels->size();
        for (std::size_t j = 0; j < n_probe; ++j) {
            const std::uint32_t px = (*probe_pixels)[j];
            if (px >= npix)
                throw std::invalid_argument("probe pixel index " + std::to_string(px) + " is outside the " +
                                            std::to_string(npix) + "-pixel sensor");
            if (probe_slot[px] >= 0)
                throw std::invalid_argument("probe pixels must not repeat; got pixel " + std::to_string(px) + " twice");
            probe_slot[px] = static_cast<std::int32_t>(j);
        }
        trace->assign(n_samples * n_probe, TraceSample{});
    }

    const std::size_t nblocks = (npix + BLOCK - 1) / BLOCK;
    start_call(calls_, nblocks, n_samples);

    CollectPlan plan;
    plan.calls = &calls_;
    plan.storage = &storage;
    plan.t_s = t_s;
    plan.intervals_known = true;
    plan.t_before = last_t_;
    guarded_for_each_block(
        calls_, nblocks, npix * n_samples, rate_check,
        [&](std::size_t b, PoissonSampler& poisson, BlockModel::BlockScratch& scratch) {
            run_block(b, photon_rate, sample_stride, n_samples, consts, poisson, scratch,
                      probe_slot.empty() ? nullptr : probe_slot.data(), n_probe, trace ? trace->data() : nullptr);
        },
        [&] { return collect_prepare(plan, true); },
        [&](std::size_t k, SortScratch& sort) { collect_sample(plan, k, sort); });
    const std::size_t bad = rate_check.first_bad();
    if (bad < rate_check.total) {
        const std::size_t k = bad / npix, pix = bad % npix;
        throw_bad_rate("photon_rate[" + std::to_string(k) + ", " + std::to_string(pix / width_) + ", " +
                           std::to_string(pix % width_) + "]",
                       static_cast<double>(photon_rate[bad]));
    }

    samples_ += n_samples;
    last_t_ = t_s[n_samples - 1];
    collect_finish(calls_);
    return plan.total;
}

template <class Real>
inline std::size_t Sensor::run_pixels_with(CallBuffers& calls, const EventStorage& storage, const std::uint32_t* pixels,
                                           std::size_t n_pixels, const Real* photon_rate, const double* t_s,
                                           std::size_t n_samples, bool static_rates) {
    if (n_pixels == 0 || n_samples == 0) {
        calls.labels.clear();
        return 0;
    }
    const std::size_t npix = state_.size();
    std::vector<char> seen(npix, 0);
    double latest = -std::numeric_limits<double>::infinity();
    std::size_t latest_j = 0;
    for (std::size_t j = 0; j < n_pixels; ++j) {
        if (pixels[j] >= npix)
            throw std::invalid_argument("pixels[" + std::to_string(j) + "]=" + std::to_string(pixels[j]) +
                                        " is outside the " + std::to_string(npix) + "-pixel sensor");
        if (seen[pixels[j]])
            throw std::invalid_argument("pixels must not repeat; got pixel " + std::to_string(pixels[j]) + " twice");
        seen[pixels[j]] = 1;
        if (state_[pixels[j]].t > latest) {
            latest = state_[pixels[j]].t;
            latest_j = j;
        }
    }
    for (std::size_t k = 0; k < n_samples; ++k) {
        if (!std::isfinite(t_s[k]))
            throw std::invalid_argument("t_s must be finite; got t_s[" + std::to_string(k) + "]=" + detail::fmt(t_s[k]));
        if (!(std::fabs(t_s[k]) < 9.2e12))  // as run(): event times are int64 microseconds
            throw std::invalid_argument("t_s must lie within +-9.2e12 s (int64 microseconds); got t_s[" +
                                        std::to_string(k) + "]=" + detail::fmt(t_s[k]));
        const double prev = k == 0 ? latest : t_s[k - 1];
        if (!(t_s[k] > prev)) {
            if (k == 0)
                throw std::invalid_argument("t_s must start after the last sample of every listed pixel; pixels[" +
                                            std::to_string(latest_j) + "] is at " + detail::fmt(latest) +
                                            " s; got t_s[0]=" + detail::fmt(t_s[0]));
            throw std::invalid_argument("t_s must be strictly increasing; got t_s[" + std::to_string(k - 1) +
                                        "]=" + detail::fmt(prev) + " and t_s[" + std::to_string(k) +
                                        "]=" + detail::fmt(t_s[k]));
        }
        if (k > 0) check_dt(t_s[k] - prev, k);
    }
    for (std::size_t j = 0; j < n_pixels; ++j)
        if (state_[pixels[j]].n > 0) check_dt(t_s[0] - state_[pixels[j]].t, 0);
    std::vector<SampleConstants> consts(n_samples);
    for (std::size_t k = 1; k < n_samples; ++k) consts[k] = model_.constants(t_s[k - 1], t_s[k]);
    const std::size_t nblocks = (n_pixels + BLOCK - 1) / BLOCK;
    start_call(calls, nblocks, n_samples);
    // The rates are checked block by block, each block's columns just before it steps them
    // (they are then in the cache for its steps: a separate pass over the whole array read it
    // from memory once more, 7 % of mcreynolds' run_pixels calls), and the blocks' new
    // states wait in calls.pixel_states until every block has passed: a bad value anywhere leaves
    // every pixel as it was, and the error names the first one in the array.
    const std::size_t rows = static_rates ? 1 : n_samples, sample_stride = static_rates ? 0 : n_pixels;
    const std::size_t total = rows * n_pixels;
    std::vector<std::size_t> block_bad(nblocks, total);
    std::vector<PixelState>& pixel_states = calls.pixel_states;
    if (pixel_states.size() < n_pixels) pixel_states.resize(n_pixels);
    NoCheck no_check{total};
    // The listed pixels need not be in increasing order: each sample's events are sorted
    // by (t, pixel), not only by t.
    CollectPlan plan;
    plan.calls = &calls;
    plan.storage = &storage;
    plan.t_s = t_s;
    std::size_t bad = total;
    try {
        guarded_for_each_block(
            calls, nblocks, total, no_check,
            [&](std::size_t b, PoissonSampler& poisson, BlockModel::BlockScratch& scratch) {
                const std::size_t lo = b * BLOCK, m = std::min(n_pixels, lo + BLOCK) - lo;
                for (std::size_t k = 0; k < rows; ++k) {
                    const std::size_t i = first_bad_rate(photon_rate + k * n_pixels + lo, m);
                    if (i < m) {
                        block_bad[b] = k * n_pixels + lo + i;
                        return;
                    }
                }
                run_pixel_block(calls, b, pixels, n_pixels, photon_rate, sample_stride, t_s, n_samples, consts, poisson, scratch);
            },
            [&]() -> std::size_t {
                bad = *std::min_element(block_bad.begin(), block_bad.end());
                if (bad < total) return 0;
                for (std::size_t j = 0; j < n_pixels; ++j) {
                    state_[pixels[j]] = pixel_states[j];
                    block_synced_[pixels[j] / BLOCK] = 0;  // this block's pixels now stand apart
                }
                return collect_prepare(plan, false);
            },
            [&](std::size_t k, SortScratch& sort) { collect_sample(plan, k, sort); });
    } catch (...) {
        // A block's error (max_events) before every block's rates were checked: a bad rate
        // is still the error, and no pixel has moved (the states wait in calls.pixel_states).
        bad = first_bad_rate(photon_rate, total);
        if (bad >= total) throw;
        stopped_ = false;
    }
    if (bad < total)
        throw_bad_rate("photon_rate[" + std::to_string(bad / n_pixels) + ", " + std::to_string(bad % n_pixels) + "]",
                       static_cast<double>(photon_rate[bad]));
    collect_finish(calls);
    return plan.total;
}

template <class Check, class Fn, class Prepare, class Part>
inline void Sensor::for_each_block(std::size_t nblocks, std::size_t updates, Check& check, Fn&& fn, Prepare&& prepare,
                    Part&& part) {
    std::exception_ptr error;
    const std::int64_t nb = static_cast<std::int64_t>(nblocks);
    const std::int64_t n_checks = static_cast<std::int64_t>(check.parts());
    std::int64_t n_parts = 0;  // set by prepare(); read by every thread after the barrier that ends it
    bool input_bad = false;    // set by one thread; read by every thread after the barrier that ends it
#if EVSTWIN_HAS_OPENMP
    const bool parallel = num_threads_ > 1 && nblocks > 1 && updates >= PARALLEL_MIN_UPDATES;
#pragma omp parallel num_threads(num_threads_) if (parallel)
#endif
    {
#if EVSTWIN_HAS_OPENMP
#pragma omp for schedule(dynamic, 4)
#endif
        for (std::int64_t i = 0; i < n_checks; ++i) check.check_part(static_cast<std::size_t>(i));
#if EVSTWIN_HAS_OPENMP
#pragma omp single
#endif
        input_bad = check.first_bad() < check.total;
        // (the single's implied barrier: input_bad final)
        const std::int64_t n_blocks_to_run = input_bad ? 0 : nb;
        PoissonSampler poisson;
        BlockModel::BlockScratch scratch;
#if EVSTWIN_HAS_OPENMP
#pragma omp for schedule(dynamic, 1)
#endif
        for (std::int64_t b = 0; b < n_blocks_to_run; ++b) {
            try {
                fn(static_cast<std::size_t>(b), poisson, scratch);
            } catch (...) {
#if EVSTWIN_HAS_OPENMP
#pragma omp critical(evstwin_error)
#endif
                if (!error) error = std::current_exception();
            }
        }
        // (the loop's implied barrier: every block is done, `error` final)
#if EVSTWIN_HAS_OPENMP
#pragma omp single
#endif
        {
            if (!error && !input_bad) {
                try {
                    n_parts = static_cast<std::int64_t>(prepare());
                } catch (...) {
                    error = std::current_exception();
                }
            }
        }
        SortScratch sort;
#if EVSTWIN_HAS_OPENMP
#pragma omp for schedule(dynamic, 1)
#endif
        for (std::int64_t i = 0; i < n_parts; ++i) {
            try {
                part(static_cast<std::size_t>(i), sort);
            } catch (...) {
#if EVSTWIN_HAS_OPENMP
#pragma omp critical(evstwin_error)
#endif
                if (!error) error = std::current_exception();
            }
        }
    }
    if (error) std::rethrow_exception(error);
}

template <class Real>
inline void Sensor::run_block(std::size_t b, const Real* rate, std::size_t sample_stride, std::size_t n_samples,
               const std::vector<SampleConstants>& consts,
               PoissonSampler& poisson, BlockModel::BlockScratch& scratch, const std::int32_t* probe_slot,
               std::size_t n_probe, TraceSample* trace) {
    const std::size_t npix = state_.size();
    const std::size_t lo = b * BLOCK, hi = std::min(npix, lo + BLOCK);
    TakenEvents taken(calls_.block_events[b], calls_.block_full_t[b]);
    std::vector<RawEvent>& out = taken.out;
    std::uint32_t pixel = 0;
    std::uint32_t* ends = calls_.block_sample_ends[b].data();  // out.size() after each sample
    const auto sample_end_us = [&consts](std::size_t j) { return floor_us(consts[j].t1); };
    BlockEmit<decltype(sample_end_us)> emit{*this, calls_, taken, ends, pixel, sample_end_us};
    const bool kernel = !probe_slot && kernel_ != Kernel::PerPixel && model_.has_block_kernel();
    const bool soa_kernel = kernel && kernel_ != Kernel::Blocks && model_.has_soa_kernel();
    const bool soa_always = kernel_ == Kernel::Vector;  // not Auto's judgement of where it pays
    std::uint32_t ids[BLOCK], active[BLOCK];
    for (std::size_t i = lo; i < hi; ++i) ids[i - lo] = static_cast<std::uint32_t>(i);
    // After a kernel step that skipped nobody, all stand at the next t0. So they do at the
    // first sample where the block's last call ended that way and nothing moved them since
    // (block_synced_): then its states are not read here only to find that out.
    bool synced = kernel && block_synced_[b] != 0;
    // Whether scratch.soa holds this block's state (standing at soa_t), to be stored back
    // before any other path touches it and at the end.
    bool in_soa = false;
    double soa_t = 0.0;
    // Pixels in the arrays that stand past the samples so far (run_pixels sampled them
    // finely; step_block_soa's held ones): their states stay in state_, untouched, until
    // a sample starts at their time and they are taken into the arrays.
    std::uint8_t held[BLOCK];
    std::uint32_t held_at[BLOCK];
    std::size_t n_held = 0;
    // Where many of a block's pixels need the per-pixel path (an event-heavy scene;
    // SOA_MAX_BUSY_QUARTERS), copying them out of the arrays and back costs more than the
    // vector pass saves: the block goes on with the array-of-structures kernel for the rest
    // of the call. The same events.
    bool soa_pays = soa_kernel;
    const auto leave_soa = [&] {
        if (in_soa) scratch.soa.store(state_.data() + lo, hi - lo, soa_t, n_held ? held : nullptr);
        in_soa = false;
        n_held = 0;
    };
    for (std::size_t k = 0; k < n_samples; ++k) {
        const SampleConstants& c = consts[k];
        const Real* row = rate + k * sample_stride;
        // The next sample's rates for this block: one row of a (samples, pixels) array, a
        // whole frame (360 KB at DAVIS346) after this one, so the hardware prefetcher, which
        // stays within a page, never asks for it and its first touch waited on memory.
#if defined(__GNUC__) || defined(__clang__)
        if (sample_stride != 0 && k + 1 < n_samples) {
            const char* next = reinterpret_cast<const char*>(row + sample_stride + lo);
            for (std::size_t line = 0; line < (hi - lo) * sizeof(Real); line += 64) __builtin_prefetch(next + line, 0, 2);
            __builtin_prefetch(next + (hi - lo) * sizeof(Real) - 1, 0, 2);  // a row not 64-byte aligned
        }
#endif
        emit.start_sample(k);
        std::size_t n_active = hi - lo;
        bool eligible = kernel && synced;
        if (kernel && !synced && in_soa) {
            // The arrays' pixels stand at c.t0 (soa_t); the held ones at their own times.
            eligible = true;
            for (std::size_t q = 0; q < n_held; ++q) {
                const PixelState& s = state_[lo + held_at[q]];
                eligible &= ((s.t == c.t0) & (s.n > 0)) | (s.t >= c.t1);
            }
            if (eligible) {
                // Those that stand at c.t0 now join the arrays.
                std::size_t still = 0;
                for (std::size_t q = 0; q < n_held; ++q) {
                    const std::size_t j = held_at[q];
                    if (state_[lo + j].t == c.t0) {
                        scratch.soa.take(state_[lo + j], j, scratch.soa.now());
                        held[j] = 0;
                    } else {
                        held_at[still++] = static_cast<std::uint32_t>(j);
                    }
                }
                n_held = still;
                n_active = hi - lo - n_held;
            } else {
                leave_soa();  // and scan the states below
            }
        }
        if (kernel && !synced && !in_soa) {
            // Eligible when every pixel either stands at t0 or has already passed t1 (a
            // pixel sub-sampled by run_pixels): the latter are skipped.
            eligible = true;
            n_active = 0;
            for (std::size_t i = lo; i < hi; ++i) {
                // The states come from memory here, at the call's first sample of a block
                // whose pixels may stand apart (block_synced_ clear: run_pixels moved some),
                // at a stride the hardware prefetcher follows only within a page: every
                // cache line of the record a few pixels ahead is asked for now, for load()
                // below. (Written out here: the same loop in a helper function in this
                // header left no prefetch instruction in a GCC 12 -O3 build.)
#if defined(__GNUC__) || defined(__clang__)
                if (i + STATE_PREFETCH_AHEAD < hi) {
                    const char* ahead = reinterpret_cast<const char*>(&state_[i + STATE_PREFETCH_AHEAD]);
                    for (std::size_t line = 0; line < sizeof(PixelState); line += 64) __builtin_prefetch(ahead + line);
                    __builtin_prefetch(ahead + sizeof(PixelState) - 1);  // where the record is not 64-byte aligned
                }
#endif
                const PixelState& s = state_[i];
                const bool at_t0 = (s.t == c.t0) & (s.n > 0);
                eligible &= at_t0 | (s.t >= c.t1);
                active[n_active] = static_cast<std::uint32_t>(i - lo);
                n_active += at_t0;
            }
        }
        // The arrays pay while most of the block advances: the passes run over the held
        // pixels too, and are dropped for them.
        if (eligible && soa_pays && (in_soa || soa_always || SOA_MIN_ACTIVE_QUARTERS * (hi - lo) <= 4 * n_active)) {
            if (!in_soa) {
                scratch.soa.load(state_.data() + lo, hi - lo);
                if (n_active < hi - lo) {
                    std::fill(held, held + (hi - lo), std::uint8_t{1});
                    for (std::size_t q = 0; q < n_active; ++q) held[active[q]] = 0;
                    for (std::size_t j = 0; j < hi - lo; ++j)
                        if (held[j]) held_at[n_held++] = static_cast<std::uint32_t>(j);
                }
            }
            in_soa = true;
            const std::size_t n_busy = model_.step_block_soa(scratch.soa, state_.data() + lo, ids, hi - lo, row + lo,
                                                             c, key_, scratch, emit, pixel, held_at, n_held);
            soa_t = c.t1;
            synced = n_held == 0;
            if (!soa_always && 4 * n_busy > SOA_MAX_BUSY_QUARTERS * (hi - lo)) {
                soa_pays = false;
                leave_soa();
            }
        } else if (eligible) {
            leave_soa();
            const bool all = n_active == hi - lo;
            model_.step_block(BlockModel::BlockView{state_.data() + lo, ids, all ? nullptr : active, n_active},
                              row + lo, c, key_, poisson, scratch, emit, pixel);
            synced = all;
        } else if (!probe_slot) {
            leave_soa();
            // Pixels standing apart (run_pixels or run_sparse moved some): those at t0 take
            // the kernel, the others the per-pixel path; then the sample's events go back into
            // pixel order, which collect_sample() expects of a block (the order the per-pixel
            // path alone gives, so the same events in the same order). A drifting star field's
            // pixels stand apart in every block of the IMX636 array, where the per-pixel path
            // for every pixel made run_sparse's full-array step 5-15 times slower.
            std::size_t n_at = 0;
            std::uint8_t at_t0[BLOCK];
            if (kernel) {
                for (std::size_t i = lo; i < hi; ++i) {
                    const PixelState& s = state_[i];
                    at_t0[i - lo] = (s.t == c.t0) & (s.n > 0);
                    active[n_at] = static_cast<std::uint32_t>(i - lo);
                    n_at += at_t0[i - lo];
                }
            }
            const std::size_t first_event = out.size();
            if (n_at > 0)
                model_.step_block(BlockModel::BlockView{state_.data() + lo, ids, active, n_at}, row + lo, c, key_,
                                  poisson, scratch, emit, pixel);
            const std::size_t kernel_events = out.size();
            for (std::size_t i = lo; i < hi; ++i) {
                if (n_at > 0 && at_t0[i - lo]) continue;
                pixel = static_cast<std::uint32_t>(i);
                model_.advance(state_[i], static_cast<double>(row[i]), c, key_, pixel, poisson, scratch.noise, emit);
            }
            if (kernel_events > first_event && out.size() > kernel_events)
                stable_sort_by_pixel(out, taken.full_t, first_event);
        } else {
            for (std::size_t i = lo; i < hi; ++i) {
                pixel = static_cast<std::uint32_t>(i);
                TraceSample* tr = probe_slot[i] >= 0 ? trace + k * n_probe + probe_slot[i] : nullptr;
                model_.advance(state_[i], static_cast<double>(row[i]), c, key_, pixel, poisson, scratch.noise, emit, tr);
            }
        }
        ends[k] = static_cast<std::uint32_t>(out.size());
    }
    leave_soa();
    block_synced_[b] = synced;
}

template <class Real>
inline void Sensor::run_pixel_block(CallBuffers& calls, std::size_t b, const std::uint32_t* pixels, std::size_t n_pixels, const Real* rate,
                                    std::size_t sample_stride, const double* t_s, std::size_t n_samples,
                                    const std::vector<SampleConstants>& consts, PoissonSampler& poisson,
                                    BlockModel::BlockScratch& scratch) {
    const std::size_t lo = b * BLOCK, hi = std::min(n_pixels, lo + BLOCK);
    TakenEvents taken(calls.block_events[b], calls.block_full_t[b]);
    std::vector<RawEvent>& out = taken.out;
    std::uint32_t pixel = 0;
    std::uint32_t* ends = calls.block_sample_ends[b].data();  // out.size() after each sample
    const auto sample_end_us = [t_s](std::size_t j) { return floor_us(t_s[j]); };
    BlockEmit<decltype(sample_end_us)> emit{*this, calls, taken, ends, pixel, sample_end_us};
    emit.start_sample(0);
    // The listed pixels' states are gathered into a contiguous block, advanced sample-major
    // (each sample reads one contiguous stretch of its row of rates) and scattered back.
    // The first interval starts at each pixel's own last sample; after it, every pixel
    // stands at the same time and the block kernel applies.
    const std::size_t m = hi - lo;
    PixelState* local = calls.pixel_states.data() + lo;  // run_pixels_with() puts them back
    for (std::size_t j = 0; j < m; ++j) local[j] = state_[pixels[lo + j]];
    const bool kernel = kernel_ != Kernel::PerPixel && model_.has_block_kernel();
    // Usually every listed pixel stands at the same time (the previous base sample).
    bool same_start = kernel;
    for (std::size_t j = 0; j < m && same_start; ++j) same_start = local[j].t == local[0].t && local[j].n > 0;
    if (same_start) {
        model_.step_block(BlockModel::BlockView{local, pixels + lo, nullptr, m}, rate + lo,
                          model_.constants(local[0].t, t_s[0]), key_, poisson, scratch, emit, pixel);
    } else {
        for (std::size_t j = 0; j < m; ++j) {
            pixel = pixels[lo + j];
            PixelState& s = local[j];
            model_.advance(s, static_cast<double>(rate[lo + j]), model_.constants(s.t, t_s[0]), key_, pixel, poisson,
                           scratch.noise, emit);
        }
    }
    ends[0] = static_cast<std::uint32_t>(out.size());
    std::size_t k = 1;
    if (kernel && kernel_ != Kernel::Blocks && model_.has_soa_kernel() && n_samples > 1) {
        // Every pixel now stands at t_s[0]: the rest of the samples on the block's arrays.
        scratch.soa.load(local, m);
        for (; k < n_samples; ++k) {
            emit.start_sample(k);
            model_.step_block_soa(scratch.soa, local, pixels + lo, m, rate + k * sample_stride + lo, consts[k], key_,
                                  scratch, emit, pixel);
            ends[k] = static_cast<std::uint32_t>(out.size());
        }
        scratch.soa.store(local, m, t_s[n_samples - 1]);
    }
    for (; k < n_samples; ++k) {
        emit.start_sample(k);
        const Real* row = rate + k * sample_stride + lo;
        if (kernel) {
            model_.step_block(BlockModel::BlockView{local, pixels + lo, nullptr, m}, row, consts[k], key_, poisson,
                              scratch, emit, pixel);
        } else {
            for (std::size_t j = 0; j < m; ++j) {
                pixel = pixels[lo + j];
                model_.advance(local[j], static_cast<double>(row[j]), consts[k], key_, pixel, poisson, scratch.noise, emit);
            }
        }
        ends[k] = static_cast<std::uint32_t>(out.size());
    }
}

}  // namespace evstwin

EVSTWIN_FP_STRICT_END
