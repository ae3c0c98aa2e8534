// Sensor::run_sparse_into(): one step of a sparse scene with time steps per pixel. Included
// by sensor.hpp.
//
// The step's samples are cut into groups of group_base_samples base samples. In group g:
//   - the pixels some source's light touches (the lit list) take the group's fine samples,
//     after one long step at the static light to the group's start if they stood earlier;
//   - those whose levels still relax after a source left them (settle_until_), and those
//     whose long steps would cost more than the base samples (long_steps_cut_below), take
//     its base samples, after the same long step;
//   - the others wait.
// Then one run() of the static map at the step's end moves every pixel that stands earlier
// there in one long exact step (run() skips the pixels already there); or, where the step
// lets pixels wait (reach_all false), only the pixels it lists, whose light changes there.
// A pixel's base samples run ahead of the groups, in one call from where it stands to its
// settling or its next lit group, with the pixels that stop alike. Where most pixels take
// the base samples anyway, the step runs densely instead (each group's lit pixels, then
// run() of every pixel at its base times). Otherwise the pixels are cut into parts (blocks b
// with b % threads == part), one a thread, each part's calls made on its own thread. Which
// pixel takes which grid depends on the step alone, so the events do not depend on the
// threads or on how a simulation is cut into steps of the same groups. Every call it makes
// is an ordinary run_pixels / run call; the step's events are their events, merged by
// (t, pixel).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <limits>
#include <map>
#include <numeric>
#include <stdexcept>
#include <string>
#include <vector>

#include "../config.hpp"
#include "../sensor.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

