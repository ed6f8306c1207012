// Parameters of the simulated aerial manipulator: plant (body, rotors, arm, flexible joints,
// effects) and controller. Read from flat double arrays in the order of
// cdam_core.sim.parameters.PLANT_NAMES / CONTROL_NAMES (sources and units documented there).
#pragma once
#include <cmath>

namespace cdam::sim {

struct PlantParams {
  static constexpr int kSize = 51;
  // rigid body, eq. (1)
  double m_body, Jx, Jy, Jz, Kx, Ky, Kz, Kphi, Ktheta, Kpsi, g;
  // rotors, eq. (2)
  double CT, CQ, L, Jm, omega_min, omega_max;
  // arm: joint-1 axis d_base below the body CoM; link k mass, length, CoM, inertia about CoM
  double d_base, m1, l1, lc1, I1xx, I1yy, I1zz, m2, l2, lc2, I2xx, I2yy, I2zz;
  // flexible joints, eqs. (3)-(5)
  double Im[2], Dm[2], Ks[2], Kd[2], Dl[2];
  // effects: Coulomb friction (motor side), backlash (total width), cubic cable term,
  // payload point mass at the link-2 tip, ground-effect gain, rotor radius, thrust loss rate
  double Fc[2], fric_eps, backlash[2], K3[2], payload, ground_k, rotor_radius, thrust_loss;

  static PlantParams from_array(const double* a) {
    PlantParams p{};
    int i = 0;
    double* scalars1[] = {&p.m_body, &p.Jx, &p.Jy, &p.Jz, &p.Kx, &p.Ky, &p.Kz, &p.Kphi,
                          &p.Ktheta, &p.Kpsi, &p.g, &p.CT, &p.CQ, &p.L, &p.Jm, &p.omega_min,
                          &p.omega_max, &p.d_base, &p.m1, &p.l1, &p.lc1, &p.I1xx, &p.I1yy,
                          &p.I1zz, &p.m2, &p.l2, &p.lc2, &p.I2xx, &p.I2yy, &p.I2zz};
    for (double* s : scalars1) *s = a[i++];
    double* pairs[] = {p.Im, p.Dm, p.Ks, p.Kd, p.Dl, p.Fc};
    for (double* s : pairs) { s[0] = a[i++]; s[1] = a[i++]; }
    p.fric_eps = a[i++];
    p.backlash[0] = a[i++]; p.backlash[1] = a[i++];
    p.K3[0] = a[i++]; p.K3[1] = a[i++];
    p.payload = a[i++]; p.ground_k = a[i++]; p.rotor_radius = a[i++]; p.thrust_loss = a[i++];
    return p;
  }
  double total_mass(bool with_payload = true) const {
    return m_body + m1 + m2 + (with_payload ? payload : 0.0);
  }
};

struct ControlParams {
  static constexpr int kSize = 26;
  double m_ctrl, kp_pos, kp_vel, ki_vel, v_max, tilt_max, kp_z, kp_vz, ki_vz, kp_att_rp, kp_att_y,
      kp_rate_rp, ki_rate_rp, kd_rate_rp, kp_rate_y, ki_rate_y, rate_max, tau_max, kp_joint,
      ki_joint, kd_joint, tau_m_max, current_lsb, kt, delay_rotor, delay_joint;

  static ControlParams from_array(const double* a) {
    ControlParams c{};
    double* f[] = {&c.m_ctrl, &c.kp_pos, &c.kp_vel, &c.ki_vel, &c.v_max, &c.tilt_max, &c.kp_z,
                   &c.kp_vz, &c.ki_vz, &c.kp_att_rp, &c.kp_att_y, &c.kp_rate_rp, &c.ki_rate_rp,
                   &c.kd_rate_rp, &c.kp_rate_y, &c.ki_rate_y, &c.rate_max, &c.tau_max,
                   &c.kp_joint, &c.ki_joint, &c.kd_joint, &c.tau_m_max, &c.current_lsb, &c.kt,
                   &c.delay_rotor, &c.delay_joint};
    int i = 0;
    for (double* s : f) *s = a[i++];
    return c;
  }
};

}  // namespace cdam::sim
