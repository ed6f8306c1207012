// The aerial manipulator's arm_coupling columns on the target, row by row from the measured
// rows (cdam_core.models.greybox.causal: the float64 reference, and the derivation):
// per measured signal (phi theta psi X Y Z q1 q2) its increments d = a(t) - a(t-1) (psi's
// wrapped to (-pi, pi]) and d2 = d(t) - d(t-1) through the Butterworth low-pass (second-order
// sections in the output's increments, started at rest): p = LP(d),
// s = LP(d2); the jet (v, p, c, s) = (a(t-1), p(t), p(t-1), s(t)) is the local trajectory
// (v - c, v, v + p); sums, products, sines and cosines of jets keep every part free of
// cancellation, so the force columns (second differences over dt^2, 1e6 x at 1 kHz) round at
// the level of their own terms. Numbers: the sections (kArmSos: body band, joint band), dt;
// which channels the model has (kArmEq >= 0). No heap; sinf and cosf.
#pragma once
#include <cmath>

#include "model.hpp"

namespace fw {

struct Jet {
  float v, p, c, s;
  float now() const { return v + p; }
};

inline Jet operator+(const Jet& a, const Jet& b) {
  return {a.v + b.v, a.p + b.p, a.c + b.c, a.s + b.s};
}
inline Jet operator-(const Jet& a) { return {-a.v, -a.p, -a.c, -a.s}; }
inline Jet operator-(const Jet& a, const Jet& b) { return a + (-b); }
inline Jet operator*(const Jet& a, const Jet& b) {
  return {a.v * b.v, (a.p * b.v + a.v * b.p) + a.p * b.p, (a.c * b.v + a.v * b.c) - a.c * b.c,
          ((a.v * b.s + b.v * a.s) + a.p * b.p) + a.c * b.c};
}

// sin and cos of a jet (causal.py's _sincos, in its order)
inline void sincos(const Jet& a, Jet* sn, Jet* cs) {
  const float sv = std::sin(a.v), cv = std::cos(a.v);
  const float hp = std::sin(0.5f * a.p), hc = std::sin(0.5f * a.c);
  const float cp = std::cos(0.5f * a.p), cc = std::cos(0.5f * a.c);
  const float sq = hp * hp + hc * hc;
  const float mid = std::cos(0.5f * (a.p + a.c)) * std::sin(0.5f * a.s);
  *sn = {sv, 2.0f * (cv * cp - sv * hp) * hp, 2.0f * (cv * cc + sv * hc) * hc,
         -2.0f * sv * sq + 2.0f * cv * mid};
  *cs = {cv, -2.0f * (sv * cp + cv * hp) * hp, -2.0f * (sv * cc - cv * hc) * hc,
         -2.0f * cv * sq - 2.0f * sv * mid};
}

class ArmColumns {
 public:
  static constexpr int kSignals = 8;          // phi theta psi X Y Z q1 q2
  static constexpr int kChannels = 5;         // X Y Z tau_theta tau_phi
  static constexpr int kCols = 8;             // columns per channel (at most)
  static constexpr int kSections = cdam_model::kArmSections;
  // the signals' indices in the model's output row (positions: phi theta psi X Y Z thm1
  // thm2 q1 q2)
  static constexpr int kIndex[kSignals] = {0, 1, 2, 3, 4, 5, 8, 9};

  static constexpr bool has(int ch) { return cdam_model::kArmEq[ch] >= 0; }
  static constexpr bool kForces =
      cdam_model::kArmEq[0] >= 0 || cdam_model::kArmEq[1] >= 0 || cdam_model::kArmEq[2] >= 0;
  static constexpr bool kMoments = cdam_model::kArmEq[3] >= 0 || cdam_model::kArmEq[4] >= 0;

  // the measured row of output values (model positions)
  void observe(const float* y) {
    Jet j[kSignals];
    for (int k = 0; k < kSignals; ++k) {
      const float a = y[kIndex[k]];
      if (!started_) prev_[k] = a;
      float d = a - prev_[k];
      if (k == 2) {   // psi: a wrapped angle
        if (d > kPi) d = d - 2.0f * kPi;
        else if (d < -kPi) d = d + 2.0f * kPi;
      }
      const float d2 = d - dprev_[k];
      const float* sos = &cdam_model::kArmSos[(k < 6 ? 0 : 1) * kSections * 6];
      const float p = filter(sos, z1_[k], d);
      const float s = filter(sos, z2_[k], d2);
      j[k] = {prev_[k], p, pprev_[k], s};
      prev_[k] = a;
      dprev_[k] = d;
      pprev_[k] = p;
    }
    started_ = true;
    columns(j);
  }

