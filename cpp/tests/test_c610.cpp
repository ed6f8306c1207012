// C610/M2006 codec (cdam/c610.hpp) and the fast activations (cdam/fast_math.hpp). Expected
// bytes are written out by hand from the protocol in ALGORITHMS.md (big-endian int16).
#include <doctest/doctest.h>

#include <cmath>
#include <cstdint>
#include <limits>

#include "cdam/c610.hpp"
#include "cdam/fast_math.hpp"
#include "cdam/mlp.hpp"

using cdam::CanFrame;
namespace c610 = cdam::c610;

TEST_CASE("c610: feedback decodes big-endian fields") {
  CanFrame f;
  f.id = 0x202;
  f.dlc = 8;
  const std::uint8_t bytes[8] = {0x1F, 0xFF, 0xFC, 0x18, 0x03, 0xE8, 0x00, 0x00};
  for (int k = 0; k < 8; ++k) f.data[k] = bytes[k];
  c610::Feedback fb;
  REQUIRE(c610::decode_feedback(f, &fb) == c610::Decode::Ok);
  CHECK(fb.motor == 2);
  CHECK(fb.angle == 8191);
  CHECK(fb.speed_rpm == -1000);
  CHECK(fb.current == 1000);
  // and back
  const CanFrame g = c610::encode_feedback(fb);
  CHECK(g.id == 0x202);
  for (int k = 0; k < 8; ++k) CHECK(g.data[k] == bytes[k]);
}

TEST_CASE("c610: malformed feedback is rejected with its kind") {
  CanFrame f;
  f.id = 0x201;
  f.dlc = 8;
  c610::Feedback fb;
  fb.motor = 99;
  f.data[0] = 0x20;  // angle 8192: out of range
  CHECK(c610::decode_feedback(f, &fb) == c610::Decode::OutOfRange);
  CHECK(fb.motor == 99);  // untouched on error
  f.data[0] = 0;
  f.data[2] = 0x4E; f.data[3] = 0x21;  // 20001 rpm
  CHECK(c610::decode_feedback(f, &fb) == c610::Decode::OutOfRange);
  f.data[2] = 0; f.data[3] = 0;
  f.data[4] = 0xD8; f.data[5] = 0xEF;  // -10001
  CHECK(c610::decode_feedback(f, &fb) == c610::Decode::OutOfRange);
  f.data[4] = 0; f.data[5] = 0;
  f.dlc = 7;
  CHECK(c610::decode_feedback(f, &fb) == c610::Decode::WrongDlc);
  f.dlc = 8;
  f.id = 0x209;
  CHECK(c610::decode_feedback(f, &fb) == c610::Decode::UnknownId);
  f.id = 0x200;
  CHECK(c610::decode_feedback(f, &fb) == c610::Decode::UnknownId);
  f.id = 0x201;
  f.extended = true;
  CHECK(c610::decode_feedback(f, &fb) == c610::Decode::UnknownId);
  f.extended = false;
  f.remote = true;
  CHECK(c610::decode_feedback(f, &fb) == c610::Decode::RemoteFrame);
}

TEST_CASE("c610: command encodes four big-endian currents, clamped") {
  const std::int16_t cur[4] = {1000, -1000, 12000, -32768};
  const CanFrame f = c610::encode_command(cur, 1);
  CHECK(f.id == 0x200);
  CHECK(f.dlc == 8);
  const std::uint8_t want[8] = {0x03, 0xE8, 0xFC, 0x18, 0x27, 0x10, 0xD8, 0xF0};  // 10000, -10000
  for (int k = 0; k < 8; ++k) CHECK(f.data[k] == want[k]);
  std::int16_t back[4];
  REQUIRE(c610::decode_command(f, back) == c610::Decode::Ok);
  CHECK(back[0] == 1000);
  CHECK(back[3] == -10000);
  CHECK(c610::encode_command(cur, 2).id == 0x1FF);
}

