// The dynamic model kinds on the target, one sample at a time: `arx`, `hybrid` (ARX + a static
// network on its residual), `greybox` (a declared model plus the effects the residual loop
// found, integrated as cdam_core.models.greybox.augmented.GreyBox does), `quad_physics` (the
// flight model's rigid body, RK4 per sample: fw/quad_physics_step.hpp), `quad_hybrid` (kind 6,
// the physics with a recurrent network on the body rates: fw/quad_hybrid_step.hpp) and, kind 5, a
// `bp_network` whose model file has a monitor section (NARX or static, beside its monitor). The numbers come from
// generated/model.hpp (`cdam export-firmware`); the structure (which effect, which declared
// model) is an integer code there, never a name. Fixed sizes, no heap; libm only for tanhf (a
// smoothed Coulomb friction), sinf and cosf (gravity, payload and attitude terms).
//
// One interface for every kind (rows t = 0, 1, ... of one record):
//   prime(u, y)    rows 0 .. kHistory-1: a measured row (input u(t), output y(t)) as history;
//   step(u, y)     rows t >= kHistory: the prediction of y(t) from the history and u(t), which
//                  becomes the newest history row (free run);
//   correct(y)     replace that newest row by the measured y(t) (one-step prediction: step then
//                  correct on every row).
// Arithmetic: float32 in the order of the Python model's float64 expressions (build the image
// with -ffp-contract=off so that no multiply-add is fused), so the firmware differs from Python
// by float32 rounding only.
#pragma once
#define CDAM_FW_STEP_MODEL_HPP
#include <cstdint>

#include "model.hpp"

#if (CDAM_MODEL_KIND == 2 && CDAM_MODEL_HAS_NET) || CDAM_MODEL_KIND == 5
#include "cdam/fast_math.hpp"
#include "cdam/mlp.hpp"
#include "cdam/scaling.hpp"
#endif
#if CDAM_MODEL_KIND == 3
#include <cmath>
#ifndef CDAM_MODEL_ARM
#define CDAM_MODEL_ARM 0
#endif
#if CDAM_MODEL_ARM
#include "fw/arm_columns.hpp"
#endif
#endif

namespace fw {

constexpr int kU = cdam_model::kInputs;     // inputs per row
constexpr int kY = cdam_model::kOutputs;    // outputs per row
constexpr int kT0 = cdam_model::kHistory;   // measured rows before the first prediction

inline std::uint32_t fnv1a_floats(std::uint32_t h, const float* p, unsigned n) {
  const auto* b = reinterpret_cast<const unsigned char*>(p);
  for (unsigned k = 0; k < n * sizeof(float); ++k) h = (h ^ b[k]) * 0x01000193u;
  return h;
}

#if CDAM_MODEL_KIND == 1 || CDAM_MODEL_KIND == 2

// y(t) = A [y(t-1); ...; y(t-na)] + (B [f(t-nk); ...; f(t-nk-nb+1)] + c) [+ w N(f lags)]
// (cdam_core.models.arx.ArxModel, hybrid.HybridNarx); coef rows: y lags, f lags, constant.
class StepModel {
 public:
  static constexpr int kNa = cdam_model::kNa, kNb = cdam_model::kNb, kNk = cdam_model::kNk;
  static constexpr int kF = cdam_model::kFeatures;
  static constexpr int kYRows = kNa > 0 ? kNa : 1;
  static constexpr int kFRows = kNk + kNb > 0 ? kNk + kNb : 1;   // f(t) .. f(t-nk-nb+1)
  static constexpr int kRows = kNa * kY + kNb * kF + 1;

  void prime(const float* u, const float* y) {
    push_features(u);
    push_output(y);
  }

