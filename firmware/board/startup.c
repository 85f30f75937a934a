/* Vector table and reset handler for the STM32F746 (Cortex-M7).
 *
 * The table is the initial stack pointer, the 15 Cortex-M system exceptions and the F746's 98
 * peripheral interrupts (RM0385 "Nested vectored interrupt controller", vector table; the order
 * is that of IRQn_Type in ST's stm32f746xx.h). Every handler is a weak alias of Default_Handler,
 * so a driver defines e.g. USART3_IRQHandler and the linker puts it in the table. */
#include <stdint.h>
#include <string.h>

#include "led.h"
#include "stm32f7.h"

int main(void);

/* Symbols from stm32f746zg.ld. */
extern uint32_t _estack;
extern uint32_t _sidata, _sdata, _edata, _sbss, _ebss;

void Reset_Handler(void) __attribute__((noreturn));
void Default_Handler(void);

#define WEAK_HANDLER(name) void name(void) __attribute__((weak, alias("Default_Handler")));
#define HANDLER_ENTRY(name) {.handler = name},
#define RESERVED_ENTRY {.handler = 0},

/* Cortex-M7 system exceptions 2..15; R = reserved slot. */
#define SYSTEM_EXCEPTIONS(X, R)                                                                    \
    X(NMI_Handler) X(HardFault_Handler) X(MemManage_Handler) X(BusFault_Handler)                  \
    X(UsageFault_Handler) R R R R X(SVC_Handler) X(DebugMon_Handler) R X(PendSV_Handler)            \
    X(SysTick_Handler)

/* STM32F746 IRQ 0..97 (IRQ 79 is reserved). */
#define PERIPHERAL_IRQS(X, R)                                                                      \
    X(WWDG_IRQHandler) X(PVD_IRQHandler) X(TAMP_STAMP_IRQHandler) X(RTC_WKUP_IRQHandler)          \
    X(FLASH_IRQHandler) X(RCC_IRQHandler) X(EXTI0_IRQHandler) X(EXTI1_IRQHandler)                  \
    X(EXTI2_IRQHandler) X(EXTI3_IRQHandler) X(EXTI4_IRQHandler) X(DMA1_Stream0_IRQHandler)        \
    X(DMA1_Stream1_IRQHandler) X(DMA1_Stream2_IRQHandler) X(DMA1_Stream3_IRQHandler)              \
    X(DMA1_Stream4_IRQHandler) X(DMA1_Stream5_IRQHandler) X(DMA1_Stream6_IRQHandler)              \
    X(ADC_IRQHandler) X(CAN1_TX_IRQHandler) X(CAN1_RX0_IRQHandler) X(CAN1_RX1_IRQHandler)          \
    X(CAN1_SCE_IRQHandler) X(EXTI9_5_IRQHandler) X(TIM1_BRK_TIM9_IRQHandler)                      \
    X(TIM1_UP_TIM10_IRQHandler) X(TIM1_TRG_COM_TIM11_IRQHandler) X(TIM1_CC_IRQHandler)            \
    X(TIM2_IRQHandler) X(TIM3_IRQHandler) X(TIM4_IRQHandler) X(I2C1_EV_IRQHandler)                \
    X(I2C1_ER_IRQHandler) X(I2C2_EV_IRQHandler) X(I2C2_ER_IRQHandler) X(SPI1_IRQHandler)          \
    X(SPI2_IRQHandler) X(USART1_IRQHandler) X(USART2_IRQHandler) X(USART3_IRQHandler)             \
    X(EXTI15_10_IRQHandler) X(RTC_Alarm_IRQHandler) X(OTG_FS_WKUP_IRQHandler)                     \
    X(TIM8_BRK_TIM12_IRQHandler) X(TIM8_UP_TIM13_IRQHandler) X(TIM8_TRG_COM_TIM14_IRQHandler)     \
    X(TIM8_CC_IRQHandler) X(DMA1_Stream7_IRQHandler) X(FMC_IRQHandler) X(SDMMC1_IRQHandler)       \
    X(TIM5_IRQHandler) X(SPI3_IRQHandler) X(UART4_IRQHandler) X(UART5_IRQHandler)                 \
    X(TIM6_DAC_IRQHandler) X(TIM7_IRQHandler) X(DMA2_Stream0_IRQHandler)                          \
    X(DMA2_Stream1_IRQHandler) X(DMA2_Stream2_IRQHandler) X(DMA2_Stream3_IRQHandler)              \
    X(DMA2_Stream4_IRQHandler) X(ETH_IRQHandler) X(ETH_WKUP_IRQHandler) X(CAN2_TX_IRQHandler)     \
    X(CAN2_RX0_IRQHandler) X(CAN2_RX1_IRQHandler) X(CAN2_SCE_IRQHandler) X(OTG_FS_IRQHandler)     \
    X(DMA2_Stream5_IRQHandler) X(DMA2_Stream6_IRQHandler) X(DMA2_Stream7_IRQHandler)              \
    X(USART6_IRQHandler) X(I2C3_EV_IRQHandler) X(I2C3_ER_IRQHandler)                              \
    X(OTG_HS_EP1_OUT_IRQHandler) X(OTG_HS_EP1_IN_IRQHandler) X(OTG_HS_WKUP_IRQHandler)            \
    X(OTG_HS_IRQHandler) X(DCMI_IRQHandler) R X(RNG_IRQHandler) X(FPU_IRQHandler)                 \
    X(UART7_IRQHandler) X(UART8_IRQHandler) X(SPI4_IRQHandler) X(SPI5_IRQHandler)                 \
    X(SPI6_IRQHandler) X(SAI1_IRQHandler) X(LTDC_IRQHandler) X(LTDC_ER_IRQHandler)                \
    X(DMA2D_IRQHandler) X(SAI2_IRQHandler) X(QUADSPI_IRQHandler) X(LPTIM1_IRQHandler)             \
    X(CEC_IRQHandler) X(I2C4_EV_IRQHandler) X(I2C4_ER_IRQHandler) X(SPDIF_RX_IRQHandler)

