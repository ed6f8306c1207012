// STM32F405 board layer (RM0090 register map). QEMU's netduinoplus2 implements SysTick and the
// USART (stm32f2xx_usart); RCC and GPIO writes are harmless there and needed on a real board.
#include "fw/hal.hpp"

namespace fw::hal {
namespace {

inline volatile std::uint32_t& reg(std::uint32_t addr) {
  return *reinterpret_cast<volatile std::uint32_t*>(addr);
}

constexpr std::uint32_t kSysTickCsr = 0xE000E010u, kSysTickRvr = 0xE000E014u,
                        kSysTickCvr = 0xE000E018u;
constexpr std::uint32_t kRccAhb1Enr = 0x40023830u, kRccApb2Enr = 0x40023844u;
constexpr std::uint32_t kGpioA = 0x40020000u;  // MODER +0x00, AFRH +0x24
constexpr std::uint32_t kUsart1 = 0x40011000u;  // SR +0x00, DR +0x04, BRR +0x08, CR1 +0x0C
constexpr std::uint32_t kSrRxne = 1u << 5, kSrTxe = 1u << 7;
constexpr std::uint32_t kCr1Ue = 1u << 13, kCr1Te = 1u << 3, kCr1Re = 1u << 2,
                        kCr1Rxneie = 1u << 5;
constexpr std::uint32_t kNvicIser1 = 0xE000E104u;  // IRQ 32..63; USART1 is IRQ 37
constexpr std::uint32_t kApb2Hz = 84000000u;  // PCLK2 at 168 MHz SYSCLK

volatile std::uint32_t g_millis = 0;

// Receive ring filled by USART1_IRQHandler, emptied by usart1_getc (single producer, single
// consumer; indices wrap mod 2^32, the size is a power of two). 128 bytes; an image that takes
// more bytes at once (fw_monitor_pil: rows in flight) compiles this file with its own size.
#ifndef CDAM_FW_UART_RING
#define CDAM_FW_UART_RING 128
#endif
constexpr std::uint32_t kRing = CDAM_FW_UART_RING;
static_assert((kRing & (kRing - 1)) == 0, "the ring size is a power of two");
volatile char g_ring[kRing];
volatile std::uint32_t g_head = 0, g_tail = 0, g_overruns = 0;

}  // namespace

void systick_free_running() {
  reg(kSysTickCsr) = 0;
  reg(kSysTickRvr) = 0x00FFFFFFu;
  reg(kSysTickCvr) = 0;
  reg(kSysTickCsr) = 0x5u;  // enable, core clock, no interrupt
}

void systick_periodic(std::uint32_t ticks) {
  reg(kSysTickCsr) = 0;
  reg(kSysTickRvr) = ticks - 1u;
  reg(kSysTickCvr) = 0;
  reg(kSysTickCsr) = 0x7u;  // enable, interrupt, core clock
}

std::uint32_t systick_value() { return reg(kSysTickCvr) & 0x00FFFFFFu; }
std::uint32_t millis() { return g_millis; }

void usart1_init(std::uint32_t baud) {
  reg(kRccAhb1Enr) |= 1u << 0;  // GPIOA clock
  reg(kRccApb2Enr) |= 1u << 4;  // USART1 clock
  // PA9, PA10: alternate function 7
  reg(kGpioA + 0x00) = (reg(kGpioA + 0x00) & ~(0xFu << 18)) | (0xAu << 18);
  reg(kGpioA + 0x24) = (reg(kGpioA + 0x24) & ~(0xFFu << 4)) | (0x77u << 4);
  reg(kUsart1 + 0x08) = (kApb2Hz + baud / 2) / baud;
  reg(kUsart1 + 0x0C) = kCr1Ue | kCr1Te | kCr1Re | kCr1Rxneie;
  reg(kNvicIser1) = 1u << (37 - 32);
}

bool usart1_getc(char* c) {
  const std::uint32_t tail = g_tail;
  if (tail == g_head) return false;
  *c = g_ring[tail % kRing];
  g_tail = tail + 1;
  return true;
}

void usart1_wait() {
  // Interrupts masked between the test and WFI, so a byte arriving in between still wakes the
  // core (a pending interrupt ends WFI even when masked); the handler runs after cpsie.
  __asm__ volatile("cpsid i" ::: "memory");
  if (g_tail == g_head) __asm__ volatile("dsb\n wfi" ::: "memory");
  __asm__ volatile("cpsie i" ::: "memory");
}

std::uint32_t usart1_overruns() { return g_overruns; }

void usart1_putc(char c) {
  while (!(reg(kUsart1 + 0x00) & kSrTxe)) {
  }
  reg(kUsart1 + 0x04) = static_cast<std::uint8_t>(c);
}

void usart1_write(const char* s, unsigned n) {
  for (unsigned k = 0; k < n; ++k) usart1_putc(s[k]);
}

}  // namespace fw::hal

extern "C" void SysTick_Handler() { fw::hal::g_millis = fw::hal::g_millis + 1; }

extern "C" void USART1_IRQHandler() {
  using namespace fw::hal;
  while (reg(kUsart1 + 0x00) & kSrRxne) {
    const char c = static_cast<char>(reg(kUsart1 + 0x04) & 0xFFu);  // reading DR clears RXNE
    const std::uint32_t head = g_head;
    if (head - g_tail < kRing) {
      g_ring[head % kRing] = c;
      g_head = head + 1;
    } else {
      g_overruns = g_overruns + 1;
    }
  }
}
