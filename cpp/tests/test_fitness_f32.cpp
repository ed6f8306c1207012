// The float32 BP fitness of the swarm search (host/kernels_f32.hpp, BpFitness with
// FitnessPrecision::Float32): its tanh against std::tanh in double, every compiled path (generic,
// AVX2, AVX-512 where the CPU has them) against the per-sample double MlpFitness on the same
// float-rounded record, bit-identical results at 1, 2 and 3 threads.
#include <doctest/doctest.h>

#include <cmath>
#include <vector>

#include "cdam/host/bp_fitness.hpp"
#include "cdam/rng.hpp"

using namespace cdam;
using namespace cdam::optim;

namespace {
// |y - tanh(x)| in units of the spacing of floats at the correctly rounded value
double ulps(float y, double exact) {
  const float r = static_cast<float>(exact);
  const float a = std::fabs(r);
  const double u = a > 0 ? static_cast<double>(std::nextafter(a, 2.0f)) - a : 1e-45;
  return std::fabs(static_cast<double>(y) - exact) / u;
}
}  // namespace

TEST_CASE("float32 tanh: within 3 ulps of tanh over [-12, 12], exact limits") {
  double worst = 0;
  for (int k = -1200000; k <= 1200000; ++k) {
    const float x = static_cast<float>(k) * 1e-5f;
    worst = std::max(worst, ulps(host::kernel_f32::tanh1(x), std::tanh(static_cast<double>(x))));
  }
  for (float x : {1e-30f, -1e-20f, 1e-7f, 3e-4f, 0.0f})
    worst = std::max(worst, ulps(host::kernel_f32::tanh1(x), std::tanh(static_cast<double>(x))));
  CHECK(worst <= 3.0);
  CHECK(host::kernel_f32::tanh1(50.0f) == 1.0f);
  CHECK(host::kernel_f32::tanh1(-1e30f) == -1.0f);
  CHECK(host::kernel_f32::tanh1(0.0f) == 0.0f);
}

TEST_CASE("BpFitness float32: every path near the double per-sample MSE; thread-independent") {
  struct Case { Index i, h, m, N; Activation act; };
  // odd sizes (vector and chunk remainders, outputs not a multiple of 4, more inputs than
  // kernel_f32::kMaxIn) and the paper's 6-20-8
  for (const Case& c : {Case{6, 20, 8, 10000, Activation::Tansig}, Case{7, 13, 3, 1001, Activation::Logsig},
                        Case{15, 5, 1, 777, Activation::Tansig}, Case{2, 3, 5, 9, Activation::Tansig}}) {
    Mlp<double> net(c.i, c.h, c.m, c.act);
    Rng rng(11);
    const Index P = 5, D = net.num_params();
    Eigen::MatrixXd X(c.i, c.N), T(c.m, c.N), thetas(D, P);
    // values exactly representable in float, so the double reference sees the same record
    for (Index k = 0; k < X.size(); ++k) X.data()[k] = static_cast<float>(rng.uniform(-2.0, 2.0));
    for (Index k = 0; k < T.size(); ++k) T.data()[k] = static_cast<float>(rng.uniform(-1.0, 1.0));
    for (Index k = 0; k < thetas.size(); ++k)
      thetas.data()[k] = static_cast<float>(rng.uniform(-1.5, 1.5));
    NormalEquations<double>::ConstMap Xm(X.data(), c.i, c.N), Tm(T.data(), c.m, c.N);
    MlpFitness<Mlp<double>> ref(net, X.data(), T.data(), c.N);
    std::vector<double> r(P);
    for (Index k = 0; k < P; ++k) r[k] = ref(thetas.col(k).data());
    for (int path = 0; path <= host::f32_path(); ++path) {
      std::vector<std::vector<double>> out;
      for (int t = 1; t <= 3; ++t) {
        BpFitness<double> f(net, Xm, Tm, t, P, FitnessPrecision::Float32);
        f.set_f32_path_limit(path);
        CHECK(f.f32_path() == path);
        out.emplace_back(P);
        f.batch(thetas.data(), P, out.back().data());
        CHECK(f(thetas.col(2).data()) == out.back()[2]);
      }
      for (Index k = 0; k < P; ++k) {
        CHECK(out[0][k] == out[1][k]);  // bit-identical at 1, 2 and 3 threads
        CHECK(out[0][k] == out[2][k]);
        CHECK(out[0][k] == doctest::Approx(r[k]).epsilon(2e-6));
      }
    }
  }
}
