// Host build of the firmware logic (the same headers as the target image): model runner,
// SLCAN + controller cycle, heap-free (EIGEN_RUNTIME_NO_MALLOC). Expected values come from
// independent computations written out here (plain loops over the exported weights, the
// protocol bytes), not from the code under test.
#define DOCTEST_CONFIG_IMPLEMENT_WITH_MAIN
#include <doctest/doctest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include "cdam/optim/mlp_fitness.hpp"
#include "cdam/slcan.hpp"
#include "fw/controller.hpp"
#include "fw/model_runner.hpp"
#include "fw/optim_run.hpp"

namespace {

// Plain double-precision forward pass over the exported theta (MATLAB column-major layout).
std::vector<double> reference_forward(const float* xn) {
  const int I = cdam_model::kInputs, H = cdam_model::kHidden, O = cdam_model::kOutputs;
  const float* th = cdam_model::kTheta;
  std::vector<double> a(H), y(O);
  for (int j = 0; j < H; ++j) {
    double s = th[I * H + j];
    for (int l = 0; l < I; ++l) s += double(th[l * H + j]) * xn[l];
    a[j] = cdam_model::kTansig ? std::tanh(s) : 1.0 / (1.0 + std::exp(-s));
  }
  const int w2 = I * H + H, b2 = w2 + H * O;
  for (int k = 0; k < O; ++k) {
    double s = th[b2 + k];
    for (int j = 0; j < H; ++j) s += double(th[w2 + j * O + k]) * a[j];
    y[k] = s;
  }
  return y;
}

}  // namespace

TEST_CASE("model runner: network equals a plain double forward pass within 1e-5") {
  Eigen::internal::set_is_malloc_allowed(false);
  float xn[fw::kIn], yn[fw::kOut];
  for (int trial = 0; trial < 50; ++trial) {
    for (int k = 0; k < fw::kIn; ++k) xn[k] = std::sin(0.37f * float(trial * fw::kIn + k));
    fw::infer_normalised(xn, yn);
    const std::vector<double> want = reference_forward(xn);
    for (int k = 0; k < fw::kOut; ++k) CHECK(std::fabs(yn[k] - want[k]) < 1e-5);
  }
  Eigen::internal::set_is_malloc_allowed(true);
}

TEST_CASE("packed network: tansig and logsig equal a plain double forward pass within 1e-5") {
  // A 3-5-2 network with weights from a closed form, in the exported layout (MATLAB order).
  constexpr int I = 3, H = 5, O = 2, D = I * H + H + H * O + O;
  float theta[D];
  for (int k = 0; k < D; ++k) theta[k] = float(0.9 * std::sin(1.7 * k + 0.3));
  for (const bool logsig : {false, true}) {
    const auto p = fw::pack_mlp<I, H, O>(theta, logsig);
    CHECK(fw::packed_matches(p, theta, logsig));
    for (int trial = 0; trial < 20; ++trial) {
      float x[I], y[O];
      for (int l = 0; l < I; ++l) x[l] = float(std::cos(0.61 * (trial * I + l)));
      fw::forward_packed(p, x, y);
      for (int k = 0; k < O; ++k) {
        double s = theta[I * H + H + H * O + k];
        for (int j = 0; j < H; ++j) {
          double n = theta[I * H + j];
          for (int l = 0; l < I; ++l) n += double(theta[l * H + j]) * x[l];
          const double a = logsig ? 1.0 / (1.0 + std::exp(-n)) : std::tanh(n);
          s += double(theta[I * H + H + j * O + k]) * a;
        }
        CHECK(std::fabs(y[k] - s) < 1e-5);
      }
    }
  }
  // One changed weight is seen by the run-time check.
  auto p = fw::pack_mlp<I, H, O>(theta, false);
  p.w[O + 2] += 1.0f;
  CHECK_FALSE(fw::packed_matches(p, theta, false));
}

TEST_CASE("model runner: predict scales, runs and back-scales") {
  float x[fw::kIn], xn[fw::kIn], y[fw::kOut];
  for (int k = 0; k < fw::kIn; ++k) {
    const double lo = cdam_model::kXMin[k], hi = cdam_model::kXMax[k];
    x[k] = float(lo + 0.3 * (hi - lo));
    xn[k] = hi > lo ? float(2 * 0.3 - 1) : 0.0f;
  }
  fw::predict(x, y);
  const std::vector<double> yn = reference_forward(xn);
  for (int k = 0; k < fw::kOut; ++k) {
    const double lo = cdam_model::kYMin[k], hi = cdam_model::kYMax[k];
    CHECK(std::fabs(y[k] - ((yn[k] + 1) * (hi - lo) / 2 + lo)) < 1e-4 * (1 + std::fabs(hi - lo)));
  }
  CHECK(fw::theta_fnv1a() == cdam_model::kThetaFnv1a);
  CHECK(fw::check_packed());
}

