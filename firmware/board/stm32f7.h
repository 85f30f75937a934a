/* Minimal STM32F746 register definitions: only what the board layer uses.
 *
 * Addresses and bit positions come from ST's reference manual RM0385 (chapters named below) and
 * were checked against STMicroelectronics/cmsis_device_f7 Include/stm32f746xx.h and ARM's
 * CMSIS_5 core_cm7.h. The names are our own; the offsets are asserted at compile time. */
#ifndef BOARD_STM32F7_H
#define BOARD_STM32F7_H

#include <stddef.h>
#include <stdint.h>

#define REG32(addr) (*(volatile uint32_t *)(uintptr_t)(addr))

/* ---- memory map (RM0385 "Memory map") */
#define PERIPH_BASE 0x40000000u
#define APB1_BASE PERIPH_BASE
#define AHB1_BASE (PERIPH_BASE + 0x00020000u)
#define UNIQUE_ID_BASE 0x1FF0F420u /* 96-bit unique device ID (RM0385 "Device electronic signature") */
#define UNIQUE_ID_BYTES 12u

/* ---- RCC (RM0385 "Reset and clock control", RCC registers) */
typedef struct {
    volatile uint32_t CR, PLLCFGR, CFGR, CIR, AHB1RSTR, AHB2RSTR, AHB3RSTR;
    uint32_t reserved0;
    volatile uint32_t APB1RSTR, APB2RSTR;
    uint32_t reserved1[2];
    volatile uint32_t AHB1ENR, AHB2ENR, AHB3ENR;
    uint32_t reserved2;
    volatile uint32_t APB1ENR, APB2ENR;
    uint32_t reserved3[2];
    volatile uint32_t AHB1LPENR, AHB2LPENR, AHB3LPENR;
    uint32_t reserved4;
    volatile uint32_t APB1LPENR, APB2LPENR;
    uint32_t reserved5[2];
    volatile uint32_t BDCR, CSR;
    uint32_t reserved6[2];
    volatile uint32_t SSCGR, PLLI2SCFGR, PLLSAICFGR, DCKCFGR1, DCKCFGR2;
} rcc_regs;
_Static_assert(offsetof(rcc_regs, APB1ENR) == 0x40, "RCC_APB1ENR offset");
_Static_assert(offsetof(rcc_regs, DCKCFGR2) == 0x90, "RCC_DCKCFGR2 offset");
#define RCC ((rcc_regs *)(AHB1_BASE + 0x3800u))

/* RCC_CSR reset flags (RM0385 5.3.21); RMVF clears them. */
#define RCC_CSR_RMVF (1u << 24)
#define RCC_CSR_BORRSTF (1u << 25)
#define RCC_CSR_PINRSTF (1u << 26)
#define RCC_CSR_PORRSTF (1u << 27)
#define RCC_CSR_SFTRSTF (1u << 28)
#define RCC_CSR_IWDGRSTF (1u << 29)
#define RCC_CSR_WWDGRSTF (1u << 30)
#define RCC_CSR_LPWRRSTF (1u << 31)

#define RCC_CR_HSION (1u << 0)
#define RCC_CR_HSIRDY (1u << 1)
#define RCC_CR_HSEON (1u << 16)
#define RCC_CR_HSERDY (1u << 17)
#define RCC_CR_HSEBYP (1u << 18)
#define RCC_CR_PLLON (1u << 24)
#define RCC_CR_PLLRDY (1u << 25)
#define RCC_PLLCFGR_PLLM_POS 0u /* 6 bits */
#define RCC_PLLCFGR_PLLN_POS 6u /* 9 bits */
#define RCC_PLLCFGR_PLLP_POS 16u /* 2 bits: 0 = /2, 1 = /4, 2 = /6, 3 = /8 */
#define RCC_PLLCFGR_PLLSRC_HSE (1u << 22)
#define RCC_PLLCFGR_PLLQ_POS 24u /* 4 bits */
#define RCC_PLLCFGR_FIELDS 0x0F437FFFu /* M, N, P, SRC, Q: bit 29 is reserved, kept */
#define RCC_CFGR_SW_MASK 0x3u
#define RCC_CFGR_SW_PLL 0x2u
#define RCC_CFGR_SWS_MASK (0x3u << 2)
#define RCC_CFGR_SWS_PLL (0x2u << 2)
#define RCC_CFGR_HPRE_MASK (0xFu << 4)  /* 0 = AHB /1 */
#define RCC_CFGR_PPRE1_MASK (0x7u << 10)
#define RCC_CFGR_PPRE1_DIV4 (0x5u << 10)
#define RCC_CFGR_PPRE2_MASK (0x7u << 13)
#define RCC_CFGR_PPRE2_DIV2 (0x4u << 13)
#define RCC_AHB1ENR_GPIOBEN (1u << 1)
#define RCC_AHB1ENR_GPIODEN (1u << 3)
#define RCC_AHB1ENR_GPIOFEN (1u << 5)
#define RCC_APB1_USART3 (1u << 18) /* same bit in APB1ENR and APB1RSTR */
#define RCC_APB1_I2C1 (1u << 21)
#define RCC_APB1ENR_PWREN (1u << 28)
#define RCC_DCKCFGR2_USART3SEL_MASK (0x3u << 4)
#define RCC_DCKCFGR2_USART3SEL_SYSCLK (0x1u << 4)
#define RCC_DCKCFGR2_I2C1SEL_MASK (0x3u << 16)
#define RCC_DCKCFGR2_I2C1SEL_HSI (0x2u << 16)

