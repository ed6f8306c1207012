// Running the simulator: open loop (inputs given) and closed loop (controller at the logging
// rate), fixed-step RK4 with sub-steps, caller-owned output buffers, no heap in the loop.
//
// Sub-step rule (the stability criterion checked): RK4 is stable for |h lambda| < 2.78; the
// fastest modes of the plant are the motor-side cable modes, omega_k = sqrt(Ks_eff / Im_eff)
// with Im_eff = Im I_link / (Im + I_link) <= Im, Ks_eff = Ks + 3 K3 dz_max^2, and the
// motor-side damping rates (Dm + Kd + Fc/eps) / Im. We take the bound
//   rate_max = max_k max(sqrt(Ks_eff,k / Im_k), (Dm_k + Kd_k + Fc_k / eps) / Im_k)
// (Im_eff <= Im makes sqrt(Ks/Im) a lower bound of the two-mass frequency; the factor
// sqrt(1 + Im/I_link) is below 1.1 here and covered by the margin) and require
// h * rate_max <= kRk4StabilityLimit = 2.5, i.e. substeps = ceil(dt * rate_max / 2.5).
// A step that leaves the state NaN or Inf (dt too large for the sub-steps given) ends the run
// with Status::Diverged; the states written before it stay valid.
#pragma once
#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>

#include "cdam/safe_size.hpp"
#include "cdam/sim/controllers.hpp"
#include "cdam/sim/coupling.hpp"
#include "cdam/sim/effects.hpp"
#include "cdam/sim/rk4.hpp"
#include "cdam/status.hpp"

