// Issue 15 asks for the pixel state "in single precision where the physics allows it (log-domain
// levels, filters) and double where it does not (time)". The engine kept double everywhere so
// its events match an independent reference bit for bit. This study measures what single
// precision would buy and what it would cost, so that choice can be made on numbers:
//
//   1. speed of the quiet pass: the engine's own detail::quiet_pass (double, the reference
//      load's chain: source follower alone, noise and background on) on a real BlockSoA of one
//      256-pixel block, warmed up by the engine's step_block_soa, against study variants of the
//      same arithmetic on float arrays (levels relative to the block's base level), at AVX-512
//      and AVX2 (the engine's dispatch; the study variants compiled with the same target
//      attributes). ns per pixel-update, min over repetitions (the machine is shared).
//   2. speed of the normals: the engine's Philox batch and ziggurat batch against a study
//      float ziggurat (16 lanes at AVX-512) on the same words, and the engine's use of the
//      words (one Philox call per pixel per two samples; the reference load uses one word of
//      each two) against one call per four samples (every word used: a change of the word
//      allocation, not of precision).
//   3. fidelity: the quiet pass's level arithmetic for 4096 pixels of the reference load
//      (thresholds with 3 % mismatch, the 10 Hz source follower's exact update and noise at
//      2e6 photons/s and 1 kHz, the leak, eq. 12's clocks), in double (the engine's), in float
//      on absolute levels and in float on levels re-based to the block's level, same normals:
//      level error after 10^4 samples (comparator off), how often the quiet/busy verdict of
//      one sample differs (lockstep: each from the same double state), and the events of a
//      study comparator run freely in each precision (background light, and a flickering one).
//
// Study variants (study:: namespace) live only here: the engine's headers are included read-only
// and nothing here is used by the engine. The study comparator of part 3 is simpler than the
// engine's (an event where the sample's end level lies past a threshold, the reference then set
// to the level; no bridge, no refractory period): the same rule for every precision, so what
// differs between them is the arithmetic's precision alone.
//
//   g++ -std=c++17 -O3 -DNDEBUG -Icpp/include bench/precision_study.cpp -o /tmp/precision_study
//   /tmp/precision_study            # all three parts, ~1 min; or: /tmp/precision_study speed|fidelity
//
// No -march: like the engine, the vector code comes from target attributes and run-time dispatch.
#include <evstwin/evstwin.hpp>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <vector>

EVSTWIN_FP_STRICT_BEGIN  // the study variants obey the engine's rule: no contracted multiply-adds

namespace {

using evstwin::BlockSoA;
using evstwin::NoiseCache;
using evstwin::PixelModel;
using evstwin::PixelParams;
using evstwin::PixelState;
using evstwin::QuietChain;
using evstwin::SampleConstants;
using evstwin::SimdLevel;

constexpr std::size_t BLOCK = 256;        // the engine's pixels per block (Sensor::BLOCK)
constexpr double BACKGROUND = 2e6;        // bench_engine.py's background, photons/s per pixel
constexpr double DT = 1e-3;               // the reference load's 1 kHz

/// The reference load's pixel (bench_engine.py: PixelParams(threshold_sigma=0.03), 10 Hz source
/// follower, no photoreceptor pole, every noise source on).
PixelParams reference_pixel() {
    PixelParams p;
    p.threshold_sigma = 0.03;
    return p;
}

/// Minimum over `reps` repetitions of the seconds one call of f takes (each repetition times
/// `calls` calls): the least disturbed figure on a shared machine.
template <class F>
double min_seconds_per_call(F&& f, int calls, int reps) {
    double best = std::numeric_limits<double>::infinity();
    for (int r = 0; r < reps; ++r) {
        const auto start = std::chrono::steady_clock::now();
        for (int i = 0; i < calls; ++i) f();
        const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        best = std::min(best, s / calls);
    }
    return best;
}

/// Keeps a value alive so the compiler cannot drop the work that made it.
template <class T>
void keep(const T& v) {
    asm volatile("" : : "g"(&v) : "memory");
}

// ---------------------------------------------------------------------------------------------
// Part 1: the quiet pass.

/// One block of the reference load as the engine holds it mid-run: states from init_state at
/// the background, then `warm` samples of the engine's own step_block_soa (events, clocks and
/// leak phases as they stand in a run).
struct EngineBlock {
    PixelModel model{reference_pixel()};
    evstwin::Philox4x32Key key = evstwin::key_from_seed(1);
    std::vector<PixelState> st = std::vector<PixelState>(BLOCK);
    std::vector<std::uint32_t> ids = std::vector<std::uint32_t>(BLOCK);
    std::vector<float> rate = std::vector<float>(BLOCK, static_cast<float>(BACKGROUND));
    PixelModel::BlockScratch scratch;
    std::uint32_t pixel = 0;
    std::size_t events = 0, k = 0;

    explicit EngineBlock(int warm) {
        for (std::size_t j = 0; j < BLOCK; ++j) {
            ids[j] = static_cast<std::uint32_t>(j);
            model.init_pixel(st[j], key, ids[j]);
            model.init_state(st[j], BACKGROUND, 0.0, key, ids[j]);
        }
        scratch.resize(BLOCK);
        scratch.soa.load(st.data(), BLOCK);
        for (int i = 0; i < warm; ++i) step();
    }
    /// One sample of the engine's block kernel (what Sensor::run does per block and sample).
    std::size_t step() {
        const SampleConstants c = model.constants(static_cast<double>(k) * DT, static_cast<double>(k + 1) * DT);
        ++k;
        auto emit = [this](double, evstwin::Polarity, std::uint8_t) { ++events; };
        return model.step_block_soa(scratch.soa, st.data(), ids.data(), BLOCK, rate.data(), c, key, scratch, emit,
                                    pixel);
    }
};

/// The QuietPass step_block_soa_impl builds for the reference load's chain (SfOnly), with the
/// sample's normals in g1 (drawn as the engine draws them): the same fields from the same
/// sources, copied here because the engine builds it inside the kernel.
struct EnginePass {
    evstwin::QuietPass q{};
    NoiseCache common;
    SampleConstants c;
    std::vector<double> g1 = std::vector<double>(BLOCK), g2 = std::vector<double>(BLOCK);