  void step(const float* u, float* y) {
    push_features(u);
    const float* coef = cdam_model::kCoef;   // kRows x kY, row-major
    float lagged[kNb * kF > 0 ? kNb * kF : 1];
    for (int j = 0; j < kNb; ++j)
      for (int c = 0; c < kF; ++c) lagged[j * kF + c] = f_[kNk + j][c];
#if CDAM_MODEL_KIND == 2 && CDAM_MODEL_HAS_NET
    float net[kY];
    network(lagged, net);
#endif
    for (int o = 0; o < kY; ++o) {
      float past = 0.0f;   // past @ Wy
      for (int j = 0; j < kNa; ++j)
        for (int c = 0; c < kY; ++c) past = past + y_[j][c] * coef[(j * kY + c) * kY + o];
      float term = 0.0f;   // [lagged f, 1] @ Wu
      for (int r = 0; r < kNb * kF; ++r) term = term + lagged[r] * coef[(kNa * kY + r) * kY + o];
      term = term + 1.0f * coef[(kRows - 1) * kY + o];
#if CDAM_MODEL_KIND == 2 && CDAM_MODEL_HAS_NET
      term = term + cdam_model::kResidualWeight * net[o];
#endif
      y[o] = past + term;
    }
    push_output(y);
  }

  // the measured row y(t), after step (every mode): a kind whose equations need measured
  // signals (greybox arm_coupling) takes them here; the others ignore it
  void observe(const float* y) { (void)y; }

  void correct(const float* y) {
    if (kNa > 0)
      for (int c = 0; c < kY; ++c) y_[0][c] = y[c];
  }

 private:
  void push_features(const float* u) {
    for (int j = kFRows - 1; j > 0; --j)
      for (int c = 0; c < kF; ++c) f_[j][c] = f_[j - 1][c];
    features(u, f_[0]);
  }

  void push_output(const float* y) {
    if (kNa == 0) return;
    for (int j = kYRows - 1; j > 0; --j)
      for (int c = 0; c < kY; ++c) y_[j][c] = y_[j - 1][c];
    for (int c = 0; c < kY; ++c) y_[0][c] = y[c];
  }

  // raw: the inputs; physics: [u / scale (4), T, roll, pitch, yaw] of f_i = (u_i / scale_i)^2
  static void features(const float* u, float* f) {
    if (!cdam_model::kPhysics) {
      for (int c = 0; c < kF; ++c) f[c] = u[c];
      return;
    }
    float q[4];
    for (int c = 0; c < 4; ++c) {
      f[c] = u[c] / cdam_model::kFeatureScale[c];
      q[c] = f[c] * f[c];
    }
    f[4] = ((q[0] + q[1]) + q[2]) + q[3];
    f[5] = ((q[0] + q[3]) - q[1]) - q[2];
    f[6] = ((q[0] + q[1]) - q[2]) - q[3];
    f[7] = ((q[0] - q[1]) + q[2]) - q[3];
  }

#if CDAM_MODEL_KIND == 2 && CDAM_MODEL_HAS_NET
  // the residual network: min-max scaling, cdam::Mlp with the fast activation, back-scaling
  static void network(const float* x, float* y) {
    using Net = cdam::Mlp<float, cdam_model::kNetInputs, cdam_model::kNetHidden, kY,
                          cdam::FastActivation>;
    const Net net(cdam_model::kNetInputs, cdam_model::kNetHidden, kY,
                  cdam_model::kNetTansig ? cdam::Activation::Tansig : cdam::Activation::Logsig);
    float xn[cdam_model::kNetInputs], hidden[cdam_model::kNetHidden], yn[kY];
    for (int k = 0; k < cdam_model::kNetInputs; ++k)
      xn[k] = cdam::minmax_forward(x[k], cdam_model::kNetXMin[k], cdam_model::kNetXMax[k]);
    net.forward(cdam_model::kNetTheta, xn, hidden, yn);
    for (int k = 0; k < kY; ++k)
      y[k] = cdam::minmax_inverse(yn[k], cdam_model::kNetYMin[k], cdam_model::kNetYMax[k]);
  }
#endif

