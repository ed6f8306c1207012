// The 1 kHz joint loop, platform independent (the target and the host tests share it):
// C610 feedback frames 0x201 and 0x202 in -> multi-turn joint states -> the identified model on
// [q1, w1, i1, q2, w2, i2] (scaled, forward, back-scaled) -> joint PID -> 0x200 current command
// out. A cycle runs when both motors have reported since the last cycle.
//
// Extra frames (not C610): 0x300 in, two little-endian float32 joint references (rad);
// 0x3F0 out after each command: float32 model output 0, uint16 cycle counter, uint16 count of
// rejected frames (diagnostics for the processor-in-the-loop test).
#pragma once
#include <cstdint>
#include <cstring>

#include "cdam/c610.hpp"
#include "fw/config.hpp"
#include "fw/model_runner.hpp"

namespace fw {

constexpr std::uint32_t kReferenceId = 0x300;
constexpr std::uint32_t kDiagnosticId = 0x3F0;
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

 private:
  float integral_ = 0.0f;
};

inline std::int16_t amps_to_counts(float a) {
  const float c = a / cdam::c610::kAmpsPerCount;
  return cdam::c610::clamp_current(static_cast<long>(c >= 0.0f ? c + 0.5f : c - 0.5f));
}

class Controller {
 public:
  // Feed one received frame. Returns true when a cycle ran; *cmd and *diag are then the
  // frames to send.
  bool on_frame(const cdam::CanFrame& f, cdam::CanFrame* cmd, cdam::CanFrame* diag) {
    if (!f.extended && !f.remote && f.id == kReferenceId && f.dlc == 8) {
      std::memcpy(ref_, f.data, 8);  // little-endian float32 pair (the target is little-endian)
      return false;
    }
    cdam::c610::Feedback fb;
    if (cdam::c610::decode_feedback(f, &fb) != cdam::c610::Decode::Ok || fb.motor > 2) {
      ++rejected_;
      return false;
    }
    const int j = fb.motor - 1;
    motors_[j].update(fb, config::kDt);
    fresh_ |= 1u << j;
    if (fresh_ != 3u) return false;
    fresh_ = 0;
    step(cmd, diag);
    return true;
  }

  const float* features() const { return x_; }
  const float* model_outputs() const { return y_; }
  const float* currents() const { return u_; }
  std::uint32_t cycles() const { return cycles_; }
  std::uint32_t rejected() const { return rejected_; }

 private:
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
};

}  // namespace fw
