/* The firmware's portable core: command handling and streaming (docs/protocol.md).
 *
 * A board calls fw_init once, then in its main loop hands received bytes to fw_receive and calls
 * fw_poll, which drains the LSM6DSOX FIFO into SAMPLES packets when streaming. Everything runs in
 * that one loop; the core never blocks except for the half-second self-test. */
#ifndef FW_FIRMWARE_H
#define FW_FIRMWARE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "fifo_stream.h"
#include "link.h"
#include "lsm6dsox.h"
#include "magnetometer.h"
#include "platform.h"

#define FW_VERSION_MAJOR 1
#define FW_VERSION_MINOR 2
#define FW_VERSION_PATCH 0

#define FW_POLL_INTERVAL_US 2000u      /* FIFO polls while streaming */
#define FW_FLUSH_AFTER_US 5000u        /* a packet leaves ~5 ms after its first sample */
#define FW_RETRY_INTERVAL_US 500000u   /* looking for a lost sensor again */
#define FW_FIFO_BURST_WORDS 128u       /* words per I2C burst */
#define FW_REPLY_TIMEOUT_US 100000u    /* waiting for transmit room for a reply */
#define FW_SENSOR_BOOT_US 20000u       /* LSM6DSOX boot after power-up: 10 ms (AN5272) */
#define FW_STATUS_INTERVAL_US 1000000u /* STATUS while streaming */
#define FW_I2C_RETRIES 3u              /* a failed FIFO transfer is tried again this often */
#define FW_MAX_SENSORS 2u              /* LSM6DSOX at 0x6A and 0x6B (SA0 low and high) */

typedef struct fw_identity {
    uint8_t unique_id[12]; /* the MCU's 96-bit unique id, in memory order */
    const char *name;      /* "NUCLEO-F746ZG" */
    uint32_t baud;         /* the UART's rate; 0 for native USB (no link limit) */
    uint32_t i2c_hz;       /* the I2C bus clock: limits the rate the FIFO can be drained at */
} fw_identity;

typedef enum fw_led_mode {
    FW_LED_IDLE = 0,      /* steady on: ready */
    FW_LED_STREAMING = 1, /* blinking at 1 Hz */
    FW_LED_ERROR = 2,     /* blinking fast: no sensor, or it stopped answering */
} fw_led_mode;

typedef struct fw_counters {
    uint32_t commands;
    uint32_t bus_errors;
    uint32_t tx_dropped_packets; /* SAMPLES dropped for want of transmit room */
    uint32_t tx_dropped_bytes;   /* every packet's wire bytes dropped for want of room */
    uint32_t i2c_errors;         /* failed I2C transfers (any, probes included) */
    uint32_t i2c_retries;        /* failed FIFO transfers tried again while streaming */
    uint32_t samples_sent;       /* samples in SAMPLES packets queued for the UART */
    uint32_t status_sent;        /* STATUS packets queued */
    uint32_t mag_i2c_errors;     /* failed I2C transfers to the magnetometer (also above) */
    uint32_t mag_samples_read;   /* field samples read (STATUS version 2) */
    uint32_t mag_samples_sent;   /* field samples in MAG_SAMPLES queued for the UART */
    uint32_t mag_overruns;       /* field samples the chip overwrote unread (ZYXOR) */
} fw_counters;

