/* Unit tests of the portable core in C, built with AddressSanitizer and UBSan (make host).
 *
 * The Python host tests check the core against the Python decoder and the emulated chip; these
 * check what is easier to reach from C (edge cases of COBS and the receiver, the FIFO packet
 * assembler with hand-made words) and feed random bytes through the whole core, so the
 * sanitizers see every path. Exit status 0 when every check holds; failures are printed. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "../core/cobs.h"
#include "../core/crc16.h"
#include "../core/fifo_stream.h"
#include "../core/firmware.h"
#include "../core/link.h"
#include "../core/lsm6dsox.h"
#include "../core/uart_divisor.h"

static int failures;
static int checks;

#define CHECK(cond)                                                                      \
    do {                                                                                 \
        checks++;                                                                        \
        if (!(cond)) {                                                                   \
            failures++;                                                                  \
            fprintf(stderr, "%s:%d: check failed: %s\n", __FILE__, __LINE__, #cond);     \
        }                                                                                \
    } while (0)

static uint32_t rng_state = 12345u;

static uint32_t rnd(void)
{
    rng_state ^= rng_state << 13;
    rng_state ^= rng_state >> 17;
    rng_state ^= rng_state << 5;
    return rng_state;
}

/* ---- CRC and COBS */

static void test_crc(void)
{
    CHECK(crc16((const uint8_t *)"123456789", 9) == 0x29B1);
    CHECK(crc16(NULL, 0) == 0xFFFF);
    const uint8_t a[] = {1, 2, 3, 4, 5};
    CHECK(crc16_update(crc16(a, 2), a + 2, 3) == crc16(a, 5));
}

static void test_cobs_round_trips(void)
{
    uint8_t in[700], enc[COBS_MAX_ENCODED(700)], dec[700];
    for (int trial = 0; trial < 3000; trial++) {
        size_t n = rnd() % sizeof in;
        int zero_share = (int)(rnd() % 4); /* none, few, many, all */
        for (size_t i = 0; i < n; i++) {
            uint32_t r = rnd();
            bool zero = zero_share == 0 ? false : zero_share == 3 ? true : r % (zero_share == 1 ? 100 : 3) == 0;
            in[i] = zero ? 0 : (uint8_t)(1 + (r >> 8) % 255);
        }
        size_t e = cobs_encode(in, n, enc);
        CHECK(e <= COBS_MAX_ENCODED(n));
        CHECK(memchr(enc, 0, e) == NULL);
        int d = cobs_decode(enc, e, dec, sizeof dec);
        CHECK(d == (int)n);
        CHECK(d < 0 || memcmp(in, dec, n) == 0);
    }
}

static void test_cobs_rejects(void)
{
    uint8_t out[16];
    const uint8_t past_end[] = {0x05, 0x01, 0x02};
    CHECK(cobs_decode(past_end, sizeof past_end, out, sizeof out) == -1);
    const uint8_t zero_inside[] = {0x03, 0x01, 0x00};
    CHECK(cobs_decode(zero_inside, sizeof zero_inside, out, sizeof out) == -1);
    const uint8_t zero_code[] = {0x00};
    CHECK(cobs_decode(zero_code, sizeof zero_code, out, sizeof out) == -1);
    const uint8_t too_long[] = {0x04, 1, 2, 3, 0x04, 4, 5, 6};
    CHECK(cobs_decode(too_long, sizeof too_long, out, 5) == -1);
    /* A run of exactly 254 non-zero bytes: with and without the trailing 0x01 block. */
    uint8_t run[254], enc[COBS_MAX_ENCODED(254) + 1], dec[260];
    for (size_t i = 0; i < sizeof run; i++)
        run[i] = (uint8_t)(1 + i % 255);
    size_t e = cobs_encode(run, sizeof run, enc);
    CHECK(enc[0] == 0xFF);
    CHECK(cobs_decode(enc, e, dec, sizeof dec) == 254);
    CHECK(cobs_decode(enc, 255, dec, sizeof dec) == 254); /* without the 0x01 block */
}

/* ---- the frame receiver */

static void test_rx_resync(void)
{
    uint8_t stream[4096];
    size_t n = 0;
    const uint8_t garbage[] = {0x13, 0x37, 0xFF, 0x00, 0x00, 0x02, 0x41};
    memcpy(stream + n, garbage, sizeof garbage);
    n += sizeof garbage;
    stream[n++] = 0x00;
    n += link_encode_pong(0xDEADBEEFu, stream + n);
    /* An over-long run without a delimiter, then a good frame. */
    memset(stream + n, 0x55, 700);
    n += 700;
    stream[n++] = 0x00;
    n += link_encode_log(LINK_LOG_INFO, "hello", stream + n);
    /* A frame with a flipped byte (bad CRC). */
    size_t bad = link_encode_pong(1, stream + n);
    stream[n + 3] ^= 0x40;
    n += bad;
    n += link_encode_ack(LINK_START, LINK_ACK_OK, NULL, stream + n);

    for (int trial = 0; trial < 200; trial++) {
        link_rx rx;
        link_rx_init(&rx);
        uint8_t types[8];
        int found = 0;
        size_t done = 0;
        while (done < n) { /* random chunking */
            size_t chunk = 1 + rnd() % 97;
            if (chunk > n - done)
                chunk = n - done;
            size_t offset = 0;
            uint8_t type;
            const uint8_t *payload;
            size_t length;
            while (link_rx_feed(&rx, stream + done, chunk, &offset, &type, &payload, &length))
                if (found < 8)
                    types[found++] = type;
            done += chunk;
        }
        CHECK(found == 3);
        CHECK(found < 3 || (types[0] == LINK_PONG && types[1] == LINK_LOG && types[2] == LINK_ACK));
        CHECK(rx.bad_frames >= 3); /* garbage, the over-long run, the bad CRC */
    }
}

