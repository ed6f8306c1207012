// The step check of the dynamic kinds (arx, hybrid, greybox) under QEMU with semihosting:
// ./fw_step_in.bin holds int32 rows, int32 mode (0: one-step, 1: free run), then `rows` rows of
// float32 [u (kU), y (kY)]. Rows 0 .. kT0-1 prime the model with the measured history; every
// later row is predicted (fw::StepModel::step) and, in one-step mode, then replaced by the
// measured row (correct). The predictions go to ./fw_step_out.bin (float32, kY per row).
// Instructions: SysTick (core clock = virtual time under -icount) read around every step; the
// host turns ticks into instructions with the calibration loop. Exit 0 ok, 2 parameters
// corrupt, 3 file error, 4 bad header.
#include <cstdint>

#include "fw/hal.hpp"
#include "fw/semihost.hpp"
#include "fw/ticks.hpp"
#include "fw/step_model.hpp"

namespace sh = fw::semihost;

extern "C" void fw_on_exit(int code) { sh::exit(code); }
extern "C" std::uint32_t fw_stack_high_water();

namespace {

using fw::ticks::elapsed;

fw::StepModel g_model;

}  // namespace

int main() {
  const std::uint32_t fnv = fw::params_fnv1a();
  sh::kv("params_fnv1a", fnv, true);
  if (fnv != cdam_model::kParamsFnv1a) return 2;
  sh::kv("inputs", fw::kU);
  sh::kv("outputs", fw::kY);
  sh::kv("history", fw::kT0);
  fw::hal::systick_free_running();
  sh::kv("cal_instructions", fw::ticks::kCalInstructions);
  sh::kv("cal_ticks", fw::ticks::calibration());
  // the cost of the two SysTick reads alone
  std::uint32_t empty = 0xFFFFFFFFu;
  for (int k = 0; k < 16; ++k) {
    const std::uint32_t t0 = fw::hal::systick_value();
    __asm__ volatile("" ::: "memory");
    const std::uint32_t d = elapsed(t0, fw::hal::systick_value());
    if (d < empty) empty = d;
  }
  sh::kv("empty_ticks", empty);

  const int in = sh::open("fw_step_in.bin", 1);
  const int out = sh::open("fw_step_out.bin", 5);
  if (in < 0 || out < 0) return 3;
  std::int32_t head[2];
  if (sh::read(in, head, sizeof head) != sizeof head) return 3;
  if (head[0] < fw::kT0 || (head[1] != 0 && head[1] != 1)) return 4;
  std::uint32_t steps = 0, max_ticks = 0;
  std::uint64_t total_ticks = 0;
  float row[fw::kU + fw::kY], y[fw::kY];
  for (std::int32_t t = 0; t < head[0]; ++t) {
    if (sh::read(in, row, sizeof row) != sizeof row) return 3;
    const float* u = row;
    const float* ym = row + fw::kU;
    if (t < fw::kT0) {
      g_model.prime(u, ym);
      continue;
    }
    const std::uint32_t t0 = fw::hal::systick_value();
    __asm__ volatile("" ::: "memory");
    g_model.step(u, y);
    __asm__ volatile("" ::: "memory");
    const std::uint32_t d = elapsed(t0, fw::hal::systick_value());
    total_ticks += d;
    if (d > max_ticks) max_ticks = d;
    ++steps;
    if (head[1] == 0) g_model.correct(ym);
    if (sh::write(out, y, sizeof y) != sizeof y) return 3;
  }
  sh::close(in);
  sh::close(out);
  sh::kv("steps", steps);
  sh::kv("step_ticks_hi", static_cast<std::uint32_t>(total_ticks >> 32));
  sh::kv("step_ticks_lo", static_cast<std::uint32_t>(total_ticks));
  sh::kv("step_ticks_max", max_ticks);
  sh::kv("stack_bytes", fw_stack_high_water());
  sh::puts("done\n");
  return 0;
}
