// Bindings: NARX regressors and free-run simulation.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <string>
#include <vector>

#include "cdam/narx.hpp"
#include "common.hpp"

namespace py = pybind11;
using namespace cdam;
using namespace cdam::bind;

namespace {

// Checked orders: each lag in 0 .. 2^31 - 1, na + nb >= 1, t0 = max(na, nk + nb - 1)
// representable; the ValueError names the lag at fault.
NarxOrders orders(long long na, long long nb, long long nk) {
  const NarxOrders o{int_arg(na, "na"), int_arg(nb, "nb"), int_arg(nk, "nk")};
  const Status st = o.check();
  if (st == Status::Overflow)
    value_error(std::string(nk >= nb ? "nk" : "nb") + ": lag too large (nk + nb - 1 = " +
                std::to_string(nk + nb - 1) + " overflows the 32-bit lag arithmetic)");
  if (st != Status::Ok) value_error("na, nb, nk: need na >= 0, nb >= 0, nk >= 0 and na + nb >= 1");
  return o;
}

// na m + nb i, checked; the ValueError names the larger order.
Index regressor_count(const NarxOrders& o, Index ni, Index no) {
  if (o.check(ni, no) != Status::Ok)
    value_error(std::string(o.na >= o.nb ? "na" : "nb") +
                ": lag too large (the regressor length na m + nb i overflows)");
  return o.regressors(ni, no);
}

void check_length(const NarxOrders& o, Index n) {
  if (n <= o.t0())
    value_error("U: " + std::to_string(n) + " samples, need more than t0 = max(na, nk + nb - 1) = " +
                std::to_string(o.t0()) + " (na = " + std::to_string(o.na) + ", nb = " +
                std::to_string(o.nb) + ", nk = " + std::to_string(o.nk) + ")");
}

py::array regressors(const py::array& U, const py::array& Y, long long na, long long nb,
                     long long nk) {
  const NarxOrders o = orders(na, nb, nk);
  return dispatch(U, "U", [&](auto tag) -> py::array {
    using T = decltype(tag);
    auto u = matrix<T>(U, "U");
    auto y = matrix<T>(Y, "Y", -1, u.shape(0));
    const Index n = u.shape(0), ni = u.shape(1), no = y.shape(1);
    check_length(o, n);
    const Index nr = regressor_count(o, ni, no), rows = n - o.t0();
    alloc_elements<T>(Checked<Index>(rows) * nr, "U");
    py::array_t<T> X({rows, nr});
    check_status(narx_regressors(u.data(), ni, y.data(), no, n, o, X.mutable_data()), "U");
    return X;
  });
}

py::array simulate(const py::array& theta, const py::array& U, const py::array& Y0,
                   long long hidden, const std::string& act, long long na, long long nb,
                   long long nk) {
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
    check_length(o, n);
    const Index nr = regressor_count(o, ni, no);
    const Index D = mlp_params_or_raise(nr, hidden, no);
    alloc_elements<T>(Checked<Index>(n) * no, "U");
    Mlp<T> net(nr, hidden, no, activation_from(act));
    auto th = vector<T>(theta, "theta", D);
    py::array_t<T> Y({n, no});
    T* yp = Y.mutable_data();
    if (t0 > 0) {
      auto y0 = c_array<T>(Y0);
      check_finite(y0, "Y0");
      std::copy(y0.data(), y0.data() + t0 * no, yp);
    }
    std::vector<T> reg(net.inputs()), hid(hidden);
    Status s;
    SignalPoll poll(256);
    {
      py::gil_scoped_release nogil;
      s = narx_simulate(net, th.data(), u.data(), yp, n, ni, o, reg.data(), hid.data(),
                        poll.hook());
    }
    poll.raise_if_interrupted();
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
