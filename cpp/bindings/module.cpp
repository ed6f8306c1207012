// The private extension cdam_core._core: a thin root; each domain registers its own functions.
#include <pybind11/pybind11.h>

#include "common.hpp"

namespace py = pybind11;

void register_preprocess(py::module_& m);
void register_network(py::module_& m);
void register_narx(py::module_& m);
void register_rng(py::module_& m);
void register_sim(py::module_& m);
void register_optim(py::module_& m);
void register_greybox(py::module_& m);
void register_kstep(py::module_& m);

PYBIND11_MODULE(_core, m) {
  m.doc() = "cdam_core._core: the C++/Eigen core (private; use the cdam_core package)";
#ifdef CDAM_VERSION
  m.attr("__version__") = CDAM_VERSION;
#endif
  register_preprocess(m);
  register_network(m);
  register_narx(m);
  register_rng(m);
  register_sim(m);
  register_optim(m);
  register_greybox(m);
  register_kstep(m);
  m.def("cancel_native_loops", [](bool cancel) {
          cdam::bind::cancel_requested().store(cancel);
        }, py::arg("cancel") = true,
        "Ask every native loop running in any thread to stop at its next poll (they end "
        "with RuntimeError: cancelled), or, with cancel=False, withdraw the request. For a program "
        "that is shutting down worker threads (cdam batch on Ctrl-C).");
}
