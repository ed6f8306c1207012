// Bindings: NARX regressors and free-run simulation.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include "cdam/narx.hpp"
#include "common.hpp"

namespace py = pybind11;
using namespace cdam;
using namespace cdam::bind;

namespace {

NarxOrders orders(int na, int nb, int nk) {
  NarxOrders o{na, nb, nk};
  if (o.check() != Status::Ok)
    value_error("na, nb, nk: need na >= 0, nb >= 0, nk >= 0 and na + nb >= 1");
  return o;
}

py::array regressors(const py::array& U, const py::array& Y, int na, int nb, int nk) {
  const NarxOrders o = orders(na, nb, nk);
  return dispatch(U, "U", [&](auto tag) -> py::array {
    using T = decltype(tag);
    auto u = matrix<T>(U, "U");
    auto y = matrix<T>(Y, "Y", -1, u.shape(0));
    const Index n = u.shape(0), ni = u.shape(1), no = y.shape(1);
    if (n <= o.t0())
      value_error("U: " + std::to_string(n) + " samples, need more than t0 = " + std::to_string(o.t0()));
    const Index nr = o.regressors(ni, no);
    py::array_t<T> X({n - o.t0(), nr});
    check_status(narx_regressors(u.data(), ni, y.data(), no, n, o, X.mutable_data()), "U");
    return X;
  });
}

py::array simulate(const py::array& theta, const py::array& U, const py::array& Y0, long hidden,
                   const std::string& act, int na, int nb, int nk) {
  const NarxOrders o = orders(na, nb, nk);
  check_positive(hidden, "hidden");
  return dispatch(U, "U", [&](auto tag) -> py::array {
    using T = decltype(tag);
    auto u = matrix<T>(U, "U");
    const Index n = u.shape(0), ni = u.shape(1), t0 = o.t0();
    if (Y0.ndim() != 2) value_error("Y0: expected a 2-D array (t0 x outputs)");
    const Index no = Y0.shape(1);
    if (no < 1) value_error("Y0: needs at least one output column");
    if (Y0.shape(0) != t0)
      value_error("Y0: expected t0 = " + std::to_string(t0) + " rows of initial outputs, got " +
                  std::to_string(Y0.shape(0)));
    if (n <= t0)
      value_error("U: " + std::to_string(n) + " samples, need more than t0 = " + std::to_string(t0));
    Mlp<T> net(o.regressors(ni, no), hidden, no, activation_from(act));
    auto th = vector<T>(theta, "theta", net.num_params());
    py::array_t<T> Y({n, no});
    T* yp = Y.mutable_data();
    if (t0 > 0) {
      auto y0 = c_array<T>(Y0);
      check_finite(y0, "Y0");
      std::copy(y0.data(), y0.data() + t0 * no, yp);
    }
    std::vector<T> reg(net.inputs()), hid(hidden);
    Status s;
    {
      py::gil_scoped_release nogil;
      s = narx_simulate(net, th.data(), u.data(), yp, n, ni, o, reg.data(), hid.data());
    }
    check_status(s, "narx_simulate");
    return Y;
  });
}

}  // namespace

void register_narx(py::module_& m) {
  m.def("narx_regressors", &regressors, py::arg("U"), py::arg("Y"), py::arg("na"), py::arg("nb"),
        py::arg("nk"),
        "Lagged regressors (N - t0, na m + nb i): [y(t-1..t-na), u(t-nk..t-nk-nb+1)], channels fastest.");
  m.def("narx_simulate", &simulate, py::arg("theta"), py::arg("U"), py::arg("Y0"), py::arg("hidden"),
        py::arg("activation"), py::arg("na"), py::arg("nb"), py::arg("nk"),
        "Free-run simulation (N, m): Y0 holds the first t0 outputs; predictions are fed back.");
}
