/* Command handling and streaming: the firmware's behaviour, independent of the board. */
#include "firmware.h"

#include <string.h>

#include "text.h"

#define MESSAGE_SIZE 160
/* Bits on I2C per FIFO word (7 bytes of 9 bits) and per poll (the FIFO_STATUS read and the
 * burst's address phases), and the share of the bus clock the firmware plans to use. */
#define I2C_BITS_PER_WORD 63u
#define I2C_BITS_PER_POLL 80u
#define I2C_USABLE_PERCENT 80u
#define TEMPERATURE_BATCH_MHZ 12500u
/* A full SAMPLES packet on the wire: 396 bytes + 2 of COBS + the 0x00, for 32 samples; a
 * SAMPLES_INDEXED one is a byte longer. */
#define WIRE_BYTES_PER_FULL_PACKET 399u
#define WIRE_BYTES_PER_FULL_INDEXED_PACKET 400u

static const lsm_settings DEFAULT_SETTINGS = {4, 4, 250}; /* 104 Hz, +-4 g, +-250 dps */

/* ---- sending */

static uint32_t now_us(fw_state *fw)
{
    return fw->platform->micros(fw->platform->ctx);
}

/* Replies wait (briefly) for transmit room; the host repeats a command whose reply is lost. */
static void send_reply(fw_state *fw, size_t length)
{
    const fw_platform *p = fw->platform;
    uint32_t start = now_us(fw);
    while (p->tx_free(p->ctx) < length) {
        if ((uint32_t)(now_us(fw) - start) > FW_REPLY_TIMEOUT_US) {
            fw->counters.tx_dropped_bytes += (uint32_t)length;
            return;
        }
        p->delay_us(p->ctx, 100);
    }
    p->tx_write(p->ctx, fw->wire, length);
}

static void send_ack(fw_state *fw, uint8_t command, uint8_t status, const char *message)
{
    send_reply(fw, link_encode_ack(command, status, message, fw->wire));
}

static void send_log(fw_state *fw, uint8_t level, const char *message)
{
    send_reply(fw, link_encode_log(level, message, fw->wire));
}

static void send_config(fw_state *fw)
{
    link_config config = {
        lsm_odr_mhz(&fw->chip), fw->chip.settings.accel_fs_g, fw->chip.settings.gyro_fs_dps,
        lsm_tick_ns(&fw->chip),
    };
    send_reply(fw, link_encode_config(&config, fw->wire));
}

static void send_info(fw_state *fw)
{
    link_info info = {
        {FW_VERSION_MAJOR, FW_VERSION_MINOR, FW_VERSION_PATCH}, fw->chip.who_am_i, {0},
        fw->identity.name,
    };
    memcpy(info.unique_id, fw->identity.unique_id, sizeof info.unique_id);
    send_reply(fw, link_encode_info(&info, fw->wire));
}

static void describe_pause(fw_state *fw, text *t);

/* SENSOR, one per sensor (docs/protocol.md, 0x0A), after CONFIG; a one-sensor board sends
 * none, so its bytes stay exactly those of plain v1. */
static void send_sensors(fw_state *fw)
{
    if (fw->sensor_count < 2)
        return;
    for (uint8_t i = 0; i < fw->sensor_count; i++) {
        const lsm6dsox *chip = i ? &fw->chip1 : &fw->chip;
        bool ok = i ? fw->sensor1_ok : fw->sensor_ok;
        link_sensor sensor = {
            i, fw->sensor_count, chip->address, chip->who_am_i,
            {lsm_odr_mhz(chip), chip->settings.accel_fs_g, chip->settings.gyro_fs_dps,
             lsm_tick_ns(chip)},
            (uint8_t)((ok ? LINK_SENSOR_ANSWERING : 0u) |
                      (i && fw->sensor1_paused ? LINK_SENSOR_PAUSED : 0u)),
        };
        send_reply(fw, link_encode_sensor(&sensor, fw->wire));
    }
    if (fw->sensor1_paused) {
        char message[MESSAGE_SIZE];
        text t;
        text_init(&t, message, sizeof message);
        describe_pause(fw, &t);
        send_log(fw, LINK_LOG_INFO, message);
    }
}

/* MAGNETOMETER after CONFIG and the SENSOR packets (docs/protocol.md, 0x0C); a board
 * without a magnetometer sends none, so its bytes stay those it sent before. A paused one
 * is followed by a LOG saying why. */
static void send_magnetometer(fw_state *fw)
{
    if (!fw->mag_found)
        return;
    link_magnetometer packet = {
        fw->mag.chip, fw->mag.address, fw->mag.who_am_i,
        mag_rate_mhz(fw->mag.chip, lsm_odr_nominal_mhz(fw->chip.settings.odr_code)),
        mag_range_ut(fw->mag.chip), mag_pt_per_lsb(fw->mag.chip), mag_mode(fw->mag.chip),
        (uint8_t)((fw->mag_ok ? LINK_MAG_ANSWERING : 0u) |
                  (fw->mag_paused ? LINK_MAG_PAUSED : 0u)),
    };
    send_reply(fw, link_encode_magnetometer(&packet, fw->wire));
    if (fw->mag_paused) {
        char message[MESSAGE_SIZE];
        text t;
        text_init(&t, message, sizeof message);
        text_str(&t, "magnetometer (");
        text_str(&t, mag_chip_name(fw->mag.chip));
        text_str(&t, ") paused: ");
        text_mhz(&t, lsm_odr_label_mhz(fw->chip.settings.odr_code));
        text_str(&t, " Hz leaves no room for its ");
        text_mhz(&t, packet.odr_mhz);
        text_str(&t, " Hz on the UART or I2C");
        send_log(fw, LINK_LOG_INFO, message);
    }
}

/* One field sample, sent at once (MAG_SAMPLES never waits: without room it is dropped, its
 * sequence number skipped). */
