// Levenberg-Marquardt training of the BP network with MATLAB trainlm's semantics (ALGORITHMS.md;
// the numpy twin is cdam_core.reference.train_lm): options, stop reasons and the one loop,
// templated on the policy that accumulates J'J and solves with it. Embeddable: no heap, no
// exceptions; the policy owns every buffer.
//
// Per epoch (lm_train below):
//   J'e and J'J at theta (policy.normal, which returns ||J'e||; J'J is skipped when a stop
//   test that does not read ||J'e|| already ends the run: the last epoch of a run computes
//   only the gradient norm it records); record mse, mu, ||J'e||,
//   validation mse; stop, in this order, on goal (mse <= goal), epochs (epoch == epochs),
//   min_grad (||J'e|| <= min_grad), mu_max (mu >= mu_max), max_fail (validation failures >=
//   max_fail, with a validation set), cancelled (the on_epoch hook returned false);
//   while mu <= mu_max: solve (J'J + mu I) d = J'e (policy.solve; a failed factorisation counts
//   as a rejected step), trial = theta + d; if mse(trial) < mse accept it, mu = max(mu mu_dec,
//   1e-20) and end the epoch; else mu *= mu_inc;
//   with a validation set: a lower validation mse keeps theta as the best (failures reset), a
//   higher one counts a failure; at the end the best-validation weights are returned.
// mu and the MSEs are doubles whatever the Scalar.
//
// Policy (J'J accumulator and solver), D = dim():
//   using Scalar;  Index dim() const;
//   double train_mse(const Scalar* theta)    training MSE, sse / (N m)
//   double normal(const Scalar* theta, bool jtj)  accumulates J'e (and J'J when jtj) at theta;
//                                            returns ||J'e||
//   bool   solve(double mu)                  step() = (J'J + mu I)^-1 J'e; false if not SPD
//   bool   validation() const;  double val_mse(const Scalar* theta)
//   Scalar* step(); Scalar* trial(); Scalar* best()   D values each (best: with validation only)
// The two policies: LmFixed (lm_fixed.hpp: fixed sizes, per-sample J'J, plain-loop Cholesky;
// the target) and LmDynamic (host/training.hpp: run-time sizes, NormalEquations' blocked J'J,
// Eigen's LLT; the host and Python).
#pragma once
#include <cmath>
#include <limits>

#include "mlp.hpp"
#include "status.hpp"

namespace cdam {

enum class LmStop { Goal = 0, Epochs, MinGrad, MuMax, MaxFail, Cancelled };

inline const char* to_string(LmStop s) {
  switch (s) {
    case LmStop::Goal: return "goal";
    case LmStop::Epochs: return "epochs";
    case LmStop::MinGrad: return "min_grad";
    case LmStop::MuMax: return "mu_max";
    case LmStop::MaxFail: return "max_fail";
    case LmStop::Cancelled: return "cancelled";
  }
  return "unknown";
}

struct LmOptions {
  int epochs = 1000;
  double goal = 0.0;
  double mu = 1e-3;
  double mu_dec = 0.1;
  double mu_inc = 10.0;
  double mu_max = 1e10;
  double min_grad = 1e-7;
  int max_fail = 6;   // with a validation set
  int threads = 1;    // LmDynamic's NormalEquations

  // The numeric ranges (the bindings check the same with messages naming each option). mu_max
  // below mu is allowed: training then stops at epoch 0 with "mu_max" (trainlm, the numpy twin).
  bool valid() const {
    return epochs >= 0 && goal >= 0 && mu > 0 && mu_dec > 0 && mu_dec < 1 && mu_inc > 1 &&
           mu_max > 0 && min_grad >= 0 && std::isfinite(goal) && std::isfinite(mu) &&
           std::isfinite(mu_inc) && std::isfinite(mu_max) && std::isfinite(min_grad) &&
           max_fail >= 1 && threads >= 1;
  }
};

// What one recorded epoch saw (val_mse is NaN without a validation set).
struct LmEpoch {
  double mse, mu, grad_norm, val_mse;
};

struct LmResult {
  LmStop stop = LmStop::Epochs;
  int recorded = 0;    // epochs recorded (at most epochs + 1)
  int best_epoch = 0;  // epoch of the returned weights
};

// The hooks' defaults: record nothing, never cancel.
struct LmNoRecord {
  void operator()(int, const LmEpoch&) const {}
};
struct LmNoCancel {
  bool operator()(int, double) const { return true; }
};

// Trains theta (policy.dim() values, in place). record(epoch, LmEpoch) is called once per
// recorded epoch; on_epoch(epoch, mse) after the stop tests, false cancels.
template <typename Policy, typename Record = LmNoRecord, typename OnEpoch = LmNoCancel>
Status lm_train(Policy& p, typename Policy::Scalar* theta, const LmOptions& opt, LmResult* out,
                Record record = Record(), OnEpoch on_epoch = OnEpoch()) {
  using Scalar = typename Policy::Scalar;
  if (!opt.valid()) return Status::InvalidArgument;
  const Index D = p.dim();
  const bool val = p.validation();
  Scalar* const step = p.step();
  Scalar* const trial = p.trial();
  Scalar* const best = val ? p.best() : nullptr;
  double mse = p.train_mse(theta);
  double mu = opt.mu;
  double vmse = val ? p.val_mse(theta) : std::numeric_limits<double>::quiet_NaN();
  double vbest = vmse;
  int fails = 0;
  if (val)
    for (Index k = 0; k < D; ++k) best[k] = theta[k];
  LmResult r;
  for (int epoch = 0;; ++epoch) {
    // The stops decided before the gradient: no J'J is needed when one of them holds.
    const bool last = mse <= opt.goal || epoch == opt.epochs || mu >= opt.mu_max ||
                      (val && fails >= opt.max_fail);
    const double gnorm = p.normal(theta, !last);
    record(epoch, LmEpoch{mse, mu, gnorm, vmse});
    r.recorded = epoch + 1;
    if (!val) r.best_epoch = epoch;
    if (mse <= opt.goal) { r.stop = LmStop::Goal; break; }
    if (epoch == opt.epochs) { r.stop = LmStop::Epochs; break; }
    if (gnorm <= opt.min_grad) { r.stop = LmStop::MinGrad; break; }
    if (mu >= opt.mu_max) { r.stop = LmStop::MuMax; break; }
    if (val && fails >= opt.max_fail) { r.stop = LmStop::MaxFail; break; }
    if (!on_epoch(epoch, mse)) { r.stop = LmStop::Cancelled; break; }
    while (mu <= opt.mu_max) {
      if (p.solve(mu)) {
        for (Index k = 0; k < D; ++k) trial[k] = theta[k] + step[k];
        const double mse2 = p.train_mse(trial);
        if (mse2 < mse) {
          for (Index k = 0; k < D; ++k) theta[k] = trial[k];
          mse = mse2;
          mu = mu * opt.mu_dec > 1e-20 ? mu * opt.mu_dec : 1e-20;
          break;
        }
      }
      mu *= opt.mu_inc;
    }
    if (val) {
      vmse = p.val_mse(theta);
      if (vmse < vbest) {
        vbest = vmse;
        for (Index k = 0; k < D; ++k) best[k] = theta[k];
        fails = 0;
        r.best_epoch = epoch + 1;
      } else if (vmse > vbest) {
        ++fails;
      }
    }
  }
  if (val)
    for (Index k = 0; k < D; ++k) theta[k] = best[k];
  if (out) *out = r;
  return Status::Ok;
}

}  // namespace cdam
