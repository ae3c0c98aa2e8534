// What the reference load's random numbers alone cost per pixel-update, with the engine's own
// batches: the floor under any kernel that draws the same noise (issue 15's speed goals).
//
// Per pixel and sample the continuous noise model with one low-pass needs one normal. This
// draws them as the block kernel does: one Philox4x32-10 call per pixel per two samples (its
// four words serve two samples; pixel.hpp's soa_sample_words) and PixelModel::
// batch_sample_normals (the ziggurat's common path as a batch, the ~2.8 % of normals in a
// wedge or the tail finished with their further words from one more Philox batch). Nothing
// else: no levels, no quiet test, no bookkeeping. So a kernel that draws these numbers cannot
// run faster than this on one core; the printed figure is an upper bound on pixel-updates/s.
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
    std::vector<std::uint32_t> ids(block);
    std::vector<double> g1(block), g2(block);
    BlockModel::BlockScratch scratch;
    scratch.resize(block);
    const Philox4x32Key key{{0x1234u, 0x5678u}};
    double sum = 0.0;
    const auto start = std::chrono::steady_clock::now();
    for (int b = 0; b < blocks; ++b) {
        for (std::size_t j = 0; j < block; ++j) ids[j] = c2[j] = static_cast<std::uint32_t>(b * block + j);
        for (int s = 0; s < samples; s += 2) {
            for (std::size_t j = 0; j < block; ++j) {
                c0[j] = static_cast<std::uint32_t>(s >> 1);
                c1[j] = 0u;
            }
            philox4x32_batch(c0.data(), c1.data(), c2.data(), PURPOSE_SAMPLE, key, block, r0.data(), r1.data(),
                             r2.data(), r3.data());
            for (int half = 0; half < 2; ++half) {
                const std::uint64_t sample = static_cast<std::uint64_t>(s + half);
                BlockModel::batch_sample_normals(
                    block, [sample](std::size_t) { return sample; }, [&ids](std::size_t j) { return ids[j]; }, key,
                    scratch, half ? r2.data() : r0.data(), half ? r3.data() : r1.data(), g1.data(), g2.data(), false);
                sum += g1[static_cast<std::size_t>(s) % block];
            }
        }
    }
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    const double updates = static_cast<double>(block) * samples * blocks;
    std::printf("SIMD level %s: %.2f ns per pixel-update for its normal, "
                "so at most %.0f M pixel-updates/s on one core (checksum %.3f)\n",
                simd_level_name(simd_level()), seconds / updates * 1e9, updates / seconds / 1e6, sum);
    return 0;
}
