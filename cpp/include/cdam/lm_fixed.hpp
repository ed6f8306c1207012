// The fixed-size, heap-free policy of the Levenberg-Marquardt loop (levenberg_marquardt.hpp's
// lm_train): the target's J'J accumulator and solver, without a validation set.
//
// Net is a cdam::Mlp<Scalar, I, H, O, ActFn> with compile-time sizes; every buffer (J'J 58 x 58
// for 4-8-2, the Cholesky factor, J'e, the step, the trial point, one sample's m x D Jacobian)
// is a fixed-size member, so an LmFixed object (static on the target: about 2 D^2 Scalars)
// never allocates.
//
//   evaluate: sse and mse = sse / (N m) (summed in double), J'e and J'J accumulated per sample
//             from Mlp::forward and Mlp::jacobian (e = t - y), lower triangle of J'J only;
//             ||J'e|| summed in double;
//   solve:    Cholesky of J'J + mu I (a non-positive pivot is a failure), then the two
//             triangular solves against J'e.
// The loop (epochs, mu rule, stop order) is lm_train's, shared with the host's LmDynamic.
// The Cholesky is plain loops (column by column, left-looking, sums in index order) rather than
// Eigen::LLT: for a fixed 58 x 58 matrix Eigen's blocked factorisation goes through
// triangular_solve_matrix with level-3 blocking, whose workspace falls back to malloc, so LLT
// fails the firmware's heap guard at link time. Plain loops also give one summation order on
// every compiler, which lets the target's float run be compared with the host's.
#pragma once
#include <Eigen/Core>
#include <cmath>

#include "levenberg_marquardt.hpp"
#include "mlp.hpp"
#include "status.hpp"

namespace cdam {

// Options and stops: LmOptions / LmStop (levenberg_marquardt.hpp); max_fail and threads do not
// apply.

template <typename Net>
class LmFixed {
 public:
  using Scalar = typename Net::Scalar;
  static constexpr int kD = Net::kParams, kI = Net::kInputs, kH = Net::kHidden,
                       kM = Net::kOutputs;
  static_assert(kD != Eigen::Dynamic, "LmFixed: fixed sizes only (host: train_lm)");
  using Square = Eigen::Matrix<Scalar, kD, kD>;
  using Vec = Eigen::Matrix<Scalar, kD, 1>;

  explicit LmFixed(const Net& net = Net()) : net_(net) {}

  // Sum of squared errors of theta on n samples (X: i x n, T: m x n, one sample per column),
  // in double. With `normal`, also J'e (jte()) and, with `with_jtj`, the lower triangle of J'J
  // (jtj()).
  double evaluate(const Scalar* theta, const Scalar* X, const Scalar* T, Index n, bool normal,
                  bool with_jtj = true) {
    double sse = 0.0;
    if (normal) {
      jte_.setZero();
      jtj_.setZero();
    }
    for (Index s = 0; s < n; ++s) {
      const Scalar* x = X + s * kI;
      const Scalar* t = T + s * kM;
      net_.forward(theta, x, a_.data(), y_.data());
      for (int k = 0; k < kM; ++k) {
        const Scalar e = t[k] - y_[k];
        e_[k] = e;
        sse += static_cast<double>(e) * static_cast<double>(e);
      }
      if (!normal) continue;
      net_.jacobian(theta, x, a_.data(), J_.data());
      for (int c = 0; c < kD; ++c) {
        Scalar g = 0;
        for (int k = 0; k < kM; ++k) g += J_(k, c) * e_[k];
        jte_[c] += g;
        if (!with_jtj) continue;
        for (int r = c; r < kD; ++r) {
          Scalar v = 0;
          for (int k = 0; k < kM; ++k) v += J_(k, r) * J_(k, c);
          jtj_(r, c) += v;
        }
      }
    }
    return sse;
  }

