// Checks (1) and (2) under QEMU with semihosting:
// (1) every float32 vector of kIn normalised inputs in ./fw_in.bin goes through the network;
//     the normalised outputs are written to ./fw_out.bin (float32, kOut per vector).
// (2) instruction counts with -icount: SysTick (core clock = virtual time) over a calibration
//     loop of known length, an empty loop and R inferences; the host turns ticks into
//     instructions (cdam_core.firmware).
// Exit status: 0 ok, 2 weights corrupt, 3 file error, 99 fault.
#include <cstdint>

#include "fw/hal.hpp"
#include "fw/model_runner.hpp"
#include "fw/semihost.hpp"
#include "fw/ticks.hpp"

namespace sh = fw::semihost;

extern "C" void fw_on_exit(int code) { sh::exit(code); }
extern "C" std::uint32_t fw_stack_high_water();

namespace {

constexpr std::uint32_t kReps = 500;

using fw::ticks::elapsed;

float g_x[fw::kIn], g_y[fw::kOut];

std::uint32_t ticks_loop(bool infer, bool scaled) {
  const std::uint32_t t0 = fw::hal::systick_value();
  for (std::uint32_t r = 0; r < kReps; ++r) {
    __asm__ volatile("" ::: "memory");
    if (infer) {
      if (scaled)
        fw::predict(g_x, g_y);
      else
        fw::infer_normalised(g_x, g_y);
    }
    __asm__ volatile("" ::: "memory");
  }
  return elapsed(t0, fw::hal::systick_value());
}

}  // namespace

int main() {
  const std::uint32_t fnv = fw::theta_fnv1a();
  sh::kv("theta_fnv1a", fnv, true);
  if (fnv != cdam_model::kThetaFnv1a || !fw::check_packed()) return 2;
  sh::kv("inputs", fw::kIn);
  sh::kv("hidden", fw::kHid);
  sh::kv("outputs", fw::kOut);

  const int in = sh::open("fw_in.bin", 1);
  const int out = sh::open("fw_out.bin", 5);
  if (in < 0 || out < 0) return 3;
  std::uint32_t n = 0;
  float x[fw::kIn], y[fw::kOut];
  while (sh::read(in, x, sizeof x) == sizeof x) {
    fw::infer_normalised(x, y);
    if (sh::write(out, y, sizeof y) != sizeof y) return 3;
    ++n;
  }
  sh::close(in);
  sh::close(out);
  sh::kv("vectors", n);

  for (int k = 0; k < fw::kIn; ++k) g_x[k] = 0.1f * static_cast<float>(k) - 0.3f;
  fw::hal::systick_free_running();
  sh::kv("cal_instructions", fw::ticks::kCalInstructions);
  sh::kv("cal_ticks", fw::ticks::calibration());
  sh::kv("reps", kReps);
  sh::kv("empty_ticks", ticks_loop(false, false));
  sh::kv("infer_ticks", ticks_loop(true, false));
  sh::kv("predict_ticks", ticks_loop(true, true));
  sh::kv("stack_bytes", fw_stack_high_water());
  sh::puts("done\n");
  return 0;
}
