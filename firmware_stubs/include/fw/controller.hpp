// The 1 kHz joint loop, platform independent (the target and the host tests share it):
// C610 feedback frames 0x201 and 0x202 in -> multi-turn joint states -> the identified model on
// [q1, w1, i1, q2, w2, i2] (scaled, forward, back-scaled) -> joint PID -> 0x200 current command
// out. A cycle runs when both motors have reported since the last cycle.
//
// Extra frames (not C610), all little-endian, defined here:
//   0x300 in   reference: two float32 joint references (rad), both finite and within
//              +-config::kJointRangeRad, else the whole frame is rejected and the last valid
//              references are held;
//   0x3F0 out  diagnostic, after each command: float32 model output 0, uint16 cycle counter,
//              uint16 count of rejected frames (all kinds; for the processor-in-the-loop test);
//   0x3F1 out  status: four uint16 counters (saturating at 65535) of rejected inputs:
//              [0-1] references not finite, [2-3] references beyond +-kJointRangeRad,
//              [4-5] measurements out of range (a C610 field outside its protocol range, or a
//              joint angle beyond +-kJointRangeRad: the motor's last valid state is held),
//              [6-7] malformed or foreign frames (wrong length, remote, extended, unknown id,
//              motors 3-8). Sent after any frame that changed a counter and on request (a
//              remote frame with id 0x3F1).
// Inputs are checked before they reach the PID, so no NaN or Inf can latch its integrator; the
// current command is converted by round_saturate (NaN -> 0 A, clamped to the C610's
// +-10000 counts), never by a plain float -> int cast.
#pragma once
#include <cmath>
#include <cstdint>
#include <cstring>

#include "cdam/c610.hpp"
#include "cdam/safe_size.hpp"
#include "fw/config.hpp"
#include "fw/model_runner.hpp"

namespace fw {

constexpr std::uint32_t kReferenceId = 0x300;
constexpr std::uint32_t kDiagnosticId = 0x3F0;
constexpr std::uint32_t kStatusId = 0x3F1;
constexpr int kFeatures = 6;  // q1, w1, i1, q2, w2, i2

class JointPid {
 public:
  // Current (A) for reference r, measured angle q and speed w.
  float step(float r, float q, float w) {
    const float e = r - q;
    integral_ += e * config::kDt;
    if (integral_ > config::kIntegralLimit) integral_ = config::kIntegralLimit;
    if (integral_ < -config::kIntegralLimit) integral_ = -config::kIntegralLimit;
    float u = config::kKp * e + config::kKi * integral_ - config::kKd * w;
    if (u > config::kCurrentLimitA) u = config::kCurrentLimitA;
    if (u < -config::kCurrentLimitA) u = -config::kCurrentLimitA;
    return u;
  }
  float integral() const { return integral_; }

 private:
  float integral_ = 0.0f;
};

// Current (A) -> C610 counts, rounded half away from zero and saturated to +-kCurrentLimit;
// NaN gives 0 A (a plain cast of NaN or of an out-of-range float is undefined behaviour).
inline std::int16_t amps_to_counts(float a) {
  constexpr auto lim = static_cast<std::int16_t>(cdam::c610::kCurrentLimit);
  return cdam::round_saturate<std::int16_t>(a / cdam::c610::kAmpsPerCount,
                                            static_cast<std::int16_t>(-lim), lim);
}

// A joint angle the loop accepts (reference or measurement): finite, |q| <= kJointRangeRad.
inline bool joint_angle_ok(float q) {
  return std::isfinite(q) && q <= config::kJointRangeRad && q >= -config::kJointRangeRad;
}

// Counters of rejected inputs (the 0x3F1 status frame), saturating at 65535.
struct InputCounts {
  std::uint16_t ref_nonfinite = 0, ref_range = 0, meas_range = 0, frames = 0;
  static void bump(std::uint16_t& c) {
    if (c != 0xFFFF) ++c;
  }
};

class Controller {
 public:
  // Feed one received frame. Returns true when a cycle ran; *cmd and *diag are then the
  // frames to send.
  bool on_frame(const cdam::CanFrame& f, cdam::CanFrame* cmd, cdam::CanFrame* diag) {
    if (!f.extended && f.id == kStatusId && f.remote) {
      status_due_ = true;
      return false;
    }
    if (!f.extended && !f.remote && f.id == kReferenceId && f.dlc == 8) {
      float r[2];
      std::memcpy(r, f.data, 8);  // little-endian float32 pair (the target is little-endian)
      if (!std::isfinite(r[0]) || !std::isfinite(r[1])) return reject(counts_.ref_nonfinite);
      if (!joint_angle_ok(r[0]) || !joint_angle_ok(r[1])) return reject(counts_.ref_range);
      ref_[0] = r[0];
      ref_[1] = r[1];
      return false;
    }
    cdam::c610::Feedback fb;
    const cdam::c610::Decode d = cdam::c610::decode_feedback(f, &fb);
    if (d == cdam::c610::Decode::OutOfRange) return reject(counts_.meas_range);
    if (d != cdam::c610::Decode::Ok || fb.motor > 2) return reject(counts_.frames);
    const int j = fb.motor - 1;
    cdam::c610::MotorState next = motors_[j];
    next.update(fb, config::kDt);
    if (!joint_angle_ok(next.theta())) return reject(counts_.meas_range);  // hold the last
    motors_[j] = next;
    fresh_ |= 1u << j;
    if (fresh_ != 3u) return false;
    fresh_ = 0;
    step(cmd, diag);
    return true;
  }

