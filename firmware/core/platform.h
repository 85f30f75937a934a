/* What the portable core needs from a board: an I2C master, a microsecond clock and a
 * transmit buffer. The NUCLEO board layer (board/) implements it on the STM32F746; the host
 * shim (host/fw_host.c) implements it for the tests. */
#ifndef FW_PLATFORM_H
#define FW_PLATFORM_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

/* What only the board knows about its health, for STATUS (docs/protocol.md, 0x08). */
typedef struct fw_board_health {
    uint32_t uart_rx_errors;        /* overrun, framing, noise, parity; receive ring full */
    uint32_t uart_tx_dropped_bytes; /* bytes the board layer itself dropped */
    uint32_t i2c_recoveries;        /* stuck bus recovered */
    uint32_t watchdog_resets;       /* since the last power-on */
    uint8_t reset_cause;            /* LINK_RESET_* */
    bool clock_fallback;            /* running on the internal oscillator */
} fw_board_health;

typedef struct fw_platform {
    void *ctx; /* passed back to every function */

    /* Write `length` bytes to consecutive registers from `reg` of the 7-bit `address`.
     * Returns 0 on success, nonzero on a NACK, a timeout or a bus error. */
    int (*i2c_write)(void *ctx, uint8_t address, uint8_t reg, const uint8_t *data,
                     size_t length);
    /* Burst-read `length` bytes from `reg` on (the register address auto-increments;
     * `length` may exceed 255). Returns 0 on success, nonzero on failure. */
    int (*i2c_read)(void *ctx, uint8_t address, uint8_t reg, uint8_t *data, size_t length);

    /* A free-running microsecond clock; wraps at 2^32 (compare with unsigned differences). */
    uint32_t (*micros)(void *ctx);
    /* Wait `us` microseconds (a board also keeps its watchdog fed here). */
    void (*delay_us)(void *ctx, uint32_t us);

    /* Bytes free in the transmit buffer, and queue `length` bytes (never more than free). */
    size_t (*tx_free)(void *ctx);
    void (*tx_write)(void *ctx, const uint8_t *data, size_t length);

    /* Optional (may be NULL: all zero): the board's own counters and reset cause. */
    void (*board_health)(void *ctx, fw_board_health *health);
} fw_platform;

#endif
