// C++ tests of the simulator: closed forms (textbook 2-link arm, hover), mixer round trip,
// delay line, the sub-step rule, and the no-heap loop. Agreement with the numpy twin, energy
// conservation and trajectories are tested from Python (tests/test_sim_*.py).
#include <doctest/doctest.h>

#include <Eigen/Core>
#include <cmath>
#include <vector>

#include "cdam/sim/simulator.hpp"

using namespace cdam::sim;

namespace {

// The defaults of cdam_core.sim.parameters (kept short: the values the tests rely on).
PlantParams default_plant() {
  PlantParams p{};
  p.m_body = 1.6; p.Jx = 0.0135; p.Jy = 0.0135; p.Jz = 0.025;
  p.Kx = p.Ky = 0.25; p.Kz = 0.3; p.Kphi = p.Ktheta = p.Kpsi = 0.005; p.g = 9.81;
  p.CT = 1.2e-5; p.CQ = 1.9e-7; p.L = 0.225; p.Jm = 3e-5; p.omega_min = 150; p.omega_max = 1000;
  p.d_base = 0.08; p.m1 = 0.12; p.l1 = 0.2; p.lc1 = 0.1; p.I1xx = p.I1yy = 4e-4; p.I1zz = 1e-5;
  p.m2 = 0.1; p.l2 = 0.2; p.lc2 = 0.12; p.I2xx = p.I2yy = 4e-4; p.I2zz = 1e-5;
  for (int k = 0; k < 2; ++k) {
    p.Im[k] = 1e-3; p.Dm[k] = 2e-3; p.Ks[k] = 20 - 5 * k; p.Kd[k] = 0.02; p.Dl[k] = 2e-3;
  }
  p.fric_eps = 0.05; p.rotor_radius = 0.127;
  return p;
}

State hover_state(double Z) {
  State x = State::Zero();
  x[2] = Z;
  x[3] = 1.0;
  return x;
}

}  // namespace

TEST_CASE("sim: hover is an equilibrium of f(x, u) with the closed-form rotor speed") {
  const PlantParams p = default_plant();
  const double om = std::sqrt(p.total_mass() * p.g / (4 * p.CT));
  Input u;
  u << om, om, om, om, 0, 0;
  State dx;
  rhs(p, 0.0, hover_state(1.0), u, dx);
  CHECK(dx.cwiseAbs().maxCoeff() < 1e-12);
}

TEST_CASE("sim: with the body at rest the arm has the textbook M(q) and G(q)") {
  const PlantParams p = default_plant();
  for (double q2 : {-1.0, 0.0, 0.7}) {
    const double q1 = 0.4;
    ArmBody b[3];
    arm_bodies(p, q1, q2, 0, 0, b);
    Eigen::Matrix2d M = Eigen::Matrix2d::Zero();
    Eigen::Vector2d G = Eigen::Vector2d::Zero();
    for (const ArmBody& bd : b) {
      M += bd.m * bd.J.transpose() * bd.J;
      Eigen::Vector2d s(bd.s1, bd.s2);
      if (bd.has_inertia) M += bd.I(1, 1) * s * s.transpose();
      G += bd.J.transpose() * (bd.m * p.g * Vec3(0, 0, 1));  // dV/dq, V = m g z
    }
    const double c2 = std::cos(q2);
    const double M11 = p.I1yy + p.I2yy + p.m1 * p.lc1 * p.lc1 +
                       p.m2 * (p.l1 * p.l1 + p.lc2 * p.lc2 + 2 * p.l1 * p.lc2 * c2);
    const double M12 = p.I2yy + p.m2 * (p.lc2 * p.lc2 + p.l1 * p.lc2 * c2);
    const double M22 = p.I2yy + p.m2 * p.lc2 * p.lc2;
    CHECK(M(0, 0) == doctest::Approx(M11).epsilon(1e-12));
    CHECK(M(0, 1) == doctest::Approx(M12).epsilon(1e-12));
    CHECK(M(1, 1) == doctest::Approx(M22).epsilon(1e-12));
    const double G1 = p.g * (p.m1 * p.lc1 + p.m2 * p.l1) * std::sin(q1) + p.g * p.m2 * p.lc2 * std::sin(q1 + q2);
    const double G2 = p.g * p.m2 * p.lc2 * std::sin(q1 + q2);
    CHECK(G[0] == doctest::Approx(G1).epsilon(1e-12));
    CHECK(G[1] == doctest::Approx(G2).epsilon(1e-12));
  }
}