static void send_mag_sample(fw_state *fw, uint32_t ticks, const int16_t xyz[3])
{
    const fw_platform *p = fw->platform;
    int16_t rows[1][3] = {{xyz[0], xyz[1], xyz[2]}};
    size_t n = link_encode_mag_samples(fw->mag_seq++, &ticks, (const int16_t(*)[3])rows, 1,
                                       fw->wire);
    if (p->tx_free(p->ctx) >= n) {
        p->tx_write(p->ctx, fw->wire, n);
        fw->counters.mag_samples_sent++;
    } else {
        fw->counters.tx_dropped_bytes += (uint32_t)n;
    }
}

/* SAMPLES never wait: without room the packet is dropped and its sequence number tells.
 * Sensor 0's go out as SAMPLES, sensor 1's as SAMPLES_INDEXED. */
static void send_packet(fw_state *fw, uint8_t sensor, const fifo_packet *packet)
{
    const fw_platform *p = fw->platform;
    size_t n = sensor
        ? link_encode_samples_indexed(sensor, packet->seq, packet->t0, packet->temperature_raw,
                                      (const int16_t(*)[6])packet->samples, packet->count,
                                      fw->wire)
        : link_encode_samples(packet->seq, packet->t0, packet->temperature_raw,
                              (const int16_t(*)[6])packet->samples, packet->count, fw->wire);
    if (p->tx_free(p->ctx) >= n) {
        p->tx_write(p->ctx, fw->wire, n);
        fw->counters.samples_sent += packet->count;
    } else {
        fw->counters.tx_dropped_packets++;
        fw->counters.tx_dropped_bytes += (uint32_t)n;
    }
}

static void send_samples(void *ctx, const fifo_packet *packet)
{
    send_packet(ctx, 0, packet);
}

static void send_samples1(void *ctx, const fifo_packet *packet)
{
    send_packet(ctx, 1, packet);
}

/* ---- STATUS (docs/protocol.md, 0x08) */

void fw_status(fw_state *fw, link_status *status)
{
    fw_board_health board = {0};
    const fw_platform *p = fw->platform;
    if (p->board_health)
        p->board_health(p->ctx, &board);
    memset(status, 0, sizeof *status);
    status->reset_cause = board.reset_cause;
    status->flags = (uint8_t)((fw->streaming ? LINK_STATUS_STREAMING : 0u) |
                              (fw->sensor_ok ? LINK_STATUS_SENSOR_OK : 0u) |
                              (board.clock_fallback ? LINK_STATUS_CLOCK_FALLBACK : 0u));
    status->uptime_ms = (uint32_t)(fw->uptime_us / 1000u);
    status->uart_tx_dropped_bytes = fw->counters.tx_dropped_bytes + board.uart_tx_dropped_bytes;
    status->uart_rx_errors = board.uart_rx_errors;
    status->i2c_errors = fw->counters.i2c_errors;
    status->i2c_recoveries = board.i2c_recoveries;
    status->i2c_retries = fw->counters.i2c_retries;
    /* Per board: every sensor's overruns and samples add up. */
    status->fifo_overruns = fw->stream.counters.overruns + fw->stream1.counters.overruns;
    status->samples_read = fw->stream.counters.samples + fw->stream1.counters.samples;
    status->samples_sent = fw->counters.samples_sent;
    status->watchdog_resets = board.watchdog_resets;
    if (fw->mag_found) { /* version 2: the magnetometer's counters */
        status->version = LINK_STATUS_VERSION_MAG;
        status->mag_i2c_errors = fw->counters.mag_i2c_errors;
        status->mag_samples_read = fw->counters.mag_samples_read;
        status->mag_overruns = fw->counters.mag_overruns;
    }
}

static void update_uptime(fw_state *fw)
{
    uint32_t now = now_us(fw);
    fw->uptime_us += (uint32_t)(now - fw->uptime_last_us);
    fw->uptime_last_us = now;
}

/* On request a reply (waits for room); while streaming never waits (dropped when full). */
static void send_status(fw_state *fw, bool reply)
{
    const fw_platform *p = fw->platform;
    link_status status;
    update_uptime(fw);
    fw_status(fw, &status);
    size_t n = link_encode_status(&status, fw->wire);
    fw->last_status_us = now_us(fw);
    fw->counters.status_sent++;
    if (reply) {
        send_reply(fw, n);
    } else if (p->tx_free(p->ctx) >= n) {
        p->tx_write(p->ctx, fw->wire, n);
    } else {
        fw->counters.tx_dropped_bytes += (uint32_t)n;
    }
}

/* ---- the sensor's bus: the board's I2C with every failed transfer counted */

static int counted_i2c_write(void *ctx, uint8_t address, uint8_t reg, const uint8_t *data,
                             size_t length)
{
    fw_state *fw = ctx;
    int err = fw->platform->i2c_write(fw->platform->ctx, address, reg, data, length);
    if (err)
        fw->counters.i2c_errors++;
    return err;
}

static int counted_i2c_read(void *ctx, uint8_t address, uint8_t reg, uint8_t *data,
                            size_t length)
{
    fw_state *fw = ctx;
    int err = fw->platform->i2c_read(fw->platform->ctx, address, reg, data, length);
    if (err)
        fw->counters.i2c_errors++;
    return err;
}

/* The magnetometer's transfers: counted as every sensor's, and as its own. */
static int mag_i2c_write(void *ctx, uint8_t address, uint8_t reg, const uint8_t *data,
                         size_t length)
{
    fw_state *fw = ctx;
    int err = counted_i2c_write(ctx, address, reg, data, length);
    if (err)
        fw->counters.mag_i2c_errors++;
    return err;
}

static int mag_i2c_read(void *ctx, uint8_t address, uint8_t reg, uint8_t *data, size_t length)
{
    fw_state *fw = ctx;
    int err = counted_i2c_read(ctx, address, reg, data, length);
    if (err)
        fw->counters.mag_i2c_errors++;
    return err;
}

static uint32_t bus_micros(void *ctx)
{
    fw_state *fw = ctx;
    return fw->platform->micros(fw->platform->ctx);
}

static void bus_delay_us(void *ctx, uint32_t us)
{
    fw_state *fw = ctx;
    fw->platform->delay_us(fw->platform->ctx, us);
}

