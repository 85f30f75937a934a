/* USART baud-rate divisor (see uart_divisor.h). */
#include "uart_divisor.h"

#define MAX_ERROR_PPM_16X 10000u /* 1 % */

static uint32_t error_ppm(uint32_t actual, uint32_t wanted)
{
    uint64_t diff = actual > wanted ? actual - wanted : wanted - actual;
    return (uint32_t)(diff * 1000000u / wanted);
}

uart_divisor uart_divisor_for(uint32_t kernel_hz, uint32_t baud)
{
    uart_divisor d = {0, false, 0};
    if (!baud || !kernel_hz)
        return d;
    uint32_t div16 = (kernel_hz + baud / 2u) / baud; /* BRR = USARTDIV with 16x */
    if (div16 < 16u)
        div16 = 16u;
    d.brr = (uint16_t)div16;
    d.actual_baud = kernel_hz / div16;
    if (error_ppm(d.actual_baud, baud) <= MAX_ERROR_PPM_16X)
        return d;
    /* 8x: USARTDIV = 2 f / baud; BRR[15:4] = USARTDIV[15:4], BRR[3] = 0,
     * BRR[2:0] = USARTDIV[3:0] >> 1 (so USARTDIV is taken even in its low nibble's step). */
    uint32_t div8 = (2u * kernel_hz + baud / 2u) / baud;
    if (div8 < 16u)
        return d;
    uint32_t actual8 = 2u * kernel_hz / div8;
    if (error_ppm(actual8, baud) < error_ppm(d.actual_baud, baud)) {
        d.brr = (uint16_t)((div8 & 0xFFF0u) | ((div8 & 0x000Fu) >> 1));
        d.over8 = true;
        d.actual_baud = actual8;
    }
    return d;
}
