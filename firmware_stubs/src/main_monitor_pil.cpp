// The residual monitor in the loop over SLCAN on USART1 (fw/slcan_port.hpp): measurement rows
// in, the model beside them, alarm frames (0x3F2) and one ack (0x3F3) per row out
// (fw/monitor_pil.hpp). Built when the model file has a monitor section.
#include "fw/hal.hpp"
#include "fw/monitor_pil.hpp"
#include "fw/slcan_port.hpp"

namespace {

fw::MonitorLoop g_loop;

}  // namespace

int main() {
  fw::hal::usart1_init(115200);
  fw::slcan_port::serve([](const cdam::CanFrame& f) {
    cdam::CanFrame out[fw::kY + 1];
    const int n = g_loop.on_frame(f, out);
    for (int k = 0; k < n; ++k) fw::slcan_port::send(out[k]);
  });
}
