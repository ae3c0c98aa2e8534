// What several C++ test files share: test inputs and states compared field by field.
#pragma once

#include <evstwin/evstwin.hpp>

#include <cstdint>
#include <cstring>
#include <tuple>
#include <utility>

namespace test_support {
using namespace evstwin;

/// Uniforms in (0, 1) from xorshift64 (Marsaglia 2003), 53 bits each: test inputs that do
/// not share the engine's Philox streams.
struct XorshiftUniform {
    std::uint64_t state;
    double operator()() {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        return (static_cast<double>(state >> 11) + 0.5) * 0x1p-53;
    }
};

inline PixelParams ideal() {
    PixelParams p;
    p.photon_shot_noise = false;
    p.dark_model = DarkModel::None;
    p.leak_rate_hz = 0.0;
    p.shot_noise_rate_hz = 0.0;
    p.cutoff_hz.reset();
    p.refractory_s = 0.0;
    p.theta_on = p.theta_off = 0.2;
    return p;
}

template <class T>
bool same_field(const T& a, const T& b) {
    return std::memcmp(&a, &b, sizeof a) == 0;
}

/// A hot pixel's clocks compare by what they hold, not by where they are (below).
inline bool same_field(const HotBox& a, const HotBox& b);

template <class A, class B, std::size_t... I>
bool same_bits(const A& a, const B& b, std::index_sequence<I...>) {
    return (same_field(std::get<I>(a), std::get<I>(b)) && ...);
}

/// Both empty, or the same bits in every field.
inline bool same_field(const HotBox& a, const HotBox& b) {
    if (!a || !b) return !a && !b;
    const auto fa = hot_state_fields(*a);
    const auto fb = hot_state_fields(*b);
    return same_bits(fa, fb, std::make_index_sequence<std::tuple_size<decltype(fa)>::value>{});
}

/// Whether two states hold the same bits in every field (state_fields: a field added to
/// PixelState cannot be missed); words: whether the kept random words (spare_words,
/// spare_sample) count too.
inline bool same_state(const PixelState& a, const PixelState& b, bool words = true) {
    PixelState a2 = a;
    if (!words) {
        a2.spare_words = b.spare_words;
        a2.spare_sample = b.spare_sample;
    }
    const auto fa = state_fields(a2);
    const auto fb = state_fields(b);
    return same_bits(fa, fb, std::make_index_sequence<std::tuple_size<decltype(fa)>::value>{});
}
}  // namespace test_support

using test_support::ideal;
using test_support::same_state;
using test_support::XorshiftUniform;
