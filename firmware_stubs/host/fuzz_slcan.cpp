// Random-byte fuzzing of the frame parsers and the controller (built with
// -fsanitize=address,undefined,float-cast-overflow): random byte streams, random mutations of
// valid SLCAN lines, SLCAN reference lines (0x300) carrying NaN, Inf, huge and ordinary floats,
// and random CAN frames go through the SLCAN LineReader / parse_line, the C610 decoders and the
// controller (frames -> parser -> controller -> command). Every parse gets its own
// exactly-sized heap copy of the line so ASan catches any read past it; a NaN or out-of-range
// float converted to an integer aborts under UBSan. After every frame the controller's
// invariants are checked: references finite and within +-kJointRangeRad, PID integrals and
// features finite, every command within the C610's +-10000 counts, the status frame well
// formed. Deterministic (fixed seed); argv[1] = iterations.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
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

// A float32 worth sending as a joint reference: special values, the range edge, huge values,
// ordinary angles and raw random bits, in about equal shares.
float reference_value() {
  const float inf = std::numeric_limits<float>::infinity();
  const float specials[] = {std::numeric_limits<float>::quiet_NaN(), -std::numeric_limits<float>::quiet_NaN(),
                            inf, -inf, 256.0f, -256.0f, 256.00003f, 1e30f, -3.4e38f,
                            std::numeric_limits<float>::denorm_min(), 0.0f, -0.0f};
  switch (next() % 4) {
    case 0: return specials[next() % (sizeof specials / sizeof specials[0])];
    case 1: return (static_cast<float>(next() % 20001) - 10000.0f) * 0.001f;  // +-10 rad
    case 2: return (static_cast<float>(next() % 2001) - 1000.0f);             // +-1000 rad
    default: {
      const std::uint32_t bits = next();
      float v;
      std::memcpy(&v, &bits, 4);
      return v;
    }
  }
}

// The SLCAN line "t3008<16 hex digits>" of a reference frame (no terminator); returns length.
std::size_t reference_line(char* out) {
  static const char hex[] = "0123456789ABCDEF";
  const float r[2] = {reference_value(), reference_value()};
  std::uint8_t b[8];
  std::memcpy(b, r, 8);
  std::size_t n = 0;
  for (const char c : {'t', '3', '0', '0', '8'}) out[n++] = c;
  for (std::uint8_t v : b) {
    out[n++] = hex[v >> 4];
    out[n++] = hex[v & 15];
  }
  return n;
}

int g_violations = 0;

void violation(const char* what) {
  if (g_violations++ < 10) std::printf("invariant violated: %s\n", what);
}

// Feeds one frame to the controller and checks its invariants.
void drive(fw::Controller& ctl, const cdam::CanFrame& f) {
  cdam::CanFrame cmd, diag, st;
  if (ctl.on_frame(f, &cmd, &diag)) {
    std::int16_t cur[4];
    if (cdam::c610::decode_command(cmd, cur) != cdam::c610::Decode::Ok) violation("command frame");
    for (int k = 0; k < 4; ++k)
      if (cur[k] > cdam::c610::kCurrentLimit || cur[k] < -cdam::c610::kCurrentLimit)
        violation("current beyond the C610 range");
    if (diag.id != fw::kDiagnosticId || diag.dlc != 8) violation("diagnostic frame");
    for (int k = 0; k < 6; ++k)
      if (!std::isfinite(ctl.features()[k])) violation("feature not finite");
  }
  for (int j = 0; j < 2; ++j) {
    if (!fw::joint_angle_ok(ctl.references()[j])) violation("reference not finite or in range");
    if (!std::isfinite(ctl.integral(j))) violation("PID integral not finite");
  }
  if (ctl.take_status(&st) && (st.id != fw::kStatusId || st.dlc != 8 || st.extended || st.remote))
    violation("status frame");
}
}  // namespace

int main(int argc, char** argv) {
  const long iters = argc > 1 ? std::atol(argv[1]) : 100000;
  static const char* seeds[] = {"t20180102030405060708", "T1ABCDEF02abCD", "r7FF3", "S8", "O",
                                "s031C", "t2008000000000000000", "t3008000000000000000",
                                "t30080000C07F0000C07F", "t30080000807F000080FF",
                                "t3008FFFFFFFF00000000", "t300800008043DB0F4940", "r3F10"};
  static const char alphabet[] = "tTrRSsOCLVNFZ0123456789ABCDEFabcdefxyz\r\n\a ";
  cdam::slcan::LineReader reader;
  fw::Controller ctl;
  long frames = 0, errors = 0;
  for (long it = 0; it < iters; ++it) {
    const std::size_t n = next() % 40;
    std::size_t n_line = n;  // bytes parsed as one line
    std::unique_ptr<char[]> buf(new char[n ? n : 1]);
    const int mode = static_cast<int>(next() % 4);
    if (mode == 3 && n >= 21) {  // a reference line, possibly with bytes of noise after it
      n_line = reference_line(buf.get());
      for (std::size_t k = n_line; k < n; ++k) buf[k] = k == n_line ? '\r' : alphabet[next() % 16];
    } else if (mode == 0 || mode == 3) {
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
        drive(ctl, e.frame);
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
    const std::uint32_t kind = next() % 4;
    if (kind == 0) {  // a reference frame with chosen floats
      f.id = fw::kReferenceId;
      f.dlc = next() % 8 ? 8 : static_cast<std::uint8_t>(next() % 9);
      const float r[2] = {reference_value(), reference_value()};
      std::memcpy(f.data, r, 8);
    } else if (kind == 1) {  // a feedback frame of motor 1 or 2, fields in or near range
      cdam::c610::Feedback fb;
      fb.motor = static_cast<std::uint8_t>(1 + next() % 2);
      fb.angle = static_cast<std::uint16_t>(next() % 8200);
      fb.speed_rpm = static_cast<std::int16_t>(static_cast<int>(next() % 40101) - 20050);
      fb.current = static_cast<std::int16_t>(static_cast<int>(next() % 20101) - 10050);
      f = cdam::c610::encode_feedback(fb);
    }
    drive(ctl, f);
  }
  const fw::InputCounts& c = ctl.input_counts();
  std::printf("fuzz: %ld iterations, %ld frames, %ld errors, %u cycles, %u rejected "
              "(references: %u non-finite, %u out of range; measurements %u; frames %u)\n",
              iters, frames, errors, ctl.cycles(), ctl.rejected(), c.ref_nonfinite, c.ref_range,
              c.meas_range, c.frames);
  if (g_violations) return 4;
  // the campaign must have reached what it is meant to test
  return frames > 0 && errors > 0 && ctl.cycles() > 100 && c.ref_nonfinite > 0 &&
                 c.ref_range > 0 && c.meas_range > 0
             ? 0
             : 3;
}
