/* What the step tick's parts share (step_tick.h). */
#include "step_tick.h"

static struct out ticks_out[2];
struct out *this_tick = &ticks_out[0];
struct out *next_tick = &ticks_out[1];
uint8_t cur_dir = 0xFF;
volatile uint8_t tick_gen;