  float y_[kYRows][kY] = {};
  float f_[kFRows][kF] = {};
};

inline std::uint32_t params_fnv1a() {
  std::uint32_t h = fnv1a_floats(0x811C9DC5u, cdam_model::kCoef, sizeof(cdam_model::kCoef) / 4);
#if CDAM_MODEL_KIND == 2 && CDAM_MODEL_HAS_NET
  h = fnv1a_floats(h, cdam_model::kNetTheta, sizeof(cdam_model::kNetTheta) / 4);
#endif
  return h;
}

#elif CDAM_MODEL_KIND == 3

// Grey-box step (GreyBox._rollout): the state is the position x and the velocity v per
// coordinate; each sample integrates `kSubsteps` semi-implicit Euler substeps of length h,
//   a = Inertia e(x, v, u),  v = v + h a,  x = x + h v,
// where e is the equations' error at zero acceleration, y - sum_p theta_p column_p, the columns
// in the Python order: the declared model's, then each effect's. The input of row t-1 drives the
// step to row t; a measured row sets x = y(t) and v = (y(t) - y(t-1)) / dt.
namespace effect {   // codes written by the exporter (cdam_core.firmware.step.EFFECT_CODES)
constexpr int kCoulomb = 1, kAsymmetric = 2, kExternalForce = 3, kDelay = 4, kBacklash = 5,
              kHardening = 6, kPayload = 7, kGroundEffect = 8, kThrustLoss = 9;

constexpr bool present(int code) {
  for (int k = 0; k < cdam_model::kEffects; ++k)
    if (cdam_model::kEffectCode[k] == code) return true;
  return false;
}
}  // namespace effect

class StepModel {
 public:
  static constexpr int kN = kY;    // positions
  static constexpr int kE = cdam_model::kEffects;
  static constexpr int kLag = cdam_model::kDelayLag;   // rows of raw input history for delays
  static constexpr int kRing = kLag + 1;

  void prime(const float* u, const float* y) {
    push_input(u);
    measured(y);
    observe(y);
  }

  void step(const float* u, float* y) {
    float ue[kU > 0 ? kU : 1];
    effective_input(ue);   // the input of row t-1, after the effects' delays
    constexpr float h = cdam_model::kH;
    for (int s = 0; s < cdam_model::kSubsteps; ++s) {
      float e[kN], a[kN];
      errors(ue, e);
      for (int i = 0; i < kN; ++i) {
        float acc = 0.0f;
        for (int j = 0; j < kN; ++j) acc = acc + cdam_model::kInertia[i * kN + j] * e[j];
        a[i] = acc;
      }
      for (int i = 0; i < kN; ++i) v_[i] = v_[i] + h * a[i];
      for (int i = 0; i < kN; ++i) x_[i] = x_[i] + h * v_[i];
    }
    for (int i = 0; i < kN; ++i) {
      xprev_[i] = xlast_[i];
      xlast_[i] = x_[i];
      y[i] = x_[i];
    }
    push_input(u);
  }

  // the measured row y(t), after step (every mode; prime takes it itself): the arm_coupling
  // columns of row t (fw::ArmColumns) for the step to row t + 1
  void observe(const float* y) {
#if CDAM_MODEL_ARM
    arm_.observe(y);
#else
    (void)y;
#endif
  }

  void correct(const float* y) {
    for (int i = 0; i < kN; ++i) xlast_[i] = xprev_[i];
    measured(y);
  }

 private:
  void measured(const float* y) {
    for (int i = 0; i < kN; ++i) {
      x_[i] = y[i];
      v_[i] = (y[i] - xlast_[i]) / cdam_model::kDt;
      xprev_[i] = xlast_[i];
      xlast_[i] = y[i];
    }
  }

