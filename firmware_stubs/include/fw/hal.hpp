// Board layer for the STM32F405 (QEMU netduinoplus2 or a real board): SysTick, USART1 for SLCAN,
// no-op GPIO. Register addresses from the STM32F405 reference manual (RM0090).
#pragma once
#include <cstdint>

namespace fw::hal {

// SysTick free-running over the core clock (no interrupt): the counter counts down from
// 0xFFFFFF. With QEMU -icount the core clock is virtual time, so ticks measure instructions.
void systick_free_running();
// SysTick interrupt every `ticks` core clocks (168000 for 1 kHz at 168 MHz); millis() counts them.
void systick_periodic(std::uint32_t ticks);
std::uint32_t systick_value();
std::uint32_t millis();

// USART1 (PA9 TX, PA10 RX, AF7), 8N1. Receive: the RXNE interrupt fills a 128-byte ring;
// transmit is polled.
void usart1_init(std::uint32_t baud);
bool usart1_getc(char* c);  // false when no byte is waiting
// Sleeps (WFI) until an interrupt when no byte is waiting. Under QEMU this matters: a core
// busy-polling the USART keeps the I/O thread from delivering the next byte (about 1 ms a byte).
void usart1_wait();
std::uint32_t usart1_overruns();  // bytes dropped because the ring was full
void usart1_putc(char c);
void usart1_write(const char* s, unsigned n);

// Status LED: a no-op stub (the netduinoplus2 has none that QEMU shows).
inline void led(bool) {}

}  // namespace fw::hal
