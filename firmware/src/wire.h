/* Message fields: u8, LEB128 varints (uv), zigzag varints (sv), text.
 * Every field is bounded by its C width: a varint longer than 10 bytes or
 * beyond 32 bits is an error, never a silent truncation. */
#ifndef WIRE_H
#define WIRE_H
#include <stdint.h>

struct reader {
    const uint8_t *buf;
    uint8_t pos, len, err;
};

struct writer {
    uint8_t *buf;
    uint8_t pos, cap, err;
};

uint8_t rd_u8(struct reader *r);
uint32_t rd_uv(struct reader *r);
int32_t rd_sv(struct reader *r);
void rd_text(struct reader *r);

void wr_u8(struct writer *w, uint8_t v);
void wr_uv(struct writer *w, uint32_t v);
void wr_sv(struct writer *w, int32_t v);
void wr_text(struct writer *w, const char *s);

#endif
