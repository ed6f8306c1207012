// The BP fitness of the optimisers: training MSE, in normalised units, of the network whose
// parameters are the individual, MSE = sum (T - Y)^2 / (N m) (DESIGN.md). Minimised; the
// pipelines report the "adaptation value" 1 / (1 + MSE).
//
// MlpFitness<Net> (target and host, any Mlp<Scalar, I, H, O>): Mlp::forward per sample on
// caller-owned data, no heap (fixed sizes: the hidden and output buffers are members).
//
// BpFitness<Scalar> (host): the record is cut into a fixed number of contiguous chunks that
// depends only on N; every (individual, chunk) partial SSE is computed by one thread with its
// own blocked evaluator (SseWorker: W1 X and W2 A as matrix products over 256 samples, the
// activation vectorised as tanh(n) = 1 - 2 / (exp(2 n) + 1), logsig 1 / (1 + exp(-n)), which
// agree with std::tanh to a few 1e-16 absolute and run about twice as fast), and the partials
// of an individual are summed in chunk order. The result is therefore bit-identical for any thread count. The constructor
// allocates (the one place); evaluating allocates nothing unless a batch is larger than any
// seen before.
#pragma once
#include <Eigen/Core>
#include <algorithm>
#include <thread>
#include <vector>

#include "../mlp.hpp"
#include "../normal_equations.hpp"

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

// SSE of one theta over a range of samples, in blocks of B samples (host; the workspace is
// allocated by the constructor).
template <typename Scalar>
class SseWorker {
 public:
  using Mat = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;
  using Map = Eigen::Map<const Mat>;
  SseWorker(const Mlp<Scalar>& net, Index B = 256)
      : net_(net), A_(net.hidden(), B), Y_(net.outputs(), B) {}

  double sse(const Scalar* theta, const Map& X, const Map& T) {
    double total = 0;
    const Index B = A_.cols();
    const bool tansig = net_.activation() == Activation::Tansig;
    for (Index b0 = 0; b0 < X.cols(); b0 += B) {
      const Index nb = std::min(B, X.cols() - b0);
      auto a = A_.leftCols(nb);
      a.noalias() = net_.W1(theta) * X.middleCols(b0, nb);
      a.colwise() += net_.b1(theta);
      if (tansig)
        a = Scalar(1) - Scalar(2) / ((Scalar(2) * a.array()).exp() + Scalar(1));
      else
        a = Scalar(1) / ((-a.array()).exp() + Scalar(1));
      auto y = Y_.leftCols(nb);
      y.noalias() = net_.W2(theta) * a;
      y.colwise() += net_.b2(theta);
      y = T.middleCols(b0, nb) - y;
      total += static_cast<double>(y.squaredNorm());
    }
    return total;
  }

 private:
  Mlp<Scalar> net_;
  Mat A_, Y_;  // h x B, m x B
};

template <typename Scalar>
class BpFitness {
 public:
  using Map = typename NormalEquations<Scalar>::ConstMap;

  // X: i x N, T: m x N (column = sample), kept by reference (caller-owned).
  BpFitness(const Mlp<Scalar>& net, const Map& X, const Map& T, int threads = 2,
            Index max_batch = 64)
      : net_(net), X_(X), T_(T), threads_(std::min(16, std::max(1, threads))) {
    chunks_ = std::max<Index>(1, std::min<Index>(16, X.cols() / 256));
    for (int t = 0; t < threads_; ++t) ne_.emplace_back(net_, 256);
    parts_.resize(static_cast<size_t>(max_batch * chunks_));
  }

  BpFitness(const BpFitness&) = delete;
  BpFitness& operator=(const BpFitness&) = delete;

  Index dim() const { return net_.num_params(); }
  int threads() const { return threads_; }
  Index chunks() const { return chunks_; }

  Scalar operator()(const Scalar* theta) {
    Scalar f;
    batch(theta, 1, &f);
    return f;
  }

  // n individuals (column-major D x n) -> n MSE values.
  void batch(const Scalar* thetas, Index n, Scalar* out) {
    const Index tasks = n * chunks_, D = dim();
    if (static_cast<size_t>(tasks) > parts_.size()) parts_.resize(static_cast<size_t>(tasks));
    const Index N = X_.cols();
    auto work = [&](int t, int nt) {
      for (Index q = t; q < tasks; q += nt) {
        const Index ind = q / chunks_, c = q % chunks_;
        const Index lo = N * c / chunks_, hi = N * (c + 1) / chunks_;
        const Map Xc(X_.data() + lo * X_.rows(), X_.rows(), hi - lo);
        const Map Tc(T_.data() + lo * T_.rows(), T_.rows(), hi - lo);
        parts_[static_cast<size_t>(q)] = ne_[t].sse(thetas + ind * D, Xc, Tc);
      }
    };
    const int nt = static_cast<int>(std::min<Index>(threads_, tasks));
    if (nt <= 1 || N * n < 2048) {
      work(0, 1);
    } else {
      std::thread helpers[15];
      const int extra = std::min(nt, 16) - 1;
      for (int t = 1; t <= extra; ++t) helpers[t - 1] = std::thread(work, t, extra + 1);
      work(0, extra + 1);
      for (int t = 0; t < extra; ++t) helpers[t].join();
    }
    const double nm = static_cast<double>(N * T_.rows());
    for (Index ind = 0; ind < n; ++ind) {
      double sse = 0;
      for (Index c = 0; c < chunks_; ++c) sse += parts_[static_cast<size_t>(ind * chunks_ + c)];
      out[ind] = static_cast<Scalar>(sse / nm);
    }
  }

 private:
  Mlp<Scalar> net_;
  Map X_, T_;
  int threads_;
  Index chunks_;
  std::vector<SseWorker<Scalar>> ne_;
  std::vector<double> parts_;
};

}  // namespace cdam::optim
