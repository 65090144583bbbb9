/* CRC-32/ISO-HDLC (frames) and CRC-8/SMBUS (frame headers). */
#ifndef CRC_H
#define CRC_H
#include <stdint.h>

#define CRC32_INIT 0xFFFFFFFFUL
uint32_t crc32_update(uint32_t crc, uint8_t byte); /* running value, no final XOR */
uint32_t crc32(const uint8_t *data, uint16_t len);  /* final value (XOR applied) */
uint8_t crc8(const uint8_t *data, uint8_t len);

#endif
