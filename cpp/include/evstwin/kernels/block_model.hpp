// The block kernels: BlockModel, PixelModel with step_block (array of structures, sampled
// and continuous models) and step_block_soa (the vector kernel over BlockSoA, defined in
// block_soa.hpp), their batched random words and normals, and the bridge's batched decisions.
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
#include "../pixel.hpp"
#include "../simd.hpp"
#include "block_arrays.hpp"
#include "quiet_pass.hpp"
#include "../simd/block_passes.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

/// PixelModel with the block kernels: many pixels of a block advanced over one sample at a
/// time, with the same events, bit for bit, as PixelModel::advance() pixel by pixel (the
/// tests check it). Sensor uses it; it adds no state of its own.
struct BlockModel : PixelModel {
    using PixelModel::PixelModel;

    /// Whether the block kernels below handle this configuration: every continuous one
    /// (step_block_continuous), the common sampled ones (step_block_impl).
    bool has_block_kernel() const {
        if (continuous) return true;
        const bool pooled = p.photon_shot_noise && p.dark_model != DarkModel::Paper;
        const bool deterministic = !p.photon_shot_noise && p.dark_model == DarkModel::None;
        return pooled || deterministic;
    }

    /// Room for pad_batch's padding (at least the Philox batches' widest vector body, 8 counters).
    static constexpr std::size_t PHILOX_BATCH_PAD = 16;
    /// Scratch space of the block kernel (one per thread).
    struct BlockScratch {
        detail::BlockArray<double> u_noise, x, current, y;
        detail::BlockArray<std::uint8_t> busy;
        detail::BlockArray<std::uint32_t> count_word;
        detail::BlockArray<double> z, count;
        // The continuous model's: the sample's second word, the noise, the bridge's variance.
        detail::BlockArray<std::uint32_t> word1, busy_at;
        detail::BlockArray<double> nz, ny, bridge_var, noise_d;
        detail::BlockArray<double> leak;  ///< the busy pixels' leak rates (continuous), or slopes (sampled)
        // block_sample_words' Philox batch: counters, the pixels that need a call, the words;
        // and the ziggurat batch's flags of the normals left to the slow path.
        detail::BlockArray<std::uint32_t> ctr0, ctr1, ctr2, need_at, r0, r1, r2, r3;
        detail::BlockArray<std::uint8_t> slow1, slow2;
        detail::BlockArray<BridgePre> bridge_pre;  ///< step_block_continuous' bridge decisions of the busy pixels
        std::vector<double> bridge_args;    ///< bridge_decisions' numbers, ARGS a pixel
        detail::BlockArray<std::uint32_t> fired;   ///< bridge_decisions' pixels whose draw fires
        double cached_rate = -1.0, cached_x = 0.0;
        // The photoreceptor pole's decay and ramp depend on the current only through the
        // electron count of the interval: kept per count for the current dt.
        std::vector<double> pr_decay, pr_ramp;
        std::vector<std::uint8_t> pr_known;
        double pr_dt = -1.0;
        NoiseCache noise;  ///< the continuous model's per-rate numbers (advance())
        NoiseCache noise_other;  ///< step_block_soa's: the last own-rate pixel's numbers, carried to the next sample and call
        // step_block_soa's fills for those pixels, made together (fill_noise_caches): their
        // rates, numbers and stages; grown to the most a call has needed.
        std::vector<double> fill_rates;
        std::vector<NoiseCache> fills;
        std::vector<NoiseIntervalStage> fill_stages;
        BlockSoA soa;  ///< step_block_soa's working copy of a block's state
        detail::BlockArena arena;  ///< where the BlockArray members above live
        void resize(std::size_t n) {
            if (x.size() >= n) return;
            const std::size_t padded = n + PHILOX_BATCH_PAD;  // room for a short batch's padding (pad_batch)
            arena.lay_out([this, n, padded](auto&& put) {
                for (auto* v : {&u_noise, &x, &current, &y, &z, &count, &nz, &ny, &bridge_var, &noise_d, &leak}) put(*v, n);
                for (auto* v : {&count_word, &word1, &busy_at, &need_at, &fired}) put(*v, n);
                for (auto* v : {&ctr0, &ctr1, &ctr2, &r0, &r1, &r2, &r3}) put(*v, padded);
                for (auto* v : {&busy, &slow1, &slow2}) put(*v, n);
                put(bridge_pre, n);
            });
        }
    };

    /// A Philox batch of m counters (ctr0..ctr2 from index 0) padded with zero counters up to a
    /// multiple of the batch loop's vector body at the current SIMD level (4 counters on SSE2
    /// and AVX2, 8 with AVX-512: simd.hpp), which does the rest one by one: a batch of a few (a
    /// block's slow normals or bridge draws, ~10) would be mostly scalar. The padding's words
    /// are not used.
    static std::size_t pad_batch(BlockScratch& scratch, std::size_t m) {
        const std::size_t width = simd_level() == SimdLevel::AVX512 ? 8 : 4;
        const std::size_t padded = (m + width - 1) / width * width;
        for (std::size_t i = m; i < padded; ++i) scratch.ctr0[i] = scratch.ctr1[i] = scratch.ctr2[i] = 0;
        return padded;
    }

    /// Which pixels of a block the kernel advances now: `active` lists their positions
    /// (local indices into the block's state, rates and ids).
    struct BlockView {
        PixelState* state;           ///< the block's pixel states
        const std::uint32_t* ids;    ///< global pixel index of each local index
        const std::uint32_t* active; ///< local indices to advance, in increasing order; nullptr: all
        std::size_t n_active;
    };