/* ---- the FIFO packet assembler */

typedef struct sink_log {
    int packets;
    fifo_packet last[64];
} sink_log;

static void sink(void *ctx, const fifo_packet *packet)
{
    sink_log *log = ctx;
    if (log->packets < 64)
        log->last[log->packets] = *packet;
    log->packets++;
}

/* Append a FIFO word with `tag` in time slot `slot` (TAG_CNT = slot mod 4). */
static size_t word(uint8_t *out, uint8_t tag, uint32_t slot, const uint8_t data[6])
{
    out[0] = (uint8_t)((tag << 3) | ((slot & 3u) << 1));
    memcpy(out + 1, data, 6);
    return LSM_FIFO_WORD_BYTES;
}

/* Words of slots [first, first + count): timestamp every 8th slot at `ticks_per_slot`. */
static uint16_t make_slots(uint8_t *out, uint32_t first, uint32_t count, uint32_t ticks0,
                           uint32_t ticks_per_slot, uint32_t skip_accel_slot)
{
    uint16_t words = 0;
    for (uint32_t slot = first; slot < first + count; slot++) {
        uint8_t data[6] = {0};
        if (slot % 8 == 0) {
            put_u32(data, ticks0 + slot * ticks_per_slot);
            words++, out += word(out, LSM_TAG_TIMESTAMP, slot, data);
        }
        put_u16(data, (uint16_t)slot);
        words++, out += word(out, LSM_TAG_GYRO, slot, data);
        if (slot != skip_accel_slot) {
            put_u16(data, (uint16_t)(1000 + slot));
            words++, out += word(out, LSM_TAG_ACCEL, slot, data);
        }
    }
    return words;
}

static void test_fifo_stream_packets(void)
{
    static uint8_t buf[200 * 3 * LSM_FIFO_WORD_BYTES];
    fifo_stream s;
    sink_log log = {0};
    fifo_stream_init(&s, 5000);
    fifo_stream_restart(&s, 104000, 0);
    /* 100 slots read at once, ticks 384.6 per slot (104 Hz): packets of 32, 32, 32 and 4. */
    uint16_t words = make_slots(buf, 0, 100, 1000, 385, UINT32_MAX);
    fifo_stream_feed(&s, buf, words, 0, sink, &log);
    CHECK(log.packets == 3);
    fifo_stream_flush(&s, 5000, false, sink, &log);
    CHECK(log.packets == 4);
    CHECK(log.last[0].count == 32 && log.last[3].count == 4);
    for (int k = 0; k < 4; k++) {
        CHECK(log.last[k].seq == k);
        CHECK(log.last[k].t0 == 1000u + 32u * (uint32_t)k * 385u);
        CHECK(log.last[k].samples[0][0] == 32 * k);       /* gyro x = slot */
        CHECK(log.last[k].samples[0][3] == 1000 + 32 * k); /* accel x */
    }
    CHECK(s.counters.samples == 100 && s.counters.incomplete_slots == 0);
}

static void test_fifo_stream_discards_settling_samples(void)
{
    static uint8_t buf[200 * 3 * LSM_FIFO_WORD_BYTES];
    fifo_stream s;
    sink_log log = {0};
    fifo_stream_init(&s, 5000);
    fifo_stream_restart(&s, 104167, 0);
    fifo_stream_discard(&s, 14); /* "104 Hz": 14 gyroscope samples of turn-on transient */
    uint16_t words = make_slots(buf, 0, 46, 1000, 384, UINT32_MAX);
    fifo_stream_feed(&s, buf, words, 0, sink, &log);
    CHECK(log.packets == 1);
    CHECK(log.last[0].seq == 0);                 /* no sequence number skipped: not a loss */
    CHECK(log.last[0].count == 32);
    CHECK(log.last[0].samples[0][0] == 14);      /* the first sample kept is slot 14 ... */
    CHECK(log.last[0].t0 == 1000u + 14u * 384u); /* ... and t0 is its time */
    CHECK(s.counters.settling == 14 && s.counters.samples == 32);
    fifo_stream_restart(&s, 104167, 0);          /* a restart forgets a pending discard */
    CHECK(s.discard == 0);
}

static void test_odr_tables(void)
{
    /* The chip runs at 6666.67 Hz / ODR_Coeff (AN5272); the labels are the datasheet's. */
    const uint32_t real[] = {0, 13021, 26042, 52083, 104167, 208333, 416667, 833333, 1666667,
                             3333333, 6666667};
    const uint32_t label[] = {0, 12500, 26000, 52000, 104000, 208000, 417000, 833000, 1667000,
                              3333000, 6667000};
    for (uint8_t code = 0; code <= LSM_ODR_CODE_MAX + 1; code++) {
        uint32_t want_real = code <= LSM_ODR_CODE_MAX ? real[code] : 0;
        uint32_t want_label = code <= LSM_ODR_CODE_MAX ? label[code] : 0;
        CHECK(lsm_odr_nominal_mhz(code) == want_real);
        CHECK(lsm_odr_label_mhz(code) == want_label);
    }
    /* Turn-on discard: 3-7 accelerometer and 4-541 gyroscope samples, growing with the rate. */
    CHECK(lsm_turn_on_discard(1, false) == 3 && lsm_turn_on_discard(10, false) == 7);
    CHECK(lsm_turn_on_discard(1, true) == 4 && lsm_turn_on_discard(10, true) == 541);
    for (uint8_t code = 2; code <= LSM_ODR_CODE_MAX; code++) {
        CHECK(lsm_turn_on_discard(code, false) >= lsm_turn_on_discard(code - 1, false));
        CHECK(lsm_turn_on_discard(code, true) > lsm_turn_on_discard(code - 1, true));
    }
    CHECK(lsm_turn_on_discard(0, true) == 0 && lsm_turn_on_discard(11, false) == 0);
    /* Trimmed: FREQ_FINE = -10 is 1.5 % slow; 104.167 Hz x 0.985 = 102.604 Hz. */
    lsm6dsox chip;
    lsm_init(&chip, NULL);
    chip.settings.odr_code = 4;
    chip.freq_fine = -10;
    CHECK(lsm_odr_mhz(&chip) == 102604);
    CHECK(lsm_tick_ns(&chip) == 25381);
}

