/* Bounded text building: output stops at the buffer's end, always 0-terminated. */
#include "text.h"

void text_init(text *t, char *buf, size_t size)
{
    t->buf = buf;
    t->size = size;
    t->length = 0;
    if (size)
        buf[0] = 0;
}

static void put(text *t, char c)
{
    if (t->length + 1 < t->size) {
        t->buf[t->length++] = c;
        t->buf[t->length] = 0;
    }
}

text *text_str(text *t, const char *s)
{
    while (s && *s)
        put(t, *s++);
    return t;
}

text *text_u32(text *t, uint32_t value)
{
    char digits[10];
    int n = 0;
    do {
        digits[n++] = (char)('0' + value % 10u);
        value /= 10u;
    } while (value);
    while (n)
        put(t, digits[--n]);
    return t;
}

text *text_i32(text *t, int32_t value)
{
    if (value < 0) {
        put(t, '-');
        return text_u32(t, (uint32_t)(-(int64_t)value));
    }
    return text_u32(t, (uint32_t)value);
}

text *text_hex8(text *t, uint8_t value)
{
    static const char hex[] = "0123456789ABCDEF";
    text_str(t, "0x");
    put(t, hex[value >> 4]);
    put(t, hex[value & 0x0Fu]);
    return t;
}

text *text_mhz(text *t, uint32_t millihertz)
{
    text_u32(t, millihertz / 1000u);
    uint32_t fraction = millihertz % 1000u;
    if (fraction) {
        put(t, '.');
        int digits = 3;
        while (fraction % 10u == 0) {
            fraction /= 10u;
            digits--;
        }
        for (int d = digits - 1; d >= 0; d--) {
            uint32_t power = 1;
            for (int k = 0; k < d; k++)
                power *= 10u;
            put(t, (char)('0' + (fraction / power) % 10u));
        }
    }
    return t;
}