    /// sample_words() for n pixels of a block: the pixels whose words are not kept from the
    /// previous sample are listed, their Philox calls made in one batch (simd.hpp: vectorised,
    /// the same bits at every instruction set), and the words handed out and kept as
    /// sample_words() does. count(j): the j-th pixel's sample counter; id(j): its global index;
    /// spare(j, words, sample): its kept words and the sample they belong to (references).
    template <class Count, class Id, class Spare>
    EVSTWIN_ALWAYS_INLINE static void batch_sample_words(std::size_t n, Count count, Id id, Spare spare,
                                                         Philox4x32Key key, BlockScratch& scratch, std::uint32_t* w0,
                                                         std::uint32_t* w1) {
        std::uint32_t *c0 = scratch.ctr0.data(), *c1 = scratch.ctr1.data(), *c2 = scratch.ctr2.data();
        std::uint32_t* need = scratch.need_at.data();
        std::size_t m = 0;
        for (std::size_t j = 0; j < n; ++j) {
            const std::uint64_t sample = count(j);
            spare(j, [&](std::uint64_t& words, std::uint64_t& kept_for) {
                if ((sample & 1u) && kept_for == sample) {
                    w0[j] = static_cast<std::uint32_t>(words);
                    w1[j] = static_cast<std::uint32_t>(words >> 32);
                } else {
                    const std::uint64_t pair = sample >> 1;
                    c0[m] = static_cast<std::uint32_t>(pair);
                    c1[m] = static_cast<std::uint32_t>(pair >> 32);
                    c2[m] = id(j);
                    need[m] = static_cast<std::uint32_t>(j);
                    ++m;
                }
            });
        }
        if (m == 0) return;
        std::uint32_t *r0 = scratch.r0.data(), *r1 = scratch.r1.data(), *r2 = scratch.r2.data(), *r3 = scratch.r3.data();
        philox4x32_batch(c0, c1, c2, PURPOSE_SAMPLE, key, m, r0, r1, r2, r3);
        for (std::size_t q = 0; q < m; ++q) {
            const std::size_t j = need[q];
            const std::uint64_t sample = count(j);
            const bool odd = (sample & 1u) != 0;
            w0[j] = odd ? r2[q] : r0[q];
            w1[j] = odd ? r3[q] : r1[q];
            spare(j, [&](std::uint64_t& words, std::uint64_t& kept_for) {
                words = static_cast<std::uint64_t>(r2[q]) | (static_cast<std::uint64_t>(r3[q]) << 32);
                kept_for = sample | 1u;
            });
        }
    }

    /// batch_sample_words() for a block held as arrays, with the two cases of a block whose
    /// pixels all share the sample's parity as loops without branches: an odd sample whose
    /// words every pixel kept (no Philox call: w0, w1 point at the kept words in h), and an
    /// even one where every pixel needs one (the batch writes the kept words straight into h).
    /// Anything else (pixels sub-sampled apart) goes through batch_sample_words() into the
    /// scratch arrays. The same words. Each case is tested by one pass over the block without
    /// an early exit (an OR of the parities or mismatches), which vectorises, fused with the
    /// counters the even case needs; a block of pixels sub-sampled apart wastes one such pass.
    EVSTWIN_ALWAYS_INLINE static void soa_sample_words(BlockSoA& h, const std::uint32_t* ids, std::size_t n,
                                                       Philox4x32Key key, BlockScratch& scratch,
                                                       const std::uint32_t*& w0, const std::uint32_t*& w1) {
        // The counters as BlockSoA keeps them: sample[j] + step (BlockSoA::count).
        const std::uint64_t* __restrict sample = h.n_base.data();
        const std::uint64_t step = h.n_step;
        std::uint32_t* __restrict lo = h.spare_lo.data();
        std::uint32_t* __restrict hi = h.spare_hi.data();
        std::uint64_t* __restrict kept_for = h.spare_sample.data();
        std::uint32_t* __restrict s0 = scratch.count_word.data();
        std::uint32_t* __restrict s1 = scratch.word1.data();
        const bool first_odd = n > 0 && ((sample[0] + step) & 1u);
        if (first_odd) {
            if (detail::sample_words_off(kept_for, sample, step, n) == 0) {
                w0 = lo;
                w1 = hi;
                return;
            }
        } else {
            std::uint32_t *__restrict c0 = scratch.ctr0.data(), *__restrict c1 = scratch.ctr1.data(),
                          *__restrict c2 = scratch.ctr2.data();
            if (!(detail::even_counters(sample, step, ids, n, c0, c1, c2) & 1u)) {
                philox4x32_batch(c0, c1, c2, PURPOSE_SAMPLE, key, n, s0, s1, lo, hi);
                detail::keep_for_next(sample, step, n, kept_for);
                w0 = s0;
                w1 = s1;
                return;
            }
        }
        batch_sample_words(
            n, [sample, step](std::size_t j) { return sample[j] + step; }, [ids](std::size_t j) { return ids[j]; },
            [&](std::size_t j, auto&& use) {
                std::uint64_t words = static_cast<std::uint64_t>(lo[j]) | (static_cast<std::uint64_t>(hi[j]) << 32);
                use(words, kept_for[j]);
                lo[j] = static_cast<std::uint32_t>(words);
                hi[j] = static_cast<std::uint32_t>(words >> 32);
            },
            key, scratch, s0, s1);
        w0 = s0;
        w1 = s1;
    }

    /// batch_sample_words() for the active pixels of a block view (array-of-structures state).
    template <bool AllActive>
    EVSTWIN_ALWAYS_INLINE static void block_sample_words(const BlockView& v, Philox4x32Key key, BlockScratch& scratch,
                                                         std::uint32_t* w0, std::uint32_t* w1) {
        PixelState* st = v.state;
        const auto at = [&v](std::size_t j) -> std::size_t { return AllActive ? j : v.active[j]; };
        batch_sample_words(
            v.n_active, [&](std::size_t j) { return st[at(j)].n; }, [&](std::size_t j) { return v.ids[at(j)]; },
            [&](std::size_t j, auto&& use) { use(st[at(j)].spare_words, st[at(j)].spare_sample); }, key, scratch, w0,
            w1);
    }

