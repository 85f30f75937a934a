/* COBS encoder and decoder (docs/protocol.md section 2). */
#include "cobs.h"

size_t cobs_encode(const uint8_t *in, size_t length, uint8_t *out)
{
    size_t code_at = 0, o = 1;
    uint8_t code = 1;
    for (size_t i = 0; i < length; i++) {
        if (in[i] == 0) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
            continue;
        }
        out[o++] = in[i];
        if (++code == 0xFF) {
            out[code_at] = code;
            code_at = o++;
            code = 1;
        }
    }
    out[code_at] = code;
    return o;
}

int cobs_decode(const uint8_t *frame, size_t length, uint8_t *out, size_t out_size)
{
    size_t i = 0, o = 0;
    while (i < length) {
        uint8_t code = frame[i++];
        if (code == 0 || i + (size_t)(code - 1) > length)
            return -1;
        for (uint8_t k = 1; k < code; k++) {
            if (frame[i] == 0 || o >= out_size)
                return -1;
            out[o++] = frame[i++];
        }
        /* A code below 255 stands for its bytes and a 0x00, except at the very end. */
        if (code != 0xFF && i < length) {
            if (o >= out_size)
                return -1;
            out[o++] = 0;
        }
    }
    return (int)o;
}
