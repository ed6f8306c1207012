// Instruction counting under QEMU -icount (check images): SysTick runs on the core clock, which
// is virtual time, so ticks are proportional to instructions; a loop of known length calibrates
// the ratio (the host divides: cdam_core.firmware.qemu).
#pragma once
#include <cstdint>

#include "fw/hal.hpp"

namespace fw::ticks {

constexpr std::uint32_t kCalIterations = 20000;  // 2 instructions each (subs, bne)
constexpr std::uint32_t kCalInstructions = 2 * kCalIterations + 1;

inline std::uint32_t elapsed(std::uint32_t start, std::uint32_t end) {
  return (start - end) & 0x00FFFFFFu;  // SysTick counts down
}

inline std::uint32_t calibration() {
  const std::uint32_t t0 = fw::hal::systick_value();
  std::uint32_t n = kCalIterations;
  __asm__ volatile("1: subs %0, %0, #1\n bne 1b" : "+r"(n)::"cc");
  return elapsed(t0, fw::hal::systick_value());
}

}  // namespace fw::ticks