    /// sample_normals() for n pixels of a block: the ziggurat's common path as one batch for
    /// each word (simd.hpp), then the few normals in a wedge or the tail finished as
    /// sample_normals() would (both sharing the pixel's further words, the first one first).
    /// Without `second` only g1 is made (g2 is left as it was): with one low-pass the noise is
    /// a 1-D process that uses g1 alone (continuous_levels), and skipping g2 cannot change g1,
    /// which takes the further words first. count(j), id(j) as in batch_sample_words.
    template <class Count, class Id>
    EVSTWIN_ALWAYS_INLINE static void batch_sample_normals(std::size_t n, Count count, Id id, Philox4x32Key key,
                                                           BlockScratch& scratch, const std::uint32_t* w0,
                                                           const std::uint32_t* w1, double* g1, double* g2,
                                                           bool second) {
        std::uint8_t *slow1 = scratch.slow1.data(), *slow2 = scratch.slow2.data();
        ziggurat_batch(w0, n, g1, slow1);
        if (second) ziggurat_batch(w1, n, g2, slow2);
        // The flags of both words in one array, so one scan finds the few to finish.
        if (second)
            for (std::size_t j = 0; j < n; ++j) slow1[j] |= static_cast<std::uint8_t>(slow2[j] << 1);
        // The few to finish, listed; their further words' first blocks in one Philox batch (a
        // scalar call each was most of the slow path's instructions), and the bracket of each
        // one's first wedge test in one pass without branches (its polynomial's latency then
        // overlaps across normals); then each finished from a stream that starts with that block.
        std::uint32_t* at = scratch.need_at.data();
        std::size_t m = list_flagged(slow1, n, at);
        if (m == 0) return;
        std::uint32_t *c0 = scratch.ctr0.data(), *c1 = scratch.ctr1.data(), *c2 = scratch.ctr2.data();
        double* q_first = scratch.noise_d.data();
        const ZigguratTables& z = ZIGGURAT;
        for (std::size_t q = 0; q < m; ++q) {
            const std::size_t j = at[q];
            const std::uint64_t sample = count(j);
            c0[q] = static_cast<std::uint32_t>(sample);
            c1[q] = static_cast<std::uint32_t>(sample >> 32);
            c2[q] = id(j);
            const std::uint32_t w = (slow1[j] & 1u) ? w0[j] : w1[j];
            const double x = static_cast<double>(w >> 8) * z.w[w & 127u];
            q_first[q] = detail::exp_neg_bracket(0.5 * x * x);
        }
        std::uint32_t *r0 = scratch.r0.data(), *r1 = scratch.r1.data(), *r2 = scratch.r2.data(), *r3 = scratch.r3.data();
        philox4x32_batch(c0, c1, c2, PURPOSE_NORMAL, key, pad_batch(scratch, m), r0, r1, r2, r3);
        // A slow normal alone in its stream (the pixel's other normal is not slow) that falls
        // in a wedge is finished here, as normal_ziggurat_slow would finish it, in a loop
        // without branches, where its first wedge test decides clearly (lhs against
        // q (1 -+ 1e-6), with the stream's first word, r0): accepted, it is that word's x;
        // rejected, the stream's second word (r1) starts over, and where that word's common
        // test accepts it, it is the second word's x. That accept-or-reject branch, taken
        // about as often as not, was most of the slow path's time (mispredicted). Either
        // normal: the first (flag 1) and the second (flag 2) each take the stream from its
        // first word when alone, and q_first is the bracket of that one's word. The others
        // (undecided first tests, a second word that is slow too, the tail, two slow normals
        // sharing a stream) are kept, in order, for the loop below.
        std::size_t d = 0;
        for (std::size_t q = 0; q < m; ++q) {
            const std::size_t j = at[q];
            const std::uint8_t flags = slow1[j];
            const bool first = flags & 1u;
            const std::uint32_t w = first ? w0[j] : w1[j], layer = w & 127u, wedge = layer != 0 ? layer : 1u;
            const double x = static_cast<double>(w >> 8) * z.w[layer];
            const double lhs = z.f[wedge] + uniform_open(r0[q]) * (z.f[wedge - 1] - z.f[wedge]);
            const bool wedge_alone = (flags != 3u) & (layer != 0);
            const bool accepted = wedge_alone & (lhs < q_first[q] * (1.0 - 1e-6));
            const std::uint32_t w_next = r1[q], layer_next = w_next & 127u;
            const bool next_common = (w_next >> 8) < z.k[layer_next];
            const bool retried = wedge_alone & (lhs > q_first[q] * (1.0 + 1e-6)) & next_common;
            const double x_next = static_cast<double>(w_next >> 8) * z.w[layer_next];
            // sign * x, sign = +-1 from bit 7, of the accepted word
            const double g_first = (1.0 - 2.0 * static_cast<double>((w >> 7) & 1u)) * x;
            const double g_next = (1.0 - 2.0 * static_cast<double>((w_next >> 7) & 1u)) * x_next;
            // *out = accepted ? g_first : retried ? g_next : *out by bit masks: a select here
            // became a mispredicted branch.
            double* out = first ? g1 + j : g2 + j;
            std::uint64_t first_bits, next_bits, old_bits;
            std::memcpy(&first_bits, &g_first, sizeof first_bits);
            std::memcpy(&next_bits, &g_next, sizeof next_bits);
            std::memcpy(&old_bits, out, sizeof old_bits);
            const std::uint64_t take_first = 0u - static_cast<std::uint64_t>(accepted);
            const std::uint64_t take_next = 0u - static_cast<std::uint64_t>(retried);
            const std::uint64_t bits =
                (first_bits & take_first) | (next_bits & take_next) | (old_bits & ~(take_first | take_next));
            std::memcpy(out, &bits, sizeof bits);
            const bool done = accepted | retried;
            at[d] = static_cast<std::uint32_t>(j);
            r0[d] = r0[q]; r1[d] = r1[q]; r2[d] = r2[q]; r3[d] = r3[q];
            q_first[d] = q_first[q];
            d += !done;
        }
        m = d;
        for (std::size_t q = 0; q < m; ++q) {
            const std::size_t j = at[q];
            const bool first_slow = slow1[j] & 1u, second_slow = slow1[j] >> 1;
            const Philox4x32Counter first{r0[q], r1[q], r2[q], r3[q]};
            PrefilledStream extra(key, id(j), count(j), PURPOSE_NORMAL, &first);
            auto more = [&extra] { return extra.word(); };
            if (first_slow) g1[j] = normal_ziggurat_slow(w0[j], more, q_first[q]);
            if (second_slow) g2[j] = normal_ziggurat_slow(w1[j], more, first_slow ? -1.0 : q_first[q]);
        }
    }

