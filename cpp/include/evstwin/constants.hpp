// Physical constants, one place each.
#pragma once

#include "config.hpp"

namespace evstwin {

/// Elementary charge [C] (CODATA 2018, exact).
inline constexpr double ELEMENTARY_CHARGE_C = 1.602176634e-19;
inline constexpr double PI = 3.14159265358979323846;

}  // namespace evstwin