  // raw input history: a ring of kRing rows, `head_` the newest; before the record's first
  // row it holds that row (np.interp holds the first value before the start). rows_ counts the
  // rows pushed and stops at 2^31 - 1 (24 days at 1 kHz; no signed overflow).
  void push_input(const float* u) {
    if constexpr (kRing > 1) {
      if (rows_ == 0)
        for (int j = 0; j < kRing; ++j)
          for (int c = 0; c < kU; ++c) u_[j][c] = u[c];
      head_ = head_ + 1 < kRing ? head_ + 1 : 0;
    }
    for (int c = 0; c < kU; ++c) u_[head_][c] = u[c];
    if (kCountRows && rows_ < 0x7FFFFFFF) ++rows_;
  }

  // the row count matters to the delays (the record's start) and the thrust loss (time)
  static constexpr bool kCountRows = kRing > 1 || effect::present(effect::kThrustLoss);


  // the input row `back` rows before the newest (0 <= back < kRing)
  const float* input(int back) const {
    if constexpr (kRing == 1) return u_[0];   // no delay: the newest row only
    const int k = head_ - back;
    return u_[k < 0 ? k + kRing : k];
  }

  // u(t - 1) with every delay applied: u(t-1-delay) = u[k-L] + frac (u[k-L+1] - u[k-L]) as
  // np.interp: slope (fp[j+1] - fp[j]) / (xp[j+1] - xp[j]) times (x - xp[j]), plus fp[j]
  void effective_input(float* ue) const {
    const float* now = input(0);
    for (int c = 0; c < kU; ++c) ue[c] = now[c];
    for (int k = 0; k < kE; ++k) {
      if (cdam_model::kEffectCode[k] != effect::kDelay) continue;
      const int c = cdam_model::kEffectIndex[k];
      const int lag = cdam_model::kEffectLag[k];
      const float* p = &cdam_model::kEffectParam[k * 4];
      const float lo = input(lag)[c], hi = input(lag > 0 ? lag - 1 : 0)[c];
      // before the record's start np.interp returns its first value (lo and hi hold it there:
      // the ring starts filled with the first row)
      ue[c] = rows_ - 1 < lag ? lo : (hi - lo) / p[1] * p[0] + lo;
    }
  }