typedef struct fw_state {
    const fw_platform *platform;
    fw_identity identity;
    link_rx rx;
    lsm6dsox chip;        /* sensor 0: the first LSM6DSOX found (SAMPLES, SELF_TEST) */
    fifo_stream stream;
    bool sensor_ok;       /* probed and configured */
    /* Sensor 1: a second LSM6DSOX at 0x6B when sensor 0 is at 0x6A (SAMPLES_INDEXED). */
    lsm6dsox chip1;
    fifo_stream stream1;
    bool sensor1_ok;
    bool sensor1_paused;  /* the rate fits sensor 0 alone: sensor 1 is not streamed */
    uint8_t sensor_count; /* 1, or 2 when the second answered at power-on */
    uint32_t last_retry1_us;
    bool streaming;
    bool want_streaming;  /* the host asked for data: resume after the sensor comes back */
    uint32_t last_poll_us;
    uint32_t last_retry_us;
    uint32_t reported_tx_drops;
    fw_counters counters;
    fw_platform sensor_bus;   /* the board's platform with I2C failures counted (ctx: fw) */
    uint64_t uptime_us;       /* since fw_init, accumulated across the 32-bit clock's wrap */
    uint32_t uptime_last_us;
    uint32_t last_status_us;
    /* The magnetometer beside sensor 0, read directly on the board's schedule
     * (docs/protocol.md, "A magnetometer beside the sensor"). */
    magnetometer mag;
    fw_platform mag_bus;      /* the sensor bus, its failures also counted as the magnetometer's */
    bool mag_found;           /* answered at power-on: MAGNETOMETER follows every CONFIG */
    bool mag_ok;              /* configured and answering */
    bool mag_paused;          /* the accelerometer's rate leaves no room for it */
    bool mag_primed;          /* the first field sample after START was read (and dropped) */
    uint8_t mag_failures;     /* failed reads in a row */
    uint16_t mag_seq;
    uint32_t mag_last_us;     /* when the last field sample was read */
    uint32_t last_retry_mag_us;
    uint8_t wire[LINK_MAX_WIRE];
    uint8_t burst[FW_FIFO_BURST_WORDS * LSM_FIFO_WORD_BYTES];
} fw_state;

/* Power-on: probe and configure the sensor with the defaults (104 Hz, 4 g, 250 dps). */
void fw_init(fw_state *fw, const fw_platform *platform, const fw_identity *identity);

/* Bytes from the host; commands are answered at once (through platform->tx_write). */
void fw_receive(fw_state *fw, const uint8_t *data, size_t length);

/* Call often: drains the FIFO every FW_POLL_INTERVAL_US while streaming, sends packets when
 * due, and looks for a lost sensor again. */
void fw_poll(fw_state *fw);

/* The STATUS packet's fields now (docs/protocol.md, 0x08). */
void fw_status(fw_state *fw, link_status *status);

/* What the LED should show, and whether it is lit at `now_ms` in that mode. */
fw_led_mode fw_led_mode_now(const fw_state *fw);
bool fw_led_lit(fw_led_mode mode, uint32_t now_ms);

/* Whether the link and the I2C bus can carry an ODR code; when not, `why` (room for `size`
 * bytes) says what limits it. Baud 0 means native USB. */
bool fw_rate_fits(uint8_t odr_code, uint32_t baud, uint32_t i2c_hz, char *why, size_t size);
/* The same for `sensors` sensors streaming at once (their traffic adds up). */
bool fw_rate_fits_sensors(uint8_t odr_code, uint32_t baud, uint32_t i2c_hz, uint8_t sensors,
                          char *why, size_t size);
/* Whether `sensors` streaming at `odr_code` leave room for a magnetometer at `mag_odr_mhz`
 * on the UART and I2C (per field sample FW_MAG_WIRE_BYTES and FW_MAG_I2C_BITS); when not,
 * the magnetometer is paused, the accelerometer keeps its rate. */
bool fw_mag_fits(uint8_t odr_code, uint32_t baud, uint32_t i2c_hz, uint8_t sensors,
                 uint32_t mag_odr_mhz);
/* A MAG_SAMPLES packet of one sample on the wire: type, seq, count, t, x, y, z, CRC, COBS
 * and the 0x00. On I2C up to three bursts of STATUS..OUT_Z (address, register, address, 7
 * data bytes) and the LSM6DSOX's TIMESTAMP0..3 (7 bytes), 9 bits a byte. */
#define FW_MAG_WIRE_BYTES 18u
#define FW_MAG_I2C_BITS (3u * 10u * 9u + 7u * 9u)

#endif