static size_t bus_tx_free(void *ctx)
{
    fw_state *fw = ctx;
    return fw->platform->tx_free(fw->platform->ctx);
}

static void bus_tx_write(void *ctx, const uint8_t *data, size_t length)
{
    fw_state *fw = ctx;
    fw->platform->tx_write(fw->platform->ctx, data, length);
}

/* ---- the sensor */

static void describe_sensor_error(fw_state *fw, int err, text *t)
{
    switch (err) {
    case LSM_ERR_WHO_AM_I:
        text_str(t, "WHO_AM_I at I2C address ");
        text_hex8(t, fw->chip.address);
        text_str(t, " reads ");
        text_hex8(t, fw->chip.who_am_i);
        text_str(t, ", an LSM6DSOX answers 0x6C: another part on the bus?");
        break;
    case LSM_ERR_RESET:
        text_str(t, "the LSM6DSOX software reset did not finish within 50 ms");
        break;
    case LSM_ERR_READBACK:
        text_str(t, "the LSM6DSOX did not keep its configuration (register read-back differs)");
        break;
    case LSM_ERR_NO_DATA:
        text_str(t, "the LSM6DSOX produced no new data during the self-test");
        break;
    default:
        text_str(t, "no LSM6DSOX answers on I2C1 (PB8 SCL, PB9 SDA) at 0x6A or 0x6B: "
                    "check the wiring, the 3.3 V supply and the pull-ups");
        break;
    }
}

/* Probe (when needed) and configure with the current settings; false on failure, with a
 * message in `t` when given. */
static int probe_sensor0(fw_state *fw)
{
    /* With two sensors, 0x6B is sensor 1's: sensor 0 is looked for at 0x6A only. */
    return fw->sensor_count > 1 ? lsm_probe_at(&fw->chip, LSM6DSOX_ADDRESS_SA0_LOW)
                                : lsm_probe(&fw->chip);
}

/* Sensor 1 with sensor 0's settings; false when it does not answer (sensor 0 goes on). */
static bool bring_up_sensor1(fw_state *fw)
{
    if (fw->sensor_count < 2)
        return false;
    int err = fw->chip1.address && fw->chip1.who_am_i == LSM6DSOX_WHO_AM_I_VALUE
        ? LSM_OK : lsm_probe_at(&fw->chip1, LSM6DSOX_ADDRESS_SA0_HIGH);
    if (!err)
        err = lsm_configure(&fw->chip1, &fw->chip.settings);
    if (err == LSM_ERR_BUS && fw->chip1.address) {
        err = lsm_probe_at(&fw->chip1, LSM6DSOX_ADDRESS_SA0_HIGH);
        if (!err)
            err = lsm_configure(&fw->chip1, &fw->chip.settings);
    }
    fw->sensor1_ok = err == LSM_OK;
    if (!fw->sensor1_ok)
        fw->counters.bus_errors++;
    return fw->sensor1_ok;
}

/* At power-on: a second LSM6DSOX at 0x6B when sensor 0 answered at 0x6A. */
static void find_second_sensor(fw_state *fw)
{
    fw->sensor_count = 1;
    if (!fw->sensor_ok || fw->chip.address != LSM6DSOX_ADDRESS_SA0_LOW)
        return;
    if (lsm_probe_at(&fw->chip1, LSM6DSOX_ADDRESS_SA0_HIGH) != LSM_OK) {
        fw->chip1.address = 0;
        return;
    }
    fw->sensor_count = 2;
    bring_up_sensor1(fw);
}

/* The magnetometer at the rate for sensor 0's; false when it does not answer. */
static bool bring_up_mag(fw_state *fw)
{
    if (!fw->mag_found)
        return false;
    int err = mag_configure(&fw->mag, lsm_odr_nominal_mhz(fw->chip.settings.odr_code));
    if (err == MAG_ERR_BUS && mag_probe(&fw->mag) == MAG_OK)
        err = mag_configure(&fw->mag, lsm_odr_nominal_mhz(fw->chip.settings.odr_code));
    fw->mag_ok = err == MAG_OK;
    fw->mag_failures = 0;
    fw->mag_primed = false;
    fw->last_retry_mag_us = now_us(fw);
    return fw->mag_ok;
}

/* At power-on: an LIS3MDL at 0x1C or 0x1E, or an LIS2MDL at 0x1E. */
static void find_magnetometer(fw_state *fw)
{
    /* Probed on the board's own bus: most boards have none, and its absence is no error
     * (the probes would add three failed transfers to every board's STATUS). */
    mag_init(&fw->mag, fw->platform);
    fw->mag_found = mag_probe(&fw->mag) == MAG_OK;
    fw->mag.bus = &fw->mag_bus;
    bring_up_mag(fw);
}

static bool bring_up_sensor(fw_state *fw, text *t)
{
    int err = fw->chip.address && fw->chip.who_am_i == LSM6DSOX_WHO_AM_I_VALUE
        ? LSM_OK : probe_sensor0(fw);
    if (!err)
        err = lsm_configure(&fw->chip, &fw->chip.settings);
    if (err == LSM_ERR_BUS && fw->chip.address) {
        /* Answered before but not now: probe again (another address after a swap). */
        err = probe_sensor0(fw);
        if (!err)
            err = lsm_configure(&fw->chip, &fw->chip.settings);
    }
    fw->sensor_ok = err == LSM_OK;
    if (!fw->sensor_ok) {
        fw->counters.bus_errors++;
        if (t)
            describe_sensor_error(fw, err, t);
    } else if (fw->sensor_count > 1) {
        bring_up_sensor1(fw); /* configured alike, whenever sensor 0 is */
        fw->last_retry1_us = now_us(fw);
    }
    return fw->sensor_ok;
}

/* Samples of the turn-on transient still ahead: the larger of the accelerometer's and the
 * gyroscope's discard count (a sample carries both), less the samples the chip has produced
 * since it was configured (counted 2 % short, so an MCU clock running fast cannot cut the
 * discard short). Discarding keeps the protocol's rule that a packet's samples are
 * consecutive and valid, where marking would need a flag v1 does not have. */