static void test_fifo_stream_hole_and_overrun(void)
{
    static uint8_t buf[200 * 3 * LSM_FIFO_WORD_BYTES];
    fifo_stream s;
    sink_log log = {0};
    fifo_stream_init(&s, 5000);
    fifo_stream_restart(&s, 104000, 0);
    /* Slot 10 lacks its accelerometer word: the packet is cut there and a seq skipped. */
    uint16_t words = make_slots(buf, 0, 20, 0, 385, 10);
    fifo_stream_feed(&s, buf, words, 0, sink, &log);
    fifo_stream_flush(&s, 0, true, sink, &log);
    CHECK(log.packets == 2);
    CHECK(log.last[0].count == 10 && log.last[0].seq == 0);
    CHECK(log.last[1].count == 9 && log.last[1].seq == 2 && log.last[1].t0 == 11u * 385u);
    CHECK(s.counters.incomplete_slots == 1);
    /* An overrun: what waits is sent, a seq skipped, the next packet waits for an anchor. */
    words = make_slots(buf, 20, 3, 0, 385, UINT32_MAX); /* slots 20..22, no anchor among them */
    fifo_stream_feed(&s, buf, words, 0, sink, &log);
    fifo_stream_overrun(&s, sink, &log);
    CHECK(log.packets == 3 && log.last[2].seq == 3 && log.last[2].count == 3);
    words = make_slots(buf, 61, 6, 0, 385, UINT32_MAX); /* slots 61..66: anchor at 64 */
    fifo_stream_feed(&s, buf, words, 10000, sink, &log);
    fifo_stream_flush(&s, 20000, false, sink, &log);
    CHECK(log.packets == 4);
    CHECK(log.last[3].seq == 5 && log.last[3].count == 6 && log.last[3].t0 == 61u * 385u);
}

static void test_fifo_stream_measures_rate(void)
{
    static uint8_t buf[400 * 3 * LSM_FIFO_WORD_BYTES];
    fifo_stream s;
    sink_log log = {0};
    fifo_stream_init(&s, 5000);
    fifo_stream_restart(&s, 104000, 0); /* nominal 384.6 ticks per slot; the chip runs 372 */
    uint16_t words = make_slots(buf, 0, 330, 7, 372, UINT32_MAX);
    fifo_stream_feed(&s, buf, words, 0, sink, &log);
    fifo_stream_flush(&s, 0, true, sink, &log);
    CHECK(log.packets == 11);
    /* Packet 10 starts at slot 320, an anchor: exact; packet 9 (slot 288) too. */
    CHECK(log.last[10].t0 == 7u + 320u * 372u);
    CHECK((s.ticks_per_slot_q16 >> 16) == 372u);
}

static void test_fifo_stream_timestamps_wrap(void)
{
    static uint8_t buf[100 * 3 * LSM_FIFO_WORD_BYTES];
    fifo_stream s;
    sink_log log = {0};
    fifo_stream_init(&s, 5000);
    fifo_stream_restart(&s, 104000, 0);
    /* The 32-bit tick counter wraps inside the second packet. */
    uint32_t ticks0 = 0xFFFFFFFFu - 40u * 385u;
    uint16_t words = make_slots(buf, 0, 96, ticks0, 385, UINT32_MAX);
    fifo_stream_feed(&s, buf, words, 0, sink, &log);
    CHECK(log.packets == 3);
    for (int k = 0; k < 3; k++)
        CHECK(log.last[k].t0 == (uint32_t)(ticks0 + 32u * (uint32_t)k * 385u));
    CHECK((s.ticks_per_slot_q16 >> 16) == 385u);
}

static void test_fifo_stream_long_runs_keep_the_rate(void)
{
    /* 12.5 Hz for longer than 2^30 ticks (7.5 hours): the rate base moves, t0 stays exact. */
    static uint8_t buf[64 * 3 * LSM_FIFO_WORD_BYTES];
    fifo_stream s;
    sink_log log = {0};
    fifo_stream_init(&s, 5000);
    fifo_stream_restart(&s, 12500, 0);
    const uint32_t per_slot = 3190; /* the chip runs 0.3 % fast */
    uint32_t slots = (1u << 30) / per_slot + 2000u;
    bool exact = true;
    for (uint32_t first = 0; first < slots; first += 64) {
        log.packets = 0;
        uint16_t words = make_slots(buf, first, 64, 12345, per_slot, UINT32_MAX);
        fifo_stream_feed(&s, buf, words, 0, sink, &log);
        exact &= log.packets == 2;
        for (int k = 0; k < 2; k++)
            exact &= log.last[k].t0 == (uint32_t)(12345u + (first + 32u * (uint32_t)k) * per_slot);
    }
    CHECK(exact);
    CHECK((s.ticks_per_slot_q16 >> 16) == per_slot);
    CHECK(s.have_base && s.base_slot > 0); /* the rate base moved on the way */
    CHECK(s.counters.dropped_packets == 0);
}

/* ---- the whole core on a fake bus: random bytes must not upset it */

typedef struct fake_chip {
    uint8_t regs[256];
    int writes;
    uint32_t now_us;
    uint8_t tx[1 << 16];
    size_t tx_length;
    int fail_reads;  /* the next this many reads fail (a glitch on the bus) */
    bool fifo_empty; /* FIFO_STATUS reads 0 words, no overrun */
} fake_chip;

