// Test-only helpers over noise.hpp: compositions the engine itself never needs in one call.
#pragma once

#include <evstwin/noise.hpp>

namespace evstwin {

/// Exact coefficients of the noise over an interval T, bridge_var included:
/// noise_coeffs_interval() then noise_coeffs_bridge() (arguments as there), the two calls
/// PixelModel's noise cache makes at different times.
inline NoiseCoeffs noise_coeffs(double a, double b, double D, double T, const SfTerms* sf = nullptr,
                                const PoleTerms* pole = nullptr) {
    NoiseCoeffs k = noise_coeffs_interval(a, b, D, T, sf, pole);
    noise_coeffs_bridge(k, a, b, D, T, sf, pole);
    return k;
}

}  // namespace evstwin