static uint32_t settling_samples_left(fw_state *fw, const lsm6dsox *chip)
{
    uint8_t code = chip->settings.odr_code;
    uint32_t accel = lsm_turn_on_discard(code, false), gyro = lsm_turn_on_discard(code, true);
    uint32_t needed = accel > gyro ? accel : gyro;
    uint64_t elapsed_us = (uint32_t)(now_us(fw) - chip->configured_us);
    uint64_t produced = elapsed_us * lsm_odr_mhz(chip) * 98u / 100000000000u;
    return produced >= needed ? 0u : needed - (uint32_t)produced;
}

/* Whether sensor 1 streams: it answers and the rate fits both sensors. */
static bool sensor1_streams(const fw_state *fw)
{
    return fw->sensor1_ok && !fw->sensor1_paused;
}

/* Sensor 1's stream; a failure loses sensor 1 only. */
static void start_stream1(fw_state *fw)
{
    int16_t temperature = 0;
    if (!fw->sensor1_ok || fw->sensor1_paused)
        return;
    int err = lsm_fifo_reset(&fw->chip1, true);
    if (!err)
        err = lsm_read_temperature(&fw->chip1, &temperature);
    if (err) {
        fw->sensor1_ok = false;
        fw->last_retry1_us = now_us(fw);
        return;
    }
    fifo_stream_restart(&fw->stream1, lsm_odr_nominal_mhz(fw->chip1.settings.odr_code),
                        temperature);
    fifo_stream_discard(&fw->stream1, settling_samples_left(fw, &fw->chip1));
}

static bool start_stream(fw_state *fw)
{
    int16_t temperature = 0;
    int err = lsm_fifo_reset(&fw->chip, true);
    if (!err)
        err = lsm_read_temperature(&fw->chip, &temperature);
    if (err)
        return false;
    fifo_stream_restart(&fw->stream, lsm_odr_nominal_mhz(fw->chip.settings.odr_code),
                        temperature);
    fifo_stream_discard(&fw->stream, settling_samples_left(fw, &fw->chip));
    start_stream1(fw);
    fw->streaming = true;
    fw->last_poll_us = now_us(fw);
    return true;
}

static void sensor_lost(fw_state *fw)
{
    char message[MESSAGE_SIZE];
    text t;
    text_init(&t, message, sizeof message);
    text_str(&t, "the LSM6DSOX at ");
    text_hex8(&t, fw->chip.address);
    text_str(&t, " stopped answering on I2C1; looking for it every 0.5 s");
    fw->counters.bus_errors++;
    fw->sensor_ok = false;
    fw->chip.configured = false;
    if (fw->streaming) {
        fifo_stream_flush(&fw->stream, now_us(fw), true, send_samples, fw);
        if (sensor1_streams(fw))
            fifo_stream_flush(&fw->stream1, now_us(fw), true, send_samples1, fw);
        fw->streaming = false;
    }
    fw->last_retry_us = now_us(fw);
    send_log(fw, LINK_LOG_ERROR, message);
}

static void sensor1_lost(fw_state *fw)
{
    fw->counters.bus_errors++;
    fw->sensor1_ok = false;
    fw->chip1.configured = false;
    fifo_stream_flush(&fw->stream1, now_us(fw), true, send_samples1, fw);
    fw->last_retry1_us = now_us(fw);
    send_log(fw, LINK_LOG_ERROR, "sensor 1, the LSM6DSOX at 0x6B, stopped answering on I2C1; "
                                 "sensor 0 goes on, looking for it every 0.5 s");
}

/* ---- rates */

/* Milli-bytes per second on the UART for `sensors` streaming at `odr_mhz` (full packets). */
static uint64_t uart_need_milli(uint32_t odr_mhz, uint8_t sensors)
{
    return (uint64_t)odr_mhz *
        (WIRE_BYTES_PER_FULL_PACKET + (sensors - 1u) * WIRE_BYTES_PER_FULL_INDEXED_PACKET) /
        LINK_MAX_SAMPLES;
}

/* Bits per second on I2C to drain `sensors` FIFOs at `odr_mhz`, polls included. */
static uint64_t i2c_need_bits(uint32_t odr_mhz, uint8_t sensors)
{
    uint64_t words_milli = (uint64_t)odr_mhz * (2u * LSM_TIMESTAMP_DECIMATION + 1u) /
                           LSM_TIMESTAMP_DECIMATION + TEMPERATURE_BATCH_MHZ;
    return sensors * (words_milli * I2C_BITS_PER_WORD / 1000u +
                      (uint64_t)I2C_BITS_PER_POLL * (1000000u / FW_POLL_INTERVAL_US));
}

bool fw_mag_fits(uint8_t odr_code, uint32_t baud, uint32_t i2c_hz, uint8_t sensors,
                 uint32_t mag_odr_mhz)
{
    uint32_t odr_mhz = lsm_odr_nominal_mhz(odr_code);
    if (!odr_mhz)
        return false;
    if (sensors < 1)
        sensors = 1;
    uint64_t bytes_milli = uart_need_milli(odr_mhz, sensors) +
                           (uint64_t)mag_odr_mhz * FW_MAG_WIRE_BYTES;
    if (baud && bytes_milli * 10u > (uint64_t)baud * 1000u)
        return false;
    uint64_t bits = i2c_need_bits(odr_mhz, sensors) +
                    (uint64_t)mag_odr_mhz * FW_MAG_I2C_BITS / 1000u;
    return !i2c_hz || bits <= (uint64_t)i2c_hz * I2C_USABLE_PERCENT / 100u;
}

bool fw_rate_fits(uint8_t odr_code, uint32_t baud, uint32_t i2c_hz, char *why, size_t size)
{
    return fw_rate_fits_sensors(odr_code, baud, i2c_hz, 1, why, size);
}

