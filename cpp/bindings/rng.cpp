// Bindings: the shared random generator (docs/DESIGN.md).
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include "cdam/rng.hpp"
#include "common.hpp"

namespace py = pybind11;

void register_rng(py::module_& m) {
  py::class_<cdam::Rng>(m, "Rng", "xoshiro128** with splitmix32 seeding; the numpy twin draws the same stream.")
      .def(py::init([](long long seed) {
             if (seed < 0 || seed > 0xFFFFFFFFLL) cdam::bind::value_error("seed: must be in 0 .. 2**32-1");
             return cdam::Rng(static_cast<std::uint32_t>(seed));
           }),
           py::arg("seed") = 0)
      .def("next_u32", &cdam::Rng::next_u32)
      .def("uniform", [](cdam::Rng& r, double a, double b) { return r.uniform<double>(a, b); },
           py::arg("a") = 0.0, py::arg("b") = 1.0)
      .def("index", [](cdam::Rng& r, long long n) {
             if (n < 1 || n > 0xFFFFFFFFLL) cdam::bind::value_error("n: must be in 1 .. 2**32-1");
             return r.index(static_cast<std::uint32_t>(n));
           }, py::arg("n"))
      .def("normal", [](cdam::Rng& r) { return r.normal<double>(); })
      .def("uniform_array", [](cdam::Rng& r, long n, double a, double b) {
             if (n < 0) cdam::bind::value_error("n: must be >= 0");
             py::array_t<double> out(n);
             for (long k = 0; k < n; ++k) out.mutable_at(k) = r.uniform<double>(a, b);
             return out;
           }, py::arg("n"), py::arg("a") = 0.0, py::arg("b") = 1.0);
}
