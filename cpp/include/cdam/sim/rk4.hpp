// Classical fixed-step Runge-Kutta 4 on fixed-size Eigen vectors (no heap).
//
// Stability: for a linear mode x' = lambda x, RK4 is stable for |h lambda| up to about 2.78 on
// the imaginary axis (2.83 at best) and 2.78 on the negative real axis. The simulator picks the
// number of sub-steps so that h * omega_max <= kRk4StabilityLimit (see simulator.hpp).
#pragma once
#include <Eigen/Core>

namespace cdam::sim {

constexpr double kRk4StabilityLimit = 2.5;  // margin below 2.78

// x <- x + h/6 (k1 + 2 k2 + 2 k3 + k4); f(t, x, dxdt) writes the derivative.
template <int N, typename F>
void rk4_step(F& f, double t, Eigen::Matrix<double, N, 1>& x, double h) {
  using V = Eigen::Matrix<double, N, 1>;
  V k1, k2, k3, k4, tmp;
  f(t, x, k1);
  tmp = x + (h / 2) * k1;
  f(t + h / 2, tmp, k2);
  tmp = x + (h / 2) * k2;
  f(t + h / 2, tmp, k3);
  tmp = x + h * k3;
  f(t + h, tmp, k4);
  x = x + (h / 6) * (k1 + 2 * k2 + 2 * k3 + k4);
}

}  // namespace cdam::sim