bool fw_rate_fits_sensors(uint8_t odr_code, uint32_t baud, uint32_t i2c_hz, uint8_t sensors,
                          char *why, size_t size)
{
    uint32_t odr_mhz = lsm_odr_nominal_mhz(odr_code);
    if (sensors < 1)
        sensors = 1;
    text t;
    text_init(&t, why, size);
    if (!odr_mhz) {
        text_str(&t, "unknown ODR code");
        return false;
    }
    /* UART, 8N1: baud / 10 bytes/s; full packets take 399 bytes per 32 samples. */
    uint64_t need_bytes_milli = uart_need_milli(odr_mhz, sensors);
    if (baud && need_bytes_milli * 10u > (uint64_t)baud * 1000u) {
        uint8_t highest = (uint8_t)(odr_code - 1u);
        while (highest > LSM_ODR_CODE_MIN &&
               !fw_rate_fits_sensors(highest, baud, 0, sensors, NULL, 0))
            highest--;
        text_str(&t, "ODR ");
        text_mhz(&t, lsm_odr_label_mhz(odr_code));
        text_str(&t, " Hz needs ");
        text_u32(&t, (uint32_t)(need_bytes_milli / 1000u));
        text_str(&t, " bytes/s; the UART at ");
        text_u32(&t, baud);
        text_str(&t, " baud carries ");
        text_u32(&t, baud / 10u);
        if (sensors > 1) {
            text_str(&t, " for ");
            text_u32(&t, sensors);
            text_str(&t, " sensors");
        }
        text_str(&t, " (highest ODR ");
        text_mhz(&t, lsm_odr_label_mhz(highest));
        text_str(&t, " Hz)");
        return false;
    }
    /* I2C: per sample a gyroscope and an accelerometer word, a timestamp word every 8th
     * slot, temperature words at 12.5 Hz, and the polls' own traffic. */
    if (i2c_hz) {
        uint64_t need_bits = i2c_need_bits(odr_mhz, sensors);
        uint64_t usable_bits = (uint64_t)i2c_hz * I2C_USABLE_PERCENT / 100u;
        if (need_bits > usable_bits) {
            uint8_t highest = (uint8_t)(odr_code - 1u);
            while (highest > LSM_ODR_CODE_MIN &&
                   !fw_rate_fits_sensors(highest, 0, i2c_hz, sensors, NULL, 0))
                highest--;
            text_str(&t, "ODR ");
            text_mhz(&t, lsm_odr_label_mhz(odr_code));
            text_str(&t, " Hz needs about ");
            text_u32(&t, (uint32_t)(need_bits / 1000u));
            text_str(&t, " kbit/s on I2C1");
            if (sensors > 1) {
                text_str(&t, " for ");
                text_u32(&t, sensors);
                text_str(&t, " sensors");
            }
            text_str(&t, "; the bus at ");
            text_u32(&t, i2c_hz / 1000u);
            text_str(&t, " kHz carries about ");
            text_u32(&t, (uint32_t)(usable_bits / 1000u));
            text_str(&t, " (highest ODR ");
            text_mhz(&t, lsm_odr_label_mhz(highest));
            text_str(&t, " Hz)");
            return false;
        }
    }
    return true;
}

/* A rate that fits sensor 0 alone pauses sensor 1 (docs/protocol.md, "Several sensors on one
 * board"): v1 hosts keep every rate a one-sensor board has. */
static void update_pause(fw_state *fw)
{
    fw->sensor1_paused = fw->sensor_count > 1 &&
        !fw_rate_fits_sensors(fw->chip.settings.odr_code, fw->identity.baud,
                              fw->identity.i2c_hz, fw->sensor_count, NULL, 0);
    /* The magnetometer yields to the sensors: paused where they leave it no room. */
    uint8_t streaming = fw->sensor1_paused ? 1u : fw->sensor_count;
    fw->mag_paused = fw->mag_found &&
        !fw_mag_fits(fw->chip.settings.odr_code, fw->identity.baud, fw->identity.i2c_hz,
                     streaming, mag_rate_mhz(fw->mag.chip,
                                             lsm_odr_nominal_mhz(fw->chip.settings.odr_code)));
}

/* "sensor 1 (0x6B) paused: 1667 Hz does not fit two sensors on I2C 400 kHz (highest 833 Hz)" */
static void describe_pause(fw_state *fw, text *t)
{
    uint8_t code = fw->chip.settings.odr_code, highest = code;
    uint32_t baud = fw->identity.baud, i2c_hz = fw->identity.i2c_hz;
    while (highest > LSM_ODR_CODE_MIN &&
           !fw_rate_fits_sensors(highest, baud, i2c_hz, fw->sensor_count, NULL, 0))
        highest--;
    text_str(t, "sensor 1 (");
    text_hex8(t, fw->chip1.address);
    text_str(t, ") paused: ");
    text_mhz(t, lsm_odr_label_mhz(code));
    text_str(t, " Hz does not fit two sensors on ");
    if (!fw_rate_fits_sensors(code, 0, i2c_hz, fw->sensor_count, NULL, 0)) {
        text_str(t, "I2C ");
        text_u32(t, i2c_hz / 1000u);
        text_str(t, " kHz");
    } else {
        text_str(t, "the UART at ");
        text_u32(t, baud);
        text_str(t, " baud");
    }
    text_str(t, " (highest ");
    text_mhz(t, lsm_odr_label_mhz(highest));
    text_str(t, " Hz)");
}

/* ---- commands */

static bool check_length(fw_state *fw, uint8_t command, size_t length, size_t expected)
{
    if (length == expected)
        return true;
    char message[MESSAGE_SIZE];
    text t;
    text_init(&t, message, sizeof message);
    text_str(&t, "payload of ");
    text_u32(&t, (uint32_t)length);
    text_str(&t, " bytes, expected ");
    text_u32(&t, (uint32_t)expected);
    send_ack(fw, command, LINK_ACK_BAD_ARGUMENT, message);
    return false;
}

static void on_hello(fw_state *fw)
{
    char message[MESSAGE_SIZE];
    text t;
    text_init(&t, message, sizeof message);
    if (!fw->sensor_ok)
        bring_up_sensor(fw, &t);
    send_info(fw);
    send_config(fw);
    send_sensors(fw);
    send_magnetometer(fw);
    if (!fw->sensor_ok)
        send_log(fw, LINK_LOG_ERROR, message);
}

