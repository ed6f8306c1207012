// Host build of the firmware logic (the same headers as the target image): model runner,
// SLCAN + controller cycle, heap-free (EIGEN_RUNTIME_NO_MALLOC). Expected values come from
// independent computations written out here (plain loops over the exported weights, the
// protocol bytes), not from the code under test.
#define DOCTEST_CONFIG_IMPLEMENT_WITH_MAIN
#include <doctest/doctest.h>

#include <cmath>
#include <cstring>
#include <string>
#include <vector>

#include "cdam/optim/bp_fitness.hpp"
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

TEST_CASE("optim run: MseFitness equals the core's MlpFitness on the flash data") {
  // fw/optim_run.hpp keeps its own fitness because bp_fitness.hpp does not compile for the
  // target (std::mutex); on the host both exist and must agree exactly (same loop, same order).
  using Net = fw::optim_run::Net;
  const Net net;
  fw::optim_run::MseFitness<Net> mine(net, cdam_optim_data::kX, cdam_optim_data::kT,
                                      cdam_optim_data::kSamples);
  cdam::optim::MlpFitness<Net> core(net, cdam_optim_data::kX, cdam_optim_data::kT,
                                    cdam_optim_data::kSamples);
  cdam::Rng rng(3);
  float theta[3 * Net::kParams];
  for (float& v : theta) v = rng.uniform(-1.0f, 1.0f);
  float a[3], b[3];
  mine.batch(theta, 3, a);
  core.batch(theta, 3, b);
  for (int k = 0; k < 3; ++k) {
    CHECK(a[k] == b[k]);
    CHECK(a[k] > 0.0f);
  }
}