    /// batch_sample_normals() for the active pixels of a block view.
    template <bool AllActive>
    EVSTWIN_ALWAYS_INLINE static void block_sample_normals(const BlockView& v, Philox4x32Key key, BlockScratch& scratch,
                                                           const std::uint32_t* w0, const std::uint32_t* w1, double* g1,
                                                           double* g2, bool second) {
        const auto at = [&v](std::size_t j) -> std::size_t { return AllActive ? j : v.active[j]; };
        batch_sample_normals(
            v.n_active, [&](std::size_t j) { return v.state[at(j)].n; }, [&](std::size_t j) { return v.ids[at(j)]; },
            key, scratch, w0, w1, g1, g2, second);
    }

    /// advance() for pixels that all stand at c.t0 with n > 0, as separate passes (random
    /// words; currents; filter, noise and the quiet test; the comparator for the few busy
    /// pixels; the commit), so each pass is a short loop the processor can overlap across
    /// pixels. Same arithmetic in the same order as step(): the same events.
    template <class Real, class Emit>
    void step_block(const BlockView& v, const Real* rate, const SampleConstants& c, Philox4x32Key key,
                    PoissonSampler& poisson, BlockScratch& scratch, Emit&& emit, std::uint32_t& pixel) const {
        // All pixels active (the common case): index them directly, without the indirection.
        if (continuous) {
            const bool sf_only = has_filter && !euler && !p.pr_pole;  // the default configuration
            if (v.active == nullptr) {
                if (sf_only)
                    step_block_continuous<true, true>(v, rate, c, key, scratch, emit, pixel);
                else
                    step_block_continuous<true, false>(v, rate, c, key, scratch, emit, pixel);
            } else {
                if (sf_only)
                    step_block_continuous<false, true>(v, rate, c, key, scratch, emit, pixel);
                else
                    step_block_continuous<false, false>(v, rate, c, key, scratch, emit, pixel);
            }
        } else if (v.active == nullptr) {
            step_block_impl<true>(v, rate, c, key, poisson, scratch, emit, pixel);
        } else {
            step_block_impl<false>(v, rate, c, key, poisson, scratch, emit, pixel);
        }
    }

    /// The block kernels' quiet test for a pixel whose new level is y1 (its state still at c.t0,
    /// its clocks spent): the line (compare()'s fast path) and, around it, the bridge's
    /// exponents. The difference d inside both thresholds at both ends, and (th_on - d0)(th_on -
    /// d1) and (th_off + d0)(th_off + d1) above the bound (a product above a bound >= 0 with
    /// its first factor positive also says that the second one is; std::min returns its first
    /// argument where a NaN is involved, and a NaN in the second one makes the first NaN). d1:
    /// the difference at c.t1 (a quiet pixel's reference becomes y1 - d1). detail::quiet_pass_body
    /// is the same test, vectorised.
    EVSTWIN_ALWAYS_INLINE bool quiet_in_interval(const PixelState& s, double y1, const NoiseCache& cache,
                                                 const SampleConstants& c, bool clock_ran_out, double& d1) const {
        const double th_on = s.theta_on, th_off = s.theta_off;
        const double g = detail::comparator_slope(s.y, y1, leak_slope(s, cache.leak_hz), c.inv_dt);
        const double db = s.y - s.ref;
        d1 = detail::comparator_end(s.y, s.ref, g, c.dt);
        return !clock_ran_out & (s.next_hot_t > c.t1) & (s.refr_until <= c.t0) &
               detail::bridge_quiet(db, d1, th_on, th_off, cache.bridge_bound);
    }

    /// What continuous_finish() leaves of a pixel that quiet_in_interval() found quiet: the new
    /// levels, and the reference leaked to y1 - d1 (the time and counter are the caller's).
    EVSTWIN_ALWAYS_INLINE static void settle_quiet(PixelState& s, const NoiseCache& cache, double z1, double y1,
                                                   double nz1, double ny1, double d1) {
        s.ref = y1 - d1;
        s.x = cache.x;
        s.z = z1;
        s.y = y1;
        s.nz = nz1;
        s.ny = ny1;
    }

