// The engine's batched Philox4x32-10 (simd.hpp's philox4x32_batch, as the block kernels call it:
// 256 counters a call, a block's pixels) at every SIMD level this processor and build run:
// ns per counter, best of 5 rounds. Checks each level's words against the scalar philox4x32.
//
//   g++ -std=c++17 -O3 -DNDEBUG -Icpp/include bench/philox_batch.cpp -o /tmp/philox_batch
//   /tmp/philox_batch
#include <evstwin/evstwin.hpp>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <vector>

int main() {
    using namespace evstwin;
    constexpr std::size_t n = 256;
    constexpr int calls = 100000;
    std::vector<std::uint32_t> c0(n), c1(n), c2(n), r0(n), r1(n), r2(n), r3(n);
    for (std::size_t i = 0; i < n; ++i) {
        c0[i] = static_cast<std::uint32_t>(i * 2654435761u);
        c1[i] = static_cast<std::uint32_t>(i >> 3);
        c2[i] = static_cast<std::uint32_t>(1000003u * i + 7u);
    }
    const Philox4x32Key key{{9u, 10u}};
    for (SimdLevel l : {SimdLevel::Baseline, SimdLevel::AVX2, SimdLevel::AVX512}) {
        if (!simd_level_supported(l)) continue;
        set_simd_level(l);
        double best = 1e30;
        std::uint32_t sum = 0;  // printed, so the calls are not optimised away
        for (int round = 0; round < 5; ++round) {
            const auto start = std::chrono::steady_clock::now();
            for (int k = 0; k < calls; ++k) {
                c0[0] = static_cast<std::uint32_t>(k);
                philox4x32_batch(c0.data(), c1.data(), c2.data(), PURPOSE_SAMPLE, key, n, r0.data(), r1.data(),
                                 r2.data(), r3.data());
                sum += r0[0];
            }
            best = std::min(best, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
        }
        std::size_t wrong = 0;
        for (std::size_t i = 0; i < n; ++i) {
            const Philox4x32Counter w = philox4x32({c0[i], c1[i], c2[i], PURPOSE_SAMPLE}, key);
            wrong += r0[i] != w[0] || r1[i] != w[1] || r2[i] != w[2] || r3[i] != w[3];
        }
        std::printf("%-8s %.2f ns per counter (%d calls of %zu, best of 5; %zu words differ from philox4x32; checksum %u)\n",
                    simd_level_name(l), best / calls / n * 1e9, calls, n, wrong, sum % 10u);
    }
    return 0;
}
