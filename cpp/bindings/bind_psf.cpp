// The PSF renderer's two loops (evstwin/stamp.hpp) for evstwin.psf.
#include "bindings.hpp"

#include <pybind11/stl.h>

#include <string>
#include <vector>

namespace {

py::array_t<double> bilinear_phase_mix(py::array_t<double, py::array::c_style> table,
                                       py::array_t<std::ptrdiff_t, py::array::c_style> q,
                                       py::array_t<std::ptrdiff_t, py::array::c_style> p,
                                       py::array_t<double, py::array::c_style> a, py::array_t<double, py::array::c_style> b,
                                       py::array_t<double, py::array::c_style> flux) {
    if (table.ndim() != 4 || table.shape(0) != table.shape(1) || table.shape(2) != table.shape(3) || table.shape(0) < 2)
    {
        std::string shape = "(";
        for (py::ssize_t d = 0; d < table.ndim(); ++d) shape += (d ? ", " : "") + std::to_string(table.shape(d));
        throw py::value_error("table must be a (phases, phases, side, side) array with phases >= 2; got shape " + shape +
                              ")");
    }
    const py::ssize_t n = q.size();
    if (q.ndim() != 1 || p.ndim() != 1 || a.ndim() != 1 || b.ndim() != 1 || flux.ndim() != 1 || p.size() != n ||
        a.size() != n || b.size() != n || flux.size() != n)
        throw py::value_error("q, p, a, b and flux must be 1-D arrays of one length; got sizes " + std::to_string(q.size()) +
                              ", " + std::to_string(p.size()) + ", " + std::to_string(a.size()) + ", " +
                              std::to_string(b.size()) + ", " + std::to_string(flux.size()));
    const py::ssize_t phases = table.shape(0), side = table.shape(2);
    const std::ptrdiff_t* qq = q.data();
    const std::ptrdiff_t* pp = p.data();
    for (py::ssize_t s = 0; s < n; ++s)
        if (qq[s] < 0 || qq[s] > phases - 2 || pp[s] < 0 || pp[s] > phases - 2)
            throw py::value_error("q and p must lie in [0, " + std::to_string(phases - 2) + "]; got q[" + std::to_string(s) +
                                  "]=" + std::to_string(qq[s]) + ", p[" + std::to_string(s) + "]=" + std::to_string(pp[s]));
    py::array_t<double> out({n, side, side});
    {
        py::gil_scoped_release unlocked;
        evstwin::bilinear_phase_mix(table.data(), static_cast<std::size_t>(phases), static_cast<std::size_t>(side), qq, pp,
                                    a.data(), b.data(), flux.data(), static_cast<std::size_t>(n), out.mutable_data());
    }
    return out;
}

/// A 2-D float64 array's row stride in elements, checking that its columns are contiguous.
std::ptrdiff_t row_stride(const py::array& v, const char* name) {
    if (v.ndim() != 2 || !v.dtype().is(py::dtype::of<double>()))
        throw py::value_error(std::string(name) + " must be a 2-D float64 array; got ndim=" + std::to_string(v.ndim()) +
                              ", dtype=" + std::string(py::str(v.dtype())));
    if (v.shape(1) > 1 && v.strides(1) != static_cast<py::ssize_t>(sizeof(double)))
        throw py::value_error(std::string(name) + " must have contiguous rows; got strides " + std::to_string(v.strides(0)) +
                              ", " + std::to_string(v.strides(1)));
    if (v.strides(0) % static_cast<py::ssize_t>(sizeof(double)) != 0)
        throw py::value_error(std::string(name) + "'s row stride must be a multiple of 8 bytes");
    return v.strides(0) / static_cast<py::ssize_t>(sizeof(double));
}

void add_scaled_terms(py::array image, const std::vector<py::array>& terms, const std::vector<double>& coef) {
    if (terms.size() != coef.size() || terms.size() > 4)
        throw py::value_error("terms and coef must have one length, at most 4; got " + std::to_string(terms.size()) +
                              " and " + std::to_string(coef.size()));
    if (!image.writeable()) throw py::value_error("image must be writeable");
    const std::ptrdiff_t stride = row_stride(image, "image");
    const double* t[4] = {};
    std::ptrdiff_t ts[4] = {};
    for (std::size_t k = 0; k < terms.size(); ++k) {
        ts[k] = row_stride(terms[k], ("terms[" + std::to_string(k) + "]").c_str());
        if (terms[k].shape(0) != image.shape(0) || terms[k].shape(1) != image.shape(1))
            throw py::value_error("terms[" + std::to_string(k) + "] must have the image's shape (" +
                                  std::to_string(image.shape(0)) + ", " + std::to_string(image.shape(1)) + "); got (" +
                                  std::to_string(terms[k].shape(0)) + ", " + std::to_string(terms[k].shape(1)) + ")");
        t[k] = static_cast<const double*>(terms[k].data());
    }
    double* out = static_cast<double*>(image.mutable_data());
    py::gil_scoped_release unlocked;
    evstwin::add_scaled_terms(out, stride, t, ts, coef.data(), terms.size(), static_cast<std::size_t>(image.shape(0)),
                              static_cast<std::size_t>(image.shape(1)));
}

}  // namespace

void register_psf(py::module_& m) {
    m.def("bilinear_phase_mix", &bilinear_phase_mix, py::arg("table"), py::arg("q"), py::arg("p"), py::arg("a"),
          py::arg("b"), py::arg("flux"),
          "A tabulated PSF's bilinear mix of phases (q, p)..(q + 1, p + 1) with weights a, b, times flux: (S, side, side).");
    m.def("add_scaled_terms", &add_scaled_terms, py::arg("image"), py::arg("terms"), py::arg("coef"),
          "image += coef[0] terms[0] + ... in that order, term by term, skipping zero coefficients (in place).");
}