    /// step_continuous() for a block, as passes: the random words; the levels, the background
    /// clocks' spending and a branch-free test of whether anything can happen in the interval
    /// (a clock ran out, a hot pixel's event is due, refractory, the line reaches a threshold,
    /// or the bridge could cross); continuous_finish() for the few pixels where it can; the
    /// commit. The quiet pixels do what continuous_finish() would do for them (nothing but
    /// the reference's leak): the same arithmetic in the same order, so the same events.
    template <bool AllActive, bool SfOnly, class Real, class Emit>
    EVSTWIN_ALWAYS_INLINE void step_block_continuous(const BlockView& v, const Real* rate, const SampleConstants& c,
                                                     Philox4x32Key key, BlockScratch& scratch, Emit&& emit,
                                                     std::uint32_t& pixel) const {
        const std::size_t n = v.n_active;
        scratch.resize(n);
        std::uint32_t* w0 = scratch.count_word.data();
        std::uint32_t* w1 = scratch.word1.data();
        // The busy pixels' local indices and new levels, packed.
        std::uint32_t* busy_at = scratch.busy_at.data();
        double* x = scratch.x.data();
        double* z = scratch.z.data();
        double* y = scratch.y.data();
        double* nz = scratch.nz.data();
        double* ny = scratch.ny.data();
        double* cur = scratch.current.data();
        double* bvar = scratch.bridge_var.data();
        double* noise_d = scratch.noise_d.data();
        double* leak = scratch.leak.data();
        PixelState* st = v.state;
        const auto at = [&v](std::size_t j) -> std::size_t { return AllActive ? j : v.active[j]; };
        // The normals in a pass of their own (their rare slow path is a call, which would make
        // the main pass save and restore its registers around it). Not needed without shot
        // noise (the per-pixel path draws them only where the noise intensity is > 0, and so
        // must this: a pixel's rate enters only through the cache, below), and then neither
        // are the sample's words, which only they use: a noiseless pixel (an ideal one) spent
        // a fifth of its time on a Philox call per two samples. The words are counter-based
        // and the kept ones are tagged with their sample, so not drawing them changes nothing.
        double* g1s = scratch.u_noise.data();
        double* g2s = scratch.count.data();
        const bool noisy = draws_normals();
        if (noisy) {
            block_sample_words<AllActive>(v, key, scratch, w0, w1);
            // The second normal only drives the two-pole system (continuous_levels).
            const bool two_poles = !SfOnly && p.pr_pole && has_filter;
            block_sample_normals<AllActive>(v, key, scratch, w0, w1, g1s, g2s, two_poles);
        } else {
            for (std::size_t j = 0; j < n; ++j) g1s[j] = g2s[j] = 0.0;
        }
        const bool background = has_background();
        NoiseCache& cache = scratch.noise;
        if (cache.dt != c.dt) cache.photon_rate = std::numeric_limits<double>::quiet_NaN();  // refill below
        std::size_t n_busy = 0;
        BridgeBatch bridge = bridge_batch(scratch, SfOnly ? n : 0);
        for (std::size_t j = 0; j < n; ++j) {
            PixelState& s = st[at(j)];
            const double r = static_cast<double>(rate[at(j)]);
            // A new rate's numbers without the bridge's until a pixel needs them (NoiseCache::bridge_ready).
            if (r != cache.photon_rate) fill_noise_cache(cache, r, c, true);  // cache.dt is c.dt
            double zj, yj, nzj, nyj;
            continuous_levels<SfOnly>(s, cache, c, g1s[j], g2s[j], zj, yj, nzj, nyj);
            const bool clock_ran_out = background && background_spend(s, cache.bg_factor, c);
            double d1;
            bool quiet = quiet_in_interval(s, yj, cache, c, clock_ran_out, d1);
            if (!quiet && !cache.bridge_ready) {
                complete_noise_cache(cache, c);
                quiet = quiet_in_interval(s, yj, cache, c, clock_ran_out, d1);
            }
            if (quiet) {
                settle_quiet(s, cache, zj, yj, nzj, nyj, d1);
                s.t = c.t1;
                ++s.n;
            } else {
                busy_at[n_busy] = static_cast<std::uint32_t>(at(j));
                x[n_busy] = cache.x;
                cur[n_busy] = cache.current_a;
                bvar[n_busy] = cache.k.bridge_var;
                noise_d[n_busy] = cache.D;
                leak[n_busy] = cache.leak_hz;
                z[n_busy] = zj;
                y[n_busy] = yj;
                nz[n_busy] = nzj;
                ny[n_busy] = nyj;
                if (SfOnly)
                    bridge_prepare(s, v.ids[at(j)], static_cast<std::uint32_t>(n_busy), yj, cache.leak_hz,
                                   cache.k.bridge_var, c, bridge);
                ++n_busy;
            }
        }
        // Without the pole (continuous_finish never refines), the busy pixels' bridge draws are
        // decided ahead, in passes without unpredictable branches (bridge_decisions).
        BridgePre* pre = nullptr;
        if (SfOnly && n_busy > 0) {
            pre = scratch.bridge_pre.data();
            bridge_decisions(bridge, n_busy, c, key, scratch, pre);
        }
        BufferedEmit<std::remove_reference_t<Emit>> buffered{emit, pixel};
        for (std::size_t b = 0; b < n_busy; ++b) {
            PixelState& s = st[busy_at[b]];
            pixel = v.ids[busy_at[b]];
            continuous_finish(s, x[b], z[b], y[b], nz[b], ny[b], cur[b], leak[b], bvar[b], noise_d[b], c, key, pixel,
                              buffered, nullptr, pre ? pre + b : nullptr);
            if (s.next_hot_t <= c.t1) hot_events(s, c.t1, key, pixel, buffered);
            s.t = c.t1;
            ++s.n;
        }
        buffered.flush();
    }

    /// The comparator's emit(t, polarity, label) for step_block_continuous' busy pixels: the
    /// events kept in a short buffer, with the pixel they belong to, and handed to `emit` in
    /// the same order when it fills and at the end of the pass (with `pixel` set to each one's,
    /// as emit reads it). The comparator's loop then makes no call an event, so its doubles
    /// are not saved and restored around one.
    template <class Emit>
    struct BufferedEmit {
        static constexpr std::size_t N = 64;
        Emit& emit;
        std::uint32_t& pixel;
        std::size_t n = 0;
        double t[N];
        std::uint32_t px[N];
        std::uint8_t pol[N], label[N];
        EVSTWIN_ALWAYS_INLINE void operator()(double t_event, Polarity p, std::uint8_t l) {
            t[n] = t_event;
            px[n] = pixel;
            pol[n] = static_cast<std::uint8_t>(p);
            label[n] = l;
            if (++n == N) flush();
        }
        EVSTWIN_NOINLINE void flush() {
            const std::uint32_t now = pixel;
            for (std::size_t i = 0; i < n; ++i) {
                pixel = px[i];
                emit(t[i], static_cast<Polarity>(pol[i]), label[i]);
            }
            pixel = now;
            n = 0;
        }
    };