TEST_CASE("controller: one cycle per pair of feedback frames, PID from the reference") {
  fw::Controller ctl;
  cdam::CanFrame cmd, diag;
  // reference 0.5 rad and -0.3 rad (little-endian float32)
  cdam::CanFrame ref;
  ref.id = 0x300;
  ref.dlc = 8;
  const float r[2] = {0.5f, -0.3f};
  std::memcpy(ref.data, r, 8);
  CHECK(!ctl.on_frame(ref, &cmd, &diag));
  cdam::c610::Feedback fb;
  fb.motor = 1;
  CHECK(!ctl.on_frame(cdam::c610::encode_feedback(fb), &cmd, &diag));
  fb.motor = 2;
  REQUIRE(ctl.on_frame(cdam::c610::encode_feedback(fb), &cmd, &diag));
  // q = 0, w = 0: u = kp e + ki e dt -> counts
  const double u1 = 8.0 * 0.5 + 2.0 * 0.5 * 0.001, u2 = 8.0 * -0.3 + 2.0 * -0.3 * 0.001;
  std::int16_t c[4];
  REQUIRE(cdam::c610::decode_command(cmd, c) == cdam::c610::Decode::Ok);
  CHECK(cmd.id == 0x200);
  CHECK(c[0] == std::lround(u1 * 1000));
  CHECK(c[1] == std::lround(u2 * 1000));
  CHECK(c[2] == 0);
  CHECK(diag.id == 0x3F0);
  std::uint16_t cyc;
  std::memcpy(&cyc, diag.data + 4, 2);
  CHECK(cyc == 1);
  // a malformed frame is counted, not acted on
  cdam::CanFrame bad = cdam::c610::encode_feedback(fb);
  bad.dlc = 6;
  CHECK(!ctl.on_frame(bad, &cmd, &diag));
  CHECK(ctl.rejected() == 1);
  // the model saw the features [q1, w1, i1, q2, w2, i2] = 0
  float zeros[fw::kIn] = {}, y[fw::kOut];
  fw::predict(zeros, y);
  CHECK(ctl.model_outputs()[0] == doctest::Approx(y[0]));
}

TEST_CASE("controller through SLCAN text: the loop image's path") {
  fw::Controller ctl;
  cdam::slcan::LineReader reader;
  const std::string zeros(16, '0');
  const std::string in = "C\rS8\rO\rt2018" + zeros + "\rt2028" + zeros + "\r";
  int frames_out = 0;
  std::string out;
  for (char ch : in) {
    cdam::slcan::Event ev;
    if (!reader.push(ch, &ev) || ev.kind != cdam::slcan::Kind::Frame) continue;
    cdam::CanFrame cmd, diag;
    if (ctl.on_frame(ev.frame, &cmd, &diag)) {
      char line[32];
      out.append(line, cdam::slcan::encode(cmd, line, sizeof line));
      ++frames_out;
    }
  }
  CHECK(frames_out == 1);
  CHECK(out == "t20080000000000000000\r");  // zero reference, zero state: zero current
}

TEST_CASE("optim run: the core's MlpFitness on the flash data equals a plain double MSE") {
  // fw/optim_run.hpp uses cdam/optim/mlp_fitness.hpp (embeddable; the threaded BpFitness is
  // fenced in cdam/host/). Reference: MSE in double with std::tanh over the same float data
  // (the fitness uses the fast float tanh, within 1e-6 of tanh).
  using Net = fw::optim_run::Net;
  const Net net;
  cdam::optim::MlpFitness<Net> fit(net, cdam_optim_data::kX, cdam_optim_data::kT,
                                   cdam_optim_data::kSamples);
  cdam::Rng rng(3);
  float theta[3 * Net::kParams];
  for (float& v : theta) v = rng.uniform(-1.0f, 1.0f);
  float got[3];
  Eigen::internal::set_is_malloc_allowed(false);
  fit.batch(theta, 3, got);
  Eigen::internal::set_is_malloc_allowed(true);
  constexpr int I = Net::kInputs, H = Net::kHidden, M = Net::kOutputs;
  for (int k = 0; k < 3; ++k) {
    const float* th = theta + k * Net::kParams;
    double sse = 0;
    for (int s = 0; s < cdam_optim_data::kSamples; ++s) {
      double a[H];
      for (int j = 0; j < H; ++j) {
        double v = th[I * H + j];
        for (int l = 0; l < I; ++l) v += double(th[l * H + j]) * cdam_optim_data::kX[s * I + l];
        a[j] = std::tanh(v);
      }
      for (int o = 0; o < M; ++o) {
        double y = th[I * H + H + H * M + o];
        for (int j = 0; j < H; ++j) y += double(th[I * H + H + j * M + o]) * a[j];
        const double e = cdam_optim_data::kT[s * M + o] - y;
        sse += e * e;
      }
    }
    const double want = sse / (cdam_optim_data::kSamples * M);
    CHECK(got[k] == doctest::Approx(want).epsilon(1e-5));
    CHECK(got[k] > 0.0f);
  }
}