    explicit EnginePass(EngineBlock& b) {
        BlockSoA& h = b.scratch.soa;
        c = b.model.constants(static_cast<double>(b.k) * DT, static_cast<double>(b.k + 1) * DT);
        b.model.noise_cache_for(common, BACKGROUND, c);
        for (std::size_t j = 0; j < BLOCK; ++j) {  // the sample's normals, as the engine draws them
            const evstwin::Philox4x32Counter w =
                evstwin::philox4x32({static_cast<std::uint32_t>(h.count(j) >> 1), 0u, b.ids[j], evstwin::PURPOSE_SAMPLE}, b.key);
            evstwin::CounterStream more(b.key, b.ids[j], h.count(j), evstwin::PURPOSE_NORMAL);
            g1[j] = evstwin::normal_ziggurat(w[0], [&more] { return more.word(); });
            g2[j] = 0.0;
        }
        b.model.prepare_quiet_terms(h, BLOCK, common, b.model.has_background());
        q.now = &h.now();
        q.next = &h.next();
        q.refr_until = h.refr_until.data(); q.next_hot_t = h.next_hot_t.data();
        q.theta_on = h.theta_on.data(); q.theta_off = h.theta_off.data();
        q.leak_g = h.leak_g.data(); q.bg_on_rate = h.bg_on_rate.data(); q.bg_off_rate = h.bg_off_rate.data();
        q.g1 = g1.data(); q.g2 = g2.data(); q.busy = h.busy.data(); q.count = BLOCK;
        q.rate = common.photon_rate;
        q.cx = common.x; q.pole_decay = common.pole_decay; q.pole_ramp = common.pole_ramp;
        q.phi_zz = common.k.phi_zz; q.phi_yz = common.k.phi_yz; q.phi_yy = common.k.phi_yy;
        q.l_zz = common.k.l_zz; q.l_yz = common.k.l_yz; q.l_yy = common.k.l_yy;
        q.bridge_bound = common.bridge_bound;
        q.sf_decay = c.sf_decay; q.sf_ramp = c.sf_ramp; q.dt = c.dt; q.inv_dt = c.inv_dt; q.t0 = c.t0; q.t1 = c.t1;
        q.bridge_stage = common.k.bridge_var > 0.0;
        h.sf_only = true;
    }
};

}  // namespace