    /// bridge_decisions' inputs, filled by bridge_prepare() for each busy pixel in the pass that
    /// finds it busy (its state is at hand there): the draws' counters and arguments (ARGS
    /// numbers a pixel) of the m pixels whose line stays inside both levels, and their places
    /// among the busy ones.
    struct BridgeBatch {
        double* args;
        std::uint32_t *c0, *c1, *c2, *at;
        std::size_t m = 0;
    };
    static BridgeBatch bridge_batch(BlockScratch& scratch, std::size_t n) {
        if (scratch.bridge_args.size() < ARGS * n) scratch.bridge_args.resize(ARGS * n);
        return {scratch.bridge_args.data(), scratch.ctr0.data(), scratch.ctr1.data(), scratch.ctr2.data(),
                scratch.need_at.data(), 0};
    }
    /// bridge_decisions' test and arguments for the b-th busy pixel (global index id, new level
    /// y1, leak rate leak_hz, bridge variance bvar; the state still at c.t0): compare_bridged()'s
    /// expressions on the same values.
    EVSTWIN_ALWAYS_INLINE void bridge_prepare(const PixelState& s, std::uint32_t id, std::uint32_t b, double y1,
                                              double leak_hz, double bvar, const SampleConstants& c,
                                              BridgeBatch& bb) const {
        const double t_start = std::max(c.t0, s.refr_until);
        const double g = detail::comparator_slope(s.y, y1, leak_slope(s, leak_hz), c.inv_dt);
        const double d_start = detail::comparator_end(s.y, s.ref, g, t_start - c.t0);
        const double d_end = detail::comparator_end(s.y, s.ref, g, c.dt);
        const double th_on = s.theta_on, th_off = s.theta_off;
        const bool inside = (bvar > 0.0) & (t_start < c.t1) & detail::inside_levels(d_start, d_end, th_on, th_off);
        const double sigma2 = 4.0 * bvar * c.inv_dt;
        const double span = c.t1 - t_start;
        const std::size_t m = bb.m;
        double* a = bb.args + ARGS * m;
        a[0] = th_on - d_start;
        a[1] = th_on - d_end;
        a[2] = th_off + d_start;
        a[3] = th_off + d_end;
        a[4] = 0.25 * sigma2 * span;
        a[5] = sigma2;
        a[6] = span;
        a[7] = t_start;
        bb.c0[m] = static_cast<std::uint32_t>(s.n);
        bb.c1[m] = static_cast<std::uint32_t>(s.n >> 32);
        bb.c2[m] = id;
        bb.at[m] = b;
        bb.m = m + inside;
    }

    /// compare_bridged()'s decision, made ahead for the n busy pixels of a block whose tests
    /// and arguments bridge_prepare() put in bb (the state still at c.t0): where the line stays
    /// inside both levels, the bridge's first Philox block (one vectorised batch), its uniform
    /// and whether it fires, and at which level (detail::bridge_fires). compare_bridged then
    /// reads them instead of drawing: the long chain of a scalar Philox call, two divisions and
    /// two exps no longer stands between a pixel's state and its comparator's first
    /// unpredictable branch. The same expressions on the same state (continuous_finish's
    /// background_fire changes only the clocks), so the same decisions.
    void bridge_decisions(const BridgeBatch& bb, std::size_t n, const SampleConstants& c, Philox4x32Key key,
                          BlockScratch& scratch, BridgePre* pre) const {
        for (std::size_t b = 0; b < n; ++b) pre[b].known = false;
        const std::size_t m = bb.m;
        const std::uint32_t *c0 = bb.c0, *c1 = bb.c1, *c2 = bb.c2, *at = bb.at;
        const double* q = bb.args;
        if (m == 0) return;
        std::uint32_t *r0 = scratch.r0.data(), *r1 = scratch.r1.data(), *r2 = scratch.r2.data(), *r3 = scratch.r3.data();
        philox4x32_batch(c0, c1, c2, PURPOSE_BRIDGE, key, m, r0, r1, r2, r3);
        std::uint32_t* fired = scratch.fired.data();
        std::size_t n_fired = 0;
        for (std::size_t k = 0; k < m; ++k) {
            BridgePre& r = pre[at[k]];
            const double* a = q + ARGS * k;
            bool on = false;
            r.fires = detail::bridge_fires(uniform_open(r0[k]), a[0], a[1], a[2], a[3], a[4], on);
            r.on = on;
            r.words = {r0[k], r1[k], r2[k], r3[k]};
            r.known = true;
            r.timed = false;
            fired[n_fired] = static_cast<std::uint32_t>(k);
            n_fired += r.fires;
        }
        // The crossing times of those that fire, as compare_bridged() draws them: the normal
        // from the second word (where the ziggurat's common path takes it; else compare_bridged
        // draws as usual), the uniform from the third, the same arithmetic on the same values.
        for (std::size_t f = 0; f < n_fired; ++f) {
            const std::size_t k = fired[f];
            BridgePre& r = pre[at[k]];
            double g_time;
            if (!normal_ziggurat_common(r1[k], g_time)) continue;
            const double* a = q + ARGS * k;
            const double u0 = r.on ? a[0] : a[2];
            const double u1 = r.on ? a[1] : a[3];
            r.tc = a[7] + bridge_first_passage_sample(u0, u1, a[5], a[6], g_time, uniform_open(r2[k]));
            r.inv_first_dt = 1.0 / (r.tc - c.t0);
            r.inv_second_dt = 1.0 / (c.t1 - r.tc);
            r.timed = true;
        }
    }
    /// bridge_decisions' numbers a pixel (BlockScratch::bridge_args).
    static constexpr std::size_t ARGS = 8;

