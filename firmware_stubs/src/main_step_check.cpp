// The step check of the dynamic kinds (arx, hybrid, greybox) under QEMU with semihosting:
// ./fw_step_in.bin holds int32 rows, int32 mode (0: one-step, 1: free run, k = 2..kMaxK:
// k-step), then `rows` rows of float32 [u (kU), y (kY)]. Rows 0 .. kT0-1 prime the model with
// the measured history; every later row is predicted (fw::StepModel::step) and, in one-step
// mode, then replaced by the measured row (correct). k-step: row t is predicted by k steps
// from a copy of a model that has taken the measured rows up to t - k (one-step below, k rows
// behind), rows t-k+1 .. t from a ring of the last kMaxK rows; rows kT0 .. kT0+k-2 are
// returned as measured (as cdam_core.models.protocol does). In every mode each measured row
// then reaches the model (fw::StepModel::observe: the measured-row input of the kinds whose
// equations read measured signals, greybox arm_coupling). The predictions go to
// ./fw_step_out.bin (float32, kY per row).
// Instructions: SysTick (core clock = virtual time under -icount) read around every step; the
// host turns ticks into instructions with the calibration loop. With a monitor section
// (CDAM_MODEL_HAS_MONITOR, fw/monitor.hpp) and in one-step mode, every predicted row also goes
// through the residual monitor (SysTick read around it too): its flags, one byte per output, go
// to ./fw_alarm_out.bin and each alarm frame (uint32 id, 8 data bytes) to ./fw_alarm_frames.bin.
// Exit 0 ok, 2 parameters corrupt, 3 file error, 4 bad header.
#include <cstdint>

#include "fw/hal.hpp"
#include "fw/semihost.hpp"
#include "fw/ticks.hpp"
#include "fw/step_model.hpp"
#include "fw/monitor.hpp"

namespace sh = fw::semihost;

extern "C" void fw_on_exit(int code) { sh::exit(code); }
extern "C" std::uint32_t fw_stack_high_water();

namespace {

using fw::ticks::elapsed;

#ifndef CDAM_MODEL_STATIC
#define CDAM_MODEL_STATIC 0
#endif
constexpr bool kStaticMap = CDAM_MODEL_STATIC != 0;

fw::StepModel g_model;
constexpr int kMaxK = 64;                  // the longest k-step horizon
fw::StepModel g_scratch;                   // k-step: the model run ahead from g_model
float g_rows[kMaxK][fw::kU + fw::kY];      // k-step: the last kMaxK rows of the record
#if CDAM_MODEL_HAS_MONITOR
fw::Monitor<fw::kY> g_monitor;
#endif

// one step with SysTick read around it: the ticks summed, the largest kept, the steps counted
void timed_step(fw::StepModel& model, const float* u, float* y, std::uint64_t& total,
                std::uint32_t& largest, std::uint32_t& count) {
  const std::uint32_t t0 = fw::hal::systick_value();
  __asm__ volatile("" ::: "memory");
  model.step(u, y);
  __asm__ volatile("" ::: "memory");
  const std::uint32_t d = elapsed(t0, fw::hal::systick_value());
  total += d;
  if (d > largest) largest = d;
  ++count;
}

// the measured row into the model (observe), SysTick read around it: summed apart from the
// step's ticks (the host adds the two per row)
std::uint64_t g_observe_ticks = 0;
std::uint32_t g_observed = 0;
void timed_observe(fw::StepModel& model, const float* ym) {
  const std::uint32_t t0 = fw::hal::systick_value();
  __asm__ volatile("" ::: "memory");
  model.observe(ym);
  __asm__ volatile("" ::: "memory");
  g_observe_ticks += elapsed(t0, fw::hal::systick_value());
  ++g_observed;
}

}  // namespace

