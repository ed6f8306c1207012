// Effects that can hide in the data (all off at their zero values; documented for users in
// cdam_core.sim.effects):
//   ground_effect  collective thrust x (1 + k (R / 4 Z)^2), Z clamped at 0.05 m
//                  (Cheeseman-Bennett's first-order form; rotor moments unaffected)
//   thrust_loss    every rotor's thrust x max(1 - c t, 0) (battery sag; CQ unaffected)
//   backlash       dead zone of total width w in the cable deflection
//   hardening      cubic cable term K3 dz^3
//   coulomb        motor-side dry friction Fc tanh(theta_m' / eps)
//   actuator_delay commands applied d ticks late: DelayLine below
//   payload_mass   a point mass at the link-2 tip (coupling.hpp)
#pragma once
#include <algorithm>
#include <array>
#include <cmath>

#include "cdam/sim/params.hpp"

namespace cdam::sim {

struct ThrustFactors {
  double collective;  // multiplies T
  double rotor;       // multiplies the roll and pitch moments
};

inline ThrustFactors thrust_factors(const PlantParams& p, double t, double Z) {
  const double loss = std::max(1.0 - p.thrust_loss * t, 0.0);
  const double z = std::max(Z, 0.05);
  const double r = p.rotor_radius / (4.0 * z);
  const double ge = 1.0 + p.ground_k * (r * r);
  return {ge * loss, loss};
}

// Dead zone of total width `width`: sign(d) max(|d| - width/2, 0).
inline double dead_zone(double d, double width) {
  return std::copysign(std::max(std::abs(d) - 0.5 * width, 0.0), d);
}

// A fixed-capacity delay line of command vectors: push the command of tick k, read the one of
// tick k - delay (the first command before the start). No heap.
template <typename Vec, int Capacity>
class DelayLine {
 public:
  static constexpr int kCapacity = Capacity;
  void reset(int delay) { delay_ = delay; count_ = 0; }
  const Vec& push(const Vec& v) {
    buf_[count_ % Capacity] = v;
    const long k = count_ - delay_;
    ++count_;
    return buf_[(k < 0 ? 0 : k) % Capacity];
  }

 private:
  std::array<Vec, Capacity> buf_{};
  long count_ = 0;
  int delay_ = 0;
};

}  // namespace cdam::sim