  // Equation errors at zero acceleration, each equation's columns in GreyBox's order: the
  // declared model's, then each effect's (the acceleration columns vanish exactly: 0 * theta).
  void errors(const float* u, float* e) const {
    const float* th = cdam_model::kBase;   // the declared model's parameter_names, in order
#if CDAM_MODEL_DECLARED == 0
    // rigid_axis [M, Fv, offset, G, Gc]: tau = M q'' + Fv q' + offset + G sin q + Gc cos q
    e[0] = u[0];
    e[0] = e[0] - th[1] * v_[0];
    e[0] = e[0] - th[2] * 1.0f;
    e[0] = e[0] - th[3] * std::sin(x_[0]);
    e[0] = e[0] - th[4] * std::cos(x_[0]);
#elif CDAM_MODEL_DECLARED == 1
    // flexible_joint [Im, Dm, Ks, Kd, I, Dl, G, Gc, offset_m, offset_l], positions
    // (theta_m, q), cable deflection d = theta_m - q (through a backlash dead band if the
    // model has one), rate dd:
    //   tau_m: tau_m = Im thm'' + Dm thm' + Ks d + Kd dd + offset_m
    //   tau_l: 0 = I q'' + Dl q' + G sin q + Gc cos q - Ks d - Kd dd + offset_l
    const float d = deflection();
    const float dd = v_[0] - v_[1];
    e[0] = u[0];
    e[0] = e[0] - th[1] * v_[0];
    e[0] = e[0] - th[2] * d;
    e[0] = e[0] - th[3] * dd;
    e[0] = e[0] - th[8] * 1.0f;
    e[1] = 0.0f;
    e[1] = e[1] - th[5] * v_[1];
    e[1] = e[1] - th[6] * std::sin(x_[1]);
    e[1] = e[1] - th[7] * std::cos(x_[1]);
    e[1] = e[1] - th[2] * -d;
    e[1] = e[1] - th[3] * -dd;
    e[1] = e[1] - th[9] * 1.0f;
#elif CDAM_MODEL_DECLARED == 2
    // quadrotor [m, Kx, Ky, Kz, Jx, Jy, Jz, Kphi, Ktheta, Kpsi], positions (phi, theta, psi,
    // X, Y, Z), inputs (T, tau_phi, tau_theta, tau_psi); flight.Quadrotor.equations
    (void)th;
    const float pd = v_[0], td = v_[1], yd = v_[2];
    const float tz = vertical_thrust(u);
    quadrotor_errors(u, tz, pd, td, yd, e);
#elif CDAM_MODEL_DECLARED == 3
    // aerial_manipulator: the quadrotor's six equations (th[0..9]), then both cable-driven
    // joints (flight.AerialManipulator.equations, columns at zero acceleration; the equation
    // errors in the Python dict's order tau_m1, tau_m2, tau_l1, tau_l2, as the inertia matrix):
    // th[10..24] = Im1 Dm1 Ks1 Kd1 Im2 Dm2 Ks2 Kd2 p1 p2 p3 g1 g2 Dl1 Dl2; positions 6..9 =
    // theta_m1 theta_m2 q1 q2, inputs 4, 5 = tau_m1 tau_m2.
    const float pd = v_[0], td = v_[1], yd = v_[2];
    const float tz = vertical_thrust(u);
    quadrotor_errors(u, tz, pd, td, yd, e);
    float d[2], dd[2];
    for (int k = 0; k < 2; ++k) {
      d[k] = deflection(k);
      dd[k] = v_[6 + k] - v_[8 + k];
      float& r = e[6 + k];   // tau_mk = Imk thmk'' + Dmk thmk' + Ksk dk + Kdk dk'
      r = u[4 + k];
      r = r - th[11 + 4 * k] * v_[6 + k];
      r = r - th[12 + 4 * k] * d[k];
      r = r - th[13 + 4 * k] * dd[k];
    }
    // link 1's absolute rate in the arm plane w = theta' + q1'; the specific force over g at
    // joint 1 at zero acceleration: (-stheta g, cphi ctheta g + depth theta'^2) / g
    const float q1 = x_[8], q2 = x_[9], q1d = v_[8], q2d = v_[9];
    const float w1 = td + q1d;
    const float c2 = std::cos(q2), s2 = std::sin(q2);
    const float st = std::sin(x_[1]);
    const float gx = -(st * kG0) / kG0;
    const float gz = ((std::cos(x_[0]) * std::cos(x_[1])) * kG0 +
                      cdam_model::kJointDepth * (td * td)) / kG0;
    const float g1 = std::sin(q1) * gz - std::cos(q1) * gx;
    const float g2 = std::sin(q1 + q2) * gz - std::cos(q1 + q2) * gx;
    float& l1 = e[8];   // p1 w'' + p3 (w'' + q2'') + p2 (...) + g1 G1 + g2 G2 + Dl1 q1' - cable
    l1 = 0.0f;
    l1 = l1 - th[19] * (c2 * 0.0f - s2 * (2.0f * w1 * q2d + q2d * q2d));
    l1 = l1 - th[21] * g1;
    l1 = l1 - th[22] * g2;
    l1 = l1 - th[23] * q1d;
    l1 = l1 - th[12] * -d[0];
    l1 = l1 - th[13] * -dd[0];
    float& l2 = e[9];   // p3 (w'' + q2'') + p2 (cos q2 w'' + sin q2 w'^2) + g2 G2 + Dl2 q2' - cable
    l2 = 0.0f;
    l2 = l2 - th[19] * (c2 * 0.0f + s2 * (w1 * w1));
    l2 = l2 - th[22] * g2;
    l2 = l2 - th[24] * q2d;
    l2 = l2 - th[16] * -d[1];
    l2 = l2 - th[17] * -dd[1];
#else
#error "declared model not supported on the firmware"
#endif
    for (int k = 0; k < kE; ++k) {
      const float* p = &cdam_model::kEffectParam[k * 4];
      float& r = e[cdam_model::kEffectEq[k]];
      const float v = v_[cdam_model::kEffectVel[k]];
      switch (cdam_model::kEffectCode[k]) {
        case effect::kCoulomb: {   // Fc sign(v), or Fc tanh(v / eps)
          const float s = p[1] > 0.0f ? std::tanh(v / p[1])
                                      : static_cast<float>((v > 0.0f) - (v < 0.0f));
          r = r - p[0] * s;
          break;
        }
        case effect::kAsymmetric: {   // dFv v [v > 0], and dFc [v > 0] without an offset
          const float pos = v > 0.0f ? 1.0f : 0.0f;
          r = r - p[0] * (v * pos);
          if (p[2] != 0.0f) r = r - p[1] * pos;
          break;
        }
        case effect::kExternalForce:   // gain (-u_extra)
          r = r - p[0] * -u[cdam_model::kEffectIndex[k]];
          break;
#if CDAM_MODEL_DECLARED == 1
        case effect::kHardening: {   // K3 d^3 on the motor side, -K3 d^3 on the link side
          const float d3 = (d * d) * d;
          e[0] = e[0] - p[0] * d3;
          e[1] = e[1] - p[0] * -d3;
          break;
        }
        case effect::kPayload:   // m (l^2 q'' + g l sin q) on the link side, q'' = 0
          r = r - p[0] * (0.0f + p[1] * std::sin(x_[1]));
          break;
#endif
#if CDAM_MODEL_DECLARED == 3
        case effect::kHardening: {   // K3 d^3 on motor k's equation, -K3 d^3 on link k's
          const int c = cdam_model::kEffectIndex[k];
          const float d3 = (d[c] * d[c]) * d[c];
          e[6 + c] = e[6 + c] - p[0] * d3;
          e[8 + c] = e[8 + c] - p[0] * -d3;
          break;
        }
#endif
#if CDAM_MODEL_DECLARED == 2 || CDAM_MODEL_DECLARED == 3
        case effect::kPayload:   // mass (Z'' + g) on Z, Z'' = 0
          r = r - p[0] * (0.0f + kG0);
          break;
        case effect::kGroundEffect: {   // k (-T cphi ctheta (R / 4 max(Z, 0.05))^2)
          const float z = x_[5] > 0.05f ? x_[5] : 0.05f;
          const float q = p[1] / (4.0f * z);
          r = r - p[0] * (-tz * (q * q));
          break;
        }
        case effect::kThrustLoss:   // c (T cphi ctheta t), t from the record's first row
          r = r - p[0] * (tz * (static_cast<float>(rows_ - 1) * cdam_model::kDt));
          break;
#endif
        default:   // delays and backlash act on the inputs and the deflection, not here
          break;
      }
    }
#if CDAM_MODEL_ARM
    // arm_coupling: the measured row's columns (fw/arm_columns.hpp), per channel theta . col
    for (int ch = 0; ch < ArmColumns::kChannels; ++ch) {
      const int q = cdam_model::kArmEq[ch];
      if (q < 0) continue;
      for (int n = 0; n < cdam_model::kArmCols[ch]; ++n)
        e[q] = e[q] - cdam_model::kArmTheta[ch * ArmColumns::kCols + n] * arm_.at(ch, n);
    }
#endif
  }

#if CDAM_MODEL_DECLARED == 2 || CDAM_MODEL_DECLARED == 3
  // the six body equations of flight.Quadrotor at zero acceleration (th = kBase)
  void quadrotor_errors(const float* u, float tz, float pd, float td, float yd, float* e) const {
    const float* th = cdam_model::kBase;
    float ux, uy;
    thrust_xy(&ux, &uy);
    e[0] = u[0] * ux;
    e[0] = e[0] - th[1] * v_[3];
    e[1] = u[0] * uy;
    e[1] = e[1] - th[2] * v_[4];
    e[2] = tz;
    e[2] = e[2] - th[0] * (0.0f + kG0);
    e[2] = e[2] - th[3] * v_[5];
    e[3] = u[1];
    e[3] = e[3] - th[5] * (-td * yd);
    e[3] = e[3] - th[6] * (td * yd);
    e[3] = e[3] - th[7] * pd;
    e[4] = u[2];
    e[4] = e[4] - th[6] * (-pd * yd);
    e[4] = e[4] - th[4] * (pd * yd);
    e[4] = e[4] - th[8] * td;
    e[5] = u[3];
    e[5] = e[5] - th[4] * (-pd * td);
    e[5] = e[5] - th[5] * (pd * td);
    e[5] = e[5] - th[9] * yd;
  }