    /// Whether step_block_soa() handles this configuration: the continuous model with the exact
    /// source follower, behind the photoreceptor pole or not; or with neither (the ideal
    /// pixel, noiseless: continuous noise needs a low-pass). That one takes the SfOnly chain
    /// as it is: without a filter the sample's sf_decay and sf_ramp are 0, so its
    /// z + (y - z_before) * 0 - (z - z_before) * 0 is z, bit for bit, for every finite level
    /// (x is a log, never -0), which is what the per-pixel path's y = z gives; a level of
    /// -inf gives NaN there, which the quiet test sends to the per-pixel path. With the pole
    /// and no filter the noise is the pole's 1-D process, which the PoleSf chain does not do.
    bool has_soa_kernel() const { return continuous && !euler && (has_filter || !p.pr_pole); }

    /// step_block_continuous() for every pixel of a block held as a structure of arrays (h,
    /// loaded from st; all pixels stand at c.t0 with n > 0): the random words and normals in
    /// batches; then one vectorised pass (detail::quiet_pass) over the pixels at the block's
    /// most common photon rate, which settles the quiet ones; then, for the few left busy (a
    /// crossing is possible, a clock ran out, a hot pixel is due, refractory, or another
    /// rate), the per-pixel path on the array-of-structures state from the start of the
    /// interval (levels, clocks, continuous_finish, hot events). The same events as
    /// step_block_continuous(). Needs has_soa_kernel().
    ///
    /// held (n_held local indices, nullptr if none): pixels that sit in the arrays but are not
    /// advanced (they stand past this sample: run_pixels sampled them finely). The passes run
    /// over them too, on their stale arrays, and their results are dropped: they never take the
    /// per-pixel path, their states in st are not touched, and the arrays' copy of them is
    /// garbage until the caller takes them in again (BlockSoA::take) or stores the block
    /// without them (BlockSoA::store's held). Their random words are counter-based (a function
    /// of the pixel, the sample and the purpose), so drawing some that are dropped changes no
    /// other pixel's. Returns how many pixels took the per-pixel path.
    template <class Real, class Emit>
    std::size_t step_block_soa(BlockSoA& h, PixelState* st, const std::uint32_t* ids, std::size_t n, const Real* rate,
                               const SampleConstants& c, Philox4x32Key key, BlockScratch& scratch, Emit&& emit,
                               std::uint32_t& pixel, const std::uint32_t* held = nullptr, std::size_t n_held = 0) const;

    /// step_block_soa() for one chain of the quiet pass (QuietChain).
    template <QuietChain Chain, class Real, class Emit>
    EVSTWIN_ALWAYS_INLINE std::size_t step_block_soa_impl(BlockSoA& h, PixelState* st, const std::uint32_t* ids, std::size_t n,
                                                          const Real* rate, const SampleConstants& c, Philox4x32Key key,
                                                          BlockScratch& scratch, Emit&& emit, std::uint32_t& pixel,
                                                          const std::uint32_t* held, std::size_t n_held) const;

    /// The quiet pass's per-pixel terms at the common rate's numbers (BlockSoA::leak_g,
    /// bg_on_rate, bg_off_rate), unless the arrays hold them already: they change only with
    /// the common rate (its leak_hz and bg_factor), so most calls make them once per block.
    void prepare_quiet_terms(BlockSoA& h, std::size_t n, const NoiseCache& common, bool background) const;

    /// The pixels the quiet pass left to the bridge alone (h.busy 1): their levels in h.next()
    /// are final unless the bridge's draw fires. As compare_bridged() (the interval starts at
    /// c.t0: not refractory), whether its uniform u falls below the crossing probability
    /// p = bridge_crossing_probability(on) + bridge_crossing_probability(off); a pixel whose
    /// draw fires is handed to the per-pixel path (h.busy 2), which draws the same uniform again
    /// and places the event; the others are settled (h.busy 0). The uniforms of all the pixels
    /// that might fire come from one Philox batch; p's two exps are bracketed by
    /// exp_neg_bracket (within 1e-8), which decides wherever u lies farther than a relative 1e-6
    /// from the bracketed sum, and the library's exps are taken only for the rare pixel whose
    /// u lies that close (or whose exponents are out of the bracket's range): the same
    /// decision as u < p for every u (as detail::bridge_fires decides).
    void bridge_stage(BlockSoA& h, const std::uint32_t* ids, const std::uint32_t* flagged, std::size_t n_flagged,
                      const NoiseCache& common, const SampleConstants& c, Philox4x32Key key, BlockScratch& scratch) const;