static int fake_write(void *ctx, uint8_t address, uint8_t reg, const uint8_t *data, size_t n)
{
    fake_chip *chip = ctx;
    if (address != LSM6DSOX_ADDRESS_SA0_HIGH)
        return 1;
    for (size_t i = 0; i < n; i++)
        chip->regs[(uint8_t)(reg + i)] = data[i];
    chip->regs[LSM_CTRL3_C] &= (uint8_t)~LSM_CTRL3_C_SW_RESET; /* the reset is instant */
    chip->writes++;
    return 0;
}

static int fake_read(void *ctx, uint8_t address, uint8_t reg, uint8_t *data, size_t n)
{
    fake_chip *chip = ctx;
    if (address != LSM6DSOX_ADDRESS_SA0_HIGH)
        return 1;
    if (chip->fail_reads > 0) {
        chip->fail_reads--;
        return 2;
    }
    chip->regs[LSM_WHO_AM_I] = LSM6DSOX_WHO_AM_I_VALUE;
    chip->regs[LSM_STATUS_REG] = LSM_STATUS_XLDA | LSM_STATUS_GDA;
    for (size_t i = 0; i < n; i++) /* FIFO reads return random words */
        data[i] = reg == LSM_FIFO_DATA_OUT_TAG ? (uint8_t)rnd() : chip->regs[(uint8_t)(reg + i)];
    if (reg == LSM_FIFO_STATUS1 && n == 2) {
        data[0] = chip->fifo_empty ? 0u : (uint8_t)rnd();
        data[1] = chip->fifo_empty ? 0u : (uint8_t)(rnd() & 0x4Bu);
    }
    return 0;
}

static uint32_t fake_micros(void *ctx)
{
    fake_chip *chip = ctx;
    return chip->now_us += 37;
}

static void fake_delay(void *ctx, uint32_t us)
{
    ((fake_chip *)ctx)->now_us += us;
}

static size_t fake_tx_free(void *ctx)
{
    fake_chip *chip = ctx;
    return sizeof chip->tx - chip->tx_length;
}

static void fake_tx_write(void *ctx, const uint8_t *data, size_t n)
{
    fake_chip *chip = ctx;
    memcpy(chip->tx + chip->tx_length, data, n);
    chip->tx_length += n;
}

static void test_core_with_fake_bus(void)
{
    static fake_chip chip;
    static fw_state fw;
    fw_platform platform = {&chip, fake_write, fake_read, fake_micros, fake_delay,
                            fake_tx_free, fake_tx_write, NULL};
    fw_identity identity = {{1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12}, "NUCLEO-F746ZG", 921600,
                            400000};
    fw_init(&fw, &platform, &identity);
    CHECK(fw.sensor_ok);
    CHECK(fw.chip.address == LSM6DSOX_ADDRESS_SA0_HIGH); /* found at the second address */
    CHECK(chip.writes == (int)LSM_SEQUENCE_LENGTH);
    CHECK(chip.regs[LSM_CTRL1_XL] == 0x48 && chip.regs[LSM_CTRL2_G] == 0x40);

    /* START, then random commands and noise with valid frames among them. */
    uint8_t wire[LINK_MAX_WIRE];
    size_t n = link_frame(LINK_START, NULL, 0, wire);
    fw_receive(&fw, wire, n);
    CHECK(fw.streaming);
    for (int round = 0; round < 20000; round++) {
        uint8_t bytes[64];
        size_t length = rnd() % sizeof bytes;
        if (rnd() % 4 == 0) {
            uint8_t payload[8];
            for (size_t i = 0; i < sizeof payload; i++)
                payload[i] = (uint8_t)rnd();
            uint8_t type = (uint8_t)(0x80u + rnd() % 8u);
            if (type == LINK_SELF_TEST)
                type = LINK_PING; /* the self-test waits on the clock: tested in Python */
            length = link_frame(type, payload, rnd() % 6, bytes);
        } else {
            for (size_t i = 0; i < length; i++)
                bytes[i] = (uint8_t)rnd();
        }
        fw_receive(&fw, bytes, length);
        fw_poll(&fw);
        if (chip.tx_length > sizeof chip.tx / 2)
            chip.tx_length = 0;
    }
    CHECK(fw.counters.commands > 1000);
    CHECK(fw.rx.bad_frames > 1000);
}

static void test_uart_divisor(void)
{
    /* 216 MHz (the PLL, from the MCO or the HSI): 16x, BRR 234, 923 077 baud. */
    uart_divisor d = uart_divisor_for(216000000u, 921600u);
    CHECK(d.brr == 234 && !d.over8 && d.actual_baud == 923076u);
    /* 16 MHz (the HSI alone): 16x would be 941 176 (+2.1 %); 8x gives 914 285 (-0.8 %). */
    d = uart_divisor_for(16000000u, 921600u);
    CHECK(d.over8 && d.brr == 0x21 && d.actual_baud == 914285u);
    /* A slower rate on the HSI stays at 16x: 138.9 -> 139, -0.08 %. */
    d = uart_divisor_for(16000000u, 115200u);
    CHECK(!d.over8 && d.brr == 139 && d.actual_baud == 115107u);
    CHECK(uart_divisor_for(16000000u, 0u).brr == 0);
}

/* The STATUS packets in chip->tx (decoded by the core's own receiver); returns how many, the
 * last one's payload in `last`. */
static int status_packets(const fake_chip *chip, uint8_t last[LINK_STATUS_PAYLOAD])
{
    static link_rx rx;
    link_rx_init(&rx);
    size_t offset = 0;
    uint8_t type;
    const uint8_t *payload;
    size_t length;
    int found = 0;
    while (link_rx_feed(&rx, chip->tx, chip->tx_length, &offset, &type, &payload, &length)) {
        if (type != LINK_STATUS)
            continue;
        CHECK(length == LINK_STATUS_PAYLOAD);
        memcpy(last, payload, LINK_STATUS_PAYLOAD);
        found++;
    }
    return found;
}