namespace study {

/// Study variant: the quiet pass's arrays for one block in single precision. Levels (z, y, ref)
/// are stored relative to the block's base level (a double kept outside the pass: here the
/// common rate's log level when the block was loaded), so the float's 24 bits resolve the
/// difference from the base, not the ~-31 of ln(I / 1 A) (whose float spacing is 1.9e-6, a
/// tenth of the leak's 2e-5 a sample). ny is the noise part, small already. Clock and Time:
/// float, or double to keep eq. 12's clocks and the times as the engine has them.
template <class Clock, class Time>
struct FloatBlock {
    struct Levels {
        std::vector<float> z, y, ny, ref;
        std::vector<Clock> on, off;
    };
    Levels buf[2];
    std::vector<float> th_on, th_off, leak_g, g1;
    std::vector<Clock> bon, boff;
    /// The times the pass compares. As float: offsets from the run call's start, rounded so a
    /// float comparison can only err towards "busy" (refr_until rounded up, next_hot_t down;
    /// the pass's t0 down, t1 up), which sends a pixel to the exact per-pixel path, never
    /// settles one wrongly: the verdicts stay exact, only a few more pixels may be busy.
    std::vector<Time> refr, hot;
    std::vector<std::uint32_t> busy;  ///< 32-bit verdicts: the lane width of the float levels
    double base = 0.0, t_call = 0.0;
};

template <class Clock, class Time>
struct FloatPass {
    const typename FloatBlock<Clock, Time>::Levels* now;
    typename FloatBlock<Clock, Time>::Levels* next;
    const Time *refr, *hot;
    const float *th_on, *th_off, *leak_g, *g1;
    const Clock *bon, *boff;
    std::uint32_t* busy;
    std::size_t count;
    float rate, x, sf_decay, sf_ramp, phi_yy, l_yy, bridge_bound, dt, inv_dt;
    Clock clock_dt;
    Time t0, t1;
    bool bridge_stage;
};

/// A float rounded towards -inf (down) or +inf (up) from a double.
inline float round_down(double v) {
    float f = static_cast<float>(v);
    if (static_cast<double>(f) > v) f = std::nextafter(f, -std::numeric_limits<float>::infinity());
    return f;
}
inline float round_up(double v) {
    float f = static_cast<float>(v);
    if (static_cast<double>(f) < v) f = std::nextafter(f, std::numeric_limits<float>::infinity());
    return f;
}

/// The block's arrays from the engine's (the same pixels, the same state), and the pass's
/// numbers from the engine's QuietPass.
template <class Clock, class Time>
void load(FloatBlock<Clock, Time>& f, const EnginePass& e, FloatPass<Clock, Time>& q) {
    const BlockSoA::Levels& s = *e.q.now;
    f.base = e.q.cx;
    f.t_call = 0.0;
    for (auto& l : f.buf) {
        for (auto* v : {&l.z, &l.y, &l.ny, &l.ref}) v->resize(BLOCK);
        l.on.resize(BLOCK);
        l.off.resize(BLOCK);
    }
    for (auto* v : {&f.th_on, &f.th_off, &f.leak_g, &f.g1}) v->resize(BLOCK);
    f.bon.resize(BLOCK); f.boff.resize(BLOCK); f.refr.resize(BLOCK); f.hot.resize(BLOCK); f.busy.resize(BLOCK);
    for (std::size_t j = 0; j < BLOCK; ++j) {
        f.buf[0].z[j] = static_cast<float>(s.z[j] - f.base);
        f.buf[0].y[j] = static_cast<float>(s.y[j] - f.base);
        f.buf[0].ref[j] = static_cast<float>(s.ref[j] - f.base);
        f.buf[0].ny[j] = static_cast<float>(s.ny[j]);
        f.buf[0].on[j] = static_cast<Clock>(s.clock_on[j]);
        f.buf[0].off[j] = static_cast<Clock>(s.clock_off[j]);
        f.th_on[j] = static_cast<float>(e.q.theta_on[j]);
        f.th_off[j] = static_cast<float>(e.q.theta_off[j]);
        f.leak_g[j] = static_cast<float>(e.q.leak_g[j]);
        f.bon[j] = static_cast<Clock>(e.q.bg_on_rate[j]);
        f.boff[j] = static_cast<Clock>(e.q.bg_off_rate[j]);
        f.g1[j] = static_cast<float>(e.q.g1[j]);
        if constexpr (std::is_same_v<Time, float>) {
            f.refr[j] = round_up(e.q.refr_until[j] - f.t_call);
            f.hot[j] = round_down(e.q.next_hot_t[j] - f.t_call);
        } else {
            f.refr[j] = e.q.refr_until[j];
            f.hot[j] = e.q.next_hot_t[j];
        }
    }
    q.now = &f.buf[0];
    q.next = &f.buf[1];
    q.refr = f.refr.data(); q.hot = f.hot.data();
    q.th_on = f.th_on.data(); q.th_off = f.th_off.data(); q.leak_g = f.leak_g.data(); q.g1 = f.g1.data();
    q.bon = f.bon.data(); q.boff = f.boff.data(); q.busy = f.busy.data(); q.count = BLOCK;
    q.rate = static_cast<float>(e.q.rate);  // the input rates are float: the comparison is exact
    q.x = static_cast<float>(e.q.cx - f.base);
    q.sf_decay = static_cast<float>(e.q.sf_decay); q.sf_ramp = static_cast<float>(e.q.sf_ramp);
    q.phi_yy = static_cast<float>(e.q.phi_yy); q.l_yy = static_cast<float>(e.q.l_yy);
    q.bridge_bound = static_cast<float>(e.q.bridge_bound);
    q.dt = static_cast<float>(e.q.dt); q.inv_dt = static_cast<float>(e.q.inv_dt);
    q.clock_dt = static_cast<Clock>(e.q.dt);
    if constexpr (std::is_same_v<Time, float>) {
        q.t0 = round_down(e.q.t0 - f.t_call);
        q.t1 = round_up(e.q.t1 - f.t_call);
    } else {
        q.t0 = e.q.t0;
        q.t1 = e.q.t1;
    }
    q.bridge_stage = e.q.bridge_stage;
}

/// Study variant of detail::quiet_pass_body<SfOnly, Noise = true, Background = true>: the same
/// operations in the same order on float levels (Clock and Time as FloatBlock says).
template <class Clock, class Time>
EVSTWIN_ALWAYS_INLINE void quiet_pass_body(const FloatPass<Clock, Time>& q, const float* __restrict rate) {
    const float* __restrict sz = q.now->z.data();
    const float* __restrict sy = q.now->y.data();
    const float* __restrict sny = q.now->ny.data();
    const float* __restrict sref = q.now->ref.data();
    const Clock* __restrict son = q.now->on.data();
    const Clock* __restrict soff = q.now->off.data();
    float* __restrict oz = q.next->z.data();
    float* __restrict oy = q.next->y.data();
    float* __restrict ony = q.next->ny.data();
    float* __restrict oref = q.next->ref.data();
    Clock* __restrict oon = q.next->on.data();
    Clock* __restrict ooff = q.next->off.data();
    const Time* __restrict refr = q.refr;
    const Time* __restrict hot = q.hot;
    const float* __restrict th_on_a = q.th_on;
    const float* __restrict th_off_a = q.th_off;
    const float* __restrict leak_g = q.leak_g;
    const float* __restrict g1 = q.g1;
    const Clock* __restrict bon = q.bon;
    const Clock* __restrict boff = q.boff;
    std::uint32_t* __restrict busy = q.busy;
    const float x = q.x, common = q.rate, sf_decay = q.sf_decay, sf_ramp = q.sf_ramp, phi_yy = q.phi_yy,
                l_yy = q.l_yy, bridge_bound = q.bridge_bound, dt = q.dt, inv_dt = q.inv_dt;
    const Clock clock_dt = q.clock_dt;
    const Time t0 = q.t0, t1 = q.t1;
    const bool bridge_stage = q.bridge_stage;
    const std::size_t count = q.count;
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC ivdep
#endif
    for (std::size_t j = 0; j < count; ++j) {
        const float s_z = sz[j], s_y = sy[j], s_ny = sny[j];
        const float z = x;
        const float yd0 = s_y - s_ny;
        const float yd = z + (yd0 - s_z) * sf_decay - (z - s_z) * sf_ramp;
        const float ny = phi_yy * s_ny + l_yy * g1[j];
        const float y = yd + ny;
        const Clock on = son[j] - bon[j] * clock_dt, off = soff[j] - boff[j] * clock_dt;
        const bool ran_out = !((on > Clock(0)) & (off > Clock(0)));
        const float th_on = th_on_a[j], th_off = th_off_a[j];
        const float g = (y - s_y) * inv_dt + leak_g[j];
        const float db = s_y - sref[j];
        const float d1 = db + g * dt;
        const float on0 = th_on - db, off0 = th_off + db;
        const bool plain = (rate[j] == common) & !ran_out & (hot[j] > t1) & (refr[j] <= t0);
        const float on1 = th_on - d1, off1 = th_off + d1;
        const bool between0 = std::min(on0, off0) > 0.0f;
        const bool quiet = plain & between0 & (std::min(on0 * on1, off0 * off1) > bridge_bound);
        const bool bridge = bridge_stage & plain & between0 & (std::min(on1, off1) > 0.0f);
        oref[j] = y - d1;
        oz[j] = z;
        oy[j] = y;
        ony[j] = ny;
        oon[j] = on;
        ooff[j] = off;
        const std::uint32_t not_quiet = !quiet;
        busy[j] = 2u * not_quiet - (not_quiet & static_cast<std::uint32_t>(bridge));
    }
}

// The study passes at the engine's SIMD levels, chosen as the engine chooses (simd_level()).
#define STUDY_QUIET_PASS_LEVEL(NAME, TARGET)                                                 \
    template <class Clock, class Time>                                                       \
    TARGET __attribute__((noinline)) void NAME(const FloatPass<Clock, Time>& q, const float* rate) { \
        quiet_pass_body(q, rate);                                                            \
    }
STUDY_QUIET_PASS_LEVEL(quiet_pass_baseline, )
STUDY_QUIET_PASS_LEVEL(quiet_pass_avx2, EVSTWIN_TARGET_AVX2)
STUDY_QUIET_PASS_LEVEL(quiet_pass_avx512, EVSTWIN_TARGET_AVX512)
#undef STUDY_QUIET_PASS_LEVEL

template <class Clock, class Time>
void quiet_pass(const FloatPass<Clock, Time>& q, const float* rate) {
    switch (evstwin::simd_level()) {
        case SimdLevel::AVX512: return quiet_pass_avx512(q, rate);
        case SimdLevel::AVX2: return quiet_pass_avx2(q, rate);
        default: return quiet_pass_baseline(q, rate);
    }
}

// ---------------------------------------------------------------------------------------------
// Part 2: the normals.

/// The engine's ziggurat tables (rng.hpp's ZIGGURAT) with the layer widths as float: j * w in
/// float is the engine's double normal rounded to float (j < 2^24 is exact in either), and
/// the slow flags (j >= k) are the engine's, bit for bit: the same words go to the slow path.
struct ZigguratF {
    float w[128];
    std::uint32_t k[128];
    ZigguratF() {
        for (int i = 0; i < 128; ++i) {
            w[i] = static_cast<float>(evstwin::ZIGGURAT.w[i]);
            k[i] = evstwin::ZIGGURAT.k[i];
        }
    }
};
const ZigguratF ZIG_F;

/// Study variant of detail::ziggurat_batch_body: the common path in float, 16 lanes a vector
/// at AVX-512 (a 16-lane gather of the float widths) where the engine's double takes 8.
EVSTWIN_ALWAYS_INLINE void ziggurat_batch_body(const std::uint32_t* __restrict w, std::size_t n, float* __restrict g,
                                               std::uint8_t* __restrict slow) {
    const float* __restrict tw = ZIG_F.w;
    const std::uint32_t* __restrict tk = ZIG_F.k;
    for (std::size_t i = 0; i < n; ++i) {
        const std::uint32_t wi = w[i], layer = wi & 127u, j = wi >> 8;
        const float x = static_cast<float>(static_cast<std::int32_t>(j)) * tw[layer];
        g[i] = x * (1.0f - 2.0f * static_cast<float>(static_cast<std::int32_t>((wi >> 7) & 1u)));
        slow[i] = static_cast<std::uint8_t>(j >= tk[layer]);
    }
}
__attribute__((noinline)) void ziggurat_batch_baseline(const std::uint32_t* w, std::size_t n, float* g,
                                                       std::uint8_t* slow) {
    ziggurat_batch_body(w, n, g, slow);
}
EVSTWIN_TARGET_AVX2 __attribute__((noinline)) void ziggurat_batch_avx2(const std::uint32_t* w, std::size_t n, float* g,
                                                                      std::uint8_t* slow) {
    ziggurat_batch_body(w, n, g, slow);
}
EVSTWIN_TARGET_AVX512 __attribute__((noinline)) void ziggurat_batch_avx512(const std::uint32_t* w, std::size_t n,
                                                                          float* g, std::uint8_t* slow) {
    ziggurat_batch_body(w, n, g, slow);
}
void ziggurat_batch(const std::uint32_t* w, std::size_t n, float* g, std::uint8_t* slow) {
    EVSTWIN_AT_LEVEL(ziggurat_batch, w, n, g, slow)
}

}  // namespace study

