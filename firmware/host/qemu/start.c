/* Start-up for running the core's C unit tests on an emulated Cortex-M7 (QEMU's mps2-an500).
 *
 * The NUCLEO's STM32F746 has no QEMU model, but its core has: this runs host/test_core.c,
 * compiled by the same arm-none-eabi-gcc with the same CPU and FPU flags as the firmware, on
 * the Cortex-M7 instruction set, with 32-bit size_t and unsigned char. Output and the exit
 * status go through semihosting (newlib's rdimon). */
#include <stdint.h>

extern void _start(void); /* newlib's crt0: .bss, semihosting handles, main, exit */
extern uint32_t __stack_top;

#define SCB_CPACR (*(volatile uint32_t *)0xE000ED88u)
#define CPACR_CP10_CP11_FULL (0xFu << 20)

void Reset_Handler(void)
{
    SCB_CPACR |= CPACR_CP10_CP11_FULL; /* the FPU, before any floating-point instruction */
    __asm volatile("dsb\n\tisb");
    _start();
    for (;;) {
    }
}

void Fault_Handler(void)
{
    for (;;) { /* QEMU's timeout ends the run; the test reports no result */
    }
}

typedef union vector {
    const uint32_t *stack_top;
    void (*handler)(void);
} vector;

__attribute__((section(".vectors"), used)) const vector vectors[8] = {
    {.stack_top = &__stack_top}, {.handler = Reset_Handler}, {.handler = Fault_Handler},
    {.handler = Fault_Handler},  {.handler = Fault_Handler}, {.handler = Fault_Handler},
    {.handler = Fault_Handler},
};