TEST_CASE("c610: MotorState unwraps through the rotor's zero using the speed") {
  c610::MotorState m(0.18f, 36.0f);
  c610::Feedback fb;
  fb.motor = 1;
  fb.angle = 8000;
  fb.speed_rpm = 10000;
  m.update(fb, 0.001f);
  CHECK(m.rotor_counts() == 8000);
  fb.angle = 100;  // 292 counts forward through the wrap (10000 rpm: 1365 counts per ms)
  m.update(fb, 0.001f);
  CHECK(m.rotor_counts() == 8292);
  fb.angle = 8100;  // backwards again with a negative speed
  fb.speed_rpm = -100;
  m.update(fb, 0.001f);
  CHECK(m.rotor_counts() == 8192 + 8100 - 8192);
  const double want = 2.0 * 3.141592653589793 * 8100.0 / 8192.0 / 36.0;
  CHECK(std::fabs(m.theta() - want) < 1e-6);
  CHECK(std::fabs(m.omega() - (-100.0 * 2.0 * 3.141592653589793 / 60.0 / 36.0)) < 1e-6);
  fb.current = -2500;
  m.update(fb, 0.001f);
  CHECK(std::fabs(m.amps() + 2.5) < 1e-6);
  CHECK(std::fabs(m.torque() + 0.45) < 1e-6);
}

TEST_CASE("fast_math: fast_tanh within 1e-6 of tanh over the float range") {
  double worst = 0.0;
  for (int k = -400000; k <= 400000; ++k) {
    const float x = static_cast<float>(k) * 5e-5f;  // [-20, 20]
    const double e = std::fabs(static_cast<double>(cdam::fast_tanh(x)) - std::tanh(double(x)));
    if (e > worst) worst = e;
  }
  CHECK(worst < 1e-6);
  const float big = std::numeric_limits<float>::max();
  CHECK(cdam::fast_tanh(big) == doctest::Approx(1.0).epsilon(1e-6));
  CHECK(cdam::fast_tanh(-big) == doctest::Approx(-1.0).epsilon(1e-6));
  CHECK(cdam::fast_tanh(0.0f) == 0.0f);
  // saturated branch (|x| beyond the clamp, one test on x^2) and NaN propagation
  CHECK(cdam::fast_tanh(8.0f) == 1.0f);
  CHECK(cdam::fast_tanh(-8.0f) == -1.0f);
  CHECK(std::isnan(cdam::fast_tanh(std::numeric_limits<float>::quiet_NaN())));
  for (float x = 0.01f; x < 9.0f; x *= 1.01f) CHECK(cdam::fast_tanh(-x) == -cdam::fast_tanh(x));
  double worst_l = 0.0;
  for (int k = -40000; k <= 40000; ++k) {
    const float x = static_cast<float>(k) * 5e-4f;
    const double want = 1.0 / (1.0 + std::exp(-double(x)));
    worst_l = std::fmax(worst_l, std::fabs(double(cdam::fast_logistic(x)) - want));
  }
  CHECK(worst_l < 1e-6);
}

TEST_CASE("fast_math: Mlp with FastActivation matches the exact network within 1e-5") {
  constexpr int I = 3, H = 5, O = 2;
  float theta[cdam::mlp_params(I, H, O)];
  for (int k = 0; k < cdam::mlp_params(I, H, O); ++k)
    theta[k] = 0.5f * std::sin(1.7f * static_cast<float>(k) + 0.3f);
  const float x[I] = {0.9f, -0.4f, 0.1f};
  float a1[H], a2[H], y1[O], y2[O];
  cdam::Mlp<float, I, H, O> exact;
  cdam::Mlp<float, I, H, O, cdam::FastActivation> fast;
  exact.forward(theta, x, a1, y1);
  fast.forward(theta, x, a2, y2);
  for (int k = 0; k < O; ++k) CHECK(std::fabs(y1[k] - y2[k]) < 1e-5f);
}
