#include "bindings.hpp"

#include <pybind11/stl.h>

#include <cstdlib>
#include <new>
#include <optional>
#include <string>

using evstwin::Sensor;

namespace {

/// Arrays the engine reads through typed pointers: C-contiguous, native-endian and aligned
/// (NumPy copies an input that is not; reading a misaligned double is undefined behaviour).
constexpr int READ_FLAGS = py::array::c_style | py::array::forcecast | py::detail::npy_api::NPY_ARRAY_ALIGNED_;
using TimesArray = py::array_t<double, READ_FLAGS>;

std::string shape_str(const py::array& a) {
    std::string s = "(";
    for (py::ssize_t i = 0; i < a.ndim(); ++i) s += (i ? ", " : "") + std::to_string(a.shape(i));
    return s + (a.ndim() == 1 ? ",)" : ")");
}

/// A (T, height, width) view that repeats one C-contiguous frame (np.broadcast_to of a
/// static scene): read as that one frame, without a copy.
bool is_static_frames(const py::array& rate) {
    if (rate.ndim() != 3 || rate.shape(0) < 1 || rate.strides(0) != 0) return false;
    const auto item = rate.itemsize();
    return rate.strides(2) == item && rate.strides(1) == item * rate.shape(2);
}

/// Checks with the GIL held; returns a C-contiguous float32/float64 array (the same object
/// when it already is one, so no copy).
py::array checked_rates(const Sensor& s, py::array rate) {
    const auto kind = rate.dtype().kind();
    if (kind != 'f' || (rate.itemsize() != 4 && rate.itemsize() != 8))
        throw py::type_error("photon_rate must be a float32 or float64 array of photons/s; got dtype " +
                             std::string(py::str(rate.dtype())));
    if (rate.ndim() != 3 || rate.shape(1) != s.height() || rate.shape(2) != s.width())
        throw py::value_error("photon_rate must have shape (T, height, width) = (T, " + std::to_string(s.height()) +
                              ", " + std::to_string(s.width()) + "); got shape " + shape_str(rate));
    // The engine reads native-endian, aligned values: a big-endian array (a FITS or HDF5
    // file's bytes) would be read as garbage and an unaligned one is undefined behaviour, so
    // both are converted here (one copy; a static broadcast copies only its one frame).
    const bool native = rate.dtype().attr("isnative").cast<bool>();
    const bool aligned = rate.attr("flags").attr("aligned").cast<bool>();
    if (!native || !aligned) {
        auto np = py::module_::import("numpy");
        const py::object dtype = rate.dtype().attr("newbyteorder")("=");
        if (rate.ndim() == 3 && rate.shape(0) >= 1 && rate.strides(0) == 0) {  // a broadcast static scene
            py::array frame = np.attr("array")(rate[py::int_(0)], py::arg("dtype") = dtype, py::arg("order") = "C");
            return np.attr("broadcast_to")(frame, rate.attr("shape"));
        }
        return np.attr("array")(rate, py::arg("dtype") = dtype, py::arg("order") = "C");
    }
    if (!(rate.flags() & py::array::c_style)) rate = py::module_::import("numpy").attr("ascontiguousarray")(rate);
    return rate;
}

TimesArray checked_times(py::array t_s, py::ssize_t n) {
    if (t_s.dtype().kind() != 'f' && t_s.dtype().kind() != 'i' && t_s.dtype().kind() != 'u')
        throw py::type_error("t_s must be an array of real times in seconds; got dtype " +
                             std::string(py::str(t_s.dtype())));
    auto t = TimesArray::ensure(t_s);
    if (!t || t.ndim() != 1 || t.shape(0) != n)
        throw py::value_error("t_s must be 1-D with one time per sample of photon_rate (" + std::to_string(n) +
                              "); got shape " + shape_str(t_s));
    return t;
}

/// Room for a call's n >= 1 events, for NumPy: malloc'd, not zero-filled (every event is
/// written) and hinted for huge pages before the first touch, so the call's threads fault its
/// pages in as they fill them. std::vector's resize value-initialised the whole output on one
/// thread first: 246 MB a call of the event-heavy load, while the other thread waited.
evstwin::Event* new_event_buffer(std::size_t n) {
    auto* p = static_cast<evstwin::Event*>(std::malloc(n * sizeof(evstwin::Event)));
    if (!p) throw std::bad_alloc();
    evstwin::detail::advise_huge_pages(p, n * sizeof(evstwin::Event));
    return p;
}

/// One call's events on their way to NumPy: storage() for Sensor::run_into, then array().
class EventsOut {
public:
    EventsOut() = default;
    EventsOut(const EventsOut&) = delete;
    EventsOut& operator=(const EventsOut&) = delete;
    ~EventsOut() { std::free(data_); }
    evstwin::EventStorage storage() {
        return [this](std::size_t n) {
            data_ = new_event_buffer(n);
            return data_;
        };
    }
    /// The n events written as an EVENT_DTYPE array that owns their buffer (GIL held).
    py::array_t<evstwin::Event> array(std::size_t n) {
        if (n == 0 || !data_) return py::array_t<evstwin::Event>(0);
        evstwin::Event* data = data_;
        py::capsule free_when_done(data, [](void* p) { std::free(p); });
        data_ = nullptr;  // the capsule owns it now
        return py::array_t<evstwin::Event>({static_cast<py::ssize_t>(n)}, data, free_when_done);
    }

private:
    evstwin::Event* data_ = nullptr;
};

template <class Real>
std::size_t run_typed(Sensor& s, const evstwin::EventStorage& storage, const py::array& rate, const TimesArray& t,
                      const std::vector<std::uint32_t>* probe, std::vector<evstwin::TraceSample>* trace,
                      bool static_frame) {
    const Real* data = static_cast<const Real*>(rate.data());
    const double* times = t.data();
    const std::size_t n = static_cast<std::size_t>(rate.shape(0));
    py::gil_scoped_release release;
    return s.run_into(storage, data, times, n, probe, trace, static_frame);
}

py::array_t<evstwin::Event> run_any(Sensor& s, py::array rate, py::array t_s, const std::vector<std::uint32_t>* probe,
                                    std::vector<evstwin::TraceSample>* trace) {
    const bool static_frame = rate.dtype().kind() == 'f' && rate.ndim() == 3 && rate.shape(1) == s.height() &&
                              rate.shape(2) == s.width() && is_static_frames(rate);
    const bool raw_ok = rate.dtype().attr("isnative").cast<bool>() && rate.attr("flags").attr("aligned").cast<bool>();
    if (!static_frame || !raw_ok || (rate.itemsize() != 4 && rate.itemsize() != 8)) rate = checked_rates(s, rate);
    auto t = checked_times(t_s, rate.shape(0));
    EventsOut out;
    const std::size_t n = rate.itemsize() == 4 ? run_typed<float>(s, out.storage(), rate, t, probe, trace, static_frame)
                                               : run_typed<double>(s, out.storage(), rate, t, probe, trace, static_frame);
    return out.array(n);
}

py::array_t<evstwin::Event> run_pixels_any(Sensor& s, py::array pixels, py::array rate, py::array t_s) {
    if (pixels.dtype().kind() != 'i' && pixels.dtype().kind() != 'u')
        throw py::type_error("pixels must be an integer array of row-major pixel indices; got dtype " +
                             std::string(py::str(pixels.dtype())));
    auto idx = py::array_t<std::int64_t, READ_FLAGS>::ensure(pixels);
    if (!idx || idx.ndim() != 1) throw py::value_error("pixels must be 1-D; got shape " + shape_str(pixels));
    const auto n = idx.shape(0);
    std::vector<std::uint32_t> px(static_cast<std::size_t>(n));
    for (py::ssize_t j = 0; j < n; ++j) {
        const std::int64_t v = idx.data()[j];
        if (v < 0 || static_cast<std::uint64_t>(v) >= s.num_pixels())
            throw py::value_error("pixels[" + std::to_string(j) + "]=" + std::to_string(v) + " is outside the " +
                                  std::to_string(s.num_pixels()) + "-pixel sensor");
        px[static_cast<std::size_t>(j)] = static_cast<std::uint32_t>(v);
    }
    const auto kind = rate.dtype().kind();
    if (kind != 'f' || (rate.itemsize() != 4 && rate.itemsize() != 8))
        throw py::type_error("photon_rate must be a float32 or float64 array of photons/s; got dtype " +
                             std::string(py::str(rate.dtype())));
    if (rate.ndim() != 2 || rate.shape(1) != n)
        throw py::value_error("photon_rate must have shape (T, len(pixels)) = (T, " + std::to_string(n) +
                              "); got shape " + shape_str(rate));
    if (!rate.dtype().attr("isnative").cast<bool>() || !rate.attr("flags").attr("aligned").cast<bool>())
        rate = py::module_::import("numpy").attr("array")(rate, py::arg("dtype") = rate.dtype().attr("newbyteorder")("="),
                                                          py::arg("order") = "C");  // native, aligned (see checked_rates)
    if (!(rate.flags() & py::array::c_style)) rate = py::module_::import("numpy").attr("ascontiguousarray")(rate);
    auto t = checked_times(t_s, rate.shape(0));
    const std::size_t T = static_cast<std::size_t>(rate.shape(0));
    const double* times = t.data();
    const void* data = rate.data();
    const bool single = rate.itemsize() == 4;
    EventsOut out;
    const evstwin::EventStorage storage = out.storage();
    std::size_t n_events = 0;
    {
        py::gil_scoped_release release;
        n_events = single ? s.run_pixels_into(storage, px.data(), px.size(), static_cast<const float*>(data), times, T)
                   : s.run_pixels_into(storage, px.data(), px.size(), static_cast<const double*>(data), times, T);
    }
    return out.array(n_events);
}

py::array_t<evstwin::Event> run_sparse_any(Sensor& s, py::array static_rate, py::array t_s, std::size_t base_every,
                                           std::size_t group_base_samples, py::array light_sample,
                                           py::array light_pixel, py::array light_rate,
                                           std::optional<py::array> reach_pixel) {
    using F64 = py::array_t<double, READ_FLAGS>;
    using U32 = py::array_t<std::uint32_t, READ_FLAGS>;
    auto rate = F64::ensure(static_rate);
    if (!rate || rate.ndim() != 2 || rate.shape(0) != s.height() || rate.shape(1) != s.width())
        throw py::value_error("static_rate must have shape (height, width) = (" + std::to_string(s.height()) + ", " +
                              std::to_string(s.width()) + "); got shape " + shape_str(static_rate));
    auto t = F64::ensure(t_s);
    if (!t || t.ndim() != 1) throw py::value_error("t_s must be 1-D; got shape " + shape_str(t_s));
    const auto integer = [](const py::array& a, const char* name) {
        if (a.size() > 0 && a.dtype().kind() != 'i' && a.dtype().kind() != 'u')
            throw py::type_error(std::string(name) + " must be an integer array; got dtype " + std::string(py::str(a.dtype())));
        const auto wide = py::array_t<std::int64_t, READ_FLAGS>::ensure(a);
        if (!wide || wide.ndim() != 1) throw py::value_error(std::string(name) + " must be 1-D; got shape " + shape_str(a));
        for (py::ssize_t i = 0; i < wide.shape(0); ++i)
            if (wide.data()[i] < 0 || wide.data()[i] > 0xFFFFFFFFll)
                throw py::value_error(std::string(name) + "[" + std::to_string(i) + "]=" + std::to_string(wide.data()[i]) +
                                      " is negative or too large");
        return U32::ensure(wide);
    };
    auto sample = integer(light_sample, "light_sample");
    auto pixel = integer(light_pixel, "light_pixel");
    auto light = F64::ensure(light_rate);
    if (!light || light.ndim() != 1 || light.shape(0) != sample.shape(0) || pixel.shape(0) != sample.shape(0))
        throw py::value_error("light_sample, light_pixel and light_rate must be 1-D of one length; got shapes " +
                              shape_str(light_sample) + ", " + shape_str(light_pixel) + " and " + shape_str(light_rate));
    evstwin::SparseStep step;
    step.static_rate = rate.data();
    step.t_s = t.data();
    step.n_samples = static_cast<std::size_t>(t.shape(0));
    step.base_every = base_every;
    step.group_base_samples = group_base_samples;
    step.light_sample = sample.data();
    step.light_pixel = pixel.data();
    step.light_rate = light.data();
    step.n_light = static_cast<std::size_t>(light.shape(0));
    U32 reach;
    if (reach_pixel) {
        reach = integer(*reach_pixel, "reach_pixel");
        step.reach_all = false;
        step.reach_pixel = reach.data();
        step.n_reach = static_cast<std::size_t>(reach.shape(0));
    }
    EventsOut out;
    const evstwin::EventStorage storage = out.storage();
    std::size_t n_events = 0;
    {
        py::gil_scoped_release release;
        n_events = s.run_sparse_into(storage, step);
    }
    return out.array(n_events);
}

int threads_arg(const std::optional<int>& n) {
    if (n && *n < 1)
        throw py::value_error("num_threads must be >= 1 or None; got num_threads=" + std::to_string(*n));
    return n ? *n : 0;
}

}  // namespace

