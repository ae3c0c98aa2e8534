// evstwin._core: the compiled engine. Private; the public API is the Python package.
#include "bindings.hpp"

#include <pybind11/stl.h>

#include <string>
#include <vector>

PYBIND11_MODULE(_core, m) {
    m.doc() = "evstwin's C++ pixel engine (private: use the evstwin package)";
    // Register the record types once, before anything converts them.
    PYBIND11_NUMPY_DTYPE(evstwin::Event, t, x, y, p);
    PYBIND11_NUMPY_DTYPE(evstwin::TraceSample, current_a, log_current, filtered, reference);
    m.attr("__version__") = EVSTWIN_VERSION;
    m.attr("EVENT_DTYPE") = py::dtype::of<evstwin::Event>();
    m.attr("ELEMENTARY_CHARGE_C") = evstwin::ELEMENTARY_CHARGE_C;
    // Why an event fired: the label codes of evstwin::EventLabel.
    py::dict labels;
    labels[py::int_(int(evstwin::LABEL_SIGNAL))] = "signal";
    labels[py::int_(int(evstwin::LABEL_SHOT_NOISE))] = "shot_noise";
    labels[py::int_(int(evstwin::LABEL_LEAK))] = "leak";
    labels[py::int_(int(evstwin::LABEL_BACKGROUND))] = "background";
    labels[py::int_(int(evstwin::LABEL_HOT_PIXEL))] = "hot_pixel";
    m.attr("EVENT_LABELS") = labels;
    m.def("has_openmp", &evstwin::has_openmp, "Whether the engine was compiled with OpenMP.");
    m.def("default_num_threads", &evstwin::default_num_threads);
    // The instruction set of the engine's batched loops (simd.hpp): the same events at every
    // level; forcing one is for tests and benchmarks.
    // The instruction set of the engine's batched loops (simd.hpp): the same events at every
    // level; forcing one is for tests and benchmarks.
    static constexpr evstwin::SimdLevel LEVELS[] = {evstwin::SimdLevel::Baseline, evstwin::SimdLevel::AVX2,
                                                    evstwin::SimdLevel::AVX512};
    m.def("simd_levels", [] {
        std::vector<std::string> out;
        for (auto l : LEVELS)
            if (evstwin::simd_level_supported(l)) out.push_back(evstwin::simd_level_name(l));
        return out;
    }, "The SIMD levels this processor and build can run, lowest first.");
    m.def("simd_level", [] { return std::string(evstwin::simd_level_name(evstwin::simd_level())); },
          "The SIMD level the engine uses now (the best supported one unless set).");
    m.def("set_simd_level", [](const std::string& name) {
        std::string supported;
        for (auto l : LEVELS) {
            if (!evstwin::simd_level_supported(l)) continue;
            supported += (supported.empty() ? "'" : ", '") + std::string(evstwin::simd_level_name(l)) + "'";
            if (name == evstwin::simd_level_name(l)) return evstwin::set_simd_level(l);
        }
        throw py::value_error("level must be one of the SIMD levels this processor runs (" + supported +
                              "); got level='" + name + "'");
    }, py::arg("level"), "Force the SIMD level of the engine's batched loops (process-wide).");
    register_pixel(m);
    register_sensor(m);
    register_readout(m);
    register_psf(m);
}
