#include "protocol_gen.h"
#include "wire.h"

uint8_t rd_u8(struct reader *r)
{
    if (r->pos >= r->len) {
        r->err = 1;
        return 0;
    }
    return r->buf[r->pos++];
}

uint32_t rd_uv(struct reader *r)
{
    uint32_t value = 0;
    for (uint8_t i = 0; i < MAX_VARINT_BYTES; i++) {
        if (r->pos >= r->len) {
            r->err = 1;
            return 0;
        }
        uint8_t b = r->buf[r->pos++];
        uint8_t bits = b & 0x7F;
        if (i < 4)
            value |= (uint32_t)bits << (7 * i);
        else if (i == 4) {
            if (bits > 0x0F)
                r->err = 1; /* beyond 32 bits */
            value |= (uint32_t)bits << 28;
        } else if (bits)
            r->err = 1;
        if (!(b & 0x80))
            return r->err ? 0 : value;
    }
    r->err = 1; /* longer than 10 bytes */
    return 0;
}

int32_t rd_sv(struct reader *r)
{
    uint32_t u = rd_uv(r);
    return (int32_t)((u >> 1) ^ (uint32_t)-(int32_t)(u & 1));
}

void rd_text(struct reader *r)
{
    uint8_t n = rd_u8(r);
    if ((uint16_t)r->pos + n > r->len)
        r->err = 1;
    else
        r->pos += n;
}

void wr_u8(struct writer *w, uint8_t v)
{
    if (w->pos >= w->cap) {
        w->err = 1;
        return;
    }
    w->buf[w->pos++] = v;
}

void wr_uv(struct writer *w, uint32_t v)
{
    while (v >= 0x80) {
        wr_u8(w, (uint8_t)(v | 0x80));
        v >>= 7;
    }
    wr_u8(w, (uint8_t)v);
}

void wr_sv(struct writer *w, int32_t v)
{
    wr_uv(w, v >= 0 ? (uint32_t)v << 1 : (((uint32_t)(-(v + 1))) << 1) | 1);
}

void wr_text(struct writer *w, const char *s)
{
    uint8_t n = 0;
    while (s[n])
        n++;
    wr_u8(w, n);
    while (*s)
        wr_u8(w, (uint8_t)*s++);
}
