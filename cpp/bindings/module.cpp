// evstwin._core: the compiled engine. Private; the public API is the Python package.
#include "bindings.hpp"

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
    register_pixel(m);
    register_sensor(m);
    register_readout(m);
}
