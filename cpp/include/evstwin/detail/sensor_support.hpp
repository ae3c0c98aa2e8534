// Three helpers of Sensor's that know nothing of pixels' physics: PixelDivider, the row
// width's division by a multiply and a shift (collect_sample() turns every event's pixel into
// (x, y)), advise_huge_pages(), the huge-page hint for its large arrays (the state, a
// call's event output), and touch_in_parallel(), the state's first touch. Included by sensor.hpp.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>

#include "../config.hpp"

#if defined(__linux__)
#include <sys/mman.h>
#endif

namespace evstwin {

namespace detail {
/// n / d for a pixel index n < 2^26 and a row width 1 <= d <= 65535 by a multiply and a
/// shift (collect_sample() turns every event's pixel into (x, y); a 32-bit division there cost more
/// than the rest of the copy). With l = ceil(log2 d), k = 26 + l and m = ceil(2^k / d),
/// n m / 2^k = n / d + n (m d - 2^k) / (d 2^k) lies below n / d + 1 / d, so its floor is
/// floor(n / d) (Granlund and Montgomery, PLDI 1994); n m < 2^26 (2^27 + 1) fits in 64 bits.
struct PixelDivider {
    static constexpr int INDEX_BITS = 26;
    explicit PixelDivider(std::uint32_t d) : d_(d) {
        if (d < 1 || d > 65535) throw std::invalid_argument("PixelDivider needs a divisor in [1, 65535]; got " + std::to_string(d));
        int l = 0;
        while ((std::uint32_t{1} << l) < d) ++l;
        shift_ = INDEX_BITS + l;
        m_ = ((std::uint64_t{1} << shift_) + d - 1) / d;
    }
    /// floor(n / d) for n < 2^26.
    std::uint32_t quotient(std::uint32_t n) const { return static_cast<std::uint32_t>((n * m_) >> shift_); }
    std::uint32_t divisor() const { return d_; }

private:
    std::uint32_t d_;
    int shift_ = 0;
    std::uint64_t m_ = 0;
};

/// Ask Linux to back the 2 MiB pages inside [p, p + bytes) with huge pages (transparent huge
/// pages in "madvise" mode, the usual default; NumPy asks the same for its large arrays). A
/// call's event output is fresh memory written once: with 4 KiB pages its page faults took
/// 5 ns an event, more than sorting it (100 ms for 19 M events, against 20 ms; the
/// documentation's decisions page). A hint: the memory and its contents are the same either way.
inline void advise_huge_pages(void* p, std::size_t bytes) {
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    constexpr std::uintptr_t HUGE_PAGE = std::uintptr_t{1} << 21;
    if (bytes < 2 * HUGE_PAGE) return;
    const std::uintptr_t a = (reinterpret_cast<std::uintptr_t>(p) + HUGE_PAGE - 1) & ~(HUGE_PAGE - 1);
    const std::uintptr_t e = (reinterpret_cast<std::uintptr_t>(p) + bytes) & ~(HUGE_PAGE - 1);
    if (e > a) (void)madvise(reinterpret_cast<void*>(a), e - a, MADV_HUGEPAGE);
#else
    (void)p;
    (void)bytes;
#endif
}

/// Fault in [p, p + bytes) from `threads` threads at once (2 MiB a thread's piece, one zero
/// byte a 4 KiB page: the kernel zeroes each page it maps, so writing the rest would only
/// write it again), before the caller constructs its objects there. On a virtual machine whose
/// hypervisor backs fresh huge pages slowly, a 162 MB array (the IMX636's state) touched once
/// in a fresh process took 0.04-0.65 s on one thread and 0.015-0.13 s on two (NumPy); the
/// sensor's build, 0.12-0.75 s before and 0.14-0.42 s after (bench/bench_sensor_build.py).
/// Only where memory is first touched changes.
inline void touch_in_parallel(void* p, std::size_t bytes, int threads) {
    constexpr std::size_t PIECE = std::size_t{1} << 21, PAGE = std::size_t{1} << 12;
    const std::int64_t pieces = static_cast<std::int64_t>((bytes + PIECE - 1) / PIECE);
    unsigned char* base = static_cast<unsigned char*>(p);
#if EVSTWIN_HAS_OPENMP
#pragma omp parallel for num_threads(threads) schedule(static) if (pieces >= 4)
#else
    (void)threads;
#endif
    for (std::int64_t k = 0; k < pieces; ++k) {
        const std::size_t end = std::min(bytes, static_cast<std::size_t>(k + 1) * PIECE);
        for (std::size_t at = static_cast<std::size_t>(k) * PIECE; at < end; at += PAGE)
            *static_cast<volatile unsigned char*>(base + at) = 0;
    }
}
}  // namespace detail

}  // namespace evstwin
