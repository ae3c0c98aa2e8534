#include "bindings.hpp"

#include <string>
#include <utility>
#include <vector>

using evstwin::Event;
using evstwin::Readout;

namespace {

using EventArray = py::array_t<Event, py::array::c_style>;

/// The events as a C-contiguous EVENT_DTYPE array (checked with the GIL held; a strided view
/// is copied once). Any other dtype is a TypeError naming it: a cast between record layouts
/// could silently reorder fields.
EventArray checked_events(const py::array& events) {
    const py::dtype want = py::dtype::of<Event>();
    if (!events.dtype().attr("__eq__")(want).cast<bool>())
        throw py::type_error("events must be an array of EVENT_DTYPE " + std::string(py::str(want)) + "; got dtype " +
                             std::string(py::str(events.dtype())));
    if (events.ndim() != 1)
        throw py::value_error("events must be 1-D; got " + std::to_string(events.ndim()) + " dimensions");
    return EventArray::ensure(events);
}

std::vector<Event> run(Readout& r, const py::array& events, std::vector<std::int64_t>* delay_u,
                       std::vector<std::uint64_t>* kept = nullptr) {
    EventArray ev = checked_events(events);
    const Event* data = ev.data();
    const auto n = static_cast<std::size_t>(ev.shape(0));
    py::gil_scoped_release release;
    return r.process(data, n, delay_u, kept);
}

}  // namespace

void register_readout(py::module_& m) {
    py::class_<Readout>(m, "Readout")
        .def(py::init<double, std::int64_t, double>(), py::arg("max_rate_hz"), py::arg("fifo_depth"),
             py::arg("tick_s"))
        .def(
            "process", [](Readout& r, const py::array& events) { return to_numpy(run(r, events, nullptr)); },
            py::arg("events"))
        .def(
            "process_with_delays",
            [](Readout& r, const py::array& events) {
                std::vector<std::int64_t> delay_u;
                auto out = run(r, events, &delay_u);
                std::vector<double> delay_s(delay_u.size());
                for (std::size_t i = 0; i < delay_u.size(); ++i)
                    delay_s[i] = static_cast<double>(delay_u[i]) * Readout::TIME_UNIT_S;
                return py::make_tuple(to_numpy(std::move(out)), to_numpy(std::move(delay_s)));
            },
            py::arg("events"))
        .def(
            "process_with_index",
            [](Readout& r, const py::array& events) {
                std::vector<std::uint64_t> kept;
                auto out = run(r, events, nullptr, &kept);
                return py::make_tuple(to_numpy(std::move(out)), to_numpy(std::move(kept)));
            },
            py::arg("events"))
        .def("reset", &Readout::reset)
        .def_property_readonly("max_rate_hz", &Readout::max_rate_hz)
        .def_property_readonly("fifo_depth", &Readout::fifo_depth)
        .def_property_readonly("tick_s", &Readout::tick_s)
        .def_property_readonly("tick_units", &Readout::tick_units)
        .def_property_readonly("last_t_us", &Readout::last_t_us)
        .def_property_readonly("n_in", [](const Readout& r) { return r.counts().n_in; })
        .def_property_readonly("n_out", [](const Readout& r) { return r.counts().n_out; })
        .def_property_readonly("n_dropped", [](const Readout& r) { return r.counts().n_dropped; })
        .def_property_readonly("n_dropped_on", [](const Readout& r) { return r.counts().n_dropped_on; })
        .def_property_readonly("n_delayed", [](const Readout& r) { return r.counts().n_delayed; })
        .def_property_readonly("max_delay_s",
                               [](const Readout& r) {
                                   return static_cast<double>(r.counts().max_delay_u) * Readout::TIME_UNIT_S;
                               })
        .def_property_readonly("peak_waiting", [](const Readout& r) { return r.counts().peak_waiting; })
        .def_readonly_static("TIME_UNIT_S", &Readout::TIME_UNIT_S)
        .def_readonly_static("MAX_QUEUE_DELAY_S", &Readout::MAX_QUEUE_DELAY_S)
        .def_readonly_static("MAX_RATE_HZ", &Readout::MAX_RATE_HZ)
        .def_readonly_static("MIN_TICK_S", &Readout::MIN_TICK_S)
        .def_readonly_static("MAX_TICK_S", &Readout::MAX_TICK_S)
        .def_readonly_static("MAX_ABS_T_US", &Readout::MAX_ABS_T_US);
}
