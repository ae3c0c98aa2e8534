// Issue 15 asks for the pixel state "in single precision where the physics allows it (log-domain
// levels, filters) and double where it does not (time)". The engine kept double everywhere so
// its events match an independent reference bit for bit. This study measures what single
// precision would buy and what it would change, so that choice can be made on numbers:
//
//   1. speed of the quiet pass: the engine's own detail::quiet_pass (double, the reference
//      load's chain: source follower alone, noise and background on) on a real BlockSoA of one
//      256-pixel block, warmed up by 3 s of the engine's step_block_soa, against study variants
//      of the same arithmetic on float arrays: levels re-based (relative to the block's level,
//      a double kept outside), eq. 12's clocks in float or double, the refractory and hot-pixel
//      times in double or as float offsets rounded so a verdict can only err towards busy.
//      At each SIMD level the engine dispatches to (the study variants compiled with the same
//      target attributes). ns per pixel-update, the least of 60 repetitions of 400 calls (the
//      machine is shared; the least is the least disturbed), data in L1/L2 as the engine has it.
//   2. speed of the normals (one a pixel-update in the reference load): the engine's Philox
//      batch, its ziggurat batch, and its whole draw (draw_floor.cpp's loop), against a float
//      ziggurat (16 lanes at AVX-512); and, because GCC 12 looks the float ziggurat's tables
//      up lane by lane (as it did the engine's double ones, which simd.hpp now gathers: this
//      study found it), the float look-up written with an AVX-512 gather and both precisions'
//      with in-register permutes, so the share of precision is told apart from that of the
//      look-up. Also what using every Philox word would save (one call per pixel per four samples instead of two:
//      the reference load uses one word of each sample's two; a change of the words, not of
//      precision).
//   3. fidelity: the quiet pass's level arithmetic for 4096 pixels of the reference load
//      (thresholds with 3 % mismatch, the 10 Hz source follower's exact update and noise at
//      2e6 photons/s and 1 kHz, the leak, eq. 12's clocks; states from init_state), in double
//      (the engine's) and in float: absolute levels, re-based levels, re-based levels with the
//      clocks in double; the same normals. 3a: level error after SAMPLES samples with the
//      comparator off. 3b: how often one sample's quiet/busy verdict or crossing differs, each
//      precision from the same double state (lockstep). 3c: each precision run freely with a
//      study comparator, events compared (pixel, sample, polarity, microsecond timestamp), for
//      the background light and for a light flickering by +-1 in ln I at 1 Hz.
//
// Study variants (namespace study) live only here: the engine's headers are included read-only
// and nothing here is used by the engine. The study comparator of part 3 is simpler than the
// engine's (an event where the sample's end level lies past a threshold, placed on the line
// from d0 to d1, the reference then set to the level; a background event where a clock runs out,
// timed as background_fire times it; no bridge, no refractory period): the same rule for every
// precision, so what differs between them is the arithmetic's precision alone.
//
//   g++ -std=c++17 -O3 -DNDEBUG -Icpp/include bench/precision_study.cpp -o /tmp/precision_study
//   /tmp/precision_study                       # both parts (~10 s)
//   /tmp/precision_study speed                 # parts 1 and 2
//   /tmp/precision_study fidelity [SAMPLES]    # part 3, 10000 samples (10 s at 1 kHz) by default
//
// No -march: like the engine, the vector code comes from target attributes and run-time dispatch.
#include <evstwin/evstwin.hpp>

#if !EVSTWIN_MULTIVERSION
#error "precision_study compares SIMD levels: it needs the engine's multiversioning (x86-64, GCC or Clang, without EVSTWIN_NO_MULTIVERSION)"
#endif

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <type_traits>
#include <vector>

EVSTWIN_FP_STRICT_BEGIN  // the study variants obey the engine's rule: no contracted multiply-adds