namespace {

cdam::CanFrame reference_frame(float r1, float r2) {
  cdam::CanFrame f;
  f.id = 0x300;
  f.dlc = 8;
  const float r[2] = {r1, r2};
  std::memcpy(f.data, r, 8);
  return f;
}

// One cycle at rest (q = w = 0 on both motors); returns the two command currents (counts).
void rest_cycle(fw::Controller& ctl, std::int16_t* c) {
  cdam::CanFrame cmd, diag;
  cdam::c610::Feedback fb;
  fb.motor = 1;
  REQUIRE(!ctl.on_frame(cdam::c610::encode_feedback(fb), &cmd, &diag));
  fb.motor = 2;
  REQUIRE(ctl.on_frame(cdam::c610::encode_feedback(fb), &cmd, &diag));
  std::int16_t all[4];
  REQUIRE(cdam::c610::decode_command(cmd, all) == cdam::c610::Decode::Ok);
  c[0] = all[0];
  c[1] = all[1];
}

std::uint16_t status_word(const cdam::CanFrame& st, int k) {
  std::uint16_t v;
  std::memcpy(&v, st.data + 2 * k, 2);
  return v;
}

}  // namespace

TEST_CASE("current conversion: NaN is 0 A, Inf and huge values saturate at the C610's 10 A") {
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  CHECK(fw::amps_to_counts(nan) == 0);
  CHECK(fw::amps_to_counts(inf) == 10000);
  CHECK(fw::amps_to_counts(-inf) == -10000);
  CHECK(fw::amps_to_counts(1e30f) == 10000);
  CHECK(fw::amps_to_counts(-1e30f) == -10000);
  CHECK(fw::amps_to_counts(10.2f) == 10000);
  CHECK(fw::amps_to_counts(1.2344f) == 1234);  // 1 mA per count, nearest
  CHECK(fw::amps_to_counts(-1.2346f) == -1235);
}

TEST_CASE("controller: a NaN reference is rejected, counted and cannot latch the integrator") {
  fw::Controller ctl;
  cdam::CanFrame cmd, diag, st;
  CHECK(!ctl.on_frame(reference_frame(0.5f, -0.3f), &cmd, &diag));
  CHECK(!ctl.take_status(&st));  // nothing rejected yet, nothing requested
  std::int16_t c[2];
  rest_cycle(ctl, c);
  // e = r, integral = r dt: u = kp r + ki r dt (A), 1000 counts per A
  CHECK(c[0] == std::lround((8.0 * 0.5 + 2.0 * 0.5 * 0.001) * 1000));
  const float nan = std::numeric_limits<float>::quiet_NaN();
  CHECK(!ctl.on_frame(reference_frame(nan, 0.1f), &cmd, &diag));
  CHECK(ctl.input_counts().ref_nonfinite == 1);
  CHECK(ctl.rejected() == 1);
  CHECK(ctl.references()[0] == 0.5f);   // the last valid pair is held, both values
  CHECK(ctl.references()[1] == -0.3f);
  REQUIRE(ctl.take_status(&st));
  CHECK(st.id == 0x3F1);
  CHECK(st.dlc == 8);
  CHECK(status_word(st, 0) == 1);
  CHECK(status_word(st, 1) == 0);
  CHECK(!ctl.take_status(&st));  // sent once per change
  rest_cycle(ctl, c);
  // second cycle on the held reference: integral = 2 r dt
  CHECK(c[0] == std::lround((8.0 * 0.5 + 2.0 * 2 * 0.5 * 0.001) * 1000));
  CHECK(std::isfinite(ctl.integral(0)));
  CHECK(std::isfinite(ctl.integral(1)));
  // a valid reference afterwards works normally: nothing was latched
  CHECK(!ctl.on_frame(reference_frame(0.0f, 0.0f), &cmd, &diag));
  rest_cycle(ctl, c);
  const double i1 = 2 * 0.5 * 0.001;  // integral of the first two cycles, e = 0 now
  CHECK(c[0] == std::lround(2.0 * i1 * 1000));
}

