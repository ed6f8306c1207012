// Check (3), second half, on the board: the fixed-size IBOA-BP + LM run of fw/optim_run.hpp
// (data in flash, no heap). The curve (float64 values) goes to ./fw_optim_curve.bin through
// semihosting, the trained weights (58 float32) to ./fw_optim_theta.bin; the host compares it with fw_optim_host's float32 run (cdam_core.firmware).
// Exit status: 0 ok, 3 file error, 4 run error (core Status), 99 fault.
#include <cstdint>

#include "fw/optim_run.hpp"
#include "fw/semihost.hpp"

namespace sh = fw::semihost;
extern "C" void fw_on_exit(int code) { sh::exit(code); }
extern "C" std::uint32_t fw_stack_high_water();

namespace {
fw::optim_run::Workspace g_work;
double g_curve[fw::optim_run::kCurveMax];
}  // namespace

int main() {
  const fw::optim_run::Result r = fw::optim_run::run(g_work, g_curve);
  sh::kv("status", static_cast<std::uint32_t>(r.status));
  if (r.status != cdam::Status::Ok) return 4;
  const int out = sh::open("fw_optim_curve.bin", 5);
  const std::size_t bytes = static_cast<std::size_t>(r.curve_len) * sizeof(double);
  if (out < 0 || sh::write(out, g_curve, bytes) != bytes) return 3;
  sh::close(out);
  const int th = sh::open("fw_optim_theta.bin", 5);
  if (th < 0 || sh::write(th, g_work.theta, sizeof g_work.theta) != sizeof g_work.theta) return 3;
  sh::close(th);
  sh::kv("iterations", fw::optim_run::kIterations);
  sh::kv("lm_epochs", static_cast<std::uint32_t>(r.lm_epochs));
  sh::kv("evaluations", static_cast<std::uint32_t>(r.evaluations));
  sh::kv("stack_bytes", fw_stack_high_water());
  return 0;
}
