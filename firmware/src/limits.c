#include "limits.h"

uint8_t limits_seen;

int8_t __attribute__((noinline)) limits_check(uint8_t moving, uint8_t negative)
{
    uint8_t hit = limits_pressed() & moving & (uint8_t)~negative & 7;
    uint8_t both = hit & limits_seen;
    limits_seen = hit;
    if (!both)
        return -1;
    return both & 1 ? 0 : both & 2 ? 1 : 2;
}
