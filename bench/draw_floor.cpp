// What the reference load's random numbers alone cost per pixel-update, with the engine's own
// batches: the floor under any kernel that draws the same noise (issue 15's speed goals).
//
// Per pixel and sample the continuous noise model with one low-pass needs one normal. The
// block kernel gets it as the engine does (pixel.hpp, soa_sample_words and
// batch_sample_normals): one Philox4x32-10 call per pixel per two samples (its four words
// serve two samples), the ziggurat's common path as a batch, and the few normals that fall in
// a wedge or the tail (2.8 %) finished one by one with further Philox words. Nothing else: no
// levels, no quiet test, no bookkeeping. So a kernel that draws these numbers cannot run
// faster than this on one core; the printed figure is an upper bound on pixel-updates/s.
//
//   g++ -std=c++17 -O3 -DNDEBUG -Icpp/include bench/draw_floor.cpp -o /tmp/draw_floor
//   /tmp/draw_floor            # prints ns per pixel-update and the bound in M updates/s
#include <evstwin/evstwin.hpp>

#include <chrono>
#include <cstdio>
#include <vector>

int main() {
    using namespace evstwin;
    constexpr std::size_t block = 256;  // the engine's pixels per block
    constexpr int samples = 4000, blocks = 90;
    std::vector<std::uint32_t> c0(block), c1(block), c2(block), r0(block), r1(block), r2(block), r3(block);
    std::vector<double> g(block);
    std::vector<std::uint8_t> slow(block);
    const Philox4x32Key key{{0x1234u, 0x5678u}};
    double sum = 0.0;
    std::size_t n_slow = 0;
    const auto start = std::chrono::steady_clock::now();
    for (int b = 0; b < blocks; ++b) {
        for (std::size_t j = 0; j < block; ++j) c2[j] = static_cast<std::uint32_t>(b * block + j);
        for (int s = 0; s < samples; s += 2) {
            for (std::size_t j = 0; j < block; ++j) {
                c0[j] = static_cast<std::uint32_t>(s >> 1);
                c1[j] = 0u;
            }
            philox4x32_batch(c0.data(), c1.data(), c2.data(), PURPOSE_SAMPLE, key, block, r0.data(), r1.data(),
                             r2.data(), r3.data());
            for (int half = 0; half < 2; ++half) {
                const std::uint32_t* w = half ? r2.data() : r0.data();
                ziggurat_batch(w, block, g.data(), slow.data());
                for (std::size_t j = 0; j < block; ++j) {
                    if (!slow[j]) continue;
                    ++n_slow;
                    CounterStream extra(key, c2[j], static_cast<std::uint64_t>(s + half), PURPOSE_NORMAL);
                    auto more = [&extra] { return extra.word(); };
                    g[j] = normal_ziggurat_slow(w[j], more);
                }
                for (std::size_t j = 0; j < block; ++j) sum += g[j];
            }
        }
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const double updates = static_cast<double>(block) * samples * blocks;
    std::printf("SIMD level %s: %.2f ns per pixel-update for its normal (%.4f of them slow), "
                "so at most %.0f M pixel-updates/s on one core (mean of the normals %.4f)\n",
                simd_level_name(simd_level()), seconds / updates * 1e9, static_cast<double>(n_slow) / updates,
                updates / seconds / 1e6, sum / updates);
    return 0;
}
