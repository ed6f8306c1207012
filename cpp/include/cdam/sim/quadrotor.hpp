// The quadrotor: attitude kinematics (unit quaternion body -> world, Z-Y-X Euler output), rotor
// speeds to thrust and moments (paper eq. (2) with the X-frame mixer), rotor gyroscopic torque.
//
// Frames: world Z up, body x forward, y left, z up. X frame, arm factor a = L / sqrt(2):
//   rotor 1 front-right (+a, -a), 2 rear-right (-a, -a), 3 rear-left (-a, +a),
//   4 front-left (+a, +a); rotors 1 and 3 spin one way, 2 and 4 the other.
//   T      = CT (O1^2 + O2^2 + O3^2 + O4^2)
//   tau_x  = a CT (-O1^2 - O2^2 + O3^2 + O4^2)          (roll,  tau_phi)
//   tau_y  = a CT (-O1^2 + O2^2 + O3^2 - O4^2)          (pitch, tau_theta)
//   tau_z  = CQ (O1^2 - O2^2 + O3^2 - O4^2)              (yaw,   tau_psi)
// (the paper's plus-frame eq. (2) rotated by 45 degrees; the rows are orthogonal, so the
// inverse is a quarter of the transposed +-1 pattern). Gyroscopic torque of the rotors:
//   tau_g = -Jm Om (omega x e_z), Om = O1 - O2 + O3 - O4,
// i.e. tau_g,x = -Jm omega_y Om, tau_g,y = +Jm omega_x Om, as in eq. (1).
#pragma once
#include <Eigen/Core>
#include <algorithm>
#include <cmath>

#include "cdam/sim/params.hpp"

namespace cdam::sim {

using Vec3 = Eigen::Matrix<double, 3, 1>;
using Vec4 = Eigen::Matrix<double, 4, 1>;
using Mat3 = Eigen::Matrix<double, 3, 3>;

inline Mat3 quat_to_rot(double w, double x, double y, double z) {
  Mat3 R;
  R << 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
      2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
      2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y);
  return R;
}

// Z-Y-X Euler angles (phi, theta, psi) of a unit quaternion.
inline Vec3 quat_to_euler(double w, double x, double y, double z) {
  const double s = std::clamp(2 * (w * y - z * x), -1.0, 1.0);
  return Vec3(std::atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y)), std::asin(s),
              std::atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)));
}

inline Vec3 cross(const Vec3& a, const Vec3& b) {
  return Vec3(a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]);
}

// Squared rotor speeds for (T, tau_x, tau_y, tau_z), clamped to [omega_min^2, omega_max^2].
inline Vec4 mixer(const PlantParams& p, double T, const Vec3& tau) {
  const double a = p.L / std::sqrt(2.0);
  const double b0 = T / p.CT, b1 = tau[0] / (a * p.CT), b2 = tau[1] / (a * p.CT),
               b3 = tau[2] / p.CQ;
  Vec4 s(0.25 * (b0 - b1 - b2 + b3), 0.25 * (b0 - b1 + b2 - b3), 0.25 * (b0 + b1 + b2 + b3),
         0.25 * (b0 + b1 - b2 - b3));
  const double lo = p.omega_min * p.omega_min, hi = p.omega_max * p.omega_max;
  for (int i = 0; i < 4; ++i) s[i] = std::min(std::max(s[i], lo), hi);
  return s;
}

// Nominal eq. (2): (T, tau_x, tau_y, tau_z) from squared rotor speeds.
inline Vec4 mixer_forward(const PlantParams& p, const Vec4& s) {
  const double a = p.L / std::sqrt(2.0);
  return Vec4(p.CT * (s[0] + s[1] + s[2] + s[3]), a * p.CT * (-s[0] - s[1] + s[2] + s[3]),
              a * p.CT * (-s[0] + s[1] + s[2] - s[3]), p.CQ * (s[0] - s[1] + s[2] - s[3]));
}

}  // namespace cdam::sim
