// The block kernels' vector path (the performance page): BlockModel::step_block_soa over a
// block held as a structure of arrays (BlockSoA): the random words and normals in batches, the
// vectorised quiet pass (quiet_pass.hpp) that settles the quiet pixels at the block's common
// photon rate, the bridge's batched decisions for the pixels it left to the bridge alone
// (bridge_stage), and the per-pixel path for the few left busy. BlockModel declares these
// (with their contracts); block_model.hpp includes this file after it.
#pragma once

#include <cstddef>
#include <cstdint>

#include "../config.hpp"
#include "../physics.hpp"
#include "../rng.hpp"
#include "../simd.hpp"
#include "block_arrays.hpp"
#include "block_model.hpp"
#include "quiet_pass.hpp"
#include "../simd/block_passes.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

template <class Real, class Emit>
inline std::size_t BlockModel::step_block_soa(BlockSoA& h, PixelState* st, const std::uint32_t* ids, std::size_t n,
                                              const Real* rate, const SampleConstants& c, Philox4x32Key key,
                                              BlockScratch& scratch, Emit&& emit, std::uint32_t& pixel,
                                              const std::uint32_t* held, std::size_t n_held) const {
    if (p.pr_pole)
        return step_block_soa_impl<QuietChain::PoleSf>(h, st, ids, n, rate, c, key, scratch, emit, pixel, held, n_held);
    return step_block_soa_impl<QuietChain::SfOnly>(h, st, ids, n, rate, c, key, scratch, emit, pixel, held, n_held);
}

