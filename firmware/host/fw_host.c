/* The firmware core as a shared library for the host tests (Python ctypes).
 *
 * A host board forwards the platform's I2C, clock and transmit calls to callbacks, so a test
 * can put the emulated LSM6DSOX (or a recording fake) behind the core and decode what it sends
 * with the Python link decoder. The core's own functions (crc16, cobs_*, link_*, lsm_*,
 * fw_rate_fits) are exported from the library as they are. */
#include <stdlib.h>
#include <string.h>

#include "../core/firmware.h"

typedef int (*host_i2c_write_fn)(uint8_t address, uint8_t reg, const uint8_t *data, size_t n);
typedef int (*host_i2c_read_fn)(uint8_t address, uint8_t reg, uint8_t *data, size_t n);
typedef uint32_t (*host_micros_fn)(void);
typedef void (*host_delay_fn)(uint32_t us);
typedef void (*host_tx_fn)(const uint8_t *data, size_t n);

typedef struct host_board {
    fw_platform platform;
    fw_state fw;
    host_i2c_write_fn i2c_write;
    host_i2c_read_fn i2c_read;
    host_micros_fn micros;
    host_delay_fn delay;
    host_tx_fn tx;
    size_t tx_free; /* what tx_free() reports: a test shrinks it to fill the buffer */
    fw_board_health health; /* what the board layer reports: a test sets it */
    char name[64];
} host_board;

static int board_i2c_write(void *ctx, uint8_t address, uint8_t reg, const uint8_t *data,
                           size_t n)
{
    return ((host_board *)ctx)->i2c_write(address, reg, data, n);
}

static int board_i2c_read(void *ctx, uint8_t address, uint8_t reg, uint8_t *data, size_t n)
{
    return ((host_board *)ctx)->i2c_read(address, reg, data, n);
}

static uint32_t board_micros(void *ctx)
{
    return ((host_board *)ctx)->micros();
}

static void board_delay_us(void *ctx, uint32_t us)
{
    ((host_board *)ctx)->delay(us);
}

static size_t board_tx_free(void *ctx)
{
    return ((host_board *)ctx)->tx_free;
}

static void board_tx_write(void *ctx, const uint8_t *data, size_t n)
{
    ((host_board *)ctx)->tx(data, n);
}

static void board_health(void *ctx, fw_board_health *health)
{
    *health = ((host_board *)ctx)->health;
}

/* A board with its core initialised (the sensor is probed and configured at once). */
host_board *fwh_create(host_i2c_write_fn i2c_write, host_i2c_read_fn i2c_read,
                       host_micros_fn micros, host_delay_fn delay, host_tx_fn tx,
                       const uint8_t *unique_id, const char *name, uint32_t baud,
                       uint32_t i2c_hz)
{
    host_board *board = calloc(1, sizeof *board);
    if (!board)
        return NULL;
    board->i2c_write = i2c_write;
    board->i2c_read = i2c_read;
    board->micros = micros;
    board->delay = delay;
    board->tx = tx;
    board->tx_free = 64u * 1024u;
    board->health.reset_cause = LINK_RESET_POWER_ON;
    strncpy(board->name, name ? name : "", sizeof board->name - 1);
    board->platform = (fw_platform){board, board_i2c_write, board_i2c_read, board_micros,
                                    board_delay_us, board_tx_free, board_tx_write,
                                    board_health};
    fw_identity identity = {{0}, board->name, baud, i2c_hz};
    memcpy(identity.unique_id, unique_id, sizeof identity.unique_id);
    fw_init(&board->fw, &board->platform, &identity);
    return board;
}

void fwh_destroy(host_board *board)
{
    free(board);
}

void fwh_set_tx_free(host_board *board, size_t bytes)
{
    board->tx_free = bytes;
}

