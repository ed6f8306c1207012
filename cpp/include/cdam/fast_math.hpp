// Fast float activations for the target: a rational tanh within 1e-6 (absolute) of tanh over
// the whole float range, with no libm call, no table and no branch the compiler cannot turn
// into a select.
//
// fast_tanh: +-1 for |x| > 7.90531110763549805 (beyond it float tanh is within 3e-7 of +-1;
// the rational below equals +-1.0f there), else the odd/even 13/6 rational minimax approximation whose coefficients Eigen 3.4 publishes
// in Eigen/src/Core/MathFunctionsImpl.h (generic_fast_tanh_float). tests/test_c610.cpp checks
// the bound against std::tanh in double on a dense grid. Cost on a Cortex-M4F: about a dozen
// FPU instructions and one division.
//
// fast_logistic uses the identity 1 / (1 + e^-x) = (1 + tanh(x / 2)) / 2, so logsig costs the
// same and stays within 5e-7 of the logistic function.
//
// FastActivation is the activation policy for cdam::Mlp (mlp.hpp's ActFn template parameter):
// Mlp<float, I, H, O, FastActivation> is the network with these functions in place of
// std::tanh / std::exp.
#pragma once

#include "activation.hpp"

namespace cdam {

// The coefficients, lowest power of x^2 first: tanh(x) ~ x P(x^2) / Q(x^2) for |x| <= kTanhClamp
// (also read by the Cortex-M4F inference kernel, firmware_stubs/include/fw/packed_mlp.hpp).
constexpr float kTanhClamp = 7.90531110763549805f;
constexpr float kTanhP[7] = {4.89352455891786e-03f,  6.37261928875436e-04f,  1.48572235717979e-05f,
                             5.12229709037114e-08f,  -8.60467152213735e-11f, 2.00018790482477e-13f,
                             -2.76076847742355e-16f};
constexpr float kTanhQ[4] = {4.89352518554385e-03f, 2.26843463243900e-03f, 1.18534705686654e-04f,
                             1.19825839466702e-06f};

inline float fast_tanh(float x) {
  const float x2 = x * x;
  // One test on x^2 instead of two on x (a Cortex-M4 has no float min/max, so each test is a
  // compare, a flag transfer and a branch). The rational is exactly +-1.0f at +-kTanhClamp, so
  // the saturated branch returns what clamping x would give. NaN fails the test and stays NaN.
  if (x2 > kTanhClamp * kTanhClamp) return x > 0.0f ? 1.0f : -1.0f;
  float p = x2 * kTanhP[6] + kTanhP[5];
  for (int k = 4; k >= 0; --k) p = x2 * p + kTanhP[k];
  p = x * p;
  float q = x2 * kTanhQ[3] + kTanhQ[2];
  q = x2 * q + kTanhQ[1];
  q = x2 * q + kTanhQ[0];
  return p / q;
}

inline float fast_logistic(float x) { return 0.5f * fast_tanh(0.5f * x) + 0.5f; }

// Activation policy: fast float functions (double falls back to the exact ones).
struct FastActivation {
  static float apply(Activation act, float n) {
    return act == Activation::Tansig ? fast_tanh(n) : fast_logistic(n);
  }
  static double apply(Activation act, double n) { return activate(act, n); }
};

}  // namespace cdam
