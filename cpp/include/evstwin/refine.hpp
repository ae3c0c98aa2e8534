// An interval's refinement where a crossing is plausible (the noise model page, "Adaptive
// cuts"): the noise at cuts of the interval drawn exactly given both ends (a Levy bridge
// construction), the noise-free chain stepped through the cuts, and the comparator with each
// piece's bridge. The cuts are adaptive: a piece is halved only while a crossing in it stays
// plausible (the test continuous_finish applies to the whole interval, with the piece's own
// bridge and chances), down to the pieces the pole or the follower resolves. A long step of a
// quiet stretch then costs a few pieces where it would cost thousands cut evenly, with the
// same law: a piece left whole is one whose crossing the test finds implausible, exactly as
// an unrefined interval is. PixelModel declares these; pixel.hpp includes this file after it.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "config.hpp"
#include "noise.hpp"
#include "pixel.hpp"
#include "rng.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

namespace detail {
/// The span (l, r] of an interval c cut into m pieces of length h (piece indices 0..m): its
/// ends exactly the interval's at l = 0 and r = m.
inline SampleConstants refined_span(const SampleConstants& c, std::uint32_t l, std::uint32_t r, std::uint32_t m,
                                    double h) {
    SampleConstants piece = c;
    piece.t0 = l == 0 ? c.t0 : c.t0 + l * h;
    piece.t1 = r == m ? c.t1 : c.t0 + r * h;
    piece.dt = piece.t1 - piece.t0;
    piece.inv_dt = 1.0 / piece.dt;
    return piece;
}

/// What refine_and_compare needs of the pieces of one level (length T = dt / 2^level): their
/// bridge variance, the noise-free chain's decays over one, and the law of a piece's midpoint
/// given its ends (the halves' transition Phi and innovation Q: mean Phi X_0 + K (X_1 - Phi^2
/// X_0), covariance Q - K Phi Q with K = Q Phi^T (Phi Q Phi^T + Q)^-1, factor L).
struct RefineLevel {
    bool ready = false;
    double bridge_var = 0;
    double plausible_limit = 0;  // PixelModel::plausible_limit at the piece's bridge and chances
    double pole_decay = 1, pole_ramp = 1, sf_decay = 1, sf_ramp = 1;
    // the halves of a piece of this level (the next level's length)
    double Pzz = 0, Pyz = 0, Pyy = 0, Kzz = 0, Kzy = 0, Kyz = 0, Kyy = 0, lzz = 0, lyz = 0, lyy = 0;
    NoiseCoeffs half;  // noise_coeffs_interval over T / 2: the next level's pieces' own
};

/// RefineLevel of pieces of length T behind the pole a (0: the follower alone) and the follower b.
/// bridge_var: the piece's, where the caller has it (the whole interval's); else NaN, and
/// `piece_coeffs` (if not null) holds noise_coeffs_interval(a, b, D, T): the level above's `half`,
/// the same bits as computing it again. Each number is the expression it always was on the same
/// values; those that two of them share are evaluated once. A pixel whose light is its own (a
/// moving source's, a star's) makes its levels afresh at every refinement, its pole rate and
/// noise intensity being its own: leo-pass on the DAVIS346 made 3.75 a refinement.
inline RefineLevel refine_level(double a, double b, double D, double T, double bridge_var,
                                const NoiseCoeffs* piece_coeffs = nullptr) {
    RefineLevel v;
    v.ready = true;
    const bool two_poles = a > 0.0 && b > 0.0;
    // The level above's half is this level's piece: its decays are exp(-a T) (where the closed
    // form kept a: detail::separated_pole_rate) and exp(-b T) (two poles, or the follower alone).
    if (a > 0.0) {
        v.pole_decay = piece_coeffs && two_poles && detail::separated_pole_rate(a, b) == a ? piece_coeffs->phi_zz
                                                                                          : std::exp(-a * T);
        v.pole_ramp = one_minus_exp_over(a * T);
    }
    v.sf_decay = piece_coeffs && (two_poles || !(a > 0.0)) ? piece_coeffs->phi_yy : std::exp(-b * T);
    v.sf_ramp = one_minus_exp_over(b * T);
    // The half piece's coefficients; with two poles its transition and covariance are also
    // what noise_coeffs_bridge() would make again for this level's bridge_var.
    NoiseIntervalStage stage;
    Ou2Covariance half_q;
    noise_interval_begin(v.half, stage, a, b, D, 0.5 * T);
    noise_interval_end(v.half, stage, b, D, &half_q);
    if (std::isnan(bridge_var)) {
        if (two_poles) {
            bridge_var = 0.0;  // noise_coeffs_interval()'s, where the system is singular
            detail::bridge_var_from_halves(v.half.phi_zz, v.half.phi_yz, v.half.phi_yy, half_q.zz, half_q.zy,
                                           half_q.yy, bridge_var);
        } else {
            // One low-pass: noise_coeffs_interval() makes its bridge_var itself.
            bridge_var = piece_coeffs ? piece_coeffs->bridge_var : noise_coeffs_interval(a, b, D, T).bridge_var;
        }
    }
    v.bridge_var = bridge_var;
    const NoiseCoeffs& q = v.half;
    if (a > 0.0) {
        const double Qzz = q.l_zz * q.l_zz, Qzy = q.l_zz * q.l_yz, Qyy = q.l_yz * q.l_yz + q.l_yy * q.l_yy;
        const double Pzz = q.phi_zz, Pyz = q.phi_yz, Pyy = q.phi_yy;  // Phi = [[Pzz, 0], [Pyz, Pyy]]
        // A = Q Phi^T; M = Phi A + Q (symmetric); K = A M^-1; C = Q - K A^T (A^T = Phi Q).
        const double Azz = Qzz * Pzz, Azy = Qzz * Pyz + Qzy * Pyy;
        const double Ayz = Qzy * Pzz, Ayy = Qzy * Pyz + Qyy * Pyy;
        const double Mzz = Pzz * Azz + Qzz, Mzy = Pzz * Azy + Qzy, Myy = Pyz * Azy + Pyy * Ayy + Qyy;
        const double det = Mzz * Myy - Mzy * Mzy;
        v.Kzz = (Azz * Myy - Azy * Mzy) / det;
        v.Kzy = (Azy * Mzz - Azz * Mzy) / det;
        v.Kyz = (Ayz * Myy - Ayy * Mzy) / det;
        v.Kyy = (Ayy * Mzz - Ayz * Mzy) / det;
        const double Czz = Qzz - (v.Kzz * Azz + v.Kzy * Azy);
        const double Czy = Qzy - (v.Kzz * Ayz + v.Kzy * Ayy);
        const double Cyy = Qyy - (v.Kyz * Ayz + v.Kyy * Ayy);
        v.lzz = Czz > 0.0 ? std::sqrt(Czz) : 0.0;
        v.lyz = v.lzz > 0.0 ? Czy / v.lzz : 0.0;
        v.lyy = std::sqrt(std::max(0.0, Cyy - v.lyz * v.lyz));
        v.Pzz = Pzz;
        v.Pyz = Pyz;
        v.Pyy = Pyy;
    } else {
        // One OU process: the middle given the ends has mean phi y0 + phi / (1 + phi^2) (y1 -
        // phi^2 y0) and variance Q / (1 + phi^2).
        const double phi = q.phi_yy, Q = q.l_yy * q.l_yy, w = 1.0 + phi * phi;
        v.Pyy = phi;
        v.Kyy = phi / w;
        v.lyy = std::sqrt(Q / w);
    }
    return v;
}
}  // namespace detail

