/* CRC-32/ISO-HDLC: reflected polynomial 0xEDB88320, init and final XOR 0xFFFFFFFF
 * (check value 0xCBF43926), a nibble at a time from a 16-entry table in flash.
 * CRC-8/SMBUS: polynomial 0x07, init 0 (check value 0xF4). */
#include <avr/pgmspace.h>

#include "crc.h"

static const uint32_t nibble_table[16] PROGMEM = {
    0x00000000UL, 0x1DB71064UL, 0x3B6E20C8UL, 0x26D930ACUL, 0x76DC4190UL, 0x6B6B51F4UL,
    0x4DB26158UL, 0x5005713CUL, 0xEDB88320UL, 0xF00F9344UL, 0xD6D6A3E8UL, 0xCB61B38CUL,
    0x9B64C2B0UL, 0x86D3D2D4UL, 0xA00AE278UL, 0xBDBDF21CUL};

uint32_t crc32_update(uint32_t crc, uint8_t byte)
{
    crc ^= byte;
    crc = (crc >> 4) ^ pgm_read_dword(&nibble_table[crc & 0x0F]);
    crc = (crc >> 4) ^ pgm_read_dword(&nibble_table[crc & 0x0F]);
    return crc;
}

uint32_t crc32(const uint8_t *data, uint16_t len)
{
    uint32_t crc = CRC32_INIT;
    while (len--)
        crc = crc32_update(crc, *data++);
    return crc ^ 0xFFFFFFFFUL;
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