/* What the board layer reports for STATUS (UART, I2C recovery, watchdog, reset cause). */
void fwh_set_board_health(host_board *board, uint32_t uart_rx_errors,
                          uint32_t uart_tx_dropped_bytes, uint32_t i2c_recoveries,
                          uint32_t watchdog_resets, uint8_t reset_cause, int clock_fallback)
{
    board->health = (fw_board_health){uart_rx_errors, uart_tx_dropped_bytes, i2c_recoveries,
                                      watchdog_resets, reset_cause, clock_fallback != 0};
}

void fwh_receive(host_board *board, const uint8_t *data, size_t n)
{
    fw_receive(&board->fw, data, n);
}

void fwh_poll(host_board *board)
{
    fw_poll(&board->fw);
}

int fwh_led_mode(const host_board *board)
{
    return (int)fw_led_mode_now(&board->fw);
}

int fwh_led_lit(int mode, uint32_t now_ms)
{
    return fw_led_lit((fw_led_mode)mode, now_ms);
}

int fwh_streaming(const host_board *board)
{
    return board->fw.streaming;
}

int fwh_sensor_count(const host_board *board)
{
    return board->fw.sensor_count;
}

/* Counters, in this order: commands, bus_errors, tx_dropped_packets, words, unknown_tags,
 * incomplete_slots, lost_slots, overruns, samples, packets, dropped_packets, rx frames,
 * rx bad_frames, settling (samples discarded as turn-on transient), tx_dropped_bytes,
 * i2c_errors, i2c_retries, samples_sent, status_sent, mag_i2c_errors, mag_samples_read,
 * mag_samples_sent, mag_overruns.
 * Returns how many were written (at most `size`). */
size_t fwh_counters(const host_board *board, uint32_t *out, size_t size)
{
    const fw_counters *c = &board->fw.counters;
    const fifo_stream_counters *s = &board->fw.stream.counters;
    const uint32_t values[] = {
        c->commands, c->bus_errors, c->tx_dropped_packets, s->words, s->unknown_tags,
        s->incomplete_slots, s->lost_slots, s->overruns, s->samples, s->packets,
        s->dropped_packets, board->fw.rx.frames, board->fw.rx.bad_frames, s->settling,
        c->tx_dropped_bytes, c->i2c_errors, c->i2c_retries, c->samples_sent, c->status_sent,
        c->mag_i2c_errors, c->mag_samples_read, c->mag_samples_sent, c->mag_overruns,
    };
    size_t n = sizeof values / sizeof values[0];
    if (n > size)
        n = size;
    memcpy(out, values, n * sizeof values[0]);
    return n;
}

/* The magnetometer as the core sees it: chip (0 none), address, rate (mHz), flags
 * (1 found, 2 answering, 4 paused). */
void fwh_magnetometer(const host_board *board, uint32_t out[4])
{
    const fw_state *fw = &board->fw;
    out[0] = fw->mag_found ? fw->mag.chip : 0u;
    out[1] = fw->mag.address;
    out[2] = fw->mag.odr_mhz;
    out[3] = (fw->mag_found ? 1u : 0u) | (fw->mag_ok ? 2u : 0u) | (fw->mag_paused ? 4u : 0u);
}

/* ---- the frame receiver on its own (the tests feed it Python-encoded frames) */

link_rx *fwh_rx_create(void)
{
    link_rx *rx = malloc(sizeof *rx);
    if (rx)
        link_rx_init(rx);
    return rx;
}

void fwh_rx_destroy(link_rx *rx)
{
    free(rx);
}

/* The next good packet (type + payload, without the CRC) from data[*offset..length), copied to
 * `packet`, which holds LINK_MAX_PACKET bytes; returns its length, or 0 when the data ran out. */
size_t fwh_rx_next(link_rx *rx, const uint8_t *data, size_t length, size_t *offset,
                   uint8_t *packet)
{
    uint8_t type;
    const uint8_t *payload;
    size_t payload_length;
    if (!link_rx_feed(rx, data, length, offset, &type, &payload, &payload_length))
        return 0;
    packet[0] = type;
    memcpy(packet + 1, payload, payload_length);
    return payload_length + 1;
}

uint32_t fwh_rx_bad_frames(const link_rx *rx)
{
    return rx->bad_frames;
}
