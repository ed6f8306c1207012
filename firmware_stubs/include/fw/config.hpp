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
// rad, the largest joint angle (reference or measured) the loop accepts. Not a mechanical stop
// (the arm has none in this code): the multi-turn angle is a float32, whose spacing below
// 256 rad (at most 2^-16 = 1.5e-5 rad) is finer than one C610 encoder count at the output,
// 2 pi / (8192 * 36) = 2.13e-5 rad, and above it is not; beyond +-256 rad the joint can no
// longer be measured (hence controlled) at the encoder's resolution.
constexpr float kJointRangeRad = 256.0f;

}  // namespace fw::config