template <QuietChain Chain, class Real, class Emit>
EVSTWIN_ALWAYS_INLINE std::size_t BlockModel::step_block_soa_impl(BlockSoA& h, PixelState* st, const std::uint32_t* ids,
                                                                  std::size_t n, const Real* rate, const SampleConstants& c,
                                                                  Philox4x32Key key, BlockScratch& scratch, Emit&& emit,
                                                                  std::uint32_t& pixel, const std::uint32_t* held,
                                                                  std::size_t n_held) const {
    constexpr bool sf_only = Chain == QuietChain::SfOnly;
    scratch.resize(n);
    BlockSoA::Levels& now = h.now();
    BlockSoA::Levels& next = h.next();
    const std::uint32_t* w0 = nullptr;
    const std::uint32_t* w1 = nullptr;
    const auto count = [&h](std::size_t j) { return h.count(j); };
    const auto id = [ids](std::size_t j) { return ids[j]; };
    double* g1s = scratch.u_noise.data();
    double* g2s = scratch.count.data();
    const bool noisy = draws_normals();
    if (noisy) {
        // The words only for the normals (as step_block_continuous): a noiseless pixel has
        // no use for them, and the kept ones are tagged with their sample.
        soa_sample_words(h, ids, n, key, scratch, w0, w1);
        // The second normal only drives the two-pole system (continuous_levels).
        batch_sample_normals(n, count, id, key, scratch, w0, w1, g1s, g2s, !sf_only);
    } else {
        for (std::size_t j = 0; j < n; ++j) g1s[j] = g2s[j] = 0.0;
    }
    // The block's common rate: the cache's if a probe has it (no refill), else the most
    // common of three probes. Any choice gives the same events; a good one leaves the
    // per-pixel path to the pixels that need it.
    NoiseCache& common = scratch.noise;
    if (common.dt != c.dt) common.photon_rate = std::numeric_limits<double>::quiet_NaN();
    const double probe[3] = {static_cast<double>(rate[0]), static_cast<double>(rate[n / 2]),
                             static_cast<double>(rate[n - 1])};
    double pick = probe[1] == probe[2] ? probe[1] : probe[0];
    for (double r : probe)
        if (r == common.photon_rate) pick = r;
    noise_cache_for(common, pick, c);  // complete (bridge_var) even when another path filled it lazily
    const bool background = has_background(), noise = common.D > 0.0;
    QuietPass q;
    q.now = &now;
    q.next = &next;
    q.refr_until = h.refr_until.data(); q.next_hot_t = h.next_hot_t.data();
    q.theta_on = h.theta_on.data(); q.theta_off = h.theta_off.data();
    prepare_quiet_terms(h, n, common, background);
    q.leak_g = h.leak_g.data(); q.bg_on_rate = h.bg_on_rate.data(); q.bg_off_rate = h.bg_off_rate.data();
    q.g1 = g1s; q.g2 = g2s; q.busy = h.busy.data(); q.count = n;
    // The pass takes the two-pole noise wherever there is noise behind the pole, which holds
    // when the pole's rate is > 0; were it not (a current that underflows), no pixel is
    // taken as quiet and the per-pixel path does them all.
    q.rate = (!sf_only && noise && !(common.a > 0.0)) ? std::numeric_limits<double>::quiet_NaN() : common.photon_rate;
    q.cx = common.x; q.pole_decay = common.pole_decay; q.pole_ramp = common.pole_ramp;
    q.phi_zz = common.k.phi_zz; q.phi_yz = common.k.phi_yz; q.phi_yy = common.k.phi_yy;
    q.l_zz = common.k.l_zz; q.l_yz = common.k.l_yz; q.l_yy = common.k.l_yy;
    q.bridge_bound = common.bridge_bound;
    q.sf_decay = c.sf_decay; q.sf_ramp = c.sf_ramp; q.dt = c.dt; q.inv_dt = c.inv_dt; q.t0 = c.t0; q.t1 = c.t1;
    // continuous_finish() refines (rather than bridges) behind a pole faster than the sampling
    // (pole_refine_ah), and with the source follower alone over an interval longer than
    // SF_REFINE_BH / b.
    q.bridge_stage = common.k.bridge_var > 0.0 &&
                     (sf_only ? !(noise && sf_rate() * c.dt > SF_REFINE_BH)
                              : !(noise && common.a > 0.0 && common.a * c.dt > pole_refine_ah(common.a)));
    h.sf_only = sf_only;
    detail::quiet_pass<Chain>(q, rate, noise, background);
    std::uint64_t* busy = h.busy.data();
    for (std::size_t i = 0; i < n_held; ++i) busy[held[i]] = 0;  // dropped, whatever the pass found
    // The pixels the pass did not settle, listed once for the two stages below.
    std::uint32_t* flagged = scratch.busy_at.data();
    const std::size_t n_flagged = list_flagged(busy, n, flagged);
    if (q.bridge_stage) bridge_stage(h, ids, flagged, n_flagged, common, c, key, scratch);
    // The busy pixels at rates of their own: the numbers of each rate that the loop below
    // meets (one fill_noise_cache() each, as it did, but for a pixel at the rate of the
    // previous busy pixel at a rate of its own, which takes the same numbers; the first
    // such takes noise_other's, the rate the last sample ended on, only if their dt is
    // c.dt). Their fills' first two stages are made here, over all of them
    // (fill_noise_caches), the last (the lazy choice, NoiseCache::lazy_credit) in the loop,
    // in order, as one fill after another: the same numbers and choices.
    NoiseCache& other = scratch.noise_other;
    std::size_t n_fills = 0;
    {
        double last = other.photon_rate;
        bool last_holds = other.dt == c.dt;
        for (std::size_t f = 0; f < n_flagged; ++f) {
            const std::size_t j = flagged[f];
            const double r = static_cast<double>(rate[j]);
            if (!busy[j] || r == common.photon_rate || (last_holds && r == last)) continue;
            if (n_fills == scratch.fill_rates.size()) scratch.fill_rates.resize(2 * n_fills + 16);
            scratch.fill_rates[n_fills++] = r;
            last = r;
            last_holds = true;
        }
    }
    if (n_fills > 0) {
        if (scratch.fills.size() < n_fills) {
            scratch.fills.resize(scratch.fill_rates.size());
            scratch.fill_stages.resize(scratch.fill_rates.size());
        }
        if (other.sf.T != c.dt || other.sf.b != sf_rate()) other.sf = sf_terms(sf_rate(), c.dt);
        fill_noise_caches(scratch.fills.data(), scratch.fill_stages.data(), scratch.fill_rates.data(), n_fills, c,
                          other.sf);
    }
    NoiseCache* own = &other;  // the numbers of the last pixel at a rate of its own
    std::size_t n_filled = 0;
    // The busy pixels, from their state at c.t0 (now), as step_continuous() does; their new
    // state goes to next, beside the quiet ones'.
    std::size_t n_busy = 0;
    for (std::size_t f = 0; f < n_flagged; ++f) {
        const std::size_t j = flagged[f];
        if (!busy[j]) continue;  // settled by the bridge stage
        ++n_busy;
        PixelState& s = st[j];
        h.give(s, j, now);
        const double r = static_cast<double>(rate[j]);
        const bool own_rate = r != common.photon_rate;  // common is complete, for c.dt
        // Another rate's numbers without the bridge's until a pixel needs them (NoiseCache::bridge_ready).
        if (own_rate && (r != own->photon_rate || own->dt != c.dt)) {
            NoiseCache& next_own = scratch.fills[n_filled++];
            next_own.lazy_credit = own->lazy_credit;
            fill_noise_finish(next_own, c, true);
            own = &next_own;
        }
        NoiseCache& cache = own_rate ? *own : common;
        double zj, yj, nzj, nyj;
        continuous_levels<sf_only>(s, cache, c, g1s[j], g2s[j], zj, yj, nzj, nyj);
        const bool clock_ran_out = background && background_spend(s, cache.bg_factor, c);
        // A pixel at another rate was not tested by the pass: it may be quiet at its own (as
        // step_block_continuous() settles it), which saves continuous_finish()'s bridge.
        double d1;
        bool quiet = own_rate && quiet_in_interval(s, yj, cache, c, clock_ran_out, d1);
        if (own_rate && !quiet && !cache.bridge_ready) {
            complete_noise_cache(cache, c);
            quiet = quiet_in_interval(s, yj, cache, c, clock_ran_out, d1);
        }
        if (quiet) {
            settle_quiet(s, cache, zj, yj, nzj, nyj, d1);
        } else {
            pixel = ids[j];
            continuous_finish(s, cache.x, zj, yj, nzj, nyj, cache.current_a, cache.leak_hz, cache.k.bridge_var,
                              cache.D, c, key, pixel, emit, nullptr);
            if (s.next_hot_t <= c.t1) hot_events(s, c.t1, key, pixel, emit);
        }
        ++s.n;
        h.take(s, j, next);
    }
    if (own != &other) other = *own;  // for the next call, whose first pixels may share its rate
    h.flip();
    return n_busy;
}

