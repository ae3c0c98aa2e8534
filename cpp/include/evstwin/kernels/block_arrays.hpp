// A block's pixels as a structure of arrays (BlockSoA), laid out apart in one allocation
// (BlockArena), and the numbers the vector quiet pass reads (QuietPass).
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <memory>
#include <new>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "../config.hpp"
#include "../state.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

namespace detail {
/// One array of a block's pixels inside a BlockArena: what the kernels use of a std::vector
/// (data(), operator[], size()), with the storage owned by the arena.
template <class T>
class BlockArray {
public:
    T* data() { return p_; }
    const T* data() const { return p_; }
    T& operator[](std::size_t i) { return p_[i]; }
    const T& operator[](std::size_t i) const { return p_[i]; }
    std::size_t size() const { return n_; }

private:
    friend class BlockArena;
    T* p_ = nullptr;
    std::size_t n_ = 0;
};

/// The per-pixel arrays of a block (BlockSoA, PixelModel::BlockScratch) in one allocation,
/// each starting one cache line after the previous one ends. Why: a block's arrays are all
/// 2 KB long (256 doubles), and as separate heap blocks (glibc puts them 2,064 bytes apart)
/// every other one started within 32 bytes of the same offset in a 4 KB page, so the quiet
/// pass's stores to one array and loads from another looked alike to the CPU's 4 KB store-load
/// aliasing check and the loads waited (the same events; up to ~12 % of the quiet pass's
/// time, and it came and went with where the heap placed them). Laid out here, n equal
/// arrays start at n different 64-byte offsets of a page (2,112 = 33 lines apart; 33 is
/// odd, so up to 64 of them).
class BlockArena {
public:
    BlockArena() = default;
    BlockArena(const BlockArena&) = delete;
    BlockArena& operator=(const BlockArena&) = delete;
    BlockArena(BlockArena&&) = default;  // the arrays' storage does not move with it
    BlockArena& operator=(BlockArena&&) = default;

    /// Lay out again every array that `each` names (each(put) calls put(array, size) for
    /// every one, in the same order each time): their elements kept up to the smaller size,
    /// new ones value-initialised (as std::vector::resize would).
    template <class Each>
    void lay_out(Each&& each) {
        std::size_t bytes = 0;
        each([&bytes](auto& a, std::size_t n) {
            using T = std::remove_reference_t<decltype(a[0])>;
            bytes = start_of(bytes) + n * sizeof(T);
        });
        std::unique_ptr<unsigned char[]> mem(new unsigned char[bytes + LINE]);
        unsigned char* base = mem.get() + (LINE - reinterpret_cast<std::uintptr_t>(mem.get()) % LINE) % LINE;
        std::size_t at = 0;
        each([&at, base](auto& a, std::size_t n) {
            using T = std::remove_reference_t<decltype(a[0])>;
            static_assert(std::is_trivially_copyable_v<T>, "BlockArena holds plain numbers");
            at = start_of(at);
            T* p = reinterpret_cast<T*>(base + at);
            const std::size_t kept = std::min(a.n_, n);
            if (kept) std::memcpy(static_cast<void*>(p), a.p_, kept * sizeof(T));
            for (std::size_t i = kept; i < n; ++i) new (p + i) T{};
            a.p_ = p;
            a.n_ = n;
            at += n * sizeof(T);
        });
        mem_ = std::move(mem);  // the old storage goes only now: its elements were copied above
    }

private:
    static constexpr std::size_t LINE = 64;
    /// Where the next array starts after one that ends at `end`: the next line, and one more.
    static std::size_t start_of(std::size_t end) { return (end + LINE - 1) / LINE * LINE + LINE; }
    std::unique_ptr<unsigned char[]> mem_;
};
}  // namespace detail

