// Bindings: five-point cubic smoothing and min-max scaling.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include "cdam/scaling.hpp"
#include "cdam/smoothing.hpp"
#include <algorithm>
#include <vector>

#include "common.hpp"

namespace py = pybind11;
using namespace cdam;
using namespace cdam::bind;

namespace {

py::array smooth(const py::array& y, long long passes_) {
  const int passes = int_arg(passes_, "passes");
  if (y.ndim() != 1 && y.ndim() != 2) value_error("y: expected a 1-D or 2-D array");
  return dispatch(y, "y", [&](auto tag) -> py::array {
    using T = decltype(tag);
    auto in = c_array<T>(y);
    if (in.size() == 0) value_error("y: empty array");
    check_finite(in, "y");
    const py::ssize_t n = in.shape(0), c = y.ndim() == 2 ? in.shape(1) : 1;
    if (n < 5) value_error("y: five-point smoothing needs at least 5 samples, got " + std::to_string(n));
    py::array_t<T> out(std::vector<py::ssize_t>(in.shape(), in.shape() + in.ndim()));
    std::copy(in.data(), in.data() + in.size(), out.mutable_data());
    Status s;
    std::vector<T> work(3 * c);
    SignalPoll poll(std::max<py::ssize_t>(1, (1 << 16) / (n * c)));  // about 64k values a poll
    {
      py::gil_scoped_release nogil;
      s = five_point_cubic_smooth_rows(out.mutable_data(), n, c, passes, work.data(), poll.hook());
    }
    poll.raise_if_interrupted();
    check_status(s, "y");
    return out;
  });
}

py::tuple fit(const py::array& x) {
  return dispatch(x, "X", [&](auto tag) -> py::tuple {
    using T = decltype(tag);
    auto a = matrix<T>(x, "X");
    const py::ssize_t c = a.shape(1);
    py::array_t<T> lo(c), hi(c);
    check_status(minmax_fit(a.data(), a.shape(0), c, lo.mutable_data(), hi.mutable_data()), "X");
    return py::make_tuple(lo, hi);
  });
}

py::array apply(const py::array& x, const py::array& lo, const py::array& hi, bool inverse) {
  return dispatch(x, "X", [&](auto tag) -> py::array {
    using T = decltype(tag);
    auto a = matrix<T>(x, "X");
    const py::ssize_t c = a.shape(1);
    auto l = vector<T>(lo, "data_min", c);
    auto h = vector<T>(hi, "data_max", c);
    py::array_t<T> out({a.shape(0), c});
    std::copy(a.data(), a.data() + a.size(), out.mutable_data());
    minmax_apply(out.mutable_data(), a.shape(0), c, l.data(), h.data(), inverse);
    return out;
  });
}

}  // namespace

void register_preprocess(py::module_& m) {
  m.def("five_point_cubic_smooth", &smooth, py::arg("y"), py::arg("passes") = 1,
        "Five-point cubic smoothing, `passes` times, per column of a (N,) or (N, C) array.");
  m.def("minmax_fit", &fit, py::arg("X"), "Per-column (min, max) of a (N, C) array.");
  m.def("minmax_apply", &apply, py::arg("X"), py::arg("data_min"), py::arg("data_max"),
        py::arg("inverse") = false,
        "Scale to [-1, 1] (or back with inverse=True); constant columns map to 0.");
}