/* The reason a CONFIGURE is refused, or LINK_ACK_OK. */
static uint8_t check_configure(fw_state *fw, const lsm_settings *s, text *t)
{
    if (!lsm_odr_nominal_mhz(s->odr_code)) {
        text_str(t, "odr_code ");
        text_u32(t, s->odr_code);
        text_str(t, ": use 1 (12.5 Hz) to 10 (6667 Hz)");
        return LINK_ACK_BAD_ARGUMENT;
    }
    if (lsm_fs_xl_code(s->accel_fs_g) < 0) {
        text_str(t, "accel_fs_g ");
        text_u32(t, s->accel_fs_g);
        text_str(t, ": use 2, 4, 8 or 16");
        return LINK_ACK_BAD_ARGUMENT;
    }
    if (lsm_fs_g_code(s->gyro_fs_dps) < 0) {
        text_str(t, "gyro_fs_dps ");
        text_u32(t, s->gyro_fs_dps);
        text_str(t, ": use 125, 250, 500, 1000 or 2000");
        return LINK_ACK_BAD_ARGUMENT;
    }
    if (fw->streaming) {
        text_str(t, "streaming: send STOP first");
        return LINK_ACK_BUSY;
    }
    /* The rule of a one-sensor board: a rate only sensor 0 fits pauses sensor 1. */
    if (!fw_rate_fits(s->odr_code, fw->identity.baud, fw->identity.i2c_hz, t->buf, t->size)) {
        t->length = strlen(t->buf);
        return LINK_ACK_BAD_ARGUMENT;
    }
    return LINK_ACK_OK;
}

static void on_configure(fw_state *fw, const uint8_t *payload)
{
    char message[MESSAGE_SIZE];
    text t;
    text_init(&t, message, sizeof message);
    lsm_settings wanted = {payload[0], payload[1], get_u16(payload + 2)};
    uint8_t status = check_configure(fw, &wanted, &t);
    if (status == LINK_ACK_OK) {
        lsm_settings previous = fw->chip.settings;
        fw->chip.settings = wanted;
        if (!bring_up_sensor(fw, &t)) {
            fw->chip.settings = previous;
            status = LINK_ACK_SENSOR_ERROR;
        }
        bring_up_mag(fw); /* its rate follows sensor 0's */
        update_pause(fw);
    }
    send_ack(fw, LINK_CONFIGURE, status, message);
    send_config(fw);
    send_sensors(fw);
    send_magnetometer(fw);
}

static void on_start(fw_state *fw)
{
    char message[MESSAGE_SIZE];
    text t;
    text_init(&t, message, sizeof message);
    if (fw->streaming) {
        send_ack(fw, LINK_START, LINK_ACK_OK, "already streaming");
        return;
    }
    if ((!fw->sensor_ok && !bring_up_sensor(fw, &t)) || !start_stream(fw)) {
        if (!t.length) {
            fw->sensor_ok = false;
            describe_sensor_error(fw, LSM_ERR_BUS, &t);
        }
        send_ack(fw, LINK_START, LINK_ACK_SENSOR_ERROR, message);
        return;
    }
    fw->want_streaming = true;
    send_ack(fw, LINK_START, LINK_ACK_OK, NULL);
    text_str(&t, "streaming ");
    text_mhz(&t, lsm_odr_label_mhz(fw->chip.settings.odr_code));
    text_str(&t, " Hz (really ");
    text_mhz(&t, lsm_odr_mhz(&fw->chip));
    text_str(&t, " Hz), +-");
    text_u32(&t, fw->chip.settings.accel_fs_g);
    text_str(&t, " g, +-");
    text_u32(&t, fw->chip.settings.gyro_fs_dps);
    text_str(&t, " dps from the LSM6DSOX at ");
    text_hex8(&t, fw->chip.address);
    if (fw->sensor_count > 1) {
        text_str(&t, sensor1_streams(fw) ? " and, as sensor 1, at " : " (sensor 1 at ");
        text_hex8(&t, fw->chip1.address);
        if (fw->sensor1_paused)
            text_str(&t, " paused: the rate does not fit two sensors)");
        else if (!fw->sensor1_ok)
            text_str(&t, " does not answer)");
    }
    if (fw->mag_found) {
        text_str(&t, "; magnetometer ");
        text_str(&t, mag_chip_name(fw->mag.chip));
        text_str(&t, " at ");
        text_hex8(&t, fw->mag.address);
        text_str(&t, fw->mag_paused ? " paused" : fw->mag_ok ? ", " : " not answering");
        if (fw->mag_ok && !fw->mag_paused) {
            text_mhz(&t, fw->mag.odr_mhz);
            text_str(&t, " Hz");
        }
    }
    fw->mag_primed = false;
    fw->mag_last_us = now_us(fw);
    send_log(fw, LINK_LOG_INFO, message);
    send_status(fw, true); /* the counters at the start, for the host to compare with */
}

static void on_stop(fw_state *fw)
{
    if (fw->streaming) {
        fifo_stream_flush(&fw->stream, now_us(fw), true, send_samples, fw);
        if (sensor1_streams(fw))
            fifo_stream_flush(&fw->stream1, now_us(fw), true, send_samples1, fw);
        fw->streaming = false;
        if (lsm_fifo_reset(&fw->chip, false))
            fw->sensor_ok = false;
        if (fw->sensor1_ok && lsm_fifo_reset(&fw->chip1, false))
            fw->sensor1_ok = false;
    }
    fw->want_streaming = false;
    send_ack(fw, LINK_STOP, LINK_ACK_OK, NULL);
}

