// The 1 kHz loop image: SLCAN on USART1 (fw/slcan_port.hpp), C610 feedback in, 0x200 current
// command out (fw/controller.hpp).
#include "fw/controller.hpp"
#include "fw/hal.hpp"
#include "fw/slcan_port.hpp"

namespace {

fw::Controller g_ctl;

}  // namespace

int main() {
  fw::hal::usart1_init(115200);
  fw::hal::systick_periodic(168000);  // 1 ms at 168 MHz
  fw::slcan_port::serve([](const cdam::CanFrame& f) {
    cdam::CanFrame cmd, diag, status;
    if (g_ctl.on_frame(f, &cmd, &diag)) {
      fw::slcan_port::send(cmd);
      fw::slcan_port::send(diag);
    }
    if (g_ctl.take_status(&status)) fw::slcan_port::send(status);  // 0x3F1: a rejected input
  });
}
