/* System clock (216 MHz from the PLL) and a microsecond clock from the DWT cycle counter. */
#ifndef BOARD_CLOCK_H
#define BOARD_CLOCK_H

#include <stdint.h>

typedef enum clock_source {
    CLOCK_HSE_BYPASS_PLL, /* 8 MHz MCO of the ST-LINK, PLL to 216 MHz (normal case) */
    CLOCK_HSI_PLL,        /* HSE absent: internal 16 MHz RC, PLL to 216 MHz (+-1 % accuracy) */
    CLOCK_HSI_ONLY,       /* PLL or over-drive failed: 16 MHz HSI, everything slow */
} clock_source;

/* Configure the clocks, the flash wait states and the I-cache; start the cycle counter. */
clock_source clock_init(void);
clock_source clock_source_used(void);
uint32_t clock_sysclk_hz(void);

/* Microseconds and milliseconds since clock_init (wrapping at 2^32). Main-loop context only:
 * the 64-bit extension of the 32-bit cycle counter needs a call at least every 19 s. */
uint32_t board_micros(void);
uint32_t board_millis(void);
/* Busy-wait `us` microseconds, feeding the watchdog meanwhile. */
void board_delay_us(uint32_t us);

/* Provided by main.c: reload the independent watchdog. */
void board_watchdog_feed(void);

#endif
