/* CRC-16/CCITT-FALSE, bit by bit: a few hundred bytes per packet, no table needed. */
#include "crc16.h"

uint16_t crc16_update(uint16_t crc, const uint8_t *data, size_t length)
{
    while (length--) {
        crc ^= (uint16_t)((uint16_t)*data++ << 8);
        for (int bit = 0; bit < 8; bit++)
            crc = (crc & 0x8000u) ? (uint16_t)((crc << 1) ^ 0x1021u) : (uint16_t)(crc << 1);
    }
    return crc;
}

uint16_t crc16(const uint8_t *data, size_t length)
{
    return crc16_update(CRC16_INIT, data, length);
}