static void health(void *ctx, fw_board_health *out)
{
    (void)ctx;
    *out = (fw_board_health){7, 100, 2, 1, LINK_RESET_IWDG, true};
}

static void test_status_and_retries(void)
{
    static fake_chip chip;
    static fw_state fw;
    memset(&chip, 0, sizeof chip);
    chip.fifo_empty = true;
    fw_platform platform = {&chip, fake_write, fake_read, fake_micros, fake_delay,
                            fake_tx_free, fake_tx_write, health};
    fw_identity identity = {{0}, "NUCLEO-F746ZG", 921600, 400000};
    fw_init(&fw, &platform, &identity);
    CHECK(fw.sensor_ok);
    link_status status;
    fw_status(&fw, &status);
    CHECK(status.i2c_errors >= 1); /* the probe of 0x6A, where nothing answers */
    CHECK(status.i2c_retries == 0);
    CHECK(status.reset_cause == LINK_RESET_IWDG && status.watchdog_resets == 1);
    CHECK(status.uart_rx_errors == 7 && status.i2c_recoveries == 2);
    CHECK(status.uart_tx_dropped_bytes == 100);
    CHECK(status.flags == (LINK_STATUS_SENSOR_OK | LINK_STATUS_CLOCK_FALLBACK));

    /* GET_STATUS is answered at once. */
    uint8_t wire[LINK_MAX_WIRE], last[LINK_STATUS_PAYLOAD];
    chip.tx_length = 0;
    fw_receive(&fw, wire, link_frame(LINK_GET_STATUS, NULL, 0, wire));
    CHECK(status_packets(&chip, last) == 1);
    CHECK(last[0] == LINK_STATUS_VERSION && last[1] == LINK_RESET_IWDG);

    /* START sends one; streaming sends one a second. */
    chip.tx_length = 0;
    fw_receive(&fw, wire, link_frame(LINK_START, NULL, 0, wire));
    CHECK(fw.streaming && status_packets(&chip, last) == 1);
    CHECK(last[2] & LINK_STATUS_STREAMING);
    uint32_t start = chip.now_us;
    while ((uint32_t)(chip.now_us - start) < 3500000u) {
        chip.now_us += 1000;
        fw_poll(&fw);
    }
    CHECK(status_packets(&chip, last) == 4);
    uint32_t uptime = get_u32(last + 3);
    CHECK(uptime >= 3000u && uptime <= chip.now_us / 1000u); /* the clock started at 0 */

    /* Two failed reads are retried and the stream goes on; four lose the sensor. */
    uint32_t errors = fw.counters.i2c_errors;
    chip.fail_reads = 2;
    chip.now_us += FW_POLL_INTERVAL_US;
    fw_poll(&fw);
    CHECK(fw.streaming && fw.sensor_ok);
    CHECK(fw.counters.i2c_retries == 2 && fw.counters.i2c_errors == errors + 2);
    chip.fail_reads = (int)FW_I2C_RETRIES + 1;
    chip.now_us += FW_POLL_INTERVAL_US;
    fw_poll(&fw);
    CHECK(!fw.streaming && !fw.sensor_ok);
    CHECK(fw.counters.i2c_retries == 2 + FW_I2C_RETRIES);
}

static void test_rates(void)
{
    /* docs/protocol.md section 6: the highest ODR per baud rate. */
    const struct { uint32_t baud; uint8_t highest; } table[] = {
        {115200, 7}, {230400, 8}, {460800, 9}, {921600, 10},
    };
    char why[160];
    for (size_t i = 0; i < sizeof table / sizeof table[0]; i++) {
        CHECK(fw_rate_fits(table[i].highest, table[i].baud, 0, why, sizeof why));
        if (table[i].highest < LSM_ODR_CODE_MAX)
            CHECK(!fw_rate_fits((uint8_t)(table[i].highest + 1), table[i].baud, 0, why,
                                sizeof why));
    }
    CHECK(fw_rate_fits(8, 921600, 400000, why, sizeof why));
    CHECK(!fw_rate_fits(9, 921600, 400000, why, sizeof why));
    CHECK(strstr(why, "highest ODR 1667 Hz") != NULL);
}

/* ---- two LSM6DSOX on one bus (0x6A and 0x6B): both found, both streamed */

typedef struct two_chips {
    uint8_t regs[2][256];
    uint32_t next_slot[2];          /* the FIFO's next time slot per chip */
    uint8_t fifo[2][8 * 3 * LSM_FIFO_WORD_BYTES];
    size_t fifo_length[2], fifo_read[2];
    uint32_t now_us;
    uint8_t tx[1 << 17];
    size_t tx_length;
    bool second_silent;             /* 0x6B stops answering */
} two_chips;

static int two_index(const two_chips *bus, uint8_t address)
{
    if (address == LSM6DSOX_ADDRESS_SA0_LOW)
        return 0;
    if (address == LSM6DSOX_ADDRESS_SA0_HIGH && !bus->second_silent)
        return 1;
    return -1;
}

static int two_write(void *ctx, uint8_t address, uint8_t reg, const uint8_t *data, size_t n)
{
    two_chips *bus = ctx;
    int c = two_index(bus, address);
    if (c < 0)
        return 1;
    for (size_t i = 0; i < n; i++)
        bus->regs[c][(uint8_t)(reg + i)] = data[i];
    bus->regs[c][LSM_CTRL3_C] &= (uint8_t)~LSM_CTRL3_C_SW_RESET;
    return 0;
}

