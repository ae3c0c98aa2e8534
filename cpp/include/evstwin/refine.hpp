// An interval's refinement where a crossing is plausible (the noise model page, "Long
// intervals"): the noise at cuts of the interval drawn exactly given both ends (a Levy bridge
// construction), the noise-free chain stepped through the cuts, and the comparator with each
// piece's bridge. PixelModel declares these; pixel.hpp includes this file after it.
#pragma once

#include <cmath>
#include <cstdint>

#include "config.hpp"
#include "noise.hpp"
#include "pixel.hpp"
#include "rng.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

namespace detail {
/// Piece i (1..m) of an interval c cut into m pieces of length h: its ends exactly the
/// interval's at i = 1 and i = m.
inline SampleConstants refined_piece(const SampleConstants& c, int i, int m, double h) {
    SampleConstants piece = c;
    piece.t0 = i == 1 ? c.t0 : c.t0 + (i - 1) * h;
    piece.t1 = i == m ? c.t1 : c.t0 + i * h;
    piece.dt = piece.t1 - piece.t0;
    piece.inv_dt = 1.0 / piece.dt;
    return piece;
}

/// Piece i (1..m, length h) of a refined interval c: the comparator with the pieces' bridge
/// (variance piece_bridge, its draws keyed by the piece) toward the noise-free level yd plus
/// the noise ny, then that level as the pixel's. The background's events due by the piece's
/// end are its own (compare takes them).
template <class Emit>
EVSTWIN_ALWAYS_INLINE void compare_refined_piece(const PixelModel& model, PixelState& s, double yd, double ny,
                                                 const SampleConstants& c, int i, int m, double h, double leak_g,
                                                 double piece_bridge, NoisePulses& pulses, Philox4x32Key key,
                                                 std::uint32_t pixel, Emit& emit) {
    const SampleConstants piece = refined_piece(c, i, m, h);
    model.compare_bridged(s, yd + ny, ny, piece, leak_g, piece_bridge, pulses, key, pixel,
                          PURPOSE_BRIDGE + 16u * static_cast<std::uint32_t>(i), emit);
    s.y = yd + ny;
    s.ny = ny;
}
}  // namespace detail

template <class Emit>
void PixelModel::refine_and_compare(PixelState& s, double x1, double z1, double yd1, double nz1, double ny1,
                                    const SampleConstants& c, double leak_g, double a, double D, NoisePulses& pulses,
                                    Philox4x32Key key, std::uint32_t pixel, Emit& emit) const {
    constexpr int MAX_LEVELS = 10;
    int levels = 1;
    while (levels < MAX_LEVELS && a * c.dt > pole_refine_ah(a) * static_cast<double>(1 << levels)) ++levels;
    const int m = 1 << levels;
    const double h = c.dt / m;
    const double b = sf_rate();
    double nzs[(1 << MAX_LEVELS) + 1], nys[(1 << MAX_LEVELS) + 1];
    nzs[0] = s.nz;
    nys[0] = s.ny;
    nzs[m] = nz1;
    nys[m] = ny1;
    CounterStream normals(key, pixel, s.n, PURPOSE_REFINE);
    double piece_bridge = 0.0;  // the pieces' bridge variance: noise_coeffs_bridge's at (a, b, D, h), from step 1
    for (int step = m / 2; step >= 1; step /= 2) {
        // X_mid | X_0, X_1 for two halves of length T = step h: mean Phi X_0 + K (X_1 -
        // Phi^2 X_0), covariance Q - K Phi Q, with K = Q Phi^T (Phi Q Phi^T + Q)^-1.
        const double T = step * h;
        // Only the last level (T = h, the pieces' length) needs the bridge's variance.
        NoiseCoeffs q = noise_coeffs_interval(a, b, D, T);
        if (step == 1) {
            noise_coeffs_bridge(q, a, b, D, T);
            piece_bridge = q.bridge_var;
        }
        const double Qzz = q.l_zz * q.l_zz, Qzy = q.l_zz * q.l_yz, Qyy = q.l_yz * q.l_yz + q.l_yy * q.l_yy;
        const double Pzz = q.phi_zz, Pyz = q.phi_yz, Pyy = q.phi_yy;  // Phi = [[Pzz, 0], [Pyz, Pyy]]
        // A = Q Phi^T
        const double Azz = Qzz * Pzz, Azy = Qzz * Pyz + Qzy * Pyy;
        const double Ayz = Qzy * Pzz, Ayy = Qzy * Pyz + Qyy * Pyy;
        // M = Phi A + Q (symmetric)
        const double Mzz = Pzz * Azz + Qzz, Mzy = Pzz * Azy + Qzy, Myy = Pyz * Azy + Pyy * Ayy + Qyy;
        const double det = Mzz * Myy - Mzy * Mzy;
        // K = A M^-1
        const double Kzz = (Azz * Myy - Azy * Mzy) / det, Kzy = (Azy * Mzz - Azz * Mzy) / det;
        const double Kyz = (Ayz * Myy - Ayy * Mzy) / det, Kyy = (Ayy * Mzz - Ayz * Mzy) / det;
        // C = Q - K A^T (A^T = Phi Q), and its Cholesky factor.
        const double Czz = Qzz - (Kzz * Azz + Kzy * Azy);
        const double Czy = Qzy - (Kzz * Ayz + Kzy * Ayy);
        const double Cyy = Qyy - (Kyz * Ayz + Kyy * Ayy);
        const double lzz = Czz > 0.0 ? std::sqrt(Czz) : 0.0;
        const double lyz = lzz > 0.0 ? Czy / lzz : 0.0;
        const double lyy = std::sqrt(std::max(0.0, Cyy - lyz * lyz));
        for (int i = step; i < m; i += 2 * step) {
            const double z0 = nzs[i - step], y0 = nys[i - step];
            const double mz = Pzz * z0, my = Pyz * z0 + Pyy * y0;  // Phi X_0
            const double ez = nzs[i + step] - Pzz * mz, ey = nys[i + step] - (Pyz * mz + Pyy * my);
            const double g1 = normal_from_uniforms(normals.uniform(), normals.uniform());
            const double g2 = normal_from_uniforms(normals.uniform(), normals.uniform());
            nzs[i] = mz + Kzz * ez + Kzy * ey + lzz * g1;
            nys[i] = my + Kyz * ez + Kyy * ey + lyz * g1 + lyy * g2;
        }
    }
    // The pieces: the noise-free chain stepped exactly for the input linear in each piece
    // (its end forced to the sample's own value), the comparator with the piece's bridge.
    const double pole_decay = std::exp(-a * h), pole_ramp = one_minus_exp_over(a * h);
    const double sf_decay = std::exp(-b * h), sf_ramp = one_minus_exp_over(b * h);
    double x_prev = s.x, z_prev = s.z, yd_prev = s.y - s.ny;
    for (int i = 1; i <= m; ++i) {
        double xi, zi, ydi;
        if (i == m) {
            xi = x1;
            zi = z1;
            ydi = yd1;
        } else {
            xi = s.x + (x1 - s.x) * (static_cast<double>(i) / m);
            zi = detail::low_pass_exact(z_prev, x_prev, xi, pole_decay, pole_ramp);
            ydi = detail::low_pass_exact(yd_prev, z_prev, zi, sf_decay, sf_ramp);
        }
        detail::compare_refined_piece(*this, s, ydi, nys[i], c, i, m, h, leak_g, piece_bridge, pulses, key, pixel, emit);
        x_prev = xi;
        z_prev = zi;
        yd_prev = ydi;
    }
}

