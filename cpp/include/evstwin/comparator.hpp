// The comparator (the paper's eq. 10-11 and 16; the pixel model page, "Stage by stage"): the
// level difference d = y - ref over one sample interval, its threshold crossings at
// interpolated times with the refractory period, the leak and the background's pulses
// (compare), the crossings of the noise's Brownian bridge that the line misses
// (compare_bridged), and each event's label (crossing_label). PixelModel declares these (with
// their contracts); pixel.hpp includes this file after it.
#pragma once

#include <cmath>
#include <cstdint>
#include <limits>

#include "config.hpp"
#include "noise.hpp"
#include "physics.hpp"
#include "pixel.hpp"
#include "rng.hpp"
#include "state.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

EVSTWIN_ALWAYS_INLINE std::uint8_t PixelModel::crossing_label(const PixelState& s, int pol, double d, double y_t,
                                                          double ny_t) const {
    const double dn = ny_t - s.noise_at_event;
    const double dl = s.level_at_event - (y_t - d);  // how far the reference has leaked
    const double ds = d - dn - dl;
    // The changes' signs turned to the crossing's direction (a negation is exact), and the
    // label picked by arithmetic on the comparisons: these are the event path's least
    // predictable branches.
    const double sign = pol == ON ? 1.0 : -1.0;
    const double sl = sign * dl, ss = sign * ds, sn = sign * dn;
    const unsigned leak = static_cast<unsigned>(sl >= ss) & static_cast<unsigned>(sl >= sn);
    const unsigned shot = static_cast<unsigned>(sn > ss);
    return static_cast<std::uint8_t>(leak * LABEL_LEAK + (1u - leak) * (shot * LABEL_SHOT_NOISE + (1u - shot) * LABEL_SIGNAL));
}

template <class Emit>
EVSTWIN_ALWAYS_INLINE void PixelModel::compare(PixelState& s, double y1, double ny1, const SampleConstants& c,
                                           double leak_g, NoisePulses& pulses, Emit& emit) const {
    const double th_on = s.theta_on, th_off = s.theta_off, refr = p.refractory_s;
    const double g = detail::comparator_slope(s.y, y1, leak_g, c.inv_dt);  // d(d)/dt
    double tb = c.t0;
    double db = s.y - s.ref;  // d(tb)
    // Fast path: no noise event, not refractory, and the line stays inside both thresholds.
    const double d1 = detail::comparator_end(s.y, s.ref, g, c.dt);
    // Evaluated without short-circuits: one well-predicted branch instead of several.
    const bool quiet = !pulses.due(c.t1) & (s.refr_until <= tb) & detail::inside_levels(db, d1, th_on, th_off);
    if (quiet) {
        s.ref = y1 - d1;
        return;
    }
    const double y0 = s.y, ny0 = s.ny;
    // An event at t with the difference d there, leaving the difference d_after: emit it
    // and remember where it left the pixel.
    // Inlined at each of its four calls (GCC's attribute; elsewhere a plain lambda): left to
    // the compiler, whether it was depended on the code around it, and an out-of-line copy
    // cost an event more.
    auto fire = [&](double t, int pol, double d, double d_after, int label) EVSTWIN_LAMBDA_ALWAYS_INLINE {
        const double f = (t - c.t0) * c.inv_dt;
        const double y_t = y0 + f * (y1 - y0), ny_t = ny0 + f * (ny1 - ny0);
        if (label < 0) label = crossing_label(s, pol, d, y_t, ny_t);
        emit(t, static_cast<Polarity>(pol), static_cast<std::uint8_t>(label));
        s.level_at_event = y_t - d_after;
        s.noise_at_event = ny_t;
    };
    for (;;) {
        if (s.refr_until > tb) {
            while (pulses.due(c.t1) && pulses.time() < s.refr_until) pulses.take();  // a dead pixel's
            if (s.refr_until >= c.t1) break;
            db += g * (s.refr_until - tb);
            tb = s.refr_until;
        }
        if (db >= th_on) {
            const double n = detail::floor_positive(db / th_on);
            const double d = db;
            db -= n * th_on;
            fire(tb, ON, d, db, -1);
            s.refr_until = tb + refr;
            continue;
        }
        if (db <= -th_off) {
            const double n = detail::floor_positive(-db / th_off);
            const double d = db;
            db += n * th_off;
            fire(tb, OFF, d, db, -1);
            s.refr_until = tb + refr;
            continue;
        }
        double tc = std::numeric_limits<double>::infinity();
        int pol = -1;
        if (g > 0.0) {
            tc = tb + (th_on - db) / g;
            pol = ON;
        } else if (g < 0.0) {
            tc = tb + (-th_off - db) / g;
            pol = OFF;
        }
        if (pulses.due(c.t1) && pulses.time() < tc) {
            // The noise pulse trips the comparator first; ref resets to the level there.
            db += g * (pulses.time() - tb);
            tb = pulses.time();
            fire(tb, pulses.polarity(), db, 0.0, LABEL_BACKGROUND);
            pulses.take();
            db = 0.0;
            s.refr_until = tb + refr;
            continue;
        }
        if (!(tc <= c.t1)) break;  // also stops on a NaN rather than looping
        if (!(tc > tb)) {
            // The next level lies closer than t can resolve (a huge slope with no
            // refractory period): the rest of this interval's levels fire as one event
            // now, merged as at a wake-up, instead of looping at one instant.
            const double d_end = db + g * (c.t1 - tb);
            const double d = db;
            db = pol == ON ? d_end - std::floor(d_end / th_on) * th_on : d_end + std::floor(-d_end / th_off) * th_off;
            fire(tb, pol, d, db - g * (c.t1 - tb), -1);
            tb = c.t1;
            s.refr_until = tb + refr;
            break;
        }
        fire(tc, pol, pol == ON ? th_on : -th_off, 0.0, -1);
        tb = tc;
        db = 0.0;
        s.refr_until = tb + refr;
    }
    s.ref = y1 - (db + g * (c.t1 - tb));
}