/* ---- PWR (RM0385 "Power controller", PWR registers) */
typedef struct {
    volatile uint32_t CR1, CSR1, CR2, CSR2;
} pwr_regs;
#define PWR ((pwr_regs *)(APB1_BASE + 0x7000u))
#define PWR_CR1_VOS_MASK (0x3u << 14)
#define PWR_CR1_VOS_SCALE1 (0x3u << 14)
#define PWR_CR1_ODEN (1u << 16)
#define PWR_CR1_ODSWEN (1u << 17)
#define PWR_CSR1_ODRDY (1u << 16)
#define PWR_CSR1_ODSWRDY (1u << 17)

/* ---- embedded flash interface (RM0385 "Embedded flash memory", FLASH registers) */
typedef struct {
    volatile uint32_t ACR, KEYR, OPTKEYR, SR, CR, OPTCR, OPTCR1;
} flash_regs;
#define FLASH_IF ((flash_regs *)(AHB1_BASE + 0x3C00u))
#define FLASH_ACR_LATENCY_MASK 0xFu
#define FLASH_ACR_PRFTEN (1u << 8)
#define FLASH_ACR_ARTEN (1u << 9)
#define FLASH_ACR_ARTRST (1u << 11)

/* ---- GPIO (RM0385 "General-purpose I/Os", GPIO registers) */
typedef struct {
    volatile uint32_t MODER, OTYPER, OSPEEDR, PUPDR, IDR, ODR, BSRR, LCKR, AFR[2];
} gpio_regs;
_Static_assert(offsetof(gpio_regs, AFR) == 0x20, "GPIO_AFRL offset");
#define GPIOB ((gpio_regs *)(AHB1_BASE + 0x0400u))
#define GPIOD ((gpio_regs *)(AHB1_BASE + 0x0C00u))
#define GPIOF ((gpio_regs *)(AHB1_BASE + 0x1400u))
#define GPIO_MODE_OUTPUT 0x1u /* MODER, 2 bits a pin */
#define GPIO_MODE_AF 0x2u
#define GPIO_SPEED_HIGH 0x2u  /* OSPEEDR, 2 bits a pin */
#define GPIO_PULL_UP 0x1u     /* PUPDR, 2 bits a pin */

/* ---- USART (RM0385 "Universal synchronous receiver transmitter", USART registers) */
typedef struct {
    volatile uint32_t CR1, CR2, CR3, BRR, GTPR, RTOR, RQR, ISR, ICR, RDR, TDR;
} usart_regs;
_Static_assert(offsetof(usart_regs, TDR) == 0x28, "USART_TDR offset");
#define USART3 ((usart_regs *)(APB1_BASE + 0x4800u))
#define USART_CR1_UE (1u << 0)
#define USART_CR1_RE (1u << 2)
#define USART_CR1_TE (1u << 3)
#define USART_CR1_RXNEIE (1u << 5)
#define USART_CR1_TXEIE (1u << 7)
#define USART_CR1_OVER8 (1u << 15) /* oversampling by 8 (BRR[2:0] = USARTDIV[3:0] >> 1) */
#define USART_CR3_EIE (1u << 0)
#define USART_ISR_PE (1u << 0)
#define USART_ISR_FE (1u << 1)
#define USART_ISR_NE (1u << 2)
#define USART_ISR_ORE (1u << 3)
#define USART_ISR_RXNE (1u << 5)
#define USART_ISR_TXE (1u << 7)
#define USART_ICR_ERRORS 0xFu /* PECF | FECF | NCF | ORECF, bits 0-3 */

