// Semihosting entry: r0 = operation, r1 = argument block, bkpt 0xAB, result in r0.
#include "fw/semihost.hpp"

namespace fw::semihost {

std::uint32_t call(std::uint32_t op, const void* arg) {
  register std::uint32_t r0 __asm__("r0") = op;
  register const void* r1 __asm__("r1") = arg;
  __asm__ volatile("bkpt 0xAB" : "+r"(r0) : "r"(r1) : "memory");
  return r0;
}

void exit(int code) {
  // SYS_EXIT_EXTENDED: {ADP_Stopped_ApplicationExit, code} -> QEMU's exit status is `code`.
  const std::uint32_t block[2] = {0x20026u, static_cast<std::uint32_t>(code)};
  for (;;) call(kExitExtended, block);
}

}  // namespace fw::semihost
