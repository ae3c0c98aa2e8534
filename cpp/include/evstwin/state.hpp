// What a pixel keeps between samples (PixelState), the numbers of one sample interval
// (SampleConstants) and of one photon rate (NoiseCache), and a probe's trace record.
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
#include <tuple>
#include <type_traits>
#include <vector>

#include "config.hpp"
#include "noise.hpp"
#include "params.hpp"
#include "rng.hpp"

EVSTWIN_FP_STRICT_BEGIN

namespace evstwin {

/// A hot pixel's own clocks (PixelModel::hot_events): its exponential rate, next event
/// and next active <-> quiet switch, last event, event and switch counters, polarity, whether
/// its telegraph is active, and its chain. Few pixels are hot, so PixelState holds these
/// apart (HotBox): 48 bytes fewer in every pixel's record, 44 MB on an IMX636.
struct HotPixelState {
    double rate_hz = 0.0;                                         ///< its exponential rate [Hz]
    double event_t = std::numeric_limits<double>::infinity();    ///< next event (inf while quiet)
    double switch_t = std::numeric_limits<double>::infinity();   ///< next active <-> quiet switch
    double last_t = -std::numeric_limits<double>::infinity();    ///< last event (for the dead time)
    std::uint64_t count = 0, switches = 0;                        ///< the Philox counters of both
    std::uint8_t pol = 0, active = 1;
    std::uint16_t chain = 0;  ///< PixelModel::hot_chains index: 0 the params', else the pixel's own
};

/// Every field of a HotPixelState, in declaration order (as state_fields below).
template <class Hot>
auto hot_state_fields(Hot& h) {
    static_assert(std::is_same<std::remove_const_t<Hot>, HotPixelState>::value, "hot_state_fields takes a HotPixelState");
    auto& [rate_hz, event_t, switch_t, last_t, count, switches, pol, active, chain] = h;
    return std::tie(rate_hz, event_t, switch_t, last_t, count, switches, pol, active, chain);
}

/// A HotPixelState that only hot pixels have: empty (one null pointer) for every other pixel,
/// and copied with the record that holds it, so PixelState stays a value.
class HotBox {
public:
    HotBox() = default;
    HotBox(const HotBox& o) : p_(o.p_ ? std::make_unique<HotPixelState>(*o.p_) : nullptr) {}
    HotBox(HotBox&&) noexcept = default;
    HotBox& operator=(const HotBox& o) {
        // A box that holds one already keeps it: copying states back and forth between
        // buffers (run_pixels) allocates nothing once both hold one.
        if (!o.p_)
            p_.reset();
        else if (p_)
            *p_ = *o.p_;
        else
            p_ = std::make_unique<HotPixelState>(*o.p_);
        return *this;
    }
    HotBox& operator=(HotBox&&) noexcept = default;
    ~HotBox() = default;