/* ---- I2C (RM0385 "Inter-integrated circuit interface", I2C registers) */
typedef struct {
    volatile uint32_t CR1, CR2, OAR1, OAR2, TIMINGR, TIMEOUTR, ISR, ICR, PECR, RXDR, TXDR;
} i2c_regs;
_Static_assert(offsetof(i2c_regs, TXDR) == 0x28, "I2C_TXDR offset");
#define I2C1 ((i2c_regs *)(APB1_BASE + 0x5400u))
#define I2C_CR1_PE (1u << 0)
#define I2C_CR2_SADD_POS 0u /* 7-bit address goes in SADD[7:1] */
#define I2C_CR2_RD_WRN (1u << 10)
#define I2C_CR2_START (1u << 13)
#define I2C_CR2_NBYTES_POS 16u
#define I2C_CR2_RELOAD (1u << 24)
#define I2C_CR2_AUTOEND (1u << 25)
#define I2C_ISR_TXE (1u << 0)
#define I2C_ISR_TXIS (1u << 1)
#define I2C_ISR_RXNE (1u << 2)
#define I2C_ISR_NACKF (1u << 4)
#define I2C_ISR_STOPF (1u << 5)
#define I2C_ISR_TC (1u << 6)
#define I2C_ISR_TCR (1u << 7)
#define I2C_ISR_BERR (1u << 8)
#define I2C_ISR_ARLO (1u << 9)
#define I2C_ISR_OVR (1u << 10)
#define I2C_ISR_BUSY (1u << 15)
#define I2C_ICR_ALL 0x3F38u /* ADDRCF NACKCF STOPCF BERRCF ARLOCF OVRCF PECCF TIMOUTCF ALERTCF */

/* ---- independent watchdog (RM0385 "Independent watchdog"), clocked by the ~32 kHz LSI */
typedef struct {
    volatile uint32_t KR, PR, RLR, SR, WINR;
} iwdg_regs;
#define IWDG ((iwdg_regs *)(APB1_BASE + 0x3000u))
#define IWDG_KEY_RELOAD 0xAAAAu
#define IWDG_KEY_UNLOCK 0x5555u
#define IWDG_KEY_START 0xCCCCu
#define IWDG_SR_BUSY 0x7u /* PVU | RVU | WVU */

/* ---- MCU debug component (RM0385 "Debug support", DBGMCU_APB1_FZ) */
#define DBGMCU_APB1_FZ REG32(0xE0042008u)
#define DBGMCU_APB1_FZ_IWDG_STOP (1u << 12)

/* ---- Cortex-M7 core (ARM DDI0489 / ARMv7-M ARM; addresses as in CMSIS core_cm7.h) */
#define SCB_AIRCR REG32(0xE000ED0Cu)
#define SCB_CCR REG32(0xE000ED14u)
#define SCB_CCR_IC (1u << 17) /* instruction cache enable */
#define SCB_CPACR REG32(0xE000ED88u)
#define SCB_CPACR_CP10_CP11_FULL (0xFu << 20) /* full access to the FPU */
#define SCB_ICIALLU REG32(0xE000EF50u)         /* invalidate the whole I-cache */
#define DEMCR REG32(0xE000EDFCu)
#define DEMCR_TRCENA (1u << 24)
#define DWT_CTRL REG32(0xE0001000u)
#define DWT_CTRL_CYCCNTENA (1u << 0)
#define DWT_CYCCNT REG32(0xE0001004u)
#define DWT_LAR REG32(0xE0001FB0u)
#define DWT_LAR_UNLOCK 0xC5ACCE55u
#define NVIC_ISER(n) REG32(0xE000E100u + 4u * (n))
#define NVIC_IPR8(irq) (*(volatile uint8_t *)(uintptr_t)(0xE000E400u + (irq)))
#define NVIC_PRIO_SHIFT 4u /* the F7 implements the upper 4 priority bits */
#define IRQ_USART3 39u

static inline void dsb(void) { __asm__ volatile("dsb 0xF" ::: "memory"); }
static inline void isb(void) { __asm__ volatile("isb 0xF" ::: "memory"); }
static inline void dmb(void) { __asm__ volatile("dmb 0xF" ::: "memory"); }

/* Interrupts off around a read-modify-write shared with an ISR; returns the old PRIMASK. */
static inline uint32_t irq_save(void)
{
    uint32_t primask;
    __asm__ volatile("mrs %0, primask\n cpsid i" : "=r"(primask)::"memory");
    return primask;
}
static inline void irq_restore(uint32_t primask)
{
    __asm__ volatile("msr primask, %0" ::"r"(primask) : "memory");
}

/* Set a 2-bit field of pin `pin` in MODER/OSPEEDR/PUPDR. */
static inline void gpio_field2(volatile uint32_t *reg, unsigned pin, uint32_t value)
{
    *reg = (*reg & ~(0x3u << (2u * pin))) | (value << (2u * pin));
}
static inline void gpio_af(gpio_regs *port, unsigned pin, uint32_t af)
{
    volatile uint32_t *afr = &port->AFR[pin / 8u];
    *afr = (*afr & ~(0xFu << (4u * (pin % 8u)))) | (af << (4u * (pin % 8u)));
}

#endif
