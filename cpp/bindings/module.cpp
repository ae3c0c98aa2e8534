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
    m.def("has_openmp", &evstwin::has_openmp, "Whether the engine was compiled with OpenMP.");
    m.def("default_num_threads", &evstwin::default_num_threads);
    register_pixel(m);
    register_sensor(m);
    register_readout(m);
}
