// The BP fitness of the optimisers: training MSE, in normalised units, of the network whose
// parameters are the individual, MSE = sum (T - Y)^2 / (N m) (DESIGN.md). Minimised; the
// pipelines report the "adaptation value" 1 / (1 + MSE).
//
// MlpFitness<Net> (target and host, any Mlp<Scalar, I, H, O, ActFn>): Mlp::forward per sample
// on caller-owned data, sums in Scalar in sample order, no heap (fixed sizes: the hidden and
// output buffers are members). The fitness concept is swarm.hpp's. The host's fast, threaded
// BpFitness (host/bp_fitness.hpp) computes the same value to rounding.
#pragma once
#include <Eigen/Core>

#include "../mlp.hpp"

namespace cdam::optim {

template <typename Net>
class MlpFitness {
 public:
  using Scalar = typename Net::Scalar;

  // X: i x n inputs, T: m x n targets, column-major (one sample per column), caller-owned.
  MlpFitness(const Net& net, const Scalar* X, const Scalar* T, Index n)
      : net_(net), X_(X), T_(T), n_(n), a_(net.hidden()), y_(net.outputs()) {}

  Index dim() const { return net_.num_params(); }

  Scalar operator()(const Scalar* theta) {
    const Index i = net_.inputs(), m = net_.outputs();
    Scalar sse = 0;
    for (Index s = 0; s < n_; ++s) {
      net_.forward(theta, X_ + s * i, a_.data(), y_.data());
      for (Index k = 0; k < m; ++k) {
        const Scalar e = T_[s * m + k] - y_[k];
        sse += e * e;
      }
    }
    return sse / static_cast<Scalar>(n_ * m);
  }

  void batch(const Scalar* thetas, Index count, Scalar* out) {
    for (Index k = 0; k < count; ++k) out[k] = (*this)(thetas + k * dim());
  }

 private:
  Net net_;
  const Scalar* X_;
  const Scalar* T_;
  Index n_;
  Eigen::Matrix<Scalar, Net::kHidden, 1> a_;
  Eigen::Matrix<Scalar, Net::kOutputs, 1> y_;
};

}  // namespace cdam::optim