int main() {
  const std::uint32_t fnv = fw::params_fnv1a();
  sh::kv("params_fnv1a", fnv, true);
  if (fnv != cdam_model::kParamsFnv1a) return 2;
#if CDAM_MODEL_HAS_MONITOR
  const std::uint32_t mon = fw::monitor_fnv1a();
  sh::kv("monitor_fnv1a", mon, true);
  if (mon != cdam_model::kMonitorFnv1a) return 2;
#endif
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
#if CDAM_MODEL_HAS_MONITOR
  const int alarm_out = sh::open("fw_alarm_out.bin", 5);
  const int frames_out = sh::open("fw_alarm_frames.bin", 5);
  if (alarm_out < 0 || frames_out < 0) return 3;
  std::uint64_t monitor_ticks = 0;
  std::uint32_t monitored = 0, frames = 0;
#endif
  std::int32_t head[2];
  if (sh::read(in, head, sizeof head) != sizeof head) return 3;
  if (head[0] < fw::kT0 || head[1] < 0 || head[1] > kMaxK) return 4;
  // a static map (CDAM_MODEL_STATIC: a network without NARX orders) has no k-step of its own:
  // its k-step prediction is the one of every row, as in Python
  const int k_ahead = head[1] >= 2 && !kStaticMap ? head[1] : 0;
  std::uint32_t steps = 0, timed = 0, max_ticks = 0;
  std::uint64_t total_ticks = 0;
  float row[fw::kU + fw::kY], y[fw::kY];
  for (std::int32_t t = 0; t < head[0]; ++t) {
    if (sh::read(in, row, sizeof row) != sizeof row) return 3;
    const float* u = row;
    const float* ym = row + fw::kU;
    if (t < fw::kT0) {
      g_model.prime(u, ym);
      if (k_ahead) for (int c = 0; c < fw::kU + fw::kY; ++c) g_rows[t % kMaxK][c] = row[c];
      continue;
    }
    if (k_ahead) {
      for (int c = 0; c < fw::kU + fw::kY; ++c) g_rows[t % kMaxK][c] = row[c];
      ++steps;
      if (t < fw::kT0 + k_ahead - 1) {   // no origin k rows back yet: the measured row
        if (sh::write(out, ym, sizeof y) != sizeof y) return 3;
        continue;
      }
      g_scratch = g_model;               // has taken the measured rows up to t - k
      for (std::int32_t j = t - k_ahead + 1; j < t; ++j) {
        g_scratch.step(g_rows[j % kMaxK], y);
        g_scratch.observe(g_rows[j % kMaxK] + fw::kU);   // the measured row (every mode)
      }
      timed_step(g_scratch, u, y, total_ticks, max_ticks, timed);
      if (sh::write(out, y, sizeof y) != sizeof y) return 3;
      const float* r = g_rows[(t - k_ahead + 1) % kMaxK];   // one row on, measured
      float skip[fw::kY];
      g_model.step(r, skip);
      g_model.correct(r + fw::kU);
      g_model.observe(r + fw::kU);
      continue;
    }
    timed_step(g_model, u, y, total_ticks, max_ticks, timed);
    ++steps;
#if CDAM_MODEL_HAS_MONITOR
    if (head[1] == 0) {
      std::uint8_t flags[fw::kY];
      std::uint16_t n = g_monitor.count();   // each frame carries the count up to its alarm
      const std::uint32_t m0 = fw::hal::systick_value();
      __asm__ volatile("" ::: "memory");
      const bool any = g_monitor.update(ym, y, flags);
      __asm__ volatile("" ::: "memory");
      monitor_ticks += elapsed(m0, fw::hal::systick_value());
      ++monitored;
      if (sh::write(alarm_out, flags, sizeof flags) != sizeof flags) return 3;
      for (int c = 0; any && c < fw::kY; ++c) {
        if (!flags[c]) continue;
        if (n < 0xFFFFu) ++n;
        const cdam::CanFrame f = fw::alarm_frame(c, flags[c], n,
                                                 static_cast<std::uint32_t>(t));
        std::uint8_t rec[12];
        for (int b = 0; b < 4; ++b) rec[b] = static_cast<std::uint8_t>(f.id >> (8 * b));
        for (int b = 0; b < 8; ++b) rec[4 + b] = f.data[b];
        if (sh::write(frames_out, rec, sizeof rec) != sizeof rec) return 3;
        ++frames;
      }
    }
#endif
    if (head[1] == 0) g_model.correct(ym);
    timed_observe(g_model, ym);   // the measured row reaches the model in every mode
    if (sh::write(out, y, sizeof y) != sizeof y) return 3;
  }
  sh::close(in);
  sh::close(out);
#if CDAM_MODEL_HAS_MONITOR
  sh::close(alarm_out);
  sh::close(frames_out);
  sh::kv("monitored", monitored);
  sh::kv("alarm_frames", frames);
  sh::kv("monitor_ticks_hi", static_cast<std::uint32_t>(monitor_ticks >> 32));
  sh::kv("monitor_ticks_lo", static_cast<std::uint32_t>(monitor_ticks));
#endif
  sh::kv("observed", g_observed);
  sh::kv("observe_ticks_hi", static_cast<std::uint32_t>(g_observe_ticks >> 32));
  sh::kv("observe_ticks_lo", static_cast<std::uint32_t>(g_observe_ticks));
  sh::kv("steps", steps);
  sh::kv("timed", timed);
  sh::kv("step_ticks_hi", static_cast<std::uint32_t>(total_ticks >> 32));
  sh::kv("step_ticks_lo", static_cast<std::uint32_t>(total_ticks));
  sh::kv("step_ticks_max", max_ticks);
  sh::kv("stack_bytes", fw_stack_high_water());
  sh::puts("done\n");
  return 0;
}
