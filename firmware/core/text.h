/* A bounded text builder for ACK and LOG messages (no printf: it would cost kilobytes). */
#ifndef FW_TEXT_H
#define FW_TEXT_H

#include <stddef.h>
#include <stdint.h>

typedef struct text {
    char *buf;
    size_t size; /* including the terminating 0 */
    size_t length;
} text;

void text_init(text *t, char *buf, size_t size);
text *text_str(text *t, const char *s);
text *text_u32(text *t, uint32_t value);
text *text_i32(text *t, int32_t value);
/* Two upper-case hex digits, with a 0x prefix. */
text *text_hex8(text *t, uint8_t value);
/* A rate in millihertz as Hz: 12500 -> "12.5", 104000 -> "104". */
text *text_mhz(text *t, uint32_t millihertz);

#endif
