/* Clock tree (RM0385 "Reset and clock control"; over-drive: "Power controller", entering
 * Over-drive mode):
 *   HSE bypass 8 MHz (ST-LINK MCO) / PLLM 4 = 2 MHz, x PLLN 216 = 432 MHz VCO,
 *   / PLLP 2 = 216 MHz SYSCLK, / PLLQ 9 = 48 MHz; HSI fallback 16 MHz / PLLM 8 = same VCO.
 *   AHB /1 = 216 MHz, APB1 /4 = 54 MHz (max 54), APB2 /2 = 108 MHz (max 108).
 *   216 MHz needs voltage scale 1 + over-drive and 7 flash wait states (2.7-3.6 V). */
#include "clock.h"

#include <stdbool.h>

#include "stm32f7.h"

#define HSI_HZ 16000000u
#define SYSCLK_TARGET_HZ 216000000u
#define PLLM_HSE 4u  /* 8 MHz / 4 = 2 MHz VCO input (1-2 MHz allowed) */
#define PLLM_HSI 8u  /* 16 MHz / 8 = 2 MHz */
#define PLLN 216u    /* 2 MHz x 216 = 432 MHz VCO (100-432 MHz allowed) */
#define PLLP_DIV2 0u /* PLLP field 0 = divide by 2 -> 216 MHz */
#define PLLQ 9u      /* 432 / 9 = 48 MHz for USB/SDMMC/RNG */
#define FLASH_WAIT_STATES 7u /* RM0385 "Relation between CPU clock and flash read time": 210-216 MHz */

/* Timeouts, counted in cycles at the 16 MHz HSI that runs while they apply. */
#define HSE_TIMEOUT_CYCLES (HSI_HZ / 10u)    /* 100 ms: a bypass clock is there at once or never */
#define READY_TIMEOUT_CYCLES (HSI_HZ / 10u)  /* 100 ms for PLL lock, over-drive, clock switch */

static clock_source s_source = CLOCK_HSI_ONLY;
static uint32_t s_sysclk_hz = HSI_HZ;
static uint32_t s_last_cycles;   /* CYCCNT at the last update */
static uint64_t s_total_cycles;  /* CYCCNT extended to 64 bits */

/* Poll until (*reg & mask) == want; false after `timeout` cycles. */
static bool wait_bits(volatile uint32_t *reg, uint32_t mask, uint32_t want, uint32_t timeout)
{
    uint32_t start = DWT_CYCCNT;
    while ((*reg & mask) != want) {
        if (DWT_CYCCNT - start > timeout) {
            return false;
        }
    }
    return true;
}

static void cycle_counter_start(void)
{
    DEMCR |= DEMCR_TRCENA;           /* power the DWT/ITM trace blocks */
    DWT_LAR = DWT_LAR_UNLOCK;        /* the M7's DWT ignores writes until its lock is opened */
    DWT_CYCCNT = 0;                  /* count from 0 at boot */
    DWT_CTRL |= DWT_CTRL_CYCCNTENA;  /* run the cycle counter */
}

static bool hse_bypass_start(void)
{
    RCC->CR |= RCC_CR_HSEBYP;        /* external clock on PH0 (OSC_IN), oscillator bypassed; set
                                      * while HSEON is 0 as required */
    RCC->CR |= RCC_CR_HSEON;         /* then enable HSE */
    if (wait_bits(&RCC->CR, RCC_CR_HSERDY, RCC_CR_HSERDY, HSE_TIMEOUT_CYCLES)) {
        return true;
    }
    RCC->CR &= ~RCC_CR_HSEON;        /* no MCO (solder bridge open?): HSE off ... */
    (void)wait_bits(&RCC->CR, RCC_CR_HSERDY, 0u, READY_TIMEOUT_CYCLES);
    RCC->CR &= ~RCC_CR_HSEBYP;       /* ... and bypass cleared (only writable with HSE off) */
    return false;
}

static bool pll_start(bool from_hse)
{
    RCC->CR &= ~RCC_CR_PLLON;        /* PLLCFGR may only change with the PLL off */
    if (!wait_bits(&RCC->CR, RCC_CR_PLLRDY, 0u, READY_TIMEOUT_CYCLES)) {
        return false;
    }
    uint32_t cfg = RCC->PLLCFGR & ~RCC_PLLCFGR_FIELDS; /* keep reserved bits at reset value */
    cfg |= (from_hse ? PLLM_HSE : PLLM_HSI) << RCC_PLLCFGR_PLLM_POS;
    cfg |= PLLN << RCC_PLLCFGR_PLLN_POS;
    cfg |= PLLP_DIV2 << RCC_PLLCFGR_PLLP_POS;
    cfg |= PLLQ << RCC_PLLCFGR_PLLQ_POS;
    cfg |= from_hse ? RCC_PLLCFGR_PLLSRC_HSE : 0u; /* PLLSRC 0 = HSI */
    RCC->PLLCFGR = cfg;              /* M, N, P, Q and source as above */
    RCC->CR |= RCC_CR_PLLON;         /* start the main PLL */
    return wait_bits(&RCC->CR, RCC_CR_PLLRDY, RCC_CR_PLLRDY, READY_TIMEOUT_CYCLES);
}

