// The input of one step of a sparse scene (Sensor::run_sparse, detail/sensor_sparse.hpp): a
// constant light map and the moving sources' light where it falls, at the step's samples.
#pragma once

#include <cstddef>
#include <cstdint>

namespace evstwin {

/// One step of a sparse scene for Sensor::run_sparse(): a constant light map over the step
/// plus the moving sources' light at its fine sample times, given where it falls (a PSF
/// stamp's pixels), never as full frames. Pointers stay the caller's; nothing is copied
/// before the call. Units: photons/s arriving on a pixel, seconds.
struct SparseStep {
    /// width * height photon rates, row-major: the light that does not change over the step
    /// (the sky's background, the sources that stay put).
    const double* static_rate = nullptr;
    /// The step's fine sample times, strictly increasing, after the sensor's last sample;
    /// t_s[n_samples - 1] ends the step: every pixel stands there after the call.
    const double* t_s = nullptr;
    std::size_t n_samples = 0;
    /// Fine samples per base sample: t_s[k] is a base time where (k + 1) % base_every == 0
    /// (n_samples must be a multiple). A pixel whose light has stopped changing but whose
    /// levels still relax (settle_time_s()) takes the base times only.
    std::size_t base_every = 1;
    /// Base samples per group: the granularity of the per-pixel choice of step. A pixel that
    /// a source touches in a group takes all the group's fine samples; one that still relaxes
    /// its base samples; every other pixel one long step across the group.
    std::size_t group_base_samples = 1;
    /// The moving sources' light: entry i adds light_rate[i] photons/s to pixel light_pixel[i]
    /// (row-major) at sample light_sample[i]. A pixel listed at a sample is lit at it (a rate
    /// of 0 included: the edge of a stamp); entries of one (sample, pixel) add up.
    const std::uint32_t* light_sample = nullptr;
    const std::uint32_t* light_pixel = nullptr;
    const double* light_rate = nullptr;
    std::size_t n_light = 0;
    /// Which pixels must stand at the step's end after the call: all of them (reach_all), or
    /// only those listed in reach_pixel (row-major) and those the step's light moved. A pixel
    /// left behind waits, its light constant, and a later step takes it on in one long step
    /// at that step's static light: list every pixel whose static light changes at this
    /// step's end. Events of a later step may then precede this step's last ones in time;
    /// they are in order again after a step with reach_all (merge the steps' events there).
    bool reach_all = true;
    const std::uint32_t* reach_pixel = nullptr;
    std::size_t n_reach = 0;
};

}  // namespace evstwin
