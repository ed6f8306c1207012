// The fully coupled rigid-flexible aerial manipulator: x' = f(t, x, u).
//
// State x (kNx = 21): p = (X, Y, Z) world [0:3]; unit quaternion (w, x, y, z) body -> world
// [3:7]; link angles q1, q2 [7:9]; motor angles theta_m1, theta_m2 after the gearbox [9:11];
// v = p' world [11:14]; omega body rates [14:17]; q' [17:19]; theta_m' [19:21].
// Input u (kNu = 6): rotor speeds O1..O4 (rad/s) and motor torques tau_m1, tau_m2 (N m).
//
// Equations. Generalised speeds nu = (v, omega, q') (8) and, separately, theta_m'. Bodies k:
// the quadrotor (mass m_body, inertia diag(Jx, Jy, Jz) at the body origin), link 1, link 2
// (rigid, inertia I_k) and the payload (point mass) of flexible_arm.hpp. With R the body ->
// world rotation and r_k, J_k, r''_v,k, s_k from flexible_arm.hpp, the world acceleration of
// a CoM and the angular acceleration of a link (body-frame components) are affine in nu':
//   a_k     = A_k nu' + b_k,  A_k = [I3, -R [r_k]x, R J_k],
//             b_k = R (omega x (omega x r_k) + 2 omega x r_k' + r''_v,k)
//   alpha_k = B_k nu' + c_k,  B_k = [0, I3, e_y s_k^T],  c_k = omega x (s_k . q') e_y,
//   omega_k = omega + (s_k . q') e_y.
// Kane's equations (the partial velocities are A_k and B_k) give
//   M nu' = Q - h,   M = sum m_k A_k^T A_k + B_k^T I_k B_k          (8 x 8, SPD)
//   h = sum m_k A_k^T b_k + B_k^T (I_k c_k + omega_k x I_k omega_k)  (body: omega x J omega)
//   Q = [ R e_z T - diag(Kx, Ky, Kz) v - sum m_k g e_z ;
//         tau_rotors + tau_gyro - diag(Kphi, Ktheta, Kpsi) omega + sum r_k x R^T(-m_k g e_z) ;
//         tau_l - Dl q' + sum J_k^T R^T (-m_k g e_z) ]
// This is the Newton-Euler / Lagrange system of the whole vehicle: the arm's reaction forces
// and moments on the body are the off-diagonal blocks of M and the arm terms of h and Q; the
// body's motion drives the arm through the same blocks. With the body fixed it reduces to eq.
// (5), M(q) q'' + C(q, q') q' + G(q) + Dl q' = tau_l; with the arm removed to eq. (1) (with
// omega for the Euler rates, exact at small angles). The motor sides follow eq. (3) (rotor
// kinetic energy taken relative to the body only, Spong's assumption). Quaternion kinematics:
// quat' = 0.5 quat (x) (0, omega).
// Energy (conserved without drag, damping and inputs; tests/test_sim_energy.py):
//   E = sum 1/2 m_k |v_k|^2 + 1/2 omega_k . I_k omega_k + 1/2 Im theta_m'^2 + 1/2 Ks dz^2
//       + 1/4 K3 dz^4 + m_k g z_k.
#pragma once
#include <Eigen/Cholesky>
#include <Eigen/Core>
#include <cmath>

#include "cdam/sim/effects.hpp"
#include "cdam/sim/flexible_arm.hpp"
#include "cdam/sim/params.hpp"
#include "cdam/sim/quadrotor.hpp"