void register_sensor(py::module_& m) {
    m.attr("TRACE_DTYPE") = py::dtype::of<evstwin::TraceSample>();

    py::class_<Sensor>(m, "Sensor")
        .def(py::init([](int width, int height, const evstwin::PixelParams& p, std::uint64_t seed,
                         std::optional<int> num_threads) {
                 return new Sensor(width, height, p, seed, threads_arg(num_threads));
             }),
             py::arg("width"), py::arg("height"), py::arg("params"), py::arg("seed") = 0,
             py::arg("num_threads") = py::none())
        .def("run",
             [](Sensor& s, py::array rate, py::array t_s) { return run_any(s, rate, t_s, nullptr, nullptr); },
             py::arg("photon_rate"), py::arg("t_s"))
        .def("run_probe",
             [](Sensor& s, py::array rate, py::array t_s, std::vector<std::uint32_t> pixels) {
                 std::vector<evstwin::TraceSample> trace;
                 auto ev = run_any(s, rate, t_s, &pixels, &trace);
                 const auto n = static_cast<py::ssize_t>(pixels.size());
                 const auto T = static_cast<py::ssize_t>(trace.size()) / std::max<py::ssize_t>(n, 1);
                 return py::make_tuple(std::move(ev), to_numpy(std::move(trace), {T, n}));
             },
             py::arg("photon_rate"), py::arg("t_s"), py::arg("pixels"))
        .def("run_pixels",
             [](Sensor& s, py::array pixels, py::array rate, py::array t_s) {
                 return run_pixels_any(s, pixels, rate, t_s);
             },
             py::arg("pixels"), py::arg("photon_rate"), py::arg("t_s"))
        .def("run_sparse", &run_sparse_any, py::arg("static_rate"), py::arg("t_s"), py::arg("base_every"),
             py::arg("group_base_samples"), py::arg("light_sample"), py::arg("light_pixel"), py::arg("light_rate"),
             py::arg("reach_pixel") = py::none())
        .def_property_readonly("last_pixel_updates", &Sensor::last_pixel_updates)
        .def("settle_time_s", &Sensor::settle_time_s, py::arg("photon_rate"))
        .def("reset", &Sensor::reset)
        .def("last_labels",
             [](const Sensor& s) { return to_numpy(std::vector<std::uint8_t>(s.last_labels())); },
             "Why each event of the last run/run_pixels call fired (EventLabel codes).")
        .def("set_hot_pixel_rates",
             [](Sensor& s, std::vector<double> rates) { s.set_hot_pixel_rates(rates); }, py::arg("rates_hz"))
        .def(
            "set_hot_pixel_chains",
            [](Sensor& s, std::vector<std::uint32_t> pixels, std::vector<double> duty, std::vector<double> burst_s,
               std::vector<double> on_share, std::vector<double> alternation) {
                const std::size_t n = pixels.size();
                if (duty.size() != n || burst_s.size() != n || on_share.size() != n || alternation.size() != n)
                    throw py::value_error("set_hot_pixel_chains: pixels, duty, burst_s, on_share and alternation must "
                                          "have the same length");
                std::vector<evstwin::HotPixelChain> chains(n);
                for (std::size_t k = 0; k < n; ++k) chains[k] = {duty[k], burst_s[k], on_share[k], alternation[k]};
                s.set_hot_pixel_chains(pixels, chains);
            },
            py::arg("pixels"), py::arg("duty"), py::arg("burst_s"), py::arg("on_share"), py::arg("alternation"))
        .def_readonly_static("MAX_HOT_PIXEL_CHAINS", &Sensor::MAX_HOT_PIXEL_CHAINS)
        .def("hot_pixel_rates",
             [](const Sensor& s) { return to_numpy(s.hot_pixel_rates(), {s.height(), s.width()}); })
        .def("thresholds",
             [](const Sensor& s, bool on) { return to_numpy(s.thresholds(on), {s.height(), s.width()}); },
             py::arg("on"))
        .def_property_readonly("width", &Sensor::width)
        .def_property_readonly("height", &Sensor::height)
        .def_property_readonly("seed", &Sensor::seed)
        .def_property_readonly("samples_seen", &Sensor::samples_seen)
        .def_property_readonly("last_time_s", &Sensor::last_time_s)
        .def_property("max_events", &Sensor::max_events, &Sensor::set_max_events)
        .def_readonly_static("DEFAULT_MAX_EVENTS", &Sensor::DEFAULT_MAX_EVENTS)
        .def_readonly_static("MAX_THREADS", &Sensor::MAX_THREADS)
        .def_readonly_static("MAX_PIXELS", &Sensor::MAX_PIXELS)
        .def_readonly_static("STATE_BYTES_PER_PIXEL", &Sensor::STATE_BYTES_PER_PIXEL)
        .def_property(
            "kernel", [](const Sensor& s) { return std::string(evstwin::kernel_name(s.kernel())); },
            [](Sensor& s, const std::string& name) {
                for (evstwin::Kernel k : {evstwin::Kernel::Auto, evstwin::Kernel::PerPixel, evstwin::Kernel::Blocks,
                                          evstwin::Kernel::Vector})
                    if (name == evstwin::kernel_name(k)) return s.set_kernel(k);
                throw py::value_error("kernel must be 'auto', 'per_pixel', 'blocks' or 'vector'; got kernel='" + name + "'");
            },
            "The code that advances the pixels: 'auto' (the fastest that applies), 'per_pixel' (the scalar "
            "reference), 'blocks' or 'vector'. The same events whichever.")
        .def_property("num_threads", &Sensor::num_threads,
                      [](Sensor& s, std::optional<int> n) { s.set_num_threads(threads_arg(n)); });
}
