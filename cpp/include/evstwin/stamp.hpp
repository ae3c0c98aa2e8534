// Two loops of the Python layer's PSF rendering (evstwin.psf, KernelPSF), in C++ because
// NumPy takes them in seven passes with a temporary array each: the bilinear mix of a
// tabulated PSF's four nearest sub-pixel phases, and a wide window's phases added to an
// image. Each computes the same expressions in the same order as the NumPy code it replaces
// (products and sums of doubles, rounded one at a time, no contraction into FMAs), so the
// results are the same bits.
#pragma once

#include <cstddef>

#include "config.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

/// out[s, i, j] = ((1 - b[s]) ((1 - a[s]) T[q, p] + a[s] T[q, p + 1])
///                 + b[s] ((1 - a[s]) T[q + 1, p] + a[s] T[q + 1, p + 1]))[i, j] * flux[s]
/// for n_src sources, with q = q[s], p = p[s] in [0, phases - 1) and T the (phases, phases,
/// side, side) C-ordered table; out is (n_src, side, side), C-ordered.
inline void bilinear_phase_mix(const double* table, std::size_t phases, std::size_t side, const std::ptrdiff_t* q,
                               const std::ptrdiff_t* p, const double* a, const double* b, const double* flux,
                               std::size_t n_src, double* out) {
    const std::size_t plane = side * side;
    for (std::size_t s = 0; s < n_src; ++s) {
        const double* t00 = table + (static_cast<std::size_t>(q[s]) * phases + static_cast<std::size_t>(p[s])) * plane;
        const double* t01 = t00 + plane;
        const double* t10 = t00 + phases * plane;
        const double* t11 = t10 + plane;
        const double as = a[s], bs = b[s], ma = 1.0 - as, mb = 1.0 - bs, f = flux[s];
        double* o = out + s * plane;
        for (std::size_t i = 0; i < plane; ++i)
            o[i] = (mb * (ma * t00[i] + as * t01[i]) + bs * (ma * t10[i] + as * t11[i])) * f;
    }
}

/// image[i, j] = (((image + c[0] T0) + c[1] T1) + ...)[i, j] over the terms with c[k] != 0, in
/// order: the same as adding c[k] T_k to the image one term at a time. n_terms <= 4; rows x
/// cols elements; row strides in elements (the image and each term may be a view of a wider
/// array; columns are contiguous). A term must not overlap the image (NumPy's out += c T would
/// buffer it; this reads each term element after earlier rows were written).
inline void add_scaled_terms(double* image, std::ptrdiff_t image_stride, const double* const* terms,
                             const std::ptrdiff_t* term_strides, const double* coef, std::size_t n_terms,
                             std::size_t rows, std::size_t cols) {
    const double* t[4];
    std::ptrdiff_t ts[4];
    double c[4];
    std::size_t m = 0;
    for (std::size_t k = 0; k < n_terms && k < 4; ++k)
        if (coef[k] != 0.0) {
            t[m] = terms[k];
            ts[m] = term_strides[k];
            c[m] = coef[k];
            ++m;
        }
    for (std::size_t r = 0; r < rows; ++r) {
        // Row pointers first, in signed arithmetic: a view's row stride may be negative.
        const std::ptrdiff_t rr = static_cast<std::ptrdiff_t>(r);
        double* o = image + rr * image_stride;
        const double* r0 = m > 0 ? t[0] + rr * ts[0] : nullptr;
        const double* r1 = m > 1 ? t[1] + rr * ts[1] : nullptr;
        const double* r2 = m > 2 ? t[2] + rr * ts[2] : nullptr;
        const double* r3 = m > 3 ? t[3] + rr * ts[3] : nullptr;
        switch (m) {
            case 1:
                for (std::size_t j = 0; j < cols; ++j) o[j] = o[j] + c[0] * r0[j];
                break;
            case 2:
                for (std::size_t j = 0; j < cols; ++j) o[j] = (o[j] + c[0] * r0[j]) + c[1] * r1[j];
                break;
            case 3:
                for (std::size_t j = 0; j < cols; ++j) o[j] = ((o[j] + c[0] * r0[j]) + c[1] * r1[j]) + c[2] * r2[j];
                break;
            case 4:
                for (std::size_t j = 0; j < cols; ++j)
                    o[j] = (((o[j] + c[0] * r0[j]) + c[1] * r1[j]) + c[2] * r2[j]) + c[3] * r3[j];
                break;
            default:
                break;
        }
    }
}

}  // namespace evstwin

EVSTWIN_FP_STRICT_END