static void on_self_test(fw_state *fw)
{
    char message[MESSAGE_SIZE];
    text t;
    text_init(&t, message, sizeof message);
    if (fw->streaming) {
        send_ack(fw, LINK_SELF_TEST, LINK_ACK_BUSY, "streaming: send STOP first");
        return;
    }
    if (!fw->sensor_ok && !bring_up_sensor(fw, &t)) {
        send_ack(fw, LINK_SELF_TEST, LINK_ACK_SENSOR_ERROR, message);
        return;
    }
    lsm_self_test_result result;
    int err = lsm_self_test(&fw->chip, &result);
    if (err) {
        fw->sensor_ok = false;
        describe_sensor_error(fw, err, &t);
        send_ack(fw, LINK_SELF_TEST, LINK_ACK_SENSOR_ERROR, message);
        return;
    }
    send_ack(fw, LINK_SELF_TEST, LINK_ACK_OK, NULL);
    link_selftest packet = {result.accel_pass, result.gyro_pass, {0}, {0}};
    memcpy(packet.accel_delta_mg, result.accel_delta_mg, sizeof packet.accel_delta_mg);
    memcpy(packet.gyro_delta_dps, result.gyro_delta_dps, sizeof packet.gyro_delta_dps);
    send_reply(fw, link_encode_selftest(&packet, fw->wire));
}

static void handle(fw_state *fw, uint8_t type, const uint8_t *payload, size_t length)
{
    fw->counters.commands++;
    switch (type) {
    case LINK_HELLO:
        if (check_length(fw, type, length, 0))
            on_hello(fw);
        break;
    case LINK_CONFIGURE:
        if (check_length(fw, type, length, 4))
            on_configure(fw, payload);
        else
            send_config(fw);
        break;
    case LINK_START:
        if (check_length(fw, type, length, 0))
            on_start(fw);
        break;
    case LINK_STOP:
        if (check_length(fw, type, length, 0))
            on_stop(fw);
        break;
    case LINK_SELF_TEST:
        if (check_length(fw, type, length, 0))
            on_self_test(fw);
        break;
    case LINK_PING:
        if (check_length(fw, type, length, 4))
            send_reply(fw, link_encode_pong(get_u32(payload), fw->wire));
        break;
    case LINK_GET_STATUS:
        if (check_length(fw, type, length, 0))
            send_status(fw, true);
        break;
    default: {
        char message[MESSAGE_SIZE];
        text t;
        text_init(&t, message, sizeof message);
        text_str(&t, "unknown command ");
        text_hex8(&t, type);
        text_str(&t, " (protocol v1)");
        send_ack(fw, type, LINK_ACK_UNSUPPORTED, message);
        break;
    }
    }
}

/* ---- the loop */

void fw_init(fw_state *fw, const fw_platform *platform, const fw_identity *identity)
{
    memset(fw, 0, sizeof *fw);
    fw->platform = platform;
    fw->identity = *identity;
    fw->sensor_bus = (fw_platform){fw, counted_i2c_write, counted_i2c_read, bus_micros,
                                   bus_delay_us, bus_tx_free, bus_tx_write, NULL};
    fw->mag_bus = (fw_platform){fw, mag_i2c_write, mag_i2c_read, bus_micros, bus_delay_us,
                                bus_tx_free, bus_tx_write, NULL};
    fw->uptime_last_us = now_us(fw);
    link_rx_init(&fw->rx);
    lsm_init(&fw->chip, &fw->sensor_bus);
    lsm_init(&fw->chip1, &fw->sensor_bus);
    fw->chip.settings = DEFAULT_SETTINGS;
    fw->chip1.settings = DEFAULT_SETTINGS;
    fw->sensor_count = 1;
    fifo_stream_init(&fw->stream, FW_FLUSH_AFTER_US);
    fifo_stream_init(&fw->stream1, FW_FLUSH_AFTER_US);
    platform->delay_us(platform->ctx, FW_SENSOR_BOOT_US); /* powered up with the board */
    bring_up_sensor(fw, NULL);
    find_second_sensor(fw);
    find_magnetometer(fw);
    update_pause(fw);
    fw->last_retry_us = now_us(fw);
}

void fw_receive(fw_state *fw, const uint8_t *data, size_t length)
{
    size_t offset = 0;
    uint8_t type;
    const uint8_t *payload;
    size_t payload_length;
    while (link_rx_feed(&fw->rx, data, length, &offset, &type, &payload, &payload_length))
        handle(fw, type, payload, payload_length);
}

/* One glitch on the bus (noise, a recovered bus) must not stop the stream: a failed FIFO
 * transfer is tried again up to FW_I2C_RETRIES times, each counted, before the sensor is
 * declared lost. A burst read that failed part-way may have popped words on the chip; the
 * stream then sees a TAG_CNT jump and cuts the packet there (a measured gap, not a wrong
 * sample). */
static int fifo_status_retrying(fw_state *fw, lsm6dsox *chip, uint16_t *words,
                                bool *overrun)
{
    int err = lsm_fifo_status(chip, words, overrun);
    for (unsigned i = 0; err && i < FW_I2C_RETRIES; i++) {
        fw->counters.i2c_retries++;
        err = lsm_fifo_status(chip, words, overrun);
    }
    return err;
}

static int fifo_read_retrying(fw_state *fw, lsm6dsox *chip, uint16_t words)
{
    int err = lsm_fifo_read(chip, fw->burst, words);
    for (unsigned i = 0; err && i < FW_I2C_RETRIES; i++) {
        fw->counters.i2c_retries++;
        err = lsm_fifo_read(chip, fw->burst, words);
    }
    return err;
}

/* Drain one sensor's FIFO into its stream; false when the sensor is lost. */
static bool drain_fifo(fw_state *fw, uint8_t sensor)
{
    lsm6dsox *chip = sensor ? &fw->chip1 : &fw->chip;
    fifo_stream *stream = sensor ? &fw->stream1 : &fw->stream;
    fifo_packet_sink sink = sensor ? send_samples1 : send_samples;
    uint16_t words = 0;
    bool overrun = false;
    if (fifo_status_retrying(fw, chip, &words, &overrun))
        return false;
    if (overrun) {
        fifo_stream_overrun(stream, sink, fw);
        send_log(fw, LINK_LOG_WARNING, sensor
                 ? "sensor 1 FIFO overrun: samples were lost before they could be read (the "
                   "host sees a gap)"
                 : "FIFO overrun: samples were lost before they could be read (the host sees "
                   "a gap)");
    }
    /* Read what is there now, in bursts; what arrives meanwhile waits for the next poll. */
    while (words) {
        uint16_t burst = words < FW_FIFO_BURST_WORDS ? words : (uint16_t)FW_FIFO_BURST_WORDS;
        if (fifo_read_retrying(fw, chip, burst))
            return false;
        fifo_stream_feed(stream, fw->burst, burst, now_us(fw), sink, fw);
        words = (uint16_t)(words - burst);
    }
    return true;
}

