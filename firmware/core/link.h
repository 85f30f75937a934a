/* Link protocol v1 (docs/protocol.md): packet types, the packet encoder and the frame receiver.
 *
 * A packet is type + payload + CRC-16 (little-endian), COBS-encoded and followed by 0x00. The
 * encoder builds device-to-host packets; the receiver cuts frames at 0x00, undoes COBS and checks
 * length and CRC, and hands out type + payload. Nothing here allocates or knows about hardware. */
#ifndef FW_LINK_H
#define FW_LINK_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#define LINK_PROTOCOL_VERSION 1u
#define LINK_MAX_PACKET 512u                 /* type + payload + CRC */
#define LINK_MAX_PAYLOAD (LINK_MAX_PACKET - 3u)
#define LINK_MAX_FRAME 515u                  /* COBS-encoded packet, without the 0x00 */
#define LINK_MAX_WIRE (LINK_MAX_FRAME + 1u)  /* with the 0x00 */
#define LINK_MAX_SAMPLES 32u
#define LINK_SAMPLE_BYTES 12u
#define LINK_SAMPLES_HEADER 9u               /* seq u16, t0 u32, count u8, temperature i16 */

/* Device to host. */
enum {
    LINK_INFO = 0x01,
    LINK_CONFIG = 0x02,
    LINK_SAMPLES = 0x03,
    LINK_ACK = 0x04,
    LINK_SELFTEST = 0x05,
    LINK_LOG = 0x06,
    LINK_PONG = 0x07,
    LINK_STATUS = 0x08, /* v1 extension: the board's health counters */
    LINK_SAMPLES_INDEXED = 0x09, /* v1 extension: SAMPLES of sensor 1, 2, ... */
    LINK_SENSOR = 0x0A,          /* v1 extension: one sensor of several */
    LINK_MAG_SAMPLES = 0x0B,     /* v1 extension: the magnetometer's field samples */
    LINK_MAGNETOMETER = 0x0C,    /* v1 extension: the magnetometer and its settings */
};

#define LINK_SENSOR_PAYLOAD 16u
#define LINK_SENSOR_ANSWERING 0x01u
/* Paused: the rate fits sensor 0 alone, so this sensor is configured but not streamed. */
#define LINK_SENSOR_PAUSED 0x02u

#define LINK_MAGNETOMETER_PAYLOAD 15u
#define LINK_MAG_MAX_SAMPLES 32u
#define LINK_MAG_ANSWERING 0x01u
/* Paused: the accelerometer's rate leaves no room for the field samples on UART or I2C. */
#define LINK_MAG_PAUSED 0x02u

/* Host to device. */
enum {
    LINK_HELLO = 0x81,
    LINK_CONFIGURE = 0x82,
    LINK_START = 0x83,
    LINK_STOP = 0x84,
    LINK_SELF_TEST = 0x85,
    LINK_PING = 0x86,
    LINK_GET_STATUS = 0x87, /* v1 extension: answered by STATUS */
};

/* ACK status. */
enum {
    LINK_ACK_OK = 0,
    LINK_ACK_BAD_ARGUMENT = 1,
    LINK_ACK_UNSUPPORTED = 2,
    LINK_ACK_SENSOR_ERROR = 3,
    LINK_ACK_BUSY = 4,
};

/* LOG level. */
enum { LINK_LOG_DEBUG = 0, LINK_LOG_INFO = 1, LINK_LOG_WARNING = 2, LINK_LOG_ERROR = 3 };

/* ---- encoder: each function writes the whole wire frame (COBS + 0x00) into `wire`, which
 * must hold LINK_MAX_WIRE bytes, and returns its length (0 when the arguments do not fit). */

typedef struct link_info {
    uint8_t firmware[3]; /* major, minor, patch */
    uint8_t who_am_i;
    uint8_t unique_id[12];
    const char *name; /* UTF-8, not terminated on the wire; NULL for none */
} link_info;

typedef struct link_config {
    uint32_t odr_mhz;
    uint8_t accel_fs_g;
    uint16_t gyro_fs_dps;
    uint32_t tick_ns;
} link_config;

typedef struct link_selftest {
    uint8_t accel_pass;
    uint8_t gyro_pass;
    int16_t accel_delta_mg[3];
    int16_t gyro_delta_dps[3];
} link_selftest;

/* STATUS (docs/protocol.md, 0x08): version 1 is 43 bytes of payload; later versions append.
 * Version 2 (a board with a magnetometer) appends mag_i2c_errors, mag_samples_read and
 * mag_overruns. */
#define LINK_STATUS_VERSION 1u
#define LINK_STATUS_PAYLOAD 43u
#define LINK_STATUS_VERSION_MAG 2u
#define LINK_STATUS_PAYLOAD_MAG 55u

enum {
    LINK_RESET_UNKNOWN = 0,
    LINK_RESET_POWER_ON = 1,
    LINK_RESET_PIN = 2,
    LINK_RESET_BROWN_OUT = 3,
    LINK_RESET_SOFTWARE = 4,
    LINK_RESET_IWDG = 5,
    LINK_RESET_WWDG = 6,
    LINK_RESET_LOW_POWER = 7,
};

