// SLCAN (Lawicel serial-line CAN) line parser and encoder, heap-free and bounds-checked: the
// firmware's CAN over USART1 and python-can's `slcan` interface speak it.
//
// Lines end with '\r' (a '\n' is accepted as a terminator too). Understood:
//   tIIILDD..      standard data frame (III hex id <= 0x7FF, L = dlc 0..8, 2 L hex digits)
//   TIIIIIIIILDD.. extended data frame (id <= 0x1FFFFFFF)
//   rIIIL / RIIIIIIIIL remote frames
//   O (open), L (listen only), C (close), Sn (bitrate code 0..8), sXXYY (BTR), V / v (version),
//   N (serial number), F (status flags), Z0/Z1 (timestamps), empty line (no-op)
// Anything else, or a malformed frame, is an Error; the answer to a command is "\r" on success
// and "\a" (BELL) on error, as python-can expects.
#pragma once
#include <cstddef>
#include <cstdint>

#include "c610.hpp"

namespace cdam {
namespace slcan {

constexpr std::size_t kMaxLine = 32;  // 'T' + 8 id + 1 dlc + 16 data + '\r' = 27

enum class Kind : std::uint8_t {
  Frame = 0, Open, ListenOnly, Close, Bitrate, BitTiming, Version, Serial, Status, Timestamp,
  Empty, Error
};

struct Event {
  Kind kind = Kind::Error;
  int arg = 0;        // bitrate code for Bitrate, 0/1 for Timestamp
  CanFrame frame;     // for Frame
};

inline int hex_value(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return -1;
}

// n hex digits at s (the caller guarantees n characters exist); false on a non-hex digit.
inline bool parse_hex(const char* s, std::size_t n, std::uint32_t* out) {
  std::uint32_t v = 0;
  for (std::size_t k = 0; k < n; ++k) {
    const int d = hex_value(s[k]);
    if (d < 0) return false;
    v = (v << 4) | static_cast<std::uint32_t>(d);
  }
  *out = v;
  return true;
}

// One line without its terminator: s[0..n). Never reads outside it.
inline Event parse_line(const char* s, std::size_t n) {
  Event ev;
  if (n == 0) {
    ev.kind = Kind::Empty;
    return ev;
  }
  const char c = s[0];
  if (c == 't' || c == 'T' || c == 'r' || c == 'R') {
    const bool ext = (c == 'T' || c == 'R');
    const bool remote = (c == 'r' || c == 'R');
    const std::size_t id_len = ext ? 8 : 3;
    if (n < 1 + id_len + 1) return ev;
    std::uint32_t id = 0, dlc = 0;
    if (!parse_hex(s + 1, id_len, &id)) return ev;
    if (id > (ext ? 0x1FFFFFFFu : 0x7FFu)) return ev;
    const char dc = s[1 + id_len];
    if (dc < '0' || dc > '8') return ev;
    dlc = static_cast<std::uint32_t>(dc - '0');
    const std::size_t data_len = remote ? 0 : 2 * dlc;
    if (n != 1 + id_len + 1 + data_len) return ev;
    CanFrame f;
    f.id = id;
    f.dlc = static_cast<std::uint8_t>(dlc);
    f.extended = ext;
    f.remote = remote;
    for (std::uint32_t k = 0; k < dlc && !remote; ++k) {
      std::uint32_t b = 0;
      if (!parse_hex(s + 2 + id_len + 2 * k, 2, &b)) return ev;
      f.data[k] = static_cast<std::uint8_t>(b);
    }
    ev.kind = Kind::Frame;
    ev.frame = f;
    return ev;
  }
  switch (c) {
    case 'O': if (n == 1) ev.kind = Kind::Open; break;
    case 'L': if (n == 1) ev.kind = Kind::ListenOnly; break;
    case 'C': if (n == 1) ev.kind = Kind::Close; break;
    case 'V': case 'v': if (n == 1) ev.kind = Kind::Version; break;
    case 'N': if (n == 1) ev.kind = Kind::Serial; break;
    case 'F': if (n == 1) ev.kind = Kind::Status; break;
    case 'S':
      if (n == 2 && s[1] >= '0' && s[1] <= '8') {
        ev.kind = Kind::Bitrate;
        ev.arg = s[1] - '0';
      }
      break;
    case 's': {
      std::uint32_t btr = 0;
      if (n == 5 && parse_hex(s + 1, 4, &btr)) {
        ev.kind = Kind::BitTiming;
        ev.arg = static_cast<int>(btr);
      }
      break;
    }
    case 'Z':
      if (n == 2 && (s[1] == '0' || s[1] == '1')) {
        ev.kind = Kind::Timestamp;
        ev.arg = s[1] - '0';
      }
      break;
    default: break;
  }
  return ev;
}

// Writes the SLCAN line of f (with its '\r') into out; returns its length, or 0 if cap is too
// small or the frame is invalid (dlc > 8, id out of range).
inline std::size_t encode(const CanFrame& f, char* out, std::size_t cap) {
  static const char kHex[] = "0123456789ABCDEF";
  if (f.dlc > 8 || f.id > (f.extended ? 0x1FFFFFFFu : 0x7FFu)) return 0;
  const std::size_t id_len = f.extended ? 8 : 3;
  const std::size_t len = 1 + id_len + 1 + (f.remote ? 0 : 2u * f.dlc) + 1;
  if (cap < len) return 0;
  std::size_t k = 0;
  out[k++] = f.remote ? (f.extended ? 'R' : 'r') : (f.extended ? 'T' : 't');
  for (std::size_t d = id_len; d-- > 0;) out[k++] = kHex[(f.id >> (4 * d)) & 0xF];
  out[k++] = static_cast<char>('0' + f.dlc);
  if (!f.remote)
    for (std::size_t b = 0; b < f.dlc; ++b) {
      out[k++] = kHex[f.data[b] >> 4];
      out[k++] = kHex[f.data[b] & 0xF];
    }
  out[k++] = '\r';
  return k;
}

// Byte-at-a-time line assembler: push() returns true when a complete line was parsed into *ev.
// A line longer than kMaxLine is dropped whole and reported as one Error at its terminator.
class LineReader {
 public:
  bool push(char c, Event* ev) {
    if (c == '\r' || c == '\n') {
      if (c == '\n' && len_ == 0 && !overflow_) return false;  // "\r\n": ignore the '\n'
      if (overflow_) {
        *ev = Event{};
      } else {
        *ev = parse_line(buf_, len_);
      }
      len_ = 0;
      overflow_ = false;
      return true;
    }
    if (len_ >= kMaxLine) {
      overflow_ = true;
      return false;
    }
    buf_[len_++] = c;
    return false;
  }
  std::size_t pending() const { return len_; }

 private:
  char buf_[kMaxLine] = {};
  std::size_t len_ = 0;
  bool overflow_ = false;
};

}  // namespace slcan
}  // namespace cdam