static bool overdrive_enable(void)
{
    PWR->CR1 |= PWR_CR1_ODEN;        /* start the over-drive regulator (PLL already on) */
    if (!wait_bits(&PWR->CSR1, PWR_CSR1_ODRDY, PWR_CSR1_ODRDY, READY_TIMEOUT_CYCLES)) {
        return false;
    }
    PWR->CR1 |= PWR_CR1_ODSWEN;      /* switch the 1.2 V domain to over-drive */
    return wait_bits(&PWR->CSR1, PWR_CSR1_ODSWRDY, PWR_CSR1_ODSWRDY, READY_TIMEOUT_CYCLES);
}

static bool flash_configure(void)
{
    /* ART accelerator: reset its cache while disabled, then enable it with the prefetch and
     * the wait states needed at 216 MHz; set before the clock goes up. */
    FLASH_IF->ACR &= ~FLASH_ACR_ARTEN;
    FLASH_IF->ACR |= FLASH_ACR_ARTRST;
    FLASH_IF->ACR &= ~FLASH_ACR_ARTRST;
    FLASH_IF->ACR = (FLASH_IF->ACR & ~FLASH_ACR_LATENCY_MASK) | FLASH_WAIT_STATES |
                    FLASH_ACR_PRFTEN | FLASH_ACR_ARTEN;
    /* Read back until the new latency is in effect (one or two reads). */
    return wait_bits(&FLASH_IF->ACR, FLASH_ACR_LATENCY_MASK, FLASH_WAIT_STATES,
                     READY_TIMEOUT_CYCLES);
}

static void icache_enable(void)
{
    /* ARMv7-M cache maintenance: invalidate, then enable (D-cache stays off: no DMA, and the
     * UART ring buffers are shared with an ISR only). */
    dsb();
    isb();
    SCB_ICIALLU = 0u;                /* invalidate all instruction cache lines */
    dsb();
    isb();
    SCB_CCR |= SCB_CCR_IC;           /* enable the I-cache */
    dsb();
    isb();
}

clock_source clock_init(void)
{
    cycle_counter_start();           /* timeouts below are counted with it, at 16 MHz */

    RCC->APB1ENR |= RCC_APB1ENR_PWREN; /* clock the power controller */
    (void)RCC->APB1ENR;
    PWR->CR1 = (PWR->CR1 & ~PWR_CR1_VOS_MASK) | PWR_CR1_VOS_SCALE1; /* scale 1 (reset value;
                                      * VOS can only change with the PLL off, as it is now) */

    bool from_hse = hse_bypass_start();
    bool pll_ok = pll_start(from_hse);
    if (!pll_ok && from_hse) {       /* HSE present but the PLL would not lock: try HSI */
        RCC->CR &= ~RCC_CR_PLLON;
        (void)wait_bits(&RCC->CR, RCC_CR_PLLRDY, 0u, READY_TIMEOUT_CYCLES);
        RCC->CR &= ~(RCC_CR_HSEON | RCC_CR_HSEBYP);
        from_hse = false;
        pll_ok = pll_start(false);
    }
    if (pll_ok && overdrive_enable() && flash_configure()) {
        /* Bus prescalers before the switch: AHB /1, APB1 /4 (54 MHz), APB2 /2 (108 MHz). */
        RCC->CFGR = (RCC->CFGR & ~(RCC_CFGR_HPRE_MASK | RCC_CFGR_PPRE1_MASK | RCC_CFGR_PPRE2_MASK)) |
                    RCC_CFGR_PPRE1_DIV4 | RCC_CFGR_PPRE2_DIV2;
        RCC->CFGR = (RCC->CFGR & ~RCC_CFGR_SW_MASK) | RCC_CFGR_SW_PLL; /* SYSCLK = PLL */
        if (wait_bits(&RCC->CFGR, RCC_CFGR_SWS_MASK, RCC_CFGR_SWS_PLL, READY_TIMEOUT_CYCLES)) {
            s_sysclk_hz = SYSCLK_TARGET_HZ;
            s_source = from_hse ? CLOCK_HSE_BYPASS_PLL : CLOCK_HSI_PLL;
        }
    }
    /* Otherwise SYSCLK stays on the 16 MHz HSI (CLOCK_HSI_ONLY). HSI itself stays on in every
     * case: I2C1 is clocked from it. */

    icache_enable();
    s_last_cycles = DWT_CYCCNT;
    s_total_cycles = s_last_cycles;  /* cycles so far, at the old rate: close enough */
    return s_source;
}

clock_source clock_source_used(void) { return s_source; }
uint32_t clock_sysclk_hz(void) { return s_sysclk_hz; }

static uint64_t cycles_now(void)
{
    uint32_t now = DWT_CYCCNT;
    s_total_cycles += (uint32_t)(now - s_last_cycles); /* modulo 2^32: one wrap at most */
    s_last_cycles = now;
    return s_total_cycles;
}

uint32_t board_micros(void)
{
    return (uint32_t)(cycles_now() / (s_sysclk_hz / 1000000u));
}

uint32_t board_millis(void)
{
    return (uint32_t)(cycles_now() / (s_sysclk_hz / 1000u));
}

void board_delay_us(uint32_t us)
{
    uint32_t start = board_micros();
    while (board_micros() - start < us) { /* bounded by `us` */
        board_watchdog_feed();
    }
}
