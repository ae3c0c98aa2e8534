// C++ tests of stamp.hpp: the PSF stamp loops.
#include <evstwin/evstwin.hpp>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <initializer_list>
#include <limits>
#include <utility>
#include <vector>

#include "check.hpp"
#include "helpers.hpp"
#include "noise_reference.hpp"

using namespace evstwin;

// stamp.hpp: the PSF renderer's two loops, on values a hand can check (each sum and product
// exact in binary), and a term with a zero coefficient is not read at all (0 x NaN would be NaN).
TEST(psf_stamp_loops_by_hand) {
    // Table (3, 3, 1, 1): T[q, p] = 3 q + p.
    std::vector<double> table(3 * 3);
    for (std::size_t i = 0; i < table.size(); ++i) table[i] = static_cast<double>(i);
    const std::ptrdiff_t q[2] = {0, 1}, p[2] = {1, 0};
    const double a[2] = {0.5, 0.0}, b[2] = {0.25, 1.0}, flux[2] = {4.0, 2.0};
    std::vector<double> out(2);
    evstwin::bilinear_phase_mix(table.data(), 3, 1, q, p, a, b, flux, 2, out.data());
    // Source 0: (0.75 (0.5 * 1 + 0.5 * 2) + 0.25 (0.5 * 4 + 0.5 * 5)) * 4 = (1.125 + 1.125) * 4.
    CHECK(out[0] == 9.0);
    // Source 1: b = 1, a = 0: T[2, 0] * 2.
    CHECK(out[1] == 12.0);

    double image[2][3] = {{1, 1, 1}, {1, 1, 1}};
    const double t0[2][4] = {{1, 2, 3, 99}, {4, 5, 6, 99}};  // a row stride of 4
    const double nan = std::numeric_limits<double>::quiet_NaN();
    const double t1[2][3] = {{nan, nan, nan}, {nan, nan, nan}};
    const double t2[2][3] = {{0.5, 0.5, 0.5}, {1, 1, 1}};
    const double* terms[3] = {&t0[0][0], &t1[0][0], &t2[0][0]};
    const std::ptrdiff_t strides[3] = {4, 3, 3};
    const double coef[3] = {2.0, 0.0, 4.0};
    evstwin::add_scaled_terms(&image[0][0], 3, terms, strides, coef, 3, 2, 3);
    CHECK(image[0][0] == 5.0 && image[0][1] == 7.0 && image[0][2] == 9.0);     // 1 + 2 t0 + 4 * 0.5
    CHECK(image[1][0] == 13.0 && image[1][1] == 15.0 && image[1][2] == 17.0);  // 1 + 2 t0 + 4
}
