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
#pragma once
#include <cmath>
#include <cstdint>

#include "model.hpp"

#ifndef CDAM_FW_STEP_MODEL_HPP
#error "include fw/step_model.hpp, which includes this header for CDAM_MODEL_KIND 4"
#endif

namespace fw {

class StepModel {
 public:
  static constexpr int kS = 13;
  static constexpr int kK = cdam_model::kKernel;       // lag kernel taps (1 without a lag)
  static constexpr int kDT = cdam_model::kDelayTrans;  // input delay of the thrust (samples)
  static constexpr int kDR = cdam_model::kDelayRot;    // input delay of the torques
  // input rows kept: u(t-1) back to u(t-1-d-(kK-1)-reaction)
  static constexpr int kBack = (kDT > kDR ? kDT : kDR) + kK - 1 + (cdam_model::kReaction ? 1 : 0);
  static constexpr int kRing = kBack + 1;
  static_assert(kRing <= cdam_model::kHistory, "the history holds every input row the step uses");

  void prime(const float* u, const float* y) {
    push_input(u);
    for (int i = 0; i < kS; ++i) x_[i] = y[i];
  }

  void step(const float* u, float* y) {
    normalise(x_);
    float f[4];
    drive(kDT, f);
    const float thrust = cdam_model::kTrans[0] * (((f[0] + f[1]) + f[2]) + f[3]);
    float acc[3] = {0.0f, 0.0f, 0.0f};
    if (cdam_model::kRatesDynamic) {
      drive(kDR, f);
      const float tau[3] = {((-f[0] - f[1]) + f[2]) + f[3], ((-f[0] + f[1]) + f[2]) - f[3],
                            ((-f[0] + f[1]) - f[2]) + f[3]};
      for (int j = 0; j < 3; ++j) acc[j] = cdam_model::kRot[j] * tau[j] + cdam_model::kRot[6 + j];
      if (cdam_model::kReaction) {
        const float* a = input(kDR);
        const float* b = input(kDR + 1);
        // (U[t-d] - U[t-d-1]) @ (-1, 1, -1, 1) / dt
        const float yaw = ((((a[0] - b[0]) * -1.0f) + (a[1] - b[1])) + ((a[2] - b[2]) * -1.0f)
                           + (a[3] - b[3])) / cdam_model::kDt;
        acc[2] = acc[2] + cdam_model::kRot[12] * yaw;
      }
    }
    rk4(thrust, acc);
    for (int i = 0; i < kS; ++i) y[i] = x_[i];
    push_input(u);
  }

  void correct(const float* y) {
    for (int i = 0; i < kS; ++i) x_[i] = y[i];
  }

 private:
  static void normalise(float* x) {
    const float n = std::sqrt(((x[6] * x[6] + x[7] * x[7]) + x[8] * x[8]) + x[9] * x[9]);
    for (int i = 6; i < 10; ++i) x[i] = x[i] / n;
  }

  // f_i = sum_j kKernel[j] u_i(t-1-d-j)^2, the newest input row being u(t-1)
  void drive(int d, float* f) const {
    for (int i = 0; i < 4; ++i) f[i] = 0.0f;
    for (int j = 0; j < kK; ++j) {
      const float* r = input(d + j);
      for (int i = 0; i < 4; ++i) f[i] = f[i] + cdam_model::kKernelW[j] * (r[i] * r[i]);
    }
  }

  static void derivative(const float* x, float thrust, const float* acc, float* dx) {
    const float* v = x + 3;
    const float qx = x[6], qy = x[7], qz = x[8], qw = x[9];
    const float wx = x[10], wy = x[11], wz = x[12];
    const float n[3] = {2.0f * (qx * qz + qw * qy), 2.0f * (qy * qz - qw * qx),
                        1.0f - 2.0f * (qx * qx + qy * qy)};
    const float dxy = cdam_model::kTrans[1], dz = cdam_model::kTrans[2];
    const float nv = (n[0] * v[0] + n[1] * v[1]) + n[2] * v[2];
    for (int i = 0; i < 3; ++i) {
      dx[i] = v[i];
      dx[3 + i] = (thrust * n[i] - dxy * v[i]) - ((dz - dxy) * n[i]) * nv;
    }
    dx[5] = dx[5] - cdam_model::kGravity;
    dx[6] = 0.5f * (qw * wx + (qy * wz - qz * wy));
    dx[7] = 0.5f * (qw * wy + (qz * wx - qx * wz));
    dx[8] = 0.5f * (qw * wz + (qx * wy - qy * wx));
    dx[9] = -0.5f * ((qx * wx + qy * wy) + qz * wz);
    if (cdam_model::kRatesDynamic) {
      const float g[3] = {wy * wz, wx * wz, wx * wy};
      const float w[3] = {wx, wy, wz};
      for (int j = 0; j < 3; ++j)
        dx[10 + j] = (acc[j] + cdam_model::kRot[3 + j] * g[j]) - cdam_model::kRot[9 + j] * w[j];
    } else {
      for (int j = 0; j < 3; ++j) dx[10 + j] = 0.0f;
    }
  }

  void rk4(float thrust, const float* acc) {
    constexpr float half = 0.5f * cdam_model::kDt;   // 0.5 * dt (float32 of the float64 product)
    constexpr float sixth = cdam_model::kDt6;        // dt / 6
    float k1[kS], k2[kS], k3[kS], k4[kS], tmp[kS];
    derivative(x_, thrust, acc, k1);
    for (int i = 0; i < kS; ++i) tmp[i] = x_[i] + half * k1[i];
    derivative(tmp, thrust, acc, k2);
    for (int i = 0; i < kS; ++i) tmp[i] = x_[i] + half * k2[i];
    derivative(tmp, thrust, acc, k3);
    for (int i = 0; i < kS; ++i) tmp[i] = x_[i] + cdam_model::kDt * k3[i];
    derivative(tmp, thrust, acc, k4);
    for (int i = 0; i < kS; ++i)
      x_[i] = x_[i] + sixth * (((k1[i] + 2.0f * k2[i]) + 2.0f * k3[i]) + k4[i]);
    normalise(x_);
  }

  // the input rows, a ring of kRing rows with `head_` the newest (u(t-1) during step)
  void push_input(const float* u) {
    head_ = head_ + 1 < kRing ? head_ + 1 : 0;
    for (int c = 0; c < 4; ++c) u_[head_][c] = u[c];
  }

  const float* input(int back) const {
    const int k = head_ - back;
    return u_[k < 0 ? k + kRing : k];
  }

  float x_[kS] = {};
  float u_[kRing][4] = {};
  int head_ = 0;
};

inline std::uint32_t params_fnv1a() {
  std::uint32_t h = fnv1a_floats(0x811C9DC5u, cdam_model::kTrans, sizeof(cdam_model::kTrans) / 4);
  h = fnv1a_floats(h, cdam_model::kRot, sizeof(cdam_model::kRot) / 4);
  return fnv1a_floats(h, cdam_model::kKernelW, sizeof(cdam_model::kKernelW) / 4);
}

}  // namespace fw