  static constexpr float kG0 = 9.81f;   // cdam_core.models.greybox.flight.G0
  // T times the world z component of the body z axis (Z-Y-X Euler angles): T cphi ctheta
  float vertical_thrust(const float* u) const {
    return u[0] * (std::cos(x_[0]) * std::cos(x_[1]));
  }
  // world x and y components: cphi stheta cpsi + sphi spsi, cphi stheta spsi - sphi cpsi
  void thrust_xy(float* ux, float* uy) const {
    const float cf = std::cos(x_[0]), sf = std::sin(x_[0]);
    const float st = std::sin(x_[1]);
    const float cp = std::cos(x_[2]), sp = std::sin(x_[2]);
    *ux = cf * st * cp + sf * sp;
    *uy = cf * st * sp - sf * cp;
  }
#endif

#if CDAM_MODEL_DECLARED == 1
  // sign(d) max(|d| - width / 2, 0) when the model has a backlash (Backlash.transform_state)
  float deflection() const {
    const float d = x_[0] - x_[1];
    for (int k = 0; k < kE; ++k) {
      if (cdam_model::kEffectCode[k] != effect::kBacklash) continue;
      const float h = cdam_model::kEffectParam[k * 4];
      const float m = std::fabs(d) - h;
      return static_cast<float>((d > 0.0f) - (d < 0.0f)) * (m > 0.0f ? m : 0.0f);
    }
    return d;
  }
#endif
#if CDAM_MODEL_DECLARED == 3
  // cable k's deflection theta_mk - qk, through the dead band of a backlash on that cable
  float deflection(int cable) const {
    const float d = x_[6 + cable] - x_[8 + cable];
    for (int k = 0; k < kE; ++k) {
      if (cdam_model::kEffectCode[k] != effect::kBacklash ||
          cdam_model::kEffectIndex[k] != cable) continue;
      const float h = cdam_model::kEffectParam[k * 4];
      const float m = std::fabs(d) - h;
      return static_cast<float>((d > 0.0f) - (d < 0.0f)) * (m > 0.0f ? m : 0.0f);
    }
    return d;
  }
#endif

