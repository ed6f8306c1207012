// The 2-link planar arm hanging below the body, each joint driven through a flexible cable
// (Spong's flexible-joint model, paper eqs. (3)-(5)).
//
// Geometry (body frame): joint-1 axis at r0 = (0, 0, -d_base), both joint axes along body y,
// q = 0 hanging straight down. With e(a) = (-sin a, 0, -cos a) and e'(a) = de/da:
//   link 1 CoM  r1 = r0 + lc1 e(q1)
//   link 2 CoM  r2 = r0 + l1 e(q1) + lc2 e(q1 + q2)
//   payload     rp = r0 + l1 e(q1) + l2 e(q1 + q2)          (point mass, effect payload_mass)
// Their body-frame velocity is J(q) q' and their acceleration J(q) q'' + r''_v with
// r''_v = -lc1 e(q1) q1'^2 (link 1), -l1 e(q1) q1'^2 - lc2 e(a2) a2'^2 (link 2), a2 = q1 + q2.
// Link k turns about body y at s_k . q' (s_1 = (1, 0), s_2 = (1, 1)); its inertia in the body
// frame is Ry(a_k) diag(Ixx, Iyy, Izz) Ry(a_k)^T.
// With the body held fixed these give the textbook M(q), C(q, q') q', G(q) of a 2-link arm:
// M11 = I1yy + I2yy + m1 lc1^2 + m2 (l1^2 + lc2^2 + 2 l1 lc2 cos q2), M12 = I2yy + m2 (lc2^2 +
// l1 lc2 cos q2), M22 = I2yy + m2 lc2^2; G = g (m1 lc1 + m2 l1) sin q1 + g m2 lc2 sin(q1 + q2),
// g m2 lc2 sin(q1 + q2) (test_sim.cpp checks this limit).
//
// Cable torque, eq. (4) with the backlash and hardening effects:
//   tau_l = Ks dz + K3 dz^3 + Kd (theta_m' - q'),   dz = dead_zone(theta_m - q, backlash)
// Motor side, eq. (3) with Coulomb friction: Im theta_m'' = tau_m - Dm theta_m' - tau_l
//   - Fc tanh(theta_m' / eps).
#pragma once
#include <Eigen/Core>
#include <cmath>

#include "cdam/sim/effects.hpp"
#include "cdam/sim/params.hpp"
#include "cdam/sim/quadrotor.hpp"

namespace cdam::sim {

struct ArmBody {
  double m;
  Vec3 r;                          // CoM in the body frame
  Eigen::Matrix<double, 3, 2> J;   // d r / d q
  Vec3 quad;                       // velocity-quadratic part of r''
  Vec3 rd;                         // r' = J q'
  double s1, s2;                   // angular rate about body y = s1 q1' + s2 q2'
  Mat3 I;                          // inertia about the CoM, body frame (zero for a point mass)
  bool has_inertia;
};

inline Vec3 arm_e(double a) { return Vec3(-std::sin(a), 0.0, -std::cos(a)); }
inline Vec3 arm_de(double a) { return Vec3(-std::cos(a), 0.0, std::sin(a)); }

inline Mat3 inertia_about_y(double a, double ixx, double iyy, double izz) {
  const double c = std::cos(a), s = std::sin(a);
  Mat3 R;
  R << c, 0, s, 0, 1, 0, -s, 0, c;
  return R * Vec3(ixx, iyy, izz).asDiagonal() * R.transpose();
}

// The three arm bodies (link 1, link 2, payload) at (q, q').
inline void arm_bodies(const PlantParams& p, double q1, double q2, double qd1, double qd2,
                       ArmBody out[3]) {
  const double a1 = q1, a2 = q1 + q2, a1d = qd1, a2d = qd1 + qd2;
  const Vec3 r0(0.0, 0.0, -p.d_base);
  const Vec3 e1 = arm_e(a1), de1 = arm_de(a1), e2 = arm_e(a2), de2 = arm_de(a2);
  ArmBody& b1 = out[0];
  b1.m = p.m1;
  b1.J.col(0) = p.lc1 * de1;
  b1.J.col(1).setZero();
  b1.r = r0 + p.lc1 * e1;
  b1.rd = p.lc1 * de1 * a1d;
  b1.quad = -p.lc1 * e1 * a1d * a1d;
  b1.s1 = 1.0; b1.s2 = 0.0;
  b1.I = inertia_about_y(a1, p.I1xx, p.I1yy, p.I1zz);
  b1.has_inertia = true;
  const double ms[2] = {p.m2, p.payload}, lcs[2] = {p.lc2, p.l2};
  for (int k = 0; k < 2; ++k) {
    ArmBody& b = out[1 + k];
    const double lc = lcs[k];
    b.m = ms[k];
    b.J.col(0) = p.l1 * de1 + lc * de2;
    b.J.col(1) = lc * de2;
    b.r = r0 + p.l1 * e1 + lc * e2;
    b.rd = p.l1 * de1 * a1d + lc * de2 * a2d;
    b.quad = -p.l1 * e1 * a1d * a1d - lc * e2 * a2d * a2d;
    b.s1 = 1.0; b.s2 = 1.0;
    b.has_inertia = (k == 0);
    if (b.has_inertia) b.I = inertia_about_y(a2, p.I2xx, p.I2yy, p.I2zz);
    else b.I.setZero();
  }
}

// Eq. (4) with backlash and hardening, joint k (0 or 1).
inline double cable_torque(const PlantParams& p, int k, double defl, double defl_d) {
  const double dz = dead_zone(defl, p.backlash[k]);
  return p.Ks[k] * dz + p.K3[k] * (dz * dz * dz) + p.Kd[k] * defl_d;
}

}  // namespace cdam::sim