inline void BlockModel::prepare_quiet_terms(BlockSoA& h, std::size_t n, const NoiseCache& common, bool background) const {
    if (!(h.terms_leak_hz == common.leak_hz)) {
        for (std::size_t j = 0; j < n; ++j)
            h.leak_g[j] = leak_slope(h.leak_spread[j], h.theta_on[j], h.theta_off[j], common.leak_hz);
        h.terms_leak_hz = common.leak_hz;
    }
    if (background && !(h.terms_bg_factor == common.bg_factor)) {
        for (std::size_t j = 0; j < n; ++j) {
            h.bg_on_rate[j] = h.bg_on_hz[j] * common.bg_factor;
            h.bg_off_rate[j] = h.bg_off_hz[j] * common.bg_factor;
        }
        h.terms_bg_factor = common.bg_factor;
    }
}

inline void BlockModel::bridge_stage(BlockSoA& h, const std::uint32_t* ids, const std::uint32_t* flagged, std::size_t n_flagged,
                                      const NoiseCache& common, const SampleConstants& c, Philox4x32Key key,
                                      BlockScratch& scratch) const {
    const BlockSoA::Levels& now = h.now();
    const BlockSoA::Levels& next = h.next();
    std::uint64_t* busy = h.busy.data();
    const double t_start = c.t0;
    const double sigma2 = 4.0 * common.k.bridge_var * c.inv_dt;
    const double span = c.t1 - t_start;
    const double mid = 0.25 * sigma2 * span;
    std::uint32_t *c0 = scratch.ctr0.data(), *c1 = scratch.ctr1.data(), *c2 = scratch.ctr2.data();
    std::uint32_t* at = scratch.need_at.data();
    double* q_fire = scratch.noise_d.data();       // the bracketed p (-1: take the exact p)
    double* e_on = scratch.x.data();               // bridge_crossing_probability's exponents
    double* e_off = scratch.y.data();
    // bridge_crossing_probability is 0 for both levels without a middle variance.
    const bool has_mid = mid > 0.0;
    // The candidates and their exponents, as bridge_crossing_probability forms them.
    std::size_t m = 0;
    for (std::size_t f = 0; f < n_flagged; ++f) {
        const std::size_t j = flagged[f];
        if (busy[j] != 1) continue;
        busy[j] = 0;
        if (!has_mid) continue;
        const double s_y = now.y[j], ref = now.ref[j], th_on = h.theta_on[j], th_off = h.theta_off[j];
        const double g =
            detail::comparator_slope(s_y, next.y[j], leak_slope(h.leak_spread[j], th_on, th_off, common.leak_hz), c.inv_dt);
        const double d_start = detail::comparator_end(s_y, ref, g, t_start - c.t0);
        const double d_end = detail::comparator_end(s_y, ref, g, c.dt);
        e_on[m] = (th_on - d_start) * (th_on - d_end) / (2.0 * mid);
        e_off[m] = (th_off + d_start) * (th_off + d_end) / (2.0 * mid);
        at[m] = static_cast<std::uint32_t>(j);
        ++m;
    }
    if (m == 0) return;
    // Their brackets in one vectorised pass: the exps' latency chains overlap.
    detail::bridge_bracket(e_on, e_off, m, q_fire);
    // Those whose p may exceed 2^-33 (a uniform can fall below it; wherever q (1 + 1e-6)
    // does), kept in place without branches, with their counters.
    std::size_t d = 0;
    for (std::size_t k = 0; k < m; ++k) {
        const std::size_t j = at[k];
        const double q = q_fire[k];
        const std::uint64_t sample = h.count(j);
        c0[d] = static_cast<std::uint32_t>(sample);
        c1[d] = static_cast<std::uint32_t>(sample >> 32);
        c2[d] = ids[j];
        at[d] = static_cast<std::uint32_t>(j);
        q_fire[d] = q;
        e_on[d] = e_on[k];
        e_off[d] = e_off[k];
        d += static_cast<std::size_t>((q < 0.0) | (q * (1.0 + 1e-6) > 0x1p-33));
    }
    if (d == 0) return;
    // CounterStream(key, pixel, sample, PURPOSE_BRIDGE)'s first word.
    std::uint32_t *r0 = scratch.r0.data(), *r1 = scratch.r1.data(), *r2 = scratch.r2.data(), *r3 = scratch.r3.data();
    philox4x32_batch(c0, c1, c2, PURPOSE_BRIDGE, key, pad_batch(scratch, d), r0, r1, r2, r3);
    for (std::size_t k = 0; k < d; ++k) {
        const bool fires = detail::bracket_fires(uniform_open(r0[k]), q_fire[k], e_on[k], e_off[k]);
        busy[at[k]] = 2u * static_cast<std::uint64_t>(fires);
    }
}

}  // namespace evstwin

EVSTWIN_FP_STRICT_END