TEST_CASE("sim: the X mixer inverts eq. (2) inside the speed limits and clamps outside") {
  const PlantParams p = default_plant();
  const Vec3 tau(0.05, -0.08, 0.01);
  const Vec4 s = mixer(p, 20.0, tau);
  const Vec4 back = mixer_forward(p, s);
  CHECK(back[0] == doctest::Approx(20.0).epsilon(1e-12));
  for (int i = 0; i < 3; ++i) CHECK(back[1 + i] == doctest::Approx(tau[i]).epsilon(1e-12));
  const Vec4 hi = mixer(p, 100.0, Vec3::Zero());
  for (int i = 0; i < 4; ++i) CHECK(hi[i] == p.omega_max * p.omega_max);
  // roll torque: rotors 3 and 4 (left, +y) faster, gives +tau_x: thrust on +y rolls about +x
  const Vec4 r = mixer(p, 20.0, Vec3(0.1, 0, 0));
  CHECK(r[2] > r[1]);
  CHECK(r[3] > r[0]);
}

TEST_CASE("sim: delay line returns the command of d ticks ago, the first one before") {
  DelayLine<Eigen::Matrix<double, 1, 1>, 8> line;
  line.reset(3);
  std::vector<double> got;
  for (int k = 0; k < 12; ++k) got.push_back(line.push(Eigen::Matrix<double, 1, 1>(k + 10.0))[0]);
  const double expect[12] = {10, 10, 10, 10, 11, 12, 13, 14, 15, 16, 17, 18};
  for (int k = 0; k < 12; ++k) CHECK(got[k] == expect[k]);
}

TEST_CASE("sim: the sub-step rule keeps h * fastest rate <= 2.5") {
  PlantParams p = default_plant();
  CHECK(substeps_for(p, 1e-3) == 1);
  CHECK(fastest_rate(p) == doctest::Approx(std::sqrt(20.0 / 1e-3)));
  p.Ks[1] = 2e4;  // a stiff cable: sqrt(2e4 / 1e-3) = 4472 rad/s -> 2 sub-steps
  const int n = substeps_for(p, 1e-3);
  CHECK(n == 2);
  CHECK(1e-3 / n * fastest_rate(p) <= 2.5);
  CHECK(1e-3 / (n - 1) * fastest_rate(p) > 2.5);
}

TEST_CASE("sim: a stiff cable with sub-steps stays bounded, without them RK4 diverges (reported)") {
  PlantParams p = default_plant();
  p.Ks[0] = 4e4;      // sqrt(4e4/1e-3) = 6325 rad/s: h omega = 6.3 at 1 ms
  p.Kd[0] = 0.0;
  p.Dm[0] = 0.0;
  State x = hover_state(1.0);
  x[9] = 0.01;  // motor 1 displaced against its cable
  const long n = 200;
  std::vector<double> U(n * kNu, 0.0), X((n + 1) * kNx);
  const double om = std::sqrt(p.total_mass() * p.g / (4 * p.CT));
  for (long k = 0; k < n; ++k)
    for (int i = 0; i < 4; ++i) U[k * kNu + i] = om;
  REQUIRE(simulate_open_loop(p, x.data(), U.data(), n, 1e-3, substeps_for(p, 1e-3), X.data()) ==
          cdam::Status::Ok);
  CHECK(std::abs(X[n * kNx + 9]) < 0.02);
  // without them the state overflows to Inf / NaN within the 200 steps: reported, not returned
  CHECK(simulate_open_loop(p, x.data(), U.data(), n, 1e-3, 1, X.data()) ==
        cdam::Status::Diverged);
}

TEST_CASE("sim: the closed loop holds hover and its loop does not allocate") {
  const PlantParams p = default_plant();
  ControlParams c{};
  c.kp_pos = 1; c.kp_vel = 2; c.ki_vel = 0.4; c.v_max = 2; c.tilt_max = 0.35; c.kp_z = 1.5;
  c.kp_vz = 4; c.ki_vz = 2; c.kp_att_rp = 6.5; c.kp_att_y = 2.8; c.kp_rate_rp = 25;
  c.ki_rate_rp = 10; c.kd_rate_rp = 0.2; c.kp_rate_y = 10; c.ki_rate_y = 2; c.rate_max = 3.5;
  c.tau_max = 1.5; c.kp_joint = 8; c.ki_joint = 4; c.kd_joint = 0.25; c.tau_m_max = 1;
  c.current_lsb = 0.001; c.kt = 0.18; c.delay_rotor = 5; c.delay_joint = 3;
  const long n = 2000;
  std::vector<double> SP(n * kNsp, 0.0), X(n * kNx), LOG(n * kNlog);
  for (long k = 0; k < n; ++k) SP[k * kNsp + 2] = 1.0;
  const State x0 = hover_state(1.0);
  Eigen::internal::set_is_malloc_allowed(false);
  const cdam::Status s = simulate_closed_loop(p, c, x0.data(), SP.data(), n, 1e-3, 1, X.data(), LOG.data());
  Eigen::internal::set_is_malloc_allowed(true);
  REQUIRE(s == cdam::Status::Ok);
  for (int i = 0; i < kNx; ++i) CHECK(std::abs(X[(n - 1) * kNx + i] - x0[i]) < 1e-9);
  CHECK(LOG[(n - 1) * kNlog] == doctest::Approx(p.total_mass() * p.g).epsilon(1e-12));
}
