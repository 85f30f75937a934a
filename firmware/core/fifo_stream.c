/* LSM6DSOX FIFO words -> SAMPLES packets (see fifo_stream.h). */
#include "fifo_stream.h"

#include <string.h>

#include "lsm6dsox.h"

#define FLAG_GYRO 0x01u
#define FLAG_ACCEL 0x02u
#define FLAG_SENT 0x04u
/* A measured tick period per slot is believed when within 25 % of the nominal one (the trim
 * spans +-19 %); a wrong timestamp word would otherwise skew every later t0. */
#define RATE_TOLERANCE_PERCENT 25u
#define REBASE_TICKS (1u << 30) /* keep (ticks - base) far from the 2^32 wrap */

void fifo_stream_init(fifo_stream *s, uint32_t flush_after_us)
{
    memset(s, 0, sizeof *s);
    s->flush_after_us = flush_after_us;
}

void fifo_stream_restart(fifo_stream *s, uint32_t odr_mhz_nominal, int16_t temperature_raw)
{
    s->have_cnt = false;
    s->slot = 0;
    s->pend_flags = 0;
    s->have_anchor = false;
    s->have_base = false;
    /* 40000 ticks of 25 us per second: ticks per slot = 40000 / ODR. */
    s->nominal_ticks_per_slot_q16 = odr_mhz_nominal
        ? (((uint64_t)40000 * 1000u) << 16) / odr_mhz_nominal : (uint64_t)1 << 16;
    s->ticks_per_slot_q16 = s->nominal_ticks_per_slot_q16;
    s->temperature_raw = temperature_raw;
    s->discard = 0;
    s->packet.count = 0;
}

void fifo_stream_discard(fifo_stream *s, uint32_t samples)
{
    s->discard = samples;
}

/* t0 of the waiting packet, when an anchor can place it. */
static bool packet_t0(const fifo_stream *s, uint32_t *t0)
{
    if (!s->have_anchor)
        return false;
    int64_t slots = (int32_t)(s->first_slot - s->anchor_slot);
    int64_t offset_q16 = slots * (int64_t)s->ticks_per_slot_q16;
    int64_t offset = offset_q16 >= 0 ? (offset_q16 + 0x8000) >> 16 : -((-offset_q16 + 0x8000) >> 16);
    *t0 = s->anchor_ticks + (uint32_t)offset;
    return true;
}

/* A sequence number is skipped: the host measures the loss from the timestamps. */
static void skip_sequence_number(fifo_stream *s)
{
    s->next_seq++;
    s->counters.dropped_packets++;
}

static void send(fifo_stream *s, uint32_t t0, fifo_packet_sink sink, void *ctx)
{
    s->packet.seq = s->next_seq++;
    s->packet.t0 = t0;
    s->packet.temperature_raw = s->temperature_raw;
    sink(ctx, &s->packet);
    s->counters.packets++;
    s->packet.count = 0;
}

void fifo_stream_flush(fifo_stream *s, uint32_t now_us, bool force, fifo_packet_sink sink,
                       void *ctx)
{
    if (s->packet.count == 0)
        return;
    bool due = force || s->packet.count == LINK_MAX_SAMPLES ||
               (uint32_t)(now_us - s->first_us) >= s->flush_after_us;
    uint32_t t0;
    if (due && packet_t0(s, &t0))
        send(s, t0, sink, ctx);
}

/* Samples that cannot be timed or sent: give up their packet, keeping its sequence number. */
static void drop_waiting(fifo_stream *s)
{
    if (s->packet.count) {
        s->packet.count = 0;
        skip_sequence_number(s);
    }
}

/* Samples of one packet must be consecutive: send what waits before a hole. */
static void cut(fifo_stream *s, uint32_t now_us, fifo_packet_sink sink, void *ctx)
{
    fifo_stream_flush(s, now_us, true, sink, ctx);
    drop_waiting(s);
}

static void add_sample(fifo_stream *s, uint32_t now_us, fifo_packet_sink sink, void *ctx)
{
    fifo_packet *packet = &s->packet;
    if (s->discard) { /* settling: never streamed, and not a gap */
        s->discard--;
        s->counters.settling++;
        return;
    }
    if (packet->count && s->slot != s->first_slot + packet->count) {
        cut(s, now_us, sink, ctx);
        skip_sequence_number(s); /* the samples of the hole */
    }
    if (packet->count == LINK_MAX_SAMPLES)
        drop_waiting(s); /* full and still no anchor: timestamps are not being batched */
    if (packet->count == 0) {
        s->first_slot = s->slot;
        s->first_us = now_us;
    }
    memcpy(packet->samples[packet->count++], s->pend, sizeof s->pend);
    s->counters.samples++;
    fifo_stream_flush(s, now_us, false, sink, ctx);
}