static int two_read(void *ctx, uint8_t address, uint8_t reg, uint8_t *data, size_t n)
{
    two_chips *bus = ctx;
    int c = two_index(bus, address);
    if (c < 0)
        return 1;
    bus->regs[c][LSM_WHO_AM_I] = LSM6DSOX_WHO_AM_I_VALUE;
    bus->regs[c][LSM_STATUS_REG] = LSM_STATUS_XLDA | LSM_STATUS_GDA;
    if (reg == LSM_FIFO_STATUS1 && n == 2) {
        /* 8 new slots per poll; chip 1's data start at slot 5000 and its clock at 10^6. */
        uint32_t base = c ? 5000u : 0u;
        uint16_t words = make_slots(bus->fifo[c], base + bus->next_slot[c], 8,
                                    c ? 1000000u - 5000u * 380u : 0u, c ? 380u : 385u,
                                    UINT32_MAX);
        bus->next_slot[c] += 8;
        bus->fifo_length[c] = (size_t)words * LSM_FIFO_WORD_BYTES;
        bus->fifo_read[c] = 0;
        data[0] = (uint8_t)words;
        data[1] = 0;
        return 0;
    }
    if (reg == LSM_FIFO_DATA_OUT_TAG) {
        if (bus->fifo_read[c] + n > bus->fifo_length[c])
            return 3;
        memcpy(data, bus->fifo[c] + bus->fifo_read[c], n);
        bus->fifo_read[c] += n;
        return 0;
    }
    for (size_t i = 0; i < n; i++)
        data[i] = bus->regs[c][(uint8_t)(reg + i)];
    return 0;
}

static uint32_t two_micros(void *ctx)
{
    return ((two_chips *)ctx)->now_us += 37;
}

static void two_delay(void *ctx, uint32_t us)
{
    ((two_chips *)ctx)->now_us += us;
}

static size_t two_tx_free(void *ctx)
{
    two_chips *bus = ctx;
    return sizeof bus->tx - bus->tx_length;
}

static void two_tx_write(void *ctx, const uint8_t *data, size_t n)
{
    two_chips *bus = ctx;
    memcpy(bus->tx + bus->tx_length, data, n);
    bus->tx_length += n;
}

typedef struct two_streams {
    int packets[2], samples[2], sensors, acks_refused, logs;
    uint8_t sensor_address[2], sensor_count, sensor_flags[2];
    bool in_order[2];      /* seq +1 per packet, per sensor */
    bool consecutive[2];   /* gyro x (the slot) +1 per sample, per sensor */
    bool right_chip[2];    /* sensor 0's slots below 5000, sensor 1's from 5000 */
    int32_t last_seq[2], last_slot[2];
    char refusal[160];
    char log[160]; /* the last LOG's text */
} two_streams;

static void read_two(const two_chips *bus, two_streams *out)
{
    static link_rx rx;
    link_rx_init(&rx);
    memset(out, 0, sizeof *out);
    for (int c = 0; c < 2; c++) {
        out->in_order[c] = out->consecutive[c] = out->right_chip[c] = true;
        out->last_seq[c] = out->last_slot[c] = -1;
    }
    size_t offset = 0;
    uint8_t type;
    const uint8_t *payload;
    size_t length;
    while (link_rx_feed(&rx, bus->tx, bus->tx_length, &offset, &type, &payload, &length)) {
        if (type == LINK_SENSOR && length == LINK_SENSOR_PAYLOAD && payload[0] < 2) {
            out->sensors++;
            out->sensor_count = payload[1];
            out->sensor_address[payload[0]] = payload[2];
            out->sensor_flags[payload[0]] = payload[15];
        } else if (type == LINK_ACK && length >= 2 && payload[1] != LINK_ACK_OK) {
            out->acks_refused++;
            size_t n = length - 2 < sizeof out->refusal - 1 ? length - 2 : sizeof out->refusal - 1;
            memcpy(out->refusal, payload + 2, n);
            out->refusal[n] = 0;
        } else if (type == LINK_LOG) {
            out->logs++;
            size_t n = length - 1 < sizeof out->log - 1 ? length - 1 : sizeof out->log - 1;
            memcpy(out->log, payload + 1, n);
            out->log[n] = 0;
        } else if (type == LINK_SAMPLES || type == LINK_SAMPLES_INDEXED) {
            int c = type == LINK_SAMPLES_INDEXED;
            const uint8_t *p = payload + c;
            if (c && payload[0] != 1) {
                out->right_chip[1] = false;
                continue;
            }
            int32_t seq = get_u16(p);
            uint8_t count = p[6];
            CHECK(length == (size_t)c + LINK_SAMPLES_HEADER + 12u * count);
            if (out->last_seq[c] >= 0 && seq != out->last_seq[c] + 1)
                out->in_order[c] = false;
            out->last_seq[c] = seq;
            for (uint8_t i = 0; i < count; i++) {
                int32_t slot = get_u16(p + LINK_SAMPLES_HEADER + 12u * i);
                if (out->last_slot[c] >= 0 && slot != out->last_slot[c] + 1)
                    out->consecutive[c] = false;
                if ((slot >= 5000) != (c == 1))
                    out->right_chip[c] = false;
                out->last_slot[c] = slot;
            }
            out->packets[c]++;
            out->samples[c] += count;
        }
    }
}