  // The 0x3F1 status frame, when one is due (a counter changed since the last, or it was
  // requested); the loop sends it after handling the frame.
  bool take_status(cdam::CanFrame* out) {
    if (!status_due_) return false;
    status_due_ = false;
    cdam::CanFrame st;
    st.id = kStatusId;
    st.dlc = 8;
    const std::uint16_t v[4] = {counts_.ref_nonfinite, counts_.ref_range, counts_.meas_range,
                                counts_.frames};
    std::memcpy(st.data, v, 8);
    *out = st;
    return true;
  }

  const float* features() const { return x_; }
  const float* model_outputs() const { return y_; }
  const float* currents() const { return u_; }
  const float* references() const { return ref_; }
  float integral(int j) const { return pid_[j].integral(); }
  const InputCounts& input_counts() const { return counts_; }
  std::uint32_t cycles() const { return cycles_; }
  std::uint32_t rejected() const { return rejected_; }

 private:
  bool reject(std::uint16_t& counter) {
    InputCounts::bump(counter);
    ++rejected_;
    status_due_ = true;
    return false;
  }

  void step(cdam::CanFrame* cmd, cdam::CanFrame* diag) {
    for (int j = 0; j < 2; ++j) {
      x_[3 * j] = motors_[j].theta();
      x_[3 * j + 1] = motors_[j].omega();
      x_[3 * j + 2] = motors_[j].amps();
    }
    float xin[kIn];
    for (int k = 0; k < kIn; ++k) xin[k] = x_[k % kFeatures];
    predict(xin, y_);
    std::int16_t counts[4] = {0, 0, 0, 0};
    for (int j = 0; j < 2; ++j) {
      u_[j] = pid_[j].step(ref_[j], x_[3 * j], x_[3 * j + 1]);
      counts[j] = amps_to_counts(u_[j]);
    }
    *cmd = cdam::c610::encode_command(counts, 1);
    ++cycles_;
    cdam::CanFrame d;
    d.id = kDiagnosticId;
    d.dlc = 8;
    std::memcpy(d.data, &y_[0], 4);
    const std::uint16_t cyc = static_cast<std::uint16_t>(cycles_);
    const std::uint16_t rej = static_cast<std::uint16_t>(rejected_);
    std::memcpy(d.data + 4, &cyc, 2);
    std::memcpy(d.data + 6, &rej, 2);
    *diag = d;
  }

  cdam::c610::MotorState motors_[2];
  JointPid pid_[2];
  float ref_[2] = {0.0f, 0.0f};
  float x_[kFeatures] = {};
  float y_[kOut] = {};
  float u_[2] = {0.0f, 0.0f};
  unsigned fresh_ = 0;
  std::uint32_t cycles_ = 0;
  std::uint32_t rejected_ = 0;
  InputCounts counts_;
  bool status_due_ = false;
};

}  // namespace fw
