#include "bindings.hpp"

#include <pybind11/stl.h>

using evstwin::DarkModel;
using evstwin::LeakPolarity;
using evstwin::LowPass;
using evstwin::PixelParams;

namespace {
std::string dark_model_name(DarkModel m) {
    switch (m) {
        case DarkModel::Poisson: return "poisson";
        case DarkModel::Paper: return "paper";
        default: return "none";
    }
}
DarkModel dark_model_from(const std::string& s) {
    if (s == "poisson") return DarkModel::Poisson;
    if (s == "paper") return DarkModel::Paper;
    if (s == "none") return DarkModel::None;
    throw py::value_error("dark_model must be one of 'poisson', 'paper', 'none'; got dark_model='" + s + "'");
}
LowPass lowpass_from(const std::string& s) {
    if (s == "exact") return LowPass::Exact;
    if (s == "euler") return LowPass::Euler;
    throw py::value_error("lowpass must be one of 'exact', 'euler'; got lowpass='" + s + "'");
}
}  // namespace

#define EVSTWIN_FIELD(name) .def_readwrite(#name, &PixelParams::name)

void register_pixel(py::module_& m) {
    m.def(
        "validate_hot_pixel_chain",
        [](double duty, double burst_s, double on_share, double alternation, const std::string& prefix) {
            evstwin::validate_hot_chain({duty, burst_s, on_share, alternation}, prefix);
        },
        py::arg("duty"), py::arg("burst_s"), py::arg("on_share"), py::arg("alternation"), py::arg("prefix"),
        "Raise ValueError naming the first field (prefix + name) of a hot pixel's chain out of range.");

    py::class_<PixelParams>(m, "PixelParams", "C++ pixel parameters (see evstwin.PixelParams)")
        .def(py::init<>())
        EVSTWIN_FIELD(theta_on) EVSTWIN_FIELD(theta_off) EVSTWIN_FIELD(refractory_s)
        EVSTWIN_FIELD(cutoff_hz) EVSTWIN_FIELD(leak_rate_hz) EVSTWIN_FIELD(shot_noise_rate_hz)
        EVSTWIN_FIELD(shot_noise_factor) EVSTWIN_FIELD(shot_noise_i_max_a) EVSTWIN_FIELD(dark_rate_e_per_s)
        EVSTWIN_FIELD(photon_shot_noise) EVSTWIN_FIELD(threshold_sigma) EVSTWIN_FIELD(fill_factor)
        EVSTWIN_FIELD(internal_qe) EVSTWIN_FIELD(transmission) EVSTWIN_FIELD(absorption_per_m)
        EVSTWIN_FIELD(depletion_width_m) EVSTWIN_FIELD(pr_pole) EVSTWIN_FIELD(pr_cutoff_ref_hz)
        EVSTWIN_FIELD(pr_ref_current_a) EVSTWIN_FIELD(shot_noise_on_rate_hz) EVSTWIN_FIELD(shot_noise_off_rate_hz)
        EVSTWIN_FIELD(background_rate_sigma) EVSTWIN_FIELD(leak_rate_sigma) EVSTWIN_FIELD(leak_random_phase)
        EVSTWIN_FIELD(leak_photocurrent_hz_per_a)
        EVSTWIN_FIELD(hot_pixel_fraction) EVSTWIN_FIELD(hot_pixel_rate_hz) EVSTWIN_FIELD(hot_pixel_rate_sigma)
        EVSTWIN_FIELD(hot_pixel_duty) EVSTWIN_FIELD(hot_pixel_burst_s) EVSTWIN_FIELD(hot_pixel_on_share) EVSTWIN_FIELD(hot_pixel_alternation)
        .def_property(
            "noise_model",
            [](const PixelParams& p) {
                return std::string(p.noise_model == evstwin::NoiseModel::Continuous ? "continuous" : "sampled");
            },
            [](PixelParams& p, const std::string& s) {
                if (s == "continuous")
                    p.noise_model = evstwin::NoiseModel::Continuous;
                else if (s == "sampled")
                    p.noise_model = evstwin::NoiseModel::Sampled;
                else
                    throw py::value_error("noise_model must be one of 'continuous', 'sampled'; got noise_model='" + s + "'");
            })
        .def_property(
            "dark_model", [](const PixelParams& p) { return dark_model_name(p.dark_model); },
            [](PixelParams& p, const std::string& s) { p.dark_model = dark_model_from(s); })
        .def_property(
            "leak_polarity",
            [](const PixelParams& p) { return std::string(p.leak_polarity == LeakPolarity::On ? "on" : "off"); },
            [](PixelParams& p, const std::string& s) {
                if (s == "on")
                    p.leak_polarity = LeakPolarity::On;
                else if (s == "off")
                    p.leak_polarity = LeakPolarity::Off;
                else
                    throw py::value_error("leak_polarity must be one of 'on', 'off'; got leak_polarity='" + s + "'");
            })
        .def_property(
            "lowpass", [](const PixelParams& p) { return std::string(p.lowpass == LowPass::Exact ? "exact" : "euler"); },
            [](PixelParams& p, const std::string& s) { p.lowpass = lowpass_from(s); })
        .def("validate", [](const PixelParams& p) { evstwin::validate(p); },
             "Raise ValueError naming the first parameter out of range.")
        .def("electrons_per_photon", &PixelParams::electrons_per_photon,
             "Electrons per photon arriving on the pixel: fill factor x eq. 2 without e.");
}
