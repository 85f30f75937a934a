/* Link protocol v1: device-to-host packet encoders and the command frame receiver. */
#include "link.h"

#include <string.h>

#include "cobs.h"
#include "crc16.h"

size_t link_frame(uint8_t type, const uint8_t *payload, size_t length, uint8_t *wire)
{
    uint8_t packet[LINK_MAX_PACKET];
    if (length > LINK_MAX_PAYLOAD)
        return 0;
    packet[0] = type;
    if (length)
        memcpy(packet + 1, payload, length);
    put_u16(packet + 1 + length, crc16(packet, 1 + length));
    size_t n = cobs_encode(packet, length + 3, wire);
    wire[n++] = 0x00;
    return n;
}

static size_t text_length(const char *text, size_t limit)
{
    size_t n = 0;
    if (text)
        while (n < limit && text[n])
            n++;
    return n;
}

size_t link_encode_info(const link_info *info, uint8_t *wire)
{
    uint8_t payload[LINK_MAX_PAYLOAD];
    payload[0] = LINK_PROTOCOL_VERSION;
    memcpy(payload + 1, info->firmware, 3);
    payload[4] = info->who_am_i;
    memcpy(payload + 5, info->unique_id, 12);
    size_t name = text_length(info->name, LINK_MAX_PAYLOAD - 17);
    if (name)
        memcpy(payload + 17, info->name, name);
    return link_frame(LINK_INFO, payload, 17 + name, wire);
}

size_t link_encode_config(const link_config *config, uint8_t *wire)
{
    uint8_t payload[11];
    put_u32(payload, config->odr_mhz);
    payload[4] = config->accel_fs_g;
    put_u16(payload + 5, config->gyro_fs_dps);
    put_u32(payload + 7, config->tick_ns);
    return link_frame(LINK_CONFIG, payload, sizeof payload, wire);
}

/* SAMPLES, or SAMPLES_INDEXED with the sensor index before the same layout. */
static size_t encode_samples(uint8_t type, uint8_t sensor_index, uint16_t seq, uint32_t t0,
                             int16_t temperature_raw, const int16_t (*samples)[6],
                             uint8_t count, uint8_t *wire)
{
    uint8_t payload[1u + LINK_SAMPLES_HEADER + LINK_MAX_SAMPLES * LINK_SAMPLE_BYTES];
    if (count == 0 || count > LINK_MAX_SAMPLES)
        return 0;
    uint8_t *p = payload;
    if (type == LINK_SAMPLES_INDEXED)
        *p++ = sensor_index;
    put_u16(p, seq);
    put_u32(p + 2, t0);
    p[6] = count;
    put_u16(p + 7, (uint16_t)temperature_raw);
    p += LINK_SAMPLES_HEADER;
    for (uint8_t i = 0; i < count; i++)
        for (int axis = 0; axis < 6; axis++, p += 2)
            put_u16(p, (uint16_t)samples[i][axis]);
    return link_frame(type, payload, (size_t)(p - payload), wire);
}

size_t link_encode_samples(uint16_t seq, uint32_t t0, int16_t temperature_raw,
                           const int16_t (*samples)[6], uint8_t count, uint8_t *wire)
{
    return encode_samples(LINK_SAMPLES, 0, seq, t0, temperature_raw, samples, count, wire);
}

size_t link_encode_samples_indexed(uint8_t sensor_index, uint16_t seq, uint32_t t0,
                                   int16_t temperature_raw, const int16_t (*samples)[6],
                                   uint8_t count, uint8_t *wire)
{
    if (sensor_index == 0 || sensor_index > 7)
        return 0;
    return encode_samples(LINK_SAMPLES_INDEXED, sensor_index, seq, t0, temperature_raw,
                          samples, count, wire);
}

size_t link_encode_sensor(const link_sensor *sensor, uint8_t *wire)
{
    uint8_t payload[LINK_SENSOR_PAYLOAD];
    payload[0] = sensor->index;
    payload[1] = sensor->count;
    payload[2] = sensor->address;
    payload[3] = sensor->who_am_i;
    put_u32(payload + 4, sensor->config.odr_mhz);
    payload[8] = sensor->config.accel_fs_g;
    put_u16(payload + 9, sensor->config.gyro_fs_dps);
    put_u32(payload + 11, sensor->config.tick_ns);
    payload[15] = sensor->flags;
    return link_frame(LINK_SENSOR, payload, sizeof payload, wire);
}

size_t link_encode_magnetometer(const link_magnetometer *mag, uint8_t *wire)
{
    uint8_t payload[LINK_MAGNETOMETER_PAYLOAD];
    payload[0] = mag->chip;
    payload[1] = mag->address;
    payload[2] = mag->who_am_i;
    put_u32(payload + 3, mag->odr_mhz);
    put_u16(payload + 7, mag->range_ut);
    put_u32(payload + 9, mag->pt_per_lsb);
    payload[13] = mag->mode;
    payload[14] = mag->flags;
    return link_frame(LINK_MAGNETOMETER, payload, sizeof payload, wire);
}

