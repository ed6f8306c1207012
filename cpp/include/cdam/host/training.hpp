// Host trainers of the BP network: train_lm (levenberg_marquardt.hpp's lm_train with the
// LmDynamic policy: run-time sizes, NormalEquations' blocked J'e / J'J, optionally threaded,
// Eigen's LLT; validation set and an epoch callback) and train_gd (plain gradient descent).
// Host code: history vectors and the workspace allocate at setup.
#ifdef CDAM_TARGET_EMBEDDED
#error "cdam/host/training.hpp is host-only (std::vector, std::function, threads); the target uses cdam/lm_fixed.hpp"
#endif
#pragma once
#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <cmath>
#include <functional>
#include <type_traits>
#include <vector>

#include "../levenberg_marquardt.hpp"
#include "../status.hpp"
#include "normal_equations.hpp"

namespace cdam {

struct TrainHistory {
  std::vector<double> mse, mu, grad_norm, val_mse;
  LmStop stop = LmStop::Epochs;
  int best_epoch = 0;
};

// Called after each recorded epoch with (epoch, mse); return false to stop ("cancelled").
using EpochCallback = std::function<bool(int, double)>;

// The host policy of lm_train: J'e and J'J from NormalEquations (blocks, no J formed, `threads`
// workers over fixed chunks, the same bits for any thread count), (J'J + mu I) d = J'e by the
// blocked Cholesky of host/kernels.hpp (AVX2 + FMA) or Eigen's LLT; an optional validation set.
// The constructor is the one place that allocates.
// Precision: J'e, J'J, the Cholesky and the step are double whatever the Scalar. In float the
// network, its products and the sums over each slice of 32 samples are float (the hand kernels
// of host/kernels_f32.hpp), the record's sums double: J'J over 10,000 samples summed in float
// would keep about 3 of its 7 digits, and J'J + mu I with mu down to 1e-20 relative needs more
// than float's 7 digits to factor (float's Cholesky fails where double's holds); the step is
// rounded to float when added to the float weights.
template <typename Scalar_>
class LmDynamic {
 public:
  using Scalar = Scalar_;
  using Mat = typename NormalEquations<Scalar>::Mat;
  using Vec = typename NormalEquations<Scalar>::Vec;
  using MatD = typename NormalEquations<Scalar>::MatD;
  using VecD = typename NormalEquations<Scalar>::VecD;
  using Map = typename NormalEquations<Scalar>::ConstMap;

  // X: i x N, T: m x N (column = sample); Xv, Tv: the validation set or null.
  LmDynamic(const Mlp<Scalar>& net, const Map& X, const Map& T, const Map* Xv, const Map* Tv,
            int threads)
      : ne_(net, 256, threads), X_(X), T_(T), Xv_(Xv), Tv_(Tv),
        val_(Xv != nullptr && Tv != nullptr && Xv->cols() > 0),
        n_train_(static_cast<double>(X.cols() * T.rows())),
        n_val_(val_ ? static_cast<double>(Xv->cols() * Tv->rows()) : 1.0),
        D_(net.num_params()), trial_(D_), best_(D_), step_s_(D_), jte_(D_), step_(D_),
        jtj_(D_, D_), lhs_(D_, D_), llt_(D_) {}

  Index dim() const { return D_; }
  double train_mse(const Scalar* theta) {
    return ne_.evaluate(theta, X_, T_, nullptr, nullptr) / n_train_;
  }
  double normal(const Scalar* theta, bool with_jtj) {
    ne_.evaluate_d(theta, X_, T_, &jte_, with_jtj ? &jtj_ : nullptr);
    return jte_.norm();
  }
  bool solve(double mu) {
    lhs_ = jtj_;
    lhs_.diagonal().array() += mu;
    // AVX2 + FMA (chosen at run time): the blocked Cholesky of host/kernels.hpp, about twice
    // Eigen's LLT compiled for SSE2 (308 x 308: 0.36 against 0.74 ms); Eigen's otherwise.
    if (host::avx2_path(host::KernelPath::Auto)) {
      if (!host::cholesky_lower(lhs_.data(), D_, D_)) return false;
      step_ = jte_;
      host::cholesky_solve(lhs_.data(), D_, D_, step_.data());
    } else {
      llt_.compute(lhs_);
      if (llt_.info() != Eigen::Success) return false;
      step_ = llt_.solve(jte_);
    }
    if constexpr (!std::is_same<Scalar, double>::value) step_s_ = step_.template cast<Scalar>();
    return true;
  }
  bool validation() const { return val_; }
  double val_mse(const Scalar* theta) {
    return ne_.evaluate(theta, *Xv_, *Tv_, nullptr, nullptr) / n_val_;
  }
  Scalar* step() {
    if constexpr (std::is_same<Scalar, double>::value) return step_.data();
    else return step_s_.data();
  }
  Scalar* trial() { return trial_.data(); }
  Scalar* best() { return best_.data(); }