template <class Emit>
EVSTWIN_ALWAYS_INLINE void PixelModel::compare_bridged(PixelState& s, double y, double ny, const SampleConstants& c,
                                                   double leak_g, double bridge_var, NoisePulses& pulses,
                                                   Philox4x32Key key, std::uint32_t pixel, std::uint32_t purpose,
                                                   Emit& emit, const BridgePre* pre) const {
    // `pre` (bridge_decisions): its `known` is the tests below (a variance, an interval left
    // after the refractory period, the line inside both levels), made on the same state
    // and values, and `fires` the draw's decision; the branches test its bytes, which are
    // at hand long before the levels' arithmetic is done (a mispredicted branch costs less).
    const bool decided = pre != nullptr;
    if (decided ? (pre->known & pre->fires) : bridge_var > 0.0) {
        const double t_start = std::max(c.t0, s.refr_until);
        if (decided || t_start < c.t1) {
            const double g = detail::comparator_slope(s.y, y, leak_g, c.inv_dt);
            const double d_start = detail::comparator_end(s.y, s.ref, g, t_start - c.t0);
            const double d_end = detail::comparator_end(s.y, s.ref, g, c.dt);
            const double th_on = s.theta_on, th_off = s.theta_off;
            if (decided || detail::inside_levels(d_start, d_end, th_on, th_off)) {
                // The variance rate of the bridge that has this middle variance over dt.
                const double sigma2 = 4.0 * bridge_var * c.inv_dt;
                const double span = c.t1 - t_start;
                const double mid = 0.25 * sigma2 * span;
                // The crossing's probabilities p_on, p_off (bridge_crossing_probability) and
                // its uniform u: it fires where u < p_on + p_off, at the ON level where u <
                // p_on (detail::bridge_fires, which needs the exps only near a tie). u is
                // drawn whatever p is: a counter-based draw changes nothing else, and where
                // p_on + p_off <= 2^-33 no uniform (uniform_open) lies below it.
                // `pre`: the same words and decision, made ahead in a batch (bridge_decisions).
                bool on = decided && pre->on;
                bool fires = decided;
                double tc = 0.0;
                if (decided && pre->timed) {
                    tc = pre->tc;  // bridge_decisions drew it, from the same words
                } else if (!decided && detail::bridge_cannot_fire(th_on - d_start, th_on - d_end, th_off + d_start,
                                                                   th_off + d_end, mid)) {
                    fires = false;  // no uniform could fire it: none drawn
                } else {
                    PrefilledStream more(key, pixel, s.n, purpose, decided ? &pre->words : nullptr);
                    const double u = more.uniform();
                    if (!decided)
                        fires = detail::bridge_fires(u, th_on - d_start, th_on - d_end, th_off + d_start, th_off + d_end,
                                                     mid, on);
                    if (fires) {
                        const double u0 = on ? th_on - d_start : th_off + d_start;
                        const double u1 = on ? th_on - d_end : th_off + d_end;
                        const double g_time = normal_ziggurat(more.word(), [&more] { return more.word(); });
                        tc = t_start + bridge_first_passage_sample(u0, u1, sigma2, span, g_time, more.uniform());
                    }
                }
                if (fires) {
                    if (tc > c.t0 && tc < c.t1) {
                        // Split the interval at the crossing: a virtual sample there, just
                        // past the level, so the comparator fires at tc; then on to y.
                        const double f = (tc - c.t0) * c.inv_dt;
                        const double d_line = (s.y - s.ref) + g * (tc - c.t0);
                        const double level = on ? th_on * (1.0 + 1e-9) : -th_off * (1.0 + 1e-9);
                        const double excursion = level - d_line;
                        const double y_c = s.y + f * (y - s.y) + excursion;
                        const double ny_c = s.ny + f * (ny - s.ny) + excursion;
                        SampleConstants first = c, second = c;
                        first.t1 = second.t0 = tc;
                        first.dt = tc - c.t0;
                        second.dt = c.t1 - tc;
                        const bool timed = decided && pre->timed;
                        first.inv_dt = timed ? pre->inv_first_dt : 1.0 / first.dt;
                        second.inv_dt = timed ? pre->inv_second_dt : 1.0 / second.dt;
                        // The background's events up to tc go to the first part (compare takes
                        // those due by its end), the rest to the second.
                        compare(s, y_c, ny_c, first, leak_g, pulses, emit);
                        s.y = y_c;
                        s.ny = ny_c;
                        compare(s, y, ny, second, leak_g, pulses, emit);
                        return;
                    }
                }
            }
        }
    }
    compare(s, y, ny, c, leak_g, pulses, emit);
}

}  // namespace evstwin

EVSTWIN_FP_STRICT_END