  // column n of channel ch at the last observed row
  float at(int ch, int n) const { return cols_[ch][n]; }

 private:
  static constexpr float kPi = 3.14159265358979f;

  // section by section in the output's increments (causal.delta_sosfilt): y = -a1 y1 - a2 y2
  // + N written as dy = (dy1 - alpha1 dy1) - alpha2 y2 + N, y = y1 + dy, alpha1 = a1 + 2,
  // alpha2 = 1 + a1 + a2 (small, kept to float32's relative precision); state per section
  // x1 x2 y1 dy1
  static float filter(const float* sos, float (*z)[4], float x) {
    for (int q = 0; q < kSections; ++q) {
      const float* c = &sos[q * 6];   // b0 b1 b2 1 alpha1 alpha2
      float* s = z[q];
      const float n = (c[0] * x + c[1] * s[0]) + c[2] * s[1];
      const float dy = ((s[3] - c[4] * s[3]) - c[5] * (s[2] - s[3])) + n;
      s[2] = s[2] + dy;
      s[3] = dy;
      s[1] = s[0];
      s[0] = x;
      x = s[2];
    }
    return x;
  }

  void columns(const Jet* j) {
    constexpr float dt = cdam_model::kDt;
    constexpr float inv2 = 1.0f / (dt * dt);
    Jet sf, cf, st, ct, sp, cp, s1, c1, s12, c12, s2, c2;
    sincos(j[0], &sf, &cf);
    sincos(j[1], &st, &ct);
    sincos(j[2], &sp, &cp);
    const Jet q12 = j[6] + j[7];
    sincos(j[6], &s1, &c1);
    sincos(q12, &s12, &c12);
    sincos(j[7], &s2, &c2);
    (void)s2;
    const Jet bx[3] = {ct * cp, ct * sp, -st};
    const Jet by[3] = {(cp * st) * sf - sp * cf, (sp * st) * sf + cp * cf, ct * sf};
    const Jet bz[3] = {(cf * st) * cp + sf * sp, (cf * st) * sp - sf * cp, cf * ct};
    if constexpr (kForces) {
      for (int i = 0; i < 3; ++i) {
        if (!has(i)) continue;
        const Jet w0 = -bz[i];
        const Jet w1 = -(s1 * bx[i]) - c1 * bz[i];
        const Jet w2 = -(s12 * bx[i]) - c12 * bz[i];
        cols_[i][0] = w0.s * inv2;
        cols_[i][1] = w1.s * inv2;
        cols_[i][2] = w2.s * inv2;
      }
    }
    if constexpr (kMoments) {
      const float acc[3] = {j[3].s * inv2, j[4].s * inv2, j[5].s * inv2 + kG0};
      auto dot = [&acc](const Jet* b) {
        return (b[0].now() * acc[0] + b[1].now() * acc[1]) + b[2].now() * acc[2];
      };
      const float ax = dot(bx), ay = dot(by), az = dot(bz);
      // Delta(C R) / dt with R(t) = rp / dt and R(t) - R(t-1) = rs / dt
      auto dcr = [](const Jet& C, float rp, float rs) { return (C.p * rp + C.v * rs) * inv2; };
      const Jet &th = j[1], &q1 = j[6], &q2 = j[7], &ph = j[0];
      if (has(3)) {
        float* o = cols_[3];
        o[0] = -ax;
        o[1] = -(c1.now() * ax) + s1.now() * az;
        o[2] = -(c12.now() * ax) + s12.now() * az;
        o[3] = dcr(c1, 2.0f * th.p + q1.p, 2.0f * th.s + q1.s);
        o[4] = dcr(c12, 2.0f * th.p + q12.p, 2.0f * th.s + q12.s);
        o[5] = dcr(c2, (2.0f * th.p + 2.0f * q1.p) + q2.p, (2.0f * th.s + 2.0f * q1.s) + q2.s);
        o[6] = q1.s * inv2;
        o[7] = q12.s * inv2;
      }
      if (has(4)) {
        float* o = cols_[4];
        o[0] = ay;
        o[1] = c1.now() * ay;
        o[2] = c12.now() * ay;
        o[3] = dcr(c1, ph.p, ph.s);
        o[4] = dcr(c12, ph.p, ph.s);
        o[5] = dcr(c2, ph.p, ph.s);
      }
    }
  }

  static constexpr float kG0 = 9.81f;   // cdam_core.models.greybox.effects.G0
  float prev_[kSignals] = {}, dprev_[kSignals] = {}, pprev_[kSignals] = {};
  float z1_[kSignals][kSections][4] = {}, z2_[kSignals][kSections][4] = {};
  float cols_[kChannels][kCols] = {};
  bool started_ = false;
};

}  // namespace fw
