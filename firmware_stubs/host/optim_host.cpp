// Check (3), second half, on the host: the run of fw/optim_run.hpp compiled for x86-64 in
// float32 (built with -ffp-contract=off and EIGEN_DONT_VECTORIZE, like the target image's
// arithmetic: no fused multiply-add, scalar Eigen). Prints key=value lines and one
// "curve=<value>" line per curve point (17 significant digits). Eigen's allocator is switched
// off around the run (EIGEN_RUNTIME_NO_MALLOC): a heap use aborts.
#include <cstdio>

#include "fw/optim_run.hpp"

namespace {
fw::optim_run::Workspace g_work;
}

int main() {
  double curve[fw::optim_run::kCurveMax];
  Eigen::internal::set_is_malloc_allowed(false);
  const fw::optim_run::Result r = fw::optim_run::run(g_work, curve);
  Eigen::internal::set_is_malloc_allowed(true);
  std::printf("status=%d\n", static_cast<int>(r.status));
  if (r.status != cdam::Status::Ok) return 4;
  std::printf("iterations=%d\nlm_epochs=%d\nevaluations=%ld\n", fw::optim_run::kIterations,
              r.lm_epochs, r.evaluations);
  for (int k = 0; k < r.curve_len; ++k) std::printf("curve=%.17g\n", curve[k]);
  return 0;
}
