// Options and stop reasons of Levenberg-Marquardt training (trainlm semantics), shared by the
// host trainer (levenberg_marquardt.hpp) and the fixed-size, heap-free one (lm_fixed.hpp).
#pragma once
#include <cmath>

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
  int max_fail = 6;
  int threads = 1;

  // The numeric ranges (the bindings check the same with messages naming each option). mu_max
  // below mu is allowed: training then stops at epoch 0 with "mu_max" (trainlm, the numpy twin).
  bool valid() const {
    return epochs >= 0 && goal >= 0 && mu > 0 && mu_dec > 0 && mu_dec < 1 && mu_inc > 1 &&
           mu_max > 0 && min_grad >= 0 && std::isfinite(goal) && std::isfinite(mu) &&
           std::isfinite(mu_inc) && std::isfinite(mu_max) && std::isfinite(min_grad) &&
           max_fail >= 1 && threads >= 1;
  }
};

}  // namespace cdam