namespace cdam::sim {

constexpr int kNx = 21;
constexpr int kNu = 6;
using State = Eigen::Matrix<double, kNx, 1>;
using Input = Eigen::Matrix<double, kNu, 1>;
using Mat8 = Eigen::Matrix<double, 8, 8>;
using Vec8 = Eigen::Matrix<double, 8, 1>;

inline Mat3 skew(const Vec3& r) {
  Mat3 S;
  S << 0, -r[2], r[1], r[2], 0, -r[0], -r[1], r[0], 0;
  return S;
}

// dx/dt at (t, x, u). No heap.
inline void rhs(const PlantParams& p, double t, const State& x, const Input& u, State& dx) {
  const double qw = x[3], qx = x[4], qy = x[5], qz = x[6];
  const Mat3 R = quat_to_rot(qw, qx, qy, qz);
  const Vec3 v = x.segment<3>(11), w = x.segment<3>(14);
  const double g = p.g;
  const Vec3 ez(0, 0, 1), ey(0, 1, 0);
  // rotors, eq. (2) X frame, with the thrust effects
  Vec4 s;
  for (int i = 0; i < 4; ++i) s[i] = u[i] * u[i];
  const double a = p.L / std::sqrt(2.0);
  const ThrustFactors f = thrust_factors(p, t, x[2]);
  const double T = p.CT * (s[0] + s[1] + s[2] + s[3]) * f.collective;
  Vec3 tau(a * p.CT * (-s[0] - s[1] + s[2] + s[3]) * f.rotor,
           a * p.CT * (-s[0] + s[1] + s[2] - s[3]) * f.rotor, p.CQ * (s[0] - s[1] + s[2] - s[3]));
  const double omr = u[0] - u[1] + u[2] - u[3];
  tau = tau - p.Jm * omr * cross(w, ez);
  tau = tau - Vec3(p.Kphi, p.Ktheta, p.Kpsi).cwiseProduct(w);
  // cable torques, eq. (4)
  double tl[2];
  for (int k = 0; k < 2; ++k) tl[k] = cable_torque(p, k, x[9 + k] - x[7 + k], x[19 + k] - x[17 + k]);
  // Kane: M nu' = Q - h
  Mat8 M = Mat8::Zero();
  Vec8 Q = Vec8::Zero(), h = Vec8::Zero();
  M.block<3, 3>(0, 0) += p.m_body * Mat3::Identity();
  M.block<3, 3>(3, 3) += Vec3(p.Jx, p.Jy, p.Jz).asDiagonal();
  h.segment<3>(3) = cross(w, Vec3(p.Jx, p.Jy, p.Jz).cwiseProduct(w));
  Q.segment<3>(0) = R * ez * T - Vec3(p.Kx, p.Ky, p.Kz).cwiseProduct(v) - p.m_body * g * ez;
  Q.segment<3>(3) = tau;
  Q[6] = tl[0] - p.Dl[0] * x[17];
  Q[7] = tl[1] - p.Dl[1] * x[18];
  ArmBody bodies[3];
  arm_bodies(p, x[7], x[8], x[17], x[18], bodies);
  // The sums over the arm bodies in block form (A_k = R [R^T, -[r]x, J]; R^T R = I):
  //   M_vv = m I, M_vw = -R [sum m r]x, M_vq = R sum m J, M_ww = sum m [r]x^T [r]x,
  //   M_wq = sum m [r]x J, M_qq = sum m J^T J; h_v = R sum m b', h_w = sum m r x b',
  //   h_q = sum m J^T b' with b' = R^T b_k; gravity likewise with g' = R^T (-g e_z).
  const Vec3 gb = R.transpose() * (-g * ez);
  double msum = 0.0;
  Vec3 mr = Vec3::Zero(), mb = Vec3::Zero(), hw = Vec3::Zero(), qw_g = Vec3::Zero();
  Mat3 Mww = Mat3::Zero();
  Eigen::Matrix<double, 3, 2> mJ = Eigen::Matrix<double, 3, 2>::Zero(),
                              Mwq = Eigen::Matrix<double, 3, 2>::Zero();
  Eigen::Matrix2d Mqq = Eigen::Matrix2d::Zero();
  Eigen::Vector2d hq = Eigen::Vector2d::Zero(), gq = Eigen::Vector2d::Zero();
  for (const ArmBody& bd : bodies) {
    const double m = bd.m;
    const Vec3 bb = cross(w, cross(w, bd.r)) + 2 * cross(w, bd.rd) + bd.quad;
    const Mat3 S = skew(bd.r);
    msum += m;
    mr += m * bd.r;
    mJ += m * bd.J;
    Mww.noalias() += m * (S.transpose() * S);
    Mwq.noalias() += m * (S * bd.J);
    Mqq.noalias() += m * (bd.J.transpose() * bd.J);
    mb += m * bb;
    hw += m * cross(bd.r, bb);
    hq.noalias() += m * (bd.J.transpose() * bb);
    qw_g += m * cross(bd.r, gb);
    gq.noalias() += m * (bd.J.transpose() * gb);
    if (bd.has_inertia) {
      // B_k = [0, I3, e_y s^T]: adds I to M_ww, I e_y s^T to M_wq, (e_y.I e_y) s s^T to M_qq
      const double sq = bd.s1 * x[17] + bd.s2 * x[18];
      const Eigen::Vector2d sv(bd.s1, bd.s2);
      const Vec3 wk = w + sq * ey;
      const Vec3 c = cross(w, sq * ey);
      const Vec3 tk = bd.I * c + cross(wk, bd.I * wk);
      Mww += bd.I;
      Mwq.noalias() += bd.I.col(1) * sv.transpose();
      Mqq.noalias() += bd.I(1, 1) * (sv * sv.transpose());
      hw += tk;
      hq += tk[1] * sv;
    }
  }
  M.block<3, 3>(0, 0) += msum * Mat3::Identity();
  const Mat3 Mvw = -R * skew(mr);
  const Eigen::Matrix<double, 3, 2> Mvq = R * mJ;
  M.block<3, 3>(0, 3) = Mvw;
  M.block<3, 3>(3, 0) = Mvw.transpose();
  M.block<3, 2>(0, 6) = Mvq;
  M.block<2, 3>(6, 0) = Mvq.transpose();
  M.block<3, 3>(3, 3) += Mww;
  M.block<3, 2>(3, 6) = Mwq;
  M.block<2, 3>(6, 3) = Mwq.transpose();
  M.block<2, 2>(6, 6) = Mqq;
  h.segment<3>(0) = R * mb;
  h.segment<3>(3) += hw;
  h.segment<2>(6) = hq;
  Q[2] -= msum * g;
  Q.segment<3>(3) += qw_g;
  Q.segment<2>(6) += gq;
  const Vec8 acc = M.ldlt().solve(Q - h);
  // motor sides, eq. (3) with Coulomb friction
  for (int k = 0; k < 2; ++k) {
    const double thd = x[19 + k];
    const double fric = p.Fc[k] * std::tanh(thd / p.fric_eps);
    dx[19 + k] = (u[4 + k] - p.Dm[k] * thd - tl[k] - fric) / p.Im[k];
  }
  dx.segment<3>(0) = v;
  // quat' = 0.5 quat (x) (0, w)
  dx[3] = 0.5 * (-qx * w[0] - qy * w[1] - qz * w[2]);
  dx[4] = 0.5 * (qw * w[0] + qy * w[2] - qz * w[1]);
  dx[5] = 0.5 * (qw * w[1] - qx * w[2] + qz * w[0]);
  dx[6] = 0.5 * (qw * w[2] + qx * w[1] - qy * w[0]);
  dx.segment<2>(7) = x.segment<2>(17);
  dx.segment<2>(9) = x.segment<2>(19);
  dx.segment<8>(11) = acc;
}

}  // namespace cdam::sim
