// A width x height array of pixels, stateful and streaming: feed it chunks of photon rates
// with their sample times and it returns the events of that chunk, sorted by time.
//
// Parallel over pixels with OpenMP when compiled with it. The pixels are cut into fixed
// blocks (independent of the thread count); each block keeps its own event list, written
// sample by sample, and collect_prepare() / collect_sample() order each sample's events of
// all blocks by (t, pixel) with a stable counting sort on the integer timestamps, the samples
// in parallel, so the output is the same bit for bit whatever the thread count or chunking.
#pragma once

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <exception>
#include <functional>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "config.hpp"
#include "detail/sensor_support.hpp"
#include "event.hpp"
#include "kernels/block_model.hpp"
#include "pixel.hpp"
#include "rng.hpp"
#include "sparse_step.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

/// Where run_into() / run_pixels_into() put a call's events: called once, from one thread,
/// once the call's count n_events is known and before any event is written; returns room for
/// that many (contents not needed: every one is written, by the call's threads in parallel).
/// Sensor::run() gives a std::vector; the Python bindings a buffer they hand to NumPy, which
/// they need not fill with zeros first nor fault in on one thread.
using EventStorage = std::function<Event*(std::size_t n_events)>;

namespace detail {
/// EventStorage for a std::vector (Sensor::run's return).
inline EventStorage vector_storage(std::vector<Event>& out) {
    return [&out](std::size_t n) {
        out.reserve(n);  // allocated, not yet touched: the hint comes before the faults
        advise_huge_pages(out.data(), n * sizeof(Event));
        out.resize(n);
        return out.data();
    };
}
}  // namespace detail

/// Which code advances a Sensor's pixels (Sensor::set_kernel). Every choice gives the same
/// events bit for bit (the tests check it); they differ in speed only.
///   Auto:      the fastest that applies: the vector kernel (PixelModel::step_block_soa) on a
///              block where it pays, else the array-of-structures kernel (step_block), else
///              the per-pixel path (PixelModel::advance).
///   PerPixel:  PixelModel::advance for every pixel and sample (the scalar reference).
///   Blocks:    the array-of-structures kernel where it applies, never the vector one.
///   Vector:    the vector kernel wherever it applies, also where Auto would judge it not to pay.
/// A call with probe pixels (run()'s trace) takes the per-pixel path whatever the choice.
enum class Kernel { Auto, PerPixel, Blocks, Vector };

inline const char* kernel_name(Kernel k) {
    switch (k) {
        case Kernel::PerPixel: return "per_pixel";
        case Kernel::Blocks: return "blocks";
        case Kernel::Vector: return "vector";
        default: return "auto";
    }
}

class Sensor {
public:
    /// Pixels per block: the unit of parallel work and of event bookkeeping.
    static constexpr std::size_t BLOCK = 256;
    /// Shortest sample interval accepted [s]: below it 1/dt and the crossing times lose meaning.
    static constexpr double MIN_DT_S = 1e-12;
    /// Largest photon rate accepted [photons/s on a pixel]; with no dark current, positive
    /// rates must be at least MIN_RATE (the log needs a representable current).
    static constexpr double MAX_RATE = 1e20;
    static constexpr double MIN_RATE = 1e-30;
    /// Most engine threads accepted: far above any machine's cores, far below the counts
    /// (5000, 2^31 - 1) at which the OpenMP runtime exits or crashes.
    static constexpr int MAX_THREADS = 1024;
    /// Default cap on the events of one run / run_pixels call: 1e8 events are about 3 GB at the
    /// peak (8-byte working records with their vectors' growth slack, the 13-byte output and
    /// its labels; up to 0.8 GB more where one sample holds most of them: the counting sort's
    /// staging, 8 bytes an event of the sample being sorted, per thread),
    /// far above any real chunk (a long simulation is cut into short calls) and below a
    /// machine's memory. Exceeding it throws std::length_error while the events are produced:
    /// they are counted every EVENT_COUNT_STEP events of a block, so a call stops within
    /// max_events + num_threads * EVENT_COUNT_STEP events, whatever the thread count.
    static constexpr std::size_t DEFAULT_MAX_EVENTS = 100'000'000;
    static constexpr std::size_t EVENT_COUNT_STEP = 4096;
    /// Most pixels of one sensor: 2^26 (8192 x 8192, 70 times the largest event sensor made),
    /// whose state alone is 2^26 * STATE_BYTES_PER_PIXEL (15 GB); a larger request is refused
    /// before anything is allocated rather than failing (or swapping) minutes into the allocation.
    static constexpr std::uint64_t MAX_PIXELS = std::uint64_t{1} << 26;
    /// Bytes of state a pixel keeps between calls (the Python layer's size messages read it).
    static constexpr std::size_t STATE_BYTES_PER_PIXEL = sizeof(PixelState);
    static_assert(MAX_PIXELS <= (std::uint64_t{1} << detail::PixelDivider::INDEX_BITS),
                  "collect_sample()'s PixelDivider needs pixel indices below 2^26");
    /// Fewest pixel-updates (pixels x samples) in one call worth a parallel region: below it
    /// (~0.3 ms of work) waking the other threads and waiting at the join costs more than
    /// it saves, and on a loaded machine the join waits for a descheduled thread.
    static constexpr std::size_t PARALLEL_MIN_UPDATES = std::size_t{1} << 15;

