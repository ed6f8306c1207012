// Random-byte fuzzing of the frame parsers (built with -fsanitize=address,undefined): random
// byte streams, random mutations of valid SLCAN lines and random CAN frames go through the
// SLCAN LineReader / parse_line, the C610 decoders and the controller. Every parse gets its
// own exactly-sized heap copy of the line so ASan catches any read past it. Deterministic
// (fixed seed); argv[1] = iterations.
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>

#include "cdam/slcan.hpp"
#include "fw/controller.hpp"

namespace {
std::uint64_t g_state = 0x9E3779B97F4A7C15ull;
std::uint32_t next() {  // splitmix64
  std::uint64_t z = (g_state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return static_cast<std::uint32_t>(z ^ (z >> 31));
}
}  // namespace

int main(int argc, char** argv) {
  const long iters = argc > 1 ? std::atol(argv[1]) : 100000;
  static const char* seeds[] = {"t20180102030405060708", "T1ABCDEF02abCD", "r7FF3", "S8", "O",
                                "s031C", "t2008000000000000000", "t3008000000000000000"};
  static const char alphabet[] = "tTrRSsOCLVNFZ0123456789ABCDEFabcdefxyz\r\n\a ";
  cdam::slcan::LineReader reader;
  fw::Controller ctl;
  long frames = 0, errors = 0;
  for (long it = 0; it < iters; ++it) {
    const std::size_t n = next() % 40;
    std::size_t n_line = n;  // bytes parsed as one line
    std::unique_ptr<char[]> buf(new char[n ? n : 1]);
    const int mode = static_cast<int>(next() % 3);
    if (mode == 0) {
      for (std::size_t k = 0; k < n; ++k) buf[k] = static_cast<char>(next() & 0xFF);
    } else if (mode == 1) {
      for (std::size_t k = 0; k < n; ++k) buf[k] = alphabet[next() % (sizeof alphabet - 1)];
    } else {
      const char* s = seeds[next() % (sizeof seeds / sizeof seeds[0])];
      const std::size_t len = std::strlen(s);
      for (std::size_t k = 0; k < n; ++k) buf[k] = k < len ? s[k] : alphabet[next() % 16];
      if (n > len && next() % 2) n_line = len;  // the seed alone, terminated
      if (n && next() % 2) buf[next() % n] = static_cast<char>(next() & 0xFF);
    }
    // the whole buffer as one line (exactly n bytes readable)
    const cdam::slcan::Event ev = cdam::slcan::parse_line(buf.get(), n_line);
    if (ev.kind == cdam::slcan::Kind::Frame) {
      ++frames;
      if (ev.frame.dlc > 8) return 1;
    } else if (ev.kind == cdam::slcan::Kind::Error) {
      ++errors;
    }
    // and as a byte stream through the line reader and the controller
    for (std::size_t k = 0; k < n; ++k) {
      cdam::slcan::Event e;
      if (reader.push(buf[k], &e) && e.kind == cdam::slcan::Kind::Frame) {
        cdam::CanFrame cmd, diag;
        cdam::c610::Feedback fb;
        (void)cdam::c610::decode_feedback(e.frame, &fb);
        std::int16_t cur[4];
        (void)cdam::c610::decode_command(e.frame, cur);
        (void)ctl.on_frame(e.frame, &cmd, &diag);
        char line[cdam::slcan::kMaxLine];
        if (cdam::slcan::encode(e.frame, line, sizeof line) == 0) return 2;
      }
    }
    // random raw frames straight into the decoders and the controller
    cdam::CanFrame f;
    f.id = next() & 0x7FF;
    if (next() % 2) f.id = 0x201 + next() % 3;
    f.dlc = static_cast<std::uint8_t>(next() % 9);
    f.remote = next() % 16 == 0;
    f.extended = next() % 16 == 0;
    for (auto& b : f.data) b = static_cast<std::uint8_t>(next());
    cdam::CanFrame cmd, diag;
    (void)ctl.on_frame(f, &cmd, &diag);
  }
  std::printf("fuzz: %ld iterations, %ld frames, %ld errors, %u cycles, %u rejected\n", iters,
              frames, errors, ctl.cycles(), ctl.rejected());
  return frames > 0 && errors > 0 ? 0 : 3;
}
