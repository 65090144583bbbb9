/* CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF; CRC-8/SMBUS: poly 0x07, init 0. */
#include "crc.h"

uint16_t crc16_update(uint16_t crc, uint8_t byte)
{
    /* nibble-free bytewise form of the 0x1021 polynomial (no table: flash and RAM are dear) */
    uint8_t x = (uint8_t)(crc >> 8) ^ byte;
    x ^= x >> 4;
    return (uint16_t)((crc << 8) ^ ((uint16_t)x << 12) ^ ((uint16_t)x << 5) ^ x);
}

uint16_t crc16(const uint8_t *data, uint16_t len)
{
    uint16_t crc = 0xFFFF;
    while (len--)
        crc = crc16_update(crc, *data++);
    return crc;
}

uint8_t crc8(const uint8_t *data, uint8_t len)
{
    uint8_t crc = 0;
    while (len--) {
        crc ^= *data++;
        for (uint8_t i = 0; i < 8; i++)
            crc = (crc & 0x80) ? (uint8_t)((crc << 1) ^ 0x07) : (uint8_t)(crc << 1);
    }
    return crc;
}
