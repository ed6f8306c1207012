// The quadrotor rigid body shared by the two flight kinds on the target, `quad_physics`
// (fw/quad_physics_step.hpp) and `quad_hybrid` (fw/quad_hybrid_step.hpp): the input ring with
// the actuation-lag drive, the translational and quaternion equations, and one RK4 step of dt
// with the drive held (cdam_core.models.flight.physics.rk4_step), the rates' derivative given
// by the kind. Every number comes from generated/model.hpp (kTrans, kKernelW, kGravity, kDt,
// kDt6); float32 in the order of the Python float64 expressions (the image is built with
// -ffp-contract=off). Fixed sizes, no heap; sqrtf only.
#pragma once
#include <cmath>

#include "model.hpp"

namespace fw {
namespace quad {

constexpr int kS = 13;   // states: position, world velocity, quaternion xyzw, body rates

inline void normalise(float* x) {
  const float n = std::sqrt(((x[6] * x[6] + x[7] * x[7]) + x[8] * x[8]) + x[9] * x[9]);
  for (int i = 6; i < 10; ++i) x[i] = x[i] / n;
}

// the roll, pitch and yaw combinations of the squared rotor speeds (X configuration)
inline void torque_combinations(const float* f, float* tau) {
  tau[0] = ((-f[0] - f[1]) + f[2]) + f[3];
  tau[1] = ((-f[0] + f[1]) + f[2]) - f[3];
  tau[2] = ((-f[0] + f[1]) - f[2]) + f[3];
}

// The rotor-speed rows, a ring of R rows with `head_` the newest (u(t-1) during a step).
template <int R>
class InputRing {
 public:
  void push(const float* u) {
    head_ = head_ + 1 < R ? head_ + 1 : 0;
    for (int c = 0; c < 4; ++c) u_[head_][c] = u[c];
  }

  const float* input(int back) const {
    const int k = head_ - back;
    return u_[k < 0 ? k + R : k];
  }

  // f_i = sum_j kKernelW[j] u_i(t-1-d-j)^2, the newest row being u(t-1)
  void drive(int d, float* f) const {
    for (int i = 0; i < 4; ++i) f[i] = 0.0f;
    for (int j = 0; j < cdam_model::kKernel; ++j) {
      const float* r = input(d + j);
      for (int i = 0; i < 4; ++i) f[i] = f[i] + cdam_model::kKernelW[j] * (r[i] * r[i]);
    }
  }

 private:
  float u_[R][4] = {};
  int head_ = 0;
};

// dx[0..9]: p' = v, v' = thrust n - dxy v - (dz - dxy) n (n . v) - g e3, q' = 1/2 q (x) (w, 0)
inline void body_derivative(const float* x, float thrust, float* dx) {
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
}

// One RK4 step of dt of the state x with the drive held; `rates(state, dx)` writes the rates'
// derivative dx[10..12]. The quaternion is normalised after the step.
template <class Rates>
inline void rk4(float* x, float thrust, const Rates& rates) {
  constexpr float half = 0.5f * cdam_model::kDt;   // 0.5 * dt (float32 of the float64 product)
  constexpr float sixth = cdam_model::kDt6;        // dt / 6
  float k1[kS], k2[kS], k3[kS], k4[kS], tmp[kS];
  body_derivative(x, thrust, k1);
  rates(x, k1);
  for (int i = 0; i < kS; ++i) tmp[i] = x[i] + half * k1[i];
  body_derivative(tmp, thrust, k2);
  rates(tmp, k2);
  for (int i = 0; i < kS; ++i) tmp[i] = x[i] + half * k2[i];
  body_derivative(tmp, thrust, k3);
  rates(tmp, k3);
  for (int i = 0; i < kS; ++i) tmp[i] = x[i] + cdam_model::kDt * k3[i];
  body_derivative(tmp, thrust, k4);
  rates(tmp, k4);
  for (int i = 0; i < kS; ++i)
    x[i] = x[i] + sixth * (((k1[i] + 2.0f * k2[i]) + 2.0f * k3[i]) + k4[i]);
  normalise(x);
}

}  // namespace quad
}  // namespace fw
