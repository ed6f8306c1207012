// Reset and vector table for the STM32F405 (Cortex-M4F). QEMU takes SP and PC from the table at
// address 0 (flash is aliased there), so the table is mandatory. Reset: enable the FPU before any
// float instruction, copy .data, zero .bss, paint the stack (for the high-water mark), run the
// static constructors, call main.
#include <cstdint>

extern "C" {
extern std::uint32_t _estack, _sidata, _sdata, _edata, _sbss, _ebss;
extern void (*__init_array_start[])();
extern void (*__init_array_end[])();
int main();
void Reset_Handler();
void Default_Handler();
void HardFault_Handler();
void SysTick_Handler() __attribute__((weak, alias("Default_Handler")));
void USART1_IRQHandler() __attribute__((weak, alias("Default_Handler")));
void fw_on_exit(int code) __attribute__((weak));
}

namespace {
constexpr std::uint32_t kStackPaint = 0xC0FFEE11u;
constexpr std::uint32_t kPaintBytes = 8192;  // painted below the initial stack pointer
}

// 16 system exceptions and the STM32F405's device interrupts up to USART1 (IRQ 37), which the
// SLCAN receive path uses; the others stay unused (null: never enabled).
constexpr int kUsart1Irq = 37;
__attribute__((section(".isr_vector"), used)) void (*const g_vectors[16 + kUsart1Irq + 1])() = {
    reinterpret_cast<void (*)()>(&_estack),
    Reset_Handler,
    Default_Handler,    // NMI
    HardFault_Handler,  // HardFault
    HardFault_Handler,  // MemManage
    HardFault_Handler,  // BusFault
    HardFault_Handler,  // UsageFault
    nullptr, nullptr, nullptr, nullptr,
    Default_Handler,    // SVCall
    Default_Handler,    // DebugMon
    nullptr,
    Default_Handler,    // PendSV
    SysTick_Handler,
    // IRQ 0 .. 36 unused, IRQ 37 USART1
    nullptr, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr,
    nullptr, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr,
    nullptr, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr,
    nullptr, nullptr, nullptr, nullptr, nullptr, nullptr, nullptr,
    USART1_IRQHandler,
};

extern "C" std::uint32_t fw_stack_high_water() {
  const std::uint32_t* top = &_estack;
  const std::uint32_t* p = top - kPaintBytes / 4;
  while (p < top && *p == kStackPaint) ++p;
  return static_cast<std::uint32_t>(reinterpret_cast<std::uintptr_t>(top) -
                                    reinterpret_cast<std::uintptr_t>(p));
}

extern "C" void Reset_Handler() {
  // CPACR: full access to CP10 and CP11 (the FPU).
  *reinterpret_cast<volatile std::uint32_t*>(0xE000ED88u) |= 0xFu << 20;
  __asm__ volatile("dsb\n isb" ::: "memory");
  for (std::uint32_t *src = &_sidata, *dst = &_sdata; dst < &_edata;) *dst++ = *src++;
  for (std::uint32_t* dst = &_sbss; dst < &_ebss;) *dst++ = 0;
  {
    std::uint32_t* p = &_estack - kPaintBytes / 4;
    std::uint32_t* sp;
    __asm__ volatile("mov %0, sp" : "=r"(sp));
    while (p < sp - 16) *p++ = kStackPaint;
  }
  for (auto f = __init_array_start; f < __init_array_end; ++f) (*f)();
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpedantic"  // calling main from the reset handler
  const int rc = main();
#pragma GCC diagnostic pop
  if (fw_on_exit) fw_on_exit(rc);
  for (;;) __asm__ volatile("wfi");
}

extern "C" void Default_Handler() {
  for (;;) __asm__ volatile("wfi");
}

// A fault ends a semihosted run with status 99 (check images define fw_on_exit); on a real
// board it parks the core.
extern "C" void HardFault_Handler() {
  if (fw_on_exit) fw_on_exit(99);
  for (;;) __asm__ volatile("wfi");
}