enum {
    LINK_STATUS_STREAMING = 0x01,
    LINK_STATUS_SENSOR_OK = 0x02,
    LINK_STATUS_CLOCK_FALLBACK = 0x04,
};

typedef struct link_status {
    uint8_t reset_cause;
    uint8_t flags;
    uint32_t uptime_ms;
    uint32_t uart_tx_dropped_bytes;
    uint32_t uart_rx_errors;
    uint32_t i2c_errors;
    uint32_t i2c_recoveries;
    uint32_t i2c_retries;
    uint32_t fifo_overruns;
    uint32_t samples_read;
    uint32_t samples_sent;
    uint32_t watchdog_resets;
    uint8_t version;           /* 0 or 1: version 1; 2: with the two fields below */
    uint32_t mag_i2c_errors;
    uint32_t mag_samples_read;
    uint32_t mag_overruns;
} link_status;

/* MAGNETOMETER (docs/protocol.md, 0x0C). */
typedef struct link_magnetometer {
    uint8_t chip;        /* 1 LIS3MDL, 2 LIS2MDL */
    uint8_t address;
    uint8_t who_am_i;
    uint32_t odr_mhz;
    uint16_t range_ut;
    uint32_t pt_per_lsb;
    uint8_t mode;
    uint8_t flags;       /* LINK_MAG_ANSWERING, LINK_MAG_PAUSED */
} link_magnetometer;

/* SENSOR (docs/protocol.md, 0x0A): one sensor of a board with several. */
typedef struct link_sensor {
    uint8_t index;
    uint8_t count;
    uint8_t address;
    uint8_t who_am_i;
    link_config config;
    uint8_t flags; /* LINK_SENSOR_ANSWERING, LINK_SENSOR_PAUSED */
} link_sensor;

/* Frame a packet of `type` + `payload` (at most LINK_MAX_PAYLOAD bytes). */
size_t link_frame(uint8_t type, const uint8_t *payload, size_t length, uint8_t *wire);

size_t link_encode_info(const link_info *info, uint8_t *wire);
size_t link_encode_config(const link_config *config, uint8_t *wire);
/* `samples` holds `count` (1..32) rows of gx, gy, gz, ax, ay, az in raw LSB. */
size_t link_encode_samples(uint16_t seq, uint32_t t0, int16_t temperature_raw,
                           const int16_t (*samples)[6], uint8_t count, uint8_t *wire);
/* SAMPLES_INDEXED: the same layout after the sensor index (1..7). */
size_t link_encode_samples_indexed(uint8_t sensor_index, uint16_t seq, uint32_t t0,
                                   int16_t temperature_raw, const int16_t (*samples)[6],
                                   uint8_t count, uint8_t *wire);
size_t link_encode_sensor(const link_sensor *sensor, uint8_t *wire);
size_t link_encode_magnetometer(const link_magnetometer *mag, uint8_t *wire);
/* MAG_SAMPLES: `count` (1..32) samples, each a time `t` (sensor 0's ticks) and x, y, z. */
size_t link_encode_mag_samples(uint16_t seq, const uint32_t *t, const int16_t (*xyz)[3],
                               uint8_t count, uint8_t *wire);
/* `message` may be NULL or empty. */
size_t link_encode_ack(uint8_t command, uint8_t status, const char *message, uint8_t *wire);
size_t link_encode_selftest(const link_selftest *result, uint8_t *wire);
size_t link_encode_log(uint8_t level, const char *text, uint8_t *wire);
size_t link_encode_pong(uint32_t token, uint8_t *wire);
size_t link_encode_status(const link_status *status, uint8_t *wire);

/* ---- receiver */

typedef struct link_rx {
    uint8_t frame[LINK_MAX_FRAME];
    size_t length;
    bool discarding;          /* an over-long frame: drop bytes up to the next 0x00 */
    uint8_t packet[LINK_MAX_PACKET];
    uint32_t frames;          /* good packets handed out */
    uint32_t bad_frames;      /* COBS, length or CRC failures, over-long frames */
} link_rx;

void link_rx_init(link_rx *rx);

/* Feed bytes from the wire, starting at `*offset`; stops after the first good packet and
 * returns true with `*type`, `*payload` (inside rx) and `*payload_length` set. `*offset`
 * moves past the bytes consumed, so call again until it returns false. */
bool link_rx_feed(link_rx *rx, const uint8_t *data, size_t length, size_t *offset,
                  uint8_t *type, const uint8_t **payload, size_t *payload_length);

/* Little-endian helpers shared by the core. */
static inline void put_u16(uint8_t *p, uint16_t v) { p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); }
static inline void put_u32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); p[2] = (uint8_t)(v >> 16); p[3] = (uint8_t)(v >> 24);
}
static inline uint16_t get_u16(const uint8_t *p) { return (uint16_t)(p[0] | (p[1] << 8)); }
static inline uint32_t get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}

#endif