namespace {

using evstwin::BlockSoA;
using evstwin::NoiseCache;
using evstwin::BlockModel;
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
    BlockModel model{reference_pixel()};
    evstwin::Philox4x32Key key = evstwin::key_from_seed(1);
    std::vector<PixelState> st = std::vector<PixelState>(BLOCK);
    std::vector<std::uint32_t> ids = std::vector<std::uint32_t>(BLOCK);
    std::vector<float> rate = std::vector<float>(BLOCK, static_cast<float>(BACKGROUND));
    BlockModel::BlockScratch scratch;
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
            // sample_words(): one Philox call per two samples, words 0-1 for the even one, 2-3
            // for the odd; sample_normals()'s first normal from the first.
            const std::uint64_t n = h.count(j);
            const evstwin::Philox4x32Counter w = evstwin::philox4x32(
                {static_cast<std::uint32_t>(n >> 1), static_cast<std::uint32_t>(n >> 33), b.ids[j], evstwin::PURPOSE_SAMPLE},
                b.key);
            evstwin::CounterStream more(b.key, b.ids[j], n, evstwin::PURPOSE_NORMAL);
            g1[j] = evstwin::normal_ziggurat(w[(n & 1u) ? 2 : 0], [&more] { return more.word(); });
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

/// Study variant: the quiet pass's arrays for one block, levels in L. In float (single
/// precision) the levels (z, y, ref) are stored relative to the block's base level (a double
/// kept outside the pass: here the common rate's log level when the block was loaded), so the
/// float's 24 bits resolve the difference from the base, not the -33 of ln(I / 1 A) at the
/// reference load's background (whose float spacing, 3.8e-6, is a fifth of the 2.1e-5 the leak
/// moves the reference a sample: part 3); in double they are the engine's, absolute (L double
/// with Clock and Time double is the engine's pass again, a check on the study's kernel). ny is
/// the noise part, small already. Clock and Time: float, or double to keep eq. 12's clocks and
/// the times as the engine has them. Due: eq. 12's clocks not spent a sample at a time but held
/// as the time they run out (t0 + budget / rate, made once in double), folded with the hot
/// pixel's next_hot_t into one due time, which the pass compares as it compares next_hot_t: no
/// clock arrays read or written (a change of the clocks' arithmetic, in either precision: the
/// same events but for the last bits of a background event's time).
template <class L, class Clock, class Time, bool Due = false>
struct StudyBlock {
    struct Levels {
        std::vector<L> z, y, ny, ref;
        std::vector<Clock> on, off;
    };
    /// The verdicts as wide as the levels' lanes (BlockSoA::busy says why).
    using Flag = std::conditional_t<sizeof(L) == 4, std::uint32_t, std::uint64_t>;
    Levels buf[2];
    std::vector<L> th_on, th_off, leak_g, g1;
    std::vector<Clock> bon, boff;
    /// The times the pass compares. As float: offsets from the run call's start, rounded so a
    /// float comparison can only err towards "busy" (refr_until rounded up, next_hot_t down;
    /// the pass's t0 down, t1 up), which sends a pixel to the exact per-pixel path, never
    /// settles one wrongly: the time tests stay exact, only a few more pixels may be busy.
    std::vector<Time> refr, hot;
    std::vector<Flag> busy;
    double base = 0.0, t_call = 0.0;
};

template <class L, class Clock, class Time, bool Due = false>
struct StudyPass {
    using Block = StudyBlock<L, Clock, Time, Due>;
    const typename Block::Levels* now;
    typename Block::Levels* next;
    const Time *refr, *hot;
    const L *th_on, *th_off, *leak_g, *g1;
    const Clock *bon, *boff;
    typename Block::Flag* busy;
    std::size_t count;
    L rate, x, sf_decay, sf_ramp, phi_yy, l_yy, bridge_bound, dt, inv_dt;
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
template <class L, class Clock, class Time, bool Due>
void load(StudyBlock<L, Clock, Time, Due>& f, const EnginePass& e, StudyPass<L, Clock, Time, Due>& q) {
    constexpr bool float_time = std::is_same_v<Time, float>;
    const BlockSoA::Levels& s = *e.q.now;
    f.base = std::is_same_v<L, float> ? e.q.cx : 0.0;
    f.t_call = 0.0;
    for (auto& l : f.buf) {
        for (auto* v : {&l.z, &l.y, &l.ny, &l.ref}) v->resize(BLOCK);
        l.on.resize(BLOCK);
        l.off.resize(BLOCK);
    }
    for (auto* v : {&f.th_on, &f.th_off, &f.leak_g, &f.g1}) v->resize(BLOCK);
    f.bon.resize(BLOCK); f.boff.resize(BLOCK); f.refr.resize(BLOCK); f.hot.resize(BLOCK); f.busy.resize(BLOCK);
    for (std::size_t j = 0; j < BLOCK; ++j) {
        f.buf[0].z[j] = static_cast<L>(s.z[j] - f.base);
        f.buf[0].y[j] = static_cast<L>(s.y[j] - f.base);
        f.buf[0].ref[j] = static_cast<L>(s.ref[j] - f.base);
        f.buf[0].ny[j] = static_cast<L>(s.ny[j]);
        f.buf[0].on[j] = static_cast<Clock>(s.clock_on[j]);
        f.buf[0].off[j] = static_cast<Clock>(s.clock_off[j]);
        f.th_on[j] = static_cast<L>(e.q.theta_on[j]);
        f.th_off[j] = static_cast<L>(e.q.theta_off[j]);
        f.leak_g[j] = static_cast<L>(e.q.leak_g[j]);
        f.bon[j] = static_cast<Clock>(e.q.bg_on_rate[j]);
        f.boff[j] = static_cast<Clock>(e.q.bg_off_rate[j]);
        f.g1[j] = static_cast<L>(e.q.g1[j]);
        double due = e.q.next_hot_t[j];
        if constexpr (Due) {
            const double inf = std::numeric_limits<double>::infinity();
            const double t_on = e.q.bg_on_rate[j] > 0.0 ? e.q.t0 + s.clock_on[j] / e.q.bg_on_rate[j] : inf;
            const double t_off = e.q.bg_off_rate[j] > 0.0 ? e.q.t0 + s.clock_off[j] / e.q.bg_off_rate[j] : inf;
            due = std::min({due, t_on, t_off});
        }
        if constexpr (float_time) {
            f.refr[j] = round_up(e.q.refr_until[j] - f.t_call);
            f.hot[j] = round_down(due - f.t_call);
        } else {
            f.refr[j] = e.q.refr_until[j];
            f.hot[j] = due;
        }
    }
    q.now = &f.buf[0];
    q.next = &f.buf[1];
    q.refr = f.refr.data(); q.hot = f.hot.data();
    q.th_on = f.th_on.data(); q.th_off = f.th_off.data(); q.leak_g = f.leak_g.data(); q.g1 = f.g1.data();
    q.bon = f.bon.data(); q.boff = f.boff.data(); q.busy = f.busy.data(); q.count = BLOCK;
    q.rate = static_cast<L>(e.q.rate);  // the input rates are float: the comparison is exact
    q.x = static_cast<L>(e.q.cx - f.base);
    q.sf_decay = static_cast<L>(e.q.sf_decay); q.sf_ramp = static_cast<L>(e.q.sf_ramp);
    q.phi_yy = static_cast<L>(e.q.phi_yy); q.l_yy = static_cast<L>(e.q.l_yy);
    q.bridge_bound = static_cast<L>(e.q.bridge_bound);
    q.dt = static_cast<L>(e.q.dt); q.inv_dt = static_cast<L>(e.q.inv_dt);
    q.clock_dt = static_cast<Clock>(e.q.dt);
    if constexpr (float_time) {
        q.t0 = round_down(e.q.t0 - f.t_call);
        q.t1 = round_up(e.q.t1 - f.t_call);
    } else {
        q.t0 = e.q.t0;
        q.t1 = e.q.t1;
    }
    q.bridge_stage = e.q.bridge_stage;
}

/// One study variant: its arrays (b) and its pass over them (q), loaded from the engine's pass.
template <class L, class Clock, class Time, bool Due = false>
struct StudyCase {
    StudyBlock<L, Clock, Time, Due> b;
    StudyPass<L, Clock, Time, Due> q{};
    explicit StudyCase(const EnginePass& e) { load(b, e, q); }
    StudyCase(const StudyCase&) = delete;  // q points into b
    StudyCase& operator=(const StudyCase&) = delete;
};

/// Study variant of detail::quiet_pass_body<SfOnly, Noise = true, Background = true>: the same
/// operations in the same order on levels in L (Clock, Time and Due as StudyBlock says). In
/// float its level tests are not made conservative (a float "quiet" need not be a double one
/// near the bridge bound; a design would add margins, at no measurable cost): part 3 counts
/// how often they differ.
template <class L, class Clock, class Time, bool Due>
EVSTWIN_ALWAYS_INLINE void quiet_pass_body(const StudyPass<L, Clock, Time, Due>& q, const float* __restrict rate) {
    using Flag = typename StudyBlock<L, Clock, Time, Due>::Flag;
    const L* __restrict sz = q.now->z.data();
    const L* __restrict sy = q.now->y.data();
    const L* __restrict sny = q.now->ny.data();
    const L* __restrict sref = q.now->ref.data();
    const Clock* __restrict son = q.now->on.data();
    const Clock* __restrict soff = q.now->off.data();
    L* __restrict oz = q.next->z.data();
    L* __restrict oy = q.next->y.data();
    L* __restrict ony = q.next->ny.data();
    L* __restrict oref = q.next->ref.data();
    Clock* __restrict oon = q.next->on.data();
    Clock* __restrict ooff = q.next->off.data();
    const Time* __restrict refr = q.refr;
    const Time* __restrict hot = q.hot;
    const L* __restrict th_on_a = q.th_on;
    const L* __restrict th_off_a = q.th_off;
    const L* __restrict leak_g = q.leak_g;
    const L* __restrict g1 = q.g1;
    const Clock* __restrict bon = q.bon;
    const Clock* __restrict boff = q.boff;
    Flag* __restrict busy = q.busy;
    const L x = q.x, common = q.rate, sf_decay = q.sf_decay, sf_ramp = q.sf_ramp, phi_yy = q.phi_yy, l_yy = q.l_yy,
            bridge_bound = q.bridge_bound, dt = q.dt, inv_dt = q.inv_dt;
    const Clock clock_dt = q.clock_dt;
    const Time t0 = q.t0, t1 = q.t1;
    const bool bridge_stage = q.bridge_stage;
    const std::size_t count = q.count;
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC ivdep
#endif
    for (std::size_t j = 0; j < count; ++j) {
        const L s_z = sz[j], s_y = sy[j], s_ny = sny[j];
        const L z = x;
        const L yd0 = s_y - s_ny;
        const L yd = z + (yd0 - s_z) * sf_decay - (z - s_z) * sf_ramp;
        const L ny = phi_yy * s_ny + l_yy * g1[j];
        const L y = yd + ny;
        Clock on = Clock(0), off = Clock(0);
        bool ran_out = false;  // Due: in the due time, tested with hot[j]
        if constexpr (!Due) {
            on = son[j] - bon[j] * clock_dt;
            off = soff[j] - boff[j] * clock_dt;
            ran_out = !((on > Clock(0)) & (off > Clock(0)));
        }
        const L th_on = th_on_a[j], th_off = th_off_a[j];
        const L g = (y - s_y) * inv_dt + leak_g[j];
        const L db = s_y - sref[j];
        const L d1 = db + g * dt;
        const L on0 = th_on - db, off0 = th_off + db;
        const bool plain = (static_cast<L>(rate[j]) == common) & !ran_out & (hot[j] > t1) & (refr[j] <= t0);
        const L on1 = th_on - d1, off1 = th_off + d1;
        const bool between0 = std::min(on0, off0) > L(0);
        const bool quiet = plain & between0 & (std::min(on0 * on1, off0 * off1) > bridge_bound);
        const bool bridge = bridge_stage & plain & between0 & (std::min(on1, off1) > L(0));
        oref[j] = y - d1;
        oz[j] = z;
        oy[j] = y;
        ony[j] = ny;
        if constexpr (!Due) {
            oon[j] = on;
            ooff[j] = off;
        }
        const Flag not_quiet = !quiet;
        busy[j] = 2u * not_quiet - (not_quiet & static_cast<Flag>(bridge));
    }
}

// The study passes at the engine's SIMD levels, chosen as the engine chooses (simd_level()).
#define STUDY_QUIET_PASS_LEVEL(NAME, TARGET)                                                                  \
    template <class L, class Clock, class Time, bool Due>                                                     \
    TARGET __attribute__((noinline)) void NAME(const StudyPass<L, Clock, Time, Due>& q, const float* rate) { \
        quiet_pass_body(q, rate);                                                                             \
    }
STUDY_QUIET_PASS_LEVEL(quiet_pass_baseline, )
STUDY_QUIET_PASS_LEVEL(quiet_pass_avx2, EVSTWIN_TARGET_AVX2)
STUDY_QUIET_PASS_LEVEL(quiet_pass_avx512, EVSTWIN_TARGET_AVX512)
#undef STUDY_QUIET_PASS_LEVEL

template <class L, class Clock, class Time, bool Due>
void quiet_pass(const StudyPass<L, Clock, Time, Due>& q, const float* rate) {
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
    switch (evstwin::simd_level()) {
        case SimdLevel::AVX512: return ziggurat_batch_avx512(w, n, g, slow);
        case SimdLevel::AVX2: return ziggurat_batch_avx2(w, n, g, slow);
        default: return ziggurat_batch_baseline(w, n, g, slow);
    }
}

// GCC 12 does not use gather instructions for the loops above (its generic tuning turns them
// off): the float batch above looks the tables up lane by lane (extracts and inserts), which is
// most of its cost, as the engine's double batch did until simd.hpp wrote its gathers out. So
// the precision's share is measured against look-ups written with AVX-512 intrinsics: the
// engine's double gather, a float gather, and in-register permutes of the 128-entry tables in
// both precisions (no memory access per lane). The double permutes give the engine's normals
// bit for bit (checked in speed()): the sign by an XOR, as x * (1 - 2 bit) flips it exactly.
// The last n % 16 words go to the plain loops.

// GCC 12's AVX-512 intrinsics leave an undefined vector that -Wmaybe-uninitialized reports (GCC
// bug 105593, as simd.hpp notes): silenced for these functions only.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
/// A lane mask's flags as bytes 0 / 1 (the engine's slow flags).
#define STUDY_STORE_FLAGS16(P, M) _mm_storeu_si128(reinterpret_cast<__m128i*>(P), _mm_maskz_mov_epi8(M, _mm_set1_epi8(1)))

EVSTWIN_TARGET_AVX512 __attribute__((noinline)) void ziggurat_gather_f(const std::uint32_t* w, std::size_t n,
                                                                      float* g, std::uint8_t* slow) {
    const __m512i m127 = _mm512_set1_epi32(127), one = _mm512_set1_epi32(1);
    std::size_t i = 0;
    for (; i + 16 <= n; i += 16) {
        const __m512i wi = _mm512_loadu_si512(w + i);
        const __m512i layer = _mm512_and_si512(wi, m127), j = _mm512_srli_epi32(wi, 8);
        const __m512 x = _mm512_mul_ps(_mm512_cvtepi32_ps(j), _mm512_i32gather_ps(layer, ZIG_F.w, 4));
        const __m512i bits = _mm512_slli_epi32(_mm512_and_si512(_mm512_srli_epi32(wi, 7), one), 31);
        _mm512_storeu_ps(g + i, _mm512_castsi512_ps(_mm512_xor_si512(_mm512_castps_si512(x), bits)));
        const __mmask16 s =
            _mm512_cmpge_epu32_mask(j, _mm512_i32gather_epi32(layer, reinterpret_cast<const int*>(ZIG_F.k), 4));
        STUDY_STORE_FLAGS16(slow + i, s);
    }
    ziggurat_batch_avx512(w + i, n - i, g + i, slow + i);
}

/// The 128-entry table t (16 lanes a register) at index bits 0-6 of idx: four two-register
/// permutes (bits 0-4) and a choice by bits 5 and 6. For 32-bit entries.
#define STUDY_LOOKUP128_32(RESULT, PERM, BLEND, T, IDX)                                          \
    do {                                                                                         \
        const __mmask16 b5 = _mm512_test_epi32_mask(IDX, _mm512_set1_epi32(32));                 \
        const __mmask16 b6 = _mm512_test_epi32_mask(IDX, _mm512_set1_epi32(64));                 \
        const auto q0 = PERM(T[0], IDX, T[1]), q1 = PERM(T[2], IDX, T[3]);                       \
        const auto q2 = PERM(T[4], IDX, T[5]), q3 = PERM(T[6], IDX, T[7]);                       \
        RESULT = BLEND(b6, BLEND(b5, q0, q1), BLEND(b5, q2, q3));                                \
    } while (0)

EVSTWIN_TARGET_AVX512 __attribute__((noinline)) void ziggurat_permute_f(const std::uint32_t* w, std::size_t n,
                                                                       float* g, std::uint8_t* slow) {
    __m512 tw[8];
    __m512i tk[8];
    for (int r = 0; r < 8; ++r) {
        tw[r] = _mm512_loadu_ps(ZIG_F.w + 16 * r);
        tk[r] = _mm512_loadu_si512(ZIG_F.k + 16 * r);
    }
    const __m512i m127 = _mm512_set1_epi32(127), one = _mm512_set1_epi32(1);
    std::size_t i = 0;
    for (; i + 16 <= n; i += 16) {
        const __m512i wi = _mm512_loadu_si512(w + i);
        const __m512i layer = _mm512_and_si512(wi, m127), j = _mm512_srli_epi32(wi, 8);
        __m512 width;
        __m512i k;
        STUDY_LOOKUP128_32(width, _mm512_permutex2var_ps, _mm512_mask_blend_ps, tw, layer);
        STUDY_LOOKUP128_32(k, _mm512_permutex2var_epi32, _mm512_mask_blend_epi32, tk, layer);
        const __m512 x = _mm512_mul_ps(_mm512_cvtepi32_ps(j), width);
        const __m512i bits = _mm512_slli_epi32(_mm512_and_si512(_mm512_srli_epi32(wi, 7), one), 31);
        _mm512_storeu_ps(g + i, _mm512_castsi512_ps(_mm512_xor_si512(_mm512_castps_si512(x), bits)));
        STUDY_STORE_FLAGS16(slow + i, _mm512_cmpge_epu32_mask(j, k));
    }
    ziggurat_batch_avx512(w + i, n - i, g + i, slow + i);
}

EVSTWIN_TARGET_AVX512 __attribute__((noinline)) void ziggurat_permute_d(const std::uint32_t* w, std::size_t n,
                                                                       double* g, std::uint8_t* slow) {
    // The widths: 128 doubles in 16 registers; a two-register permute covers 16 (bits 0-3),
    // bits 4-6 choose among the eight.
    __m512d tw[16];
    __m512i tk[8];
    for (int r = 0; r < 16; ++r) tw[r] = _mm512_loadu_pd(evstwin::ZIGGURAT.w + 8 * r);
    for (int r = 0; r < 8; ++r) tk[r] = _mm512_loadu_si512(evstwin::ZIGGURAT.k + 16 * r);
    const __m512i m127 = _mm512_set1_epi32(127), one = _mm512_set1_epi32(1);
    std::size_t i = 0;
    for (; i + 16 <= n; i += 16) {
        const __m512i wi = _mm512_loadu_si512(w + i);
        const __m512i layer = _mm512_and_si512(wi, m127), j = _mm512_srli_epi32(wi, 8);
        const __m512i sign = _mm512_and_si512(_mm512_srli_epi32(wi, 7), one);
        __m512i k;
        STUDY_LOOKUP128_32(k, _mm512_permutex2var_epi32, _mm512_mask_blend_epi32, tk, layer);
        STUDY_STORE_FLAGS16(slow + i, _mm512_cmpge_epu32_mask(j, k));
        for (int h = 0; h < 2; ++h) {
            const __m256i lh = h ? _mm512_extracti64x4_epi64(layer, 1) : _mm512_castsi512_si256(layer);
            const __m256i jh = h ? _mm512_extracti64x4_epi64(j, 1) : _mm512_castsi512_si256(j);
            const __m256i sh = h ? _mm512_extracti64x4_epi64(sign, 1) : _mm512_castsi512_si256(sign);
            const __m512i idx = _mm512_cvtepu32_epi64(lh);
            const __mmask8 b4 = _mm512_test_epi64_mask(idx, _mm512_set1_epi64(16));
            const __mmask8 b5 = _mm512_test_epi64_mask(idx, _mm512_set1_epi64(32));
            const __mmask8 b6 = _mm512_test_epi64_mask(idx, _mm512_set1_epi64(64));
            __m512d q[8];
            for (int r = 0; r < 8; ++r) q[r] = _mm512_permutex2var_pd(tw[2 * r], idx, tw[2 * r + 1]);
            const __m512d a0 = _mm512_mask_blend_pd(b4, q[0], q[1]), a1 = _mm512_mask_blend_pd(b4, q[2], q[3]);
            const __m512d a2 = _mm512_mask_blend_pd(b4, q[4], q[5]), a3 = _mm512_mask_blend_pd(b4, q[6], q[7]);
            const __m512d width = _mm512_mask_blend_pd(b6, _mm512_mask_blend_pd(b5, a0, a1), _mm512_mask_blend_pd(b5, a2, a3));
            const __m512d x = _mm512_mul_pd(_mm512_cvtepi32_pd(jh), width);
            const __m512i bits = _mm512_slli_epi64(_mm512_cvtepu32_epi64(sh), 63);
            _mm512_storeu_pd(g + i + 8 * h, _mm512_castsi512_pd(_mm512_xor_si512(_mm512_castpd_si512(x), bits)));
        }
    }
    evstwin::detail::ZigguratBatch::run(evstwin::SimdAvx512{}, w + i, n - i, g + i, slow + i);
}
#undef STUDY_LOOKUP128_32
#undef STUDY_STORE_FLAGS16
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

}  // namespace study

namespace {

const char* level_names[] = {"baseline", "avx2", "avx512"};

// ---------------------------------------------------------------------------------------------
// Part 1 and 2: the timings.

void speed() {
    std::printf("== speed: ns per pixel-update, the least of 60 (quiet pass: 5 x 60) repetitions of 400 calls of a block "
                "(wall clock, one thread) ==\n");
    EngineBlock block(3000);  // 3 s of the reference load's background: a block as it stands mid-run
    EnginePass e(block);
    // The engine's whole block kernel for context (normals, quiet pass, bridge stage, per-pixel
    // path, events): a second copy of that block, run on for 60 x 200 samples past the snapshot.
    EngineBlock kernel_block(3000);
    const double kernel_ns = min_seconds_per_call([&] { kernel_block.step(); }, 200, 60) / BLOCK * 1e9;
    // The study's passes: StudyPass<levels, clocks, times, due> (float levels re-based).
    study::StudyCase<double, double, double> c_dd(e);
    study::StudyCase<double, double, double, true> c_ddue(e);
    study::StudyCase<float, float, float> c_fff(e);
    study::StudyCase<float, float, double> c_ffd(e);
    study::StudyCase<float, double, float> c_fdf(e);
    study::StudyCase<float, double, double> c_fdd(e);
    study::StudyCase<float, float, float, true> c_fdue(e);
    struct Variant {
        const char* name;
        void (*run)(const void*, const float*);
        const void* q;
    };
    // A pass as a plain function of its QuietPass (type-erased, so the variants sit in one table).
    const auto as_variant = [](const char* name, const auto& q) {
        using Q = std::decay_t<decltype(q)>;
        return Variant{name, [](const void* p, const float* r) { study::quiet_pass(*static_cast<const Q*>(p), r); }, &q};
    };
    const Variant variants[] = {
        {"engine: detail::quiet_pass (double)",
         [](const void* p, const float* r) {
             evstwin::detail::quiet_pass<QuietChain::SfOnly>(*static_cast<const evstwin::QuietPass*>(p), r, true, true);
         },
         &e.q},
        as_variant("study, double (the engine's, as a check)", c_dd.q),
        as_variant("study, double, clocks as due times", c_ddue.q),
        as_variant("float levels, float clocks, float times", c_fff.q),
        as_variant("float levels, float clocks, double times", c_ffd.q),
        as_variant("float levels, double clocks, float times", c_fdf.q),
        as_variant("float levels, double clocks, double times", c_fdd.q),
        as_variant("float levels, clocks as due times (float)", c_fdue.q),
    };
    constexpr std::size_t N_VARIANTS = sizeof(variants) / sizeof(variants[0]);
    const SimdLevel levels[] = {SimdLevel::AVX512, SimdLevel::AVX2, SimdLevel::Baseline};
    // Five rounds over all variants, the least of each kept: a disturbance of the shared machine
    // then cannot favour one variant by hitting another's only measurement.
    double ns[N_VARIANTS][3];
    for (auto& row : ns) std::fill(row, row + 3, std::numeric_limits<double>::infinity());
    for (int round = 0; round < 5; ++round) {
        for (SimdLevel l : levels) {
            if (!evstwin::simd_level_supported(l)) continue;
            evstwin::set_simd_level(l);
            for (std::size_t v = 0; v < N_VARIANTS; ++v) {
                const double t = min_seconds_per_call([&] {
                    variants[v].run(variants[v].q, block.rate.data());
                    keep(e.q.busy[0]);
                }, 400, 60) / BLOCK * 1e9;
                ns[v][static_cast<int>(l)] = std::min(ns[v][static_cast<int>(l)], t);
            }
        }
    }
    evstwin::set_simd_level(evstwin::best_simd_level());
    std::printf("engine step_block_soa, whole (reference pixel, background block, %s): %.2f ns\n",
                evstwin::simd_level_name(evstwin::simd_level()), kernel_ns);
    std::printf("\n-- quiet pass, ns per pixel-update (in brackets: the engine's time over it) --\n");
    std::printf("%-44s %16s %16s %16s\n", "", "avx512", "avx2", "baseline");
    for (std::size_t v = 0; v < N_VARIANTS; ++v) {
        std::printf("%-44s", variants[v].name);
        for (SimdLevel l : levels) {
            const int k = static_cast<int>(l);
            if (!evstwin::simd_level_supported(l)) std::printf(" %16s", "-");
            else std::printf(" %8.3f (%4.2fx)", ns[v][k], ns[0][k] / ns[v][k]);
        }
        std::printf("\n");
    }
    const int best = static_cast<int>(evstwin::best_simd_level());
    // The double reference: the faster of the engine's pass and the study's (the same bits; on
    // a shared machine either may draw a disturbed figure).
    const double quiet_engine = ns[0][best], quiet_d = std::min(ns[0][best], ns[1][best]), quiet_ddue = ns[2][best], quiet_all_f = ns[3][best],
                 quiet_dbl_clocks = std::min(ns[5][best], ns[6][best]), quiet_due = ns[7][best];
    // The verdicts on this snapshot (part 3 measures how often they would differ over a run), and
    // the study's double pass against the engine's, bit for bit.
    evstwin::detail::quiet_pass<QuietChain::SfOnly>(e.q, block.rate.data(), true, true);
    for (const Variant& v : variants) v.run(v.q, block.rate.data());
    std::size_t n_quiet = 0, differ_f = 0, differ_due = 0, differ_ddue = 0;
    bool same_levels = true;
    const BlockSoA::Levels& eng = *e.q.next;
    for (std::size_t j = 0; j < BLOCK; ++j) {
        n_quiet += e.q.busy[j] == 0;
        differ_f += e.q.busy[j] != c_fff.q.busy[j];
        differ_due += e.q.busy[j] != c_fdue.q.busy[j];
        differ_ddue += e.q.busy[j] != c_ddue.q.busy[j];
        same_levels &= e.q.busy[j] == c_dd.q.busy[j] && eng.z[j] == c_dd.b.buf[1].z[j] && eng.y[j] == c_dd.b.buf[1].y[j] &&
                  eng.ny[j] == c_dd.b.buf[1].ny[j] && eng.ref[j] == c_dd.b.buf[1].ref[j] &&
                  eng.clock_on[j] == c_dd.b.buf[1].on[j] && eng.clock_off[j] == c_dd.b.buf[1].off[j];
    }
    std::printf("snapshot: %zu of %zu pixels quiet (engine); the study's double pass gives the engine's levels and verdicts "
                "bit for bit: %s; verdicts that differ from the engine's: %zu (float, all float), %zu (float, due times), "
                "%zu (double, due times)\n",
                n_quiet, BLOCK, same_levels ? "yes" : "NO", differ_f, differ_due, differ_ddue);
    // Single precision keeps the engine's rule that every SIMD level gives the same bits (IEEE
    // float operations in the same order, nothing contracted): the all-float pass at each level.
    {
        std::vector<float> first_y, first_ref;
        std::vector<std::uint32_t> first_busy;
        bool same_at_levels = true;
        for (SimdLevel l : levels) {
            if (!evstwin::simd_level_supported(l)) continue;
            evstwin::set_simd_level(l);
            study::quiet_pass(c_fff.q, block.rate.data());
            if (first_y.empty()) {
                first_y = c_fff.b.buf[1].y;
                first_ref = c_fff.b.buf[1].ref;
                first_busy = c_fff.b.busy;
            } else {
                same_at_levels &= std::memcmp(first_y.data(), c_fff.b.buf[1].y.data(), BLOCK * sizeof(float)) == 0 &&
                                  std::memcmp(first_ref.data(), c_fff.b.buf[1].ref.data(), BLOCK * sizeof(float)) == 0 &&
                                  first_busy == c_fff.b.busy;
            }
        }
        evstwin::set_simd_level(evstwin::best_simd_level());
        std::printf("the all-float pass gives the same bits at every SIMD level: %s\n", same_at_levels ? "yes" : "NO");
    }

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
    BlockModel::BlockScratch scratch;
    scratch.resize(BLOCK);
    const evstwin::Philox4x32Key key = evstwin::key_from_seed(7);
    evstwin::philox4x32_batch(c0.data(), c1.data(), c2.data(), evstwin::PURPOSE_SAMPLE, key, BLOCK, r0.data(), r1.data(),
                              r2.data(), r3.data());
    std::printf("%-10s %12s %12s %12s %14s %14s\n", "level", "Philox call", "zig double", "zig float",
                "engine normals", "+ slow path");
    std::printf("%-10s %12s %12s %12s %14s %14s\n", "", "per pixel", "common path", "common path",
                "(draw_floor)", "(of which)");
    double philox_ns = 0, zd_ns = 0, zf_ns = 0, full_ns = 0;
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
                    BlockModel::batch_sample_normals(
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
            philox_ns = ph; zd_ns = zd; zf_ns = zf; full_ns = f;
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

    // The table look-ups written with AVX-512 intrinsics (study::ziggurat_gather_*, _permute_*);
    // without AVX-512 the study ends here (no summary).
    if (!evstwin::simd_level_supported(SimdLevel::AVX512)) return;
    std::vector<double> gd2(BLOCK);
    std::vector<float> gf2(BLOCK);
    std::vector<std::uint8_t> slow2(BLOCK);
    evstwin::set_simd_level(SimdLevel::AVX512);
    evstwin::ziggurat_batch(r0.data(), BLOCK, gd.data(), slow.data());
    study::ziggurat_batch(r0.data(), BLOCK, gf.data(), slow2.data());
    const auto same_d = [&] {
        return std::memcmp(gd.data(), gd2.data(), BLOCK * sizeof(double)) == 0 && slow == slow2;
    };
    const auto same_f = [&] { return std::memcmp(gf.data(), gf2.data(), BLOCK * sizeof(float)) == 0 && slow == slow2; };
    // The float normals against the engine's double ones (common path only).
    double rel = 0.0;
    for (std::size_t j = 0; j < BLOCK; ++j)
        if (!slow[j] && gd[j] != 0.0) rel = std::max(rel, std::fabs(static_cast<double>(gf[j]) - gd[j]) / std::fabs(gd[j]));
    const int calls = 400, reps = 60;
    std::printf("\n-- ziggurat common path at avx512 with the table look-ups written by hand, ns per normal --\n");
    std::printf("%-34s %10s %26s\n", "", "ns", "same as the engine's batch");
    // The engine's double batch is itself written with gathers (simd.hpp, since this study).
    std::printf("%-34s %10.3f %26s\n", "double, engine (simd.hpp: gathers)", zd_ns, "-");
    const double zd_gather = zd_ns;
    std::fill(gd2.begin(), gd2.end(), 0.0);
    study::ziggurat_permute_d(r0.data(), BLOCK, gd2.data(), slow2.data());
    bool ok = same_d();
    double t = min_seconds_per_call([&] { study::ziggurat_permute_d(r0.data(), BLOCK, gd2.data(), slow2.data()); keep(gd2[0]); },
                             calls, reps) / BLOCK * 1e9;
    std::printf("%-34s %10.3f %26s\n", "double, permutes (no memory)", t, ok ? "yes, bit for bit" : "NO");
    const double zd_best = std::min(zd_gather, t);
    std::printf("%-34s %10.3f %26s\n", "float, plain loop (GCC)", zf_ns, "float: the study's batch");
    study::ziggurat_gather_f(r0.data(), BLOCK, gf2.data(), slow2.data());
    ok = same_f();
    t = min_seconds_per_call([&] { study::ziggurat_gather_f(r0.data(), BLOCK, gf2.data(), slow2.data()); keep(gf2[0]); },
                             calls, reps) / BLOCK * 1e9;
    std::printf("%-34s %10.3f %26s\n", "float, gather", t, ok ? "yes, bit for bit" : "NO");
    const double zf_gather = t;
    std::fill(gf2.begin(), gf2.end(), 0.0f);
    study::ziggurat_permute_f(r0.data(), BLOCK, gf2.data(), slow2.data());
    ok = same_f();
    t = min_seconds_per_call([&] { study::ziggurat_permute_f(r0.data(), BLOCK, gf2.data(), slow2.data()); keep(gf2[0]); },
                             calls, reps) / BLOCK * 1e9;
    std::printf("%-34s %10.3f %26s\n", "float, permutes (no memory)", t, ok ? "yes, bit for bit" : "NO");
    const double zf_best = std::min(zf_gather, t);
    std::printf("float normals against the engine's double: largest relative difference %.2e (common path)\n", rel);
    std::printf("best double look-up saves %.3f ns on the engine's batch (bit for bit); float's best saves a further %.3f\n",
                zd_ns - zd_best, zd_best - zf_best);
    evstwin::set_simd_level(evstwin::best_simd_level());

    // What single precision itself buys a pixel-update at this level: each float pass against the
    // double one (the study's is the same code but for the type; the engine's own pass, the same
    // arithmetic and bits, times ~10 % slower here), and the ziggurat against the best double
    // look-up (the rest of the engine's gain there is the look-up's vectorisation, which double
    // gets bit for bit).
    std::printf("\n== summary at %s, ns per pixel-update ==\n", evstwin::simd_level_name(evstwin::simd_level()));
    std::printf("quiet pass in double: engine %.3f, study %.3f (same bits); the faster is the reference below\n",
                quiet_engine, ns[1][best]);
    std::printf("single precision, upper bound (all float):                      quiet pass %.3f + normals %.3f = %.3f\n",
                quiet_d - quiet_all_f, zd_best - zf_best, quiet_d - quiet_all_f + zd_best - zf_best);
    std::printf("single precision, clocks in double (3c; the faster of the two):  quiet pass %.3f + normals %.3f = %.3f\n",
                quiet_d - quiet_dbl_clocks, zd_best - zf_best, quiet_d - quiet_dbl_clocks + zd_best - zf_best);
    std::printf("clocks as due times, in double (any precision):                 quiet pass %.3f\n", quiet_d - quiet_ddue);
    std::printf("single precision on top of due times:                           quiet pass %.3f + normals %.3f = %.3f\n",
                quiet_ddue - quiet_due, zd_best - zf_best, quiet_ddue - quiet_due + zd_best - zf_best);
    // The engine's batch gathers; permutes can only beat it where gathers are slow (microcode).
    std::printf("without precision: ziggurat look-up by permutes instead of the engine's gathers (same bits) %.3f; "
                "every Philox word used (other words, any precision) %.3f\n",
                zd_ns - zd_best, philox_ns / 4);
}

// ---------------------------------------------------------------------------------------------
// Part 3: fidelity.

/// One pixel's quiet-pass state, levels in precision T (the reference load's chain: SfOnly,
/// noise and background on) relative to a base level kept outside (0: absolute), eq. 12's
/// clocks in C.
template <class T, class C = T>
struct Track {
    T z, y, ny, ref;
    C on, off;
};

/// The quiet pass's arithmetic for one pixel and sample, in T (quiet_pass_body's operations in
/// its order); returns d1, sets quiet (the pass's verdict without the time and rate terms).
template <class T, class C>
T quiet_step(Track<T, C>& s, T x, T g, T th_on, T th_off, T leak_g, C bon, C boff, T sf_decay, T sf_ramp, T phi_yy,
             T l_yy, T bridge_bound, T dt, T inv_dt, C clock_dt, bool& quiet, bool& ran_out, T& db_out) {
    const T z = x;
    const T yd0 = s.y - s.ny;
    const T yd = z + (yd0 - s.z) * sf_decay - (z - s.z) * sf_ramp;
    const T ny = phi_yy * s.ny + l_yy * g;
    const T y = yd + ny;
    const C on = s.on - bon * clock_dt, off = s.off - boff * clock_dt;
    ran_out = !((on > C(0)) & (off > C(0)));
    const T gs = (y - s.y) * inv_dt + leak_g;
    const T db = s.y - s.ref;
    const T d1 = db + gs * dt;
    db_out = db;
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

/// quiet_step() for pixel s in T and C from the double numbers of the sample (c, cache) and
/// of the pixel (leak_g, bon, boff): each rounded once to the track's precision. x: the
/// common level, already re-based where the track is.
template <class T, class C>
T quiet_step_from(Track<T, C>& tr, double x, double g, const PixelState& s, double leak_g, double bon, double boff,
                  const SampleConstants& c, const NoiseCache& cache, bool& quiet, bool& ran_out, T& db_out) {
    return quiet_step<T, C>(tr, static_cast<T>(x), static_cast<T>(g), static_cast<T>(s.theta_on),
                            static_cast<T>(s.theta_off), static_cast<T>(leak_g), static_cast<C>(bon), static_cast<C>(boff),
                            static_cast<T>(c.sf_decay), static_cast<T>(c.sf_ramp), static_cast<T>(cache.k.phi_yy),
                            static_cast<T>(cache.k.l_yy), static_cast<T>(cache.bridge_bound), static_cast<T>(c.dt),
                            static_cast<T>(c.inv_dt), static_cast<C>(c.dt), quiet, ran_out, db_out);
}

struct StudyEvent {
    std::uint32_t pixel;
    std::uint32_t sample;
    std::int8_t pol;      ///< +1 ON, -1 OFF (crossing); +2 / -2 eq. 12's background
    double t;             ///< its time [s]: a crossing's on the line from d0 to d1, a background one's from its clock
    bool operator<(const StudyEvent& o) const {
        return pixel != o.pixel ? pixel < o.pixel : sample != o.sample ? sample < o.sample : pol < o.pol;
    }
};

/// How two event lists (sorted) agree: events at the same pixel, sample and polarity; for the
/// others, the nearest event of the same pixel and polarity; the pixels whose lists agree
/// entirely; the counts of each kind; and the timestamps of the background events matched.
void compare_events(const char* name, const std::vector<StudyEvent>& ref, const std::vector<StudyEvent>& other,
                    std::size_t n_pix) {
    std::size_t same = 0, near1 = 0, near10 = 0;
    // The matched events' times, crossings [0] and background [1]: mean and largest
    // difference, and how many microsecond timestamps (the engine's) differ.
    std::size_t matched[2] = {}, other_us[2] = {};
    double dt_max[2] = {}, dt_sum[2] = {};
    std::vector<char> pixel_differs(n_pix, 0);
    std::size_t i = 0, j = 0;
    while (i < ref.size() && j < other.size()) {  // exact matches by a merge
        const StudyEvent &a = ref[i], &b = other[j];
        if (a.pixel == b.pixel && a.sample == b.sample && a.pol == b.pol) {
            ++same;
            const int kind = a.pol == 2 || a.pol == -2;
            const double d = std::fabs(a.t - b.t);
            dt_max[kind] = std::max(dt_max[kind], d);
            dt_sum[kind] += d;
            ++matched[kind];
            other_us[kind] += std::llround(a.t * 1e6) != std::llround(b.t * 1e6);
            ++i; ++j;
        } else if (a < b) {
            pixel_differs[a.pixel] = 1;
            ++i;
        } else {
            pixel_differs[b.pixel] = 1;
            ++j;
        }
    }
    for (; i < ref.size(); ++i) pixel_differs[ref[i].pixel] = 1;
    for (; j < other.size(); ++j) pixel_differs[other[j].pixel] = 1;
    // The unmatched: the nearest event of the same pixel and polarity (the lists are short per pixel).
    std::size_t a = 0;
    for (const StudyEvent& ev : ref) {
        while (a < other.size() && other[a].pixel < ev.pixel) ++a;
        std::uint32_t best = std::numeric_limits<std::uint32_t>::max();
        for (std::size_t b = a; b < other.size() && other[b].pixel == ev.pixel; ++b) {
            if (other[b].pol != ev.pol) continue;
            best = std::min(best, ev.sample > other[b].sample ? ev.sample - other[b].sample : other[b].sample - ev.sample);
        }
        if (best == 0) continue;
        near1 += best <= 1;
        near10 += best <= 10;
    }
    const auto kinds = [](const std::vector<StudyEvent>& v, std::size_t& cross, std::size_t& bg) {
        cross = bg = 0;
        for (const StudyEvent& e : v) (e.pol == 1 || e.pol == -1 ? cross : bg) += 1;
    };
    std::size_t cross_d, bg_d, cross_o, bg_o;
    kinds(ref, cross_d, bg_d);
    kinds(other, cross_o, bg_o);
    std::size_t differ = 0;
    for (char c : pixel_differs) differ += c;
    const std::size_t others = ref.size() - same;
    std::printf("  %-18s %8zu events (double %zu; crossings %+.3f %%, background %+.3f %%): %6.2f %% identical; of the %zu "
                "others %zu within 1 sample, %zu within 10; %5.2f %% of pixels differ somewhere\n",
                name, other.size(), ref.size(),
                100.0 * (static_cast<double>(cross_o) - static_cast<double>(cross_d)) / static_cast<double>(cross_d),
                100.0 * (static_cast<double>(bg_o) - static_cast<double>(bg_d)) / static_cast<double>(bg_d),
                100.0 * static_cast<double>(same) / static_cast<double>(ref.size()), others, near1, near10,
                100.0 * static_cast<double>(differ) / static_cast<double>(n_pix));
    const char* kind_name[2] = {"crossings", "background"};
    for (int kind = 0; kind < 2; ++kind)
        if (matched[kind])
            std::printf("  %-18s %-10s at the same sample: %7zu; times differ by %.4f us on average, %.3f us at most; "
                        "%zu (%.3f %%) microsecond timestamps differ\n",
                        "", kind_name[kind], matched[kind], 1e6 * dt_sum[kind] / static_cast<double>(matched[kind]),
                        1e6 * dt_max[kind], other_us[kind],
                        100.0 * static_cast<double>(other_us[kind]) / static_cast<double>(matched[kind]));
}

void fidelity(std::size_t n_samples) {
    const std::size_t n_pix = 4096;
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
                double db_d;
                float db_f;
                quiet_step_from(d, cache.x, g, s, leak_g[j], bon[j], boff[j], c, cache, q, r, db_d);
                quiet_step_from(fa, cache.x, g, s, leak_g[j], bon[j], boff[j], c, cache, q, r, db_f);
                quiet_step_from(fr, cache.x - base, g, s, leak_g[j], bon[j], boff[j], c, cache, q, r, db_f);
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
    // a threshold, the reference then set to the level; eq. 12's clocks fire background events,
    // which also set the reference, and get a fresh budget -ln u). 3b: lockstep, each float
    // verdict from the double state of the same sample, so one sample's disagreement does not
    // carry over. 3c: each precision runs freely and the event lists are compared.
    struct Scenario {
        const char* name;
        double amplitude;  // the light's log level swings by this (1 Hz sine), on every pixel
    };
    for (const Scenario sc : {Scenario{"background light (the reference load's 99 % of pixels)", 0.0},
                              Scenario{"flickering light: ln I swings +-1 at 1 Hz (signal events)", 1.0}}) {
        std::printf("\n%s:\n", sc.name);
        const double base = cache.x;
        constexpr int TRACKS = 3;  // float absolute; float re-based; float re-based with double clocks
        const char* names[TRACKS] = {"float, absolute", "float, re-based", "re-based, dbl clk"};
        std::size_t verdict[TRACKS] = {}, crossing[TRACKS] = {}, busy_dbl = 0, cross_dbl = 0;
        std::vector<StudyEvent> ev_d, ev[TRACKS];
        for (std::size_t j = 0; j < n_pix; ++j) {
            const PixelState& s = st[j];
            const auto id = static_cast<std::uint32_t>(j);
            // A track's state from a double one (levels re-based by b, rounded).
            const auto from = [](const Track<double>& t, double b, auto& out) {
                using T = std::decay_t<decltype(out.y)>;
                using C = std::decay_t<decltype(out.on)>;
                out = {static_cast<T>(t.z - b), static_cast<T>(t.y - b), static_cast<T>(t.ny), static_cast<T>(t.ref - b),
                       static_cast<C>(t.on), static_cast<C>(t.off)};
            };
            Track<double> d{s.z, s.y, s.ny, s.ref, s.bg_clock_on, s.bg_clock_off};
            Track<float> fa{}, fr{};
            Track<float, double> fc{};
            from(d, 0.0, fa);
            from(d, base, fr);
            from(d, base, fc);
            // One sample of a track with base b; records its events.
            const auto run = [&](auto& tr, double b, double x, double g, double u, std::uint32_t k,
                                 std::vector<StudyEvent>* out, bool& quiet, int& cross) {
                using T = std::decay_t<decltype(tr.y)>;
                using C = std::decay_t<decltype(tr.on)>;
                bool ran_out;
                T db;
                const T d1 = quiet_step_from(tr, x - b, g, s, leak_g[j], bon[j], boff[j], c, cache, quiet, ran_out, db);
                cross = d1 >= static_cast<T>(s.theta_on) ? 1 : d1 <= -static_cast<T>(s.theta_off) ? -1 : 0;
                if (!out) return;
                if (cross) {
                    // Where the line from d0 to d1 meets the threshold, in double from the track's
                    // numbers (as the engine's per-pixel path would place it from a float state).
                    const double th = cross > 0 ? s.theta_on : -s.theta_off;
                    const double f = (th - static_cast<double>(db)) / (static_cast<double>(d1) - static_cast<double>(db));
                    out->push_back({id, k, static_cast<std::int8_t>(cross), (k + f) * DT});
                    tr.ref = tr.y;
                }
                if (ran_out) {
                    const bool on = !(tr.on > C(0));
                    // Its time after the sample's end, as background_fire: the budget left / rate.
                    const double left = on ? static_cast<double>(tr.on) / bon[j] : static_cast<double>(tr.off) / boff[j];
                    out->push_back({id, k, static_cast<std::int8_t>(on ? 2 : -2), (k + 1) * DT + left});
                    if (on) tr.on = tr.on + static_cast<C>(-std::log(u));
                    else tr.off = tr.off + static_cast<C>(-std::log(u));
                    if (!(tr.on > C(0))) tr.on = static_cast<C>(1e-30);
                    if (!(tr.off > C(0))) tr.off = static_cast<C>(1e-30);
                    tr.ref = tr.y;
                }
            };
            for (std::uint32_t k = 0; k < n_samples; ++k) {
                double g, u;
                draws(id, k + 1, g, u);
                const double x = cache.x + sc.amplitude * std::sin(2.0 * evstwin::PI * 1.0 * (k + 1) * DT);
                // 3b: the float verdicts from the double state as it stands.
                Track<float> la{}, lr{};
                Track<float, double> lc{};
                from(d, 0.0, la);
                from(d, base, lr);
                from(d, base, lc);
                bool q_d, q[TRACKS];
                int x_d, xs[TRACKS];
                run(la, 0.0, x, g, u, k, nullptr, q[0], xs[0]);
                run(lr, base, x, g, u, k, nullptr, q[1], xs[1]);
                run(lc, base, x, g, u, k, nullptr, q[2], xs[2]);
                run(d, 0.0, x, g, u, k, &ev_d, q_d, x_d);
                busy_dbl += !q_d;
                cross_dbl += x_d != 0;
                for (int t = 0; t < TRACKS; ++t) {
                    verdict[t] += q[t] != q_d;
                    crossing[t] += xs[t] != x_d;
                }
                // 3c: the free-running float tracks.
                run(fa, 0.0, x, g, u, k, &ev[0], q[0], xs[0]);
                run(fr, base, x, g, u, k, &ev[1], q[1], xs[1]);
                run(fc, base, x, g, u, k, &ev[2], q[2], xs[2]);
            }
        }
        const double total = static_cast<double>(n_pix) * static_cast<double>(n_samples);
        std::printf("3b. lockstep (one sample from the same double state), of %.0f pixel-samples: double busy %.4f %%, "
                    "crossing %.4f %%\n",
                    total, 100.0 * static_cast<double>(busy_dbl) / total, 100.0 * static_cast<double>(cross_dbl) / total);
        for (int t = 0; t < TRACKS; ++t)
            std::printf("  %-18s quiet/busy verdict differs %4zu times (%.2e), crossing differs %4zu times (%.2e)\n",
                        names[t], verdict[t], static_cast<double>(verdict[t]) / total, crossing[t],
                        static_cast<double>(crossing[t]) / total);
        std::printf("3c. free-running %zu samples, events against double's:\n", n_samples);
        std::sort(ev_d.begin(), ev_d.end());
        for (int t = 0; t < TRACKS; ++t) {
            std::sort(ev[t].begin(), ev[t].end());
            compare_events(names[t], ev_d, ev[t], n_pix);
        }
    }
}

}  // namespace

EVSTWIN_FP_STRICT_END

int main(int argc, char** argv) {
    const bool all = argc < 2;
    const long samples = argc >= 3 ? std::atol(argv[2]) : 10000;
    if (argc > 3 || (!all && std::strcmp(argv[1], "speed") != 0 && std::strcmp(argv[1], "fidelity") != 0) ||
        (argc == 3 && std::strcmp(argv[1], "fidelity") != 0)) {
        std::fprintf(stderr, "usage: %s [speed | fidelity [SAMPLES]]\n", argv[0]);
        return 2;
    }
    if (samples < 1 || samples > 1000000) {
        std::fprintf(stderr, "fidelity SAMPLES must be in [1, 1000000]; got %s\n", argv[2]);
        return 2;
    }
    std::printf("best SIMD level: %s\n", evstwin::simd_level_name(evstwin::best_simd_level()));
    if (all || std::strcmp(argv[1], "speed") == 0) speed();
    if (all || std::strcmp(argv[1], "fidelity") == 0) fidelity(static_cast<std::size_t>(samples));
    return 0;
}