/// The fields of a block's pixel states that the continuous block kernel's common path reads
/// or writes, as a structure of arrays: a working copy of the block for the samples of one
/// run call (loaded before the first, stored after the last), so that path is one loop over
/// contiguous arrays that the compiler vectorises. The array-of-structures PixelState stays
/// the state between calls and for the rare pixels that need the whole comparator.
///
/// The fields a sample changes for every pixel are double-buffered (but the sample counter,
/// which grows by one for every pixel: n_base): a sample reads `now()`
/// and writes `next()` for every pixel (a quiet pixel's new values, or a busy one's after the
/// per-pixel path), then flip() makes them current. So the vector loop stores everything
/// unconditionally (a conditional store, "keep the old value unless quiet", is what stops a
/// compiler vectorising it) and the per-pixel path still starts from the old state.
struct BlockSoA {
    /// How many pixels ahead load() asks for their states' cache lines. Speed only.
    static constexpr std::size_t PREFETCH_AHEAD = 8;
    struct Levels {
        detail::BlockArray<double> x, z, y, nz, ny, ref, clock_on, clock_off;
    };
    Levels buf[2];
    int cur = 0;
    /// The sample counters (PixelState::n): pixel j's is n_base[j] + n_step (count()). Every
    /// pixel in the arrays advances one sample a step (flip() counts them), so no pass loads or
    /// stores a counter that only grows by one; take() and give() translate.
    detail::BlockArray<std::uint64_t> n_base;
    std::uint64_t n_step = 0;
    detail::BlockArray<double> refr_until, next_hot_t;  ///< changed only by the per-pixel path
    detail::BlockArray<double> theta_on, theta_off, leak_spread, bg_on_hz, bg_off_hz;  ///< constant in a run
    /// The quiet pass's per-pixel terms that hold while the block's common rate does (made by
    /// PixelModel::prepare_quiet_terms, with the operations the pass made them with): the leak's
    /// part of the slope, PixelModel::leak_slope(leak_spread, theta_on, theta_off, leak_hz), and
    /// the background clocks' rates bg_on_hz * bg_factor, bg_off_hz * bg_factor. One stream
    /// each in place of two or three, and their multiplies out of every sample's pass.
    detail::BlockArray<double> leak_g, bg_on_rate, bg_off_rate;
    /// The leak_hz and bg_factor those terms are for (NaN: none; load() forgets them).
    double terms_leak_hz = std::numeric_limits<double>::quiet_NaN();
    double terms_bg_factor = std::numeric_limits<double>::quiet_NaN();
    /// Whether the levels' x and nz are left unwritten by the quiet pass (QuietChain::SfOnly):
    /// with the source follower alone z is x (no pole between them) and nz is 0 (z carries no
    /// noise: PixelModel::continuous_levels), in every state at all times, so give() makes
    /// them and the pass saves a stream of loads and two of stores.
    bool sf_only = false;
    /// PixelState::spare_words as its two 32-bit halves (the Philox batch writes its third and
    /// fourth words straight into them, and the next odd sample reads them in place), and
    /// spare_sample: changed in place by the word batch.
    detail::BlockArray<std::uint32_t> spare_lo, spare_hi;
    detail::BlockArray<std::uint64_t> spare_sample;
    /// The quiet pass's verdict per pixel (0 quiet, 1 bridge, 2 per-pixel path), 64-bit like
    /// the levels: a byte array would make the vectoriser take 64 pixels an iteration (one
    /// byte vector), eight zmm registers per level, and spill them to the stack.
    detail::BlockArray<std::uint64_t> busy;
    detail::BlockArena arena;  ///< where the arrays above live

    Levels& now() { return buf[cur]; }
    const Levels& now() const { return buf[cur]; }
    Levels& next() { return buf[cur ^ 1]; }
    void flip() {
        cur ^= 1;
        ++n_step;
    }
    /// Pixel j's sample counter (PixelState::n) before the coming step.
    std::uint64_t count(std::size_t j) const { return n_base[j] + n_step; }

