// Bindings: the aerial-manipulator simulator (cdam/sim/). Arrays are samples x channels.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <string>

#include "cdam/sim/simulator.hpp"
#include "common.hpp"

namespace py = pybind11;
using namespace cdam::sim;
using cdam::bind::check_status;
using cdam::bind::value_error;

namespace {

PlantParams plant_from(const py::array& a) {
  auto v = cdam::bind::vector<double>(a, "plant", PlantParams::kSize);
  PlantParams p = PlantParams::from_array(v.data());
  if (check_plant(p) != cdam::Status::Ok)
    value_error("plant: masses, inertias, CT, CQ, L, Im, fric_eps and g must be positive; "
                "payload and backlash non-negative; 0 <= omega_min < omega_max");
  return p;
}

ControlParams control_from(const py::array& a) {
  auto v = cdam::bind::vector<double>(a, "control", ControlParams::kSize);
  ControlParams c = ControlParams::from_array(v.data());
  if (c.delay_rotor < 0 || c.delay_joint < 0 || c.delay_rotor > kMaxDelay || c.delay_joint > kMaxDelay)
    value_error("control: delay_rotor and delay_joint must be in 0 .. " + std::to_string(kMaxDelay) +
                " ticks");
  return c;
}

int check_step(double dt, long long substeps) {
  if (!(dt > 0) || !std::isfinite(dt)) value_error("dt: must be positive and finite");
  return cdam::bind::int_arg(substeps, "substeps", 1, 1000);
}

// A run that ended with non-finite states: the step dt / substeps was too long for the plant.
void check_run(cdam::Status s, const char* what) {
  if (s == cdam::Status::Diverged)
    value_error(std::string("dt: the simulation diverged (NaN or Inf state); use a smaller dt or "
                            "more substeps (sim_substeps gives the stable count)"));
  check_status(s, what);
}

}  // namespace

void register_sim(py::module_& m) {
  m.attr("SIM_NX") = kNx;
  m.attr("SIM_NU") = kNu;
  m.attr("SIM_NSP") = kNsp;
  m.attr("SIM_NLOG") = kNlog;
  m.attr("SIM_PLANT_SIZE") = PlantParams::kSize;
  m.attr("SIM_CONTROL_SIZE") = ControlParams::kSize;

  m.def("sim_rhs", [](const py::array& plant, double t, const py::array& x, const py::array& u) {
        const PlantParams p = plant_from(plant);
        auto xv = cdam::bind::vector<double>(x, "x", kNx);
        auto uv = cdam::bind::vector<double>(u, "u", kNu);
        if (!std::isfinite(t)) value_error("t: must be finite");
        State xs = Eigen::Map<const State>(xv.data()), dx;
        rhs(p, t, xs, Eigen::Map<const Input>(uv.data()), dx);
        py::array_t<double> out(kNx);
        Eigen::Map<State>(out.mutable_data()) = dx;
        return out;
      }, py::arg("plant"), py::arg("t"), py::arg("x"), py::arg("u"),
      "dx/dt of the coupled aerial manipulator (state 21, input 6: rotor speeds, motor torques).");

  m.def("sim_fastest_rate", [](const py::array& plant) { return fastest_rate(plant_from(plant)); },
        py::arg("plant"), "Fastest motor-side mode bound (rad/s) used for the RK4 sub-step rule.");
  m.def("sim_substeps", [](const py::array& plant, double dt) {
        if (!(dt > 0) || !std::isfinite(dt)) value_error("dt: must be positive and finite");
        return substeps_for(plant_from(plant), dt);
      }, py::arg("plant"), py::arg("dt"),
      "RK4 sub-steps per dt so that h * fastest_rate <= 2.5.");

  m.def("sim_open_loop", [](const py::array& plant, const py::array& x0, const py::array& U,
                            double dt, long long substeps_) {
        const PlantParams p = plant_from(plant);
        auto xv = cdam::bind::vector<double>(x0, "x0", kNx);
        auto Uv = cdam::bind::matrix<double>(U, "U", kNu);
        const int substeps = check_step(dt, substeps_);
        const long n = static_cast<long>(Uv.shape(0));
        cdam::bind::alloc_elements<double>((cdam::Checked<cdam::Index>(n) + 1) * kNx, "U");
        py::array_t<double> X({n + 1, static_cast<long>(kNx)});
        cdam::Status s;
        cdam::bind::SignalPoll poll(64);
        {
          py::gil_scoped_release nogil;
          s = simulate_open_loop(p, xv.data(), Uv.data(), n, dt, substeps, X.mutable_data(),
                                 poll.hook());
        }
        poll.raise_if_interrupted();
        check_run(s, "sim_open_loop");
        return X;
      }, py::arg("plant"), py::arg("x0"), py::arg("U"), py::arg("dt"), py::arg("substeps"),
      "States (N+1, 21) under inputs U (N, 6) held for dt each.");

  m.def("sim_closed_loop", [](const py::array& plant, const py::array& control, const py::array& x0,
                              const py::array& SP, double dt, long long substeps_) {
        const PlantParams p = plant_from(plant);
        const ControlParams c = control_from(control);
        auto xv = cdam::bind::vector<double>(x0, "x0", kNx);
        auto SPv = cdam::bind::matrix<double>(SP, "setpoints", kNsp);
        const int substeps = check_step(dt, substeps_);
        const long n = static_cast<long>(SPv.shape(0));
        py::array_t<double> X({n, static_cast<long>(kNx)});
        py::array_t<double> LOG({n, static_cast<long>(kNlog)});
        cdam::Status s;
        cdam::bind::SignalPoll poll(64);
        {
          py::gil_scoped_release nogil;
          s = simulate_closed_loop(p, c, xv.data(), SPv.data(), n, dt, substeps, X.mutable_data(),
                                   LOG.mutable_data(), poll.hook());
        }
        poll.raise_if_interrupted();
        check_run(s, "sim_closed_loop");
        return py::make_tuple(X, LOG);
      }, py::arg("plant"), py::arg("control"), py::arg("x0"), py::arg("setpoints"), py::arg("dt"),
      py::arg("substeps"),
      "Closed-loop flight: (states (N, 21), log (N, 10)) for setpoints (N, 8).");
}
