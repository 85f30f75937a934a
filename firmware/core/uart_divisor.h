/* The USART baud-rate divisor for a kernel clock (RM0385 "USART baud rate generation").
 *
 * 16x oversampling tolerates more clock error and noise, so it is used unless it lands more
 * than 1 % off the asked rate; 8x oversampling (OVER8) halves the divisor's step. On the
 * NUCLEO's fallback clock (the 16 MHz HSI alone) 921600 baud is 941 176 with 16x (+2.1 %, at
 * the edge of the ST-LINK's receiver with the HSI's own 1 %), 914 286 with 8x (-0.8 %). */
#ifndef FW_UART_DIVISOR_H
#define FW_UART_DIVISOR_H

#include <stdbool.h>
#include <stdint.h>

typedef struct uart_divisor {
    uint16_t brr;         /* the USART_BRR value */
    bool over8;           /* set USART_CR1.OVER8 */
    uint32_t actual_baud; /* the rate it gives */
} uart_divisor;

uart_divisor uart_divisor_for(uint32_t kernel_hz, uint32_t baud);

#endif
