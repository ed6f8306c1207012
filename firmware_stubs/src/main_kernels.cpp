// Check (3): other core kernels on the target with semihosting.
// Five-point cubic smoothing: ./fw_smooth_in.bin = int32 n, int32 passes, n float32 samples;
// the smoothed window goes to ./fw_smooth_out.bin (float32). Exit 0 ok, 3 file error, 4 kernel
// error, 99 fault.
#include <cstdint>

#include "cdam/smoothing.hpp"
#include "fw/semihost.hpp"

namespace sh = fw::semihost;
extern "C" void fw_on_exit(int code) { sh::exit(code); }
extern "C" std::uint32_t fw_stack_high_water();

namespace {
constexpr std::int32_t kMaxWindow = 1024;
float g_window[kMaxWindow];
}  // namespace

int main() {
  const int in = sh::open("fw_smooth_in.bin", 1);
  if (in < 0) return 3;
  std::int32_t head[2] = {0, 0};
  if (sh::read(in, head, sizeof head) != sizeof head) return 3;
  if (head[0] < 0 || head[0] > kMaxWindow) return 3;
  const std::size_t bytes = static_cast<std::size_t>(head[0]) * sizeof(float);
  if (sh::read(in, g_window, bytes) != bytes) return 3;
  sh::close(in);
  if (cdam::five_point_cubic_smooth_inplace(g_window, head[0], 1, head[1]) != cdam::Status::Ok)
    return 4;
  const int out = sh::open("fw_smooth_out.bin", 5);
  if (out < 0 || sh::write(out, g_window, bytes) != bytes) return 3;
  sh::close(out);
  sh::kv("smoothed", static_cast<std::uint32_t>(head[0]));
  sh::kv("stack_bytes", fw_stack_high_water());
  return 0;
}
