/* Consistent Overhead Byte Stuffing (Cheshire and Baker 1999), as docs/protocol.md frames it. */
#ifndef FW_COBS_H
#define FW_COBS_H

#include <stddef.h>
#include <stdint.h>

/* Longest encoding of `n` bytes: one code byte, plus one per 254 data bytes. */
#define COBS_MAX_ENCODED(n) ((n) + (n) / 254u + 1u)

/* Encode `length` bytes into `out` (room for COBS_MAX_ENCODED(length)); returns the encoded
 * length. The output holds no 0x00; the caller sends the 0x00 delimiter. */
size_t cobs_encode(const uint8_t *in, size_t length, uint8_t *out);

/* Decode one frame (without its 0x00) into `out` (room for `out_size` bytes). Returns the
 * decoded length, or -1 when the frame holds a 0x00, a code points past its end, or the
 * result does not fit. Accepts both forms of a frame ending after a 254-byte run. */
int cobs_decode(const uint8_t *frame, size_t length, uint8_t *out, size_t out_size);

#endif
