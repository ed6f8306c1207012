// The `quad_hybrid` flight model on the target (cdam_core.models.flight.hybrid.QuadHybrid),
// included by fw/step_model.hpp for CDAM_MODEL_KIND 6: the quadrotor physics with a recurrent
// tanh network on its body rates. Per sample, with w the rates of the state and the drive of
// the physics (f_i = sum_j kKernelW[j] u_i(t-1-d-j)^2, fw/quad_body.hpp):
//   x = [(w - kInMean) / kInScale, tau(f at delay dR + j) / kFeatureScale, j = 0..kLags-1]
//   n = tanh(W1 x + b1),   out = kOutScale o (W2 n + b2)
//   w(t+1) = (w + d) + out,   d = dt (b o tau(f at dR) + e) (prior "dynamic"; 0 with "hold")
// and position, velocity and attitude by one RK4 step of dt with thrust kT/m sum f (delay dT)
// held and the rates moving linearly from w to w(t+1) (w' = (w(t+1) - w) / dt), after which
// the rates are set to w(t+1). theta as the model file stores it: W1 (kNetIn x kHidden,
// row-major: W1(h, i) = theta[i kHidden + h]), b1, W2 (kHidden x 3, row-major: W2(k, h) =
// theta[off + 3 h + k]), b2. Every number comes from generated/model.hpp; float32 in the
// order of the Python float64 expressions (-ffp-contract=off; the dot products summed in
// index order); tanh is libm's tanhf. Fixed sizes, no heap.
#pragma once
#include <cmath>
#include <cstdint>

#include "fw/quad_body.hpp"
#include "model.hpp"

#ifndef CDAM_FW_STEP_MODEL_HPP
#error "include fw/step_model.hpp, which includes this header for CDAM_MODEL_KIND 6"
#endif

namespace fw {

class StepModel {
 public:
  static constexpr int kS = quad::kS;
  static constexpr int kK = cdam_model::kKernel;       // lag kernel taps (1 without a lag)
  static constexpr int kDT = cdam_model::kDelayTrans;  // input delay of the thrust (samples)
  static constexpr int kDR = cdam_model::kDelayRot;    // input delay of the torques
  static constexpr int kLags = cdam_model::kLags;      // rotor-speed lags the network sees
  static constexpr int kH = cdam_model::kNetHidden;
  static constexpr int kIn = 3 + 3 * kLags;            // the network's inputs
  static_assert(cdam_model::kNetInputs == kIn, "the network sees the rates and 3 lags each");
  // input rows kept: u(t-1) back to u(t-1-max(dT, dR+lags-1)-(kK-1))
  static constexpr int kBack = (kDT > kDR + kLags - 1 ? kDT : kDR + kLags - 1) + kK - 1;
  static constexpr int kRing = kBack + 1;
  static_assert(kRing <= cdam_model::kHistory, "the history holds every input row the step uses");

  void prime(const float* u, const float* y) {
    ring_.push(u);
    for (int i = 0; i < kS; ++i) x_[i] = y[i];
  }

  void step(const float* u, float* y) {
    using namespace cdam_model;
    const float* kInMean = kNetScale;          // kNetScale = [in mean (3), in scale (3),
    const float* kInScale = kNetScale + 3;     //   out scale (3), feature scale (3 lags)]
    const float* kOutScale = kNetScale + 6;
    const float* kFeatureScale = kNetScale + 9;
    quad::normalise(x_);
    float f[4], tau[3];
    ring_.drive(kDT, f);
    const float thrust = kTrans[0] * (((f[0] + f[1]) + f[2]) + f[3]);
    const float* w = x_ + 10;
    float in[kIn];
    for (int c = 0; c < 3; ++c) in[c] = (w[c] - kInMean[c]) / kInScale[c];
    for (int j = 0; j < kLags; ++j) {
      ring_.drive(kDR + j, f);
      quad::torque_combinations(f, tau);
      for (int c = 0; c < 3; ++c) in[3 + 3 * j + c] = tau[c] / kFeatureScale[3 * j + c];
    }
    float drift[3] = {0.0f, 0.0f, 0.0f};
    if (kPriorDynamic) {
      ring_.drive(kDR, f);
      quad::torque_combinations(f, tau);
      for (int c = 0; c < 3; ++c) drift[c] = kDt * (kDrift[c] * tau[c] + kDrift[3 + c]);
    }
    float out[3];
    network(in, out);
    for (int c = 0; c < 3; ++c) out[c] = kOutScale[c] * out[c];
    float next[3], acc[3];
    for (int c = 0; c < 3; ++c) {
      next[c] = (w[c] + drift[c]) + out[c];
      acc[c] = (next[c] - w[c]) / kDt;
    }
    quad::rk4(x_, thrust, [&acc](const float*, float* dx) {
      for (int c = 0; c < 3; ++c) dx[10 + c] = acc[c];
    });
    for (int c = 0; c < 3; ++c) x_[10 + c] = next[c];
    for (int i = 0; i < kS; ++i) y[i] = x_[i];
    ring_.push(u);
  }

  // the measured row y(t), after step (every mode): a kind whose equations need measured
  // signals (greybox arm_coupling) takes them here; the others ignore it
  void observe(const float* y) { (void)y; }

  void correct(const float* y) {
    for (int i = 0; i < kS; ++i) x_[i] = y[i];
  }

 private:
  // out = W2 tanh(W1 x + b1) + b2, theta in the model file's layout (top)
  static void network(const float* x, float* out) {
    using namespace cdam_model;
    const float* W1 = kNetTheta;
    const float* b1 = W1 + kIn * kH;
    const float* W2 = b1 + kH;
    const float* b2 = W2 + kH * 3;
    float a[kH];
    for (int h = 0; h < kH; ++h) {
      float s = 0.0f;
      for (int i = 0; i < kIn; ++i) s = s + x[i] * W1[i * kH + h];
      a[h] = std::tanh(s + b1[h]);
    }
    for (int k = 0; k < 3; ++k) {
      float s = 0.0f;
      for (int h = 0; h < kH; ++h) s = s + a[h] * W2[h * 3 + k];
      out[k] = s + b2[k];
    }
  }

  float x_[kS] = {};
  quad::InputRing<kRing> ring_;
};

inline std::uint32_t params_fnv1a() {
  using namespace cdam_model;
  std::uint32_t h = fnv1a_floats(0x811C9DC5u, kTrans, sizeof(kTrans) / 4);
  h = fnv1a_floats(h, kKernelW, sizeof(kKernelW) / 4);
  h = fnv1a_floats(h, kDrift, sizeof(kDrift) / 4);
  h = fnv1a_floats(h, kNetScale, sizeof(kNetScale) / 4);
  return fnv1a_floats(h, kNetTheta, sizeof(kNetTheta) / 4);
}

}  // namespace fw