TEST_CASE("controller: Inf and out-of-range references are rejected, the range edge accepted") {
  fw::Controller ctl;
  cdam::CanFrame cmd, diag, st;
  const float inf = std::numeric_limits<float>::infinity();
  CHECK(!ctl.on_frame(reference_frame(inf, 0.0f), &cmd, &diag));
  CHECK(!ctl.on_frame(reference_frame(0.0f, -inf), &cmd, &diag));
  CHECK(!ctl.on_frame(reference_frame(1e30f, 0.0f), &cmd, &diag));
  CHECK(!ctl.on_frame(reference_frame(0.0f, std::nextafter(256.0f, 1e9f)), &cmd, &diag));
  CHECK(ctl.input_counts().ref_nonfinite == 2);
  CHECK(ctl.input_counts().ref_range == 2);
  CHECK(ctl.references()[0] == 0.0f);
  CHECK(ctl.references()[1] == 0.0f);
  CHECK(!ctl.on_frame(reference_frame(-256.0f, 256.0f), &cmd, &diag));  // the edge itself
  CHECK(ctl.references()[0] == -256.0f);
  CHECK(ctl.input_counts().ref_range == 2);
  std::int16_t c[2];
  rest_cycle(ctl, c);
  CHECK(c[0] == -10000);  // saturated at the C610's range, not wrapped
  CHECK(c[1] == 10000);
  REQUIRE(ctl.take_status(&st));
  CHECK(status_word(st, 0) == 2);
  CHECK(status_word(st, 1) == 2);
}

TEST_CASE("controller: out-of-range measurements are counted and the last valid state held") {
  fw::Controller ctl;
  cdam::CanFrame cmd, diag, st;
  cdam::c610::Feedback fb;
  fb.motor = 1;
  cdam::CanFrame bad = cdam::c610::encode_feedback(fb);
  bad.data[0] = 0x20;  // angle 0x2000 = 8192: one past the encoder's 0..8191
  CHECK(!ctl.on_frame(bad, &cmd, &diag));
  CHECK(ctl.input_counts().meas_range == 1);
  // motor 1 spinning at 20,000 rpm (the C610's range), 2731 counts a millisecond: the output
  // angle grows by 2 pi 2731 / (8192 36) = 0.0582 rad a frame and would pass kJointRangeRad
  // after 256 / 0.0582 = 4399.8 frames; from there on the measured angle is held within range
  cdam::c610::Feedback rest;
  rest.motor = 2;
  fb.speed_rpm = 20000;
  long angle = 0;
  int first_reject = -1;
  float q_max = 0.0f;
  for (int k = 0; k < 5000; ++k) {
    fb.angle = static_cast<std::uint16_t>(angle % 8192);
    const std::uint16_t before = ctl.input_counts().meas_range;
    ctl.on_frame(cdam::c610::encode_feedback(fb), &cmd, &diag);
    if (ctl.input_counts().meas_range != before && first_reject < 0) first_reject = k;
    if (ctl.on_frame(cdam::c610::encode_feedback(rest), &cmd, &diag))
      q_max = std::max(q_max, ctl.features()[0]);
    angle += 2731;
  }
  const double per_frame = 2 * M_PI * 2731.0 / (8192.0 * 36.0);
  CHECK(first_reject == static_cast<int>(std::floor(256.0 / per_frame)) + 1);
  CHECK(q_max <= 256.0f);
  CHECK(q_max > 256.0f - 0.06f);
  const std::uint16_t held = ctl.input_counts().meas_range;
  CHECK(held > 1);
  REQUIRE(ctl.take_status(&st));
  CHECK(status_word(st, 2) == held);
  CHECK(status_word(st, 3) == 0);
  // a foreign motor and a short frame are malformed, not measurements
  fb.motor = 3;
  CHECK(!ctl.on_frame(cdam::c610::encode_feedback(fb), &cmd, &diag));
  cdam::CanFrame short_frame = reference_frame(0.0f, 0.0f);
  short_frame.dlc = 4;
  CHECK(!ctl.on_frame(short_frame, &cmd, &diag));
  CHECK(ctl.input_counts().frames == 2);
}

TEST_CASE("controller: a remote frame 0x3F1 requests the status frame") {
  fw::Controller ctl;
  cdam::CanFrame cmd, diag, st;
  CHECK(!ctl.take_status(&st));
  cdam::CanFrame req;
  req.id = 0x3F1;
  req.remote = true;
  CHECK(!ctl.on_frame(req, &cmd, &diag));
  CHECK(ctl.rejected() == 0);
  REQUIRE(ctl.take_status(&st));
  for (int k = 0; k < 4; ++k) CHECK(status_word(st, k) == 0);
}
