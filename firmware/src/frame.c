/* Deframer: the same rules as firmware_protocol/framing.py. A candidate starts
 * at each SYNC; a bad header, an oversize LEN, an unknown KIND, a bad CRC or a
 * missing END drops only that SYNC byte and the scan resumes at the next byte.
 * A candidate still waiting for bytes is abandoned as soon as a complete valid
 * frame sits behind it. */
#include <string.h>

#include "config.h"
#include "crc.h"
#include "frame.h"
#include "uart.h"

struct deframer_stats deframer_stats;
static const struct frame_upper *upper;

void deframer_attach(const struct frame_upper *u)
{
    upper = u;
}
static uint8_t buf[DEFRAME_BUF];
static uint16_t fill;
/* buf[0..held) holds frames acknowledged but not executed yet (a FIFO: executed from
 * the front, checked and appended behind it); the scan for new frames starts there */
static uint16_t held;
static uint8_t drop_held;

const uint8_t *deframer_first(uint8_t *len)
{
    if (!held)
        return 0;
    *len = buf[1];
    return buf + FRAME_HEADER_LEN;
}

void deframer_pop(void)
{
    uint16_t total = FRAME_OVERHEAD + buf[1];
    memmove(buf, buf + total, fill - total);
    fill -= total;
    held -= total;
}

void deframer_drop_held(void)
{
    drop_held = 1;
}

#if STEP_ENGINE /* (only its frames wait on more than the queue's room) */
uint8_t deframer_room_behind(uint8_t len)
{
    return held + FRAME_SIZE(len) + FRAME_MAX <= DEFRAME_BUF;
}
#endif

uint8_t deframer_more_behind(uint8_t len)
{
    return fill > held + FRAME_SIZE(len);
}

void deframer_receive(void)
{
    fill += uart_read(buf + fill, DEFRAME_BUF - fill);
}

static uint8_t header_ok(const uint8_t *p)
{
    return crc8(p + 1, 4) == p[5] && p[1] <= FRAME_MAX_PAYLOAD && p[2] >= KIND_DATA &&
           p[2] <= KIND_URGENT;
}

static uint8_t body_ok(const uint8_t *p)
{
    uint8_t len = p[1];
    uint16_t end = FRAME_HEADER_LEN + (uint16_t)len;
    if (p[end + FRAME_CRC_LEN] != FRAME_END)
        return 0; /* cheaper than the CRC: a shortened frame fails here */
    uint32_t crc = crc32(p + 1, end - 1);
    return p[end] == (uint8_t)(crc >> 24) && p[end + 1] == (uint8_t)(crc >> 16) &&
           p[end + 2] == (uint8_t)(crc >> 8) && p[end + 3] == (uint8_t)crc;
}

/* First complete valid frame at or after start, or -1. */
static int16_t complete_frame_after(uint16_t start)
{
    for (uint16_t i = start; i + FRAME_OVERHEAD <= fill; i++) {
        if (buf[i] != FRAME_SYNC)
            continue;
        uint8_t len = buf[i + 1];
        if (len > FRAME_MAX_PAYLOAD || i + FRAME_OVERHEAD + len > fill)
            continue;
        if (crc8(buf + i + 1, 4) == buf[i + 5] && body_ok(buf + i))
            return (int16_t)i;
    }
    return -1;
}

void deframer_run(void)
{
    uint16_t pos = held;
    for (;;) {
        upper->meanwhile();
        while (pos < fill && buf[pos] != FRAME_SYNC)
            pos++;
        if (fill - pos < FRAME_HEADER_LEN)
            break;
        uint8_t *p = buf + pos;
        if (!header_ok(p)) {
            deframer_stats.bad_headers++;
            pos++;
            continue;
        }
        uint16_t total = FRAME_OVERHEAD + p[1];
        if (fill - pos < total) {
            int16_t later = complete_frame_after(pos + 1);
            if (later < 0)
                break;
            deframer_stats.bad_headers++;
            pos = (uint16_t)later;
            continue;
        }
        if (!body_ok(p)) {
            deframer_stats.bad_frames++;
            upper->rejected(p[2], p[3]);
            pos++;
            continue;
        }
        deframer_stats.frames++;
        if (pos > held) { /* right behind the held frames: it may be held too */
            memmove(buf + held, buf + pos, fill - pos);
            fill -= pos - held;
            pos = held;
            p = buf + pos;
        }
        uint8_t hold = upper->received(p[2], p[3], p[4], p + FRAME_HEADER_LEN, p[1]);
        if (drop_held) { /* a new session: the held frames are forgotten */
            drop_held = 0;
            memmove(buf, buf + held, fill - held);
            fill -= held;
            pos -= held;
            held = 0;
        }
        pos += total;
        if (hold) {
            held = pos;
            break; /* one frame checked per call: bounded work per main-loop turn */
        }
    }
    if (pos > held) {
        memmove(buf + held, buf + pos, fill - pos);
        fill -= pos - held;
    }
}

void frame_send(uint8_t kind, uint8_t seq, uint8_t ack, const uint8_t *payload, uint8_t len)
{
    uint8_t head[FRAME_HEADER_LEN] = {FRAME_SYNC, len, kind, seq, ack, 0};
    head[5] = crc8(head + 1, 4);
    uint32_t crc = crc32_run(crc32_run(CRC32_INIT, head + 1, FRAME_HEADER_LEN - 1), payload, len);
    crc ^= 0xFFFFFFFFUL;
    uint8_t tail[FRAME_CRC_LEN + 1] = {(uint8_t)(crc >> 24), (uint8_t)(crc >> 16),
                                       (uint8_t)(crc >> 8), (uint8_t)crc, FRAME_END};
    uart_write(head, FRAME_HEADER_LEN);
    uart_write(payload, len);
    uart_write(tail, sizeof tail);
}
