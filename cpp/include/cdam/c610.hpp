// C610 / M2006 (DJI RoboMaster) CAN codec, shared by the host tests and the firmware. Heap-free,
// no exceptions, no floating point in the frame layer. Protocol (ALGORITHMS.md, section C610):
// 1 Mbit/s, standard 11-bit ids.
// - Command 0x200 (motors 1-4) and 0x1FF (motors 5-8): four big-endian int16 currents,
//   -10000..10000 counts (1 mA per count).
// - Feedback 0x200 + id (0x201..0x208), 1 kHz: bytes 0-1 rotor angle 0..8191 (one rotor turn,
//   big-endian unsigned), 2-3 rotor speed rpm (int16), 4-5 torque current (int16, command
//   scale), 6-7 unused on the C610 (the C620 puts the temperature in byte 6).
// - M2006 P36 gearbox 36:1.
// The decoder rejects what the Python codec (cdam_core.can.codec) rejects, with the same kinds.
#pragma once
#include <cstdint>
#include <limits>

#include "safe_size.hpp"

namespace cdam {

// One classic CAN frame (what SLCAN and the C610 carry).
struct CanFrame {
  std::uint32_t id = 0;      // 11-bit (standard) or 29-bit (extended) identifier
  std::uint8_t dlc = 0;      // 0..8
  bool extended = false;
  bool remote = false;
  std::uint8_t data[8] = {0, 0, 0, 0, 0, 0, 0, 0};
};

namespace c610 {

constexpr std::uint32_t kCommandLow = 0x200;   // motors 1-4
constexpr std::uint32_t kCommandHigh = 0x1FF;  // motors 5-8
constexpr std::uint32_t kFeedbackBase = 0x200; // feedback id = 0x200 + motor (1..8)
constexpr int kCountsPerRev = 8192;
constexpr int kCurrentLimit = 10000;           // counts, = 10 A
constexpr int kSpeedLimitRpm = 20000;
constexpr float kAmpsPerCount = 0.001f;
constexpr float kGearRatio = 36.0f;
constexpr float kDefaultKtOutput = 0.18f;      // N m/A at the output (cdam_core.can.codec)

enum class Decode : std::uint8_t { Ok = 0, WrongDlc, UnknownId, OutOfRange, RemoteFrame };

inline const char* to_string(Decode d) {
  switch (d) {
    case Decode::Ok: return "ok";
    case Decode::WrongDlc: return "wrong_dlc";
    case Decode::UnknownId: return "unknown_id";
    case Decode::OutOfRange: return "out_of_range";
    case Decode::RemoteFrame: return "remote_frame";
  }
  return "unknown";
}

struct Feedback {
  std::uint8_t motor = 0;      // 1..8
  std::uint16_t angle = 0;     // rotor angle 0..8191
  std::int16_t speed_rpm = 0;  // rotor speed
  std::int16_t current = 0;    // torque current counts
  std::uint16_t reserved = 0;  // bytes 6-7
};

inline std::int16_t get_i16(const std::uint8_t* p) {
  return static_cast<std::int16_t>(static_cast<std::uint16_t>((p[0] << 8) | p[1]));
}
inline std::uint16_t get_u16(const std::uint8_t* p) {
  return static_cast<std::uint16_t>((p[0] << 8) | p[1]);
}
inline void put_u16(std::uint8_t* p, std::uint16_t v) {
  p[0] = static_cast<std::uint8_t>(v >> 8);
  p[1] = static_cast<std::uint8_t>(v & 0xFF);
}

inline std::int16_t clamp_current(long v) {
  return static_cast<std::int16_t>(v > kCurrentLimit ? kCurrentLimit
                                                     : (v < -kCurrentLimit ? -kCurrentLimit : v));
}

inline bool is_feedback_id(const CanFrame& f) {
  return !f.extended && f.id >= kFeedbackBase + 1 && f.id <= kFeedbackBase + 8;
}

// Feedback frame 0x201..0x208 -> fb. Out-of-range angle/speed/current are rejected.
inline Decode decode_feedback(const CanFrame& f, Feedback* fb) {
  if (f.remote) return Decode::RemoteFrame;
  if (!is_feedback_id(f)) return Decode::UnknownId;
  if (f.dlc != 8) return Decode::WrongDlc;
  Feedback r;
  r.motor = static_cast<std::uint8_t>(f.id - kFeedbackBase);
  r.angle = get_u16(f.data);
  r.speed_rpm = get_i16(f.data + 2);
  r.current = get_i16(f.data + 4);
  r.reserved = get_u16(f.data + 6);
  if (r.angle >= kCountsPerRev) return Decode::OutOfRange;
  if (r.speed_rpm > kSpeedLimitRpm || r.speed_rpm < -kSpeedLimitRpm) return Decode::OutOfRange;
  if (r.current > kCurrentLimit || r.current < -kCurrentLimit) return Decode::OutOfRange;
  *fb = r;
  return Decode::Ok;
}

inline CanFrame encode_feedback(const Feedback& fb) {
  CanFrame f;
  f.id = kFeedbackBase + fb.motor;
  f.dlc = 8;
  put_u16(f.data, fb.angle);
  put_u16(f.data + 2, static_cast<std::uint16_t>(fb.speed_rpm));
  put_u16(f.data + 4, static_cast<std::uint16_t>(fb.current));
  put_u16(f.data + 6, fb.reserved);
  return f;
}

// Current command for four motors (counts; clamped to +-kCurrentLimit). bank 1: 0x200, motors
// 1-4; bank 2: 0x1FF, motors 5-8.
inline CanFrame encode_command(const std::int16_t currents[4], int bank = 1) {
  CanFrame f;
  f.id = bank == 2 ? kCommandHigh : kCommandLow;
  f.dlc = 8;
  for (int k = 0; k < 4; ++k)
    put_u16(f.data + 2 * k, static_cast<std::uint16_t>(clamp_current(currents[k])));
  return f;
}

inline Decode decode_command(const CanFrame& f, std::int16_t currents[4]) {
  if (f.remote) return Decode::RemoteFrame;
  if (f.extended || (f.id != kCommandLow && f.id != kCommandHigh)) return Decode::UnknownId;
  if (f.dlc != 8) return Decode::WrongDlc;
  for (int k = 0; k < 4; ++k) currents[k] = get_i16(f.data + 2 * k);
  return Decode::Ok;
}

// Multi-turn state of one M2006 from successive feedback frames (the rule of
// cdam_core.can.codec.MotorState): the rotor angle is unwrapped by choosing the wrap whose
// step best matches the step predicted from the mean of the two frames' speeds over dt (the
// nearest wrap when dt = 0). The output angle is relative to the first frame's gearbox turn.
class MotorState {
 public:
  explicit MotorState(float kt = kDefaultKtOutput, float gear_ratio = kGearRatio)
      : kt_(kt), gear_(gear_ratio) {}

