// The `quad_physics` flight model on the target (cdam_core.models.flight.physics.QuadPhysics),
// included by fw/step_model.hpp for CDAM_MODEL_KIND 4. The 13 states (position, world velocity,
// quaternion xyzw, body rates) advance by one RK4 step of dt per sample with the drive held:
//   thrust = kT/m sum_i f_i,   f_i = sum_j kKernel[j] u_i(t-1-dT-j)^2   (actuation lag kernel)
//   torque acceleration = b o tau(f) + e  [+ r_z (s . (u(t-1-dR) - u(t-2-dR))) / dt on z]
//   p' = v,  v' = thrust n - dxy v - (dz - dxy) n (n . v) - g e3,  n = R(q) e3,
//   q' = 1/2 q (x) (w, 0),   w' = torque acceleration + c o (wy wz, wx wz, wx wy) - k o w
// (w' = 0 with the rates held), the quaternion normalised before the step and after it.
// Every number comes from generated/model.hpp; float32 in the order of the Python float64
// expressions (the image is built with -ffp-contract=off). Fixed sizes, no heap; sqrtf only.
// The rigid body, the input ring and RK4 are fw/quad_body.hpp's (shared with quad_hybrid).
#pragma once
#include <cmath>
#include <cstdint>

#include "fw/quad_body.hpp"
#include "model.hpp"

#ifndef CDAM_FW_STEP_MODEL_HPP
#error "include fw/step_model.hpp, which includes this header for CDAM_MODEL_KIND 4"
#endif

namespace fw {

class StepModel {
 public:
  static constexpr int kS = quad::kS;
  static constexpr int kK = cdam_model::kKernel;       // lag kernel taps (1 without a lag)
  static constexpr int kDT = cdam_model::kDelayTrans;  // input delay of the thrust (samples)
  static constexpr int kDR = cdam_model::kDelayRot;    // input delay of the torques
  // input rows kept: u(t-1) back to u(t-1-d-(kK-1)-reaction)
  static constexpr int kBack = (kDT > kDR ? kDT : kDR) + kK - 1 + (cdam_model::kReaction ? 1 : 0);
  static constexpr int kRing = kBack + 1;
  static_assert(kRing <= cdam_model::kHistory, "the history holds every input row the step uses");

  void prime(const float* u, const float* y) {
    ring_.push(u);
    for (int i = 0; i < kS; ++i) x_[i] = y[i];
  }

  void step(const float* u, float* y) {
    quad::normalise(x_);
    float f[4];
    ring_.drive(kDT, f);
    const float thrust = cdam_model::kTrans[0] * (((f[0] + f[1]) + f[2]) + f[3]);
    float acc[3] = {0.0f, 0.0f, 0.0f};
    if (cdam_model::kRatesDynamic) {
      ring_.drive(kDR, f);
      float tau[3];
      quad::torque_combinations(f, tau);
      for (int j = 0; j < 3; ++j) acc[j] = cdam_model::kRot[j] * tau[j] + cdam_model::kRot[6 + j];
      if (cdam_model::kReaction) {
        const float* a = ring_.input(kDR);
        const float* b = ring_.input(kDR + 1);
        // (U[t-d] - U[t-d-1]) @ (-1, 1, -1, 1) / dt
        const float yaw = ((((a[0] - b[0]) * -1.0f) + (a[1] - b[1])) + ((a[2] - b[2]) * -1.0f)
                           + (a[3] - b[3])) / cdam_model::kDt;
        acc[2] = acc[2] + cdam_model::kRot[12] * yaw;
      }
    }
    // w' = torque acceleration + c o (wy wz, wx wz, wx wy) - k o w (0 with the rates held)
    quad::rk4(x_, thrust, [&acc](const float* x, float* dx) {
      if (cdam_model::kRatesDynamic) {
        const float wx = x[10], wy = x[11], wz = x[12];
        const float g[3] = {wy * wz, wx * wz, wx * wy};
        const float w[3] = {wx, wy, wz};
        for (int j = 0; j < 3; ++j)
          dx[10 + j] = (acc[j] + cdam_model::kRot[3 + j] * g[j]) - cdam_model::kRot[9 + j] * w[j];
      } else {
        for (int j = 0; j < 3; ++j) dx[10 + j] = 0.0f;
      }
    });
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
  float x_[kS] = {};
  quad::InputRing<kRing> ring_;
};

inline std::uint32_t params_fnv1a() {
  std::uint32_t h = fnv1a_floats(0x811C9DC5u, cdam_model::kTrans, sizeof(cdam_model::kTrans) / 4);
  h = fnv1a_floats(h, cdam_model::kRot, sizeof(cdam_model::kRot) / 4);
  return fnv1a_floats(h, cdam_model::kKernelW, sizeof(cdam_model::kKernelW) / 4);
}

}  // namespace fw
