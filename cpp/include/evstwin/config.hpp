// OpenMP shim: the library compiles and gives identical events with or without OpenMP.
// A consumer opts in by compiling with OpenMP (e.g. linking OpenMP::OpenMP_CXX); the
// evstwin::evstwin target never forces it on anyone.
#pragma once

// evstwin is C++17 (inline variables, hex float literals, if constexpr). Said first, in the
// header every other one includes, so an older -std gets this line rather than a lexer error
// deep in rng.hpp. MSVC reports __cplusplus as 199711L unless /Zc:__cplusplus; _MSVC_LANG is right.
#if defined(_MSVC_LANG) ? (_MSVC_LANG < 201703L) : (__cplusplus < 201703L)
#error "evstwin needs C++17 or newer: compile with -std=c++17 (or target_compile_features(... cxx_std_17))"
#endif

#if defined(_OPENMP) && !defined(EVSTWIN_NO_OPENMP)
#include <omp.h>
#define EVSTWIN_HAS_OPENMP 1
#else
#define EVSTWIN_HAS_OPENMP 0
#endif

// The per-pixel update is called once per pixel and sample; inlining it into the sensor
// loop removes a call and lets the compiler keep the pixel state in registers.
#if defined(__GNUC__) || defined(__clang__)
#define EVSTWIN_ALWAYS_INLINE inline __attribute__((always_inline))
#elif defined(_MSC_VER)
#define EVSTWIN_ALWAYS_INLINE __forceinline
#else
#define EVSTWIN_ALWAYS_INLINE inline
#endif

// A rare path kept out of line, so the common one around it stays short.
#if defined(__GNUC__) || defined(__clang__)
#define EVSTWIN_NOINLINE __attribute__((noinline))
#elif defined(_MSC_VER)
#define EVSTWIN_NOINLINE __declspec(noinline)
#else
#define EVSTWIN_NOINLINE
#endif

namespace evstwin {

/// Number of threads a parallel loop would use by default (1 without OpenMP).
inline int default_num_threads() {
#if EVSTWIN_HAS_OPENMP
    return omp_get_max_threads();
#else
    return 1;
#endif
}

inline constexpr bool has_openmp() { return EVSTWIN_HAS_OPENMP != 0; }

}  // namespace evstwin