    /// num_threads <= 0 means the OpenMP default.
    Sensor(int width, int height, const PixelParams& params, std::uint64_t seed = 0, int num_threads = 0)
        : model_(params), width_(width), height_(height), seed_(seed), key_(key_from_seed(seed)) {
        if (width < 1 || width > 65535)
            throw std::invalid_argument("width must be in [1, 65535]; got width=" + std::to_string(width));
        if (height < 1 || height > 65535)
            throw std::invalid_argument("height must be in [1, 65535]; got height=" + std::to_string(height));
        const std::uint64_t n = static_cast<std::uint64_t>(width) * static_cast<std::uint64_t>(height);
        if (n > MAX_PIXELS)
            throw std::invalid_argument("width * height must be at most " + std::to_string(MAX_PIXELS) +
                                        " pixels (8192 x 8192); got width=" + std::to_string(width) + ", height=" +
                                        std::to_string(height) + ": " + std::to_string(n) + " pixels, " +
                                        std::to_string((n * STATE_BYTES_PER_PIXEL + 500'000'000) / 1'000'000'000) +
                                        " GB of pixel state");
        set_num_threads(num_threads);
        // 176 bytes a pixel (162 MB for the IMX636 array): huge pages spare the construction
        // most of its page faults (a hint: the memory is the same either way), and the
        // sensor's threads take those left.
        state_.reserve(static_cast<std::size_t>(n));
        detail::advise_huge_pages(state_.data(), static_cast<std::size_t>(n) * sizeof(PixelState));
        detail::touch_in_parallel(state_.data(), static_cast<std::size_t>(n) * sizeof(PixelState), num_threads_);
        state_.resize(static_cast<std::size_t>(n));
        reset();
    }

    int width() const { return width_; }
    int height() const { return height_; }
    std::size_t num_pixels() const { return state_.size(); }
    std::uint64_t seed() const { return seed_; }
    const PixelParams& params() const { return model_.p; }
    /// Samples consumed since construction or the last reset.
    std::uint64_t samples_seen() const { return samples_; }
    /// Time of the last sample consumed [s] (-inf before the first).
    double last_time_s() const { return last_t_; }
    int num_threads() const { return num_threads_; }
    std::size_t max_events() const { return max_events_; }
    /// Events one call may produce before it throws std::length_error (>= 1). After that
    /// error run()'s pixels are partly advanced (run_pixels() leaves its own as they were), so
    /// run() and run_pixels() refuse to go on (std::logic_error) until reset().
    void set_max_events(std::size_t n) {
        // The sort indexes a call's events with 32 bits.
        if (n < 1 || n > 0xFFFFFFFFull)
            throw std::invalid_argument("max_events must be in [1, 4294967295]; got max_events=" + std::to_string(n));
        max_events_ = n;
    }

    /// The code that advances the pixels (Kernel; Auto by default): the same events whichever.
    Kernel kernel() const { return kernel_; }
    void set_kernel(Kernel k) {
        if (static_cast<int>(k) < 0 || static_cast<int>(k) > 3)
            throw std::invalid_argument("kernel must be auto, per_pixel, blocks or vector; got " +
                                        std::to_string(static_cast<int>(k)));
        kernel_ = k;
    }

    void set_num_threads(int num_threads) {
        if (num_threads < 0 || num_threads > MAX_THREADS)
            throw std::invalid_argument("num_threads must be in [1, " + std::to_string(MAX_THREADS) +
                                        "] (or 0/None for the default); got num_threads=" + std::to_string(num_threads));
        num_threads_ = num_threads == 0 ? std::min(default_num_threads(), MAX_THREADS) : num_threads;
    }

    /// Forget the past: the next sample is a first sample again. Mismatch stays (it is a
    /// property of the pixels for this seed).
    void reset() {
        stopped_ = false;
        // Each pixel's state is a function of its index and the seed alone, so the threads
        // change nothing; in parallel, because the IMX636 array's 921,600 pixels took 0.3 s
        // on one thread (its mismatch draws), as long as seconds of a sparse run.
        const std::int64_t npix = static_cast<std::int64_t>(state_.size());
#if EVSTWIN_HAS_OPENMP
#pragma omp parallel for num_threads(num_threads_) schedule(static) if (npix >= std::int64_t{1} << 16)
#endif
        for (std::int64_t j = 0; j < npix; ++j) {
            const std::size_t i = static_cast<std::size_t>(j);
            state_[i] = PixelState{};
            model_.init_pixel(state_[i], key_, static_cast<std::uint32_t>(i), hot_map_.empty() ? -1.0 : hot_map_[i],
                              hot_chain_map_.empty() ? std::uint16_t{0} : hot_chain_map_[i]);
        }
        block_synced_.assign((state_.size() + BLOCK - 1) / BLOCK, 0);
        settle_until_.assign(state_.size(), -std::numeric_limits<double>::infinity());
        settling_.clear();
        sparse_end_ = -std::numeric_limits<double>::infinity();
        sparse_mark_.clear();  // an error part-way may have left marks
        sparse_column_.clear();
        samples_ = 0;
        last_t_ = -std::numeric_limits<double>::infinity();
    }

    /// An explicit hot-pixel map: the hot rate of every pixel (row-major, photons play no part;
    /// 0 = not hot), in place of the random draw of hot_pixel_fraction; empty = back to the
    /// draw. Resets the sensor (the map is a property of the pixels, as the mismatch is).
    void set_hot_pixel_rates(const std::vector<double>& rates_hz) {
        if (!rates_hz.empty() && rates_hz.size() != state_.size())
            throw std::invalid_argument("hot_pixel_rates_hz must have one rate per pixel (" + std::to_string(height_) + " x " +
                                        std::to_string(width_) + " = " + std::to_string(state_.size()) + "); got " +
                                        std::to_string(rates_hz.size()) + " values");
        for (std::size_t i = 0; i < rates_hz.size(); ++i)
            if (!(rates_hz[i] >= 0.0 && rates_hz[i] <= 1e6))
                throw std::invalid_argument("hot_pixel_rates_hz must be in [0, 1e6] Hz; got hot_pixel_rates_hz[" +
                                            std::to_string(i / width_) + ", " + std::to_string(i % width_) + "]=" +
                                            detail::fmt(rates_hz[i]));
        hot_map_ = rates_hz;
        reset();
    }

    /// Most pixels with a hot-pixel chain of their own (HotPixelState::chain is 16 bits).
    static constexpr std::size_t MAX_HOT_PIXEL_CHAINS = 65535;

    /// Hot pixels with a telegraph and polarity chain of their own: pixels[k] (row-major
    /// index) fires by chains[k] in place of the params' hot_pixel_duty, _burst_s, _on_share
    /// and _alternation, whenever it is hot (by the draw or the explicit map). Empty = every
    /// pixel back to the params' chain. Resets the sensor (a property of the pixels). A pixel
    /// without one of its own draws exactly what it drew before.
    void set_hot_pixel_chains(const std::vector<std::uint32_t>& pixels, const std::vector<HotPixelChain>& chains) {
        if (pixels.size() != chains.size())
            throw std::invalid_argument("hot pixel chains: pixels and chains must have the same length; got " +
                                        std::to_string(pixels.size()) + " pixels and " + std::to_string(chains.size()) +
                                        " chains");
        if (pixels.size() > MAX_HOT_PIXEL_CHAINS)
            throw std::invalid_argument("hot pixel chains: at most " + std::to_string(MAX_HOT_PIXEL_CHAINS) +
                                        " pixels may have a chain of their own; got " + std::to_string(pixels.size()));
        std::vector<std::uint16_t> chain_map(pixels.empty() ? 0 : state_.size(), 0);
        for (std::size_t k = 0; k < pixels.size(); ++k) {
            const std::string name = "hot_pixel_chains[" + std::to_string(k) + "].";
            if (pixels[k] >= state_.size())
                throw std::invalid_argument(name + "pixel must be a row-major index below " +
                                            std::to_string(state_.size()) + "; got " + std::to_string(pixels[k]));
            if (chain_map[pixels[k]] != 0)
                throw std::invalid_argument(name + "pixel " + std::to_string(pixels[k]) + " (x, y) = (" +
                                            std::to_string(pixels[k] % width_) + ", " +
                                            std::to_string(pixels[k] / width_) + ") has a chain already");
            validate_hot_chain(chains[k], name);
            chain_map[pixels[k]] = static_cast<std::uint16_t>(k + 1);
        }
        model_.hot_chains.resize(1, model_.hot_chains.front());
        for (const HotPixelChain& c : chains) model_.hot_chains.emplace_back(c);
        hot_chain_map_ = std::move(chain_map);
        reset();
    }

    /// Each pixel's hot rate [Hz] (0 = not hot), row-major: the draw or the explicit map.
    std::vector<double> hot_pixel_rates() const {
        std::vector<double> out(state_.size());
        for (std::size_t i = 0; i < state_.size(); ++i) out[i] = state_[i].hot ? state_[i].hot->rate_hz : 0.0;
        return out;
    }

    /// Why each event of the last run / run_pixels call fired (EventLabel), in its order.
    const std::vector<std::uint8_t>& last_labels() const { return calls_.labels; }

    /// Per-pixel thresholds (mismatch included), row-major.
    std::vector<double> thresholds(bool on) const {
        std::vector<double> out(state_.size());
        for (std::size_t i = 0; i < state_.size(); ++i) out[i] = on ? state_[i].theta_on : state_[i].theta_off;
        return out;
    }

    /// Consume n_samples samples. photon_rate is C-ordered (n_samples, height, width) in
    /// photons/s arriving on each pixel; t_s the sample times in seconds, strictly increasing
    /// and after the last sample of the previous run. Returns the events, sorted by t.
    ///
    /// probe_pixels (row-major indices) and trace, when given, record the pixel's internal
    /// signals at every sample: trace is resized to n_samples * probe_pixels.size().
    ///
    /// Throws std::invalid_argument, before any state changes, on a bad input.
    ///
    /// sample_stride is the distance between two samples' frames in elements: the default
    /// (0 = width * height) for a dense array; 0 samples of one static frame are given as
    /// `static_frame = true`, which repeats the first frame for every sample time.
    template <class Real>
    std::vector<Event> run(const Real* photon_rate, const double* t_s, std::size_t n_samples,
                           const std::vector<std::uint32_t>* probe_pixels = nullptr,
                           std::vector<TraceSample>* trace = nullptr, bool static_frame = false) {
        std::vector<Event> events;
        run_into(detail::vector_storage(events), photon_rate, t_s, n_samples, probe_pixels, trace, static_frame);
        return events;
    }

    /// run() with the events written into `storage` (called once with their number, unless
    /// there are none); returns that number.
    template <class Real>
    std::size_t run_into(const EventStorage& storage, const Real* photon_rate, const double* t_s,
                         std::size_t n_samples, const std::vector<std::uint32_t>* probe_pixels = nullptr,
                         std::vector<TraceSample>* trace = nullptr, bool static_frame = false);

    /// Advance only the listed pixels through their own sample times: the sparse second
    /// input for the pixels near a fast source, which need finer sampling than the rest.
    /// photon_rate is C-ordered (n_samples, n_pixels): column j belongs to pixels[j]
    /// (row-major indices, no repeats). t_s must start after every listed pixel's last
    /// sample. A later run() skips, for these pixels, the samples at or before the time they
    /// have reached; so sub-sampling a pixel and then running the whole array gives that
    /// pixel the union of the two time grids, with its own sample counter keying its random
    /// numbers. Throws std::invalid_argument, before any state changes, on a bad input.
    /// `static_rates = true`: photon_rate is one row of n_pixels rates, the same at every
    /// sample (as run()'s static_frame).
    template <class Real>
    std::vector<Event> run_pixels(const std::uint32_t* pixels, std::size_t n_pixels, const Real* photon_rate,
                                  const double* t_s, std::size_t n_samples, bool static_rates = false) {
        std::vector<Event> events;
        run_pixels_into(detail::vector_storage(events), pixels, n_pixels, photon_rate, t_s, n_samples, static_rates);
        return events;
    }

    /// run_pixels() with the events written into `storage` (as run_into); returns their number.
    template <class Real>
    std::size_t run_pixels_into(const EventStorage& storage, const std::uint32_t* pixels, std::size_t n_pixels,
                                const Real* photon_rate, const double* t_s, std::size_t n_samples,
                                bool static_rates = false) {
        check_usable();
        return run_pixels_with(calls_, storage, pixels, n_pixels, photon_rate, t_s, n_samples, static_rates);
    }

    /// Advance every pixel through one step of a sparse scene (SparseStep) with time steps
    /// per pixel: in each group of the step's samples, the pixels a source's light touches
    /// take the fine samples, those whose levels still relax after a source left them
    /// (settle_time_s(), carried from step to step) and those whose long steps would be cut
    /// finer than the base samples where their noise may cross (PixelModel::
    /// long_steps_cut_below) take the base samples, and every other pixel one long exact step;
    /// then all reach the step's end (or those the step names: SparseStep::reach_all). The noise, background
    /// clocks, leak, hot pixels and refractory keep their laws over any step (the continuous
    /// model; the documentation's noise model page), so the statistics are those of a dense
    /// run at the fine rate. Needs noise_model = continuous and lowpass = exact. Returns the
    /// step's events sorted by (t, pixel); last_labels() holds theirs. Throws
    /// std::invalid_argument, before any pixel moves, on a bad input.
    std::vector<Event> run_sparse(const SparseStep& step) {
        std::vector<Event> events;
        run_sparse_into(detail::vector_storage(events), step);
        return events;
    }

    /// run_sparse() with the events written into `storage` (as run_into); returns their number.
    std::size_t run_sparse_into(const EventStorage& storage, const SparseStep& step);

    /// Pixel-updates of the last run_sparse() call: long steps, fine and base samples, summed
    /// over the pixels (a dense call's is pixels x samples).
    std::uint64_t last_pixel_updates() const { return last_pixel_updates_; }

    /// How long a pixel's levels keep relaxing after its light stops changing [s], at a
    /// constant photon rate: five time constants of the slower of the source follower and,
    /// when on, the photoreceptor pole at the pixel's mean current (its cutoff scales with
    /// the current, eq. 9: a dim pixel's pole is slow). Until then, the comparator's line
    /// between two samples far apart would misplace the crossings the relaxation makes.
    double settle_time_s(double photon_rate) const {
        const double sf = model_.sf_rate();
        const double pole = model_.pole_rate(ELEMENTARY_CHARGE_C * model_.mean_electron_rate(photon_rate));
        const double slowest = p_min_positive(sf, pole);
        return slowest > 0.0 ? SETTLE_TIME_CONSTANTS / slowest : 0.0;
    }

private:
    struct CallBuffers;  // one call's working memory (defined below, after RawEvent)
    /// run()'s vector kernel (Kernel::Auto) takes a block where at least this many quarters of its pixels
    /// advance at a sample (the others stand past it, sampled finely by run_pixels): it runs
    /// over the whole block, so below that the array-of-structures kernel over the pixels
    /// that advance costs less. Speed only: either gives the same events.
    static constexpr std::size_t SOA_MIN_ACTIVE_QUARTERS = 2;
    /// run() (Kernel::Auto) leaves the vector kernel for the rest of a call in a block where more than this
    /// many quarters of its pixels took the per-pixel path at a sample (an event-heavy scene):
    /// then copying them out of the arrays and back costs more than the vector pass saves.
    /// Measured with bench/engine_driver.cpp (continuous 130 CUTOFF_HZ, one thread, user+sys):
    /// a quarter, against the half it was, is as fast at 20-40 Hz (0.40 / 0.81-0.83 /
    /// 0.91-0.94 s against 0.40 / 0.81-0.82 / 0.94-0.95 s) and faster at 45-60 Hz (1.00-1.01
    /// against 1.06 s at 45 Hz, 1.04-1.06 against 1.15-1.16 s at 50 Hz); an eighth loses at
    /// 20-30 Hz (0.45 / 0.84-0.85 s). Speed only: either kernel gives the same events.
    static constexpr std::size_t SOA_MAX_BUSY_QUARTERS = 1;
    /// How many pixels ahead run()'s first pass over a block's states asks for their cache lines.
    /// Speed only.
    static constexpr std::size_t STATE_PREFETCH_AHEAD = 8;
    /// run_sparse() samples a pixel at the base rate throughout where refine_and_compare would
    /// cut its long steps into pieces shorter than SPARSE_PIECE_COST base intervals
    /// (PixelModel::long_steps_cut_below): a piece of the finest level the bisection reaches
    /// costs about two of its nodes (a midpoint's draw or a piece's comparator, scalar), each
    /// about four quiet samples of the vector kernel. geo-stare's dark IMX636 pixel (pole at
    /// 18 /s, 100 Hz base rate) passes the test, and its long steps cost a little less than its
    /// base samples (bench/bench_long_steps.py). Speed only: either way the statistics are the
    /// same.
    static constexpr double SPARSE_PIECE_COST = 8.0;
    /// run_sparse() runs a step densely (every pixel at the base samples, the lit ones at
    /// the fine ones) where more than this share of the pixels takes the base samples anyway.
    /// Speed only.
    static constexpr double SPARSE_DENSE_SHARE = 0.25;
    /// Time constants a pixel's levels take to settle (settle_time_s): e^-5 = 0.7 % of a step is left.
    static constexpr double SETTLE_TIME_CONSTANTS = 5.0;
    /// The smaller of two rates, ignoring a zero (a stage that is off).
    static double p_min_positive(double a, double b) {
        if (a <= 0.0) return b;
        if (b <= 0.0) return a;
        return std::min(a, b);
    }
    /// run_sparse()'s part for one group of a step: the runs it makes (see run_sparse_into).
    struct SparseRun {
        std::vector<std::uint32_t> pixels;
        std::vector<double> rate;   ///< (times.size(), pixels.size()), C-ordered
        std::vector<double> times;
    };

    /// The state after a call that stopped part-way (max_events, out of memory) is neither
    /// the old one nor the new one: refuse to build on it.
    void check_usable() const {
        if (stopped_)
            throw std::logic_error("the previous run call stopped part-way (an error inside it, e.g. max_events), "
                                   "which may have left the pixels half advanced: reset() the sensor before running it again");
    }

    /// for_each_block, marking the sensor stopped when a block throws (in run(), the pixels
    /// of the other blocks have advanced). A block does not start once the call is over max_events.
    template <class Check, class Fn, class Prepare, class Part>
    void guarded_for_each_block(CallBuffers& calls, std::size_t nblocks, std::size_t updates, Check& check, Fn&& fn,
                                Prepare&& prepare, Part&& part) {
        try {
            for_each_block(
                nblocks, updates, check,
                [&](std::size_t b, PoissonSampler& poisson, BlockModel::BlockScratch& scratch) {
                    if (calls.events_in_call.load(std::memory_order_relaxed) > max_events_) throw_max_events();
                    fn(b, poisson, scratch);
                    note_events(calls, calls.block_events[b].size() % EVENT_COUNT_STEP);  // the rest of this block's count
                },
                prepare, part);
        } catch (...) {
            stopped_ = true;
            throw;
        }
    }

    /// A call's photon rates checked in parts of RATE_CHECK_PART values, spread over the call's
    /// threads at the start of its parallel region (for_each_block). A memory-bound pass, but
    /// serial it was 5 % of mcreynolds' run_pixels calls on 2 threads, and the reference load
    /// (250 samples of 346 x 260 float rates a call, 90 MB) runs 3.6 % faster on 2 threads
    /// without it (measured when it was removed; git history); in the region it needs no second fork and join. first_bad(): the first bad index in the
    /// whole array (the parts' first, in order), `total` if none, whatever the threads.
    static constexpr std::size_t RATE_CHECK_PART = std::size_t{1} << 16;
    /// for_each_block's input check where the caller checks its input itself, inside the blocks
    /// (run_pixels_into): nothing to do before them.
    struct NoCheck {
        std::size_t total;
        std::size_t parts() const { return 0; }
        void check_part(std::size_t) {}
        std::size_t first_bad() const { return total; }
    };
    template <class Real>
    struct RateCheck {
        RateCheck(const Sensor& sensor_, const Real* rate_, std::size_t total_)
            : sensor(sensor_), rate(rate_), total(total_), part_bad((total_ + RATE_CHECK_PART - 1) / RATE_CHECK_PART) {}
        std::size_t parts() const { return part_bad.size(); }
        /// Part i's first bad index, or its end if none. Never throws.
        void check_part(std::size_t i) {
            const std::size_t lo = i * RATE_CHECK_PART, n = std::min(total, lo + RATE_CHECK_PART) - lo;
            part_bad[i] = lo + sensor.first_bad_rate(rate + lo, n);
        }
        std::size_t first_bad() const {
            for (std::size_t i = 0; i < part_bad.size(); ++i)
                if (part_bad[i] < std::min(total, (i + 1) * RATE_CHECK_PART)) return part_bad[i];
            return total;
        }
        const Sensor& sensor;
        const Real* rate;
        std::size_t total;
        std::vector<std::size_t> part_bad;
    };

    /// fn(block, poisson, scratch) for every block, in parallel when OpenMP is on, with
    /// per-thread sampler caches and scratch (neither changes results). Blocks are fixed, so
    /// which thread runs one does not matter. Then, once every block is done and unless one
    /// failed, prepare() (one thread) returns a number of parts, and part(i, sort) runs for
    /// each of them, again spread over the threads (collect_sample()'s per-sample sort: the
    /// samples' events go to disjoint places of the output). An exception in a block, in
    /// prepare or in a part is rethrown here, after the parallel region (it must not escape
    /// it). One parallel region per call, and none for less than PARALLEL_MIN_UPDATES of
    /// work; blocks and parts are handed out dynamically so a thread that shares its core
    /// with another process takes fewer of them. First of all the region runs the input's
    /// check (check.check_part(i) for its parts, spread over the threads); if it finds a bad
    /// value no block runs, nothing is prepared, and the caller throws (check.first_bad()).
    template <class Check, class Fn, class Prepare, class Part>
    void for_each_block(std::size_t nblocks, std::size_t updates, Check& check, Fn&& fn, Prepare&& prepare,
                        Part&& part);

    /// A block's working record of an event, 8 bytes (it was 16: the event-heavy load writes,
    /// counts and copies hundreds of MB of them a call): the low 32 bits of its microsecond
    /// (floor_us) and its pixel, label and polarity in one word. The rest of the time is its
    /// sample's: an event lies within 2^31 us (35 min) of its sample's end, so event_time()
    /// recovers it from that end; emit() checks, and a block with an event that does not (a
    /// sample interval of over half an hour) keeps its events' full times beside the records
    /// from then on (keep_full_time; the same output either way).
    struct RawEvent {
        std::uint32_t t_lo;  ///< the event's microsecond, modulo 2^32
        std::uint32_t code;  ///< pixel << 4 | label << 1 | polarity (event_code)
        RawEvent() = default;
        /// For emplace_back: the fields stored straight into the list. push_back of a braced
        /// record built it on the stack and copied it with one wider load, which the processor
        /// cannot forward from the small stores (a stall on every event). Forced inline: in the
        /// kernels that emit (large functions past GCC's inlining budget) GCC 12 called it, two
        /// stores behind a call on every event (68 call sites in engine_driver at -O3).
        EVSTWIN_ALWAYS_INLINE RawEvent(std::uint32_t t_lo_, std::uint32_t code_) : t_lo(t_lo_), code(code_) {}
        std::uint32_t pixel() const { return code >> 4; }
        std::uint8_t label() const { return static_cast<std::uint8_t>((code >> 1) & 7u); }
        std::uint8_t p() const { return static_cast<std::uint8_t>(code & 1u); }
    };
    static_assert(sizeof(RawEvent) == 8, "RawEvent is two 32-bit words");
    static_assert(LABEL_HOT_PIXEL < 8, "RawEvent::code keeps the label in 3 bits");
    static_assert(MAX_PIXELS <= (std::uint64_t{1} << 28), "RawEvent::code keeps the pixel in 28 bits");
    /// One call's working memory (run(), run_pixels()): the listed pixels' working states,
    /// each block's events, the call's labels and its event count. The sensor's own serve
    /// its calls; run_sparse()'s threads each keep one more, for the calls each makes alone
    /// on its own pixels at the same time as the others.
    struct CallBuffers {
        /// run_pixels_into()'s working copies of the listed pixels' states, in the list's
        /// order (kept from call to call for its memory: as large as the longest list so
        /// far, at most state_'s size).
        std::vector<PixelState> pixel_states;
        std::vector<std::vector<RawEvent>> block_events;
        std::vector<std::vector<std::int64_t>> block_full_t;  ///< each block's full event times, if kept (RawEvent)
        std::vector<std::vector<std::uint32_t>> block_sample_ends;  ///< each block's event count after each sample
        std::size_t blocks_in_call = 0, samples_in_call = 0;
        std::vector<std::uint8_t> labels;
        std::atomic<std::size_t> events_in_call{0};
    };
    static std::uint32_t event_code(std::uint32_t pixel, Polarity pol, std::uint8_t label) {
        return pixel << 4 | static_cast<std::uint32_t>(label) << 1 | (static_cast<std::uint32_t>(pol) & 1u);
    }
    /// The microsecond whose low 32 bits are t_lo nearest end_us: the event's own where it lies
    /// within [end_us - 2^31, end_us + 2^31), which emit() ensures (else the full time is kept).
    static std::int64_t event_time(std::int64_t end_us, std::uint32_t t_lo) {
        const std::uint32_t d = t_lo - static_cast<std::uint32_t>(end_us);  // modulo 2^32
        return end_us + static_cast<std::int64_t>(d) - (d >= 0x80000000u ? std::int64_t{1} << 32 : 0);
    }
    /// Whether event_time(end_us, t_us's low bits) gives t_us back. The difference is taken
    /// modulo 2^64, so it cannot overflow: two of floor_us' times (run() takes |t| < 9.2e12 s)
    /// differ by less than 2^64 - 2^31, so only a true difference within 2^31 passes.
    static bool near_sample_end(std::int64_t t_us, std::int64_t end_us) {
        return static_cast<std::uint64_t>(t_us) - static_cast<std::uint64_t>(end_us) + 0x80000000ull < 0x100000000ull;
    }
    /// emit()'s rare path, out of line: the block's full event times (full_t), kept once an
    /// event lies too far from its sample's end for event_time(): the earlier events' times are
    /// filled in from theirs (end_us(j): sample j's end in microseconds; ends: the block's counts
    /// after each sample before `sample`, the current one), then t_us is added for the newest.
    template <class EndUs>
    EVSTWIN_NOINLINE static void keep_full_time(std::vector<std::int64_t>& full_t, const std::vector<RawEvent>& out,
                                                const std::uint32_t* ends, std::size_t sample, const EndUs& end_us,
                                                std::int64_t t_us) {
        std::size_t j = 0;
        for (std::size_t e = full_t.size(); e + 1 < out.size(); ++e) {
            while (j < sample && e >= ends[j]) ++j;
            full_t.push_back(event_time(end_us(j), out[e].t_lo));
        }
        full_t.push_back(t_us);
    }

    /// The records out[first..] (with their full times, where the block keeps them) stably
    /// into pixel order: run_block's sample where some pixels took the kernel and others the
    /// per-pixel path.
    static void stable_sort_by_pixel(std::vector<RawEvent>& out, std::vector<std::int64_t>& full_t, std::size_t first) {
        const auto by_pixel = [](const RawEvent& a, const RawEvent& b) { return a.pixel() < b.pixel(); };
        if (full_t.empty()) {
            std::stable_sort(out.begin() + static_cast<std::ptrdiff_t>(first), out.end(), by_pixel);
            return;
        }
        std::vector<std::size_t> order(out.size() - first);
        for (std::size_t i = 0; i < order.size(); ++i) order[i] = first + i;
        std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return by_pixel(out[a], out[b]); });
        const std::vector<RawEvent> records(out.begin() + static_cast<std::ptrdiff_t>(first), out.end());
        const std::vector<std::int64_t> times(full_t.begin() + static_cast<std::ptrdiff_t>(first), full_t.end());
        for (std::size_t i = 0; i < order.size(); ++i) {
            out[first + i] = records[order[i] - first];
            full_t[first + i] = times[order[i] - first];
        }
    }

    /// A block's event list, taken out of its call's block_events while the block runs and put
    /// back after it (also when it throws). The vectors' headers lie side by side there,
    /// and blocks are handed out in order, so two threads appending to neighbouring blocks'
    /// lists wrote the same cache line (the end pointer) on every event: false sharing that
    /// cost the event-heavy load ~15 % more CPU an event on 2 threads than on 1.
    struct TakenEvents {
        TakenEvents(std::vector<RawEvent>& home, std::vector<std::int64_t>& full_t_home)
            : home_(home), full_t_home_(full_t_home) {
            out.swap(home_);
            full_t.swap(full_t_home_);
        }
        ~TakenEvents() {
            out.swap(home_);
            full_t.swap(full_t_home_);
        }
        TakenEvents(const TakenEvents&) = delete;
        TakenEvents& operator=(const TakenEvents&) = delete;
        std::vector<RawEvent> out;
        std::vector<std::int64_t> full_t;  ///< empty, or every event's time (keep_full_time)

    private:
        std::vector<RawEvent>& home_;
        std::vector<std::int64_t>& full_t_home_;
    };

    /// run_block's and run_pixel_block's emit(t, polarity, label): the event's record onto the
    /// block's list (pixel: the one the model is stepping), kept with its full time once one
    /// lies too far from its sample's end for the record's low bits (keep_full_time), and the
    /// call's count checked as the list grows. start_sample(k) before sample k's steps.
    template <class SampleEndUs>
    struct BlockEmit {
        Sensor& sensor;
        CallBuffers& calls;
        TakenEvents& taken;
        const std::uint32_t* ends;
        const std::uint32_t& pixel;
        SampleEndUs sample_end_us;  ///< sample j's end in microseconds
        std::size_t sample = 0;
        std::int64_t end_us = 0;                  ///< the current sample's end
        bool full_times = !taken.full_t.empty();  ///< the block keeps its events' full times

        void start_sample(std::size_t k) {
            sample = k;
            end_us = sample_end_us(k);
        }
        void operator()(double t, Polarity pol, std::uint8_t label) {
            std::vector<RawEvent>& out = taken.out;
            const std::int64_t t_us = floor_us(t);
            out.emplace_back(static_cast<std::uint32_t>(t_us), event_code(pixel, pol, label));
            if (full_times || !near_sample_end(t_us, end_us)) {
                keep_full_time(taken.full_t, out, ends, sample, sample_end_us, t_us);
                full_times = true;
            }
            if (out.size() % EVENT_COUNT_STEP == 0) sensor.note_events(calls, EVENT_COUNT_STEP);  // memory bound, checked as it grows
        }
    };

    /// The event's time in integer microseconds, floored as a sensor's timestamp counter
    /// does (it reads the microseconds elapsed: an event 0.9 us into a tick bears that tick;
    /// rounded, a timestamp would be 0.5 us later than the sensor's on average). A time
    /// within a nanosecond below a whole microsecond counts as that microsecond: a crossing
    /// meant to fall on one (a leak's period, k dt) lands there only within the rounding its
    /// arithmetic accumulates (1.05e-12 s for the 2nd period of a 4 Hz leak at 1 kHz), not
    /// on the tick before. The truncation is exact, and so is the remainder x - i for any
    /// |x| < 2^63 (at and above 2^52, x is an integer and the remainder 0). Monotone.
    static std::int64_t floor_us(double t_s) {
        const double x = t_s * 1e6;
        const std::int64_t i = static_cast<std::int64_t>(x);  // toward zero
        const double frac = x - static_cast<double>(i);       // in (-1, 1)
        return i - static_cast<std::int64_t>(frac < -US_TOLERANCE) + static_cast<std::int64_t>(frac >= 1.0 - US_TOLERANCE);
    }
    /// floor_us()'s tolerance, in microseconds (a nanosecond).
    static constexpr double US_TOLERANCE = 1e-3;

    /// Clear the blocks' event lists (keeping their memory) and size their per-sample marks.
    static void start_call(CallBuffers& calls, std::size_t nblocks, std::size_t n_samples) {
        calls.blocks_in_call = nblocks;
        calls.samples_in_call = n_samples;
        if (calls.block_events.size() < nblocks) {
            calls.block_events.resize(nblocks);
            calls.block_full_t.resize(nblocks);
            calls.block_sample_ends.resize(nblocks);
        }
        for (std::size_t b = 0; b < nblocks; ++b) {
            calls.block_events[b].clear();
            calls.block_full_t[b].clear();
            calls.block_sample_ends[b].assign(n_samples, 0);
        }
        calls.events_in_call.store(0, std::memory_order_relaxed);
    }

    void check_times(const double* t_s, std::size_t n) const {
        for (std::size_t k = 0; k < n; ++k) {
            if (!std::isfinite(t_s[k]))
                throw std::invalid_argument("t_s must be finite; got t_s[" + std::to_string(k) + "]=" + detail::fmt(t_s[k]));
            const double prev = k == 0 ? last_t_ : t_s[k - 1];
            if (!(t_s[k] > prev)) {
                if (k == 0)
                    throw std::invalid_argument("t_s must continue after the previous run's last sample (" +
                                                detail::fmt(last_t_) + " s); got t_s[0]=" + detail::fmt(t_s[0]));
                throw std::invalid_argument("t_s must be strictly increasing; got t_s[" + std::to_string(k - 1) +
                                            "]=" + detail::fmt(prev) + " and t_s[" + std::to_string(k) +
                                            "]=" + detail::fmt(t_s[k]));
            }
            if (!(std::fabs(t_s[k]) < 9.2e12))
                throw std::invalid_argument("t_s must lie within +-9.2e12 s (int64 microseconds); got t_s[" +
                                            std::to_string(k) + "]=" + detail::fmt(t_s[k]));
            if (k > 0 || samples_ > 0) check_dt(t_s[k] - prev, k);
        }
    }

    /// The limits that depend on the sample interval dt (k names the sample in messages).
    void check_dt(double dt, std::size_t k) const {
        if (!(dt >= MIN_DT_S))
            throw std::invalid_argument("sample intervals must be >= 1e-12 s; got dt=" + detail::fmt(dt) + " s at t_s[" +
                                        std::to_string(k) + "]");
        if (model_.has_filter && model_.euler && 2.0 * PI * *model_.p.cutoff_hz * dt > 2.0)
            throw std::invalid_argument("lowpass='euler' (eq. 7) is unstable when 2 pi cutoff_hz dt > 2; got cutoff_hz=" +
                                        detail::fmt(*model_.p.cutoff_hz) + " and dt=" + detail::fmt(dt) + " s at t_s[" +
                                        std::to_string(k) + "]: use lowpass='exact' or shorter samples");
        // The largest eq. 12 rate is R_n (at no current) or F R_n (at I_max) when F > 1. The
        // continuous model draws the background exactly, whatever dt.
        if (!model_.continuous &&
            std::max(1.0, model_.p.shot_noise_factor) * std::max(model_.bg_on_hz, model_.bg_off_hz) * dt > 0.5)
            throw std::invalid_argument(
                "max(1, shot_noise_factor) * shot_noise_rate_hz * dt must be <= 0.5 (eq. 13-15 draw at most one "
                "event per sample); got shot_noise_rate_hz=" + detail::fmt(model_.p.shot_noise_rate_hz) +
                ", shot_noise_factor=" + detail::fmt(model_.p.shot_noise_factor) + " and dt=" + detail::fmt(dt) + " s");
    }

    /// Index of the first rate that is NaN, infinite, negative, or zero without dark
    /// current; `total` if none. A vectorisable pass answers "is anything bad?" first.
    template <class Real>
    std::size_t first_bad_rate(const Real* rate, std::size_t total_size) const {
        const std::int64_t total = static_cast<std::int64_t>(total_size);
        // Compared in the input's own type, counted rather than OR-ed, so the loop vectorises.
        // The largest Real not above MAX_RATE: float(1e20) rounds up to 1.00000002e20, which
        // the double limit refuses, so a float32 input must not slip past it.
        Real top = static_cast<Real>(MAX_RATE);
        if (static_cast<double>(top) > MAX_RATE) top = std::nextafter(top, Real(0));
        const Real lowest = model_.dark_mean_e_per_s <= 0.0 ? static_cast<Real>(MIN_RATE) : Real(0);
        std::int64_t n_bad = 0;
        // One thread's part of the call's check (RateCheck): the parts are spread over the
        // call's threads inside its one parallel region.
#if EVSTWIN_HAS_OPENMP
#pragma omp simd reduction(+ : n_bad)
#endif
        for (std::int64_t i = 0; i < total; ++i) {
            const Real v = rate[i];
            // Fails for NaN, negatives, +inf, and zero where there is no dark current.
            n_bad += static_cast<std::int64_t>(!((v >= lowest) & (v <= top)));
        }
        if (n_bad == 0) return total_size;
        for (std::size_t i = 0; i < total_size; ++i) {
            const Real v = rate[i];
            if (!(v >= lowest && v <= top)) return i;
        }
        return total_size;
    }

    [[noreturn]] static void throw_bad_rate(const std::string& where, double v) {
        if (v >= 0.0 && v < MIN_RATE)
            throw std::invalid_argument(
                "photon_rate must be >= 1e-30 photons/s where there is no dark current (dark_model='none' or "
                "dark_rate_e_per_s=0): the log photoreceptor needs a positive current; got " + where + "=" + detail::fmt(v));
        throw std::invalid_argument("photon_rate must be finite, >= 0 and <= 1e20 photons/s; got " + where + "=" +
                                    detail::fmt(v));
    }

    std::vector<SampleConstants> sample_constants(const double* t_s, std::size_t n) const {
        std::vector<SampleConstants> out(n);
        double prev = last_t_;
        for (std::size_t k = 0; k < n; ++k) {
            out[k] = model_.constants(prev, t_s[k]);
            prev = t_s[k];
        }
        return out;
    }

    template <class Real>
    void run_block(std::size_t b, const Real* rate, std::size_t sample_stride, std::size_t n_samples,
                   const std::vector<SampleConstants>& consts,
                   PoissonSampler& poisson, BlockModel::BlockScratch& scratch, const std::int32_t* probe_slot,
                   std::size_t n_probe, TraceSample* trace);

    /// run_pixels_into() on the given working memory (`calls`): the sensor's own, or one of
    /// run_sparse()'s threads', whose calls run alone on that thread (a call made inside a
    /// parallel region runs its blocks on the calling thread only) on pixels no other thread
    /// touches. The call's labels are left in calls.labels. It does not check_usable(): its
    /// callers have.
    template <class Real>
    std::size_t run_pixels_with(CallBuffers& calls, const EventStorage& storage, const std::uint32_t* pixels,
                                std::size_t n_pixels, const Real* photon_rate, const double* t_s,
                                std::size_t n_samples, bool static_rates);

    /// The sparse counterpart of run_block: entries [lo, hi) of a pixel list, each with its
    /// own column of rates; sample k's row at rate + k * sample_stride (0: one row for all).
    template <class Real>
    void run_pixel_block(CallBuffers& calls, std::size_t b, const std::uint32_t* pixels, std::size_t n_pixels, const Real* rate,
                         std::size_t sample_stride, const double* t_s, std::size_t n_samples,
                         const std::vector<SampleConstants>& consts, PoissonSampler& poisson,
                         BlockModel::BlockScratch& scratch);

    /// Count n more events of this call; throw once the call passes max_events_ (whichever
    /// thread gets there first; the exception is rethrown after the parallel region).
    void note_events(CallBuffers& calls, std::size_t n) {
        const std::size_t now = calls.events_in_call.fetch_add(n, std::memory_order_relaxed) + n;
        if (now > max_events_) throw_max_events();
    }

    /// One message whichever thread or check gets there first: the outcome (an error exactly
    /// when the call's events exceed max_events) and its text do not depend on the threads.
    [[noreturn]] void throw_max_events() const {
        throw std::length_error("a run call produced more than max_events=" + std::to_string(max_events_) +
                                " events (about 30 bytes each while collected); use shorter chunks, or raise "
                                "max_events if memory allows");
    }

    /// A record with its full time, for collect_sample()'s comparison sort.
    struct TimedEvent {
        std::int64_t t_us;
        RawEvent e;
    };

    /// collect_sample()'s working memory for one thread: the counting sort's slots, or a sample's
    /// events for the comparison sort.
    struct SortScratch {
        std::vector<std::uint32_t> slots;
        std::vector<TimedEvent> sample_events;
        std::vector<std::uint32_t> coarse;  ///< counting_sort_in_interval's coarse pass: where each span goes
        std::vector<RawEvent> staged;       ///< the records in coarse order (t_lo: the offset from lo)
    };

    /// What collect_prepare() lays out for collect_sample(): the output, the blocks that made
    /// events, and where each sample's events start in the output.
    struct CollectPlan {
        CallBuffers* calls = nullptr;  ///< the call's blocks and labels
        const EventStorage* storage = nullptr;
        Event* events = nullptr;  ///< storage's room for the call's `total` events
        std::size_t total = 0;
        std::vector<std::uint32_t> busy;  ///< the blocks with events, in order
        std::vector<std::size_t> base;    ///< sample k's events go to [base[k], base[k + 1])
        bool pixel_ordered = true;
        detail::PixelDivider row{1};      ///< pixel -> (x, y) without a division
        /// The call's sample times: the ends from which event_time() recovers each sample's
        /// events' times.
        const double* t_s = nullptr;
        /// run()'s (not run_pixels'): sample k's events lie in [t_s[k - 1], t_s[k]] (t_before
        /// before the first), so its microseconds lie between those times' (floor_us is
        /// monotone), which collect_sample() takes as the counting sort's range without a pass
        /// to find it.
        bool intervals_known = false;
        double t_before = 0.0;
    };

    /// The call's events in output order: by time in microseconds; within one microsecond,
    /// events of an earlier sample interval first (a microsecond can straddle two run() calls,
    /// and this is the order that concatenating their outputs gives), then by pixel; ties (one
    /// pixel's events in one microsecond of one interval) in the order they were made.
    ///
    /// Every event of sample k lies in [t0, t1] of its interval, so after flooring to
    /// microseconds none comes after an event of sample k + 1: the order is sample by sample,
    /// and within a sample by (t_us, pixel). So each sample's place in the output is known
    /// from the blocks' counts alone (collect_prepare), and the samples are sorted
    /// independently, in parallel (collect_sample). The blocks write each sample's events in
    /// pixel order when `pixel_ordered` (run(): each block's pixels in increasing order, every
    /// pixel's events together), so a stable counting sort on t_us over the blocks taken in
    /// order gives that order in two passes, without comparisons; otherwise (run_pixels' list
    /// in any order), or where a sample's microseconds span far more slots than it has events,
    /// a stable sort by (t_us, pixel) of that sample's events does.
    ///
    /// Returns the number of samples to sort (0 when there are no events).
    std::size_t collect_prepare(CollectPlan& plan, bool pixel_ordered);

    /// Block b's events of sample k in the order it made them, as fn(time, record) until fn
    /// returns false; returns whether it never did. time: from_low(the record's t_lo) where the
    /// block keeps only the low bits, else from_full(the block's full_t of it).
    template <class FromLow, class FromFull, class Fn>
    static bool for_each_event_in_sample(const CallBuffers& calls, std::uint32_t b, std::size_t k, FromLow&& from_low,
                                         FromFull&& from_full, Fn&& fn);

    /// for_each_event_in_sample with each event's offset d = t_us - lo from a microsecond lo
    /// less than 2^31 before the sample's end, where t_us - lo lies in [0, 2^31); any other
    /// event gives some d >= 2^31. Where the block keeps only the low bits, an event lies
    /// within 2^31 us of its sample's end (emit()), so the difference of the low bits is the
    /// offset: 32-bit arithmetic in the counting sort's loops.
    template <class Fn>
    static bool for_each_offset_in_sample(const CallBuffers& calls, std::uint32_t b, std::size_t k, std::int64_t lo, Fn&& fn);

    /// for_each_event_in_sample with each event's full time (event_time from the sample's end
    /// end_us, or the block's full_t).
    template <class Fn>
    static bool for_each_in_sample(const CallBuffers& calls, std::uint32_t b, std::size_t k, std::int64_t end_us, Fn&& fn);

    /// counting_sort_in_interval() stages a sample's records by coarse spans of time from this
    /// many events (their 13-byte records fill far more than a core's first-level cache).
    static constexpr std::size_t STAGED_MIN_EVENTS = 2048;

    /// Event{t_us, x, y, p} into *dst. On a little-endian machine as two overlapping 8-byte
    /// stores (t; then bytes 5 to 12: t's top three bytes, x, y, p) rather than four: the
    /// counting sort scatters the records over a sample's part of the output, where each
    /// store of a 13-byte record to a line not yet in the cache held up the loop. Exactly the
    /// record's 13 bytes are written, the same bytes.
    static void put_event(Event* dst, std::int64_t t_us, std::uint16_t x, std::uint16_t y, std::uint8_t p) {
#if defined(__BYTE_ORDER__) && __BYTE_ORDER__ == __ORDER_LITTLE_ENDIAN__
        static_assert(offsetof(Event, x) == 8 && offsetof(Event, y) == 10 && offsetof(Event, p) == 12,
                      "put_event writes Event's packed little-endian layout");
        const std::uint64_t t = static_cast<std::uint64_t>(t_us);
        const std::uint64_t tail = t >> 40 | std::uint64_t{x} << 24 | std::uint64_t{y} << 40 | std::uint64_t{p} << 56;
        unsigned char* out = reinterpret_cast<unsigned char*>(dst);
        std::memcpy(out, &t, sizeof t);
        std::memcpy(out + 5, &tail, sizeof tail);
#else
        *dst = Event{t_us, x, y, p};
#endif
    }

    /// Sample k's events of all blocks, sorted, into their place of the output (see
    /// collect_prepare). Touches only that place: samples may run concurrently.
    void collect_sample(CollectPlan& plan, std::size_t k, SortScratch& sort);

    /// collect_sample()'s counting sort over the microseconds of sample k's interval (plan.t_s, intervals_known),
    /// without the pass that finds the events' own range: one pass counts, one puts (a sample
    /// of STAGED_MIN_EVENTS or more: one stages the records by coarse spans of time first, and
    /// the put goes over them in that order). Returns
    /// false, having written nothing, where that range is unknown (no previous time), too wide
    /// for the events (as collect_sample() decides on the events' own range), or an event lies
    /// outside it (none does: the guard keeps the slots in bounds); collect_sample() then sorts
    /// as before. Either way the same order: by t_us, then block and place in the block.
    template <class Put>
    bool counting_sort_in_interval(const CollectPlan& plan, std::size_t k, std::int64_t end_us, SortScratch& sort,
                                   Put put) const;

    /// Keep the blocks' memory for the next call, unless a flood made it large.
    static void collect_finish(CallBuffers& calls);

    BlockModel model_;
    int width_, height_;
    std::uint64_t seed_;
    Philox4x32Key key_;
    int num_threads_ = 1;
    std::vector<PixelState> state_;
    std::uint64_t samples_ = 0;
    double last_t_ = -std::numeric_limits<double>::infinity();
    /// Per block: nonzero when every pixel of it stands at last_t_ after at least one sample
    /// (its last run() call ended with a kernel step that skipped nobody) and nothing has moved
    /// one since (run_pixels() clears its pixels' blocks; reset() all). run() then starts the
    /// block's first sample without reading its states to check that (20 MB for the DAVIS346
    /// array). A call that throws part-way leaves the flags of the blocks it ran set, but
    /// also stops the sensor until reset().
    std::vector<std::uint8_t> block_synced_;
    /// The calls' working memory (run_sparse()'s threads': sparse_calls_).
    CallBuffers calls_;
    std::vector<double> hot_map_;
    std::vector<std::uint16_t> hot_chain_map_;  ///< per pixel, its hot_chains index (empty: all 0)
    std::size_t max_events_ = DEFAULT_MAX_EVENTS;
    Kernel kernel_ = Kernel::Auto;
    /// run_sparse(): per pixel, the time until which its levels relax after a source's light
    /// left it (settle_time_s), and the pixels with such a time still ahead.
    std::vector<double> settle_until_;
    std::vector<std::uint32_t> settling_;
    /// The end of the last run_sparse() step (-inf before one): where its waiting pixels'
    /// light began, so the next step's start.
    double sparse_end_ = -std::numeric_limits<double>::infinity();
    /// run_sparse()'s per-pixel scratch, kept from call to call (its marks all 0 and its
    /// columns all -1 between calls): the IMX636 array's 4.6 MB need not be zeroed each step.
    std::vector<std::uint8_t> sparse_mark_;
    std::vector<std::int32_t> sparse_column_;
    /// run_sparse()'s judgement of which pixels take the base samples throughout, per pixel,
    /// with the static light and base interval it was made for.
    std::vector<std::uint8_t> sparse_busy_;
    std::vector<double> sparse_static_;
    double sparse_busy_dt_ = 0.0;
    std::uint64_t last_pixel_updates_ = 0;
    /// run_sparse()'s threads' working memory, one each (made as a step first needs them).
    std::vector<std::unique_ptr<CallBuffers>> sparse_calls_;
    /// Set by a call that stopped part-way; an atomic since run_sparse()'s threads' calls may
    /// set it at the same time.
    std::atomic<bool> stopped_{false};
};

}  // namespace evstwin
EVSTWIN_FP_STRICT_END

// The definitions of Sensor's calls, block scheduler and event collection.
#include "detail/sensor_collect.hpp"
#include "detail/sensor_run.hpp"
#include "detail/sensor_sparse.hpp"
