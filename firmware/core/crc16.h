/* CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection): the link protocol's CRC. */
#ifndef FW_CRC16_H
#define FW_CRC16_H

#include <stddef.h>
#include <stdint.h>

#define CRC16_INIT 0xFFFFu

/* Continue a CRC over `length` bytes (start with CRC16_INIT). */
uint16_t crc16_update(uint16_t crc, const uint8_t *data, size_t length);

/* The CRC of `length` bytes; crc16("123456789") == 0x29B1. */
uint16_t crc16(const uint8_t *data, size_t length);

#endif
