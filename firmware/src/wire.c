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
    uint8_t pos = r->pos;
    uint8_t left = pos < r->len ? (uint8_t)(r->len - pos) : 0;
    const uint8_t *p = r->buf + pos;
    if (!left)
        goto bad;
    uint8_t g = p[0];
    if (!(g & 0x80)) {
        r->pos = (uint8_t)(pos + 1);
        return g; /* one byte (most fields): fits every width */
    }
    /* each 7-bit group into the value's bytes as it comes, unrolled (a variable 32-bit
     * shift is a loop on the AVR): group i holds bits 7i..7i + 6 */
    union {
        uint32_t u;
        uint8_t b[4];
    } v;
    uint8_t n;
    v.u = g & 0x7F;
    if (left < 2)
        goto bad;
    g = p[1];
    v.b[0] |= (uint8_t)(g << 7);
    v.b[1] = (uint8_t)((g & 0x7F) >> 1);
    if (!(g & 0x80)) {
        n = 2;
        goto done;
    }
    if (left < 3)
        goto bad;
    g = p[2];
    v.b[1] |= (uint8_t)(g << 6);
    v.b[2] = (uint8_t)((g & 0x7F) >> 2);
    if (bits <= 16) {
        if (g & 0xFC)
            goto bad; /* a fourth byte, or bits beyond 16 */
        n = 3;
        goto done;
    }
    if (!(g & 0x80)) {
        n = 3;
        goto done;
    }
    if (left < 4)
        goto bad;
    g = p[3];
    v.b[2] |= (uint8_t)(g << 5);
    v.b[3] = (uint8_t)((g & 0x7F) >> 3);
    if (!(g & 0x80)) {
        n = 4;
        goto done;
    }
    if (left < 5)
        goto bad;
    g = p[4];
    if (g & 0xF0)
        goto bad; /* a sixth byte, or bits beyond 32 */
    v.b[3] |= (uint8_t)(g << 4);
    n = 5;
done:
    r->pos = (uint8_t)(pos + n);
    return v.u;
bad:
    r->err = 1; /* cut short, longer than the field allows or beyond its width */
    return 0;
}

void rd_skip(struct reader *r, uint8_t bits)
{
    uint8_t pos = r->pos, len = r->len;
    uint8_t last = bits > 16 ? 4 : 2; /* the field's last byte, as rd_bounded */
    uint8_t beyond = bits > 16 ? 0xF0 : 0xFC;
    for (uint8_t i = 0;; i++, pos++) {
        if (pos >= len) {
            r->err = 1;
            return;
        }
        uint8_t g = r->buf[pos];
        if (i == last) {
            if (g & beyond)
                r->err = 1;
            break;
        }
        if (!(g & 0x80))
            break;
    }
    r->pos = (uint8_t)(pos + 1);
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

/* v >> 7 by moving bytes (-Os makes a loop of seven 32-bit shifts) */
static inline __attribute__((always_inline)) uint32_t shr7(uint32_t v)
{
    union { uint32_t u; uint8_t b[4]; } x = {v}, y;
    y.b[0] = x.b[1];
    y.b[1] = x.b[2];
    y.b[2] = x.b[3];
    y.b[3] = 0;
    return (y.u << 1) | (x.b[0] >> 7);
}

/* (a report's every FLOW: its bytes written in place when five fit, not one call each) */
void wr_uv(struct writer *w, uint32_t v)
{
    uint8_t pos = w->pos;
    if ((uint8_t)(w->cap - pos) < 5 || pos > w->cap) {
        while (v >= 0x80) {
            wr_u8(w, (uint8_t)(v | 0x80));
            v = shr7(v);
        }
        wr_u8(w, (uint8_t)v);
        return;
    }
    uint8_t *p = w->buf + pos;
    while (v >= 0x80) {
        *p++ = (uint8_t)(v | 0x80);
        v = shr7(v);
    }
    *p++ = (uint8_t)v;
    w->pos = (uint8_t)(p - w->buf);
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