static void test_two_sensors(void)
{
    static two_chips bus;
    static fw_state fw;
    static two_streams seen;
    memset(&bus, 0, sizeof bus);
    fw_platform platform = {&bus, two_write, two_read, two_micros, two_delay, two_tx_free,
                            two_tx_write, NULL};
    fw_identity identity = {{0}, "NUCLEO-F746ZG", 921600, 400000};
    fw_init(&fw, &platform, &identity);
    CHECK(fw.sensor_ok && fw.sensor1_ok && fw.sensor_count == 2);
    CHECK(fw.chip.address == LSM6DSOX_ADDRESS_SA0_LOW);
    CHECK(fw.chip1.address == LSM6DSOX_ADDRESS_SA0_HIGH);
    /* Both configured alike (104 Hz, 4 g, 250 dps). */
    CHECK(bus.regs[0][LSM_CTRL1_XL] == 0x48 && bus.regs[1][LSM_CTRL1_XL] == 0x48);
    CHECK(bus.regs[0][LSM_CTRL2_G] == 0x40 && bus.regs[1][LSM_CTRL2_G] == 0x40);

    /* HELLO: INFO, CONFIG, then SENSOR 0 and 1 with their addresses. */
    uint8_t wire[LINK_MAX_WIRE];
    fw_receive(&fw, wire, link_frame(LINK_HELLO, NULL, 0, wire));
    read_two(&bus, &seen);
    CHECK(seen.sensors == 2 && seen.sensor_count == 2);
    CHECK(seen.sensor_address[0] == 0x6A && seen.sensor_address[1] == 0x6B);

    CHECK(seen.sensor_flags[0] == LINK_SENSOR_ANSWERING);
    CHECK(seen.sensor_flags[1] == LINK_SENSOR_ANSWERING && seen.logs == 0);

    /* 1667 Hz fits sensor 0 alone (I2C at 400 kHz): accepted, sensor 1 paused and a LOG says
     * why; sensor 0 streams at 1667 Hz, sensor 1 sends nothing. */
    bus.tx_length = 0;
    uint8_t configure[4] = {8, 4, 0xFA, 0x00};
    fw_receive(&fw, wire, link_frame(LINK_CONFIGURE, configure, 4, wire));
    read_two(&bus, &seen);
    CHECK(seen.acks_refused == 0 && fw.sensor1_paused);
    CHECK(seen.sensors == 2 && seen.sensor_flags[0] == LINK_SENSOR_ANSWERING);
    CHECK(seen.sensor_flags[1] == (LINK_SENSOR_ANSWERING | LINK_SENSOR_PAUSED));
    CHECK(seen.logs == 1 && strcmp(seen.log, "sensor 1 (0x6B) paused: 1667 Hz does not fit two "
                                             "sensors on I2C 400 kHz (highest 833 Hz)") == 0);
    CHECK(bus.regs[0][LSM_CTRL1_XL] == 0x88);
    bus.tx_length = 0;
    fw_receive(&fw, wire, link_frame(LINK_START, NULL, 0, wire));
    for (int i = 0; i < 200; i++) {
        bus.now_us += FW_POLL_INTERVAL_US;
        fw_poll(&fw);
    }
    fw_receive(&fw, wire, link_frame(LINK_STOP, NULL, 0, wire));
    read_two(&bus, &seen);
    CHECK(seen.packets[0] > 10 && seen.samples[0] > 500 && seen.packets[1] == 0);
    int packets_alone = seen.packets[0];
    link_status status;
    fw_status(&fw, &status);
    CHECK(status.samples_sent == (uint32_t)seen.samples[0]);
    uint32_t sent_alone = status.samples_sent;
    CHECK(seen.in_order[0] && seen.consecutive[0] && seen.right_chip[0]);
    CHECK(seen.logs == 1 && strstr(seen.log, "(sensor 1 at 0x6B paused: the rate does not fit "
                                             "two sensors)") != NULL);
    /* HELLO while paused: SENSOR 1 says so, and the LOG follows. */
    bus.tx_length = 0;
    fw_receive(&fw, wire, link_frame(LINK_HELLO, NULL, 0, wire));
    read_two(&bus, &seen);
    CHECK(seen.sensor_flags[1] == (LINK_SENSOR_ANSWERING | LINK_SENSOR_PAUSED));
    CHECK(seen.logs == 1 && strstr(seen.log, "sensor 1 (0x6B) paused") != NULL);
    /* 3333 Hz does not fit even sensor 0: refused as on a one-sensor board, nothing changes. */
    bus.tx_length = 0;
    configure[0] = 9;
    fw_receive(&fw, wire, link_frame(LINK_CONFIGURE, configure, 4, wire));
    read_two(&bus, &seen);
    CHECK(seen.acks_refused == 1 && strstr(seen.refusal, "highest ODR 1667 Hz") != NULL);
    CHECK(strstr(seen.refusal, "sensors") == NULL && fw.chip.settings.odr_code == 8);
    /* 833 Hz fits both: sensor 1 streams again, no LOG. */
    bus.tx_length = 0;
    configure[0] = 7;
    fw_receive(&fw, wire, link_frame(LINK_CONFIGURE, configure, 4, wire));
    CHECK(bus.regs[0][LSM_CTRL1_XL] == 0x78 && bus.regs[1][LSM_CTRL1_XL] == 0x78);
    read_two(&bus, &seen);
    CHECK(!fw.sensor1_paused && seen.logs == 0);
    CHECK(seen.sensor_flags[1] == LINK_SENSOR_ANSWERING);

    /* Stream: both sensors' packets, each with its own sequence numbers (sensor 1's from 0,
     * sensor 0's going on from its run alone). */
    bus.tx_length = 0;
    fw_receive(&fw, wire, link_frame(LINK_START, NULL, 0, wire));
    for (int i = 0; i < 400; i++) {
        bus.now_us += FW_POLL_INTERVAL_US;
        fw_poll(&fw);
    }
    read_two(&bus, &seen);
    CHECK(seen.packets[0] > 20 && seen.packets[1] > 20);
    CHECK(seen.samples[0] > 1000 && seen.samples[1] > 1000);
    CHECK(seen.in_order[0] && seen.in_order[1]);
    CHECK(seen.consecutive[0] && seen.consecutive[1]);
    CHECK(seen.right_chip[0] && seen.right_chip[1]);
    CHECK(seen.last_seq[0] == packets_alone + seen.packets[0] - 1);
    CHECK(seen.last_seq[1] == seen.packets[1] - 1);
    fw_status(&fw, &status);
    CHECK(status.samples_sent - sent_alone == (uint32_t)(seen.samples[0] + seen.samples[1]));

    /* Sensor 1 goes silent: a LOG, sensor 0 streams on; back, sensor 1 streams again. */
    bus.tx_length = 0;
    bus.second_silent = true;
    for (int i = 0; i < 100; i++) {
        bus.now_us += FW_POLL_INTERVAL_US;
        fw_poll(&fw);
    }
    CHECK(fw.streaming && fw.sensor_ok && !fw.sensor1_ok);
    read_two(&bus, &seen);
    CHECK(seen.logs == 1 && seen.packets[0] > 5);
    bus.second_silent = false;
    bus.tx_length = 0;
    for (int i = 0; i < 400; i++) {
        bus.now_us += FW_POLL_INTERVAL_US;
        fw_poll(&fw);
    }
    CHECK(fw.sensor1_ok);
    read_two(&bus, &seen);
    CHECK(seen.packets[1] > 5 && seen.right_chip[1]);

    /* STOP: nothing after its ACK. */
    fw_receive(&fw, wire, link_frame(LINK_STOP, NULL, 0, wire));
    CHECK(!fw.streaming);
}