namespace cdam::sim {

constexpr int kNlog = 10;   // T, tau_phi, tau_theta, tau_psi, tau_m1, tau_m2, O1..O4
constexpr int kMaxDelay = 255;

// Fastest mode (rad/s) of the motor sides; dz_max bounds the cable deflection for K3.
inline double fastest_rate(const PlantParams& p, double dz_max = 0.2) {
  double r = 0.0;
  for (int k = 0; k < 2; ++k) {
    const double ks = p.Ks[k] + 3.0 * std::abs(p.K3[k]) * dz_max * dz_max;
    const double damp = p.Dm[k] + p.Kd[k] + (p.fric_eps > 0 ? std::abs(p.Fc[k]) / p.fric_eps : 0.0);
    r = std::max(r, std::max(std::sqrt(ks / p.Im[k]), damp / p.Im[k]));
  }
  return r;
}

// At least 1; saturates at INT_MAX for a huge dt (NaN gives 1) instead of an undefined cast.
inline int substeps_for(const PlantParams& p, double dt) {
  return round_saturate<int>(std::ceil(dt * fastest_rate(p) / kRk4StabilityLimit), 1,
                             std::numeric_limits<int>::max());
}

inline void normalise_quaternion(State& x) { x.segment<4>(3) /= x.segment<4>(3).norm(); }

inline Status check_plant(const PlantParams& p) {
  const double pos[] = {p.m_body, p.Jx, p.Jy, p.Jz, p.g, p.CT, p.CQ, p.L, p.Im[0], p.Im[1],
                        p.fric_eps, p.m1, p.m2};
  for (double v : pos)
    if (!(v > 0) || !std::isfinite(v)) return Status::InvalidArgument;
  if (p.payload < 0 || p.backlash[0] < 0 || p.backlash[1] < 0 || p.omega_min < 0 ||
      p.omega_max <= p.omega_min)
    return Status::InvalidArgument;
  return Status::Ok;
}

// Open loop: states (kNx x (n+1), column-major, column k = x at t = k dt) from x0 under inputs
// U (kNu x n), each held over one dt split into `substeps` RK4 steps; the quaternion is
// renormalised after each dt. `poll` (status.hpp) is asked every tick; false: Cancelled.
template <typename Poll = NeverCancel>
inline Status simulate_open_loop(const PlantParams& p, const double* x0, const double* U, long n,
                                 double dt, int substeps, double* X, Poll poll = Poll()) {
  if (n < 0 || !(dt > 0) || substeps < 1) return Status::InvalidArgument;
  State x = Eigen::Map<const State>(x0);
  Eigen::Map<State> x_first(X);
  x_first = x;
  const double h = dt / substeps;
  Input u;
  auto f = [&](double t, const State& xs, State& dx) { rhs(p, t, xs, u, dx); };
  for (long k = 0; k < n; ++k) {
    if (!poll()) return Status::Cancelled;
    u = Eigen::Map<const Input>(U + k * kNu);
    const double t = k * dt;
    for (int j = 0; j < substeps; ++j) rk4_step<kNx>(f, t + j * h, x, h);
    normalise_quaternion(x);
    if (!x.allFinite()) return Status::Diverged;
    Eigen::Map<State> x_next(X + (k + 1) * kNx);
    x_next = x;
  }
  return Status::Ok;
}

// Closed loop: setpoints SP (kNsp x n); writes states X (kNx x n, the state at each tick) and
// LOG (kNlog x n: the commanded T, tau_phi, tau_theta, tau_psi from the clamped rotor speeds by
// the nominal eq. (2), tau_m1, tau_m2, O1..O4). Commands are held over the tick (zero-order
// hold) and applied delay_rotor / delay_joint ticks late. `poll` as in simulate_open_loop.
template <typename Poll = NeverCancel>
inline Status simulate_closed_loop(const PlantParams& p, const ControlParams& c, const double* x0,
                                   const double* SP, long n, double dt, int substeps, double* X,
                                   double* LOG, Poll poll = Poll()) {
  if (n < 1 || !(dt > 0) || substeps < 1) return Status::InvalidArgument;
  if (!(c.delay_rotor >= 0 && c.delay_rotor <= kMaxDelay && c.delay_joint >= 0 &&
        c.delay_joint <= kMaxDelay))
    return Status::InvalidArgument;  // before the casts: NaN or a huge delay is no int
  const int dr = static_cast<int>(c.delay_rotor), dj = static_cast<int>(c.delay_joint);
  State x = Eigen::Map<const State>(x0);
  CtrlState cs = CtrlState::Zero();
  cs.segment<3>(8) = x.segment<3>(14);
  DelayLine<Vec4, kMaxDelay + 1> rotor_line;
  DelayLine<Eigen::Matrix<double, 2, 1>, kMaxDelay + 1> joint_line;
  rotor_line.reset(dr);
  joint_line.reset(dj);
  const double h = dt / substeps;
  Input u;
  auto f = [&](double t, const State& xs, State& dx) { rhs(p, t, xs, u, dx); };
  for (long k = 0; k < n; ++k) {
    if (!poll()) return Status::Cancelled;
    Eigen::Map<State> x_out(X + k * kNx);
    x_out = x;
    const Setpoint sp = Eigen::Map<const Setpoint>(SP + k * kNsp);
    const Command cmd = control_tick(p, c, x, sp, cs, dt);
    Vec4 om;
    for (int i = 0; i < 4; ++i) om[i] = std::sqrt(cmd.s[i]);
    Eigen::Map<Eigen::Matrix<double, kNlog, 1>> log(LOG + k * kNlog);
    log.segment<4>(0) = mixer_forward(p, cmd.s);
    log[4] = cmd.tau_m[0];
    log[5] = cmd.tau_m[1];
    log.segment<4>(6) = om;
    const Vec4& om_applied = rotor_line.push(om);
    const Eigen::Matrix<double, 2, 1>& tm_applied =
        joint_line.push(Eigen::Matrix<double, 2, 1>(cmd.tau_m[0], cmd.tau_m[1]));
    u.segment<4>(0) = om_applied;
    u.segment<2>(4) = tm_applied;
    const double t = k * dt;
    for (int j = 0; j < substeps; ++j) rk4_step<kNx>(f, t + j * h, x, h);
    normalise_quaternion(x);
    if (!x.allFinite()) return Status::Diverged;
  }
  return Status::Ok;
}

}  // namespace cdam::sim
