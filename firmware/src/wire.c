#include "wire.h"

uint8_t rd_u8(struct reader *r)
{
    if (r->pos >= r->len) {
        r->err = 1;
        return 0;
    }
    return r->buf[r->pos++];
}

uint32_t rd_bounded(struct reader *r, uint8_t bits)
{
    if (r->pos < r->len && !(r->buf[r->pos] & 0x80))
        return r->buf[r->pos++]; /* one byte (most fields): fits every width */
    uint8_t max_bytes = (uint8_t)((bits + 6) / 7);
    uint32_t value = 0;
    for (uint8_t i = 0; i < max_bytes; i++) {
        if (r->pos >= r->len) {
            r->err = 1;
            return 0;
        }
        uint8_t b = r->buf[r->pos++];
        uint8_t shift = (uint8_t)(7 * i);
        uint32_t part = (uint32_t)(b & 0x7F);
        /* the bits that would fall beyond the field's width */
        if (shift + 7 > bits && (part >> (bits - shift)))
            r->err = 1;
        value |= part << shift;
        if (!(b & 0x80))
            return r->err ? 0 : value;
    }
    r->err = 1; /* longer than the field allows */
    return 0;
}

uint32_t rd_field(struct reader *r, uint8_t type)
{
    switch (type) {
    case FT_U8:
        return rd_u8(r);
    case FT_U16:
    case FT_I16:
        return rd_bounded(r, 16);
    default:
        return rd_bounded(r, 32);
    }
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
