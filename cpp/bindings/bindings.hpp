// Shared declarations of the binding units. The only place pybind11 meets evstwin.
#pragma once

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <evstwin/evstwin.hpp>

namespace py = pybind11;


void register_pixel(py::module_& m);
void register_sensor(py::module_& m);
void register_readout(py::module_& m);
void register_psf(py::module_& m);

/// Move a std::vector into a NumPy array that owns it (freed with the array).
template <class T>
py::array_t<T> to_numpy(std::vector<T>&& v, std::vector<py::ssize_t> shape = {}) {
    auto* owned = new std::vector<T>(std::move(v));
    py::capsule free_when_done(owned, [](void* p) { delete static_cast<std::vector<T>*>(p); });
    if (shape.empty()) shape = {static_cast<py::ssize_t>(owned->size())};
    return py::array_t<T>(shape, owned->data(), free_when_done);
}
