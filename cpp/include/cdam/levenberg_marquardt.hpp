// Levenberg-Marquardt training of the BP network with MATLAB trainlm's semantics
// (ALGORITHMS.md; the numpy twin is cdam_core.reference.train_lm). Per epoch:
//   record mse, mu, ||J'e||, validation mse; stop on goal, epochs, min_grad, mu_max, max_fail;
//   solve (J'J + mu I) d = J'e (Cholesky); accept if the training MSE falls (mu *= mu_dec, at
//   least 1e-20), else mu *= mu_inc and retry while mu <= mu_max;
//   track validation failures; with a validation set the best-validation weights are returned.
// Host code (history vectors and the normal-equation workspace allocate at setup).
#pragma once
#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <vector>

#include "lm_options.hpp"
#include "normal_equations.hpp"
#include "status.hpp"

namespace cdam {

struct TrainHistory {
  std::vector<double> mse, mu, grad_norm, val_mse;
  LmStop stop = LmStop::Epochs;
  int best_epoch = 0;
};

// Called after each recorded epoch with (epoch, mse); return false to stop ("cancelled").
using EpochCallback = std::function<bool(int, double)>;

template <typename Scalar>
Status train_lm(const Mlp<Scalar>& net, Scalar* theta_io,
                const typename NormalEquations<Scalar>::ConstMap& X,
                const typename NormalEquations<Scalar>::ConstMap& T,
                const typename NormalEquations<Scalar>::ConstMap* Xv,
                const typename NormalEquations<Scalar>::ConstMap* Tv, const LmOptions& opt,
                TrainHistory& hist, const EpochCallback& on_epoch = {}) {
  using Mat = typename NormalEquations<Scalar>::Mat;
  using Vec = typename NormalEquations<Scalar>::Vec;
  const Index D = net.num_params();
  const double n_train = static_cast<double>(X.cols() * T.rows());
  if (!opt.valid()) return Status::InvalidArgument;
  if (X.cols() < 1) return Status::Empty;
  if (X.rows() != net.inputs() || T.rows() != net.outputs() || T.cols() != X.cols())
    return Status::SizeMismatch;
  const bool val = Xv != nullptr && Tv != nullptr && Xv->cols() > 0;
  NormalEquations<Scalar> ne(net, 256, opt.threads);
  Eigen::Map<Vec> theta(theta_io, D);
  Vec trial(D), best(D), jte(D), step(D);
  Mat jtj(D, D), lhs(D, D);
  Eigen::LLT<Mat> llt(D);

  double mse = ne.evaluate(theta.data(), X, T, nullptr, nullptr) / n_train;
  double mu = opt.mu;
  const double n_val = val ? static_cast<double>(Xv->cols() * Tv->rows()) : 1.0;
  double vmse = val ? ne.evaluate(theta.data(), *Xv, *Tv, nullptr, nullptr) / n_val
                    : std::numeric_limits<double>::quiet_NaN();
  double vbest = vmse;
  int fails = 0;
  best = theta;
  hist = TrainHistory{};
  for (int epoch = 0;; ++epoch) {
    ne.evaluate(theta.data(), X, T, &jte, &jtj);
    const double gnorm = static_cast<double>(jte.norm());
    hist.mse.push_back(mse);
    hist.mu.push_back(mu);
    hist.grad_norm.push_back(gnorm);
    hist.val_mse.push_back(vmse);
    if (!val) hist.best_epoch = epoch;
    if (mse <= opt.goal) { hist.stop = LmStop::Goal; break; }
    if (epoch == opt.epochs) { hist.stop = LmStop::Epochs; break; }
    if (gnorm <= opt.min_grad) { hist.stop = LmStop::MinGrad; break; }
    if (mu >= opt.mu_max) { hist.stop = LmStop::MuMax; break; }
    if (val && fails >= opt.max_fail) { hist.stop = LmStop::MaxFail; break; }
    if (on_epoch && !on_epoch(epoch, mse)) { hist.stop = LmStop::Cancelled; break; }
    while (mu <= opt.mu_max) {
      lhs = jtj;
      lhs.diagonal().array() += static_cast<Scalar>(mu);
      llt.compute(lhs);
      if (llt.info() == Eigen::Success) {
        step = llt.solve(jte);
        trial = theta + step;
        const double mse2 = ne.evaluate(trial.data(), X, T, nullptr, nullptr) / n_train;
        if (mse2 < mse) {
          theta = trial;
          mse = mse2;
          mu = std::max(mu * opt.mu_dec, 1e-20);
          break;
        }
      }
      mu *= opt.mu_inc;
    }
    if (val) {
      vmse = ne.evaluate(theta.data(), *Xv, *Tv, nullptr, nullptr) / n_val;
      if (vmse < vbest) {
        vbest = vmse;
        best = theta;
        fails = 0;
        hist.best_epoch = epoch + 1;
      } else if (vmse > vbest) {
        ++fails;
      }
    }
  }
  if (val) theta = best;
  return Status::Ok;
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