static void test_rates_two_sensors(void)
{
    /* docs/protocol.md section 6, two sensors: the UART and I2C limits. */
    const struct { uint32_t baud; uint8_t highest; } table[] = {
        {115200, 6}, {230400, 7}, {460800, 8}, {921600, 9},
    };
    char why[160];
    for (size_t i = 0; i < sizeof table / sizeof table[0]; i++) {
        CHECK(fw_rate_fits_sensors(table[i].highest, table[i].baud, 0, 2, why, sizeof why));
        CHECK(!fw_rate_fits_sensors((uint8_t)(table[i].highest + 1), table[i].baud, 0, 2, why,
                                    sizeof why));
    }
    CHECK(fw_rate_fits_sensors(7, 921600, 400000, 2, why, sizeof why));
    CHECK(!fw_rate_fits_sensors(8, 921600, 400000, 2, why, sizeof why));
    CHECK(strstr(why, "highest ODR 833 Hz") != NULL);
    CHECK(fw_rate_fits_sensors(8, 921600, 400000, 1, why, sizeof why));
}

/* The magnetometer's datasheet tables, its encoders and the bus budget it yields to. */
static void test_magnetometer(void)
{
    mag_register_write seq[MAG_SEQUENCE_LENGTH];
    /* LIS3MDL at 80 Hz: OM = 11, DO = 111; +-4 gauss; OMZ = 11; BDU; continuous last. */
    CHECK(mag_rate_mhz(MAG_CHIP_LIS3MDL, 104167u) == 80000u);
    CHECK(mag_rate_mhz(MAG_CHIP_LIS3MDL, 52083u) == 40000u);
    CHECK(mag_rate_mhz(MAG_CHIP_LIS3MDL, 13021u) == 10000u);
    CHECK(mag_rate_mhz(MAG_CHIP_LIS2MDL, 52083u) == 50000u);
    CHECK(mag_rate_mhz(MAG_CHIP_LIS2MDL, 6666667u) == 100000u);
    CHECK(mag_sequence(MAG_CHIP_LIS3MDL, 80000u, seq) == 5u);
    CHECK(seq[0].reg == 0x20 && seq[0].value == 0x7C);
    CHECK(seq[2].reg == 0x23 && seq[2].value == 0x0C);
    CHECK(seq[3].reg == 0x24 && seq[3].value == 0x40);
    CHECK(seq[4].reg == 0x22 && seq[4].value == 0x00);
    CHECK(mag_sequence(MAG_CHIP_LIS2MDL, 20000u, seq) == 3u);
    CHECK(seq[0].reg == 0x61 && seq[0].value == 0x03);
    CHECK(seq[1].reg == 0x62 && seq[1].value == 0x10);
    CHECK(seq[2].reg == 0x60 && seq[2].value == 0x84);
    /* MAG_SAMPLES: 4 + 10 bytes per sample before the CRC. */
    uint8_t wire[LINK_MAX_WIRE];
    uint32_t t[2] = {0x00012345u, 0x00012545u};
    int16_t xyz[2][3] = {{1000, -2000, 3000}, {-1, 0, 32767}};
    size_t n = link_encode_mag_samples(0x0102, t, (const int16_t(*)[3])xyz, 2, wire);
    uint8_t packet[64];
    int m = cobs_decode(wire, n - 1, packet, sizeof packet);
    CHECK(m == 1 + 3 + 20 + 2 && packet[0] == LINK_MAG_SAMPLES && packet[3] == 2);
    CHECK(link_encode_mag_samples(0, t, (const int16_t(*)[3])xyz, 0, wire) == 0);
    /* One sensor leaves room at every rate it streams; two at 833 Hz do not. */
    CHECK(fw_mag_fits(8, 921600u, 400000u, 1, 80000u));
    CHECK(fw_mag_fits(6, 921600u, 400000u, 2, 80000u));
    CHECK(!fw_mag_fits(7, 921600u, 400000u, 2, 80000u));
    CHECK(!fw_mag_fits(7, 115200u, 400000u, 1, 80000u));
}

int main(void)
{
    test_crc();
    test_cobs_round_trips();
    test_cobs_rejects();
    test_rx_resync();
    test_fifo_stream_packets();
    test_fifo_stream_discards_settling_samples();
    test_odr_tables();
    test_fifo_stream_hole_and_overrun();
    test_fifo_stream_measures_rate();
    test_fifo_stream_timestamps_wrap();
    test_fifo_stream_long_runs_keep_the_rate();
    test_core_with_fake_bus();
    test_status_and_retries();
    test_rates();
    test_two_sensors();
    test_rates_two_sensors();
    test_uart_divisor();
    test_magnetometer();
    printf("%d checks, %d failed\n", checks, failures);
    return failures ? 1 : 0;
}
