/* Message fields: u8, bounded LEB128 varints (u16/u32, zigzag i16/i32), text.
 * A varint longer than its field allows (3 bytes for 16 bits, 5 for 32) or a
 * value beyond the field's width is an error, never a silent truncation. */
#ifndef WIRE_H
#define WIRE_H
#include <stdint.h>

enum { FT_U8, FT_U16, FT_U32, FT_I16, FT_I32 }; /* descriptor types, as protocol_gen.h */

struct reader {
    const uint8_t *buf;
    uint8_t pos, len, err;
};

struct writer {
    uint8_t *buf;
    uint8_t pos, cap, err;
};

uint8_t rd_u8(struct reader *r);
uint32_t rd_bounded(struct reader *r, uint8_t bits);       /* unsigned, 16 or 32 bits */
uint32_t rd_field(struct reader *r, uint8_t type);         /* any descriptor type, raw bits */
void rd_skip(struct reader *r, uint8_t bits); /* a varint passed, its form checked as rd_bounded's */
static inline int32_t unzigzag(uint32_t u)
{
    return (int32_t)((u >> 1) ^ (uint32_t)-(int32_t)(u & 1));
}

void wr_u8(struct writer *w, uint8_t v);
void wr_uv(struct writer *w, uint32_t v);
void wr_sv(struct writer *w, int32_t v);
void wr_text(struct writer *w, const char *s);

#endif
