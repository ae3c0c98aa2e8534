// OpenMP shim: the library compiles and gives identical events with or without OpenMP.
// A consumer opts in by compiling with OpenMP (e.g. linking OpenMP::OpenMP_CXX); the
// evstwin::evstwin target never forces it on anyone.
#pragma once

// evstwin is C++17 (inline variables, hex float literals, if constexpr). Said first, in the
// header every other one includes, so an older -std gets this line rather than a lexer error
// deep in rng.hpp. MSVC reports __cplusplus as 199711L unless /Zc:__cplusplus; _MSVC_LANG is right.
#if defined(_MSVC_LANG) ? (_MSVC_LANG < 201703L) : (__cplusplus < 201703L)
#error "evstwin needs C++17 or newer: compile with -std=c++17 (or target_compile_features(... cxx_std_17))"
// A missing header is fatal to GCC and Clang, which go on after #error (31 more errors, 149 lines).
#include "evstwin: stopped at the line above"
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

// The same for a lambda (written after its parameter list; no `inline` keyword there).
#if defined(__GNUC__) || defined(__clang__)
#define EVSTWIN_LAMBDA_ALWAYS_INLINE __attribute__((always_inline))
#else
#define EVSTWIN_LAMBDA_ALWAYS_INLINE
#endif

// A rare path kept out of line, so the common one around it stays short.
#if defined(__GNUC__) || defined(__clang__)
#define EVSTWIN_NOINLINE __attribute__((noinline))
#elif defined(_MSC_VER)
#define EVSTWIN_NOINLINE __declspec(noinline)
#else
#define EVSTWIN_NOINLINE
#endif

// No fused multiply-adds in the engine: a compiler may contract a * b + c into one FMA
// (rounded once instead of twice) wherever the target has FMA, which GCC does by default for
// the AVX-512 kernels that simd.hpp and the block kernels compile alongside the portable
// baseline, and for a consumer who builds with -march=native. The events would then depend
// on the instruction set. Every engine header turns contraction off between these two
// markers, so Sensor's events are the same bit for bit at every SIMD level and for any -march.
// What this covers: the functions compiled inside the markers. GCC decides per function and
// an always_inline engine function inlined into a consumer's own function (e.g. calling
// PixelModel::advance directly) takes the consumer's options; Sensor::run / run_pixels and
// Readout, which are not always_inline, keep them. -ffast-math (or clang's -ffp-contract=fast,
// which overrides its pragma) breaks bit-identity in other ways too, hence the warning.
#if defined(__clang__)
#define EVSTWIN_FP_STRICT_BEGIN _Pragma("float_control(push)") _Pragma("clang fp contract(off)")
#define EVSTWIN_FP_STRICT_END _Pragma("float_control(pop)")
#elif defined(__GNUC__)
#define EVSTWIN_FP_STRICT_BEGIN _Pragma("GCC push_options") _Pragma("GCC optimize(\"fp-contract=off\")")
#define EVSTWIN_FP_STRICT_END _Pragma("GCC pop_options")
#elif defined(_MSC_VER)
#define EVSTWIN_FP_STRICT_BEGIN __pragma(fp_contract(off))
#define EVSTWIN_FP_STRICT_END __pragma(fp_contract(on))
#else
#define EVSTWIN_FP_STRICT_BEGIN
#define EVSTWIN_FP_STRICT_END
#endif
#if defined(__FAST_MATH__) && !defined(EVSTWIN_ALLOW_FAST_MATH)
#warning "evstwin compiled with -ffast-math: events may differ between SIMD levels, thread counts and builds (define EVSTWIN_ALLOW_FAST_MATH to silence)"
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