 private:
  NormalEquations<Scalar> ne_;
  const Map& X_;
  const Map& T_;
  const Map* Xv_;
  const Map* Tv_;
  bool val_;
  double n_train_, n_val_;
  Index D_;
  Vec trial_, best_, step_s_;  // step_s_: the step in Scalar (float)
  VecD jte_, step_;
  MatD jtj_, lhs_;  // D x D
  Eigen::LLT<MatD> llt_;
};

// Levenberg-Marquardt (trainlm semantics, levenberg_marquardt.hpp) on the host: theta_io (D
// values) trained in place; hist gets mse, mu, ||J'e|| and validation mse per recorded epoch,
// the stop reason and the best epoch. With a validation set the best-validation weights are
// returned.
template <typename Scalar>
Status train_lm(const Mlp<Scalar>& net, Scalar* theta_io,
                const typename NormalEquations<Scalar>::ConstMap& X,
                const typename NormalEquations<Scalar>::ConstMap& T,
                const typename NormalEquations<Scalar>::ConstMap* Xv,
                const typename NormalEquations<Scalar>::ConstMap* Tv, const LmOptions& opt,
                TrainHistory& hist, const EpochCallback& on_epoch = {}) {
  if (!opt.valid()) return Status::InvalidArgument;
  if (X.cols() < 1) return Status::Empty;
  if (X.rows() != net.inputs() || T.rows() != net.outputs() || T.cols() != X.cols())
    return Status::SizeMismatch;
  LmDynamic<Scalar> policy(net, X, T, Xv, Tv, opt.threads);
  hist = TrainHistory{};
  LmResult r;
  const Status st = lm_train(
      policy, theta_io, opt, &r,
      [&hist](int, const LmEpoch& e) {
        hist.mse.push_back(e.mse);
        hist.mu.push_back(e.mu);
        hist.grad_norm.push_back(e.grad_norm);
        hist.val_mse.push_back(e.val_mse);
      },
      [&on_epoch](int epoch, double mse) { return !on_epoch || on_epoch(epoch, mse); });
  hist.stop = r.stop;
  hist.best_epoch = r.best_epoch;
  return st;
}

// Plain batch gradient-descent BP on the MSE (the baseline): theta -= lr * dMSE/dtheta, with
// dMSE/dtheta = -2 J'e / (N m). History: mse per epoch; stops on goal or epochs. lr must be
// positive and finite; an MSE that turns NaN or Inf (lr too large) ends the run with
// Status::Diverged (the history up to it is kept).
template <typename Scalar>
Status train_gd(const Mlp<Scalar>& net, Scalar* theta_io,
                const typename NormalEquations<Scalar>::ConstMap& X,
                const typename NormalEquations<Scalar>::ConstMap& T, double lr, int epochs,
                double goal, TrainHistory& hist, int threads = 1,
                const EpochCallback& on_epoch = {}) {
  using Vec = typename NormalEquations<Scalar>::Vec;
  if (!(lr > 0) || !std::isfinite(lr) || epochs < 0 || !(goal >= 0) || !std::isfinite(goal) ||
      threads < 1)
    return Status::InvalidArgument;
  if (X.cols() < 1) return Status::Empty;
  if (X.rows() != net.inputs() || T.rows() != net.outputs() || T.cols() != X.cols())
    return Status::SizeMismatch;
  const Index D = net.num_params();
  const double n_train = static_cast<double>(X.cols() * T.rows());
  NormalEquations<Scalar> ne(net, 256, threads);
  Eigen::Map<Vec> theta(theta_io, D);
  Vec jte(D);
  hist = TrainHistory{};
  for (int epoch = 0;; ++epoch) {
    const double mse = ne.evaluate(theta.data(), X, T, &jte, nullptr) / n_train;
    hist.mse.push_back(mse);
    hist.best_epoch = epoch;
    if (!std::isfinite(mse)) return Status::Diverged;
    if (mse <= goal) { hist.stop = LmStop::Goal; break; }
    if (epoch == epochs) { hist.stop = LmStop::Epochs; break; }
    if (on_epoch && !on_epoch(epoch, mse)) { hist.stop = LmStop::Cancelled; break; }
    theta += static_cast<Scalar>(lr * 2.0 / n_train) * jte;
  }
  return Status::Ok;
}

}  // namespace cdam
