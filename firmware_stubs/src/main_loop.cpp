// The 1 kHz loop image: SLCAN on USART1 (python-can's `slcan` interface, or a USB-serial SLCAN
// adapter on a real board), C610 feedback in, 0x200 current command out (fw/controller.hpp).
// Commands are answered with '\r' (error: '\a'), as the Lawicel protocol and python-can expect.
#include "cdam/slcan.hpp"
#include "fw/controller.hpp"
#include "fw/hal.hpp"

namespace {

fw::Controller g_ctl;
cdam::slcan::LineReader g_reader;
bool g_open = false;

void send(const cdam::CanFrame& f) {
  char line[cdam::slcan::kMaxLine];
  const std::size_t n = cdam::slcan::encode(f, line, sizeof line);
  fw::hal::usart1_write(line, static_cast<unsigned>(n));
}

void handle(const cdam::slcan::Event& ev) {
  using cdam::slcan::Kind;
  switch (ev.kind) {
    case Kind::Frame: {
      if (!g_open) return;
      cdam::CanFrame cmd, diag, status;
      if (g_ctl.on_frame(ev.frame, &cmd, &diag)) {
        send(cmd);
        send(diag);
      }
      if (g_ctl.take_status(&status)) send(status);  // 0x3F1: a rejected input, or requested
      return;
    }
    case Kind::Open: case Kind::ListenOnly: g_open = true; break;
    case Kind::Close: g_open = false; break;
    case Kind::Version: fw::hal::usart1_write("V1013", 5); break;
    case Kind::Serial: fw::hal::usart1_write("NCDAM", 5); break;
    case Kind::Status: fw::hal::usart1_write("F00", 3); break;
    case Kind::Error: fw::hal::usart1_putc('\a'); return;
    default: break;
  }
  fw::hal::usart1_putc('\r');
}

}  // namespace

int main() {
  fw::hal::usart1_init(115200);
  fw::hal::systick_periodic(168000);  // 1 ms at 168 MHz
  for (;;) {
    char c;
    cdam::slcan::Event ev;
    if (!fw::hal::usart1_getc(&c)) {
      fw::hal::usart1_wait();
      continue;
    }
    if (g_reader.push(c, &ev)) handle(ev);
  }
}