// A piece's bridge draws are keyed PURPOSE_BRIDGE + 16 x its end (up to 2^MAX_REFINE_LEVELS),
// each with a few blocks of its own: they must stay below the next purpose's range.
static_assert(static_cast<std::uint64_t>(PURPOSE_BRIDGE) + 16u * ((1ull << PixelModel::MAX_REFINE_LEVELS) + 1u) <
                  static_cast<std::uint64_t>(PURPOSE_INIT),
              "refine_and_compare's bridge keys would reach PURPOSE_INIT");

template <class Emit>
void PixelModel::refine_and_compare(PixelState& s, double x1, double z1, double yd1, double nz1, double ny1,
                                    const SampleConstants& c, double leak_g, double a, double b, double D,
                                    double bridge_var, double excursions, NoisePulses& pulses, Philox4x32Key key,
                                    std::uint32_t pixel, Emit& emit) const {
    const bool pole = a > 0.0;
    // The deepest level: pieces of a h <= pole_refine_ah(a) behind the pole, b h <=
    // SF_REFINE_BH with the follower alone.
    const double rate = pole ? a : b, piece_rh = pole ? pole_refine_ah(a) : SF_REFINE_BH;
    int deepest = 1;
    while (deepest < MAX_REFINE_LEVELS && rate * c.dt > piece_rh * static_cast<double>(1u << deepest)) ++deepest;
    const std::uint32_t m = 1u << deepest;
    const double h = c.dt / m, inv_m = 1.0 / m;  // m a power of two: x * inv_m is x / m exactly
    // The levels' constants depend on (a, b, D, dt) alone: the same for every pixel of a
    // uniform sky, so each thread keeps the last interval's (the same bits either way).
    struct LevelCache {
        double a = -1, b = -1, D = -1, dt = -1, bridge_var = -1, excursions = -1;
        detail::RefineLevel levels[MAX_REFINE_LEVELS + 1];
    };
    static thread_local LevelCache cache;
    if (!(cache.a == a && cache.b == b && cache.D == D && cache.dt == c.dt && cache.bridge_var == bridge_var &&
          cache.excursions == excursions)) {
        cache.a = a;
        cache.b = b;
        cache.D = D;
        cache.dt = c.dt;
        cache.bridge_var = bridge_var;
        cache.excursions = excursions;
        for (detail::RefineLevel& l : cache.levels) l.ready = false;
    }
    detail::RefineLevel* levels = cache.levels;
    const auto level = [&](int l) -> const detail::RefineLevel& {
        if (!levels[l].ready) {
            const double share = static_cast<double>(1u << l);
            // A level's pieces are halves of the level above's, which was made first (a piece
            // of level l comes from halving one of level l - 1): its `half` is their noise.
            levels[l] = detail::refine_level(a, b, D, l == 0 ? c.dt : c.dt / share,
                                             l == 0 ? bridge_var : std::numeric_limits<double>::quiet_NaN(),
                                             l > 0 && levels[l - 1].ready ? &levels[l - 1].half : nullptr);
            // A piece's chances to cross: its share of the interval's, at least one.
            levels[l].plausible_limit = plausible_limit(levels[l].bridge_var, std::max(1.0, excursions / share));
        }
        return levels[l];
    };
    // The pieces still to run, the last first: each its level, its end (in pieces of h) and
    // the noise there. The piece run next starts where the one before ended (at `at`), at
    // the state s holds, with the noise-free chain (x, z, yd) and the noise n_z there.
    struct Pending {
        int level;
        std::uint32_t end;
        double nz, ny;
    };
    Pending stack[MAX_REFINE_LEVELS + 2];
    int top = 0;
    stack[top++] = {0, m, nz1, ny1};
    std::uint32_t at = 0;
    int splits = 0;
    const double x0 = pole ? s.x : s.z;  // without the pole the follower's input is x itself (s.z at c.t0)
    double x_at = x0, z_at = pole ? s.z : x0, yd_at = s.y - s.ny, nz_at = s.nz;
    CounterStream normals(key, pixel, s.n, PURPOSE_REFINE);
    while (top > 0) {
        const Pending piece = stack[top - 1];
        const detail::RefineLevel& lv = level(piece.level);
        // The noise-free chain at the piece's end: exactly, for the input linear in it (the
        // interval's end forced to the sample's own values).
        double x_end, z_end, yd_end;
        if (piece.end == m) {
            x_end = x1;
            z_end = pole ? z1 : x1;
            yd_end = yd1;
        } else {
            x_end = x0 + (x1 - x0) * (static_cast<double>(piece.end) * inv_m);
            z_end = pole ? detail::low_pass_exact(z_at, x_at, x_end, lv.pole_decay, lv.pole_ramp) : x_end;
            yd_end = detail::low_pass_exact(yd_at, z_at, z_end, lv.sf_decay, lv.sf_ramp);
        }
        const double y_end = yd_end + piece.ny;
        const SampleConstants span = detail::refined_span(c, at, piece.end, m, h);
        // A piece is run whole at the deepest level, where no crossing is plausible, inside
        // the refractory period (nothing fires there: only the noise at its end counts, drawn
        // already; cutting such pieces cost the event-heavy load half its instructions), or
        // once the interval has been halved MAX_REFINE_SPLITS times (a line that crosses a
        // level in every piece: a leak firing every few seconds over a year-long sample). A
        // piece with a background event due in it is halved on to the deepest level: the
        // event resets the reference to the level there, which only a resolved piece's line
        // puts near the noise's path (continuous_finish).
        if (piece.level == deepest || splits == MAX_REFINE_SPLITS || s.refr_until >= span.t1 ||
            (piece.level > 0 && !pulses.due(span.t1) && !crossing_within(s, y_end, span, leak_g, lv.plausible_limit))) {
            // The comparator over the piece with its bridge (its draws keyed by the piece's
            // end); the background's events due by its end are its own (compare takes them).
            compare_bridged(s, y_end, piece.ny, span, leak_g, lv.bridge_var, pulses, key, pixel,
                            PURPOSE_BRIDGE + 16u * piece.end, emit);
            s.y = y_end;
            s.ny = piece.ny;
            x_at = x_end;
            z_at = z_end;
            yd_at = yd_end;
            nz_at = piece.nz;
            at = piece.end;
            --top;
            continue;
        }
        // Halve it: the noise at its middle given both ends (two normals behind the pole, one
        // with the follower alone; ziggurat draws, one word each but rarely).
        const auto more = [&normals] { return normals.word(); };
        const double g1 = normal_ziggurat(normals.word(), more);
        double mid_z = 0.0, mid_y;
        if (pole) {
            const double g2 = normal_ziggurat(normals.word(), more);
            const double mz = lv.Pzz * nz_at, my = lv.Pyz * nz_at + lv.Pyy * s.ny;  // Phi X_0
            const double ez = piece.nz - lv.Pzz * mz, ey = piece.ny - (lv.Pyz * mz + lv.Pyy * my);
            mid_z = mz + lv.Kzz * ez + lv.Kzy * ey + lv.lzz * g1;
            mid_y = my + lv.Kyz * ez + lv.Kyy * ey + lv.lyz * g1 + lv.lyy * g2;
        } else {
            const double phi = lv.Pyy;
            mid_y = phi * s.ny + lv.Kyy * (piece.ny - phi * (phi * s.ny)) + lv.lyy * g1;
        }
        ++splits;
        stack[top - 1].level = piece.level + 1;
        stack[top++] = {piece.level + 1, at + ((piece.end - at) >> 1), mid_z, mid_y};
    }
}

}  // namespace evstwin

EVSTWIN_FP_STRICT_END
