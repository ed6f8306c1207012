// Closed loop as flown: Pixhawk-like PID cascades (position -> velocity -> tilt, altitude ->
// climb rate -> thrust, attitude angle -> body rate -> torque) and the STM32-like joint PID on
// the motor angle producing the motor torque; every stage saturated. One tick per 1 kHz sample.
//
// Setpoints sp (kNsp = 8): X, Y, Z (m), roll and pitch offsets added to the position loop's
// tilt (the operator's sticks, rad), yaw psi (rad), joint setpoints q1, q2 (rad).
//   v_sp  = sat(kp_pos (p_sp - p), v_max); a = kp_vel e_v + ki_vel int(e_v) (int clamped 2)
//   theta_d = sat(sat((a_x cos psi + a_y sin psi) / g) + sp_theta), phi_d likewise with
//   (a_x sin psi - a_y cos psi) / g, both within tilt_max
//   vz_sp = sat(kp_z (Z_sp - Z), 1.5); a_z = kp_vz e_vz + ki_vz int(e_vz) (int clamped 5)
//   T = m_ctrl (g + a_z) / max(cos phi cos theta, 0.5), within [0, 4 CT omega_max^2]
//   w_sp = sat(kp_att e_eta, rate_max) (yaw error wrapped), tau = sat(J (kp e_w + ki int(e_w)
//   - kd dw/dt), tau_max) (int clamped 1, dw/dt a backward difference)
//   tau_m = sat(kp_j (q_sp - theta_m) + ki_j int - kd_j theta_m', tau_m_max), then rounded to
//   the C610 current step kt * current_lsb.
// Controller state cs (kNcs = 11): 3 velocity integrators, 3 rate integrators, 2 joint
// integrators, the previous body rates.
#pragma once
#include <Eigen/Core>
#include <algorithm>
#include <cmath>

#include "cdam/sim/coupling.hpp"
#include "cdam/sim/params.hpp"
#include "cdam/sim/quadrotor.hpp"

namespace cdam::sim {

constexpr int kNsp = 8;
constexpr int kNcs = 11;
using Setpoint = Eigen::Matrix<double, kNsp, 1>;
using CtrlState = Eigen::Matrix<double, kNcs, 1>;

inline double sat(double v, double lim) { return std::min(std::max(v, -lim), lim); }
inline double wrap_angle(double a) { return std::atan2(std::sin(a), std::cos(a)); }

struct Command {
  Vec4 s;       // squared rotor speeds (clamped)
  double tau_m[2];
};

inline Command control_tick(const PlantParams& p, const ControlParams& c, const State& x,
                            const Setpoint& sp, CtrlState& cs, double dt) {
  const double g = p.g;
  const Vec3 eta = quat_to_euler(x[3], x[4], x[5], x[6]);
  const double phi = eta[0], theta = eta[1], psi = eta[2];
  double acc[2];
  for (int i = 0; i < 2; ++i) {
    const double vsp = sat(c.kp_pos * (sp[i] - x[i]), c.v_max);
    const double e = vsp - x[11 + i];
    cs[i] = sat(cs[i] + e * dt, 2.0);
    acc[i] = c.kp_vel * e + c.ki_vel * cs[i];
  }
  const double cy = std::cos(psi), sy = std::sin(psi), tmax = c.tilt_max;
  const double theta_d = sat(sat((acc[0] * cy + acc[1] * sy) / g, tmax) + sp[4], tmax);
  const double phi_d = sat(sat((acc[0] * sy - acc[1] * cy) / g, tmax) + sp[3], tmax);
  const double vzsp = sat(c.kp_z * (sp[2] - x[2]), 1.5);
  const double ez = vzsp - x[13];
  cs[2] = sat(cs[2] + ez * dt, 5.0);
  const double az = c.kp_vz * ez + c.ki_vz * cs[2];
  const double m = c.m_ctrl > 0 ? c.m_ctrl : p.total_mass(false);
  double T = m * (g + az) / std::max(std::cos(phi) * std::cos(theta), 0.5);
  T = std::min(std::max(T, 0.0), 4.0 * p.CT * p.omega_max * p.omega_max);
  const double e_eta[3] = {phi_d - phi, theta_d - theta, wrap_angle(sp[5] - psi)};
  const double kp_att[3] = {c.kp_att_rp, c.kp_att_rp, c.kp_att_y};
  const double kp_r[3] = {c.kp_rate_rp, c.kp_rate_rp, c.kp_rate_y};
  const double ki_r[3] = {c.ki_rate_rp, c.ki_rate_rp, c.ki_rate_y};
  const double kd_r[3] = {c.kd_rate_rp, c.kd_rate_rp, 0.0};
  const double J[3] = {p.Jx, p.Jy, p.Jz};
  Vec3 tau;
  for (int i = 0; i < 3; ++i) {
    const double w = x[14 + i];
    const double wsp = sat(kp_att[i] * e_eta[i], c.rate_max);
    const double e = wsp - w;
    cs[3 + i] = sat(cs[3 + i] + e * dt, 1.0);
    const double dw = (w - cs[8 + i]) / dt;
    tau[i] = sat(J[i] * (kp_r[i] * e + ki_r[i] * cs[3 + i] - kd_r[i] * dw), c.tau_max);
    cs[8 + i] = w;
  }
  Command out;
  out.s = mixer(p, T, tau);
  for (int k = 0; k < 2; ++k) {
    const double e = sp[6 + k] - x[9 + k];
    cs[6 + k] = sat(cs[6 + k] + e * dt, 0.5);
    double tm = sat(c.kp_joint * e + c.ki_joint * cs[6 + k] - c.kd_joint * x[19 + k], c.tau_m_max);
    if (c.current_lsb > 0) {
      const double lsb = c.kt * c.current_lsb;
      tm = lsb * std::floor(tm / lsb + 0.5);
    }
    out.tau_m[k] = tm;
  }
  return out;
}

}  // namespace cdam::sim
