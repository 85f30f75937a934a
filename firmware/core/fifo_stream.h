/* From LSM6DSOX FIFO words to SAMPLES packets: slots, timestamps, packet boundaries.
 *
 * The FIFO holds tagged words; TAG_CNT (2 bits) steps by one per time slot, and the words of one
 * slot (gyroscope, accelerometer, and the timestamp or temperature when batched) share it. A
 * sample is a slot with both a gyroscope and an accelerometer word. Every 8th slot carries a
 * timestamp word: an anchor tying that slot to the chip's 32-bit tick counter. A packet's t0 is
 * placed from the nearest anchor and the tick period per slot measured between anchors, so a
 * packet waits for the first anchor after a (re)start (at most 8 slots).
 *
 * A packet is cut when it holds 32 samples, when its first sample is `flush_after_us` old, and
 * before any discontinuity (a lost slot, an overrun), because the samples of one packet must be
 * consecutive. Lost data are reported by skipping a sequence number, which tells the host to
 * measure the loss from the timestamps (docs/protocol.md section 5). */
#ifndef FW_FIFO_STREAM_H
#define FW_FIFO_STREAM_H

#include <stdbool.h>
#include <stdint.h>

#include "link.h"

typedef struct fifo_packet {
    uint16_t seq;
    uint32_t t0;
    int16_t temperature_raw;
    uint8_t count;
    int16_t samples[LINK_MAX_SAMPLES][6]; /* gx, gy, gz, ax, ay, az */
} fifo_packet;

typedef struct fifo_stream_counters {
    uint32_t words;
    uint32_t unknown_tags;
    uint32_t incomplete_slots;  /* a slot with only one of gyroscope and accelerometer */
    uint32_t lost_slots;        /* TAG_CNT jumped */
    uint32_t overruns;
    uint32_t samples;
    uint32_t packets;
    uint32_t dropped_packets;   /* sequence numbers skipped (data lost before the host) */
    uint32_t settling;          /* samples discarded as the sensor's turn-on transient */
} fifo_stream_counters;

typedef struct fifo_stream {
    /* slot counting */
    bool have_cnt;
    uint8_t prev_cnt;
    uint32_t slot;
    uint8_t pend_flags; /* bit 0 gyro, bit 1 accel of the slot being assembled */
    int16_t pend[6];
    /* anchors: slot -> ticks */
    bool have_anchor;
    uint32_t anchor_slot, anchor_ticks;
    bool have_base;
    uint32_t base_slot, base_ticks;    /* first anchor since the (re)start: measures the rate */
    uint64_t ticks_per_slot_q16;       /* measured, else nominal */
    uint64_t nominal_ticks_per_slot_q16;
    int16_t temperature_raw;
    uint32_t discard;                  /* samples still to drop (turn-on transient) */
    /* packet being assembled */
    fifo_packet packet;
    uint32_t first_slot;
    uint32_t first_us;                 /* when its first sample was read */
    uint16_t next_seq;                 /* keeps counting across STOP and START */
    uint32_t flush_after_us;
    fifo_stream_counters counters;
} fifo_stream;

/* A complete packet: the caller sends it (or drops it, keeping its sequence number). */
typedef void (*fifo_packet_sink)(void *ctx, const fifo_packet *packet);

/* Power-on state: sequence numbers from 0. */
void fifo_stream_init(fifo_stream *s, uint32_t flush_after_us);

/* Start of a stream (the FIFO was emptied): forget slots, anchors and waiting samples; keep the
 * sequence number. `odr_mhz_nominal` sets the tick period per slot until it is measured. */
void fifo_stream_restart(fifo_stream *s, uint32_t odr_mhz_nominal, int16_t temperature_raw);

/* Drop the next `samples` samples (the turn-on transient after a (re)configure) before they
 * enter a packet. They are not a loss: no sequence number is skipped, and the first packet's
 * t0 is the time of the first sample kept. Cleared by fifo_stream_restart. */
void fifo_stream_discard(fifo_stream *s, uint32_t samples);

/* Feed `words` FIFO words read at `now_us`; complete packets go to `sink`. */
void fifo_stream_feed(fifo_stream *s, const uint8_t *data, uint16_t words, uint32_t now_us,
                      fifo_packet_sink sink, void *ctx);

/* The FIFO overran: words were lost. Sends what is waiting (when it can be timed), skips a
 * sequence number and restarts slot counting; the next packet waits for a new anchor. */
void fifo_stream_overrun(fifo_stream *s, fifo_packet_sink sink, void *ctx);

/* Send the waiting packet if it is due (32 samples, or its first sample older than
 * flush_after_us) or `force`d, and it can be timed. */
void fifo_stream_flush(fifo_stream *s, uint32_t now_us, bool force, fifo_packet_sink sink,
                       void *ctx);

#endif