    void resize(std::size_t m) {
        if (busy.size() >= m) return;
        arena.lay_out([this, m](auto&& put) {
            for (Levels& l : buf) {
                for (auto* v : {&l.x, &l.z, &l.y, &l.nz, &l.ny, &l.ref, &l.clock_on, &l.clock_off}) put(*v, m);
            }
            for (auto* v : {&refr_until, &next_hot_t, &theta_on, &theta_off, &leak_spread, &bg_on_hz, &bg_off_hz,
                            &leak_g, &bg_on_rate, &bg_off_rate})
                put(*v, m);
            put(spare_lo, m);
            put(spare_hi, m);
            put(spare_sample, m);
            put(n_base, m);
            put(busy, m);
        });
    }
    /// Pixel j's fields from its state, its changing levels into `into`: now() for a state at
    /// the coming step's start, next() for one at its end (the per-pixel path's; its counter
    /// one ahead of count()).
    EVSTWIN_ALWAYS_INLINE void take(const PixelState& s, std::size_t j, Levels& into) {
        take_at(fields(into), s, j, s.n - n_step - static_cast<std::uint64_t>(&into != &now()));
    }
    /// Pixel j's fields back into its state, its changing levels from `from` (the constant
    /// ones are not written).
    EVSTWIN_ALWAYS_INLINE void give(PixelState& s, std::size_t j, const Levels& from) const {
        give_at(fields(from), sf_only, s, j, n_step);  // (fields() takes x from z with sf_only)
    }
    /// Every pixel's fields from its state: take() for each, and the constant ones.
    void load(const PixelState* __restrict st, std::size_t m) {
        resize(m);
        terms_leak_hz = terms_bg_factor = std::numeric_limits<double>::quiet_NaN();
        n_step = 0;
        sf_only = false;  // x and nz as loaded, until a step of the source follower alone
        const Fields f = fields(now());
        double* __restrict ton = theta_on.data();
        double* __restrict toff = theta_off.data();
        double* __restrict ls = leak_spread.data();
        double* __restrict bon = bg_on_hz.data();
        double* __restrict boff = bg_off_hz.data();
        for (std::size_t j = 0; j < m; ++j) {
#if defined(__GNUC__) || defined(__clang__)
            // run() loads a block's states straight from memory when it knows they all stand at
            // the sample's start (Sensor::block_synced_), at a stride the hardware prefetcher
            // follows only within a page: the fields' lines a few pixels ahead are asked for now.
            if (j + PREFETCH_AHEAD < m) {
                const char* ahead = reinterpret_cast<const char*>(st + j + PREFETCH_AHEAD);
                for (std::size_t line = 0; line < sizeof(PixelState); line += 64) __builtin_prefetch(ahead + line);
                __builtin_prefetch(ahead + sizeof(PixelState) - 1);  // where the record is not 64-byte aligned
            }
#endif
            const PixelState& s = st[j];
            take_at(f, s, j, s.n);  // take(s, j, now()) with n_step = 0
            ton[j] = s.theta_on; toff[j] = s.theta_off; ls[j] = s.leak_spread;
            bon[j] = s.bg_on_hz; boff[j] = s.bg_off_hz;
        }
    }
    /// Back into the states, which all stand at t_s now; but for the pixels flagged in held
    /// (nullptr: none), whose states are left as they are (step_block_soa's held pixels).
    void store(PixelState* __restrict st, std::size_t m, double t_s, const std::uint8_t* held = nullptr) const {
        const ConstFields f = fields(now());
        const bool sf = sf_only;
        const std::uint64_t step = n_step;
        for (std::size_t j = 0; j < m; ++j) {
            if (held && held[j]) continue;
            give_at(f, sf, st[j], j, step);
            st[j].t = t_s;
        }
    }

private:
    /// The arrays take() and give() touch, at one Levels, by address: fetched once for a whole
    /// block in load() and store(). (Through the vectors, every store might alias their
    /// pointers and the compiler reloads them for every field of every pixel: ~70 instructions
    /// a pixel in load() where this takes ~46.)
    template <class Real, class Word, class Count>
    struct FieldsOf {
        Real *x, *z, *y, *nz, *ny, *ref, *clock_on, *clock_off, *refr_until, *next_hot_t;
        Count *n_base, *spare_sample;
        Word *spare_lo, *spare_hi;
    };
    using Fields = FieldsOf<double, std::uint32_t, std::uint64_t>;
    using ConstFields = FieldsOf<const double, const std::uint32_t, const std::uint64_t>;
    Fields fields(Levels& l) {
        return {l.x.data(),          l.z.data(),          l.y.data(),        l.nz.data(),
                l.ny.data(),         l.ref.data(),        l.clock_on.data(), l.clock_off.data(),
                refr_until.data(),   next_hot_t.data(),   n_base.data(),     spare_sample.data(),
                spare_lo.data(),     spare_hi.data()};
    }
    /// With the source follower alone, x is read from z (sf_only; give()).
    ConstFields fields(const Levels& l) const {
        return {sf_only ? l.z.data() : l.x.data(), l.z.data(),          l.y.data(),        l.nz.data(),
                l.ny.data(),         l.ref.data(),        l.clock_on.data(), l.clock_off.data(),
                refr_until.data(),   next_hot_t.data(),   n_base.data(),     spare_sample.data(),
                spare_lo.data(),     spare_hi.data()};
    }
    /// take() and give() of one pixel, where n_base is its counter less the step's, and
    /// sf_only as BlockSoA's: nz is 0 with the source follower alone (and fields() points x at z).
    static EVSTWIN_ALWAYS_INLINE void take_at(const Fields& f, const PixelState& s, std::size_t j, std::uint64_t n_base) {
        f.x[j] = s.x; f.z[j] = s.z; f.y[j] = s.y; f.nz[j] = s.nz; f.ny[j] = s.ny;
        f.ref[j] = s.ref; f.clock_on[j] = s.bg_clock_on; f.clock_off[j] = s.bg_clock_off;
        f.n_base[j] = n_base;
        f.refr_until[j] = s.refr_until; f.next_hot_t[j] = s.next_hot_t;
        f.spare_lo[j] = static_cast<std::uint32_t>(s.spare_words);
        f.spare_hi[j] = static_cast<std::uint32_t>(s.spare_words >> 32);
        f.spare_sample[j] = s.spare_sample;
    }
    static EVSTWIN_ALWAYS_INLINE void give_at(const ConstFields& f, bool sf_only, PixelState& s, std::size_t j,
                                              std::uint64_t step) {
        s.x = f.x[j]; s.z = f.z[j]; s.y = f.y[j];
        s.nz = sf_only ? 0.0 : f.nz[j]; s.ny = f.ny[j];
        s.ref = f.ref[j]; s.bg_clock_on = f.clock_on[j]; s.bg_clock_off = f.clock_off[j]; s.n = f.n_base[j] + step;
        s.refr_until = f.refr_until[j]; s.next_hot_t = f.next_hot_t[j];
        s.spare_words = static_cast<std::uint64_t>(f.spare_lo[j]) | (static_cast<std::uint64_t>(f.spare_hi[j]) << 32);
        s.spare_sample = f.spare_sample[j];
    }
};