  float x_[kN] = {}, v_[kN] = {}, xlast_[kN] = {}, xprev_[kN] = {};
  float u_[kRing][kU] = {};
  int head_ = 0;
  int rows_ = 0;
#if CDAM_MODEL_ARM
  ArmColumns arm_;
#endif
};

inline std::uint32_t params_fnv1a() {
  std::uint32_t h = fnv1a_floats(0x811C9DC5u, cdam_model::kBase, sizeof(cdam_model::kBase) / 4);
  h = fnv1a_floats(h, cdam_model::kInertia, sizeof(cdam_model::kInertia) / 4);
  h = fnv1a_floats(h, cdam_model::kEffectParam, sizeof(cdam_model::kEffectParam) / 4);
#if CDAM_MODEL_ARM
  h = fnv1a_floats(h, cdam_model::kArmTheta, sizeof(cdam_model::kArmTheta) / 4);
  h = fnv1a_floats(h, cdam_model::kArmSos, sizeof(cdam_model::kArmSos) / 4);
#endif
  return h;
}

#elif CDAM_MODEL_KIND == 5

// A bp_network one sample at a time (cdam_core.models.network.BPNetwork with a monitor
// section; a static network is na = 0, nb = 1, nk = 0): the regressor [y(t-1); ...; y(t-na);
// u(t-nk); ...; u(t-nk-nb+1)] in cdam/narx.hpp's order, min-max scaled per element (the
// output scaler's numbers for past outputs, the input scaler's for inputs), cdam::Mlp with the
// fast activation, back-scaled by the output scaler.
class StepModel {
 public:
  static constexpr int kNa = cdam_model::kNa, kNb = cdam_model::kNb, kNk = cdam_model::kNk;
  static constexpr int kYRows = kNa > 0 ? kNa : 1;
  static constexpr int kURows = kNk + kNb > 0 ? kNk + kNb : 1;   // u(t) .. u(t-nk-nb+1)
  static constexpr int kIn = cdam_model::kNetInputs, kHidden = cdam_model::kNetHidden;
  static_assert(kIn == kNa * kY + kNb * kU, "the network's inputs are the regressor");