SYSTEM_EXCEPTIONS(WEAK_HANDLER, )
PERIPHERAL_IRQS(WEAK_HANDLER, )

typedef union vector_entry {
    const uint32_t *stack_top;
    void (*handler)(void);
} vector_entry;

#define SYSTEM_VECTORS 16u
#define PERIPHERAL_VECTORS 98u

__attribute__((section(".isr_vector"), used)) const vector_entry vector_table[] = {
    {.stack_top = &_estack},
    {.handler = Reset_Handler},
    SYSTEM_EXCEPTIONS(HANDLER_ENTRY, RESERVED_ENTRY)
    PERIPHERAL_IRQS(HANDLER_ENTRY, RESERVED_ENTRY)
};
_Static_assert(sizeof vector_table / sizeof vector_table[0] == SYSTEM_VECTORS + PERIPHERAL_VECTORS,
               "vector table must hold SP + 15 exceptions + 98 IRQs");

void Reset_Handler(void)
{
    /* FPU first: the code below and everything after may use VFP registers (CP10/CP11 full
     * access, ARMv7-M ARM B3.2.20); the barriers make the new access rights take effect. */
    SCB_CPACR |= SCB_CPACR_CP10_CP11_FULL;
    dsb();
    isb();

    /* Initialised data from flash to RAM, then the zeroed data. */
    memcpy(&_sdata, &_sidata, (size_t)((uintptr_t)&_edata - (uintptr_t)&_sdata));
    memset(&_sbss, 0, (size_t)((uintptr_t)&_ebss - (uintptr_t)&_sbss));

    (void)main();
    for (;;) {
        /* main never returns; if it does, let the watchdog reset the board. */
    }
}

/* Any unexpected exception or interrupt, HardFault included: red LED on, then wait for the
 * independent watchdog (started by main) to reset the board. The only unbounded wait. */
void Default_Handler(void)
{
    led_fault_on();
    for (;;) {
    }
}