  void update(const Feedback& fb, float dt) {
    if (!started_) {
      turns_ = fb.angle;
      started_ = true;
    } else {
      long step = static_cast<long>(fb.angle) - last_angle_;
      const float predicted =
          0.5f * (static_cast<float>(fb.speed_rpm) + static_cast<float>(last_rpm_)) / 60.0f * dt *
          static_cast<float>(kCountsPerRev);
      const float wraps = (predicted - static_cast<float>(step)) / static_cast<float>(kCountsPerRev);
      // nearest integer, saturated (a NaN dt gives 0 wraps instead of an undefined cast)
      const long k = round_saturate<long>(wraps, std::numeric_limits<long>::min(),
                                          std::numeric_limits<long>::max());
      step += k * kCountsPerRev;
      turns_ += step;
    }
    last_angle_ = fb.angle;
    last_rpm_ = fb.speed_rpm;
    current_ = fb.current;
  }

  bool started() const { return started_; }
  std::int64_t rotor_counts() const { return turns_; }
  // Output shaft angle (rad), speed (rad/s), current (A), torque (N m).
  float theta() const {
    constexpr float kTwoPi = 6.28318530717958647692f;
    return kTwoPi * static_cast<float>(turns_) / static_cast<float>(kCountsPerRev) / gear_;
  }
  float omega() const {
    constexpr float kTwoPi = 6.28318530717958647692f;
    return static_cast<float>(last_rpm_) * kTwoPi / 60.0f / gear_;
  }
  float amps() const { return static_cast<float>(current_) * kAmpsPerCount; }
  float torque() const { return kt_ * amps(); }

 private:
  float kt_, gear_;
  bool started_ = false;
  std::int64_t turns_ = 0;
  long last_angle_ = 0;
  std::int16_t last_rpm_ = 0;
  std::int16_t current_ = 0;
};

}  // namespace c610
}  // namespace cdam