/// What the continuous block kernel's common path needs: the block's arrays and the numbers
/// of one photon rate (the block's common one) for one sample interval.
struct QuietPass {
    const BlockSoA::Levels* now;
    BlockSoA::Levels* next;
    const double *refr_until, *next_hot_t, *theta_on, *theta_off;
    /// BlockSoA's terms for this rate (PixelModel::prepare_quiet_terms): the leak's part of the slope, and the
    /// background clocks' rates (bg_on_hz * bg_factor, bg_off_hz * bg_factor).
    const double *leak_g, *bg_on_rate, *bg_off_rate;
    const double *g1, *g2;
    std::uint64_t* busy;
    std::size_t count;
    double rate;  ///< the common photon rate: the pixels at any other are left busy
    double cx, pole_decay, pole_ramp;                 ///< NoiseCache's x and pole numbers at that rate
    double phi_zz, phi_yz, phi_yy, l_zz, l_yz, l_yy;  ///< its noise transition and innovation
    double bridge_bound;
    double sf_decay, sf_ramp, dt, inv_dt, t0, t1;
    /// Whether a pixel that only the bridge keeps from quiet may be settled by the bridge stage
    /// (step_block_soa_impl): the bridge has a variance and continuous_finish() would not refine.
    bool bridge_stage;
};

}  // namespace evstwin

EVSTWIN_FP_STRICT_END