inline std::size_t Sensor::run_sparse_into(const EventStorage& storage, const SparseStep& step) {
    check_usable();
    const std::size_t npix = state_.size(), n = step.n_samples;
    // --- checks: nothing moves before every one has passed ---
    if (!model_.continuous || model_.euler)
        throw std::invalid_argument("run_sparse needs noise_model='continuous' and lowpass='exact' (the long steps "
                                    "advance the noise exactly over any interval only then)");
    if (n == 0) throw std::invalid_argument("run_sparse needs at least one sample; got n_samples=0");
    if (!step.static_rate || !step.t_s) throw std::invalid_argument("run_sparse needs static_rate and t_s");
    if (step.base_every < 1 || n % step.base_every != 0)
        throw std::invalid_argument("base_every must be >= 1 and divide n_samples (the step ends on a base time); got "
                                    "base_every=" + std::to_string(step.base_every) + " and n_samples=" +
                                    std::to_string(n));
    if (step.group_base_samples < 1)
        throw std::invalid_argument("group_base_samples must be >= 1; got 0");
    if (step.n_light > 0 && (!step.light_sample || !step.light_pixel || !step.light_rate))
        throw std::invalid_argument("run_sparse: n_light=" + std::to_string(step.n_light) +
                                    " needs light_sample, light_pixel and light_rate");
    check_times(step.t_s, n);
    // Where the step starts: the last run() or run_sparse() step, whichever is later.
    const double t_begin = std::max(last_t_, sparse_end_);
    if (!(step.t_s[0] > t_begin))
        throw std::invalid_argument("t_s must continue after the previous step's end (" + detail::fmt(t_begin) +
                                    " s); got t_s[0]=" + detail::fmt(step.t_s[0]));
    if (!step.reach_all && step.n_reach > 0 && !step.reach_pixel)
        throw std::invalid_argument("run_sparse: n_reach=" + std::to_string(step.n_reach) + " needs reach_pixel");
    if (!step.reach_all)
        for (std::size_t i = 0; i < step.n_reach; ++i)
            if (step.reach_pixel[i] >= npix)
                throw std::invalid_argument("reach_pixel[" + std::to_string(i) + "]=" + std::to_string(step.reach_pixel[i]) +
                                            " is outside the " + std::to_string(npix) + "-pixel sensor");
    const std::size_t bad_static = first_bad_rate(step.static_rate, npix);
    if (bad_static < npix)
        throw_bad_rate("static_rate[" + std::to_string(bad_static / width_) + ", " + std::to_string(bad_static % width_) +
                           "]",
                       step.static_rate[bad_static]);
    for (std::size_t i = 0; i < step.n_light; ++i) {
        if (step.light_sample[i] >= n)
            throw std::invalid_argument("light_sample[" + std::to_string(i) + "]=" + std::to_string(step.light_sample[i]) +
                                        " is not a sample of the step (n_samples=" + std::to_string(n) + ")");
        if (step.light_pixel[i] >= npix)
            throw std::invalid_argument("light_pixel[" + std::to_string(i) + "]=" + std::to_string(step.light_pixel[i]) +
                                        " is outside the " + std::to_string(npix) + "-pixel sensor");
        const double v = step.light_rate[i];
        if (!(v >= 0.0 && v <= MAX_RATE))
            throw std::invalid_argument("light_rate must be finite, >= 0 and <= 1e20 photons/s; got light_rate[" +
                                        std::to_string(i) + "]=" + detail::fmt(v));
    }

    // --- the groups' lit pixels and their rates (static light plus the sources'), in the
    // entries' order within a group ---
    const std::size_t group = std::min(n, step.group_base_samples * step.base_every);
    const std::size_t n_groups = (n + group - 1) / group;
    std::vector<std::size_t> first(n_groups + 1, 0);
    for (std::size_t i = 0; i < step.n_light; ++i) ++first[step.light_sample[i] / group + 1];
    for (std::size_t g = 0; g < n_groups; ++g) first[g + 1] += first[g];
    std::vector<std::size_t> order(step.n_light);
    {
        std::vector<std::size_t> next(first.begin(), first.end() - 1);
        for (std::size_t i = 0; i < step.n_light; ++i) order[next[step.light_sample[i] / group]++] = i;
    }
    // A pixel the step will sample must stand before its first sample (run_pixels would
    // refuse it part-way, after other pixels had moved).
    const auto check_before_step = [&](std::uint32_t px) {
        if (!(state_[px].t < step.t_s[0]))
            throw std::invalid_argument("run_sparse: pixel (x, y) = (" + std::to_string(px % width_) + ", " +
                                        std::to_string(px / width_) + ") stands at " + detail::fmt(state_[px].t) +
                                        " s, not before the step's first sample t_s[0]=" + detail::fmt(step.t_s[0]));
    };
    std::vector<SparseRun> lit(n_groups);
    if (sparse_column_.size() != npix) sparse_column_.assign(npix, -1);
    std::int32_t* column = sparse_column_.data();  // -1 but while a group's lit pixels are listed
    for (std::size_t g = 0; g < n_groups; ++g) {
        SparseRun& r = lit[g];
        const std::size_t k0 = g * group, k1 = std::min(n, k0 + group);
        for (std::size_t e = first[g]; e < first[g + 1]; ++e) {
            const std::uint32_t px = step.light_pixel[order[e]];
            if (column[px] < 0) {
                column[px] = 0;
                r.pixels.push_back(px);
            }
        }
        std::sort(r.pixels.begin(), r.pixels.end());
        const std::size_t m = r.pixels.size();
        for (std::size_t j = 0; j < m; ++j) column[r.pixels[j]] = static_cast<std::int32_t>(j);
        r.times.assign(step.t_s + k0, step.t_s + k1);
        r.rate.resize((k1 - k0) * m);
        for (std::size_t k = 0; k < k1 - k0; ++k)
            for (std::size_t j = 0; j < m; ++j) r.rate[k * m + j] = step.static_rate[r.pixels[j]];
        for (std::size_t e = first[g]; e < first[g + 1]; ++e) {
            const std::size_t i = order[e];
            double& v = r.rate[(step.light_sample[i] - k0) * m + static_cast<std::size_t>(column[step.light_pixel[i]])];
            v = v + step.light_rate[i];
        }
        for (const std::uint32_t px : r.pixels) column[px] = -1;
        const std::size_t bad = first_bad_rate(r.rate.data(), r.rate.size());
        if (bad < r.rate.size()) {
            const std::uint32_t px = r.pixels[bad % m];
            throw_bad_rate("static_rate plus the sources' light at sample " + std::to_string(k0 + bad / m) +
                               ", pixel (x, y) = (" + std::to_string(px % width_) + ", " + std::to_string(px / width_) +
                               ")",
                           r.rate[bad]);
        }
        for (const std::uint32_t px : r.pixels) check_before_step(px);
    }
    for (const std::uint32_t px : settling_) check_before_step(px);

    // --- the pixels that take the base samples throughout: those whose long steps
    // refine_and_compare would cut into pieces shorter than SPARSE_PIECE_COST base intervals
    // (their noise stays within reach of a threshold that long). For them long steps cost
    // more than they save. Speed only: either way the pixel's statistics are the same. ---
    double base_dt = std::numeric_limits<double>::infinity();
    {
        double prev = t_begin;
        for (std::size_t k = step.base_every - 1; k < n; k += step.base_every) {
            base_dt = std::min(base_dt, step.t_s[k] - prev);
            prev = step.t_s[k];
        }
    }
    std::vector<std::uint32_t> busy;
    if (std::isfinite(base_dt)) {
        // Judged again only where the light or the base interval changed since the last step
        // (a drifting star field changes a few percent of the pixels a step).
        const double piece_s = SPARSE_PIECE_COST * base_dt;
        const double theta = std::min(model_.p.theta_on, model_.p.theta_off);
        const bool all = sparse_busy_.size() != npix || base_dt != sparse_busy_dt_;
        if (all) {
            sparse_busy_.assign(npix, 0);
            sparse_static_.assign(npix, std::numeric_limits<double>::quiet_NaN());
            sparse_busy_dt_ = base_dt;
        }
        double last_rate = std::numeric_limits<double>::quiet_NaN();  // a uniform sky: judged once
        bool last_busy = false;
        for (std::size_t i = 0; i < npix; ++i) {
            const double rate = step.static_rate[i];
            if (rate != sparse_static_[i]) {
                sparse_static_[i] = rate;
                if (rate != last_rate) {
                    last_rate = rate;
                    last_busy = model_.long_steps_cut_below(rate, theta, piece_s);
                }
                sparse_busy_[i] = last_busy;
            }
            if (sparse_busy_[i]) busy.push_back(static_cast<std::uint32_t>(i));
        }
    }

    // --- the runs, group by group, then the long step of everyone else to the step's end ---
    // Where most pixels take the base samples anyway, the step runs densely: each group's lit
    // pixels through run_pixels, then every pixel through run() at the group's base times (it
    // skips the lit ones, ahead already), as the dense path does (geo-stare's sky on the
    // IMX636: through run_pixels those pixels cost 10-20 % more, and a copy of their states).
    const bool dense = SPARSE_DENSE_SHARE * static_cast<double>(npix) < static_cast<double>(busy.size());
    const bool judged_busy = std::isfinite(base_dt);  // sparse_busy_ holds this step's judgement
    if (sparse_mark_.size() != npix) sparse_mark_.assign(npix, 0);
    std::uint8_t* in_group = sparse_mark_.data();  // 1: listed once; 0 between uses
    // Each group's start: the step's start, then the previous group's last sample (a base time).
    std::vector<double> starts(n_groups);
    for (std::size_t g = 0; g < n_groups; ++g) starts[g] = g == 0 ? t_begin : step.t_s[g * group - 1];
    // A pixel's base samples run ahead of the groups: from group `from` (where it stands, or
    // stood still before) to the group where it is lit next (`next`, n_groups: none), or
    // sooner, to the first group that starts once its levels have settled (busy pixels take
    // every group); returns the end (exclusive). Those groups' base samples are then one
    // run_pixels call for the pixels that stop alike, not one call a group, which took every
    // settling pixel through the kernel's set-up once for each group's few base samples
    // (mcreynolds: ~8,500 pixels settle for 0.28 s after a light source passed, and its
    // groups are 4-44 ms). The same samples for each pixel as group by group, so the same events.
    const auto base_stop = [&](std::uint32_t px, std::size_t from, std::size_t next) {
        std::size_t stop = next;
        if (!(judged_busy && sparse_busy_[px]))
            stop = std::min<std::size_t>(stop, static_cast<std::size_t>(std::lower_bound(starts.begin(), starts.end(),
                                                                                          settle_until_[px]) -
                                                                         starts.begin()));
        return std::max(stop, from);
    };
    // The group each lit pixel is lit in next (n_groups: not again in this step), found from
    // the last group back; sparse_column_ holds each pixel's next group meanwhile (-1: none),
    // its first in the step at the end.
    std::vector<std::vector<std::uint32_t>> next_lit(n_groups);
    for (std::size_t g = n_groups; g-- > 0;) {
        const std::vector<std::uint32_t>& pixels = lit[g].pixels;
        next_lit[g].resize(pixels.size());
        for (std::size_t j = 0; j < pixels.size(); ++j) {
            const std::uint32_t px = pixels[j];
            next_lit[g][j] = column[px] < 0 ? static_cast<std::uint32_t>(n_groups) : static_cast<std::uint32_t>(column[px]);
            column[px] = static_cast<std::int32_t>(g);
        }
    }
    // The pixels still settling from an earlier step, and those that take the base samples
    // throughout, each once: ahead from the step's start to their end (not dense).
    std::vector<std::pair<std::uint32_t, std::uint32_t>> ahead_at_start;  // (pixel, end)
    if (!dense) {
        for (const std::vector<std::uint32_t>* list : {&settling_, &busy})
            for (const std::uint32_t px : *list) {
                if (in_group[px]) continue;
                in_group[px] = 1;
                const std::size_t next = column[px] < 0 ? n_groups : static_cast<std::size_t>(column[px]);
                const std::size_t stop = base_stop(px, 0, next);
                if (stop > 0) ahead_at_start.emplace_back(px, static_cast<std::uint32_t>(stop));
            }
        for (const std::vector<std::uint32_t>* list : {&settling_, &busy})
            for (const std::uint32_t px : *list) in_group[px] = 0;
    }
    for (const SparseRun& r : lit)
        for (const std::uint32_t px : r.pixels) column[px] = -1;

    // One part of the pixels through the whole step: those of blocks b (of BLOCK pixels, run()'s:
    // its per-block flags then belong to one part) with b % n_parts == part, their calls made
    // one after another on `calls`. Without `dense`, the parts share no pixel and run at once,
    // one a thread, each call alone on its thread: one parallel region a step rather than a
    // few calls a group each with its own (a lit group is ~1,000 pixels over a few samples, too
    // little for a region of its own: mcreynolds ran on one thread). Each pixel takes the same
    // calls whatever the parts, so the events do not depend on them. With `dense` (one part)
    // the groups' run() calls are the sensor's, in parallel themselves.
    struct Part {
        std::vector<Event> events;
        std::vector<std::uint8_t> labels;
        std::uint64_t updates = 0;
        std::size_t at_end = 0;  // pixels the groups took to the step's end (its last sample is a base time)
    };
    // A call's events and labels onto a part's.
    const auto take_into = [](Part& out, const CallBuffers& calls, const std::vector<Event>& events) {
        out.events.insert(out.events.end(), events.begin(), events.end());
        out.labels.insert(out.labels.end(), calls.labels.begin(), calls.labels.end());
    };
    const auto run_listed = [&](CallBuffers& calls, Part& out, const std::vector<std::uint32_t>& pixels,
                                const double* rate, const double* t, std::size_t n_t, bool static_rates) {
        std::vector<Event> events;
        run_pixels_with(calls, detail::vector_storage(events), pixels.data(), pixels.size(), rate, t, n_t, static_rates);
        take_into(out, calls, events);
        out.updates += pixels.size() * n_t;
    };
    // The static light of some pixels: one row, the same at each of their samples.
    const auto static_rates = [&](const std::vector<std::uint32_t>& pixels) {
        std::vector<double> rates(pixels.size());
        for (std::size_t j = 0; j < pixels.size(); ++j) rates[j] = step.static_rate[pixels[j]];
        return rates;
    };
    // One long step of some pixels (increasing indices, each behind t) at the static light to
    // t, in one run_pixels call per time they stand at, so that each call's blocks start
    // together and take the block kernels.
    const auto long_step = [&](CallBuffers& calls, Part& out, const std::vector<std::uint32_t>& pixels, double t) {
        std::map<double, std::vector<std::uint32_t>> by_start;
        std::vector<std::uint32_t>* last = nullptr;
        double last_t = 0.0;
        for (const std::uint32_t px : pixels) {
            const double t0 = state_[px].t;
            if (!last || t0 != last_t) {
                last = &by_start[t0];
                last_t = t0;
            }
            last->push_back(px);
        }
        for (const auto& at : by_start) run_listed(calls, out, at.second, static_rates(at.second).data(), &t, 1, true);
    };
    const auto run_part = [&](CallBuffers& calls, std::size_t part, std::size_t n_parts, Part& out) {
        const auto mine = [&](std::uint32_t px) { return n_parts == 1 || (px / BLOCK) % n_parts == part; };
        // The base samples of groups [g0, g1).
        const auto base_times = [&](std::size_t g0, std::size_t g1) {
            std::vector<double> base;
            for (std::size_t k = g0 * group; k < std::min(n, g1 * group); ++k)
                if ((k + 1) % step.base_every == 0) base.push_back(step.t_s[k]);
            return base;
        };
        std::map<std::size_t, std::vector<std::uint32_t>> ahead;  // end (exclusive) -> pixels
        // The pixels of `ahead` from group `from` on; those that stood still so far (in the
        // step, or waiting from an earlier one) first take one long step to its start.
        const auto run_ahead = [&](std::size_t from) {
            for (auto& [stop, pixels] : ahead) {
                std::sort(pixels.begin(), pixels.end());
                std::vector<std::uint32_t> entering;
                for (const std::uint32_t px : pixels)
                    if (state_[px].t < starts[from]) entering.push_back(px);
                long_step(calls, out, entering, starts[from]);
                const std::vector<double> base = base_times(from, stop);
                run_listed(calls, out, pixels, static_rates(pixels).data(), base.data(), base.size(), true);
                if (stop == n_groups) out.at_end += pixels.size();
            }
            ahead.clear();
        };
        for (const auto& [px, stop] : ahead_at_start)
            if (mine(px)) ahead[stop].push_back(px);
        run_ahead(0);
        SparseRun own;  // this part's lit pixels of a group, where there are other parts
        std::vector<std::uint32_t> own_next;
        for (std::size_t g = 0; g < n_groups; ++g) {
            const std::size_t k0 = g * group, k1 = std::min(n, k0 + group);
            const double t_start = starts[g], t_end = step.t_s[k1 - 1];
            const SparseRun* r = &lit[g];
            const std::vector<std::uint32_t>* next = &next_lit[g];
            if (n_parts > 1) {
                const std::size_t m = r->pixels.size(), nk = r->times.size();
                own.pixels.clear();
                own_next.clear();
                std::vector<std::size_t> cols;
                for (std::size_t j = 0; j < m; ++j)
                    if (mine(r->pixels[j])) {
                        cols.push_back(j);
                        own.pixels.push_back(r->pixels[j]);
                        own_next.push_back((*next)[j]);
                    }
                own.rate.resize(nk * cols.size());
                for (std::size_t k = 0; k < nk; ++k)
                    for (std::size_t c = 0; c < cols.size(); ++c) own.rate[k * cols.size() + c] = r->rate[k * m + cols[c]];
                own.times = r->times;
                r = &own;
                next = &own_next;
            }
            {
                // Those that stood still so far: one long step at the static light to the
                // group's start.
                std::vector<std::uint32_t> entering;
                for (const std::uint32_t px : r->pixels)
                    if (state_[px].t < t_start) entering.push_back(px);
                long_step(calls, out, entering, t_start);
            }
            if (!r->pixels.empty())
                run_listed(calls, out, r->pixels, r->rate.data(), r->times.data(), r->times.size(), false);
            if (dense) {
                const std::vector<double> base = base_times(g, g + 1);
                take_into(out, calls, run(step.static_rate, base.data(), base.size(), nullptr, nullptr, true));
                out.updates += (npix - r->pixels.size()) * base.size();
            }
            // A lit pixel relaxes from the group's end on: ahead through the groups until it
            // has settled or is lit again.
            for (std::size_t j = 0; j < r->pixels.size(); ++j) {
                const std::uint32_t px = r->pixels[j];
                settle_until_[px] = t_end + settle_time_s(step.static_rate[px]);
                if (dense) continue;
                const std::size_t stop = base_stop(px, g + 1, (*next)[j]);
                if (stop > g + 1) ahead[stop].push_back(px);
            }
            run_ahead(g + 1);
            if (g + 1 == n_groups) out.at_end += r->pixels.size();
        }
    };

    std::vector<Event> events;
    std::vector<std::uint8_t> labels;
    std::uint64_t updates = 0;
    std::size_t at_end = 0;
    try {
        std::size_t n_parts = 1;
#if EVSTWIN_HAS_OPENMP
        if (!dense && num_threads_ > 1) n_parts = static_cast<std::size_t>(num_threads_);
#endif
        std::vector<Part> parts(n_parts);
        if (n_parts == 1) {
            run_part(calls_, 0, 1, parts[0]);
        } else {
            while (sparse_calls_.size() < n_parts) sparse_calls_.push_back(std::make_unique<CallBuffers>());
            std::vector<std::exception_ptr> errors(n_parts);
#if EVSTWIN_HAS_OPENMP
#pragma omp parallel for num_threads(num_threads_) schedule(static, 1)
#endif
            for (std::int64_t i = 0; i < static_cast<std::int64_t>(n_parts); ++i) {
                const std::size_t part = static_cast<std::size_t>(i);
                try {
                    run_part(*sparse_calls_[part], part, n_parts, parts[part]);
                } catch (...) {
                    errors[part] = std::current_exception();
                }
            }
            // The first part's error: which one does not depend on timing unless two parts
            // fail (max_events, counted per call).
            for (const std::exception_ptr& e : errors)
                if (e) std::rethrow_exception(e);
        }
        for (const Part& part : parts) at_end += part.at_end;
        // The pixels still settling after the step, for the next: the earlier ones and this
        // step's lit ones, each once.
        const double t_last = step.t_s[n - 1];
        {
            std::vector<std::uint32_t> still;
            const auto keep = [&](std::uint32_t px) {
                if (in_group[px] || !(settle_until_[px] > t_last)) return;
                in_group[px] = 1;
                still.push_back(px);
            };
            for (const std::uint32_t px : settling_) keep(px);
            for (const SparseRun& r : lit)
                for (const std::uint32_t px : r.pixels) keep(px);
            for (const std::uint32_t px : still) in_group[px] = 0;
            settling_.swap(still);
        }
        // The last group's pixels stand at the step's end already (its last sample is a base
        // time). The rest reach it on the sensor's own buffers, their events after the parts'.
        Part& rest = parts.emplace_back();
        if (dense) {
            // Every pixel stands at t_last: the last group's run() took them there.
        } else if (step.reach_all) {
            // run() skips the pixels already there; a block whose pixels stand apart takes the
            // kernel for those that start together (run_block).
            take_into(rest, calls_, run(step.static_rate, &t_last, 1, nullptr, nullptr, true));
            rest.updates += npix - at_end;
        } else {
            std::vector<std::uint32_t> reach;
            for (std::size_t i = 0; i < step.n_reach; ++i) {
                const std::uint32_t px = step.reach_pixel[i];
                if (in_group[px] == 0 && state_[px].t < t_last) {
                    in_group[px] = 1;  // once, if listed twice
                    reach.push_back(px);
                }
            }
            for (const std::uint32_t px : reach) in_group[px] = 0;
            std::sort(reach.begin(), reach.end());
            long_step(calls_, rest, reach, t_last);
        }
        for (const Part& part : parts) {
            events.insert(events.end(), part.events.begin(), part.events.end());
            labels.insert(labels.end(), part.labels.begin(), part.labels.end());
            updates += part.updates;
        }
        sparse_end_ = t_last;
    } catch (...) {
        stopped_ = true;  // earlier groups' pixels have moved
        throw;
    }

    // --- the step's events by (t, pixel); a pixel's ties in the order its calls made them ---
    std::vector<std::uint32_t> idx(events.size());
    std::iota(idx.begin(), idx.end(), 0u);
    std::stable_sort(idx.begin(), idx.end(), [&](std::uint32_t a, std::uint32_t b) {
        const Event &ea = events[a], &eb = events[b];
        if (ea.t != eb.t) return ea.t < eb.t;
        return static_cast<std::uint32_t>(ea.y) * static_cast<std::uint32_t>(width_) + ea.x <
               static_cast<std::uint32_t>(eb.y) * static_cast<std::uint32_t>(width_) + eb.x;
    });
    std::vector<std::uint8_t>& out_labels = calls_.labels;
    out_labels.resize(idx.size());
    last_pixel_updates_ = updates;
    if (idx.empty()) return 0;
    Event* out = storage(idx.size());
    for (std::size_t i = 0; i < idx.size(); ++i) {
        out[i] = events[idx[i]];
        out_labels[i] = labels[idx[i]];
    }
    return idx.size();
}

}  // namespace evstwin

EVSTWIN_FP_STRICT_END