    explicit operator bool() const { return p_ != nullptr; }
    HotPixelState& operator*() const { return *p_; }
    HotPixelState* operator->() const { return p_.get(); }
    /// A fresh HotPixelState (the one held before, if any, is dropped).
    HotPixelState& emplace() {
        p_ = std::make_unique<HotPixelState>();
        return *p_;
    }
    void reset() { p_.reset(); }

private:
    std::unique_ptr<HotPixelState> p_;
};

/// The state of one pixel between samples: one record a pixel, read whole at every sample
/// (sensor_run.hpp prefetches it line by line), so every byte in it costs memory traffic.
struct PixelState {
    double x = 0.0;            ///< log-photoreceptor input at the last sample, ln(I / 1 A)
    double z = 0.0;            ///< input of the source follower (photoreceptor pole output)
    double y = 0.0;            ///< source-follower output: the level the comparator sees
    double ref = 0.0;          ///< comparator reference (level at the last event, leaking)
    double refr_until = -std::numeric_limits<double>::infinity();  ///< refractory end [s]
    double theta_on = 0.0;     ///< this pixel's thresholds, mismatch included
    double theta_off = 0.0;
    double t = -std::numeric_limits<double>::infinity();  ///< time of the last sample [s]
    std::uint64_t n = 0;                          ///< samples consumed: the RNG's sample counter
    std::uint64_t spare_words = 0;                ///< Philox words 2-3 of the last even sample
    std::uint64_t spare_sample = ~std::uint64_t{0};  ///< the odd sample they belong to
    // Continuous noise model: the noise parts of z and y (z holds the noise-free pole output,
    // y the whole level, so the noise-free source-follower output is y - ny).
    double nz = 0.0, ny = 0.0;
    // Where the last event left the pixel, to tell why the next one fires: the level set as
    // the reference then (before any leak) and the noise part of the signal then.
    double level_at_event = 0.0, noise_at_event = 0.0;
    // This pixel's background: its leak rate's log-normal factor (mean 1; the rate itself
    // follows the light, PixelModel::leak_rate_hz) and eq. 12 rates with their spread.
    double leak_spread = 1.0, bg_on_hz = 0.0, bg_off_hz = 0.0;
    /// A hot pixel's next event or switch, whichever comes first (inf: not hot, or quiet for
    /// good): the one hot-pixel number every sample reads; the rest is in `hot`.
    double next_hot_t = std::numeric_limits<double>::infinity();
    HotBox hot;  ///< a hot pixel's clocks (empty: not hot)
    /// Continuous model: what is left of the exponential budgets of eq. 12's ON and OFF clocks.
    double bg_clock_on = 0.0, bg_clock_off = 0.0;
};

/// Every field of a PixelState, in declaration order, as a tuple of references: the one list
/// of them (tests compare states field by field through it). Made by a structured binding,
/// which needs exactly as many names as the struct has fields: a field added to PixelState
/// and not here fails to compile.
template <class State>
auto state_fields(State& s) {
    static_assert(std::is_same<std::remove_const_t<State>, PixelState>::value, "state_fields takes a PixelState");
    auto& [x, z, y, ref, refr_until, theta_on, theta_off, t, n, spare_words, spare_sample, nz, ny, level_at_event,
           noise_at_event, leak_spread, bg_on_hz, bg_off_hz, next_hot_t, hot, bg_clock_on, bg_clock_off] = s;
    return std::tie(x, z, y, ref, refr_until, theta_on, theta_off, t, n, spare_words, spare_sample, nz, ny,
                    level_at_event, noise_at_event, leak_spread, bg_on_hz, bg_off_hz, next_hot_t, hot, bg_clock_on,
                    bg_clock_off);
}

/// CounterStream(key, pixel, sample, purpose) whose first block of four words a Philox batch
/// has already computed (`first`; nullptr: none, the stream computes it as usual). The same
/// words in the same order: the first four from `first`, the rest from the stream, which
/// recomputes its first block once to reach the second (only the ziggurat's rare slow path
/// asks for a fifth word).
class PrefilledStream {
public:
    PrefilledStream(Philox4x32Key key, std::uint32_t pixel, std::uint64_t sample, std::uint32_t purpose,
                    const Philox4x32Counter* first)
        : rest_(key, pixel, sample, purpose), used_(first ? 0 : 5) {
        if (first) first_ = *first;
    }
    std::uint32_t word() {
        if (used_ < 4) return first_[used_++];
        if (used_ == 4) {  // past the given block: the stream's first block is the same four words
            for (int i = 0; i < 4; ++i) (void)rest_.word();
            used_ = 5;
        }
        return rest_.word();
    }
    /// As CounterStream::uniform(): the next word in (0, 1).
    double uniform() { return uniform_open(word()); }

private:
    CounterStream rest_;
    Philox4x32Counter first_{};
    int used_;  ///< words taken from first_ (0-4); 5: the rest come from rest_
};

/// compare_bridged()'s draw for one pixel made ahead by the block kernel (bridge_decisions):
/// the first block of the bridge's random words and whether (and at which level) it fires.
struct BridgePre {
    Philox4x32Counter words{};
    /// compare_bridged()'s test of whether the bridge applies (a bridge variance, time left after
    /// the refractory period, the line inside both levels there and at the end), made ahead:
    /// false, no draw; true, `fires` and `on` are the draw's decision.
    bool known = false;
    bool fires = false, on = false;
    /// Where it fires and its normal took the ziggurat's common path (one word): the crossing
    /// time tc that compare_bridged() would draw from the same words, and 1 / (tc - c.t0),
    /// 1 / (c.t1 - tc), its two pieces' inverse lengths (the same expressions). Drawn in a
    /// batch, so these divisions and the square root overlap across pixels instead of standing
    /// in each event's chain.
    bool timed = false;
    double tc = 0.0, inv_first_dt = 0.0, inv_second_dt = 0.0;
};

/// Per-sample constants shared by every pixel: computed once per sample, not per pixel.
struct SampleConstants {
    double t0 = 0.0, t1 = 0.0, dt = 0.0;
    double inv_dt = 0.0;       ///< 1 / dt: a multiply in the hot loop instead of a divide
    double e_over_dt = 0;      ///< e / dt: the current of one electron per interval [A]
    double log_e_over_dt = 0;  ///< ln(e / dt)
    double sf_decay = 0;       ///< exact: exp(-2 pi fc dt); euler: 1 - 2 pi fc dt
    double sf_ramp = 0;        ///< exact: (1 - exp(-u)) / u, u = 2 pi fc dt; euler: 2 pi fc dt
};

/// What the continuous model computes for one (photon rate, interval): the same for every
/// pixel at the background's rate, so one per thread is kept and reused while they repeat.
struct NoiseCache {
    double photon_rate = -1.0, dt = -1.0;
    double current_a = 0, x = 0, a = 0, D = 0;
    double pole_decay = 0, pole_ramp = 0;
    NoiseCoeffs k;
    SfTerms sf;  ///< the source follower's part of k for this dt (sf_terms)
    double bg_factor = 0;  ///< eq. 12's illumination factor at current_a (background_factor)
    double leak_hz = 0;    ///< the leak rate at this photon rate before a pixel's spread (leak_rate_hz)
    /// For the block kernel's quiet test: a pixel whose line stays inside both thresholds over
    /// the whole interval cannot cross by the bridge when (theta - d0)(theta - d1) exceeds this
    /// for both levels. Then both exponents of bridge_crossing_probability exceed 24, so
    /// p_on + p_off < 2 exp(-24) = 7.6e-11, below the smallest uniform there is, 2^-33 =
    /// 1.16e-10: the draw could not fire. 48 (1 + 1e-8) times the middle variance over the
    /// interval (the margin covers the rounding of the exponent's division).
    /// While !bridge_ready: the same bound for twice k.q_yy, above it (bridge_var_bounded()).
    double bridge_bound = 0;
    /// false: k.bridge_var is not computed yet, and bridge_bound is the upper bound from
    /// k.q_yy (fill_noise_cache(..., lazy_bridge = true)); complete_noise_cache() computes it.
    /// A pixel found quiet with the upper bound is quiet with the exact one: the same
    /// decision, and the bridge's terms (an exp, two expm1 and five divisions) only for the
    /// pixels that might cross.
    bool bridge_ready = true;
    /// When lazy fills pay (fill_noise_cache): +1 for a lazy fill no pixel had to complete and
    /// for an eager one, -3 for a completion; lazy while >= 0. Over long intervals most pixels
    /// need the bridge anyway, and then the split costs more than it saves (the bridge's terms
    /// wait for the quiet test). Speed only: either way gives the same numbers.
    int lazy_credit = 0;
};

/// What one pixel-sample update reports for a probe (diagnostic trace).
struct TraceSample {
    double current_a;    ///< photodiode current over the interval [A]
    double log_current;  ///< x = ln(I / 1 A)
    double filtered;     ///< y, the comparator input
    double reference;    ///< the comparator reference at the end of the interval
};

/// Eq. 12's background events of one sample interval, in time order, as the comparator takes
/// them (PixelModel::compare): each resets the reference where the pixel is not refractory. The
/// sampled model draws at most one an interval; the continuous model's clocks fire as often as
/// they run out, so a long interval keeps every event of a busy clock (MAX: a clock of 100 Hz
/// over 0.2 s fires ~20 times; the 65th of one interval and later are dropped).
struct NoisePulses {
    static constexpr int MAX = 64;
    int n = 0, next = 0;
    double t[MAX];
    std::uint8_t pol[MAX];
    /// Whether a pulse not yet taken lies at or before t1 (the comparator's interval end).
    bool due(double t1) const { return next < n && t[next] <= t1; }
    double time() const { return t[next]; }
    int polarity() const { return pol[next]; }
    void take() { ++next; }
    void add(double t_s, int polarity) {
        if (n == MAX) return;
        // Insertion in time order (a few, most often one): ties keep the order they came in.
        int i = n++;
        for (; i > 0 && t[i - 1] > t_s; --i) {
            t[i] = t[i - 1];
            pol[i] = pol[i - 1];
        }
        t[i] = t_s;
        pol[i] = static_cast<std::uint8_t>(polarity);
    }
};

}  // namespace evstwin

EVSTWIN_FP_STRICT_END
