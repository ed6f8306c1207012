// Loop constants shared by the firmware and (read by regular expression) by
// cdam_core.firmware, so the pure-Python loop uses the same numbers. One `constexpr float
// kName = value;` per line.
#pragma once

namespace fw::config {

constexpr float kDt = 0.001f;            // s, the loop period (C610 feedback rate)
constexpr float kKp = 8.0f;              // A / rad
constexpr float kKi = 2.0f;              // A / (rad s)
constexpr float kKd = 0.4f;              // A / (rad/s), on the measured speed
constexpr float kIntegralLimit = 2.0f;   // rad s, anti-windup clamp of the integral
constexpr float kCurrentLimitA = 10.0f;  // A, the C610's range

}  // namespace fw::config
