// The SLCAN side of an image on USART1 (python-can's `slcan` interface, or a USB-serial SLCAN
// adapter on a real board): bytes through cdam::slcan::LineReader; while the channel is open
// each frame goes to the image's handler; the commands are answered with '\r' (error: '\a'),
// as the Lawicel protocol and python-can expect. Used by fw_loop and fw_monitor_pil.
#pragma once
#include "cdam/slcan.hpp"
#include "fw/hal.hpp"

namespace fw::slcan_port {

inline void send(const cdam::CanFrame& f) {
  char line[cdam::slcan::kMaxLine];
  const std::size_t n = cdam::slcan::encode(f, line, sizeof line);
  fw::hal::usart1_write(line, static_cast<unsigned>(n));
}

// Never returns: reads USART1 (sleeping while no byte waits) and calls on_frame(frame) for
// each frame received while the channel is open.
template <typename OnFrame>
[[noreturn]] void serve(OnFrame on_frame) {
  using cdam::slcan::Kind;
  cdam::slcan::LineReader reader;
  bool open = false;
  for (;;) {
    char c;
    cdam::slcan::Event ev;
    if (!fw::hal::usart1_getc(&c)) {
      fw::hal::usart1_wait();
      continue;
    }
    if (!reader.push(c, &ev)) continue;
    switch (ev.kind) {
      case Kind::Frame:
        if (open) on_frame(ev.frame);
        continue;
      case Kind::Open: case Kind::ListenOnly: open = true; break;
      case Kind::Close: open = false; break;
      case Kind::Version: fw::hal::usart1_write("V1013", 5); break;
      case Kind::Serial: fw::hal::usart1_write("NCDAM", 5); break;
      case Kind::Status: fw::hal::usart1_write("F00", 3); break;
      case Kind::Error: fw::hal::usart1_putc('\a'); continue;
      default: break;
    }
    fw::hal::usart1_putc('\r');
  }
}

}  // namespace fw::slcan_port