  // Trains theta (kD values, in place) on n samples with lm_train. mse_hist / mu_hist (may be
  // null) receive one value per recorded epoch, at most opt.epochs + 1; *recorded is their count.
  Status train(Scalar* theta, const Scalar* X, const Scalar* T, Index n,
               const LmOptions& opt, double* mse_hist, double* mu_hist, int* recorded,
               LmStop* stop) {
    if (recorded) *recorded = 0;
    if (n < 1) return Status::Empty;
    X_ = X;
    T_ = T;
    n_ = n;
    LmResult r;
    const Status st = lm_train(*this, theta, opt, &r, [&](int epoch, const LmEpoch& e) {
      if (mse_hist) mse_hist[epoch] = e.mse;
      if (mu_hist) mu_hist[epoch] = e.mu;
    });
    if (st != Status::Ok) return st;
    if (recorded) *recorded = r.recorded;
    if (stop) *stop = r.stop;
    return Status::Ok;
  }

  // The policy of lm_train, on the samples given to train().
  Index dim() const { return kD; }
  double train_mse(const Scalar* theta) {
    return evaluate(theta, X_, T_, n_, false) / (static_cast<double>(n_) * kM);
  }
  double normal(const Scalar* theta, bool with_jtj) {
    evaluate(theta, X_, T_, n_, true, with_jtj);
    double g2 = 0.0;
    for (int c = 0; c < kD; ++c) g2 += static_cast<double>(jte_[c]) * static_cast<double>(jte_[c]);
    return std::sqrt(g2);
  }
  bool solve(double mu) {
    lhs_ = jtj_;
    for (int c = 0; c < kD; ++c) lhs_(c, c) += static_cast<Scalar>(mu);
    if (!cholesky_inplace(lhs_)) return false;
    step_ = jte_;
    cholesky_solve(lhs_, step_);
    return true;
  }
  bool validation() const { return false; }
  double val_mse(const Scalar*) { return 0.0; }
  Scalar* step() { return step_.data(); }
  Scalar* trial() { return trial_.data(); }
  Scalar* best() { return nullptr; }  // no validation set on the target

  // Cholesky A = L L' in place on the lower triangle of A (the upper triangle is not read).
  // False when a pivot is not positive (or not finite).
  static bool cholesky_inplace(Square& A) {
    for (int j = 0; j < kD; ++j) {
      Scalar d = A(j, j);
      for (int k = 0; k < j; ++k) d -= A(j, k) * A(j, k);
      if (!(d > Scalar(0)) || !std::isfinite(d)) return false;
      const Scalar ljj = std::sqrt(d);
      A(j, j) = ljj;
      for (int i = j + 1; i < kD; ++i) {
        Scalar v = A(i, j);
        for (int k = 0; k < j; ++k) v -= A(i, k) * A(j, k);
        A(i, j) = v / ljj;
      }
    }
    return true;
  }

  // Solves L L' x = b in place (L from cholesky_inplace).
  static void cholesky_solve(const Square& L, Vec& b) {
    for (int i = 0; i < kD; ++i) {
      Scalar v = b[i];
      for (int k = 0; k < i; ++k) v -= L(i, k) * b[k];
      b[i] = v / L(i, i);
    }
    for (int i = kD - 1; i >= 0; --i) {
      Scalar v = b[i];
      for (int k = i + 1; k < kD; ++k) v -= L(k, i) * b[k];
      b[i] = v / L(i, i);
    }
  }

  const Vec& jte() const { return jte_; }
  const Square& jtj() const { return jtj_; }  // lower triangle valid

 private:
  Net net_;
  Square jtj_, lhs_;
  Vec jte_, step_, trial_;
  Eigen::Matrix<Scalar, kM, kD> J_;
  Eigen::Matrix<Scalar, kH, 1> a_;
  Eigen::Matrix<Scalar, kM, 1> y_, e_;
  const Scalar* X_ = nullptr;  // the training set of the running train()
  const Scalar* T_ = nullptr;
  Index n_ = 0;
};

}  // namespace cdam