/* Sensor 1 lost: look for it every FW_RETRY_INTERVAL_US; back, it streams again. */
static void retry_sensor1(fw_state *fw, uint32_t now)
{
    if (fw->sensor_count < 2 || fw->sensor1_ok ||
        (uint32_t)(now - fw->last_retry1_us) < FW_RETRY_INTERVAL_US)
        return;
    fw->last_retry1_us = now;
    if (!bring_up_sensor1(fw))
        return;
    send_log(fw, LINK_LOG_INFO, "sensor 1, the LSM6DSOX at 0x6B, answers again");
    if (fw->streaming)
        start_stream1(fw);
}

/* The magnetometer, read directly on the board's schedule: from 3/4 of its period after the
 * last field sample, one burst of its status and output registers per poll until ZYXDA says
 * a new sample is there; that sample is stamped with sensor 0's timestamp counter, read right
 * after it, and sent at once. The first sample after START is dropped (it may be old). Four
 * failed reads in a row lose the magnetometer (a LOG; looked for every 0.5 s); sensor 0 goes
 * on. */
static void poll_mag(fw_state *fw, uint32_t now)
{
    if (!fw->mag_found || fw->mag_paused)
        return;
    if (!fw->mag_ok) {
        if ((uint32_t)(now - fw->last_retry_mag_us) < FW_RETRY_INTERVAL_US)
            return;
        if (bring_up_mag(fw))
            send_log(fw, LINK_LOG_INFO, "the magnetometer answers again");
        return;
    }
    uint32_t period_us = (uint32_t)(1000000000ull / fw->mag.odr_mhz);
    if ((uint32_t)(now - fw->mag_last_us) < period_us / 4u * 3u)
        return;
    int16_t xyz[3];
    bool ready = false, overrun = false;
    if (mag_read(&fw->mag, xyz, &ready, &overrun)) {
        if (++fw->mag_failures > FW_I2C_RETRIES) {
            fw->mag_ok = false;
            fw->last_retry_mag_us = now;
            send_log(fw, LINK_LOG_ERROR, "the magnetometer stopped answering on I2C1; sensor 0 "
                                         "goes on, looking for it every 0.5 s");
        } else {
            fw->counters.i2c_retries++;
        }
        return;
    }
    fw->mag_failures = 0;
    if (!ready)
        return;
    if (overrun && fw->mag_primed) /* late: the chip overwrote a sample (a hole, not an error) */
        fw->counters.mag_overruns++;
    uint32_t ticks = 0;
    if (lsm_read_timestamp(&fw->chip, &ticks))
        return; /* sensor 0's trouble: its FIFO poll finds it */
    fw->mag_last_us = now;
    fw->counters.mag_samples_read++;
    if (!fw->mag_primed) {
        fw->mag_primed = true;
        return;
    }
    send_mag_sample(fw, ticks, xyz);
}

static void report_tx_drops(fw_state *fw)
{
    uint32_t dropped = fw->counters.tx_dropped_packets - fw->reported_tx_drops;
    const fw_platform *p = fw->platform;
    if (!dropped || p->tx_free(p->ctx) < 2u * LINK_MAX_WIRE)
        return;
    char message[MESSAGE_SIZE];
    text t;
    text_init(&t, message, sizeof message);
    text_u32(&t, dropped);
    text_str(&t, " SAMPLES packets dropped: the host did not read the port fast enough");
    fw->reported_tx_drops = fw->counters.tx_dropped_packets;
    send_log(fw, LINK_LOG_WARNING, message);
}

void fw_poll(fw_state *fw)
{
    update_uptime(fw);
    uint32_t now = now_us(fw);
    if (!fw->sensor_ok) {
        if ((uint32_t)(now - fw->last_retry_us) < FW_RETRY_INTERVAL_US)
            return;
        fw->last_retry_us = now;
        if (!bring_up_sensor(fw, NULL))
            return;
        send_log(fw, LINK_LOG_INFO, "the LSM6DSOX answers again");
        if (fw->want_streaming && !start_stream(fw))
            sensor_lost(fw);
        return;
    }
    if (!fw->streaming)
        return;
    retry_sensor1(fw, now);
    if ((uint32_t)(now - fw->last_poll_us) >= FW_POLL_INTERVAL_US) {
        fw->last_poll_us = now;
        if (!drain_fifo(fw, 0)) {
            sensor_lost(fw);
            return;
        }
        if (sensor1_streams(fw) && !drain_fifo(fw, 1))
            sensor1_lost(fw);
        poll_mag(fw, now_us(fw));
    }
    fifo_stream_flush(&fw->stream, now_us(fw), false, send_samples, fw);
    if (sensor1_streams(fw))
        fifo_stream_flush(&fw->stream1, now_us(fw), false, send_samples1, fw);
    report_tx_drops(fw);
    if ((uint32_t)(now_us(fw) - fw->last_status_us) >= FW_STATUS_INTERVAL_US)
        send_status(fw, false);
}

fw_led_mode fw_led_mode_now(const fw_state *fw)
{
    if (!fw->sensor_ok)
        return FW_LED_ERROR;
    return fw->streaming ? FW_LED_STREAMING : FW_LED_IDLE;
}

bool fw_led_lit(fw_led_mode mode, uint32_t now_ms)
{
    switch (mode) {
    case FW_LED_STREAMING:
        return now_ms % 1000u < 500u; /* 1 Hz */
    case FW_LED_ERROR:
        return now_ms % 125u < 62u;   /* 8 Hz */
    default:
        return true;
    }
}
