/* CRC-16/CCITT-FALSE (frames) and CRC-8/SMBUS (frame headers). */
#ifndef CRC_H
#define CRC_H
#include <stdint.h>

uint16_t crc16_update(uint16_t crc, uint8_t byte);
uint16_t crc16(const uint8_t *data, uint16_t len);
uint8_t crc8(const uint8_t *data, uint8_t len);

#endif
