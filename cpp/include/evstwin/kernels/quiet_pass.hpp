// The continuous block kernel's common path (quiet_pass): one loop over a block's arrays
// without branches, compiled per SIMD level, that settles the pixels that stay quiet.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <new>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "../config.hpp"
#include "../physics.hpp"
#include "../simd.hpp"
#include "block_arrays.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

/// The configurations the quiet pass is compiled for: the exact source follower alone (the
/// default) or behind the photoreceptor pole (DAVIS346-like presets). Others (Euler, no
/// source follower) keep the array-of-structures kernel.
enum class QuietChain { SfOnly, PoleSf };

namespace detail {

/// The continuous block kernel's common path for every pixel of a block: continuous_levels(),
/// background_spend() and the quiet test of step_block_continuous(), one loop over the arrays
/// without branches or conditional stores, so it vectorises. Every pixel's new levels (but x
/// and nz with the source follower alone, which are z and 0: BlockSoA::sf_only) go to
/// q.next (a quiet pixel's are final: what continuous_finish() would leave); q.busy says 0 for
/// quiet, 1 where only the bridge's draw could fire (the bridge stage), 2 for the per-pixel
/// path, which starts over from q.now. The same operations in
/// the same order as the scalar code and no contraction (EVSTWIN_FP_STRICT): the same bits at
/// every instruction set. Noise: the rate's noise intensity is > 0; Background: eq. 12's
/// background is on (both compile-time, so no operation sits behind a branch).
template <QuietChain Chain, bool Noise, bool Background, class Real>
EVSTWIN_ALWAYS_INLINE void quiet_pass_body(const QuietPass& q, const Real* __restrict rate) {
    const double* __restrict sx = q.now->x.data();
    const double* __restrict sz = q.now->z.data();
    const double* __restrict sy = q.now->y.data();
    const double* __restrict snz = q.now->nz.data();
    const double* __restrict sny = q.now->ny.data();
    const double* __restrict sref = q.now->ref.data();
    const double* __restrict son = q.now->clock_on.data();
    const double* __restrict soff = q.now->clock_off.data();
    double* __restrict ox = q.next->x.data();
    double* __restrict oz = q.next->z.data();
    double* __restrict oy = q.next->y.data();
    double* __restrict onz = q.next->nz.data();
    double* __restrict ony = q.next->ny.data();
    double* __restrict oref = q.next->ref.data();
    double* __restrict oon = q.next->clock_on.data();
    double* __restrict ooff = q.next->clock_off.data();
    const double* __restrict refr = q.refr_until;
    const double* __restrict hot = q.next_hot_t;
    const double* __restrict th_on_a = q.theta_on;
    const double* __restrict th_off_a = q.theta_off;
    const double* __restrict leak_g = q.leak_g;
    const double* __restrict bon = q.bg_on_rate;
    const double* __restrict boff = q.bg_off_rate;
    const double* __restrict g1 = q.g1;
    const double* __restrict g2 = q.g2;
    std::uint64_t* __restrict busy = q.busy;
    constexpr bool pole = Chain == QuietChain::PoleSf;
    const double x = q.cx, common = q.rate;
    const double pole_decay = q.pole_decay, pole_ramp = q.pole_ramp, sf_decay = q.sf_decay, sf_ramp = q.sf_ramp;
    const double phi_zz = q.phi_zz, phi_yz = q.phi_yz, phi_yy = q.phi_yy, l_zz = q.l_zz, l_yz = q.l_yz, l_yy = q.l_yy;
    const double bridge_bound = q.bridge_bound, dt = q.dt, inv_dt = q.inv_dt;
    const double t0 = q.t0, t1 = q.t1;
    const bool bridge_stage = q.bridge_stage;
    const std::size_t count = q.count;
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC ivdep
#endif
    for (std::size_t j = 0; j < count; ++j) {
        const double s_z = sz[j], s_y = sy[j], s_ny = sny[j];
        // continuous_levels(): the pole (if any), the exact source follower, the noise.
        double z = x;
        if constexpr (pole) z = low_pass_exact(s_z, sx[j], x, pole_decay, pole_ramp);
        const double yd = low_pass_exact(s_y - s_ny, s_z, z, sf_decay, sf_ramp);
        double nz = 0.0, ny = 0.0;
        if constexpr (Noise) {
            // With the pole its rate is > 0 wherever there is noise: the two-pole system.
            // Without it z carries no noise (continuous_levels): nz stays 0, unwritten.
            if constexpr (pole) {
                nz = noise_z_next(phi_zz, l_zz, snz[j], g1[j]);
                ny = noise_y_next(phi_yz, phi_yy, l_yz, l_yy, snz[j], s_ny, g1[j], g2[j]);
            } else {
                ny = noise_y_next(phi_yy, l_yy, s_ny, g1[j]);
            }
        }
        const double y = yd + ny;
        // background_spend().
        double on = son[j], off = soff[j];
        bool ran_out = false;
        if constexpr (Background) {
            // background_spend()'s (bg_on_hz bg_factor) dt, the product in brackets made once.
            on = clock_spent(son[j], bon[j], dt);
            off = clock_spent(soff[j], boff[j], dt);
            ran_out = clock_ran_out(on, off);
        }
        // The quiet test (step_block_continuous()).
        const double th_on = th_on_a[j], th_off = th_off_a[j];
        const double g = comparator_slope(s_y, y, leak_g[j], inv_dt);
        const double db = s_y - sref[j];
        const double d1 = comparator_end(s_y, sref[j], g, dt);
        const bool plain = (static_cast<double>(rate[j]) == common) & !ran_out & (hot[j] > t1) & (refr[j] <= t0);
        const bool quiet = plain & bridge_quiet(db, d1, th_on, th_off, bridge_bound);
        // Not quiet, but the line stays between the levels (compare_bridged()'s test): only the
        // bridge's draw can make it fire.
        const bool bridge = bridge_stage & plain & inside_levels(db, d1, th_on, th_off);
        oref[j] = y - d1;
        if constexpr (pole) ox[j] = x;  // else z is x (BlockSoA::sf_only)
        oz[j] = z;
        oy[j] = y;
        if constexpr (pole) onz[j] = nz;
        ony[j] = ny;
        oon[j] = on;
        ooff[j] = off;
        // 0, 1 or 2 as arithmetic: a nested select here becomes a branch and stops the vectoriser.
        const std::uint64_t not_quiet = !quiet;
        busy[j] = 2u * not_quiet - (not_quiet & static_cast<std::uint64_t>(bridge));
    }
}

/// quiet_pass_body() as a kernel of at_simd_level (simd.hpp): one body at every level.
template <QuietChain Chain, bool Noise, bool Background>
struct QuietPassKernel {
    template <class Level, class Real>
    static EVSTWIN_ALWAYS_INLINE void run(Level, const QuietPass& q, const Real* rate) {
        quiet_pass_body<Chain, Noise, Background>(q, rate);
    }
};

/// quiet_pass_body() for the run-time noise and background switches.
template <QuietChain Chain, class Real>
inline void quiet_pass(const QuietPass& q, const Real* rate, bool noise, bool background) {
    if (noise) {
        if (background) return at_simd_level<QuietPassKernel<Chain, true, true>>(q, rate);
        return at_simd_level<QuietPassKernel<Chain, true, false>>(q, rate);
    }
    if (background) return at_simd_level<QuietPassKernel<Chain, false, true>>(q, rate);
    at_simd_level<QuietPassKernel<Chain, false, false>>(q, rate);
}

}  // namespace detail

}  // namespace evstwin

EVSTWIN_FP_STRICT_END
