// The logistic map z <- 4 z (1 - z) (ALGORITHMS.md, "Chaotic elite learning", CABC), shared by
// IBOA's chaotic elite learning and CABC's chaotic initialisation and scout search.
//
// Seeding (one Rng draw): z0 = 0.05 + 0.9 u. The orbit must avoid the points that end in a
// fixed point or a short cycle (0, 0.25, 0.5, 0.75, 1); after every step (and at seeding) a z
// within 1e-12 of one of them, or outside (0, 1), is replaced by the documented fallback
// 0.123456789 (never hit in double on the host in practice; float orbits on the target can
// collapse, which the fallback absorbs). The numpy twin computes (4 z) (1 - z) in the same order,
// so both languages produce the same orbit bit for bit.
#pragma once
#include <cmath>

#include "../rng.hpp"

namespace cdam::optim {

template <typename Scalar>
struct LogisticMap {
  Scalar z = Scalar(0.7);

  static Scalar guard(Scalar v) {
    const Scalar eps = Scalar(1e-12);
    if (!(v > eps && v < Scalar(1) - eps) || std::abs(v - Scalar(0.25)) < eps ||
        std::abs(v - Scalar(0.5)) < eps || std::abs(v - Scalar(0.75)) < eps)
      return Scalar(0.123456789);
    return v;
  }
  // One draw.
  void seed(Rng& rng) { z = guard(Scalar(0.05) + Scalar(0.9) * rng.uniform<Scalar>()); }
  // Advances the map and returns the new z in (0, 1).
  Scalar next() {
    z = guard(Scalar(4) * z * (Scalar(1) - z));
    return z;
  }
};

}  // namespace cdam::optim