namespace {

const char* level_names[] = {"baseline", "avx2", "avx512"};

// ---------------------------------------------------------------------------------------------
// Part 1 and 2: the timings.

void speed() {
    std::printf("== speed: ns per pixel-update, min of 60 repetitions (wall clock, one thread) ==\n");
    EngineBlock block(3000);  // 3 s of the reference load's background: a block as it stands mid-run
    EnginePass e(block);
    // The engine's whole block kernel for context (normals, quiet pass, bridge stage, per-pixel
    // path, events): the samples it runs are the ones after the snapshot above.
    EngineBlock kernel_block(3000);
    const double kernel_ns =
        min_seconds_per_call([&] { kernel_block.step(); }, 200, 60) / BLOCK * 1e9;
    std::size_t n_quiet = 0;
    study::FloatBlock<float, float> fa;
    study::FloatPass<float, float> qa{};
    study::load(fa, e, qa);
    study::FloatBlock<float, double> fm;
    study::FloatPass<float, double> qm{};
    study::load(fm, e, qm);
    study::FloatBlock<double, double> fl;
    study::FloatPass<double, double> ql{};
    study::load(fl, e, ql);
    const SimdLevel levels[] = {SimdLevel::AVX512, SimdLevel::AVX2, SimdLevel::Baseline};
    std::printf("engine step_block_soa, whole (reference pixel, background block, %s): %.2f ns\n",
                evstwin::simd_level_name(evstwin::simd_level()), kernel_ns);
    std::printf("\n%-10s %28s %30s %30s %30s\n", "level", "engine double quiet_pass",
                "float levels, float clocks,", "float levels, float clocks,", "float levels only");
    std::printf("%-10s %28s %30s %30s %30s\n", "", "", "float times (offsets)", "double times",
                "(clocks, times double)");
    for (SimdLevel l : levels) {
        if (!evstwin::simd_level_supported(l)) continue;
        evstwin::set_simd_level(l);
        const int calls = 400, reps = 60;
        const double d = min_seconds_per_call(
            [&] { evstwin::detail::quiet_pass<QuietChain::SfOnly>(e.q, block.rate.data(), true, true); keep(e.q.busy[0]); },
            calls, reps) / BLOCK * 1e9;
        const double a = min_seconds_per_call([&] { study::quiet_pass(qa, block.rate.data()); keep(qa.busy[0]); }, calls, reps) /
                         BLOCK * 1e9;
        const double m = min_seconds_per_call([&] { study::quiet_pass(qm, block.rate.data()); keep(qm.busy[0]); }, calls, reps) /
                         BLOCK * 1e9;
        const double o = min_seconds_per_call([&] { study::quiet_pass(ql, block.rate.data()); keep(ql.busy[0]); }, calls, reps) /
                         BLOCK * 1e9;
        std::printf("%-10s %28.3f %22.3f (%4.2fx) %22.3f (%4.2fx) %22.3f (%4.2fx)\n", level_names[static_cast<int>(l)], d,
                    a, d / a, m, d / m, o, d / o);
    }
    evstwin::set_simd_level(evstwin::best_simd_level());
    // The verdicts: the float pass must settle the same pixels (part 3 measures how often it
    // would not over a run); on this snapshot:
    evstwin::detail::quiet_pass<QuietChain::SfOnly>(e.q, block.rate.data(), true, true);
    study::quiet_pass(qa, block.rate.data());
    std::size_t differ = 0;
    for (std::size_t j = 0; j < BLOCK; ++j) {
        n_quiet += e.q.busy[j] == 0;
        differ += e.q.busy[j] != qa.busy[j];
    }
    std::printf("snapshot verdicts: %zu of %zu pixels quiet (engine), %zu verdicts differ (float-all)\n", n_quiet, BLOCK,
                differ);

    // Part 2: the normals of the reference load (one a pixel-update: the source follower alone).
    std::printf("\n-- normals (reference load: one normal a pixel-update) --\n");
    std::vector<std::uint32_t> c0(BLOCK), c1(BLOCK), c2(BLOCK), r0(BLOCK), r1(BLOCK), r2(BLOCK), r3(BLOCK);
    std::vector<double> gd(BLOCK), g2(BLOCK);
    std::vector<float> gf(BLOCK);
    std::vector<std::uint8_t> slow(BLOCK);
    for (std::size_t j = 0; j < BLOCK; ++j) {
        c0[j] = 12345u;
        c2[j] = static_cast<std::uint32_t>(j);
    }
    PixelModel::BlockScratch scratch;
    scratch.resize(BLOCK);
    const evstwin::Philox4x32Key key = evstwin::key_from_seed(7);
    evstwin::philox4x32_batch(c0.data(), c1.data(), c2.data(), evstwin::PURPOSE_SAMPLE, key, BLOCK, r0.data(), r1.data(),
                              r2.data(), r3.data());
    std::printf("%-10s %12s %12s %12s %14s %14s\n", "level", "Philox call", "zig double", "zig float",
                "engine normals", "+ slow path");
    std::printf("%-10s %12s %12s %12s %14s %14s\n", "", "per pixel", "common path", "common path",
                "(draw_floor)", "(of which)");
    double philox_ns = 0, zd_ns = 0, zf_ns = 0, full_ns = 0, common_ns = 0;
    for (SimdLevel l : levels) {
        if (!evstwin::simd_level_supported(l)) continue;
        evstwin::set_simd_level(l);
        const int calls = 400, reps = 60;
        const double ph = min_seconds_per_call([&] {
            evstwin::philox4x32_batch(c0.data(), c1.data(), c2.data(), evstwin::PURPOSE_SAMPLE, key, BLOCK, r0.data(),
                                      r1.data(), r2.data(), r3.data());
            keep(r0[0]);
        }, calls, reps) / BLOCK * 1e9;
        const double zd = min_seconds_per_call([&] { evstwin::ziggurat_batch(r0.data(), BLOCK, gd.data(), slow.data()); keep(gd[0]); },
                                               calls, reps) / BLOCK * 1e9;
        const double zf = min_seconds_per_call([&] { study::ziggurat_batch(r0.data(), BLOCK, gf.data(), slow.data()); keep(gf[0]); },
                                               calls, reps) / BLOCK * 1e9;
        // The engine's normals as its block kernel draws them for the reference load
        // (draw_floor.cpp's loop): one Philox call a pixel per two samples, then
        // batch_sample_normals (common path batched, the slow ~2.8 % finished) per sample.
        // A fresh counter a call, so the slow path meets its share of words.
        std::uint32_t pair = 0;
        const auto ids = [](std::size_t j) { return static_cast<std::uint32_t>(j); };
        const auto full = [&](bool with_slow) {
            for (std::size_t j = 0; j < BLOCK; ++j) c0[j] = pair;
            evstwin::philox4x32_batch(c0.data(), c1.data(), c2.data(), evstwin::PURPOSE_SAMPLE, key, BLOCK, r0.data(),
                                      r1.data(), r2.data(), r3.data());
            for (int half = 0; half < 2; ++half) {
                const std::uint64_t sample = 2u * static_cast<std::uint64_t>(pair) + static_cast<std::uint64_t>(half);
                if (with_slow)
                    PixelModel::batch_sample_normals(
                        BLOCK, [sample](std::size_t) { return sample; }, ids, key, scratch, half ? r2.data() : r0.data(),
                        half ? r3.data() : r1.data(), gd.data(), g2.data(), false);
                else
                    evstwin::ziggurat_batch(half ? r2.data() : r0.data(), BLOCK, gd.data(), slow.data());
                keep(gd[0]);
            }
            ++pair;
        };
        const double f = min_seconds_per_call([&] { full(true); }, calls, reps) / (2 * BLOCK) * 1e9;
        const double f_common = min_seconds_per_call([&] { full(false); }, calls, reps) / (2 * BLOCK) * 1e9;
        std::printf("%-10s %12.3f %12.3f %12.3f %14.3f %14.3f\n", level_names[static_cast<int>(l)], ph, zd, zf, f,
                    f - f_common);
        if (l == evstwin::best_simd_level()) {
            philox_ns = ph; zd_ns = zd; zf_ns = zf; full_ns = f; common_ns = f_common;
        }
    }
    evstwin::set_simd_level(evstwin::best_simd_level());
    // What each change saves a pixel-update at the best level. The slow path (a wedge or the
    // tail: the same words either way) and the counters are left as they are.
    std::printf("\nat %s, per pixel-update:\n", evstwin::simd_level_name(evstwin::simd_level()));
    std::printf("  engine normals %.3f ns = Philox %.3f (one call / 2 updates) + ziggurat %.3f + slow path and counters %.3f\n",
                full_ns, philox_ns / 2, zd_ns, full_ns - philox_ns / 2 - zd_ns);
    std::printf("  float ziggurat saves %.3f ns; every Philox word used (one call / 4 updates, any precision) saves %.3f ns\n",
                zd_ns - zf_ns, philox_ns / 4);
    keep(common_ns);
}

// ---------------------------------------------------------------------------------------------
// Part 3: fidelity.

/// One pixel's quiet-pass state in precision T (the reference load's chain: SfOnly, noise and
/// background on), levels relative to `base` (0: absolute).
template <class T>
struct Track {
    T z, y, ny, ref, on, off;
};

/// The quiet pass's arithmetic for one pixel and sample, in T (quiet_pass_body's operations in
/// its order); returns d1, sets quiet (the pass's verdict without the time and rate terms).
template <class T>
T quiet_step(Track<T>& s, T x, T g, T th_on, T th_off, T leak_g, T bon, T boff, T sf_decay, T sf_ramp, T phi_yy,
             T l_yy, T bridge_bound, T dt, T inv_dt, bool& quiet, bool& ran_out) {
    const T z = x;
    const T yd0 = s.y - s.ny;
    const T yd = z + (yd0 - s.z) * sf_decay - (z - s.z) * sf_ramp;
    const T ny = phi_yy * s.ny + l_yy * g;
    const T y = yd + ny;
    const T on = s.on - bon * dt, off = s.off - boff * dt;
    ran_out = !((on > T(0)) & (off > T(0)));
    const T gs = (y - s.y) * inv_dt + leak_g;
    const T db = s.y - s.ref;
    const T d1 = db + gs * dt;
    const T on0 = th_on - db, off0 = th_off + db, on1 = th_on - d1, off1 = th_off + d1;
    quiet = !ran_out & (std::min(on0, off0) > T(0)) & (std::min(on0 * on1, off0 * off1) > bridge_bound);
    s.ref = y - d1;
    s.z = z;
    s.y = y;
    s.ny = ny;
    s.on = on;
    s.off = off;
    return d1;
}

struct StudyEvent {
    std::uint32_t pixel;
    std::uint32_t sample;
    std::int8_t pol;      ///< +1 ON, -1 OFF (crossing); +2 / -2 eq. 12's background
    double t_offset;      ///< a background event's time after the sample's end [s] (clock / rate)
    bool operator<(const StudyEvent& o) const {
        return pixel != o.pixel ? pixel < o.pixel : sample != o.sample ? sample < o.sample : pol < o.pol;
    }
};

/// How two event lists (sorted) agree: events at the same pixel, sample and polarity; those
/// within +-k samples; and the largest background-timestamp difference among the matched.
void compare_events(const char* name, const std::vector<StudyEvent>& ref, const std::vector<StudyEvent>& other) {
    std::size_t same = 0, near1 = 0, near10 = 0, bg_matched = 0;
    double bg_dt_max = 0.0, bg_dt_sum = 0.0;
    std::size_t i = 0, j = 0;
    // Exact matches by a merge.
    std::vector<char> used(other.size(), 0);
    while (i < ref.size() && j < other.size()) {
        if (ref[i].pixel == other[j].pixel && ref[i].sample == other[j].sample && ref[i].pol == other[j].pol) {
            ++same;
            used[j] = 1;
            if (ref[i].pol == 2 || ref[i].pol == -2) {
                const double d = std::fabs(ref[i].t_offset - other[j].t_offset);
                bg_dt_max = std::max(bg_dt_max, d);
                bg_dt_sum += d;
                ++bg_matched;
            }
            ++i; ++j;
        } else if (ref[i] < other[j]) {
            ++i;
        } else {
            ++j;
        }
    }
    // The rest: the nearest unmatched event of the same pixel and polarity.
    std::size_t unmatched_ref = ref.size() - same;
    {
        std::size_t a = 0;
        for (const StudyEvent& ev : ref) {
            while (a < other.size() && (other[a].pixel < ev.pixel)) ++a;
            // (a linear scan per pixel: the lists are short per pixel)
            std::uint32_t best = std::numeric_limits<std::uint32_t>::max();
            bool exact = false;
            for (std::size_t b = a; b < other.size() && other[b].pixel == ev.pixel; ++b) {
                if (other[b].pol != ev.pol) continue;
                const std::uint32_t d = ev.sample > other[b].sample ? ev.sample - other[b].sample : other[b].sample - ev.sample;
                if (d == 0) exact = true;
                best = std::min(best, d);
            }
            if (exact) continue;
            near1 += best <= 1;
            near10 += best <= 10;
        }
    }
    std::printf("  %-16s %9zu events (double %zu): %9zu identical (%6.3f %%); of the %zu others %zu within 1 sample, "
                "%zu within 10\n",
                name, other.size(), ref.size(), same, 100.0 * static_cast<double>(same) / static_cast<double>(ref.size()),
                unmatched_ref, near1, near10);
    if (bg_matched)
        std::printf("  %-16s background events at the same sample: %zu, their timestamps differ by %.2f us on average, "
                    "%.2f us at most\n",
                    "", bg_matched, 1e6 * bg_dt_sum / static_cast<double>(bg_matched), 1e6 * bg_dt_max);
}

void fidelity() {
    const std::size_t n_pix = 4096, n_samples = 10000;
    std::printf("\n== fidelity: %zu pixels of the reference load, %zu samples at 1 kHz, same normals ==\n", n_pix,
                n_samples);
    const PixelModel model(reference_pixel());
    const evstwin::Philox4x32Key key = evstwin::key_from_seed(1);
    const SampleConstants c = model.constants(0.0, DT);
    NoiseCache cache;
    model.fill_noise_cache(cache, BACKGROUND, c);
    std::printf("numbers: x = ln(I) = %.4f, sf_decay %.9f, phi_yy %.9f, l_yy (noise a sample) %.3e, leak %.3f Hz, "
                "bg factor %.6f, bridge_bound %.3e\n",
                cache.x, c.sf_decay, cache.k.phi_yy, cache.k.l_yy, cache.leak_hz, cache.bg_factor, cache.bridge_bound);
    std::vector<PixelState> st(n_pix);
    std::vector<double> leak_g(n_pix), bon(n_pix), boff(n_pix);
    for (std::size_t j = 0; j < n_pix; ++j) {
        const auto id = static_cast<std::uint32_t>(j);
        model.init_pixel(st[j], key, id);
        model.init_state(st[j], BACKGROUND, 0.0, key, id);
        leak_g[j] = model.leak_slope(st[j].leak_spread, st[j].theta_on, st[j].theta_off, cache.leak_hz);
        bon[j] = st[j].bg_on_hz * cache.bg_factor;
        boff[j] = st[j].bg_off_hz * cache.bg_factor;
    }
    std::printf("float spacing at |x| = %.1f: %.2e; the leak moves the reference %.2e a sample, the noise %.2e "
                "(one sigma)\n",
                std::fabs(cache.x), static_cast<double>(std::nextafter(static_cast<float>(std::fabs(cache.x)), 1e30f) -
                                                        static_cast<float>(std::fabs(cache.x))),
                leak_g[0] * DT, cache.k.l_yy);

    // The sample's normal and the uniform of a background clock's fresh budget: the same
    // numbers for every precision (the normal in float is the engine's double rounded).
    const auto draws = [&](std::uint32_t pixel, std::uint64_t sample, double& g, double& u) {
        const evstwin::Philox4x32Counter w = evstwin::philox4x32(
            {static_cast<std::uint32_t>(sample), static_cast<std::uint32_t>(sample >> 32), pixel, evstwin::PURPOSE_SAMPLE},
            key);
        evstwin::CounterStream more(key, pixel, sample, evstwin::PURPOSE_NORMAL);
        g = evstwin::normal_ziggurat(w[0], [&more] { return more.word(); });
        u = evstwin::uniform_open(w[1]);
    };

    // 3a: the level arithmetic alone (no comparator: the reference drifts with the leak and
    // nothing resets it), 10^4 samples; error of the float tracks against double.
    {
        double err_y_abs = 0, err_ref_abs = 0, err_d_abs = 0, err_y_reb = 0, err_ref_reb = 0, err_d_reb = 0;
        double rms_d_abs = 0, rms_d_reb = 0, drift_abs = 0, drift_reb = 0, drift_dbl = 0;
        double err_clock = 0;
        const double base = cache.x;
        for (std::size_t j = 0; j < n_pix; ++j) {
            const PixelState& s = st[j];
            Track<double> d{s.z, s.y, s.ny, s.ref, s.bg_clock_on, s.bg_clock_off};
            Track<float> fa{static_cast<float>(s.z), static_cast<float>(s.y), static_cast<float>(s.ny),
                            static_cast<float>(s.ref), static_cast<float>(s.bg_clock_on), static_cast<float>(s.bg_clock_off)};
            Track<float> fr{static_cast<float>(s.z - base), static_cast<float>(s.y - base), static_cast<float>(s.ny),
                            static_cast<float>(s.ref - base), static_cast<float>(s.bg_clock_on),
                            static_cast<float>(s.bg_clock_off)};
            // Without the comparator, the clocks are not reset: keep them from running out.
            d.on = d.off = 1e9; fa.on = fa.off = fr.on = fr.off = 1e9f;
            const double d0 = s.y - s.ref;
            for (std::size_t k = 0; k < n_samples; ++k) {
                double g, u;
                draws(static_cast<std::uint32_t>(j), k + 1, g, u);
                bool q, r;
                quiet_step<double>(d, cache.x, g, s.theta_on, s.theta_off, leak_g[j], bon[j], boff[j], c.sf_decay,
                                   c.sf_ramp, cache.k.phi_yy, cache.k.l_yy, cache.bridge_bound, c.dt, c.inv_dt, q, r);
                quiet_step<float>(fa, static_cast<float>(cache.x), static_cast<float>(g), static_cast<float>(s.theta_on),
                                  static_cast<float>(s.theta_off), static_cast<float>(leak_g[j]),
                                  static_cast<float>(bon[j]), static_cast<float>(boff[j]), static_cast<float>(c.sf_decay),
                                  static_cast<float>(c.sf_ramp), static_cast<float>(cache.k.phi_yy),
                                  static_cast<float>(cache.k.l_yy), static_cast<float>(cache.bridge_bound),
                                  static_cast<float>(c.dt), static_cast<float>(c.inv_dt), q, r);
                quiet_step<float>(fr, static_cast<float>(cache.x - base), static_cast<float>(g),
                                  static_cast<float>(s.theta_on), static_cast<float>(s.theta_off),
                                  static_cast<float>(leak_g[j]), static_cast<float>(bon[j]), static_cast<float>(boff[j]),
                                  static_cast<float>(c.sf_decay), static_cast<float>(c.sf_ramp),
                                  static_cast<float>(cache.k.phi_yy), static_cast<float>(cache.k.l_yy),
                                  static_cast<float>(cache.bridge_bound), static_cast<float>(c.dt),
                                  static_cast<float>(c.inv_dt), q, r);
            }
            const double dd = d.y - d.ref;
            const double da = static_cast<double>(fa.y) - static_cast<double>(fa.ref);
            const double dr = static_cast<double>(fr.y) - static_cast<double>(fr.ref);
            err_y_abs = std::max(err_y_abs, std::fabs(static_cast<double>(fa.y) - d.y));
            err_ref_abs = std::max(err_ref_abs, std::fabs(static_cast<double>(fa.ref) - d.ref));
            err_d_abs = std::max(err_d_abs, std::fabs(da - dd));
            err_y_reb = std::max(err_y_reb, std::fabs(static_cast<double>(fr.y) + base - d.y));
            err_ref_reb = std::max(err_ref_reb, std::fabs(static_cast<double>(fr.ref) + base - d.ref));
            err_d_reb = std::max(err_d_reb, std::fabs(dr - dd));
            rms_d_abs += (da - dd) * (da - dd);
            rms_d_reb += (dr - dd) * (dr - dd);
            // The leak's drift of d = y - ref over the run: theta_on per leak period, 10 s here.
            drift_dbl += dd - d0;
            drift_abs += da - d0;
            drift_reb += dr - d0;
            err_clock = std::max(err_clock, std::fabs(static_cast<double>(fr.on) - d.on));
        }
        const double n = static_cast<double>(n_pix);
        std::printf("\n3a. level arithmetic alone after %zu samples (comparator off), float against double, log units:\n",
                    n_samples);
        std::printf("  %-22s %12s %12s %14s %14s %20s\n", "", "max |dy|", "max |dref|", "max |d(y-ref)|", "rms d(y-ref)",
                    "mean drift of y-ref");
        std::printf("  %-22s %12s %12s %14s %14s %20.6f\n", "double (engine)", "-", "-", "-", "-", drift_dbl / n);
        std::printf("  %-22s %12.3e %12.3e %14.3e %14.3e %20.6f\n", "float, absolute", err_y_abs, err_ref_abs, err_d_abs,
                    std::sqrt(rms_d_abs / n), drift_abs / n);
        std::printf("  %-22s %12.3e %12.3e %14.3e %14.3e %20.6f\n", "float, re-based", err_y_reb, err_ref_reb, err_d_reb,
                    std::sqrt(rms_d_reb / n), drift_reb / n);
        keep(err_clock);
    }

    // 3b and 3c: the comparator on (the study's: an event where the sample's end level lies past
    // a threshold, the reference then set to the level; eq. 12's clocks fire background events
    // and get a fresh budget -ln u). 3b: lockstep, each float verdict from the double state of
    // the same sample, so one sample's disagreement does not carry over. 3c: each precision
    // runs freely and the event lists are compared.
    struct Scenario {
        const char* name;
        double amplitude;  // the light's log level swings by this (1 Hz sine), on every pixel
    };
    for (const Scenario sc : {Scenario{"background light (the reference load's 99 % of pixels)", 0.0},
                              Scenario{"flickering light: ln I swings +-1 at 1 Hz (signal events)", 1.0}}) {
        std::printf("\n%s:\n", sc.name);
        const double base = cache.x;
        std::size_t verdict_abs = 0, verdict_reb = 0, cross_abs = 0, cross_reb = 0, busy_dbl = 0, cross_dbl = 0;
        std::vector<StudyEvent> ev_d, ev_a, ev_r;
        for (std::size_t j = 0; j < n_pix; ++j) {
            const PixelState& s = st[j];
            const auto id = static_cast<std::uint32_t>(j);
            Track<double> d{s.z, s.y, s.ny, s.ref, s.bg_clock_on, s.bg_clock_off};
            Track<float> fa{static_cast<float>(s.z), static_cast<float>(s.y), static_cast<float>(s.ny),
                            static_cast<float>(s.ref), static_cast<float>(s.bg_clock_on), static_cast<float>(s.bg_clock_off)};
            Track<float> fr{static_cast<float>(s.z - base), static_cast<float>(s.y - base), static_cast<float>(s.ny),
                            static_cast<float>(s.ref - base), static_cast<float>(s.bg_clock_on),
                            static_cast<float>(s.bg_clock_off)};
            // One sample of a track in T with base b; records its events.
            const auto run = [&](auto& tr, double b, double x, double g, double u, std::uint32_t k,
                                 std::vector<StudyEvent>* out, bool& quiet, int& crossing) {
                using T = std::decay_t<decltype(tr.y)>;
                bool ran_out;
                const T d1 = quiet_step<T>(tr, static_cast<T>(x - b), static_cast<T>(g), static_cast<T>(s.theta_on),
                                           static_cast<T>(s.theta_off), static_cast<T>(leak_g[j]), static_cast<T>(bon[j]),
                                           static_cast<T>(boff[j]), static_cast<T>(c.sf_decay), static_cast<T>(c.sf_ramp),
                                           static_cast<T>(cache.k.phi_yy), static_cast<T>(cache.k.l_yy),
                                           static_cast<T>(cache.bridge_bound), static_cast<T>(c.dt),
                                           static_cast<T>(c.inv_dt), quiet, ran_out);
                crossing = d1 >= static_cast<T>(s.theta_on) ? 1 : d1 <= -static_cast<T>(s.theta_off) ? -1 : 0;
                if (!out) return;
                if (crossing) {
                    out->push_back({id, k, static_cast<std::int8_t>(crossing), 0.0});
                    tr.ref = tr.y;
                }
                if (ran_out) {
                    const bool on = !(tr.on > T(0));
                    const double left = on ? static_cast<double>(tr.on) / bon[j] : static_cast<double>(tr.off) / boff[j];
                    out->push_back({id, k, static_cast<std::int8_t>(on ? 2 : -2), left});
                    if (on) tr.on = tr.on + static_cast<T>(-std::log(u));
                    else tr.off = tr.off + static_cast<T>(-std::log(u));
                    if (!(tr.on > T(0))) tr.on = static_cast<T>(1e-30);
                    if (!(tr.off > T(0))) tr.off = static_cast<T>(1e-30);
                    tr.ref = tr.y;
                }
            };
            for (std::uint32_t k = 0; k < n_samples; ++k) {
                double g, u;
                draws(id, k + 1, g, u);
                const double x = cache.x + sc.amplitude * std::sin(2.0 * evstwin::PI * 1.0 * (k + 1) * DT);
                // 3b: the float verdicts from the double state as it stands (rounded to float).
                Track<float> la{static_cast<float>(d.z), static_cast<float>(d.y), static_cast<float>(d.ny),
                                static_cast<float>(d.ref), static_cast<float>(d.on), static_cast<float>(d.off)};
                Track<float> lr{static_cast<float>(d.z - base), static_cast<float>(d.y - base), static_cast<float>(d.ny),
                                static_cast<float>(d.ref - base), static_cast<float>(d.on), static_cast<float>(d.off)};
                bool q_d, q_a, q_r;
                int x_d, x_a, x_r;
                run(la, 0.0, x, g, u, k, nullptr, q_a, x_a);
                run(lr, base, x, g, u, k, nullptr, q_r, x_r);
                run(d, 0.0, x, g, u, k, &ev_d, q_d, x_d);
                busy_dbl += !q_d;
                cross_dbl += x_d != 0;
                verdict_abs += q_a != q_d;
                verdict_reb += q_r != q_d;
                cross_abs += x_a != x_d;
                cross_reb += x_r != x_d;
                // 3c: the free-running float tracks.
                run(fa, 0.0, x, g, u, k, &ev_a, q_a, x_a);
                run(fr, base, x, g, u, k, &ev_r, q_r, x_r);
            }
        }
        const double total = static_cast<double>(n_pix) * static_cast<double>(n_samples);
        std::printf("3b. lockstep (one sample from the same double state), of %.0f pixel-samples: double busy %.4f %%, "
                    "crossing %.4f %%\n",
                    total, 100.0 * static_cast<double>(busy_dbl) / total, 100.0 * static_cast<double>(cross_dbl) / total);
        std::printf("  %-16s quiet/busy verdict differs %zu times (%.2e), crossing differs %zu times (%.2e)\n",
                    "float, absolute", verdict_abs, static_cast<double>(verdict_abs) / total, cross_abs,
                    static_cast<double>(cross_abs) / total);
        std::printf("  %-16s quiet/busy verdict differs %zu times (%.2e), crossing differs %zu times (%.2e)\n",
                    "float, re-based", verdict_reb, static_cast<double>(verdict_reb) / total, cross_reb,
                    static_cast<double>(cross_reb) / total);
        std::printf("3c. free-running, events against double's:\n");
        std::sort(ev_d.begin(), ev_d.end());
        std::sort(ev_a.begin(), ev_a.end());
        std::sort(ev_r.begin(), ev_r.end());
        compare_events("float, absolute", ev_d, ev_a);
        compare_events("float, re-based", ev_d, ev_r);
    }
}

}  // namespace

EVSTWIN_FP_STRICT_END

int main(int argc, char** argv) {
    const bool all = argc < 2;
    if (!all && std::strcmp(argv[1], "speed") != 0 && std::strcmp(argv[1], "fidelity") != 0) {
        std::fprintf(stderr, "usage: %s [speed|fidelity]\n", argv[0]);
        return 2;
    }
    std::printf("best SIMD level: %s\n", evstwin::simd_level_name(evstwin::best_simd_level()));
    if (all || std::strcmp(argv[1], "speed") == 0) speed();
    if (all || std::strcmp(argv[1], "fidelity") == 0) fidelity();
    return 0;
}
