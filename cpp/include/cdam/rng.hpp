// The shared random generator: xoshiro128** (Blackman and Vigna) with splitmix32-style seeding.
// Specified in docs/DESIGN.md; the numpy twin is cdam_core.reference.Rng. 32-bit arithmetic
// only, so the same stream comes out on a Cortex-M4F and on the host.
#pragma once
#include <cmath>
#include <cstdint>

namespace cdam {

class Rng {
 public:
  explicit Rng(std::uint32_t seed = 0) { reseed(seed); }

  void reseed(std::uint32_t seed) {
    std::uint32_t x = seed;
    for (auto& s : s_) {
      x += 0x9E3779B9u;
      std::uint32_t z = x;
      z = (z ^ (z >> 16)) * 0x85EBCA6Bu;
      z = (z ^ (z >> 13)) * 0xC2B2AE35u;
      s = z ^ (z >> 16);
    }
  }

  std::uint32_t next_u32() {
    const std::uint32_t result = rotl(s_[1] * 5u, 7) * 9u;
    const std::uint32_t t = s_[1] << 9;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = rotl(s_[3], 11);
    return result;
  }

  // One draw: (next >> 8) * 2^-24, in [0, 1), exact in float and double.
  template <typename Scalar = double>
  Scalar uniform() {
    return static_cast<Scalar>(next_u32() >> 8) * static_cast<Scalar>(5.9604644775390625e-08);
  }
  template <typename Scalar>
  Scalar uniform(Scalar a, Scalar b) {
    return a + (b - a) * uniform<Scalar>();
  }
  // One draw: an index in 0 .. n-1 (n >= 1), by a 64-bit multiply-shift.
  std::uint32_t index(std::uint32_t n) {
    return static_cast<std::uint32_t>((static_cast<std::uint64_t>(next_u32()) * n) >> 32);
  }
  // Two draws: Box-Muller, cosine branch.
  template <typename Scalar = double>
  Scalar normal() {
    const Scalar u1 = uniform<Scalar>();
    const Scalar u2 = uniform<Scalar>();
    return std::sqrt(Scalar(-2) * std::log(Scalar(1) - u1)) *
           std::cos(Scalar(6.283185307179586476925286766559) * u2);
  }

  const std::uint32_t* state() const { return s_; }

 private:
  static std::uint32_t rotl(std::uint32_t x, int k) { return (x << k) | (x >> (32 - k)); }
  std::uint32_t s_[4];
};

}  // namespace cdam
