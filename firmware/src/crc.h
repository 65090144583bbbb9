/* CRC-32/ISO-HDLC (frames) and CRC-8/SMBUS (frame headers). */
#ifndef CRC_H
#define CRC_H
#include <stdint.h>

#define CRC32_INIT 0xFFFFFFFFUL
/* the running value over `len` bytes more (no final XOR): a frame sent in pieces */
uint32_t crc32_run(uint32_t crc, const uint8_t *data, uint8_t len);
uint32_t crc32(const uint8_t *data, uint16_t len);  /* final value (XOR applied) */
uint8_t crc8(const uint8_t *data, uint8_t len);

#endif