  void prime(const float* u, const float* y) {
    push_input(u);
    push_output(y);
  }

  void step(const float* u, float* y) {
    using Net = cdam::Mlp<float, kIn, kHidden, kY, cdam::FastActivation>;
    using namespace cdam_model;
    push_input(u);
    const Net net(kIn, kHidden, kY, kNetTansig ? cdam::Activation::Tansig
                                               : cdam::Activation::Logsig);
    float x[kIn], hidden[kHidden], yn[kY];
    int p = 0;
    for (int j = 0; j < kNa; ++j)
      for (int c = 0; c < kY; ++c, ++p)
        x[p] = cdam::minmax_forward(y_[j][c], kNetXMin[p], kNetXMax[p]);
    for (int j = 0; j < kNb; ++j)
      for (int c = 0; c < kU; ++c, ++p)
        x[p] = cdam::minmax_forward(u_[kNk + j][c], kNetXMin[p], kNetXMax[p]);
    net.forward(kNetTheta, x, hidden, yn);
    for (int k = 0; k < kY; ++k) y[k] = cdam::minmax_inverse(yn[k], kNetYMin[k], kNetYMax[k]);
    push_output(y);
  }

  // the measured row y(t), after step (every mode): a kind whose equations need measured
  // signals (greybox arm_coupling) takes them here; the others ignore it
  void observe(const float* y) { (void)y; }

  void correct(const float* y) {
    if (kNa > 0)
      for (int c = 0; c < kY; ++c) y_[0][c] = y[c];
  }

 private:
  void push_input(const float* u) {
    for (int j = kURows - 1; j > 0; --j)
      for (int c = 0; c < kU; ++c) u_[j][c] = u_[j - 1][c];
    for (int c = 0; c < kU; ++c) u_[0][c] = u[c];
  }

  void push_output(const float* y) {
    if (kNa == 0) return;
    for (int j = kYRows - 1; j > 0; --j)
      for (int c = 0; c < kY; ++c) y_[j][c] = y_[j - 1][c];
    for (int c = 0; c < kY; ++c) y_[0][c] = y[c];
  }

  float y_[kYRows][kY] = {};
  float u_[kURows][kU] = {};
};

inline std::uint32_t params_fnv1a() {
  return fnv1a_floats(0x811C9DC5u, cdam_model::kNetTheta, sizeof(cdam_model::kNetTheta) / 4);
}

#endif

}  // namespace fw

#if CDAM_MODEL_KIND == 4
#include "fw/quad_physics_step.hpp"   // the quad_physics flight model: RK4 on 13 states
#elif CDAM_MODEL_KIND == 6
#include "fw/quad_hybrid_step.hpp"    // quad_hybrid: the physics + a recurrent rate network
#endif