static void add_anchor(fifo_stream *s, uint32_t ticks)
{
    if (s->have_base && ticks - s->base_ticks > REBASE_TICKS)
        s->have_base = false;
    if (!s->have_base) {
        s->have_base = true;
        s->base_slot = s->slot;
        s->base_ticks = ticks;
    } else if ((int32_t)(s->slot - s->base_slot) >= (int32_t)LSM_TIMESTAMP_DECIMATION) {
        uint64_t measured = ((uint64_t)(ticks - s->base_ticks) << 16) / (s->slot - s->base_slot);
        uint64_t nominal = s->nominal_ticks_per_slot_q16;
        uint64_t margin = nominal * RATE_TOLERANCE_PERCENT / 100u;
        if (measured + margin >= nominal && measured <= nominal + margin) {
            s->ticks_per_slot_q16 = measured;
        } else { /* an implausible timestamp: measure again from here */
            s->base_slot = s->slot;
            s->base_ticks = ticks;
        }
    }
    s->have_anchor = true;
    s->anchor_slot = s->slot;
    s->anchor_ticks = ticks;
}

void fifo_stream_feed(fifo_stream *s, const uint8_t *data, uint16_t words, uint32_t now_us,
                      fifo_packet_sink sink, void *ctx)
{
    for (uint16_t w = 0; w < words; w++, data += LSM_FIFO_WORD_BYTES) {
        uint8_t tag = (uint8_t)(data[0] >> 3);
        uint8_t cnt = (uint8_t)((data[0] >> 1) & 0x03u);
        s->counters.words++;
        if (tag < LSM_TAG_GYRO || tag > LSM_TAG_CFG_CHANGE) {
            s->counters.unknown_tags++;
            continue;
        }
        if (!s->have_cnt) {
            s->have_cnt = true;
            s->prev_cnt = cnt;
        } else if (cnt != s->prev_cnt) {
            uint8_t step = (uint8_t)((cnt - s->prev_cnt) & 0x03u);
            if ((s->pend_flags & (FLAG_GYRO | FLAG_ACCEL)) && !(s->pend_flags & FLAG_SENT))
                s->counters.incomplete_slots++;
            s->counters.lost_slots += step - 1u;
            s->slot += step;
            s->prev_cnt = cnt;
            s->pend_flags = 0;
        }
        const uint8_t *d = data + 1;
        switch (tag) {
        case LSM_TAG_GYRO:
        case LSM_TAG_ACCEL: {
            uint8_t flag = tag == LSM_TAG_GYRO ? FLAG_GYRO : FLAG_ACCEL;
            if (s->pend_flags & (flag | FLAG_SENT))
                break; /* a second word of the same sensor in one slot: keep the first */
            int16_t *out = s->pend + (tag == LSM_TAG_GYRO ? 0 : 3);
            for (int axis = 0; axis < 3; axis++)
                out[axis] = (int16_t)get_u16(d + 2 * axis);
            s->pend_flags |= flag;
            if ((s->pend_flags & (FLAG_GYRO | FLAG_ACCEL)) == (FLAG_GYRO | FLAG_ACCEL)) {
                s->pend_flags |= FLAG_SENT;
                add_sample(s, now_us, sink, ctx);
            }
            break;
        }
        case LSM_TAG_TEMPERATURE:
            s->temperature_raw = (int16_t)get_u16(d);
            break;
        case LSM_TAG_TIMESTAMP:
            add_anchor(s, get_u32(d));
            break;
        default: /* CFG_CHANGE: the settings do not change while streaming */
            break;
        }
    }
}

void fifo_stream_overrun(fifo_stream *s, fifo_packet_sink sink, void *ctx)
{
    s->counters.overruns++;
    /* What waits was read before the overwrite: send it, then mark the loss. */
    fifo_stream_flush(s, s->first_us, true, sink, ctx);
    drop_waiting(s);
    skip_sequence_number(s);
    s->have_cnt = false;
    s->pend_flags = 0;
    s->have_anchor = false;
    s->have_base = false;
}