size_t link_encode_mag_samples(uint16_t seq, const uint32_t *t, const int16_t (*xyz)[3],
                               uint8_t count, uint8_t *wire)
{
    uint8_t payload[3u + 10u * LINK_MAG_MAX_SAMPLES];
    if (count < 1 || count > LINK_MAG_MAX_SAMPLES)
        return 0;
    put_u16(payload, seq);
    payload[2] = count;
    for (unsigned i = 0; i < count; i++) {
        uint8_t *row = payload + 3 + 10 * i;
        put_u32(row, t[i]);
        for (int axis = 0; axis < 3; axis++)
            put_u16(row + 4 + 2 * axis, (uint16_t)xyz[i][axis]);
    }
    return link_frame(LINK_MAG_SAMPLES, payload, 3u + 10u * count, wire);
}

size_t link_encode_ack(uint8_t command, uint8_t status, const char *message, uint8_t *wire)
{
    uint8_t payload[LINK_MAX_PAYLOAD];
    payload[0] = command;
    payload[1] = status;
    size_t n = text_length(message, LINK_MAX_PAYLOAD - 2);
    if (n)
        memcpy(payload + 2, message, n);
    return link_frame(LINK_ACK, payload, 2 + n, wire);
}

size_t link_encode_selftest(const link_selftest *result, uint8_t *wire)
{
    uint8_t payload[14];
    payload[0] = result->accel_pass;
    payload[1] = result->gyro_pass;
    for (int axis = 0; axis < 3; axis++) {
        put_u16(payload + 2 + 2 * axis, (uint16_t)result->accel_delta_mg[axis]);
        put_u16(payload + 8 + 2 * axis, (uint16_t)result->gyro_delta_dps[axis]);
    }
    return link_frame(LINK_SELFTEST, payload, sizeof payload, wire);
}

size_t link_encode_log(uint8_t level, const char *text, uint8_t *wire)
{
    uint8_t payload[LINK_MAX_PAYLOAD];
    payload[0] = level;
    size_t n = text_length(text, LINK_MAX_PAYLOAD - 1);
    if (n)
        memcpy(payload + 1, text, n);
    return link_frame(LINK_LOG, payload, 1 + n, wire);
}

size_t link_encode_pong(uint32_t token, uint8_t *wire)
{
    uint8_t payload[4];
    put_u32(payload, token);
    return link_frame(LINK_PONG, payload, sizeof payload, wire);
}

size_t link_encode_status(const link_status *status, uint8_t *wire)
{
    uint8_t payload[LINK_STATUS_PAYLOAD_MAG];
    const uint32_t counters[] = {
        status->uptime_ms, status->uart_tx_dropped_bytes, status->uart_rx_errors,
        status->i2c_errors, status->i2c_recoveries, status->i2c_retries,
        status->fifo_overruns, status->samples_read, status->samples_sent,
        status->watchdog_resets,
    };
    _Static_assert(3u + 4u * (sizeof counters / sizeof counters[0]) == LINK_STATUS_PAYLOAD,
                   "STATUS version 1 layout");
    bool with_mag = status->version == LINK_STATUS_VERSION_MAG;
    payload[0] = with_mag ? LINK_STATUS_VERSION_MAG : LINK_STATUS_VERSION;
    payload[1] = status->reset_cause;
    payload[2] = status->flags;
    for (size_t i = 0; i < sizeof counters / sizeof counters[0]; i++)
        put_u32(payload + 3 + 4 * i, counters[i]);
    if (!with_mag)
        return link_frame(LINK_STATUS, payload, LINK_STATUS_PAYLOAD, wire);
    put_u32(payload + LINK_STATUS_PAYLOAD, status->mag_i2c_errors);
    put_u32(payload + LINK_STATUS_PAYLOAD + 4, status->mag_samples_read);
    put_u32(payload + LINK_STATUS_PAYLOAD + 8, status->mag_overruns);
    return link_frame(LINK_STATUS, payload, LINK_STATUS_PAYLOAD_MAG, wire);
}

void link_rx_init(link_rx *rx)
{
    memset(rx, 0, sizeof *rx);
}

/* A whole frame (without its 0x00): undo COBS, check length and CRC. */
static bool unframe(link_rx *rx, size_t *packet_length)
{
    int n = cobs_decode(rx->frame, rx->length, rx->packet, sizeof rx->packet);
    if (n < 3)
        return false;
    size_t body = (size_t)n - 2;
    if (get_u16(rx->packet + body) != crc16(rx->packet, body))
        return false;
    *packet_length = (size_t)n;
    return true;
}

bool link_rx_feed(link_rx *rx, const uint8_t *data, size_t length, size_t *offset,
                  uint8_t *type, const uint8_t **payload, size_t *payload_length)
{
    while (*offset < length) {
        uint8_t byte = data[(*offset)++];
        if (byte != 0x00) {
            if (rx->discarding)
                continue;
            if (rx->length == sizeof rx->frame) {
                /* More than a frame without a delimiter: drop it all up to the next 0x00. */
                rx->discarding = true;
                rx->length = 0;
                rx->bad_frames++;
                continue;
            }
            rx->frame[rx->length++] = byte;
            continue;
        }
        if (rx->discarding) {
            rx->discarding = false;
            continue;
        }
        if (rx->length == 0)
            continue; /* an empty frame: the host's lone 0x00 */
        size_t packet_length = 0;
        bool good = unframe(rx, &packet_length);
        rx->length = 0;
        if (!good) {
            rx->bad_frames++;
            continue;
        }
        rx->frames++;
        *type = rx->packet[0];
        *payload = rx->packet + 1;
        *payload_length = packet_length - 3;
        return true;
    }
    return false;
}