    template <bool AllActive, class Real, class Emit>
    EVSTWIN_ALWAYS_INLINE void step_block_impl(const BlockView& v, const Real* rate, const SampleConstants& c,
                                               Philox4x32Key key, PoissonSampler& poisson, BlockScratch& scratch,
                                               Emit&& emit, std::uint32_t& pixel) const {
        const std::size_t n = v.n_active;
        scratch.resize(n);
        double* u_noise = scratch.u_noise.data();
        double* x = scratch.x.data();
        double* cur = scratch.current.data();
        double* y = scratch.y.data();
        double* leak = scratch.leak.data();
        std::uint8_t* busy = scratch.busy.data();
        PixelState* st = v.state;
        // at(j): the local index of the j-th active pixel.
        const auto at = [&v](std::size_t j) -> std::size_t { return AllActive ? j : v.active[j]; };
        const bool shot = has_background();
        if (p.photon_shot_noise) {
            std::uint32_t* count_word = scratch.count_word.data();
            std::uint32_t* w1 = scratch.word1.data();
            block_sample_words<AllActive>(v, key, scratch, count_word, w1);
            for (std::size_t j = 0; j < n; ++j) u_noise[j] = uniform_open(w1[j]);
            for (std::size_t j = 0; j < n; ++j) {
                const std::uint32_t px = v.ids[at(j)];
                const std::uint64_t sample = st[at(j)].n;
                const auto more = [&] { return CounterStream(key, px, sample, PURPOSE_POISSON_EXTRA); };
                const double mu = mean_electron_rate(static_cast<double>(rate[at(j)])) * c.dt;
                const double k = static_cast<double>(poisson.from_word(mu, count_word[j], more));
                x[j] = log_count(k) + c.log_e_over_dt;
                cur[j] = k * c.e_over_dt;
                scratch.count[j] = k;
            }
        } else {
            if (shot) {
                std::uint32_t* w0 = scratch.count_word.data();
                std::uint32_t* w1 = scratch.word1.data();
                block_sample_words<AllActive>(v, key, scratch, w0, w1);
                for (std::size_t j = 0; j < n; ++j) u_noise[j] = uniform_open(w1[j]);
            }
            for (std::size_t j = 0; j < n; ++j) {
                const double r = static_cast<double>(rate[at(j)]);
                cur[j] = ELEMENTARY_CHARGE_C * (e_per_photon * r);
                if (r != scratch.cached_rate) {  // most pixels share the background's rate
                    scratch.cached_rate = r;
                    scratch.cached_x = std::log(cur[j]);
                }
                x[j] = scratch.cached_x;
            }
        }
        double* z = scratch.z.data();
        if (p.pr_pole) {
            // The photoreceptor pole, cutoff proportional to the pixel's current (step()).
            if (scratch.pr_dt != c.dt) {
                scratch.pr_decay.assign(LOG_TABLE_SIZE, 0.0);
                scratch.pr_ramp.assign(LOG_TABLE_SIZE, 0.0);
                scratch.pr_known.assign(LOG_TABLE_SIZE, 0);
                scratch.pr_dt = c.dt;
            }
            for (std::size_t j = 0; j < n; ++j) {
                const PixelState& si = st[at(j)];
                double decay, ramp;
                const double k = p.photon_shot_noise ? scratch.count[j] : -1.0;
                const bool tabled = k >= 0.0 && k < static_cast<double>(LOG_TABLE_SIZE);
                const std::size_t slot = tabled ? static_cast<std::size_t>(k) : 0;
                if (tabled && scratch.pr_known[slot]) {
                    decay = scratch.pr_decay[slot];
                    ramp = scratch.pr_ramp[slot];
                } else {
                    const double u = pole_rate(cur[j]) * c.dt;
                    decay = std::exp(-u);
                    ramp = detail::low_pass_ramp(u);
                    if (tabled) {
                        scratch.pr_decay[slot] = decay;
                        scratch.pr_ramp[slot] = ramp;
                        scratch.pr_known[slot] = 1;
                    }
                }
                z[j] = detail::low_pass_exact(si.z, si.x, x[j], decay, ramp);
            }
        } else {
            z = x;  // no pole: the source follower's input is the log itself
        }
        // Filter, noise decision and the quiet test: branch-free arithmetic.
        for (std::size_t j = 0; j < n; ++j) {
            PixelState& si = st[at(j)];
            const double yi = detail::source_follower(has_filter, euler, si.y, si.z, z[j], c.sf_decay, c.sf_ramp);
            y[j] = yi;
            bool noise = false;
            if (shot) {
                const double f = background_factor(cur[j]) * c.dt;
                noise = (u_noise[j] < si.bg_off_hz * f) | (u_noise[j] > 1.0 - si.bg_on_hz * f);
            }
            noise |= si.next_hot_t <= c.t1;
            const double th_on = si.theta_on, th_off = si.theta_off;
            const double lg = leak_slope(si, leak_rate_hz(static_cast<double>(rate[at(j)])));
            leak[j] = lg;
            const double g = detail::comparator_slope(si.y, yi, lg, c.inv_dt);
            const double db = si.y - si.ref;
            const double d1 = detail::comparator_end(si.y, si.ref, g, c.dt);
            const bool quiet = !noise & (si.refr_until <= c.t0) & detail::inside_levels(db, d1, th_on, th_off);
            busy[j] = !quiet;
            if (quiet) si.ref = yi - d1;
        }
        for (std::size_t j = 0; j < n; ++j) {
            PixelState& si = st[at(j)];
            if (busy[j]) {
                pixel = v.ids[at(j)];
                NoisePulses pulses;
                if (shot) shot_noise(si, u_noise[j], cur[j], c, pulses);
                compare(si, y[j], 0.0, c, leak[j], pulses, emit);
                if (si.next_hot_t <= c.t1) hot_events(si, c.t1, key, pixel, emit);
            }
            si.x = x[j];
            si.z = z[j];
            si.y = y[j];
            si.t = c.t1;
            ++si.n;
        }
    }

    /// fill_noise_cache()'s first two stages for m rates into caches[0, m) (stages: room for
    /// m): the first stage of all, then the second of all, so that one rate's chain of
    /// divisions and square roots overlaps the next rates' libm calls. (Fill after fill, each
    /// chain waited for its own libm calls and the next fill's calls for the chain: one fill
    /// is longer than the processor's out-of-order window.) fill_noise_finish() then completes each, in the caller's
    /// order: the same numbers as fill_noise_cache(). sf: sf_terms(sf_rate(), c.dt), given to
    /// the caches that hold another interval's.
    void fill_noise_caches(NoiseCache* caches, NoiseIntervalStage* stages, const double* rates, std::size_t m,
                           const SampleConstants& c, const SfTerms& sf) const {
        for (std::size_t i = 0; i < m; ++i) {
            NoiseCache& k = caches[i];
            if (k.sf.T != sf.T || k.sf.b != sf.b) k.sf = sf;
            fill_noise_begin(k, stages[i], rates[i], c);
        }
        for (std::size_t i = 0; i < m; ++i) fill_noise_end(caches[i], stages[i]);
    }
};

}  // namespace evstwin

EVSTWIN_FP_STRICT_END

// The vector kernel over BlockSoA (BlockModel::step_block_soa and its stages).
#include "block_soa.hpp"