template <class Emit>
void PixelModel::refine_sf_and_compare(PixelState& s, double x1, double yd1, double ny1, const SampleConstants& c, double leak_g,
                                       double b, double D, NoisePulses& pulses, Philox4x32Key key, std::uint32_t pixel,
                                       Emit& emit) const {
    constexpr int MAX_LEVELS = 10;
    int levels = 1;
    while (levels < MAX_LEVELS && b * c.dt > SF_REFINE_BH * static_cast<double>(1 << levels)) ++levels;
    const int m = 1 << levels;
    const double h = c.dt / m;
    double nys[(1 << MAX_LEVELS) + 1];
    nys[0] = s.ny;
    nys[m] = ny1;
    CounterStream normals(key, pixel, s.n, PURPOSE_REFINE);
    for (int step = m / 2; step >= 1; step /= 2) {
        const NoiseCoeffs q = noise_coeffs_interval(0.0, b, D, step * h);
        const double phi = q.phi_yy, Q = q.l_yy * q.l_yy, w = 1.0 + phi * phi;
        const double gain = phi / w, sd = std::sqrt(Q / w);
        for (int i = step; i < m; i += 2 * step) {
            const double y0 = nys[i - step];
            const double g1 = normal_from_uniforms(normals.uniform(), normals.uniform());
            nys[i] = phi * y0 + gain * (nys[i + step] - phi * (phi * y0)) + sd * g1;
        }
    }
    const double piece_bridge = noise_coeffs_interval(0.0, b, D, h).bridge_var;
    const double sf_decay = std::exp(-b * h), sf_ramp = one_minus_exp_over(b * h);
    // Without the pole the follower's input is x itself (z = x, s.z its value at c.t0).
    double x_prev = s.z, yd_prev = s.y - s.ny;
    for (int i = 1; i <= m; ++i) {
        double xi, ydi;
        if (i == m) {
            xi = x1;
            ydi = yd1;
        } else {
            xi = s.z + (x1 - s.z) * (static_cast<double>(i) / m);
            ydi = detail::low_pass_exact(yd_prev, x_prev, xi, sf_decay, sf_ramp);
        }
        detail::compare_refined_piece(*this, s, ydi, nys[i], c, i, m, h, leak_g, piece_bridge, pulses, key, pixel, emit);
        x_prev = xi;
        yd_prev = ydi;
    }
}

}  // namespace evstwin

EVSTWIN_FP_STRICT_END
