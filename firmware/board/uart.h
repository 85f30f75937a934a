/* USART3 on PD8 (TX) / PD9 (RX), the ST-LINK virtual COM port: 921600 baud 8N1, interrupt
 * driven, with a 2 KB receive ring and a 16 KB transmit ring. */
#ifndef BOARD_UART_H
#define BOARD_UART_H

#include <stddef.h>
#include <stdint.h>

#define UART_BAUD 921600u

typedef struct uart_stats {
    uint32_t overruns;       /* ORE: a byte arrived before the previous one was read */
    uint32_t framing_errors; /* FE, NE or PE on a received byte (the byte is dropped) */
    uint32_t rx_dropped;     /* bytes lost because the receive ring was full */
    uint32_t tx_dropped;     /* bytes uart_write could not queue (the ring was full) */
} uart_stats;

/* Needs clock_init first (the baud rate divisor comes from the system clock). */
void uart_init(void);

/* Copy up to `max` received bytes out of the ring; returns how many. */
size_t uart_read(uint8_t *buf, size_t max);

/* Room in the transmit ring, and queue `n` bytes (n <= uart_tx_free(); more are dropped). */
size_t uart_tx_free(void);
void uart_write(const uint8_t *data, size_t n);

uart_stats uart_get_stats(void);

#endif
